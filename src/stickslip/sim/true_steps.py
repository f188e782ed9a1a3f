"""The simulated MM3A's true steps: the day's drifted models, the ripple, the noise, the end stops.

Every step is drawn around the true mean with multiplicative lognormal noise; the mean
carries a small smooth ripple along the travel and is evaluated at the moving joint's
current position at every step (see :mod:`stickslip.sim.arm`). A burst is simulated at
once with numpy (chunked fixed-point iteration of the step positions).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..calibration.result import Parameter
from ..devices.base import DeviceError
from ..models import DIRECTIONS, JointModel, PrismaticParams, direction_sign

__all__ = ["RIPPLE", "TrueSteps", "joint_number"]

RIPPLE = 0.004
"""Relative amplitude of the smooth position-dependent ripple of the true mean step."""

_RIPPLE_PERIODS = {1: 7, 2: 7, 3: 5}
_CHUNK = 4096


def joint_number(joint: int) -> int:
    """``joint`` as 1, 2 or 3; ``ValueError`` naming the joints otherwise (a float must be whole)."""
    try:
        j = int(joint)
    except (TypeError, ValueError):
        j = -1
    if j not in (1, 2, 3) or (isinstance(joint, float) and not float(joint).is_integer()):
        raise ValueError(f"unknown joint {joint!r}: joints are 1, 2 (rotary) and 3 (prismatic)")
    return j


class TrueSteps:
    """The arm's true step physics and the truth it tells: models, parameters, the mean step, a burst.

    The attributes are set by :class:`~stickslip.sim.arm.SimulatedMM3A` (the day's models,
    the ripple's phases, the noise's generator and spread, the pose).
    """

    _models: dict[tuple[int, str], JointModel]
    _ripple_phase: dict[int, float]
    _rng: np.random.Generator
    _sigma: float
    _q: dict[int, float]
    _theta: float
    _psi: float

    _joint = staticmethod(joint_number)

    @property
    def pose(self) -> kin.Pose:
        """The current true pose (joints rad, rad, m; tilt rad)."""
        return kin.Pose(self._q[1], self._q[2], self._q[3], self._theta, self._psi)

    def true_models(self) -> dict[tuple[int, str], JointModel]:
        """The day's true mean-step models, ``{(joint, direction): JointModel}`` (SI)."""
        return dict(self._models)

    def true_parameters(self) -> list[Parameter]:
        """The day's true parameters, as :meth:`Calibration.parameters` gives calibrated ones.

        ``stderr`` is ``None``; values are SI (m, 1, rad).
        """
        out: list[Parameter] = []
        for joint in (3, 2, 1):
            for direction in DIRECTIONS:
                p = self._models[(joint, direction)].params
                if isinstance(p, PrismaticParams):
                    for name, value, unit in (("a", p.a, "m"), ("b", p.b, "1"), ("c", p.c, "m")):
                        out.append(Parameter(joint, direction, name, None, float(value), None, unit))
                else:
                    for name, values in (("gamma0", p.gamma0), ("d", p.d)):
                        for k, value in zip(p.knots, values, strict=True):
                            out.append(Parameter(joint, direction, name, float(k), float(value), None, "rad"))
        return out

    def true_mean_step(
        self, joint: int, direction: str | int, q: float | NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """The true mean step (m or rad) of ``joint`` in ``direction`` at position ``q``.

        Includes the ripple (what a single step averages to); the other joints and the
        tilt are the current pose.
        """
        joint = self._joint(joint)
        sign = direction_sign(direction)
        A, al, be = self._coefficients(joint, sign)
        qq = self._q[joint] if q is None else q
        return self._mean_step(joint, np.asarray(qq, dtype=float), A, al, be)

    def _coefficients(self, joint: int, sign: int) -> tuple[float, float, float]:
        """``(A, alpha, beta)``: model step along the travel ``A + alpha cos q + beta sin q``."""
        model = self._models[(joint, "+" if sign > 0 else "-")]
        q1, q2, q3, theta, psi = self.pose
        A, al, be = model.rotary_coefficients(q1, q2, q3, theta, psi)
        return float(A), float(al), float(be)

    def _mean_step(
        self, joint: int, q: NDArray[np.float64], A: float, al: float, be: float
    ) -> NDArray[np.float64]:
        spec = kin.JOINTS[joint]
        base = A if (al == 0.0 and be == 0.0) else A + al * np.cos(q) + be * np.sin(q)
        phase = 2.0 * math.pi * _RIPPLE_PERIODS[joint] * (q - spec.lower) / spec.span + self._ripple_phase[joint]
        return base * (1.0 + RIPPLE * np.sin(phase))

    def _advance(self, joint: int, sign: int, n: int) -> tuple[int, float]:
        """Simulate ``n`` steps of ``joint`` in direction ``sign``; returns ``(k_stop, q_end)``.

        ``k_stop`` is the index of the first step that began at the end stop (``n``
        if none did). Step positions within a chunk are found by fixed-point
        iteration of ``p_k = q + sign * sum_{j<k} gamma(p_j) eps_j`` (converges to
        1e-12 of the span in a few rounds, since gamma changes slowly).
        """
        spec = kin.JOINTS[joint]
        stop = spec.upper if sign > 0 else spec.lower
        q = self._q[joint]
        if sign * (stop - q) <= 0.0:
            return 0, stop
        A, al, be = self._coefficients(joint, sign)
        if not A - math.hypot(al, be) > 0.0:
            raise DeviceError(f"the true step of joint {joint} would be <= 0 in this pose")
        tol = 1e-12 * spec.span
        done = 0
        while done < n:
            m = min(_CHUNK, n - done)
            eps = np.exp(self._sigma * self._rng.standard_normal(m) - 0.5 * self._sigma**2)
            p = np.full(m, q)
            for _ in range(12):
                sizes = self._mean_step(joint, p, A, al, be) * eps
                csum = np.cumsum(sizes)
                p_new = q + sign * np.concatenate(([0.0], csum[:-1]))
                change = float(np.max(np.abs(p_new - p)))
                p = p_new
                if change <= tol:
                    break
            sizes = self._mean_step(joint, p, A, al, be) * eps
            ends = p + sign * sizes
            hit = np.nonzero(sign * (ends - stop) >= 0.0)[0]
            if hit.size:
                return done + int(hit[0]) + 1, stop
            q = float(ends[-1])
            done += m
        return n, q

