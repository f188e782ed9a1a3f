"""Fig. 8 after the paper: the calibrated rotary joint simulated step by step over its range.

The simulation is :func:`stickslip.models.iter_traverse_steps` (the one step-by-step
loop of stickslip) on the calibrated Eq. (8); this module only records and draws it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..models import RotaryParams, StepProfile, iter_traverse_steps
from ..plotting import pyplot
from ._plotting import AxesArray, panel_grid
from ._units import position_scale, step_scale

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

    from ..calibration import Calibration

__all__ = ["StepRun", "StepSimulation", "step_simulation_data"]

_MAX_VERTICES = 3000  # a smooth curve needs no 100 000 vertices


@dataclass(frozen=True)
class StepRun:
    """One simulated traverse.

    Attributes
    ----------
    direction : str
    q3 : float
        Extension of the prismatic joint, m.
    start, end : float
        The traversed interval, rad.
    q, gamma : ndarray
        Position before each step and the step size, rad.
    gamma0 : float
        The step with no gravity torque at this q3, rad.
    """

    direction: str
    q3: float
    start: float
    end: float
    q: NDArray[np.float64]
    gamma: NDArray[np.float64]
    gamma0: float

    @property
    def steps(self) -> int:
        """Number of steps of the traverse."""
        return int(self.q.size)

    @property
    def average(self) -> float:
        """The traverse's average step, ``|end - start| / steps`` (rad)."""
        return abs(self.end - self.start) / self.steps


@dataclass(frozen=True)
class StepSimulation:
    """The paper's Fig. 8: simulated steps along full-range traverses, per direction and q3."""

    joint: int
    runs: list[StepRun]

    def plot(self, ax: Axes | Sequence[Axes] | AxesArray | None = None) -> AxesArray:
        """Two panels (− then +): step size (µrad) against step number; returns the ``(1, 2)`` Axes array."""
        axes = panel_grid(1, 2, ax, height=4.4)
        cmap = pyplot().get_cmap("tab10")
        k, unit = step_scale(self.joint)
        kq, uq = position_scale(self.joint)
        for a, d in zip(axes[0], ("-", "+"), strict=True):
            runs = [r for r in self.runs if r.direction == d]
            for i, r in enumerate(runs):
                c = cmap(i)
                n = np.arange(1, r.steps + 1)
                every = max(1, r.steps // _MAX_VERTICES)
                a.plot(
                    n[::every],
                    r.gamma[::every] * k,
                    "-",
                    color=c,
                    lw=1.2,
                    label=f"q3 = {r.q3 * 1e3:.0f} mm: {r.steps} steps",
                )
                a.axhline(
                    r.average * k, color=c, ls="--", lw=0.9, label=f"average (range / steps) {r.average * k:.2f} {unit}"
                )
                a.axhline(
                    r.gamma0 * k, color=c, ls=":", lw=0.9, label=f"γ0 (no gravity torque) {r.gamma0 * k:.2f} {unit}"
                )
            a.set_xlabel("step number")
            a.set_ylabel(f"step size γ{self.joint}{d} ({unit})")
            span = f"q{self.joint} {runs[0].start * kq:.0f}{uq} → {runs[0].end * kq:.0f}{uq}" if runs else ""
            a.set_title(f"Fig. 8: joint {self.joint}{d} simulated step by step\n{span}, θ = ψ = 0", fontsize=10)
            a.grid(True, alpha=0.3)
            if runs:
                a.legend(fontsize=7)
            else:
                a.text(0.5, 0.5, "not calibrated", ha="center", va="center", transform=a.transAxes)
        return axes


def step_simulation_data(
    calibration: Calibration, joint: int = 2, theta: float = 0.0, psi: float = 0.0
) -> StepSimulation:
    """Simulate the calibrated ``joint`` step by step over its full range (the paper's Fig. 8).

    Negative direction from the upper stop to the lower (π/6 → −7π/6 for joint 2),
    positive the other way, at q3 = 0 and 12 mm; the arm outstretched (q2 = −π/2) for
    joint 1. ``theta``, ``psi``: base tilt, rad.
    """
    spec = kin.joint_spec(joint)
    runs: list[StepRun] = []
    for d in ("-", "+"):
        try:
            model = calibration.model(joint, d)
        except KeyError:
            continue
        if not isinstance(model.params, RotaryParams):
            raise ValueError(f"joint {joint} is not rotary: Fig. 8 simulates a rotary joint")
        params = model.params
        start, end = (spec.upper, spec.lower) if d == "-" else (spec.lower, spec.upper)
        q1, q2 = (0.0, 0.0) if joint == 2 else (0.0, -math.pi / 2)
        for q3 in (0.0, kin.Q3_MAX):
            A, al, be = (float(np.asarray(x)) for x in model.rotary_coefficients(q1, q2, q3, theta, psi))
            walk = np.array(list(iter_traverse_steps(start, end, StepProfile(A, al, be).gamma)), dtype=float)
            g0 = float(np.asarray(params.at(q3)[0]))
            runs.append(StepRun(d, q3, start, end, walk[:, 0], walk[:, 1], g0))
    return StepSimulation(joint, runs)
