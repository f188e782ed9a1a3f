"""Fig. 9 after the paper: d against D = γ(θ = 0) − γ0 for a full-range traverse of joint 2.

The exact relation (:func:`stickslip.calibration.invert_d_exact`'s forward map), the
paper's simulate-and-fit quadratic (:func:`stickslip.calibration.fit_paper_quadratic`)
and its Eq. 9 as printed (:func:`stickslip.calibration.eq9_printed`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..calibration import eq9_printed, fit_paper_quadratic
from ..models import RotaryParams, steps_between
from ..plotting import pyplot
from ._units import step_scale

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

    from ..calibration import Calibration

__all__ = ["PAPER_DELTA_RANGE", "CalibratedPoint", "DRelation", "d_relation_data"]

PAPER_DELTA_RANGE = 9.2e-6
"""The range of ``gamma(theta=0) - gamma0`` the paper observed, ±9.2 µrad (its Section 3.5), rad."""


@dataclass(frozen=True)
class CalibratedPoint:
    """The calibration's own ``(D, d)`` for one direction and q3 (rad; q3 in m)."""

    direction: str
    q3: float
    delta: float
    d: float
    d_quadratic: float


@dataclass(frozen=True)
class DRelation:
    """The paper's Fig. 9: ``d`` against ``D = gamma(theta=0) - gamma0`` (all rad).

    Attributes
    ----------
    delta : ndarray
        Grid of ``D`` (rad), ±9.2 µrad as in the paper.
    gamma0 : ndarray
        ``gamma0`` values of the exact curves (rad).
    d_exact : ndarray
        ``(len(gamma0), len(delta))`` exact inversions (rad); NaN beyond the largest
        average a ``gamma0`` can give.
    d_quadratic : ndarray
        The paper's method (simulate, fit a quadratic) on the same grid (rad).
    quadratic : tuple
        Its coefficients ``(p2, p1, p0)`` (SI).
    d_printed : ndarray
        Eq. 9 as printed (rad).
    calibrated : list of CalibratedPoint
    """

    delta: NDArray[np.float64]
    gamma0: NDArray[np.float64]
    d_exact: NDArray[np.float64]
    d_quadratic: NDArray[np.float64]
    quadratic: tuple[float, float, float]
    d_printed: NDArray[np.float64]
    calibrated: list[CalibratedPoint] = field(default_factory=list)

    def quadratic_error_by_gamma0(self) -> NDArray[np.float64]:
        """Largest ``|d_quadratic - d_exact|`` over the D grid, per ``gamma0`` (rad)."""
        return np.asarray(np.nanmax(np.abs(self.d_quadratic[None, :] - self.d_exact), axis=1), dtype=float)

    @property
    def max_quadratic_error(self) -> float:
        """Largest ``|d_quadratic - d_exact|`` over the grid and every ``gamma0`` (rad)."""
        return float(np.nanmax(np.abs(self.d_quadratic[None, :] - self.d_exact)))

    def error_text(self) -> str:
        """``"at most 0.12 µrad at γ0 = 20 µrad, …"``: the quadratic's error in words."""
        k, unit = step_scale(2)
        errs = self.quadratic_error_by_gamma0()
        parts = [f"{e * k:.2f} {unit} at γ0 = {g * k:.0f} {unit}" for g, e in zip(self.gamma0, errs, strict=True)]
        return "at most " + ", ".join(parts) + " from the exact relation"

    def plot(self, ax: Axes | None = None) -> Axes:
        """One panel: d (µrad) against D (µrad); returns the Axes."""
        if ax is None:
            _fig, ax = pyplot().subplots(figsize=(7.5, 5.0), constrained_layout=True)
        k, unit = step_scale(2)
        cmap = pyplot().get_cmap("viridis")
        for i, g0 in enumerate(self.gamma0):
            c = cmap(i / max(1, len(self.gamma0) - 1))
            ax.plot(self.delta * k, self.d_exact[i] * k, "-", color=c, lw=1.2, label=f"exact, γ0 = {g0 * k:.0f} {unit}")
        ax.plot(
            self.delta * k,
            self.d_quadratic * k,
            "k--",
            lw=1.5,
            label=f"paper's method: quadratic fit to simulations (max error {self.max_quadratic_error * k:.2f} {unit})",
        )
        ax.plot(self.delta * k, self.d_printed * k, "r:", lw=1.5, label="Eq. 9 as printed in the paper")
        for i, p in enumerate(self.calibrated):  # a marker each, not a hue alone
            ax.plot(
                p.delta * k,
                p.d * k,
                "D^vP"[i % 4],
                ms=6,
                mfc="none",
                label=f"this calibration: {p.direction}, q3 = {p.q3 * 1e3:.0f} mm",
            )
        for x in (-PAPER_DELTA_RANGE, PAPER_DELTA_RANGE):
            ax.axvline(x * k, color="0.5", ls="--", lw=0.8)
        ax.set_xlabel(f"D = γ(θ = 0) − γ0 over the full range ({unit})")
        ax.set_ylabel(f"d ({unit})")
        ax.set_title("Fig. 9: joint 2, d from the full-range average step")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
        return ax


