"""Frames, joint ranges and the static-load terms of the MM3A-type arm.

Conventions (docs/design.md §2): joints 1 and 2 are rotary (radians), joint 3 is
prismatic (metres). With z0 vertical, the base frame is rotated by ``theta`` about
x0, then by ``psi`` about the new y0, so unit gravity in the base frame is

    g0 = (cos(theta) sin(psi), -sin(theta), -cos(theta) cos(psi)).

Joint 1 turns the arm about z0. In the frame turned by ``q1`` the joint-2 axis is
z1 = -y and the arm (joint-3) axis is z2 = (-sin q2, 0, cos q2): ``q2 = 0`` points the
arm up, ``q2 = -pi/2`` holds it out horizontally.

The *load term* of a joint is the dimensionless static load that the paper's models
multiply by a calibrated parameter. For each joint it is derived here from the
geometry, and it reproduces the paper's terms at ``q1 = 0`` exactly:

========  ===================================  ==========================================
joint     general (this module)                 paper, ``q1 = 0`` (``zeta = psi - q2``)
========  ===================================  ==========================================
3         ``-g0' . z2`` (gravity along the arm)  ``cos(zeta) cos(theta)``  (Eq. 3)
2         ``-(z2 x g0') . z1`` (minus torque)    ``sin(zeta) cos(theta)``  (Eq. 8)
1         ``-(r z2 x g0) . z0 / |r|``            ``-sin(q2) (sin(theta) cos(q1)
                                                 + cos(theta) sin(psi) sin(q1))``
========  ===================================  ==========================================

(``g0'`` is gravity in the frame turned by ``q1``.) The minus signs make the load term
*negative torque*, the paper's sign: with it, ``d_- > 0`` means gravity helps the
negative direction. For rotary joints the load along the joint's own travel has the
form ``alpha cos(q) + beta sin(q)``, which :func:`rotary_load_coefficients` returns,
so averages over a traverse have a closed form (see :mod:`stickslip.models`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, NamedTuple, Self, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..joints import JOINTS, Q3_MAX, ROTARY_SPAN, JointSet, JointSpec, coordinate_problem, joint_spec, tilt_problem

__all__ = [
    "Pose",
    "pose_problems",
    "JointSpec",
    "JointSet",
    "JOINTS",
    "Q3_MAX",
    "ROTARY_SPAN",
    "joint_spec",
    "zeta",
    "rotation_base",
    "gravity_base",
    "arm_axis",
    "joint2_axis",
    "prismatic_load",
    "joint2_load",
    "joint1_load",
    "load_term",
    "rotary_load_coefficients",
]

class _PoseFields(NamedTuple):
    q1: float = 0.0
    q2: float = -math.pi / 2
    q3: float = 0.0
    theta: float = 0.0
    psi: float = 0.0


_P = TypeVar("_P", bound="Pose")


class Pose(_PoseFields):
    """A configuration of the arm and its base: joints (rad, rad, m) and tilt (rad).

    For a traverse or a move of joint j, ``q{j}`` is ignored (the moving joint's own
    coordinate comes separately).

    Checked once, here, for what holds on every arm (:func:`pose_problems`): finite numbers,
    ``q1``, ``q2`` within a full turn, ``q3`` within a metre, the tilt within [-pi, pi]; else
    ``ValueError`` naming the value and its likely unit slip (``Pose(q2=-90)``: degrees). An
    arm's own stops are checked where the arm is known (:meth:`JointSpec.range_problem`).
    """

    __slots__ = ()

    def __new__(
        cls, q1: float = 0.0, q2: float = -math.pi / 2, q3: float = 0.0, theta: float = 0.0, psi: float = 0.0
    ) -> Self:
        problems = pose_problems(q1, q2, q3, theta, psi)
        if problems:
            raise ValueError("pose: " + "; ".join(problems))
        return super().__new__(cls, q1, q2, q3, theta, psi)

    @classmethod
    def _make(cls: type[_P], iterable: Iterable[Any]) -> _P:  # type: ignore[override]  # (mypy: NamedTuple _NT)
        """As the named tuple's, but checked (so :meth:`_replace` is too)."""
        return cls(*iterable)


