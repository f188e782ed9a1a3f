"""The rig as data: arms, their joints and geometry, keep-out volumes, named positions (frozen dataclasses).

Everything here is in SI units (m, rad) and in the *rig frame*, a right-handed frame
fixed to the microscope (docs/rig.md): each arm's base frame is placed in it by the
arm's mount (an origin and a rotation). :mod:`.load` builds these objects from a rig
file and checks every value; :mod:`.envelope` checks a planned path against them.

Two arm kinds:

* ``"mm3a"`` — rotary, rotary, prismatic (docs/design.md §2): the tip is
  :func:`stickslip.kinematics.tip`; the links are the segment from joint 1's axis to
  joint 2's axis (``offset``) and the arm from joint 2's axis to the tip.
* ``"xyz"`` — three prismatic stages along ``axes`` carrying a tool: the holder is at
  ``sum(q_i axis_i)``, the tip at ``holder + tool``; the link is the tool.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..devices.base import device_key
from ..joints import JointSpec
from ..kinematics import Geometry, Stage

__all__ = [
    "ARM_KINDS",
    "SHAPES",
    "Arm",
    "Box",
    "Cylinder",
    "HalfSpace",
    "Joint",
    "Mount",
    "NamedPosition",
    "Rig",
    "Volume",
    "rotation_matrix",
]

ARM_KINDS = ("mm3a", "xyz")
"""The arm kinds a rig file may name (the module docstring)."""
SHAPES = ("box", "cylinder", "half-space")
"""The keep-out volume shapes a rig file may name."""

Vec = tuple[float, float, float]


def rotation_matrix(angles: Vec) -> NDArray[np.float64]:
    """``Rz(c) Ry(b) Rx(a)`` for ``angles = (a, b, c)`` rad: turn about the rig's x, then y, then z axis."""
    a, b, c = angles
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return np.asarray(rz @ ry @ rx, dtype=float)


@dataclass(frozen=True)
class Joint:
    """One joint of an arm.

    Attributes
    ----------
    number : int
        1, 2 or 3: the joint as the procedures and the calibration name it.
    channel : int
        The controller channel that drives it (1-based, as the device URL's joints).
    sign : int
        +1, or -1 when a positive step of the channel moves the joint backwards.
    kind : {"rotary", "prismatic"}
    lower, upper : float
        The joint's range (its end stops), rad or m.
    stops : tuple of str
        Which end stops it has (``"lower"``, ``"upper"``): where a traverse may end.
    soft_lower, soft_upper : float
        Soft limits, rad or m, within the range: no planned path goes beyond them.
    step : float
        A small step of the joint, rad or m (the rig file's ``step``): how many steps
        surely reach a stop without a calibration. ``nan``: the kind's
        :data:`stickslip.joints.NOMINAL_STEP`.
    """

    number: int
    channel: int
    sign: int
    kind: str
    lower: float
    upper: float
    stops: tuple[str, ...] = ("lower", "upper")
    soft_lower: float = -math.inf
    soft_upper: float = math.inf
    step: float = math.nan

    @property
    def unit(self) -> str:
        """``"rad"`` or ``"m"``."""
        return "rad" if self.kind == "rotary" else "m"

    @property
    def limits(self) -> tuple[float, float]:
        """The tighter of the range and the soft limits, rad or m."""
        return (max(self.lower, self.soft_lower), min(self.upper, self.soft_upper))


@dataclass(frozen=True)
class Mount:
    """Where an arm's base frame sits in the rig frame: ``origin`` (m) and ``rotation`` (rad, about x, y, z)."""

    origin: Vec = (0.0, 0.0, 0.0)
    rotation: Vec = (0.0, 0.0, 0.0)

    def matrix(self) -> NDArray[np.float64]:
        """The rotation from the base frame to the rig frame (:func:`rotation_matrix`)."""
        return rotation_matrix(self.rotation)

    def to_rig(self, p: ArrayLike) -> NDArray[np.float64]:
        """Points ``(..., 3)`` in the base frame, m, to the rig frame, m."""
        return np.asarray(np.asarray(p, dtype=float) @ self.matrix().T + np.asarray(self.origin), dtype=float)