def d_relation_data(
    calibration: Calibration | None = None,
    joint: int = 2,
    gamma0_values: Sequence[float] = (20e-6, 40e-6, 60e-6, 80e-6, 100e-6),
    n: int = 41,
    simulate: str = "steps",
) -> DRelation:
    """``d`` against ``D`` for a full-range traverse at θ = ψ = 0 (joint 1: θ = −π/2), the paper's Fig. 9.

    Exact curves for each ``gamma0`` (rad); the paper's comparator fitted to
    simulations of the same ``gamma0`` grid (``simulate``: ``"steps"`` as the paper
    did, or ``"exact"``); Eq. 9 as printed. The calibration's own ``(D, d)`` points
    are added when it models the joint.
    """
    spec = kin.joint_spec(joint)
    start, end = spec.upper, spec.lower
    q1, q2 = (0.0, 0.0) if joint == 2 else (0.0, -math.pi / 2)
    theta = 0.0 if joint == 2 else -math.pi / 2
    al, be = (float(x) for x in kin.rotary_load_coefficients(joint, q1, q2, 0.0, theta, 0.0))
    delta = np.linspace(-PAPER_DELTA_RANGE, PAPER_DELTA_RANGE, n)
    g0s = np.asarray(gamma0_values, dtype=float)
    exact = np.vstack([_exact_curve(float(g0), delta, start, end, al, be) for g0 in g0s])
    quad = fit_paper_quadratic(
        gamma0_values=tuple(float(g) for g in g0s),
        delta_range=PAPER_DELTA_RANGE,
        start=start,
        end=end,
        alpha=al,
        beta=be,
        simulate=simulate,
    )
    points = _calibrated_points(calibration, joint, quad.d) if calibration is not None else []
    return DRelation(
        delta,
        g0s,
        exact,
        np.asarray(quad.d(delta), dtype=float),
        quad.coefficients,
        np.asarray(eq9_printed(delta), dtype=float),
        points,
    )


def _calibrated_points(
    calibration: Calibration, joint: int, quadratic: Callable[[float], NDArray[np.float64]]
) -> list[CalibratedPoint]:
    """The calibration's ``(D, d)`` per direction at q3 = 0 and 12 mm, and the quadratic's d at that D."""
    spec = kin.joint_spec(joint)
    q1, q2 = (0.0, 0.0) if joint == 2 else (0.0, -math.pi / 2)
    theta = 0.0 if joint == 2 else -math.pi / 2
    points: list[CalibratedPoint] = []
    for d in ("-", "+"):
        try:
            m = calibration.model(joint, d)
        except KeyError:
            continue
        if not isinstance(m.params, RotaryParams):
            continue
        s, e = (spec.upper, spec.lower) if d == "-" else (spec.lower, spec.upper)
        for q3 in (0.0, kin.Q3_MAX):
            g0, dd = (float(np.asarray(x)) for x in m.params.at(q3))
            avg = float(np.asarray(m.average_gamma(s, e, q1, q2, q3, theta, 0.0)))
            points.append(CalibratedPoint(d, q3, avg - g0, dd, float(np.asarray(quadratic(avg - g0)))))
    return points


def _exact_curve(
    g0: float, delta: NDArray[np.float64], start: float, end: float, al: float, be: float
) -> NDArray[np.float64]:
    """d at each D for one ``gamma0``: the exact relation, forward on a dense d grid, read off.

    The average step is computed in closed form on its physical branch (d from the
    stall limit up to the largest average) and interpolated at the D grid; beyond the
    largest average the entry is NaN. :func:`stickslip.calibration.invert_d_exact`
    gives the same numbers one point at a time (checked in the tests).
    """
    qq = np.linspace(end, start, 4001)
    load = al * np.cos(qq) + be * np.sin(qq)
    lmin, lmax = float(np.min(load)), float(np.max(load))
    d_lo = -g0 / lmax if lmax > 0 else -3 * g0
    d_hi = g0 / -lmin if lmin < 0 else 3 * g0
    dd = np.linspace(d_lo, d_hi, 502)[1:-1]
    avg = abs(end - start) / steps_between(start, end, g0, dd * al, dd * be)
    k = int(np.argmax(avg)) + 1
    return np.asarray(np.interp(delta, avg[:k] - g0, dd[:k], left=np.nan, right=np.nan), dtype=float)
