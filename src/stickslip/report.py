"""Figures in the manner of the paper's, and a self-contained HTML report.

Compute, then plot: each ``*_data`` function returns a small result object holding
arrays in SI units; its ``.plot(ax=None)`` draws it with labelled display units
(nm, µrad, degrees) and returns the Axes (or array of Axes). matplotlib is imported
lazily, with the Agg backend when there is no display.

* :func:`prismatic_data` -- Fig. 4: step of joint 3 against ``zeta = psi - q2`` for
  each tilt ``theta`` in the data, with the model curve.
* :func:`rotary_interval_data` -- Figs. 6 and 10: average step of joint 2 over each
  pi/6 interval against ``zeta`` at the interval's midpoint, at q3 = 0 and 12 mm, with
  the model's exact average over each interval.
* :func:`step_simulation_data` -- Fig. 8: step-by-step simulation of joint 2 over its
  full range.
* :func:`d_relation_data` -- Fig. 9: ``d`` against ``D = gamma(theta=0) -
  gamma0`` from the exact relation, the paper's simulate-and-fit quadratic, and its
  Eq. 9 as printed.
* :func:`build_report` -- all of the above as PNGs plus ``index.html`` with the
  calibration, the validation table (model against constant step) and residuals.
"""

from __future__ import annotations

import html
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from . import kinematics as kin
from .measurements import Traverse

if TYPE_CHECKING:  # pragma: no cover
    from .calibration import Calibration

__all__ = [
    "PrismaticFigure",
    "RotaryIntervalFigure",
    "StepSimulation",
    "DRelation",
    "ValidationFigure",
    "Report",
    "prismatic_data",
    "rotary_interval_data",
    "step_simulation_data",
    "simulate_steps",
    "d_relation_data",
    "validation_data",
    "build_report",
]

_TOL = 1e-3  # rad: poses typed by hand still match
_Q3_TOL = 1e-5  # m
SEED_DELTA_RANGE = 9.2e-6
"""The range of ``gamma(theta=0) - gamma0`` the paper observed, ±9.2 µrad (its Section 3.5)."""


def _plt():
    """matplotlib.pyplot, with the Agg backend when there is no display."""
    try:
        import matplotlib
    except ImportError:
        raise ImportError("plots need matplotlib: pip install 'stickslip[plot]'") from None
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY") and os.name != "nt":
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _deg(x: Any) -> Any:
    return np.degrees(x)


def _key(v: float, tol: float = _TOL) -> float:
    return round(v / tol) * tol


# ---------------------------------------------------------------- Fig. 4: prismatic joint


@dataclass
class Series:
    """One curve of a figure: data points and the model, SI units.

    Attributes
    ----------
    label : str
    direction : str
    zeta_data, gamma_data : ndarray
        Measured traverses: ``zeta`` (rad) and average step (m or rad).
    days : list of str
        Day of each data point.
    zeta_model, gamma_model : ndarray
        The model along the series (rad; m or rad).
    style : str
        ``"line"`` for a continuous model curve, ``"steps"`` for interval averages.
    """

    label: str
    direction: str
    zeta_data: NDArray[np.float64]
    gamma_data: NDArray[np.float64]
    days: list[str]
    zeta_model: NDArray[np.float64]
    gamma_model: NDArray[np.float64]
    style: str = "line"
    zeta_curve: NDArray[np.float64] | None = None
    gamma_curve: NDArray[np.float64] | None = None


def _series_axes(plt, n: int, ax):
    if ax is None:
        fig, axes = plt.subplots(1, n, figsize=(5.5 * n, 5.6), sharey=False, constrained_layout=True)
        return fig, np.atleast_1d(axes)
    axes = np.atleast_1d(ax)
    if axes.size != n:
        raise ValueError(f"this figure needs {n} Axes, got {axes.size}")
    return axes[0].figure, axes


def _plot_series(
    axes,
    series: Sequence[Series],
    scale: float,
    unit: str,
    title: str,
    directions=("+", "-"),
    legend_title: str = "markers: measured; lines: model",
):
    plt = _plt()
    cmap = plt.get_cmap("tab10")
    markers = "o^sDvP*Xh<>"
    all_days = sorted({day for s in series for day in s.days})
    marker_of = {day: markers[i % len(markers)] for i, day in enumerate(all_days)}
    for ax, d in zip(axes, directions, strict=True):
        ss = [s for s in series if s.direction == d]
        for i, s in enumerate(ss):
            color = cmap(i % 10)
            if s.zeta_curve is not None and s.gamma_curve is not None:
                ax.plot(_deg(s.zeta_curve), s.gamma_curve * scale, "-", color=color, lw=0.8, alpha=0.5)
            if s.style == "steps":
                ax.plot(
                    _deg(s.zeta_model),
                    s.gamma_model * scale,
                    "s--",
                    color=color,
                    ms=4,
                    mfc="none",
                    lw=1.2,
                    label=s.label,
                )
            elif s.style == "points":
                ax.plot(_deg(s.zeta_model), s.gamma_model * scale, "x", color=color, ms=5, label=s.label)
            else:
                ax.plot(_deg(s.zeta_model), s.gamma_model * scale, "-", color=color, lw=1.5, label=s.label)
            if s.zeta_data.size:
                days_here = np.array(s.days)
                for day in sorted(set(s.days)):
                    sel = days_here == day
                    ax.plot(
                        _deg(s.zeta_data[sel]),
                        s.gamma_data[sel] * scale,
                        marker_of[day],
                        color=color,
                        ms=4,
                        alpha=0.8,
                        ls="none",
                    )
        if len(marker_of) > 1 and ss:
            for day, mk in marker_of.items():  # legend entries for the days (marker shape)
                ax.plot([], [], mk, color="0.3", ms=4, ls="none", label=f"day {day}")
        ax.set_xlabel("ζ = ψ − q2 (degrees)")
        ax.set_ylabel(f"step size γ{d} ({unit})")
        ax.set_title(title.format(d=d))
        ax.grid(True, alpha=0.3)
        if ss:
            ax.legend(
                fontsize=7,
                title=legend_title,
                title_fontsize=7,
                loc="upper center",
                bbox_to_anchor=(0.5, -0.14),
                ncol=2,
                frameon=False,
            )
        else:
            ax.text(0.5, 0.5, "not calibrated", ha="center", va="center", transform=ax.transAxes)
    return axes