@dataclass(frozen=True)
class Arm:
    """One manipulator of the rig.

    Attributes
    ----------
    name : str
    kind : {"mm3a", "xyz"}
    controller : str
        The controller URL, never with a password (:mod:`.secrets` adds it when opening).
    joints : tuple of Joint
        Joints 1, 2, 3 in order.
    mount : Mount
    geometry : Geometry or None
        An MM3A's link lengths (``offset``, ``length``), m; ``None`` for an ``xyz`` arm.
    axes : tuple of 3 vectors
        An ``xyz`` arm's stage directions in its base frame (unit vectors).
    tool : vector
        An ``xyz`` arm's tool, from the holder to the tip in its base frame, m.
    radius : float
        The links' half thickness, m: each link is a capsule of this radius.
    calibration, tuning : str or None
        The arm's calibration and tuning files (paths as written, relative to the rig file).
    password_env : str or None
        The environment variable holding the controller's password.
    password_keyring : tuple of (service, user) or None
        Where the OS keyring keeps it (the optional ``keyring`` package).
    home : tuple of 3 floats
        The pose drawn when no position is kept, rad or m.
    """

    name: str
    kind: str
    controller: str
    joints: tuple[Joint, Joint, Joint]
    mount: Mount = Mount()
    geometry: Geometry | None = None
    axes: tuple[Vec, Vec, Vec] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    tool: Vec = (0.0, 0.0, -0.01)
    radius: float = 0.0
    calibration: str | None = None
    tuning: str | None = None
    password_env: str | None = None
    password_keyring: tuple[str, str] | None = None
    home: Vec = (0.0, 0.0, 0.0)

    def joint_specs(self) -> dict[int, JointSpec]:
        """The arm's joints as the procedures take them (:data:`stickslip.joints.JointSet`).

        Kind, range, nominal step and home from the rig file. An ``mm3a`` arm's joints
        are planned with the calibration's load-dependent models (docs/design.md §3); an
        ``xyz`` arm's stages with the calibration's constant step of each direction.
        """
        model = "paper" if self.kind == "mm3a" else "constant"
        return {
            j.number: JointSpec(j.number, j.kind, j.lower, j.upper, j.unit, nominal_step=j.step,
                                home=self.home[j.number - 1], step_model=model)
            for j in self.joints
        }

    def stage(self) -> Stage | None:
        """An ``xyz`` arm's kinematics in its base frame (its axes and tool); ``None`` for an ``mm3a``."""
        return Stage(self.axes, self.tool) if self.kind == "xyz" else None

    def joint(self, number: int) -> Joint:
        """The joint numbered ``number`` (1, 2, 3); ``KeyError`` otherwise."""
        for j in self.joints:
            if j.number == number:
                return j
        raise KeyError(f"arm {self.name!r} has no joint {number}")

    def segments(self, q: ArrayLike) -> NDArray[np.float64]:
        """The links at poses ``q`` ``(..., 3)`` as segments in the rig frame, m: shape ``(..., L, 2, 3)``.

        The last segment ends at the tip (so ``segments(q)[..., -1, 1, :]`` is the tip).
        """
        a = np.asarray(q, dtype=float)
        if self.kind == "mm3a":
            g = self.geometry or Geometry()
            q1, q2, q3 = a[..., 0], a[..., 1], a[..., 2]
            c1, s1 = np.cos(q1), np.sin(q1)
            r = g.length + q3
            u = g.offset - r * np.sin(q2)
            base = np.zeros(a.shape[:-1] + (3,))
            elbow = np.stack((g.offset * c1, g.offset * s1, np.zeros_like(q1)), axis=-1)
            tip = np.stack((u * c1, u * s1, r * np.cos(q2)), axis=-1)
            links = np.stack((np.stack((base, elbow), axis=-2), np.stack((elbow, tip), axis=-2)), axis=-3)
        else:
            holder = a @ np.asarray(self.axes, dtype=float)
            tip = holder + np.asarray(self.tool)
            links = np.stack((holder, tip), axis=-2)[..., None, :, :]
        return self.mount.to_rig(links)

    def tip(self, q: ArrayLike) -> NDArray[np.float64]:
        """The tip at poses ``q`` ``(..., 3)`` in the rig frame, m."""
        return np.asarray(self.segments(q)[..., -1, 1, :], dtype=float)

    def reach_radii(self) -> tuple[float, float, float]:
        """How far a point of the arm moves per unit of each joint, at most (m/rad or m/m).

        The sum ``sum_i radii_i |dq_i|`` bounds how far any point of the arm (links, tip)
        moves along a straight path in joint space: what :mod:`.envelope` samples by.
        """
        if self.kind == "mm3a":
            g = self.geometry or Geometry()
            r2 = g.length + max(abs(self.joint(3).lower), abs(self.joint(3).upper))
            return (abs(g.offset) + r2, r2, 1.0)
        n = [float(np.linalg.norm(v)) for v in self.axes]
        return (n[0], n[1], n[2])


