"""Bringing an earlier calibration up to date with a few new traverses (docs/models.md §5).

What drifts from day to day on a stick-slip joint is mostly the *scale* of its step
(piezo gain, contact wear, temperature, preload), while the shape of the load
dependence stays. So each joint and direction gets a step scale ``s`` with

    gamma_today(pose) = s * gamma_prior(pose)

and a Bayesian update of ``log s``: prior ``N(0, drift^2)`` (how far a day may move the
scale), each new traverse ``k`` measuring ``r_k = log(gamma_meas / gamma_prior_pred)``
with variance ``sigma_model^2`` (the prior calibration's model error: what it cannot
explain even on its own day). The posterior is normal:

    precision = 1 / drift^2 + sum_k 1 / sigma_model^2
    log s     = (sum_k r_k / sigma_model^2) / precision,   var(log s) = 1 / precision

Everything the new traverses cannot identify (the shape parameters, the joints and
directions without a new traverse) is kept from the prior; the uncertainty that
follows is carried into ``sigma_model`` (``sqrt(sigma_model^2 + var(log s))``; a joint
and direction with no new traverse gets ``drift`` added the same way).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..families import FamilyModel
from ..measurements import Traverse
from ..models import JointModel, PrismaticParams, RotaryParams
from .result import Calibration, CalibrationError, _constant_step, _day_of, _group, _provenance

__all__ = ["DRIFT_PRIOR", "ScaleUpdate", "update_calibration", "scaled_model", "model_sigma", "prediction_sd"]

DRIFT_PRIOR = 0.15
"""Default prior standard deviation of the day-to-day change of a joint's step scale (relative)."""

DEFAULT_SIGMA = {3: 0.075, 2: 0.02, 1: 0.02}
"""Relative model error (1 sigma) assumed where a calibration carries none (the paper's
procedure is exactly determined, so it has no residuals): half the largest errors the
paper reports for its models (15 % prismatic; rotary 2 %, taken as 4 %), so that ~95 %
intervals span those errors. Calibrate with more poses to measure it instead."""


@dataclass(frozen=True)
class ScaleUpdate:
    """The update of one joint and direction.

    Attributes
    ----------
    joint : int
    direction : str
    n : int
        New traverses used.
    scale : float
        Posterior mean step scale ``exp(E[log s])`` relative to the prior, 1.
    scale_sd : float
        Posterior standard deviation of ``log s`` (relative), 1.
    """

    joint: int
    direction: str
    n: int
    scale: float
    scale_sd: float

    def as_dict(self) -> dict[str, object]:
        return {
            "joint": self.joint,
            "direction": self.direction,
            "traverses": self.n,
            "scale": self.scale,
            "scale_sd": self.scale_sd,
        }


def model_sigma(cal: Calibration, joint: int, direction: str) -> tuple[float, bool]:
    """Relative model error of ``cal`` for a joint and direction, and whether it is assumed (not measured)."""
    s = cal.sigma_model.get((joint, direction))
    if s is not None and math.isfinite(s) and s > 0:
        return float(s), False
    return DEFAULT_SIGMA.get(joint, 0.05), True


STEP_NOISE = 0.03
"""Relative standard deviation of a single step assumed for short moves (docs/models.md §4)."""


def prediction_sd(cal: Calibration, joint: int, direction: str, n_steps: float | None = None) -> tuple[float, bool]:
    """Relative standard deviation of a prediction, and whether it rests on an assumed model error.

    The mean step: ``sigma_model`` (the leave-one-pose-out error of the chosen family,
    which already holds the parameters' estimation error). A move of ``n_steps`` steps adds
    the per-step scatter ``STEP_NOISE / sqrt(n_steps)``.
    """
    sig, assumed = model_sigma(cal, joint, direction)
    if n_steps is not None and n_steps > 0:
        sig = math.hypot(sig, STEP_NOISE / math.sqrt(n_steps))
    return sig, assumed