@dataclass
class PrismaticFigure:
    """Data of the paper's Fig. 4: joint-3 step against ζ for several θ (see :func:`prismatic_data`)."""

    series: list[Series]

    def plot(self, ax=None):
        """Two panels, γ3+ and γ3−, in nm against ζ in degrees; returns the Axes array."""
        plt = _plt()
        _fig, axes = _series_axes(plt, 2, ax)
        return _plot_series(axes, self.series, 1e9, "nm", "prismatic joint 3, direction {d}")


def prismatic_data(calibration: Calibration, traverses: Sequence[Traverse]) -> PrismaticFigure:
    """Joint-3 traverses grouped into curves of the paper's Fig. 4, with the model.

    Traverses at the same direction, ``theta`` and ``psi`` with several ``q2`` form a
    curve over ``q2`` (the paper's experiment 1); the rest at the same ``theta`` and
    ``q2`` with several ``psi`` form a curve over ``psi`` (experiment 2). Without
    such data the model alone is drawn at ``theta = 0, -pi/3, -pi/2`` (``psi = 0``).
    The model is the calibration's Eq. (3) at each curve's ``q1``.
    """
    spec2 = kin.JOINTS[2]
    out: list[Series] = []
    for d in ("+", "-"):
        try:
            model = calibration.model(3, d)
        except KeyError:
            continue
        ts = [t for t in traverses if t.joint == 3 and t.direction == d]
        used: set[int] = set()
        by_tp: dict[tuple[float, float], list[int]] = {}
        for i, t in enumerate(ts):
            by_tp.setdefault((_key(t.theta), _key(t.psi)), []).append(i)
        for (th, ps), idx in sorted(by_tp.items(), key=lambda kv: (-kv[0][0], kv[0][1])):
            if len({_key(ts[i].q2) for i in idx}) < 2:
                continue
            used.update(idx)
            q1 = ts[idx[0]].q1
            q2 = np.linspace(spec2.lower, spec2.upper, 241)
            g = model.gamma(q1, q2, 0.0, th, ps)
            sel = [ts[i] for i in idx]
            label = f"θ = {math.degrees(th):.0f}°, ψ = {math.degrees(ps):.0f}° (q2 varied)"
            out.append(
                Series(
                    label,
                    d,
                    np.array([t.psi - t.q2 for t in sel]),
                    np.array([t.gamma for t in sel]),
                    [t.day for t in sel],
                    ps - q2,
                    g,
                )
            )
        by_tq: dict[tuple[float, float], list[int]] = {}
        for i, t in enumerate(ts):
            if i not in used:
                by_tq.setdefault((_key(t.theta), _key(t.q2)), []).append(i)
        for (th, q2v), idx in sorted(by_tq.items()):
            psis = [ts[i].psi for i in idx]
            if len({_key(p) for p in psis}) < 2:
                continue
            used.update(idx)
            q1 = ts[idx[0]].q1
            lo, hi = min(psis), max(psis)
            pad = 0.05 * (hi - lo)
            ps = np.linspace(lo - pad, hi + pad, 241)
            g = model.gamma(q1, q2v, 0.0, th, ps)
            sel = [ts[i] for i in idx]
            label = f"θ = {math.degrees(th):.0f}°, q2 = {math.degrees(q2v):.0f}° (ψ varied)"
            out.append(
                Series(
                    label,
                    d,
                    np.array([t.psi - t.q2 for t in sel]),
                    np.array([t.gamma for t in sel]),
                    [t.day for t in sel],
                    ps - q2v,
                    g,
                )
            )
        rest = [t for i, t in enumerate(ts) if i not in used]
        if rest:
            pred = np.array([calibration.predict(t) for t in rest])
            z = np.array([t.psi - t.q2 for t in rest])
            order = np.argsort(z)
            s = Series(
                "other poses",
                d,
                z,
                np.array([t.gamma for t in rest]),
                [t.day for t in rest],
                z[order],
                pred[order],
                style="points",
            )
            out.append(s)
        if not any(s.direction == d for s in out):
            for th in (0.0, -math.pi / 3, -math.pi / 2):
                q2 = np.linspace(spec2.lower, spec2.upper, 241)
                out.append(
                    Series(
                        f"θ = {math.degrees(th):.0f}°, ψ = 0° (model only)",
                        d,
                        np.array([]),
                        np.array([]),
                        [],
                        -q2,
                        model.gamma(0.0, q2, 0.0, th, 0.0),
                    )
                )
    return PrismaticFigure(out)


