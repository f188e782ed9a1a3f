"""The tip in task space: forward kinematics, the Jacobian and inverse kinematics.

With the frames of docs/design.md §2 (joint 1 about z0; in the frame turned by ``q1``
the joint-2 axis is ``-y`` and the arm axis is ``z2 = (-sin q2, 0, cos q2)``), the tip
in the base frame (before the base tilt; metres) is (docs/design.md §9)

    p(q) = Rz(q1) · ( offset · x̂ + (length + q3) · z2(q2) )

``offset`` is the distance from joint 1's axis to joint 2's axis along ``x1`` and
``length`` the distance from joint 2's axis to the tip at ``q3 = 0``
(:class:`Geometry`). In the arm's plane (the frame turned by ``q1``) the tip is at
``(u, 0, w)`` with ``u = offset - r sin q2``, ``w = r cos q2`` and ``r = length + q3``.

The three columns of the Jacobian ``J = dp/dq`` are mutually orthogonal:

* ``J1 = z0 × p`` is normal to the arm's plane, of length ``rho = |u|`` (the tip's
  distance from joint 1's axis);
* ``J2 = r · Rz(q1) (-cos q2, 0, -sin q2)`` lies in the plane, across the arm, of
  length ``r``;
* ``J3 = Rz(q1) z2`` is the arm's axis, of length 1.

So ``det J = ±rho · r``, and the inverse is a projection on each column,
``dq_i = J_i · dp / |J_i|²``. The only singularity in reach is ``rho = 0``: the tip on
joint 1's axis (with ``offset = 0``, the arm pointing straight up or down), where
joint 1 turns the tip in place and a sideways move would need an unbounded turn.
Near it (``rho < min_reach``, :data:`MIN_REACH` by default) the functions here
refuse with :class:`SingularPose` rather than return huge joint increments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..joints import MM3A_GEOMETRY, JointSet
from ..units import UnitError, format_position, parse_length
from .frames import JOINTS

__all__ = [
    "Geometry",
    "DEFAULT_GEOMETRY",
    "MIN_REACH",
    "OutOfReach",
    "SingularPose",
    "tip",
    "jacobian",
    "tip_sd",
    "distance_from_axis",
    "inverse",
    "joint_rates",
    "limit_problem",
]

MIN_REACH = 1e-3
"""Closest the tip may come to joint 1's axis, m, before a pose counts as singular.