def scaled_model(model: JointModel, factor: float) -> JointModel:
    """``model`` with every step multiplied by ``factor`` (shape parameters unchanged)."""
    p = model.params
    if isinstance(model, FamilyModel):
        return FamilyModel(model.joint, model.direction, model.params.scaled(factor))
    if isinstance(p, PrismaticParams):
        return JointModel(model.joint, model.direction, PrismaticParams(p.a * factor, p.b, p.c * factor))
    if isinstance(p, RotaryParams):
        return JointModel(
            model.joint,
            model.direction,
            RotaryParams(
                (p.gamma0[0] * factor, p.gamma0[1] * factor), (p.d[0] * factor, p.d[1] * factor), p.knots
            ),
        )
    raise TypeError(f"cannot scale a model with parameters {type(p).__name__}")


def update_calibration(
    prior: Calibration,
    traverses: Sequence[Traverse],
    drift: float = DRIFT_PRIOR,
    day: str | None = None,
    source: str | None = None,
) -> tuple[Calibration, list[ScaleUpdate]]:
    """Update ``prior`` with new ``traverses`` (as few as one per joint and direction).

    Returns the updated calibration (method ``"<prior method> + update"``) and the
    update of each joint and direction. Raises :class:`CalibrationError` when a traverse
    is of a joint and direction the prior does not have (there is nothing to update).
    """
    if not drift > 0 or not math.isfinite(drift):
        raise ValueError(f"drift = {drift!r} must be a positive relative standard deviation")
    groups = _group(traverses)
    if not groups:
        raise CalibrationError("no new traverses to update the calibration with")
    missing = sorted(k for k in groups if k not in prior.models)
    if missing:
        have = ", ".join(f"{j}{d}" for j, d in sorted(prior.models))
        raise CalibrationError(
            "the prior calibration has no model for "
            + ", ".join(f"joint {j}{d}" for j, d in missing)
            + f" (it has: {have}); calibrate those from scratch"
        )
    models = dict(prior.models)
    sigma = dict(prior.sigma_model)
    cov = dict(prior.covariance)
    stderr = dict(prior.stderr)
    updates: list[ScaleUpdate] = []
    notes = [f"updated from the calibration of {prior.day or '?'} ({prior.method}) with {len(traverses)} traverses"]
    for key in sorted(prior.models):
        j, d = key
        sig, assumed = model_sigma(prior, j, d)
        ts = groups.get(key, [])
        if not ts:
            sigma[key] = math.hypot(sig, drift)
            notes.append(f"joint {j}{d}: no new traverse; kept from the prior, uncertainty widened by the drift")
            continue
        pred = prior.predict_many(ts)
        meas = np.array([t.gamma for t in ts])
        r = np.log(meas / pred)
        precision = 1.0 / drift**2 + len(ts) / sig**2
        mean = float(np.sum(r) / sig**2 / precision)
        sd = 1.0 / math.sqrt(precision)
        factor = math.exp(mean)
        models[key] = scaled_model(prior.models[key], factor)
        if key in cov:
            p = models[key].params
            # only step-valued parameters scale; b, b2 are ratios
            names = p.names()
            f = np.array([1.0 if n in ("b", "b2", "k") or isinstance(models[key], FamilyModel) else factor
                          for n, _ in names])
            cov[key] = cov[key] * np.outer(f, f)
        se = stderr.get(key)
        if se is not None and not isinstance(models[key], FamilyModel):
            names = models[key].params.names()
            stderr[key] = np.array([s if n in ("b", "b2", "k") else s * factor for s, (n, _) in zip(se, names, strict=True)])
        sigma[key] = math.hypot(sig, sd)
        updates.append(ScaleUpdate(j, d, len(ts), factor, sd))
        notes.append(
            f"joint {j}{d}: step scale x{factor:.4f} (± {sd * 100:.2g} %) from {len(ts)} traverse(s)"
            + (" (prior model error assumed)" if assumed else "")
        )
    consts = {k: _constant_step(k[0], k[1], m) for k, m in models.items()}
    all_ts = list(traverses)
    prov = _provenance(all_ts, source, len(all_ts), notes)
    prov["prior"] = {"day": prior.day, "method": prior.method, "created": prior.created}
    prov["updates"] = [u.as_dict() for u in updates]
    cal = Calibration(models, stderr, consts, _day_of(all_ts, day), f"{prior.method} + update", prov)
    cal.sigma_model.update(sigma)
    cal.covariance.update(cov)
    cal.selection.update(prior.selection)
    return cal, updates
