"""Per-day, per-direction panels of measured average steps beside the model (Figs. 4, 6, 10).

The data object :class:`StepFigure` holds, for every day of the table and each
direction, the curves of one pose each: the model's line in SI units and the measured
traverses with the model's prediction for each of them. Its ``plot`` draws a grid,
one row per day, one column per direction: days are never pooled.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..plotting import pyplot
from ._plotting import LINE_STYLES, AxesArray, panel_grid
from ._units import step_scale

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

    from ..calibration import Calibration
    from ..measurements import Traverse

__all__ = ["Curve", "Panel", "StepFigure", "MODEL_ONLY"]

MODEL_ONLY = "model only"
"""The ``day`` of a panel drawn without measured traverses."""

_EMPTY = np.zeros(0)


@dataclass(frozen=True)
class Curve:
    """One pose: the model along a coordinate, and the traverses measured in that pose.

    Attributes
    ----------
    label : str
        The pose in words with units, e.g. ``"θ = -90°, ψ = 0°"``.
    x_model, gamma_model : ndarray
        The model's mean step (m or rad) along the plotted coordinate ``x`` (rad).
    x_data, gamma_data : ndarray
        Each measured traverse: ``x`` (rad; the interval's midpoint for a rotary
        traverse) and its average step ``|end - start| / steps`` (m or rad).
        ``gamma_data`` is empty for a model-only curve.
    gamma_pred : ndarray
        The calibration's prediction at each ``x_data``: its exact average over the
        traverse (``Calibration.predict``), m or rad.
    x_halfwidth : ndarray
        Half the traversed interval in ``x`` (rad); zeros for the prismatic joint.
    """

    label: str
    x_model: NDArray[np.float64]
    gamma_model: NDArray[np.float64]
    x_data: NDArray[np.float64] = field(default_factory=lambda: _EMPTY)
    gamma_data: NDArray[np.float64] = field(default_factory=lambda: _EMPTY)
    gamma_pred: NDArray[np.float64] = field(default_factory=lambda: _EMPTY)
    x_halfwidth: NDArray[np.float64] = field(default_factory=lambda: _EMPTY)


@dataclass(frozen=True)
class Panel:
    """The curves of one day and one direction (``day`` is :data:`MODEL_ONLY` without data)."""

    day: str
    direction: str
    curves: list[Curve]

    @property
    def n_traverses(self) -> int:
        """Measured traverses drawn in this panel."""
        return sum(c.gamma_data.size for c in self.curves)


@dataclass(frozen=True)
class StepFigure:
    """Measured average steps and the model, one panel per day and direction.

    Attributes
    ----------
    joint : int
    title : str
        The figure's subject, e.g. ``"Fig. 4: prismatic joint 3"``.
    x_label : str
        The plotted coordinate in words (its unit, degrees, is added by ``plot``).
    panels : list of Panel
        Ordered by day, then direction.
    sample : dict
        ``day -> "in-sample"`` and so on (:attr:`stickslip.report.sample.Sample.title`);
        a day not in it gets no label.
    """

    joint: int
    title: str
    x_label: str
    panels: list[Panel]
    sample: dict[str, str] = field(default_factory=dict)

    @property
    def days(self) -> list[str]:
        """The panel rows, in order."""
        return list(dict.fromkeys(p.day for p in self.panels))

    @property
    def directions(self) -> list[str]:
        """The panel columns, in order."""
        return list(dict.fromkeys(p.direction for p in self.panels))

    def panel(self, day: str, direction: str) -> Panel:
        """The panel of one day and direction (KeyError if there is none)."""
        for p in self.panels:
            if p.day == day and p.direction == direction:
                return p
        raise KeyError((day, direction))

    def plot(self, ax: Axes | Sequence[Axes] | AxesArray | None = None) -> AxesArray:
        """Draw one row per day, one column per direction; returns the ``(days, directions)`` Axes array.

        Lines: the model per pose (the legend names each pose by its colour and line style); filled
        markers: measured averages (a horizontal bar spans a rotary traverse's
        interval); open squares: the model's prediction for the same traverse. Steps
        in nm or µrad, the coordinate in degrees.
        """
        days, dirs = self.days, self.directions
        axes = panel_grid(len(days), len(dirs), ax, height=6.0)
        labels = list(dict.fromkeys(c.label for p in self.panels for c in p.curves))
        cmap = pyplot().get_cmap("tab10")
        # each pose a colour and a line style: told apart in grey print and by a colour-blind reader
        colour = {lab: (cmap(i % 10), LINE_STYLES[i % len(LINE_STYLES)]) for i, lab in enumerate(labels)}
        scale, unit = step_scale(self.joint)
        for r, day in enumerate(days):
            for c, d in enumerate(dirs):
                a = axes[r, c]
                try:
                    panel = self.panel(day, d)
                except KeyError:
                    panel = Panel(day, d, [])
                _draw_panel(a, panel, colour, scale)
                a.set_xlabel(f"{self.x_label} (degrees)")
                a.set_ylabel(f"step size γ{self.joint}{d} ({unit})")
                what = day if day == MODEL_ONLY else f"day {day}, {panel.n_traverses} traverses"
                sample = f" — {self.sample[day]}" if day in self.sample else ""
                a.set_title(f"{self.title}, direction {d}\n{what}{sample}", fontsize=10)
        return axes


def _draw_panel(a: Axes, panel: Panel, colour: dict[str, tuple[Any, str]], scale: float) -> None:
    """The lines, measured points and predictions of one panel, with its legend."""
    for cv in panel.curves:
        col, ls = colour[cv.label]
        a.plot(np.degrees(cv.x_model), cv.gamma_model * scale, ls=ls, color=col, lw=1.3, label=cv.label)
        if cv.gamma_data.size:
            xerr = np.degrees(cv.x_halfwidth) if np.any(cv.x_halfwidth > 0) else None
            a.errorbar(
                np.degrees(cv.x_data),
                cv.gamma_data * scale,
                xerr=xerr,
                fmt="o",
                color=col,
                ms=5,
                elinewidth=1.0,
                capsize=2,
            )
            a.plot(np.degrees(cv.x_data), cv.gamma_pred * scale, "s", color=col, mfc="none", ms=8, mew=1.2)
        elif cv.gamma_pred.size:  # model only: its average over each interval
            a.errorbar(
                np.degrees(cv.x_data),
                cv.gamma_pred * scale,
                xerr=np.degrees(cv.x_halfwidth),
                fmt="s",
                color=col,
                mfc="none",
                ms=7,
                capsize=2,
            )
    # one legend entry per pose (its colour), then what the markers mean
    if any(cv.gamma_data.size for cv in panel.curves):
        bars = any(np.any(cv.x_halfwidth > 0) for cv in panel.curves)
        a.plot([], [], "o", color="0.3", ms=5, label="measured" + (" (bar: traversed interval)" if bars else ""))
        a.plot([], [], "s", color="0.3", mfc="none", ms=8, label="model's prediction for the same traverse")
    elif any(cv.gamma_pred.size for cv in panel.curves):
        a.plot([], [], "s", color="0.3", mfc="none", ms=7, label="model's average over each π/6 interval")
    a.grid(True, alpha=0.3)
    if panel.curves:
        a.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    else:
        a.text(
            0.5,
            0.5,
            "no traverses" if panel.day != MODEL_ONLY else "not calibrated",
            ha="center",
            va="center",
            transform=a.transAxes,
        )


def predictions(calibration: Calibration, traverses: Sequence[Traverse]) -> NDArray[np.float64]:
    """The calibration's exact average step over each traverse (m or rad)."""
    return np.array([float(calibration.predict(t)) for t in traverses], dtype=float)


def pose_label(theta: float, psi: float, **fixed: float) -> str:
    """``"θ = -90°, ψ = 0°"`` plus any fixed joints given, in degrees or mm."""
    parts = [f"θ = {math.degrees(theta):.0f}°", f"ψ = {math.degrees(psi):.0f}°"]
    for name, v in fixed.items():
        parts.append(f"{name} = {v * 1e3:.0f} mm" if name == "q3" else f"{name} = {math.degrees(v):.0f}°")
    return ", ".join(parts)