At 1 mm a joint-1 step of ~50 µrad moves the tip by ~50 nm, and a 10 µm sideways move
needs 0.6° of joint 1 (200 steps)."""

_MAX_SIZE = 1.0  # m: nothing on a micromanipulator is a metre long; catches unit slips


class OutOfReach(ValueError):
    """A target tip position needs a joint outside its range (the message names the limit)."""


class SingularPose(ValueError):
    """A pose or path too close to the singularity (the tip on joint 1's axis)."""


def _mm_slip(v: float) -> str:
    """`` (in mm? ...)`` for a geometry length beyond :data:`_MAX_SIZE` that is one in millimetres (a bare 21)."""
    mm = v * 1e-3
    return f" (in mm? {v:.6g} mm is {mm:.6g} m: lengths are in metres)" if abs(mm) <= _MAX_SIZE < abs(v) else ""


@dataclass(frozen=True)
class Geometry:
    """The two lengths that place the tip: ``offset`` and ``length``, m.

    Parameters
    ----------
    offset : float
        Distance from joint 1's axis to joint 2's axis, along ``x1`` (the arm's plane), m.
        Default 0 (read from the MM3A's description, ``stickslip.joints.MM3A_FILE``):
        the MM3A's joint-2 axis crosses joint 1's axis (to within a millimetre;
        measure yours, docs/taskspace.md).
    length : float
        Distance from joint 2's axis to the tip with joint 3 retracted (``q3 = 0``), m,
        > 0. Default 21 mm (from the same file): an MM3A with a short tip holder and
        tip. Measure yours: it scales every rotary move of the tip.
    """

    offset: float = MM3A_GEOMETRY[0]
    length: float = MM3A_GEOMETRY[1]

    def __post_init__(self) -> None:
        for name in ("offset", "length"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"geometry {name} = {v!r} must be a finite length in metres")
            object.__setattr__(self, name, float(v))
        if not 0.0 < self.length <= _MAX_SIZE:
            raise ValueError(f"geometry length = {self.length:.6g} m must be in (0, {_MAX_SIZE:g}] m"
                             + _mm_slip(self.length))
        if not abs(self.offset) <= _MAX_SIZE:
            raise ValueError(f"geometry offset = {self.offset:.6g} m must be within ±{_MAX_SIZE:g} m"
                             + _mm_slip(self.offset))

    @classmethod
    def parse(cls, text: str) -> Geometry:
        """``"OFFSET,LENGTH"`` with units, e.g. ``"0mm,21mm"`` or ``"0,0.021"`` (metres)."""
        parts = str(text).split(",")
        if len(parts) != 2:
            raise ValueError(f"geometry {text!r}: write OFFSET,LENGTH, e.g. 0mm,21mm")
        try:
            offset, length = (parse_length(p) for p in parts)
        except UnitError as e:
            raise ValueError(f"geometry {text!r}: {e}") from None
        return cls(offset, length)

    def as_dict(self) -> dict[str, float]:
        """``{"offset": m, "length": m}``."""
        return {"offset": self.offset, "length": self.length}


DEFAULT_GEOMETRY = Geometry()


def _q(q: ArrayLike) -> NDArray[np.float64]:
    a = np.asarray(q, dtype=float)
    if a.shape[-1:] != (3,):
        raise ValueError(f"joint coordinates must have a last axis of 3 (q1 rad, q2 rad, q3 m), got shape {a.shape}")
    return a


def tip(q: ArrayLike, geometry: Geometry = DEFAULT_GEOMETRY) -> NDArray[np.float64]:
    """Tip position in the base frame, m, shape ``(..., 3)``.

    ``p(q) = Rz(q1) (offset x̂ + (length + q3) z2(q2))``; ``q = (q1 rad, q2 rad, q3 m)``,
    shape ``(..., 3)``.
    """
    a = _q(q)
    q1, q2, q3 = a[..., 0], a[..., 1], a[..., 2]
    r = geometry.length + q3
    u = geometry.offset - r * np.sin(q2)
    return np.stack((u * np.cos(q1), u * np.sin(q1), r * np.cos(q2)), axis=-1)


def jacobian(q: ArrayLike, geometry: Geometry = DEFAULT_GEOMETRY) -> NDArray[np.float64]:
    """The Jacobian ``dp/dq`` (columns: m/rad, m/rad, m/m), shape ``(..., 3, 3)``.

    Column ``i`` is the tip's velocity per unit velocity of joint ``i``; see the module
    docstring for their closed forms and orthogonality.
    """
    a = _q(q)
    q1, q2, q3 = a[..., 0], a[..., 1], a[..., 2]
    c1, s1, c2, s2 = np.cos(q1), np.sin(q1), np.cos(q2), np.sin(q2)
    r = geometry.length + q3
    u = geometry.offset - r * s2
    zero = np.zeros_like(u)
    j1 = np.stack((-u * s1, u * c1, zero), axis=-1)
    j2 = np.stack((-r * c2 * c1, -r * c2 * s1, -r * s2), axis=-1)
    j3 = np.stack((-s2 * c1, -s2 * s1, c2), axis=-1)
    return np.stack((j1, j2, j3), axis=-1)


def tip_sd(q: ArrayLike, q_sd: ArrayLike, geometry: Geometry = DEFAULT_GEOMETRY) -> NDArray[np.float64]:
    """Standard deviation of each tip coordinate, m, from independent joint standard deviations (rad, rad, m).

    First-order propagation: ``Cov(p) = J diag(sd**2) J^T`` and the square roots of its
    diagonal, ``sd_k = sqrt(sum_i (J_ki sd_i)**2)``; ``q`` and ``q_sd`` have shape ``(3,)``.
    """
    J = jacobian(_q(q), geometry)
    sd = np.asarray(q_sd, dtype=float).reshape(3)
    return np.asarray(np.sqrt(np.sum((J * sd) ** 2, axis=-1)), dtype=float)


def distance_from_axis(q: ArrayLike, geometry: Geometry = DEFAULT_GEOMETRY) -> NDArray[np.float64]:
    """``rho``: the tip's distance from joint 1's axis, m (the singularity is ``rho = 0``)."""
    a = _q(q)
    return np.abs(geometry.offset - (geometry.length + a[..., 2]) * np.sin(a[..., 1]))


def _singular_message(rho: float, min_reach: float, where: str) -> str:
    return (
        f"{where} is {rho * 1e3:.3g} mm from joint 1's axis, closer than {min_reach * 1e3:.3g} mm: "
        f"a singular pose (joint 1 turns the tip almost in place, so a sideways move would need "
        f"a very large turn); tilt the arm (joint 2) away from the vertical first"
    )


def joint_rates(
    q: ArrayLike,
    v: ArrayLike,
    geometry: Geometry = DEFAULT_GEOMETRY,
    min_reach: float = MIN_REACH,
) -> NDArray[np.float64]:
    """Joint velocities ``J⁻¹ v`` (rad/s, rad/s, m/s) for a tip velocity ``v`` (m/s) at ``q``.

    The resolved-rate step: ``dq_i = J_i · v / |J_i|²`` (the columns are orthogonal).
    Works as well for small displacements (m in, rad/m out). Raises
    :class:`SingularPose` when the tip is closer than ``min_reach`` (m) to joint 1's axis.
    """
    a = _q(q)
    if a.ndim != 1:
        raise ValueError("joint_rates takes one pose (q1, q2, q3)")
    rho = float(distance_from_axis(a, geometry))
    if rho < min_reach:
        raise SingularPose(_singular_message(rho, min_reach, "the tip"))
    J = jacobian(a, geometry)
    vv = np.asarray(v, dtype=float).reshape(3)
    norms2 = np.sum(J * J, axis=0)
    return np.asarray((J.T @ vv) / norms2, dtype=float)


def limit_problem(q: ArrayLike, joints: JointSet | None = None) -> str | None:
    """``"joint j would be at ... beyond its lower/upper limit ..."`` for the first joint out of range, or ``None``.

    ``joints``: the arm's (a rig file's), the MM3A's by default.
    """
    a = _q(q)
    for j in (1, 2, 3):
        spec = (JOINTS if joints is None else joints)[j]
        v = float(a[j - 1])
        if spec.contains(v):
            continue
        side = "lower" if v < spec.lower else "upper"
        bound = spec.lower if side == "lower" else spec.upper
        return (f"joint {j} would be at {format_position(v, spec)}, beyond its {side} limit "
                f"{format_position(bound, spec)}")
    return None


def _candidates(p: NDArray[np.float64], geometry: Geometry, near: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Both IK branches (tip on either side of joint 1's axis), each angle wrapped nearest ``near`` and one turn
    either side of it (joint 2's range is 240°: the turn inside it may be more than half a turn from ``near``)."""
    x, y, z = (float(c) for c in p)
    rho = math.hypot(x, y)
    phi = math.atan2(y, x) if rho > 0.0 else float(near[0])
    out = []
    turn = 2.0 * math.pi
    for u, q1 in ((rho, phi), (-rho, phi + math.pi)):
        q2 = math.atan2(geometry.offset - u, z)
        r = math.hypot(geometry.offset - u, z)
        q1 += turn * round((float(near[0]) - q1) / turn)
        q2 += turn * round((float(near[1]) - q2) / turn)
        for k1 in (0, -1, 1):
            for k2 in (0, -1, 1):
                out.append(np.array([q1 + k1 * turn, q2 + k2 * turn, r - geometry.length]))
    return out


def _distance(a: NDArray[np.float64], b: NDArray[np.float64], geometry: Geometry) -> float:
    """Joint-space distance, rotary joints weighted by the arm's length (m)."""
    w = geometry.length
    return float(math.hypot(w * (a[0] - b[0]), w * (a[1] - b[1]), a[2] - b[2]))


def inverse(
    p: ArrayLike,
    geometry: Geometry = DEFAULT_GEOMETRY,
    near: ArrayLike | None = None,
    min_reach: float = MIN_REACH,
    check_limits: bool = True,
) -> NDArray[np.float64]:
    """Joint coordinates (rad, rad, m) that put the tip at ``p`` (m, base frame).

    Closed form: ``q1`` is the azimuth of ``p`` (or opposite it), then in the arm's
    plane ``r sin q2 = offset - u``, ``r cos q2 = z``, ``q3 = r - length``. Of the two
    branches and the ``2 pi`` turns of the angles, the solution within the joints'
    ranges nearest ``near`` (default: the outstretched pose) is returned.

    Raises
    ------
    SingularPose
        If ``p`` is closer than ``min_reach`` (m) to joint 1's axis.
    OutOfReach
        If no solution is within the joints' ranges (the message names the limit of
        the nearest solution), when ``check_limits``.
    """
    pp = np.asarray(p, dtype=float).reshape(3)
    if not np.all(np.isfinite(pp)):
        raise ValueError(f"tip position {pp.tolist()} is not finite")
    ref = np.array([0.0, -math.pi / 2, 0.0]) if near is None else _q(near).reshape(3)
    rho = math.hypot(float(pp[0]), float(pp[1]))
    if rho < min_reach:
        raise SingularPose(_singular_message(rho, min_reach, "the target"))
    cands = sorted(_candidates(pp, geometry, ref), key=lambda c: _distance(c, ref, geometry))
    if not check_limits:
        return cands[0]
    for c in cands:
        if limit_problem(c) is None:
            return c
    problem = limit_problem(cands[0])
    shown = ", ".join(f"{v * 1e6:.1f}" for v in pp)
    raise OutOfReach(f"the tip cannot reach ({shown}) µm: {problem}")
