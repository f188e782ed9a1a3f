"""Prediction intervals: how uncertain a calibration's predicted step is, pose by pose (docs/models.md §4).

A family calibration keeps, per joint and direction, a :class:`~.result.Predictive`: the
relative error at a calibrated pose (the model's residual there), how fast the error grew
with the distance from the poses a refit kept in the cross-validation, and the calibrated
poses. The relative standard deviation of a predicted mean step at a pose is
``sqrt(floor^2 + (slope d^2)^2 + drift^2 + drift_sd^2)``, ``d`` the pose's distance to the
nearest calibrated pose in the space of the loads the step depends on: narrow where the
calibration measured, wider between and beyond its poses (``d`` to the first power in a file
whose error model records no ``exponent``); ``drift`` the bias the fit leaves at the end of its
session, where a user predicts, from the residual of a pose traversed again there
(:mod:`.drift`; a bias of one sign for every prediction of the session, so it adds to the
interval as a bias adds to the mean square error, in quadrature, with its posterior standard
deviation; zero without a repeat). The
same standard deviation is what ``predict --interval`` and ``plan`` print (``1.96 sigma``) and
what the tracking filter (:mod:`stickslip.motion.tracking`) starts its step scales' variance
from in a pose.

A calibration without it (the paper's exactly determined procedure, a file from before,
an updated calibration) has one relative model error per joint and direction,
``sigma_model``, or an assumed one (:data:`DEFAULT_SIGMA`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .groups import load_coordinates_of, nearest
from .result import Calibration

__all__ = ["DEFAULT_SIGMA", "STEP_NOISE", "model_sigma", "relative_sd", "prediction_sd"]

DEFAULT_SIGMA = {3: 0.075, 2: 0.02, 1: 0.02}
"""Relative model error (1 sigma) assumed where a calibration carries none (the paper's
procedure is exactly determined, so it has no residuals): half the largest errors the
paper reports for its models (15 % prismatic; rotary 2 %, taken as 4 %), so that ~95 %
intervals span those errors. Calibrate with more poses to measure it instead."""

STEP_NOISE = 0.03
"""Relative standard deviation of a single step assumed for short moves (docs/models.md §4)."""


def model_sigma(cal: Calibration, joint: int, direction: str) -> tuple[float, bool]:
    """Relative model error of ``cal`` for a joint and direction over the workspace, and whether it is
    assumed (not measured)."""
    s = cal.sigma_model.get((joint, direction))
    if s is not None and math.isfinite(s) and s > 0:
        return float(s), False
    return DEFAULT_SIGMA.get(joint, 0.05), True


def relative_sd(
    cal: Calibration,
    joint: int,
    direction: str,
    q1: ArrayLike,
    q2: ArrayLike,
    q3: ArrayLike,
    theta: ArrayLike,
    psi: ArrayLike,
    start: ArrayLike | None = None,
    end: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Relative standard deviation (1) of predicted mean steps of ``joint`` in ``direction``, vectorised.

    ``start``/``end`` given: of the average over those traverses; else of the step at the pose
    (the moving joint at its own column). Where the calibration keeps no
    :class:`~.result.Predictive` for this joint and direction: its constant ``sigma_model``
    (or the assumed one).
    """
    arrays = [np.asarray(x, dtype=float) for x in (q1, q2, q3, theta, psi)]
    if start is not None and end is not None:
        arrays += [np.asarray(start, dtype=float), np.asarray(end, dtype=float)]
    cols = np.broadcast_arrays(*arrays)
    shape = cols[0].shape
    pred = cal.predictive.get((int(joint), direction))
    if pred is None or len(pred.poses) == 0:
        return np.full(shape, model_sigma(cal, joint, direction)[0])
    flat = [np.ravel(c) for c in cols[:5]]
    here = load_coordinates_of(joint, np.stack(flat, axis=1))
    d = nearest(here, load_coordinates_of(joint, pred.poses))[0]
    var = pred.floor**2 + (pred.slope * d**pred.exponent) ** 2 + pred.drift**2 + pred.drift_sd**2
    out: NDArray[np.float64] = np.sqrt(var).reshape(shape)
    return out


def prediction_sd(
    cal: Calibration,
    joint: int,
    direction: str,
    n_steps: float | None = None,
    pose: Sequence[float] | None = None,
    span: tuple[float, float] | None = None,
) -> tuple[float, bool]:
    """Relative standard deviation of a prediction, and whether it rests on an assumed model error.

    The mean step: at ``pose`` (q1, q2, q3, theta, psi; the moving joint's own column is where
    the step is asked, or ``span`` = (from, to) along it for a move's average) from the
    calibration's :class:`~.result.Predictive`, else its constant ``sigma_model``. A move of
    ``n_steps`` steps adds the per-step scatter ``STEP_NOISE / sqrt(n_steps)``.
    """
    sig, assumed = model_sigma(cal, joint, direction)
    if pose is not None and (int(joint), direction) in cal.predictive:
        se = (None, None) if span is None else span
        q1, q2, q3, theta, psi = (float(v) for v in pose)
        sig = float(relative_sd(cal, joint, direction, q1, q2, q3, theta, psi, start=se[0], end=se[1]).reshape(-1)[0])
    if n_steps is not None and n_steps > 0:
        sig = math.hypot(sig, STEP_NOISE / math.sqrt(n_steps))
    return sig, assumed
