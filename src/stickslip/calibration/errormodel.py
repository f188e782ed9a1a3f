"""The error model a calibration keeps for its prediction intervals (docs/models.md §4)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["MAX_RELATIVE_SD", "Predictive"]

MAX_RELATIVE_SD = 10.0
"""Largest relative standard deviation (1) an error model's terms and a calibration's ``sigma_model`` may hold:
an interval ten times the step says nothing more; a file holding more is refused (``slope``: ten times this)."""


@dataclass(frozen=True)
class Predictive:
    """How uncertain one joint and direction's predictions are, pose by pose (docs/models.md §4).

    The relative standard deviation of a predicted mean step at a pose is
    ``sqrt(floor^2 + (slope d^exponent)^2 + drift^2 + drift_sd^2)``, ``d`` the pose's distance
    to the nearest of ``poses`` in the space of the loads the step depends on
    (:func:`~.groups.load_coordinates_of`): the model's residual at a calibrated pose, growing
    with the distance as the cross-validation's held-out poses did
    (:func:`~.selection.error_model`; both directions of the joint together), and the bias the
    fit leaves at the end of its session, which no cross-validation of one session sees
    (:mod:`~.drift`; zero without a pose traversed twice in a session). Check traverses at random
    poses, not fitted, multiply all four by one scale per joint (:mod:`~.check`).

    Attributes
    ----------
    floor : float
        Relative error at a calibrated pose, 1.
    slope : float
        Growth of the relative error per unit of load-space distance to the power ``exponent``, 1.
    poses : ndarray, shape (n, 5)
        The calibrated poses (q1, q2, q3, theta, psi; SI), or a farthest-point sample of them.
    exponent : float
        How the model's error grows with the distance: 2 (an interpolation error, as the
        calibrations make it), 1 (linear: read from a file whose error model records no exponent).
    drift : float
        The relative bias the fit leaves at the end of its session, its posterior mean from the late
        repeats' residuals (:attr:`~.drift.EndBias.bias`), 1; 0 without a repeated pose (and in
        files before).
    drift_sd : float
        Its posterior standard deviation, 1 (``drift^2 + drift_sd^2`` is the bias's posterior mean
        square, :func:`~.drift.end_bias`).
    """

    floor: float
    slope: float
    poses: NDArray[np.float64]
    exponent: float = 1.0
    drift: float = 0.0
    drift_sd: float = 0.0

    def problem(self) -> str | None:
        """Why these terms cannot be an error model (one line), or None: a term beyond
        :data:`MAX_RELATIVE_SD`, or none at a calibrated pose (an exact prediction claimed there)."""
        lim = MAX_RELATIVE_SD
        if not (0.0 <= self.floor < lim and 0.0 <= self.slope < 10 * lim):
            return f"floor must be in [0, {lim:g}) and slope in [0, {10 * lim:g}), got {self.floor!r}, {self.slope!r}"
        if not (abs(self.drift) < lim and 0.0 <= self.drift_sd < lim):
            return (f"drift must be in (-{lim:g}, {lim:g}) and drift_sd in [0, {lim:g}), "
                    f"got {self.drift!r}, {self.drift_sd!r}")
        if not self.floor**2 + self.drift**2 + self.drift_sd**2 > 0.0:  # squared as relative_sd squares them
            return ("floor, drift and drift_sd are all zero (or too small to square): the intervals would claim an "
                    "exact prediction at the calibrated poses; a fitted model keeps its residual there")
        return None