# ---------------------------------------------------------------- Figs. 6 and 10: rotary intervals


@dataclass
class RotaryIntervalFigure:
    """Data of the paper's Figs. 6/10 (see :func:`rotary_interval_data`)."""

    joint: int
    series: list[Series]

    def plot(self, ax=None):
        """Two panels, γ− and γ+, in µrad against ζ (degrees) at each interval's midpoint."""
        plt = _plt()
        _fig, axes = _series_axes(plt, 2, ax)
        return _plot_series(
            axes,
            self.series,
            1e6,
            "µrad",
            f"rotary joint {self.joint}, direction {{d}}, per π/6 interval",
            directions=("-", "+"),
            legend_title="filled: measured; open squares: model average over the interval",
        )


def _pi6_intervals(spec: kin.JointSpec) -> list[tuple[float, float]]:
    n = int(round(spec.span / (math.pi / 6)))
    edges = np.linspace(spec.lower, spec.upper, n + 1)
    return list(zip(edges[:-1], edges[1:], strict=True))


def rotary_interval_data(
    calibration: Calibration, traverses: Sequence[Traverse], joint: int = 2, max_interval: float = math.pi / 3 + 1e-3
) -> RotaryIntervalFigure:
    """Rotary traverses over short intervals (the paper used π/6), against ζ at the midpoint.

    Traverses of ``joint`` no longer than ``max_interval`` (rad) are grouped by
    direction and pose (q1, q3, θ, ψ); each group is a curve: the measured average
    step of every interval, plotted at its midpoint ``zeta = psi - q_mid``, and the
    model's *exact average over the same interval* (the paper plotted the interval
    average at the midpoint too), with the pointwise model as a thin line. Without
    such data the model alone is drawn for the π/6 intervals of the range at
    q3 = 0 and 12 mm, θ = ψ = 0.
    """
    spec = kin.JOINTS[joint]
    out: list[Series] = []
    for d in ("-", "+"):
        try:
            model = calibration.model(joint, d)
        except KeyError:
            continue
        ts = [t for t in traverses if t.joint == joint and t.direction == d and abs(t.end - t.start) <= max_interval]
        groups: dict[tuple, list[Traverse]] = {}
        for t in ts:
            groups.setdefault((_key(t.q1), _key(t.q3, _Q3_TOL), _key(t.theta), _key(t.psi)), []).append(t)
        if not groups:
            for q3 in (0.0, kin.Q3_MAX):
                groups[(0.0, q3, 0.0, 0.0)] = []
        for (q1, q3, th, ps), sel in sorted(groups.items(), key=lambda kv: (kv[0][2] != 0.0, kv[0][1], kv[0][2])):
            if sel:
                ivs = sorted({(round(min(t.start, t.end), 6), round(max(t.start, t.end), 6)) for t in sel})
            else:
                ivs = [(round(a, 12), round(b, 12)) for a, b in _pi6_intervals(spec)]
            lo = np.array([a for a, _ in ivs])
            hi = np.array([b for _, b in ivs])
            start, end = (lo, hi) if d == "+" else (hi, lo)
            q2c, q1c = (0.0, q1) if joint == 2 else (-math.pi / 2, 0.0)
            avg = model.average_gamma(start, end, q1c, q2c, q3, th, ps)
            mid = (lo + hi) / 2
            if joint == 2:
                z_model, z_data = ps - mid, np.array([t.psi - (t.start + t.end) / 2 for t in sel])
            else:  # joint 1: plot against q1 itself
                z_model, z_data = mid, np.array([(t.start + t.end) / 2 for t in sel])
            qq = np.linspace(spec.lower, spec.upper, 361)
            if joint == 2:
                curve = model.gamma(q1, qq, q3, th, ps)
                z_curve = ps - qq
            else:
                curve = model.gamma(qq, -math.pi / 2, q3, th, ps)
                z_curve = qq
            order = np.argsort(z_model)
            label = f"q3 = {q3 * 1e3:.0f} mm, θ = {math.degrees(th):.0f}°" + (" (model only)" if not sel else "")
            out.append(
                Series(
                    label,
                    d,
                    z_data,
                    np.array([t.gamma for t in sel]),
                    [t.day for t in sel],
                    z_model[order],
                    avg[order],
                    style="steps",
                    zeta_curve=z_curve,
                    gamma_curve=curve,
                )
            )
    return RotaryIntervalFigure(joint, out)


# ---------------------------------------------------------------- Fig. 8: step-by-step simulation