def pose_problems(q1: float, q2: float, q3: float, theta: float, psi: float) -> list[str]:
    """Why ``(q1, q2, q3, theta, psi)`` is no arm's pose, whatever the arm (empty if it can be one).

    :func:`~stickslip.joints.coordinate_problem` of each joint and
    :func:`~stickslip.joints.tilt_problem` of the tilt: not finite, a joint beyond a full turn
    (1, 2) or a metre (3), a tilt outside [-pi, pi].
    """
    problems = [p for j, q in ((1, q1), (2, q2), (3, q3)) if (p := coordinate_problem(f"q{j}", j, q))]
    return problems + [p for name, v in (("theta", theta), ("psi", psi)) if (p := tilt_problem(name, v))]


def zeta(q2: ArrayLike, psi: ArrayLike) -> NDArray[np.float64]:
    """The paper's ``zeta = psi - q2`` (rad)."""
    return np.asarray(np.asarray(psi, dtype=float) - np.asarray(q2, dtype=float), dtype=float)


def _rx(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_base(theta: float, psi: float) -> NDArray[np.float64]:
    """Orientation of the base frame in the world: ``Rx(theta) @ Ry(psi)`` (the paper's base tilt, rad).

    Columns are the base axes x0, y0, z0 written in world coordinates.
    """
    return _rx(theta) @ _ry(psi)


def gravity_base(theta: ArrayLike, psi: ArrayLike) -> NDArray[np.float64]:
    """Unit gravity in the base frame, shape ``(..., 3)``, for the paper's base tilt ``theta``, ``psi`` (rad).

    ``g0 = (cos(theta) sin(psi), -sin(theta), -cos(theta) cos(psi))``; equal to
    ``rotation_base(theta, psi).T @ (0, 0, -1)``.
    """
    theta = np.asarray(theta, dtype=float)
    psi = np.asarray(psi, dtype=float)
    ct = np.cos(theta)
    return np.stack(np.broadcast_arrays(ct * np.sin(psi), -np.sin(theta), -ct * np.cos(psi)), axis=-1)


def _gravity_arm_frame(q1: ArrayLike, theta: ArrayLike, psi: ArrayLike) -> NDArray[np.float64]:
    """Gravity in the frame turned by ``q1`` about z0: ``Rz(q1).T @ g0``."""
    g = gravity_base(theta, psi)
    q1 = np.asarray(q1, dtype=float)
    c, s = np.cos(q1), np.sin(q1)
    gx = c * g[..., 0] + s * g[..., 1]
    gy = -s * g[..., 0] + c * g[..., 1]
    return np.stack(np.broadcast_arrays(gx, gy, g[..., 2]), axis=-1)


def arm_axis(q1: ArrayLike, q2: ArrayLike) -> NDArray[np.float64]:
    """Unit arm (joint-3) axis z2 in the base frame, shape ``(..., 3)``, at joints ``q1``, ``q2`` (rad)."""
    q1 = np.asarray(q1, dtype=float)
    q2 = np.asarray(q2, dtype=float)
    s2 = np.sin(q2)
    return np.stack(np.broadcast_arrays(-s2 * np.cos(q1), -s2 * np.sin(q1), np.cos(q2)), axis=-1)


def joint2_axis(q1: ArrayLike) -> NDArray[np.float64]:
    """Unit joint-2 axis z1 in the base frame (``-y0`` at ``q1 = 0``; ``q1`` in rad), shape ``(..., 3)``."""
    q1 = np.asarray(q1, dtype=float)
    return np.stack(np.broadcast_arrays(np.sin(q1), -np.cos(q1), np.zeros_like(q1)), axis=-1)


def prismatic_load(q1: ArrayLike, q2: ArrayLike, theta: ArrayLike, psi: ArrayLike) -> NDArray[np.float64]:
    """Gravity along the arm axis, ``-g0 . z2`` (dimensionless, in [-1, 1]).

    Positive when gravity pulls the slider inwards (against ``+``). Equals the
    paper's ``cos(zeta) cos(theta)`` (Eq. 3) at ``q1 = 0``.
    """
    g = _gravity_arm_frame(q1, theta, psi)
    q2 = np.asarray(q2, dtype=float)
    return np.asarray(np.sin(q2) * g[..., 0] - np.cos(q2) * g[..., 2], dtype=float)


def joint2_load(q1: ArrayLike, q2: ArrayLike, theta: ArrayLike, psi: ArrayLike) -> NDArray[np.float64]:
    """Minus the unit gravity torque about the joint-2 axis from a mass on the arm.

    ``-(z2 x g0) . z1``, dimensionless in [-1, 1]. Equals the paper's
    ``sin(zeta) cos(theta)`` (Eq. 8) at ``q1 = 0``.
    """
    alpha, beta = rotary_load_coefficients(2, q1, q2, 0.0, theta, psi)
    q2 = np.asarray(q2, dtype=float)
    return np.asarray(alpha * np.cos(q2) + beta * np.sin(q2), dtype=float)


def joint1_load(q1: ArrayLike, q2: ArrayLike, theta: ArrayLike, psi: ArrayLike) -> NDArray[np.float64]:
    """Minus the unit gravity torque about z0 from a mass on the arm (joint 1).

    ``-sin(q2) (sin(theta) cos(q1) + cos(theta) sin(psi) sin(q1))``: the horizontal
    reach of the arm (``-sin q2``, 1 when outstretched) times the docs/design.md term.
    Zero at ``theta = psi = 0``; largest at ``theta = -pi/2`` (the paper's
    "interchanged" roles for joint 1).
    """
    alpha, beta = rotary_load_coefficients(1, q1, q2, 0.0, theta, psi)
    q1 = np.asarray(q1, dtype=float)
    return np.asarray(alpha * np.cos(q1) + beta * np.sin(q1), dtype=float)


def load_term(
    joint: int,
    q1: ArrayLike,
    q2: ArrayLike,
    q3: ArrayLike,
    theta: ArrayLike,
    psi: ArrayLike,
) -> NDArray[np.float64]:
    """The load term of ``joint`` (1, 2 or 3) in a pose (dimensionless); see the module table.

    ``q1``, ``q2`` rad, ``q3`` m, the base tilt ``theta``, ``psi`` rad (the paper's names); for
    joint 3 at ``q1 = 0`` it is ``cos(zeta) cos(theta)`` with ``zeta = psi - q2``. An unknown
    joint raises ``ValueError``.
    """
    if joint == 3:
        return prismatic_load(q1, q2, theta, psi)
    if joint == 2:
        return joint2_load(q1, q2, theta, psi)
    if joint == 1:
        return joint1_load(q1, q2, theta, psi)
    raise ValueError(f"unknown joint {joint!r}")


def rotary_load_coefficients(
    joint: int,
    q1: ArrayLike,
    q2: ArrayLike,
    q3: ArrayLike,
    theta: ArrayLike,
    psi: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(alpha, beta)`` such that the load on rotary ``joint`` is ``alpha cos q + beta sin q``.

    ``q`` is the joint's own coordinate; ``alpha`` and ``beta`` depend only on the
    other joints and the tilt, so they stay constant along a traverse of ``joint``.
    The column of the moving joint is ignored.

    * joint 2: ``alpha = g'_x``, ``beta = g'_z`` with ``g'`` gravity in the frame
      turned by ``q1``; at ``q1 = 0``: ``alpha cos q2 + beta sin q2 = sin(psi - q2) cos(theta)``.
    * joint 1: ``alpha = -sin(q2) sin(theta)``, ``beta = -sin(q2) cos(theta) sin(psi)``.
    """
    if joint == 2:
        g = _gravity_arm_frame(q1, theta, psi)
        return g[..., 0], g[..., 2]
    if joint == 1:
        q2 = np.asarray(q2, dtype=float)
        theta = np.asarray(theta, dtype=float)
        psi = np.asarray(psi, dtype=float)
        reach = -np.sin(q2)
        alpha = reach * np.sin(theta)
        beta = reach * np.cos(theta) * np.sin(psi)
        a, b = np.broadcast_arrays(alpha, beta)
        return a, b
    raise ValueError(f"joint {joint!r} is not rotary")
