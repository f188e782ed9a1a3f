"""Load-aware mean step-size models (the paper's Eqs. 2, 3, 7, 8) and traverse averages.

All functions are pure and vectorised over poses; SI units throughout (step sizes in
metres for the prismatic joint, radians for rotary joints).

Prismatic joint 3, direction ``i``::

    eta_i(q2)  = 1 - b_i |cos q2|                                  (2)
    gamma_3i   = eta_i(q2) (a_i - c_i L3),   L3 = cos(zeta) cos(theta) at q1 = 0   (3)

Rotary joints 1 and 2, direction ``i``::

    gamma_ji   = gamma_ji0(q3) + d_i(q3) L_j                       (7), (8)

with ``L2 = sin(zeta) cos(theta)`` at ``q1 = 0`` and the load terms of
:mod:`stickslip.kinematics` in general. ``gamma_ji0`` and ``d_i`` are interpolated
linearly in ``q3`` between the values calibrated at ``q3 = 0`` and ``q3 = 12 mm``.

The *average step over a traverse* from ``start`` to ``end`` is
``|end - start| / N`` with ``N = integral dq / gamma(q)``. For rotary joints
``gamma(q) = A + B cos(q - phi)``-type, so ``N`` has a closed form
(:func:`steps_between`), cross-checked against adaptive quadrature
(:func:`steps_between_quad`) and a step-by-step simulation
(:func:`simulate_traverse_steps`).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import kinematics as kin
from ..joints import TILT_LIMIT, coordinate_bound, coordinate_problem, tilt_problem

FloatArray = NDArray[np.float64]

__all__ = [
    "DIRECTIONS",
    "STALL_RATIO",
    "direction_sign",
    "direction_label",
    "eta",
    "gamma_prismatic",
    "gamma_rotary",
    "interp_q3",
    "PrismaticParams",
    "RotaryParams",
    "JointModel",
    "Params",
    "NonPhysicalError",
    "antiderivative_inverse_step",
    "StepProfile",
    "sinusoid_range",
    "steps_between",
    "steps_between_quad",
    "iter_traverse_steps",
    "simulate_traverse_steps",
    "position_after_steps",
]

DIRECTIONS = ("+", "-")

STALL_RATIO = 1e-6
"""Smallest ratio of a model's smallest step to its largest (1) that ``check_physical`` accepts. A step that is
> 0 only to rounding (gamma0 - |d| = 1e-20 rad beside gamma0 = 1e-5 rad) passed a strict > 0 and then gave counts
of 1e15 from the quadrature of 1/gamma instead of a stall refusal; below a millionth of its largest step the count
to cross that pose is no step count a controller sends, and the difference is within a few thousand ulps of the
parameters: a stall, said as one."""


def direction_sign(direction: str | int) -> int:
    """``+1`` for ``"+"`` (or ``1``), ``-1`` for ``"-"``/``"−"`` (or ``-1``)."""
    if direction in ("+", 1, "1", "+1", "pos"):
        return 1
    if direction in ("-", "−", -1, "-1", "neg"):
        return -1
    raise ValueError(f"direction must be '+' or '-', got {direction!r}")


def direction_label(sign: int | str) -> str:
    """``"+"`` or ``"-"`` for a direction given as a sign or label."""
    return "+" if direction_sign(sign) > 0 else "-"


_MAX_KNOT = 1.0
"""Largest |q3| of a rotary model's knot, m: no micromanipulator's joint 3 extends a metre, so a knot beyond it is
a unit slip (knots (0, 12) for 0 and 12 mm interpolated as if 12 m: the q3 = 12 mm values were never reached)."""


class NonPhysicalError(ValueError):
    """A parameter set that would give a step size <= 0 somewhere, or b outside [0, 1)."""


# ---------------------------------------------------------------- pure model functions


def eta(q2: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Stepping efficiency of the prismatic joint, Eq. (2): ``1 - b |cos q2|``.

    Parameters
    ----------
    q2 : array_like
        Joint-2 angle, rad.
    b : array_like
        Efficiency loss when the arm is perpendicular to the outstretched pose (1).
    """
    out: NDArray[np.float64] = 1.0 - np.asarray(b, dtype=float) * np.abs(np.cos(np.asarray(q2, dtype=float)))
    return out


