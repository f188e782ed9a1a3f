"""Validation figure: the model's and the constant step's relative error per traverse, per day.

The numbers are :func:`stickslip.calibration.validate`'s; this module splits them by
day and joint and labels them in-sample or out-of-sample (:mod:`.sample`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..calibration import validate
from ._plotting import AxesArray, panel_grid
from ._units import step_scale

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

    from ..calibration import Calibration
    from ..measurements import Traverse

__all__ = ["ValidationCell", "ValidationFigure", "validation_data"]


@dataclass(frozen=True)
class ValidationCell:
    """The traverses of one day and joint.

    Attributes
    ----------
    day : str
    joint : int
    measured : ndarray
        Measured average steps (m or rad).
    model_error, constant_error : ndarray
        Relative errors ``predicted / measured - 1`` of the model and of the constant step.
    """

    day: str
    joint: int
    measured: NDArray[np.float64]
    model_error: NDArray[np.float64]
    constant_error: NDArray[np.float64]

    @property
    def n(self) -> int:
        return int(self.measured.size)


@dataclass(frozen=True)
class ValidationFigure:
    """Relative errors per day (rows) and joint (columns), labelled with the sample kind."""

    days: list[str]
    joints: list[int]
    cells: list[ValidationCell]
    sample: dict[str, str] = field(default_factory=dict)
    """``day -> "in-sample"`` and so on (:attr:`stickslip.report.sample.Sample.title`)."""

    def cell(self, day: str, joint: int) -> ValidationCell | None:
        """The cell of one day and joint, None if that day has no traverse of the joint."""
        for c in self.cells:
            if c.day == day and c.joint == joint:
                return c
        return None

    def plot(self, ax: Axes | Sequence[Axes] | AxesArray | None = None) -> AxesArray:
        """Error (%) against the measured step (nm or µrad), one panel per day and joint; returns the Axes array."""
        axes = panel_grid(len(self.days), len(self.joints), ax, height=4.0)
        for r, day in enumerate(self.days):
            for c, j in enumerate(self.joints):
                _draw_cell(axes[r, c], self.cell(day, j), day, j, self.sample.get(day, ""))
        return axes


def _draw_cell(a: Axes, cell: ValidationCell | None, day: str, joint: int, sample: str) -> None:
    k, unit = step_scale(joint)
    # the sample label on a line of its own: "may overlap the calibration data" ran off a one-panel figure
    tag = f"\n{sample}" if sample else ""
    a.set_title(f"validation, joint {joint}, day {day}{tag}", fontsize=10)
    a.set_xlabel(f"measured average step ({unit})")
    a.set_ylabel("relative error of the prediction (%)")
    a.grid(True, alpha=0.3)
    a.axhline(0, color="k", lw=0.8)
    if cell is None:
        a.text(0.5, 0.5, "no traverses", ha="center", va="center", transform=a.transAxes)
        return
    m = cell.measured * k
    ce, me = cell.constant_error * 100, cell.model_error * 100
    # two decimals, as the page's table (html.pct): one decimal read a 0.02 % model as "0.0 %"
    a.plot(m, ce, "x", color="tab:red", ms=6, label=f"constant step: max |error| {np.max(np.abs(ce)):.2f} %")
    a.plot(m, me, "o", color="tab:blue", ms=5, label=f"model: max |error| {np.max(np.abs(me)):.2f} %")
    a.legend(fontsize=7, title=f"{cell.n} traverse{'' if cell.n == 1 else 's'}", title_fontsize=7)


def validation_data(
    calibration: Calibration, traverses: Sequence[Traverse], sample: Mapping[str, str] | None = None
) -> ValidationFigure:
    """Per-day, per-joint errors of :func:`stickslip.calibration.validate` for plotting.

    Only traverses of joints and directions the calibration models are used.
    ``sample``: ``day -> label`` for the panel titles
    (:func:`stickslip.report.sample.classify_days`).
    """
    ts = [t for t in traverses if (t.joint, t.direction) in calibration.models]
    v = validate(calibration, ts)
    days_arr = np.array([t.day for t in v.traverses])
    joints_arr = np.array([t.joint for t in v.traverses])
    days = sorted(set(days_arr.tolist()))
    joints = sorted(set(joints_arr.tolist()))
    cells = []
    for day in days:
        for j in joints:
            sel = (days_arr == day) & (joints_arr == j)
            if sel.any():
                cells.append(ValidationCell(day, j, v.measured[sel], v.model_error[sel], v.constant_error[sel]))
    return ValidationFigure(days, joints, cells, dict(sample or {}))