@dataclass(frozen=True)
class Box:
    """A box: its ``centre`` (m), ``half`` sizes along its own axes (m), and ``rotation``.

    ``rotation`` is the 3x3 matrix (row-major) that turns the box's axes into the rig's:
    the identity for a box with faces along the rig's axes.
    """

    name: str
    centre: Vec
    half: Vec
    margin: float = 0.0
    rotation: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    shape: str = field(default="box", init=False)

    def matrix(self) -> NDArray[np.float64]:
        """``rotation`` as a 3x3 array (box axes to rig axes)."""
        return np.asarray(self.rotation, dtype=float).reshape(3, 3)

    def size(self) -> float:
        """Its smallest extent, m."""
        return 2.0 * min(self.half)


@dataclass(frozen=True)
class Cylinder:
    """A solid cylinder: the centre of its base ``base``, unit ``axis``, ``radius`` and ``height``, m."""

    name: str
    base: Vec
    axis: Vec
    radius: float
    height: float
    margin: float = 0.0
    shape: str = field(default="cylinder", init=False)

    def size(self) -> float:
        """Its smallest extent, m."""
        return min(2.0 * self.radius, self.height)


@dataclass(frozen=True)
class HalfSpace:
    """Everything on the side of the plane through ``point`` that unit ``normal`` points to (m)."""

    name: str
    point: Vec
    normal: Vec
    margin: float = 0.0
    shape: str = field(default="half-space", init=False)

    def size(self) -> float:
        """Unbounded."""
        return math.inf


Volume = Box | Cylinder | HalfSpace


@dataclass(frozen=True)
class NamedPosition:
    """A named position of one arm: its joints' targets (rad or m; ``None`` leaves one) and the order they move in."""

    name: str
    arm: str
    q: tuple[float | None, float | None, float | None]
    order: tuple[int, ...]


@dataclass(frozen=True)
class Rig:
    """A whole rig: its arms, keep-out volumes, named positions and the rules between arms.

    Attributes
    ----------
    path : str
        The file it was read from (for messages).
    name : str
    arms : tuple of Arm
        The first one is the default arm.
    volumes : tuple of Volume
        Keep-out volumes in the rig frame (a stage tilt already applied).
    positions : tuple of NamedPosition
    arm_distance : float
        The least distance between two arms' links and tips, m.
    stage_tilt : float
        The stage's tilt about the rig's x axis, rad (applied to volumes marked ``on_stage``).
    n_sigma : float
        How many standard deviations of the tip's position are added to every margin.
    database : str or None
        Where the rig's history is kept (the file's ``database``): an SQLite file (its
        path, a relative one already taken from the rig file's folder) or a
        ``postgresql://`` URL without a password; ``None`` when the file names none.
    """

    path: str
    name: str
    arms: tuple[Arm, ...]
    volumes: tuple[Volume, ...] = ()
    positions: tuple[NamedPosition, ...] = ()
    arm_distance: float = 0.0
    stage_tilt: float = 0.0
    n_sigma: float = 3.0
    database: str | None = None

    def arm(self, name: str | None = None) -> Arm:
        """The arm called ``name`` (the first one for ``None``); ``KeyError`` naming the arms otherwise."""
        if name is None:
            return self.arms[0]
        for a in self.arms:
            if a.name == name:
                return a
        names = ", ".join(a.name for a in self.arms)
        raise KeyError(f"{self.path}: no arm named {name!r} (the arms: {names})")

    def state_key(self, arm: str | None = None) -> str:
        """The key ``arm``'s positions and journal are kept under: its controller's device key, or
        ``KEY#arm=NAME`` when another arm of the rig shares its controller (on other channels).

        The lock stays the controller's (:func:`~stickslip.devices.base.device_key`): one process
        drives a controller at a time.
        """
        a = self.arm(arm)
        key = device_key(a.controller)
        shared = any(o.name != a.name and device_key(o.controller) == key for o in self.arms)
        return f"{key}#arm={a.name}" if shared else key

    def position(self, arm: str, name: str) -> NamedPosition:
        """The named position ``name`` of ``arm``; ``KeyError`` naming the known ones otherwise."""
        for p in self.positions:
            if p.arm == arm and p.name == name:
                return p
        known = ", ".join(p.name for p in self.positions if p.arm == arm) or "none"
        raise KeyError(f"{self.path}: arm {arm!r} has no named position {name!r} (its positions: {known})")