def gamma_prismatic(
    q2: ArrayLike,
    theta: ArrayLike,
    psi: ArrayLike,
    a: ArrayLike,
    b: ArrayLike,
    c: ArrayLike,
    q1: ArrayLike = 0.0,
) -> NDArray[np.float64]:
    """Mean step of prismatic joint 3, Eq. (3): ``eta(q2) (a - c cos(zeta) cos(theta))``, m.

    Parameters
    ----------
    q2, theta, psi, q1 : array_like
        Pose, rad. The axial load term is ``-g0 . z2`` (``cos(zeta) cos(theta)`` at q1 = 0).
    a : array_like
        Step with no axial load and full efficiency (q2 = -pi/2, theta = 0), m. Eq. (4).
    b : array_like
        Efficiency loss, dimensionless. Eq. (5).
    c : array_like
        Change of step per unit axial load, m. Eq. (6).
    """
    load = kin.prismatic_load(q1, q2, theta, psi)
    return eta(q2, b) * (np.asarray(a, dtype=float) - np.asarray(c, dtype=float) * load)


def gamma_rotary(load: ArrayLike, gamma0: ArrayLike, d: ArrayLike) -> NDArray[np.float64]:
    """Mean step of a rotary joint, Eqs. (7), (8): ``gamma0 + d L``, rad.

    Parameters
    ----------
    load : array_like
        Load term ``L`` (``sin(zeta) cos(theta)`` for joint 2 at q1 = 0), dimensionless.
    gamma0 : array_like
        Step with no gravity torque (theta = +-pi/2), rad.
    d : array_like
        Change of step per unit load, rad.
    """
    out: FloatArray = np.asarray(gamma0, dtype=float) + np.asarray(d, dtype=float) * np.asarray(load, dtype=float)
    return out


def interp_q3(q3: ArrayLike, knots: tuple[float, float], values: tuple[float, float]) -> NDArray[np.float64]:
    """Linear interpolation (and extrapolation) in ``q3`` (m) between two calibrated values."""
    q3 = np.asarray(q3, dtype=float)
    (x0, x1), (v0, v1) = knots, values
    return v0 + (v1 - v0) * (q3 - x0) / (x1 - x0)


# ---------------------------------------------------------------- parameter containers


@dataclass(frozen=True)
class PrismaticParams:
    """Parameters of Eq. (3) for one direction of the prismatic joint.

    Attributes
    ----------
    a : float
        Step with no load at full efficiency, m.
    b : float
        Efficiency loss, dimensionless, in [0, 1).
    c : float
        Change of step per unit axial load, m.
    """

    a: float
    b: float
    c: float

    kind = "prismatic"

    def names(self) -> list[tuple[str, float | None]]:
        return [("a", None), ("b", None), ("c", None)]

    def as_vector(self) -> NDArray[np.float64]:
        return np.array([self.a, self.b, self.c])

    @classmethod
    def from_vector(cls, v: ArrayLike) -> PrismaticParams:
        a, b, c = (float(x) for x in np.asarray(v, dtype=float))
        return cls(a, b, c)

    def check_physical(self) -> None:
        """Raise :class:`NonPhysicalError` unless b in [0, 1) and the step > 0 in every pose, and shorter than
        joint 3's whole stroke (a step in nm or µm given as a number of m).

        "> 0" with a relative margin: ``a - |c|`` more than :data:`STALL_RATIO` of ``a + |c|`` (a step zero to
        rounding is a stall, not a count of 1e15).
        """
        if not (0.0 <= self.b < 1.0) or not math.isfinite(self.b):
            raise NonPhysicalError(f"b = {self.b:.4g} is outside [0, 1): the efficiency 1 - b|cos q2| would be <= 0")
        if not self.a + abs(self.c) < kin.Q3_MAX:  # a = 972 meant as nm: every plan 1e-9 of its steps
            raise NonPhysicalError(
                f"a + |c| = {self.a + abs(self.c):.4g} m: a step longer than joint 3's whole stroke "
                f"({kin.Q3_MAX * 1e3:g} mm); a and c are in m (972 nm is 972e-9)"
            )
        if not self.a - abs(self.c) > STALL_RATIO * (self.a + abs(self.c)):
            raise NonPhysicalError(
                f"a - |c| = {(self.a - abs(self.c)) * 1e9:.4g} nm, not more than {STALL_RATIO:g} of a + |c|: "
                "the step would be <= 0 (or stall) "
                "when the axial load is "
                f"{'+1' if self.c > 0 else '-1'} (cos(zeta) cos(theta) = {'1' if self.c > 0 else '-1'})"
            )


