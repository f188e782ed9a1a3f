"""Validation: a calibration's predictions against measured traverses, beside the
constant-step comparator (relative errors, a table and a plot)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from matplotlib.axes import Axes

from .. import plotting
from ..measurements import Traverse
from .result import Calibration

# ----------------------------------------------------------------------------- validation


@dataclass(frozen=True)
class ValidationResult:
    """Model against the paper's constant-step comparator on a set of traverses.

    Attributes
    ----------
    traverses : list of Traverse
    measured, predicted, constant : ndarray
        Average steps (m or rad) measured, predicted by the model, and by the constant step.
    """

    traverses: list[Traverse]
    measured: NDArray[np.float64]
    predicted: NDArray[np.float64]
    constant: NDArray[np.float64]

    @property
    def model_error(self) -> NDArray[np.float64]:
        """Relative error of the model per traverse, ``predicted / measured - 1``."""
        return self.predicted / self.measured - 1.0

    @property
    def constant_error(self) -> NDArray[np.float64]:
        """Relative error of the constant step per traverse."""
        return self.constant / self.measured - 1.0

    def rows(self) -> list[dict[str, float]]:
        """Per joint: n, max and mean |relative error| of model and constant step (fractions)."""
        out = []
        joints = np.array([t.joint for t in self.traverses])
        for j in sorted(set(joints.tolist())):
            sel = joints == j
            me, ce = np.abs(self.model_error[sel]), np.abs(self.constant_error[sel])
            out.append(
                {
                    "joint": int(j),
                    "n": int(sel.sum()),
                    "model_max_rel_error": float(me.max()),
                    "model_mean_rel_error": float(me.mean()),
                    "constant_max_rel_error": float(ce.max()),
                    "constant_mean_rel_error": float(ce.mean()),
                }
            )
        return out

    def report(self) -> str:
        lines = ["joint   n   model max  model mean   const max  const mean"]
        for r in self.rows():
            lines.append(
                f"{r['joint']:>5} {r['n']:>3} {r['model_max_rel_error']:>10.2%} {r['model_mean_rel_error']:>11.2%} "
                f"{r['constant_max_rel_error']:>11.2%} {r['constant_mean_rel_error']:>11.2%}"
            )
        return "\n".join(lines)

    def __repr__(self) -> str:
        worst = ", ".join(f"joint {r['joint']}: {r['model_max_rel_error']:.2%}" for r in self.rows())
        return f"ValidationResult({len(self.traverses)} traverses; model max |relative error| {worst})"

    def _repr_html_(self) -> str:
        """Per joint: the model's and the constant step's relative errors (%), for Jupyter."""
        from ..notebook import html_table

        rows = [
            [r["joint"], r["n"]] + [f"{100 * r[k]:.2f}" for k in (
                "model_max_rel_error", "model_mean_rel_error", "constant_max_rel_error", "constant_mean_rel_error"
            )]
            for r in self.rows()
        ]
        return html_table(
            "validation: |predicted / measured average step - 1|",
            ["joint", "n", "model max (%)", "model mean (%)", "constant max (%)", "constant mean (%)"], rows,
        )

    def plot(self, ax: Axes | None = None) -> Axes:
        """Relative error of each traverse's average step, model against constant step; returns the Axes.

        Relative errors (%) put the prismatic (nm) and rotary (µrad) joints on one honest
        axis. Traverses are grouped by joint along x.
        """
        ax = plotting.axes(ax, (7, 4))
        x0 = 0
        for j in sorted({t.joint for t in self.traverses}):
            sel = np.array([t.joint == j for t in self.traverses])
            x = x0 + np.arange(int(sel.sum()))
            ax.plot(x, self.model_error[sel] * 100, "o", label=f"joint {j}: calibrated model")
            ax.plot(x, self.constant_error[sel] * 100, "x", label=f"joint {j}: constant step (paper's comparator)")
            x0 += int(sel.sum()) + 1
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel("traverse (grouped by joint)")
        ax.set_ylabel("predicted / measured average step − 1 (%)")
        ax.set_title(f"validation: model against constant step, {len(self.traverses)} traverses")
        ax.legend(fontsize="small")
        return ax


def validate(calibration: Calibration, traverses: Sequence[Traverse]) -> ValidationResult:
    """Compare the model and the constant-step comparator with measured traverses."""
    traverses = list(traverses)
    if not traverses:
        raise ValueError("no traverses to validate against")
    measured = np.array([t.gamma for t in traverses])
    predicted = calibration.predict_many(traverses)
    constant = np.array([calibration.constant_step(t.joint, t.direction) for t in traverses])
    return ValidationResult(traverses, measured, predicted, constant)
