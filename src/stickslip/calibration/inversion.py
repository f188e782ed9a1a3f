"""Joint 2 from averages: the exact inversion of the averaged rotary relation for ``d``,
and the paper's Eq. 9 simulate-and-fit method kept as a comparator (design.md §4)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..models import (
    NonPhysicalError,
    StepProfile,
    simulate_traverse_steps,
    sinusoid_range,
    steps_between,
)
from .result import CalibrationError

_LOAD_ZERO = 1e-6  # a load coefficient below this counts as "no gravity torque"


# ----------------------------------------------------------------------------- exact inversion


def _load_range(start: float, end: float, alpha: float, beta: float) -> tuple[float, float]:
    """Min and max of the load ``alpha cos q + beta sin q`` for q between start and end."""
    mn, mx = sinusoid_range(min(start, end), max(start, end), alpha, beta)
    return float(mn), float(mx)


def invert_d_exact(
    gamma_measured: float,
    gamma0: float,
    start: float,
    end: float,
    alpha: float,
    beta: float,
) -> float:
    """Solve the paper's Eq. 8 for ``d`` from an average step over a traverse, exactly.

    Finds ``d`` such that ``|end - start| / integral dq / (gamma0 + d (alpha cos q +
    beta sin q)) = gamma_measured``. The step count is convex in ``d``; the physical
    root lies on the branch that contains ``d = 0``, between the ``d`` at which the
    step first reaches zero on the way and the ``d`` of the largest reachable
    average. Solved by Brent's method on a bracket, to ~1e-15 rad.

    Parameters
    ----------
    gamma_measured : float
        Average step measured over the traverse, rad.
    gamma0 : float
        Step with no gravity torque at the same q3, rad.
    start, end : float
        The traversed interval of the joint, rad.
    alpha, beta : float
        Load coefficients along the traverse (:func:`stickslip.kinematics.rotary_load_coefficients`).

    Returns
    -------
    float
        ``d``, rad.
    """
    from scipy.optimize import brentq, minimize_scalar

    if not (gamma_measured > 0 and gamma0 > 0):
        raise CalibrationError(f"step sizes must be positive (measured {gamma_measured:.4g}, gamma0 {gamma0:.4g})")
    lmin, lmax = _load_range(start, end, alpha, beta)
    if max(abs(lmin), abs(lmax)) < _LOAD_ZERO:
        raise CalibrationError("the traverse has no gravity torque along it: d cannot be determined from it")
    span = abs(end - start)

    def avg(d: float) -> float:
        return span / float(steps_between(start, end, gamma0, d * alpha, d * beta))

    # d-domain where the step stays > 0 along the traverse
    d_lo = -gamma0 / lmax if lmax > 0 else -math.inf
    d_hi = gamma0 / (-lmin) if lmin < 0 else math.inf
    shrink = 1e-7
    lo = d_lo * (1 - shrink) if math.isfinite(d_lo) else -50 * gamma0
    hi = d_hi * (1 - shrink) if math.isfinite(d_hi) else 50 * gamma0
    # The step count is convex in d, so the average has a single maximum at d_peak.
    # The physical root lies on the side of d_peak that contains d = 0 (no load effect).
    res = minimize_scalar(lambda d: -avg(d), bounds=(lo, hi), method="bounded", options={"xatol": 1e-9 * gamma0})
    d_peak = float(res.x)
    g_peak = avg(d_peak)
    if gamma_measured >= g_peak:
        if gamma_measured > g_peak * (1 + 1e-9):
            raise CalibrationError(
                f"measured average {gamma_measured * 1e6:.4g} µrad is larger than any d can give with "
                f"gamma0 = {gamma0 * 1e6:.4g} µrad (at most {g_peak * 1e6:.4g} µrad): check the traverse and gamma0"
            )
        return d_peak
    a, b = (lo, d_peak) if d_peak >= 0.0 else (d_peak, hi)
    if (avg(a) - gamma_measured) * (avg(b) - gamma_measured) > 0:
        raise CalibrationError(
            f"measured average {gamma_measured * 1e6:.4g} µrad cannot be reached with gamma0 = "
            f"{gamma0 * 1e6:.4g} µrad: the joint would stall on the way"
        )
    return float(brentq(lambda d: avg(d) - gamma_measured, a, b, xtol=1e-18, rtol=1e-14, maxiter=500))


def invert_d_exact_many(
    gamma_measured: NDArray[np.float64],
    gamma0: float,
    start: float,
    end: float,
    alpha: float,
    beta: float,
) -> NDArray[np.float64]:
    """:func:`invert_d_exact` for many averages measured over the same traverse and pose, at once.

    The traverse's bracket (the ``d`` domain where the step stays positive and the
    ``d`` of the largest reachable average) depends only on the pose and ``gamma0``, so
    it is found once; every average is then solved by bisection on that bracket, all
    together with numpy, to 1e-18 rad or 1e-14 relative (as :func:`invert_d_exact`'s
    Brent solve). The same refusals: the first average that cannot be inverted raises
    :func:`invert_d_exact`'s own error for it.
    """
    from scipy.optimize import minimize_scalar

    g = np.asarray(gamma_measured, dtype=float).reshape(-1)
    if g.size == 0:
        return np.zeros(0)
    if not (np.all(g > 0) and gamma0 > 0):
        first = int(np.flatnonzero(~(g > 0))[0]) if not np.all(g > 0) else 0
        return np.array([invert_d_exact(float(g[first]), gamma0, start, end, alpha, beta)])  # raises
    lmin, lmax = _load_range(start, end, alpha, beta)
    if max(abs(lmin), abs(lmax)) < _LOAD_ZERO:
        return np.array([invert_d_exact(float(g[0]), gamma0, start, end, alpha, beta)])  # raises
    span = abs(end - start)

    def avg(d: NDArray[np.float64] | float) -> NDArray[np.float64]:
        d = np.asarray(d, dtype=float)
        return np.asarray(span / steps_between(start, end, gamma0, d * alpha, d * beta), dtype=float)

    d_lo = -gamma0 / lmax if lmax > 0 else -math.inf
    d_hi = gamma0 / (-lmin) if lmin < 0 else math.inf
    shrink = 1e-7
    lo = d_lo * (1 - shrink) if math.isfinite(d_lo) else -50 * gamma0
    hi = d_hi * (1 - shrink) if math.isfinite(d_hi) else 50 * gamma0
    res = minimize_scalar(
        lambda d: -float(avg(d)), bounds=(lo, hi), method="bounded", options={"xatol": 1e-9 * gamma0}
    )
    d_peak = float(res.x)
    g_peak = float(avg(d_peak))
    a, b = (lo, d_peak) if d_peak >= 0.0 else (d_peak, hi)
    fa, fb = float(avg(a)), float(avg(b))
    at_peak = g >= g_peak
    unreachable = (at_peak & (g > g_peak * (1 + 1e-9))) | (~at_peak & ((fa - g) * (fb - g) > 0))
    if unreachable.any():
        first = int(np.flatnonzero(unreachable)[0])
        return np.array([invert_d_exact(float(g[first]), gamma0, start, end, alpha, beta)])  # raises
    # bisection on [a, b], where avg - g changes sign; which end is below depends on the branch
    rising = fb > fa
    left = np.full(g.size, a)
    right = np.full(g.size, b)
    for _ in range(200):
        mid = 0.5 * (left + right)
        above = avg(mid) > g
        go_left = above if rising else ~above
        right = np.where(go_left, mid, right)
        left = np.where(go_left, left, mid)
        if np.all(right - left <= 1e-18 + 1e-14 * np.abs(mid)):
            break
    d = 0.5 * (left + right)
    return np.where(at_peak, d_peak, d)


# ----------------------------------------------------------------------------- Eq. 9 comparator

EQ9_PRINTED = (3.41, 0.025, 6.42e-7)
"""Eq. 9 as printed in the paper: ``d = 3.41 D^2 + 0.025 D + 6.42e-7`` (SI, rad)."""


def eq9_printed(delta: float | NDArray[np.float64]) -> NDArray[np.float64]:
    """Eq. 9 exactly as printed (rad in, rad out). Kept to show it is inconsistent with Fig. 10."""
    p2, p1, p0 = EQ9_PRINTED
    delta = np.asarray(delta, dtype=float)
    return p2 * delta**2 + p1 * delta + p0


@dataclass(frozen=True)
class PaperQuadratic:
    """The paper's simulate-and-fit relation ``d = p2 D^2 + p1 D + p0`` (its Eq. 9 method).

    Attributes
    ----------
    coefficients : tuple of float
        ``(p2, p1, p0)`` in SI: ``p2`` in 1/rad, ``p1`` dimensionless, ``p0`` in rad.
    grid : dict
        The simulated grid: arrays ``gamma0``, ``d``, ``delta`` (rad).
    """

    coefficients: tuple[float, float, float]
    grid: dict[str, NDArray[np.float64]] = field(repr=False)

    def d(self, delta: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """``d`` (rad) from ``D = gamma(theta=0) - gamma0`` (rad)."""
        p2, p1, p0 = self.coefficients
        delta = np.asarray(delta, dtype=float)
        return p2 * delta**2 + p1 * delta + p0


def _simulate_full_range_averages(
    gamma0: NDArray[np.float64], d: NDArray[np.float64], start: float, end: float, alpha: float, beta: float
) -> NDArray[np.float64]:
    """Step-by-step simulation of each (gamma0, d) pair (the paper's Fig. 8 simulation).

    Each average is ``|end - start| / N`` with ``N`` from
    :func:`stickslip.models.simulate_traverse_steps` on Eq. (8),
    ``gamma(q) = gamma0 + d (alpha cos q + beta sin q)``.
    """
    out = np.empty(len(gamma0))
    for i, (g0, dd) in enumerate(zip(gamma0.tolist(), d.tolist(), strict=True)):
        try:
            n = simulate_traverse_steps(start, end, StepProfile(g0, dd * alpha, dd * beta).gamma)
        except NonPhysicalError:
            raise NonPhysicalError("a simulated step size is <= 0: shrink the grid") from None
        out[i] = abs(end - start) / n
    return out


def fit_paper_quadratic(
    gamma0_values: Sequence[float] = tuple(np.linspace(20e-6, 100e-6, 5)),
    delta_range: float = 9.2e-6,
    n_d: int = 9,
    start: float = kin.JOINTS[2].upper,
    end: float = kin.JOINTS[2].lower,
    alpha: float = 0.0,
    beta: float = -1.0,
    simulate: str = "exact",
) -> PaperQuadratic:
    """Reproduce the paper's Eq. 9 method: simulate a grid of ``(gamma0, d)``, fit a quadratic.

    For each ``gamma0`` the ``d`` grid is chosen so that ``D = gamma(theta=0) - gamma0``
    spans about ``±delta_range`` (the paper used ±9.2 µrad). Averages come from a
    step-by-step simulation (``simulate="steps"``, as the paper did; seconds) or from the
    exact integral (``"exact"``, the default; the two differ by less than one step in
    ~10^5). The default traverse is joint 2 over its full range at
    ``theta = psi = 0`` (load ``-sin q2``).

    Returns
    -------
    PaperQuadratic
    """
    g0s, ds = [], []
    # first-order slope: D ≈ d * mean load along the traverse
    qs = np.linspace(min(start, end), max(start, end), 2001)
    mload = float(np.mean(alpha * np.cos(qs) + beta * np.sin(qs)))
    lmin, lmax = _load_range(start, end, alpha, beta)
    for g0 in gamma0_values:
        dmax = delta_range / abs(mload)
        # keep every simulated step >= 10 % of gamma0 along the traverse
        d_lo = max(-dmax, -0.9 * g0 / lmax) if lmax > 0 else -dmax
        d_hi = min(dmax, 0.9 * g0 / -lmin) if lmin < 0 else dmax
        for d in np.linspace(d_lo, d_hi, n_d):
            g0s.append(g0)
            ds.append(d)
    g0a, da = np.array(g0s), np.array(ds)
    if simulate == "steps":
        avg = _simulate_full_range_averages(g0a, da, start, end, alpha, beta)
    elif simulate == "exact":
        avg = abs(end - start) / steps_between(start, end, g0a, da * alpha, da * beta)
    else:
        raise ValueError(f"simulate must be 'steps' or 'exact', got {simulate!r}")
    # keep the physical branch only: for each gamma0 the average must still rise with d
    keep = np.ones(len(g0a), dtype=bool)
    for g0 in np.unique(g0a):
        idx = np.nonzero(g0a == g0)[0]
        falling = np.nonzero(np.diff(avg[idx]) <= 0)[0]
        if len(falling):
            keep[idx[falling[0] + 1 :]] = False
    g0a, da, avg = g0a[keep], da[keep], avg[keep]
    delta = avg - g0a
    p2, p1, p0 = np.polyfit(delta, da, 2)
    return PaperQuadratic((float(p2), float(p1), float(p0)), {"gamma0": g0a, "d": da, "delta": delta})