@dataclass(frozen=True)
class RotaryParams:
    """Parameters of Eq. (8) for one direction of a rotary joint, at two extensions of q3.

    Attributes
    ----------
    gamma0 : tuple of float
        Step with no gravity torque at ``q3 = knots[0]`` and ``knots[1]``, rad.
    d : tuple of float
        Change of step per unit load at the same extensions, rad.
    knots : tuple of float
        The two q3 values (m) the parameters were calibrated at; default (0, 12 mm).
    """

    gamma0: tuple[float, float]
    d: tuple[float, float]
    knots: tuple[float, float] = field(default=(0.0, kin.Q3_MAX))

    kind = "rotary"

    def __post_init__(self) -> None:
        k = self.knots
        if (
            len(k) != 2
            or not all(isinstance(x, numbers.Real) and math.isfinite(x) and abs(x) <= _MAX_KNOT for x in k)
            or k[0] == k[1]
        ):
            raise ValueError(
                f"RotaryParams: knots = {k!r} must be two different q3 values in m within ±{_MAX_KNOT:g} m "
                f"(the paper's are 0 and {kin.Q3_MAX:g} m; 12 is 12 m, not 12 mm)"
            )

    def at(self, q3: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(gamma0, d)`` at extension ``q3`` (m), interpolated linearly."""
        return interp_q3(q3, self.knots, self.gamma0), interp_q3(q3, self.knots, self.d)

    def names(self) -> list[tuple[str, float | None]]:
        k0, k1 = self.knots
        return [("gamma0", k0), ("gamma0", k1), ("d", k0), ("d", k1)]

    def as_vector(self) -> NDArray[np.float64]:
        return np.array([self.gamma0[0], self.gamma0[1], self.d[0], self.d[1]])

    @classmethod
    def from_vector(cls, v: ArrayLike, knots: tuple[float, float] = (0.0, kin.Q3_MAX)) -> RotaryParams:
        g00, g01, d0, d1 = (float(x) for x in np.asarray(v, dtype=float))
        return cls((g00, g01), (d0, d1), knots)

    def check_physical(self, load_bound: float = 1.0) -> None:
        """Raise :class:`NonPhysicalError` unless the step is > 0 for every |load| <= ``load_bound``, and shorter
        than a rotary joint's whole range (a step in µrad given as a number of rad).

        ``gamma0 - |d|`` is concave in q3 between the knots, so checking the knots
        covers the whole stroke. "> 0" with a relative margin: more than :data:`STALL_RATIO` of
        ``gamma0 + |d|`` (a step zero to rounding is a stall, not a count of 1e15).
        """
        for k, g0, d in zip(self.knots, self.gamma0, self.d, strict=True):
            if not g0 + abs(d) * load_bound < kin.ROTARY_SPAN:  # 52 meant as µrad: every plan 1e-6 of its steps
                raise NonPhysicalError(
                    f"at q3 = {k * 1e3:g} mm, gamma0 + |d| = {g0 + abs(d) * load_bound:.4g} rad: a step longer than "
                    f"a rotary joint's whole range ({kin.ROTARY_SPAN:.4g} rad); gamma0 and d are in rad "
                    "(52 µrad is 52e-6)"
                )
            if not g0 - abs(d) * load_bound > STALL_RATIO * (abs(g0) + abs(d) * load_bound):
                raise NonPhysicalError(
                    f"at q3 = {k * 1e3:g} mm, gamma0 - |d| = {(g0 - abs(d) * load_bound) * 1e6:.4g} µrad, not more "
                    f"than {STALL_RATIO:g} of gamma0 + |d|: the step would be <= 0 (or stall) where the gravity "
                    "torque is largest"
                )


Params = PrismaticParams | RotaryParams


@dataclass(frozen=True)
class JointModel:
    """The step-size model of one joint in one direction.

    Attributes
    ----------
    joint : int
        1, 2 or 3.
    direction : str
        ``"+"`` or ``"-"``.
    params : PrismaticParams or RotaryParams
    """

    joint: int
    direction: str
    params: Params

    def __post_init__(self) -> None:
        _check_joint_model(self.joint, self.direction, self.params)

    def gamma(
        self, q1: ArrayLike, q2: ArrayLike, q3: ArrayLike, theta: ArrayLike, psi: ArrayLike
    ) -> NDArray[np.float64]:
        """Mean step size in a pose: m (joint 3) or rad (joints 1, 2), the paper's ``gamma``.

        ``q1``, ``q2`` rad, ``q3`` m, ``theta``, ``psi`` rad (array_like, broadcast). The moving
        joint's own column matters for rotary joints.
        """
        _check_pose_arrays("gamma", {"q1": q1, "q2": q2, "q3": q3, "theta": theta, "psi": psi})
        p = self.params
        if isinstance(p, PrismaticParams):
            return gamma_prismatic(q2, theta, psi, p.a, p.b, p.c, q1=q1)
        g0, d = p.at(q3)
        return gamma_rotary(kin.load_term(self.joint, q1, q2, q3, theta, psi), g0, d)

    def rotary_coefficients(
        self, q1: ArrayLike, q2: ArrayLike, q3: ArrayLike, theta: ArrayLike, psi: ArrayLike
    ) -> tuple[FloatArray, ...]:
        """``(A, alpha, beta)`` with ``gamma(q) = A + alpha cos q + beta sin q`` along the joint's travel.

        For the prismatic joint the step does not depend on q3, so ``alpha = beta = 0``
        and ``A`` is the step size.
        """
        p = self.params
        if isinstance(p, PrismaticParams):
            g = gamma_prismatic(q2, theta, psi, p.a, p.b, p.c, q1=q1)
            z = np.zeros_like(g)
            return g, z, z
        g0, d = p.at(q3)
        al, be = kin.rotary_load_coefficients(self.joint, q1, q2, q3, theta, psi)
        return tuple(np.broadcast_arrays(g0, d * al, d * be))

    def average_gamma(
        self,
        start: ArrayLike,
        end: ArrayLike,
        q1: ArrayLike,
        q2: ArrayLike,
        q3: ArrayLike,
        theta: ArrayLike,
        psi: ArrayLike,
    ) -> NDArray[np.float64]:
        """Average step over a traverse from ``start`` to ``end``: ``|end - start| / N`` (m or rad).

        ``start``, ``end``: the moving joint's coordinate (m for joint 3, rad otherwise); the pose
        ``q1``, ``q2`` rad, ``q3`` m, ``theta``, ``psi`` rad. Exact: ``N`` is the closed-form
        integral of ``1 / gamma`` along the traverse. The fixed joints are taken from ``q1, q2, q3``;
        the moving joint's column is ignored.
        """
        _check_pose_arrays("average_gamma", {"q1": q1, "q2": q2, "q3": q3, "theta": theta, "psi": psi,
                                             "start": start, "end": end}, self.joint)
        A, al, be = self.rotary_coefficients(q1, q2, q3, theta, psi)
        n = steps_between(start, end, A, al, be)
        out: NDArray[np.float64] = np.abs(np.asarray(end, dtype=float) - np.asarray(start, dtype=float)) / n
        return out


def _check_pose_arrays(what: str, values: dict[str, ArrayLike], joint: int = 0) -> None:
    """Refuse a pose no arm takes, element-wise (:func:`~stickslip.joints.coordinate_problem`, ``tilt_problem``):
    ``ValueError`` naming the first such value and its likely unit slip (``q2 = -90``, degrees, gave a step)."""
    for name, v in values.items():
        j = joint if name in ("start", "end") else _POSE_JOINT[name]
        bound = TILT_LIMIT if j == 0 else coordinate_bound(j)
        if type(v) is float and -bound <= v <= bound:  # a scalar within: no array made (nan is not)
            continue
        a = np.asarray(v, dtype=float)
        if a.size and -bound <= a.min() and a.max() <= bound:  # (a nan makes min and max nan: not within)
            continue
        bad = ~(np.abs(a) <= bound)
        if bad.any():
            x = float(a[bad].flat[0])
            problem = tilt_problem(name, x) if j == 0 else coordinate_problem(name, j, x)
            raise ValueError(f"JointModel.{what}: {problem}")


_POSE_JOINT = {"q1": 1, "q2": 2, "q3": 3, "theta": 0, "psi": 0}


def _check_joint_model(joint: object, direction: object, params: object) -> None:
    """Refuse a joint, direction or parameter kind that the model would use silently (a rotary joint's
    parameters on joint 3 gave a step in "m" from values in rad)."""
    if isinstance(joint, bool) or not isinstance(joint, numbers.Integral) or joint not in (1, 2, 3):
        raise ValueError(f"JointModel: joint = {joint!r} must be 1, 2 or 3")
    if direction not in DIRECTIONS or not isinstance(direction, str):
        raise ValueError(f"JointModel: direction = {direction!r} must be '+' or '-'")
    want = PrismaticParams if joint == 3 else RotaryParams
    if isinstance(params, PrismaticParams | RotaryParams) and not isinstance(params, want):
        raise ValueError(
            f"JointModel: joint {joint} takes {want.__name__} (its step in {'m' if joint == 3 else 'rad'}), "
            f"got {type(params).__name__}"
        )


# ---------------------------------------------------------------- traverse integrals


def _as_amp_phase(alpha: FloatArray, beta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``alpha cos q + beta sin q = B sin(q + phi)``: returns ``(B, phi)`` with B >= 0."""
    return np.hypot(alpha, beta), np.arctan2(alpha, beta)


def antiderivative_inverse_step(q: ArrayLike, A: ArrayLike, alpha: ArrayLike, beta: ArrayLike) -> NDArray[np.float64]:
    """A continuous antiderivative of ``1 / (A + alpha cos q + beta sin q)`` in ``q``.

    Valid where ``A > sqrt(alpha**2 + beta**2)`` (the step is positive on the whole
    circle). With ``x = q + phi`` and ``B sin x = alpha cos q + beta sin q``::

        F(x) = 2/s [ atan((A tan(x/2) + B) / s) + pi * round(x / (2 pi)) ],  s = sqrt(A^2 - B^2)

    The ``round`` term removes the jumps of ``tan(x/2)`` at odd multiples of pi, so
    ``F`` is continuous and increasing. For ``B -> 0`` it tends to ``q / A``.
    """
    q = np.asarray(q, dtype=float)
    A = np.asarray(A, dtype=float)
    B, phi = _as_amp_phase(np.asarray(alpha, dtype=float), np.asarray(beta, dtype=float))
    s = np.sqrt((A - B) * (A + B))
    x = q + phi
    k = np.round(x / (2.0 * np.pi))
    xr = x - 2.0 * np.pi * k  # in [-pi, pi]
    out: FloatArray = 2.0 / s * (np.arctan((A * np.tan(xr / 2.0) + B) / s) + np.pi * k)
    return out


def _antiderivative_log(q: FloatArray, A: FloatArray, alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """Antiderivative of ``1 / (A + B sin x)`` for ``B > A > 0`` (step positive only on part of the circle).

    ``F(x) = 1/s ln|(A tan(x/2) + B - s) / (A tan(x/2) + B + s)|``, ``s = sqrt(B^2 - A^2)``.
    It is continuous across ``x = pi`` (the ratio tends to 1 as ``tan(x/2) -> +-inf``)
    and valid on any interval where the step stays positive.
    """
    B, phi = _as_amp_phase(alpha, beta)
    s = np.sqrt((B - A) * (B + A))
    x = q + phi
    xr = x - 2.0 * np.pi * np.round(x / (2.0 * np.pi))
    t = np.tan(xr / 2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = A * t + B
        val = np.log(np.abs((u - s) / (u + s))) / s
    return np.where(np.isfinite(t), val, 0.0)


def sinusoid_range(
    lo: ArrayLike, hi: ArrayLike, alpha: ArrayLike, beta: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Minimum and maximum of ``alpha cos q + beta sin q`` for ``q`` in ``[lo, hi]`` (vectorised).

    The load term of a rotary joint along its travel has this form, so this gives the
    smallest and largest load (and, plus ``A``, the smallest and largest step) on a traverse.
    """
    lo, hi, alpha, beta = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (lo, hi, alpha, beta)))
    B, phi = _as_amp_phase(alpha, beta)
    f_lo = alpha * np.cos(lo) + beta * np.sin(lo)
    f_hi = alpha * np.cos(hi) + beta * np.sin(hi)
    mn, mx = np.minimum(f_lo, f_hi), np.maximum(f_lo, f_hi)
    # B sin(q + phi) has its minimum at q = -pi/2 - phi + 2 pi k and its maximum at pi/2 - phi + 2 pi k
    for target, is_max in ((-np.pi / 2, False), (np.pi / 2, True)):
        k = np.ceil((lo + phi - target) / (2 * np.pi))
        q = target - phi + 2 * np.pi * k
        inside = q <= hi
        if is_max:
            mx = np.where(inside, np.maximum(mx, B), mx)
        else:
            mn = np.where(inside, np.minimum(mn, -B), mn)
    return mn, mx


_TWO_PI = 2.0 * math.pi


class StepProfile:
    """The step size along a joint's travel, ``gamma(q) = A + alpha cos q + beta sin q``, for scalars.

    A pure-``math`` twin of :func:`steps_between` / :func:`position_after_steps` for hot
    paths (planning inside a 1 kHz loop): microseconds per call instead of numpy's
    per-call overhead. ``A`` in m or rad; ``alpha``, ``beta`` in the same unit.
    """

    __slots__ = ("A", "alpha", "beta", "B", "phi", "s", "kind")

    def __init__(self, A: float, alpha: float = 0.0, beta: float = 0.0):
        self.A, self.alpha, self.beta = float(A), float(alpha), float(beta)
        if not (math.isfinite(self.A) and math.isfinite(self.alpha) and math.isfinite(self.beta)):
            _check_finite(A=self.A, alpha=self.alpha, beta=self.beta)
        self.B = math.hypot(alpha, beta)
        self.phi = math.atan2(alpha, beta)
        if self.B <= 1e-13 * abs(self.A):
            self.kind, self.s = "const", 0.0  # no variation along the travel (to double precision)
        elif self.A > self.B * (1.0 + 1e-12):
            self.kind, self.s = "atan", math.sqrt((self.A - self.B) * (self.A + self.B))
        else:
            self.kind, self.s = "other", 0.0

    def gamma(self, q: float) -> float:
        """Mean step size at ``q`` (``A``'s unit: m or rad; ``q`` rad, or m where the step is constant)."""
        return self.A + self.alpha * math.cos(q) + self.beta * math.sin(q)

    def F(self, q: float) -> float:
        """The arctangent antiderivative of ``1 / gamma`` (see :func:`antiderivative_inverse_step`)."""
        x = q + self.phi
        k = round(x / _TWO_PI)
        xr = x - _TWO_PI * k
        return 2.0 / self.s * (math.atan((self.A * math.tan(0.5 * xr) + self.B) / self.s) + math.pi * k)

    def steps(self, q0: float, q1: float) -> float:
        """Real-valued number of steps from ``q0`` to ``q1`` (>= 0)."""
        if not (math.isfinite(q0) and math.isfinite(q1)):  # nan steps (or inf) for a position
            _check_finite(start=q0, end=q1)
        if self.kind == "const":
            if not self.A > 0:
                raise NonPhysicalError(f"step size {self.A:.3g} <= 0: the joint cannot move")
            return abs(q1 - q0) / self.A
        if self.kind == "atan":
            return abs(self.F(q1) - self.F(q0))
        return float(_steps_between_arrays(q0, q1, self.A, self.alpha, self.beta))

    def inverse(self, q0: float, n: float, sign: int) -> float:
        """Dead reckoning: solve ``sign (F(q) - F(q0)) = n`` for ``q`` (safeguarded Newton, ``F' = 1/gamma``).

        ``n`` >= 0 steps, ``sign`` +1 or -1 (a sign of 5 went 5 times as far, n < 0 backwards).
        """
        if sign not in (1, -1) or not (n >= 0.0 and math.isfinite(n) and math.isfinite(q0)):
            _check_steps(q0, n, sign)
        if self.kind == "const":
            if not self.A > 0:  # (steps refuses the same; a negative step would dead-reckon backwards)
                raise NonPhysicalError(f"step size {self.A:.3g} <= 0: the joint cannot move")
            return q0 + sign * n * self.A
        if self.kind != "atan":
            return position_after_steps(q0, n, sign, self.A, self.alpha, self.beta)
        F0 = self.F(q0)
        lo_q = q0 + sign * n * (self.A - self.B)  # between n smallest and n largest steps away
        hi_q = q0 + sign * n * (self.A + self.B)
        lo, hi = min(lo_q, hi_q), max(lo_q, hi_q)
        q = min(max(q0 + sign * n * self.gamma(q0), lo), hi)
        tol = 1e-13 * max(1.0, abs(q))
        for _ in range(100):
            r = sign * (self.F(q) - F0) - n  # increasing in sign * q
            if r == 0.0:
                return q
            if sign * r > 0:
                hi = q
            else:
                lo = q
            q_new = q - sign * r * self.gamma(q)
            if not lo < q_new < hi:
                q_new = 0.5 * (lo + hi)
            if abs(q_new - q) <= tol:
                return q_new
            q = q_new
        return q


def _check_finite(**values: float) -> None:
    """ValueError naming the first argument that is not a finite number (a nan gave nan steps, silently)."""
    for name, v in values.items():
        if not math.isfinite(v):
            raise ValueError(f"{name} = {v!r} must be a finite number (m or rad)")


def _check_steps(start: float, n_steps: float, sign: object) -> None:
    """ValueError for a dead reckoning that is not ``n_steps >= 0`` steps from a finite ``start`` in ``sign``."""
    if sign not in (1, -1):
        raise ValueError(f"sign = {sign!r} must be +1 or -1")
    if not (n_steps >= 0.0 and math.isfinite(n_steps)):
        raise ValueError(f"n_steps = {n_steps!r} must be a finite number >= 0 (the direction gives the sign)")
    _check_finite(start=start)


def steps_between(
    start: ArrayLike,
    end: ArrayLike,
    A: ArrayLike,
    alpha: ArrayLike = 0.0,
    beta: ArrayLike = 0.0,
) -> NDArray[np.float64]:
    """Number of steps (real-valued) to travel from ``start`` to ``end``: ``|integral dq / gamma(q)|``.

    ``gamma(q) = A + alpha cos q + beta sin q`` (m or rad), exact in closed form: the
    arctangent antiderivative where the step is positive on the whole circle
    (``A > sqrt(alpha^2 + beta^2)``), the logarithmic one where it is positive only
    along the traverse. Raises :class:`NonPhysicalError` if the step is <= 0
    somewhere on the way (the joint would stall). Agrees with adaptive quadrature
    (:func:`steps_between_quad`) to ~1e-12 relative. Scalars take a pure-``math`` path. A value
    that is not finite raises ``ValueError`` naming it (it gave nan steps).
    """
    if (
        isinstance(start, float | int)
        and isinstance(end, float | int)
        and isinstance(A, float | int)
        and isinstance(alpha, float | int)
        and isinstance(beta, float | int)
    ):
        n = StepProfile(float(A), float(alpha), float(beta)).steps(float(start), float(end))
        if not math.isfinite(n):  # (the arrays' path refuses the same)
            raise NonPhysicalError(f"{n} steps from {start!r} to {end!r} with a step of {A!r}: no count a float holds")
        return np.asarray(n)
    return _steps_between_arrays(start, end, A, alpha, beta)


def _steps_between_arrays(
    start: ArrayLike, end: ArrayLike, A: ArrayLike, alpha: ArrayLike, beta: ArrayLike
) -> NDArray[np.float64]:
    start, end, A, alpha, beta = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (start, end, A, alpha, beta))
    )
    for name, x in (("start", start), ("end", end), ("A", A), ("alpha", alpha), ("beta", beta)):
        if not np.all(np.isfinite(x)):
            bad = x[~np.isfinite(x)].ravel()[0]
            raise ValueError(f"{name} holds {bad!r}: it must be finite (m or rad)")
    B = np.hypot(alpha, beta)
    out = np.empty(start.shape, dtype=float)
    closed = A > B * (1.0 + 1e-12)
    if np.any(closed):
        sl = closed
        Fa = antiderivative_inverse_step(start[sl], A[sl], alpha[sl], beta[sl])
        Fb = antiderivative_inverse_step(end[sl], A[sl], alpha[sl], beta[sl])
        out[sl] = np.abs(Fb - Fa)
    rest = ~closed
    if np.any(rest):
        lo, hi = np.minimum(start, end)[rest], np.maximum(start, end)[rest]
        a, al, be = A[rest], alpha[rest], beta[rest]
        if np.any(a + sinusoid_range(lo, hi, al, be)[0] <= 0.0):
            raise NonPhysicalError("the step size reaches zero along the traverse: the joint would stall there")
        logform = (B[rest] > a * (1.0 + 1e-12)) & (a > 0)
        vals = np.empty(lo.shape)
        if np.any(logform):
            f = logform
            vals[f] = np.abs(
                _antiderivative_log(hi[f], a[f], al[f], be[f]) - _antiderivative_log(lo[f], a[f], al[f], be[f])
            )
        for i in np.nonzero(~logform)[0]:  # A == B to 1e-12: rare; quadrature
            vals[i] = steps_between_quad(float(lo[i]), float(hi[i]), float(a[i]), float(al[i]), float(be[i]))
        out[rest] = vals
    out[start == end] = 0.0  # no travel: the log form gave -inf - -inf = nan where the step is near zero there
    if not np.all(np.isfinite(out)):  # a step within rounding of zero on the way (1e-179 rad beside 1): a stall
        raise NonPhysicalError("the step size comes within rounding of zero along the traverse (or the count "
                               "overflows): the joint would stall")
    return out


def steps_between_quad(start: float, end: float, A: float, alpha: float = 0.0, beta: float = 0.0) -> float:
    """Same as :func:`steps_between` by adaptive Gauss–Kronrod quadrature (scipy.integrate.quad).

    Relative tolerance 1e-12. Raises :class:`NonPhysicalError` where the step is
    <= 0 on the way.
    """
    from scipy import integrate

    lo, hi = min(start, end), max(start, end)
    if A + float(sinusoid_range(lo, hi, alpha, beta)[0]) <= 0.0:
        raise NonPhysicalError(f"the step size reaches zero between {lo:.6g} and {hi:.6g}: the joint would stall there")
    val, _err = integrate.quad(
        lambda q: 1.0 / (A + alpha * math.cos(q) + beta * math.sin(q)), lo, hi, epsabs=0.0, epsrel=1e-12, limit=200
    )
    return float(val)


def iter_traverse_steps(
    start: float, end: float, gamma: Callable[[float], float], max_steps: int = 10_000_000
) -> Iterator[tuple[float, float]]:
    """The paper's step-by-step simulation of a traverse (its Fig. 8): yields ``(q, gamma(q))`` per step.

    Starting at ``start``, each step moves towards ``end`` by ``gamma(q)`` evaluated
    where the step begins, until ``end`` is reached or passed. With ``gamma`` the mean
    step of Eq. (8), ``gamma(q) = A + alpha cos q + beta sin q``
    (:meth:`StepProfile.gamma`), this is the simulation behind the paper's Fig. 8 and
    its Eq. 9 method. This is the one step-by-step loop of stickslip: the count
    (:func:`simulate_traverse_steps`), the Eq. 9 comparator and the report's Fig. 8
    all iterate it.

    Parameters
    ----------
    start, end : float
        The traversed interval, m or rad.
    gamma : callable
        Mean step size at a position, m or rad; must stay > 0.
    max_steps : int
        Refuse to go on after this many steps (a step size too small to finish).

    Yields
    ------
    (q, g) : tuple of float
        The position before the step and the step size, m or rad.
    """
    sign = 1.0 if end >= start else -1.0
    q, n = float(start), 0
    while (end - q) * sign > 0.0:
        g = gamma(q)
        if not g > 0.0:
            raise NonPhysicalError(f"step size {g!r} <= 0 at q = {q:.6g}: the joint stalls")
        yield q, g
        q += sign * g
        n += 1
        if n >= max_steps:
            raise RuntimeError(f"more than {max_steps} steps: step size too small")


def simulate_traverse_steps(
    start: float, end: float, gamma: Callable[[float], float], max_steps: int = 10_000_000
) -> int:
    """Count discrete steps from ``start`` until ``end`` is reached or passed.

    The count of :func:`iter_traverse_steps` (the paper's Fig. 8 simulation):
    each step moves by ``gamma(q)`` evaluated where the step begins. ``gamma`` returns
    a positive step size (m or rad).
    """
    n = 0
    for _ in iter_traverse_steps(start, end, gamma, max_steps):
        n += 1
    return n


def position_after_steps(
    start: float, n_steps: float, direction: int, A: float, alpha: float = 0.0, beta: float = 0.0
) -> float:
    """Dead reckoning: where a joint ends after ``n_steps`` steps from ``start`` in ``direction``.

    Solves ``integral_start^q dq / gamma = n_steps`` for ``q`` (monotone, so a bracketed
    root find on the closed form). ``gamma(q) = A + alpha cos q + beta sin q`` > 0; ``start``,
    ``A``, ``alpha``, ``beta`` in m (joint 3) or rad; ``n_steps`` >= 0 (``direction`` gives the
    sign: ``"+"``/``"-"`` or +1/-1). A value that is not finite raises ``ValueError``.
    """
    start, n_steps, A, alpha, beta = (float(x) for x in (start, n_steps, A, alpha, beta))
    direction = direction_sign(direction)
    _check_steps(start, n_steps, direction)
    _check_finite(A=A, alpha=alpha, beta=beta)
    if n_steps == 0:
        return start
    B = math.hypot(alpha, beta)
    if B <= 1e-13 * abs(A):  # no load variation along the way (to double precision)
        if not A > 0:  # a negative step would dead-reckon backwards
            raise NonPhysicalError(f"step size {A:.3g} <= 0: the joint cannot move")
        return float(start + direction * n_steps * A)
    from scipy.optimize import brentq

    if not A > B:
        raise NonPhysicalError("dead reckoning needs a step size that is positive on the whole circle")
    F0 = float(antiderivative_inverse_step(start, A, alpha, beta))

    def f(q: float) -> float:
        return direction * (float(antiderivative_inverse_step(q, A, alpha, beta)) - F0) - n_steps

    lo_step, hi_step = A - B, A + B
    # the answer lies between n * min step and n * max step away
    a = start + direction * n_steps * lo_step
    b = start + direction * n_steps * hi_step
    pad = 1e-9 * abs(b - start) + 1e-300
    lo, hi = min(a, b) - pad, max(a, b) + pad
    return float(brentq(f, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200))