def simulate_steps(
    start: float, end: float, A: float, alpha: float, beta: float, max_steps: int = 5_000_000
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Step from ``start`` until ``end`` is reached, each step ``A + alpha cos q + beta sin q``.

    The paper's simulation (its Fig. 8): the step is evaluated where it begins. Returns
    ``(q, gamma)``: the position before each step and the step size (rad). The number of
    steps equals :func:`stickslip.models.simulate_traverse_steps` on the same model.
    """
    sign = 1.0 if end >= start else -1.0
    qs: list[float] = []
    gs: list[float] = []
    q = float(start)
    cos, sin = math.cos, math.sin
    while (end - q) * sign > 0.0:
        g = A + alpha * cos(q) + beta * sin(q)
        if not g > 0.0:
            raise ValueError(f"step size {g:.4g} <= 0 at q = {q:.6g}: the joint stalls")
        qs.append(q)
        gs.append(g)
        q += sign * g
        if len(qs) >= max_steps:
            raise RuntimeError(f"more than {max_steps} steps")
    return np.array(qs), np.array(gs)


@dataclass
class StepSimulation:
    """The paper's Fig. 8: simulated step along a full-range traverse, per direction and q3.

    Attributes
    ----------
    runs : list of dict
        Each: ``direction``, ``q3`` (m), ``q`` and ``gamma`` arrays (rad), ``steps``,
        ``average`` (range / steps, rad), ``gamma0`` (rad).
    """

    joint: int
    runs: list[dict[str, Any]]

    def plot(self, ax=None):
        """Two panels (− then +): step size (µrad) against step number."""
        plt = _plt()
        _fig, axes = _series_axes(plt, 2, ax)
        cmap = plt.get_cmap("tab10")
        for ax_, d in zip(axes, ("-", "+"), strict=True):
            runs = [r for r in self.runs if r["direction"] == d]
            for i, r in enumerate(runs):
                c = cmap(i)
                n = np.arange(1, r["steps"] + 1)
                every = max(1, r["steps"] // 3000)  # a smooth curve: no need to draw 100 000 vertices
                ax_.plot(
                    n[::every],
                    r["gamma"][::every] * 1e6,
                    "-",
                    color=c,
                    lw=1.2,
                    label=f"q3 = {r['q3'] * 1e3:.0f} mm: {r['steps']} steps",
                )
                ax_.axhline(
                    r["average"] * 1e6,
                    color=c,
                    ls="--",
                    lw=0.9,
                    label=f"average (range / steps) {r['average'] * 1e6:.2f} µrad",
                )
                ax_.axhline(
                    r["gamma0"] * 1e6,
                    color=c,
                    ls=":",
                    lw=0.9,
                    label=f"γ0 (no gravity torque) {r['gamma0'] * 1e6:.2f} µrad",
                )
            ax_.set_xlabel("step number")
            ax_.set_ylabel(f"step size γ{self.joint}{d} (µrad)")
            start_deg = math.degrees(runs[0]["start"]) if runs else 0.0
            end_deg = math.degrees(runs[0]["end"]) if runs else 0.0
            ax_.set_title(f"simulated joint {self.joint}{d}: q{self.joint} {start_deg:.0f}° → {end_deg:.0f}°, θ = 0")
            ax_.grid(True, alpha=0.3)
            if runs:
                ax_.legend(fontsize=7)
            else:
                ax_.text(0.5, 0.5, "not calibrated", ha="center", va="center", transform=ax_.transAxes)
        return axes


def step_simulation_data(
    calibration: Calibration, joint: int = 2, theta: float = 0.0, psi: float = 0.0
) -> StepSimulation:
    """Simulate the calibrated joint step by step over its full range (the paper's Fig. 8).

    Negative direction from the upper stop to the lower (π/6 → −7π/6 for joint 2),
    positive the other way, at q3 = 0 and 12 mm, arm outstretched for joint 1.
    """
    spec = kin.JOINTS[joint]
    runs = []
    for d in ("-", "+"):
        try:
            model = calibration.model(joint, d)
        except KeyError:
            continue
        start, end = (spec.upper, spec.lower) if d == "-" else (spec.lower, spec.upper)
        for q3 in (0.0, kin.Q3_MAX):
            q1, q2 = (0.0, 0.0) if joint == 2 else (0.0, -math.pi / 2)
            A, al, be = (float(np.asarray(x)) for x in model.rotary_coefficients(q1, q2, q3, theta, psi))
            q, g = simulate_steps(start, end, A, al, be)
            g0 = float(model.params.at(q3)[0])
            runs.append(
                {
                    "direction": d,
                    "q3": q3,
                    "q": q,
                    "gamma": g,
                    "steps": int(q.size),
                    "average": abs(end - start) / q.size,
                    "gamma0": g0,
                    "start": start,
                    "end": end,
                }
            )
    return StepSimulation(joint, runs)


# ---------------------------------------------------------------- Fig. 9: d against the difference


@dataclass
class DRelation:
    """The paper's Fig. 9: ``d`` against ``D = gamma(theta=0) - gamma0`` (all rad).

    Attributes
    ----------
    delta : ndarray
        Grid of ``D`` (rad), ±9.2 µrad as in the paper.
    gamma0 : ndarray
        ``gamma0`` values of the exact curves (rad).
    d_exact : ndarray
        ``(len(gamma0), len(delta))`` exact inversions (rad).
    d_quadratic : ndarray
        The paper's method (simulate, fit a quadratic) on the same grid (rad).
    quadratic : tuple
        Its coefficients ``(p2, p1, p0)`` (SI).
    d_printed : ndarray
        Eq. 9 as printed (rad).
    calibrated : list of dict
        The calibration's own points (``direction``, ``q3``, ``delta``, ``d``), rad.
    max_quadratic_error : float
        Largest ``|d_quadratic - d_exact|`` over the grid and gamma0 values (rad).
    """

    delta: NDArray[np.float64]
    gamma0: NDArray[np.float64]
    d_exact: NDArray[np.float64]
    d_quadratic: NDArray[np.float64]
    quadratic: tuple[float, float, float]
    d_printed: NDArray[np.float64]
    calibrated: list[dict[str, Any]] = field(default_factory=list)

    def quadratic_error_by_gamma0(self) -> NDArray[np.float64]:
        """Largest ``|d_quadratic - d_exact|`` over the D grid, per ``gamma0`` (rad)."""
        return np.nanmax(np.abs(self.d_quadratic[None, :] - self.d_exact), axis=1)

    @property
    def max_quadratic_error(self) -> float:
        return float(np.nanmax(np.abs(self.d_quadratic[None, :] - self.d_exact)))

    def plot(self, ax=None):
        """One panel: d (µrad) against D (µrad)."""
        plt = _plt()
        if ax is None:
            _fig, ax = plt.subplots(figsize=(6.4, 4.6), constrained_layout=True)
        cmap = plt.get_cmap("viridis")
        for i, g0 in enumerate(self.gamma0):
            ax.plot(
                self.delta * 1e6,
                self.d_exact[i] * 1e6,
                "-",
                color=cmap(i / max(1, len(self.gamma0) - 1)),
                lw=1.2,
                label=f"exact, γ0 = {g0 * 1e6:.0f} µrad",
            )
        p2, p1, p0 = self.quadratic
        ax.plot(
            self.delta * 1e6,
            self.d_quadratic * 1e6,
            "k--",
            lw=1.5,
            label=f"paper's method: quadratic fit to simulations (max error {self.max_quadratic_error * 1e6:.2f} µrad)",
        )
        ax.plot(self.delta * 1e6, self.d_printed * 1e6, "r:", lw=1.5, label="Eq. 9 as printed in the paper")
        for c in self.calibrated:
            ax.plot(
                c["delta"] * 1e6,
                c["d"] * 1e6,
                "D",
                ms=6,
                mfc="none",
                label=f"this calibration: {c['direction']}, q3 = {c['q3'] * 1e3:.0f} mm",
            )
        for x in (-SEED_DELTA_RANGE, SEED_DELTA_RANGE):
            ax.axvline(x * 1e6, color="0.5", ls="--", lw=0.8)
        ax.set_xlabel("D = γ(θ = 0) − γ0 over the full range (µrad)")
        ax.set_ylabel("d (µrad)")
        ax.set_title("joint 2: d from the full-range average step")
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
    """``d`` against ``D`` for a full-range traverse of joint 2 at θ = ψ = 0 (the paper's Fig. 9).

    Exact curves come from :func:`stickslip.calibration.invert_d_exact` for each
    ``gamma0``; the paper's comparator from :func:`stickslip.calibration.fit_paper_quadratic`
    (step-by-step simulations of the same ``gamma0`` grid, fitted by a quadratic);
    Eq. 9 as printed from :func:`stickslip.calibration.eq9_printed`. The calibration's
    own ``(D, d)`` points are added when it models the joint.
    """
    from .calibration import eq9_printed, fit_paper_quadratic
    from .models import steps_between

    spec = kin.JOINTS[joint]
    start, end = spec.upper, spec.lower
    q1, q2 = (0.0, 0.0) if joint == 2 else (0.0, -math.pi / 2)
    theta = 0.0 if joint == 2 else -math.pi / 2
    al, be = (float(x) for x in kin.rotary_load_coefficients(joint, q1, q2, 0.0, theta, 0.0))
    delta = np.linspace(-SEED_DELTA_RANGE, SEED_DELTA_RANGE, n)
    g0s = np.asarray(gamma0_values, dtype=float)
    span = abs(end - start)
    lmin, lmax = np.min(load := al * np.cos(qq := np.linspace(end, start, 4001)) + be * np.sin(qq)), np.max(load)
    exact = np.full((g0s.size, delta.size), np.nan)
    for i, g0 in enumerate(g0s):
        # the exact relation, computed forward on a dense d grid (vectorised closed form), then read
        # off at the D grid on its physical branch (d from the stall limit up to the largest average);
        # invert_d_exact gives the same numbers one point at a time (checked in the tests)
        d_lo = -g0 / lmax if lmax > 0 else -3 * g0
        d_hi = g0 / -lmin if lmin < 0 else 3 * g0
        dd = np.linspace(d_lo, d_hi, 502)[1:-1]
        avg = span / steps_between(start, end, g0, dd * al, dd * be)
        k = int(np.argmax(avg)) + 1
        exact[i] = np.interp(delta, avg[:k] - g0, dd[:k], left=np.nan, right=np.nan)
    quad = fit_paper_quadratic(
        gamma0_values=tuple(g0s),
        delta_range=SEED_DELTA_RANGE,
        start=start,
        end=end,
        alpha=al,
        beta=be,
        simulate=simulate,
    )
    cal_points = []
    if calibration is not None:
        for d in ("-", "+"):
            try:
                m = calibration.model(joint, d)
            except KeyError:
                continue
            s, e = (spec.upper, spec.lower) if d == "-" else (spec.lower, spec.upper)
            for q3 in (0.0, kin.Q3_MAX):
                g0, dd = (float(np.asarray(x)) for x in m.params.at(q3))
                avg = float(m.average_gamma(s, e, q1, q2, q3, theta, 0.0))
                cal_points.append(
                    {"direction": d, "q3": q3, "delta": avg - g0, "d": dd, "d_quadratic": float(quad.d(avg - g0))}
                )
    return DRelation(
        delta, g0s, exact, np.asarray(quad.d(delta)), quad.coefficients, np.asarray(eq9_printed(delta)), cal_points
    )


# ---------------------------------------------------------------- validation


@dataclass
class ValidationFigure:
    """Relative error of the model and of the constant step per traverse, per joint.

    Attributes
    ----------
    joints : list of int
    measured : dict
        ``joint -> array`` of measured average steps (m or rad).
    model_error, constant_error : dict
        ``joint -> array`` of relative errors ``predicted / measured - 1``.
    """

    joints: list[int]
    measured: dict[int, NDArray[np.float64]]
    model_error: dict[int, NDArray[np.float64]]
    constant_error: dict[int, NDArray[np.float64]]

    def plot(self, ax=None):
        """One panel per joint: error (%) against the measured step (nm or µrad)."""
        plt = _plt()
        _fig, axes = _series_axes(plt, len(self.joints), ax)
        for ax_, j in zip(axes, self.joints, strict=True):
            k, unit = (1e9, "nm") if j == 3 else (1e6, "µrad")
            m = self.measured[j] * k
            me, ce = self.model_error[j], self.constant_error[j]
            ax_.plot(
                m, ce * 100, "x", color="tab:red", ms=5, label=f"constant step (max {np.max(np.abs(ce)) * 100:.1f} %)"
            )
            ax_.plot(m, me * 100, "o", color="tab:blue", ms=4, label=f"model (max {np.max(np.abs(me)) * 100:.1f} %)")
            ax_.axhline(0, color="k", lw=0.8)
            ax_.set_xlabel(f"measured average step ({unit})")
            ax_.set_ylabel("relative error of the prediction (%)")
            ax_.set_title(f"joint {j}: {m.size} traverses")
            ax_.grid(True, alpha=0.3)
            ax_.legend(fontsize=8)
        return axes


def validation_data(calibration: Calibration, traverses: Sequence[Traverse]) -> ValidationFigure:
    """Per-joint errors of :func:`stickslip.calibration.validate` for plotting."""
    from .calibration import validate

    v = validate(calibration, traverses)
    joints = np.array([t.joint for t in v.traverses])
    js = sorted(set(joints.tolist()))
    return ValidationFigure(
        js,
        {j: v.measured[joints == j] for j in js},
        {j: v.model_error[joints == j] for j in js},
        {j: v.constant_error[joints == j] for j in js},
    )


# ---------------------------------------------------------------- the report


def _err_by_gamma0(rel: DRelation) -> str:
    """'at most X µrad at γ0 = ... µrad, ... from the exact relation' in words."""
    errs = rel.quadratic_error_by_gamma0()
    parts = [f"{e * 1e6:.2f} µrad at γ0 = {g * 1e6:.0f} µrad" for g, e in zip(rel.gamma0, errs, strict=True)]
    return "at most " + ", ".join(parts) + " from the exact relation"


@dataclass
class Report:
    """What :func:`build_report` wrote: the HTML page and the PNG figures."""

    directory: Path
    html: Path
    figures: list[Path]


def _table_html(rows: list[dict[str, Any]], columns: list[tuple[str, str]]) -> str:
    head = "".join(f"<th>{html.escape(label)}</th>" for _, label in columns)
    body = []
    for r in rows:
        cells = "".join(f"<td>{html.escape(str(r.get(k, '')))}</td>" for k, _ in columns)
        body.append(f"<tr>{cells}</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _pct(x: float | None) -> str:
    return "" if x is None or not math.isfinite(x) else f"{100 * x:.2f} %"


_CSS = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f2f2f2; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.92em; color: #444; }
.warn { color: #a40; }
"""


def build_report(
    calibration: Calibration,
    traverses: Sequence[Traverse],
    directory: str | Path,
    dpi: int = 120,
    seed_simulation: str = "steps",
) -> Report:
    """Write the paper-style figures and ``index.html`` into ``directory`` (created if needed).

    The page shows the calibration with standard errors, the validation table (model
    against the constant-step comparator, :func:`stickslip.calibration.validate`), the
    residuals per joint and direction, and every figure (PNG files referenced by
    relative path, so the directory can be moved or zipped as a whole).

    ``seed_simulation`` is how the paper's Eq. 9 comparator gets its averages:
    ``"steps"`` (step-by-step, as the paper did) or ``"exact"`` (faster, same curve).
    """
    from .analysis import residual_summary
    from .calibration import validate

    plt = _plt()
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    traverses = list(traverses)
    joints = set(calibration.joints)
    figures: list[tuple[Path, str]] = []
    notes: list[str] = []
    rel_holder: list[DRelation] = []

    def save(fig, name: str, caption: str) -> None:
        p = out / name
        fig.savefig(p, dpi=dpi)
        plt.close(fig)
        figures.append((p, caption))

    if 3 in joints:
        fig, axes = plt.subplots(1, 2, figsize=(11, 6.0), constrained_layout=True)
        prismatic_data(calibration, traverses).plot(axes)
        save(
            fig,
            "fig4_prismatic.png",
            "Fig. 4 after the paper: average step of prismatic joint 3 against ζ = ψ − q2, "
            "measured (points) and the calibrated model, Eq. (3) (lines), per tilt θ.",
        )
    if 2 in joints:
        fig, axes = plt.subplots(1, 2, figsize=(11, 6.0), constrained_layout=True)
        rotary_interval_data(calibration, traverses, 2).plot(axes)
        save(
            fig,
            "fig6_rotary_intervals.png",
            "Figs. 6 and 10 after the paper: average step of joint 2 over each π/6 interval, plotted at the "
            "interval's midpoint ζ, at q3 = 0 and 12 mm; squares are the model's exact average over the same "
            "interval, the thin line the pointwise model, Eq. (8).",
        )
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), constrained_layout=True)
        step_simulation_data(calibration, 2).plot(axes)
        save(
            fig,
            "fig8_simulated_steps.png",
            "Fig. 8 after the paper: step-by-step simulation of the calibrated joint 2 over its full range at "
            "θ = ψ = 0 (dashed: the average step range/steps; dotted: γ0, the step without gravity torque).",
        )
        rel = d_relation_data(calibration, 2, simulate=seed_simulation)
        rel_holder.append(rel)
        fig, ax = plt.subplots(figsize=(7.5, 5), constrained_layout=True)
        rel.plot(ax)
        save(
            fig,
            "fig9_d_relation.png",
            "Fig. 9 after the paper: d against D = γ(θ = 0) − γ0 for a full-range traverse of joint 2. "
            "Solid: the exact relation for several γ0; dashed: the paper's method (quadratic fitted to "
            f"step-by-step simulations), {_err_by_gamma0(rel)}; dotted: "
            "Eq. 9 as printed, which gives d < 1 µrad and cannot match the paper's own Fig. 10.",
        )
    rel = rel_holder[0] if rel_holder else None
    anova_rows: list[dict[str, Any]] = []
    if traverses:
        from .analysis import PoseGroup, anova

        try:
            an = anova(traverses, two_way=False)
        except ValueError:
            an = None
        for t in an.tests if an is not None else []:
            anova_rows.append(
                {
                    "test": "across days" if t.test == "day" else "+ vs −",
                    "joint": t.joint,
                    "what": t.direction if t.test == "day" else t.day,
                    "pose": PoseGroup(t.joint, t.pose, t.interval).describe(),
                    "n": t.n,
                    "F": f"{t.F:.4g}",
                    "p": f"{t.p:.3g}",
                    "verdict": t.verdict(an.alpha),
                }
            )
    modelled = [t for t in traverses if (t.joint, t.direction) in calibration.models]
    if len(modelled) < len(traverses):
        notes.append(
            f"{len(traverses) - len(modelled)} traverses of joints/directions this calibration does not "
            "model are left out of the validation"
        )
    val = validate(calibration, modelled) if modelled else None
    if val is not None:
        vf = validation_data(calibration, modelled)
        fig, axes = plt.subplots(1, len(vf.joints), figsize=(5.5 * len(vf.joints), 4.4), constrained_layout=True)
        vf.plot(axes)
        save(
            fig,
            "validation.png",
            "Every traverse: relative error of the model's prediction (o) and of the "
            "constant step (x), against the measured average step.",
        )

    parts = [
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>stickslip report</title>"
        f"<style>{_CSS}</style></head><body>"
    ]
    parts.append(f"<h1>stickslip report — calibration of {html.escape(str(calibration.day))}</h1>")
    days = sorted({t.day for t in traverses})
    parts.append(
        f"<p>{len(traverses)} traverses from {len(days)} day(s): {html.escape(', '.join(days))}. "
        f"Calibration method: {html.escape(str(calibration.method))}.</p>"
    )
    if val is not None:
        vrows = [
            {
                "joint": r["joint"],
                "n": r["n"],
                "mmax": _pct(r["model_max_rel_error"]),
                "mmean": _pct(r["model_mean_rel_error"]),
                "cmax": _pct(r["constant_max_rel_error"]),
                "cmean": _pct(r["constant_mean_rel_error"]),
            }
            for r in val.rows()
        ]
        parts.append("<h2>Validation: model against constant step</h2>")
        parts.append(
            "<p>Relative error of the predicted average step over each traverse. The paper reports a "
            "maximum error of about 15 % (prismatic) and 2 % (rotary) for its model, against 40 % and "
            "7 % for a constant step.</p>"
        )
        parts.append(
            _table_html(
                vrows,
                [
                    ("joint", "joint"),
                    ("n", "traverses"),
                    ("mmax", "model max"),
                    ("mmean", "model mean"),
                    ("cmax", "constant-step max"),
                    ("cmean", "constant-step mean"),
                ],
            )
        )
        res = residual_summary(calibration, modelled)
        rrows = []
        for r in res.rows_:
            k, unit = (1e9, "nm") if r.joint == 3 else (1e6, "µrad")
            rrows.append(
                {
                    "jd": f"{r.joint}{r.direction}",
                    "n": r.n,
                    "rms": _pct(r.rms_rel),
                    "max": _pct(r.max_rel),
                    "rmsa": f"{r.rms_abs * k:.4g} {unit}",
                    "maxa": f"{r.max_abs * k:.4g} {unit}",
                }
            )
        parts.append("<h2>Residuals per joint and direction</h2>")
        parts.append(
            _table_html(
                rrows,
                [
                    ("jd", "joint"),
                    ("n", "n"),
                    ("rms", "RMS (relative)"),
                    ("max", "max (relative)"),
                    ("rmsa", "RMS"),
                    ("maxa", "max"),
                ],
            )
        )
    prow = []
    for p in (rec.to_dict() for rec in calibration.parameters()):
        j, name = p["joint"], p["name"]
        k, unit = (1.0, "") if name == "b" else ((1e9, "nm") if j == 3 else (1e6, "µrad"))
        se = p["stderr"]
        prow.append(
            {
                "jd": f"{j}{p['direction']}",
                "name": name,
                "q3": "" if p["q3"] is None else f"{p['q3'] * 1e3:g} mm",
                "value": f"{p['value'] * k:.5g} {unit}".strip(),
                "se": "" if se is None else f"{se * k:.3g} {unit}".strip(),
            }
        )
    if rel is not None and rel.calibrated:
        drows = [
            {
                "jd": f"2{c['direction']}",
                "q3": f"{c['q3'] * 1e3:g} mm",
                "D": f"{c['delta'] * 1e6:.3f} µrad",
                "d": f"{c['d'] * 1e6:.3f} µrad",
                "dq": f"{c['d_quadratic'] * 1e6:.3f} µrad",
                "err": f"{(c['d_quadratic'] - c['d']) * 1e6:+.3f} µrad",
            }
            for c in rel.calibrated
        ]
        parts.append("<h2>d from the full-range average: exact against the paper's quadratic</h2>")
        parts.append(
            "<p>For this calibration's joint-2 models: D is the full-range average step at θ = ψ = 0 "
            "minus γ0; d the calibrated value (exact relation); the paper's method reads d off a quadratic "
            "fitted to step-by-step simulations. Over the plotted grid the quadratic is "
            f"{html.escape(_err_by_gamma0(rel))} (largest where a curve turns steep: "
            "there the average step hardly changes with d).</p>"
        )
        parts.append(
            _table_html(
                drows,
                [
                    ("jd", "joint"),
                    ("q3", "q3"),
                    ("D", "D"),
                    ("d", "d (exact)"),
                    ("dq", "d (seed quadratic)"),
                    ("err", "quadratic − exact"),
                ],
            )
        )
    if anova_rows:
        parts.append("<h2>Day-to-day and direction ANOVA</h2>")
        parts.append(
            "<p>One-way ANOVA of the average step across days (per joint, direction and repeated pose) "
            "and of + against − (per joint, day and pose); significant at α = 0.05 means the paper's "
            "advice holds: recalibrate every day, and per direction.</p>"
        )
        parts.append(
            _table_html(
                anova_rows,
                [
                    ("test", "test"),
                    ("joint", "joint"),
                    ("what", "day / direction"),
                    ("pose", "pose"),
                    ("n", "n"),
                    ("F", "F"),
                    ("p", "p"),
                    ("verdict", "at α = 0.05"),
                ],
            )
        )
    parts.append("<h2>Calibrated parameters</h2>")
    parts.append(
        _table_html(
            prow,
            [("jd", "joint"), ("name", "parameter"), ("q3", "at q3"), ("value", "value"), ("se", "standard error")],
        )
    )
    for n in notes:
        parts.append(f"<p class='warn'>note: {html.escape(n)}</p>")
    parts.append("<h2>Figures</h2>")
    for p, caption in figures:
        parts.append(
            f"<figure><img src='{html.escape(p.name)}' alt='{html.escape(p.stem)}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )
    parts.append(f"<h2>Calibration report</h2><pre>{html.escape(calibration.report())}</pre>")
    parts.append("</body></html>")
    page = out / "index.html"
    page.write_text("\n".join(parts), encoding="utf-8")
    return Report(out, page, [p for p, _ in figures])
