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

Friction also drifts, and with it how strongly a load changes the step, in both
directions of a joint alike: a second parameter per joint, the load sensitivity
``1 + lambda`` (every gravity-load term multiplied by it; prior ``N(0, load_drift^2)``),
enters the same linear-Gaussian update through ``d log gamma / d lambda`` at each new
traverse's pose. A traverse without load leaves it at the prior; a loaded + and -
pair pins it down.

Everything the new traverses cannot identify (the shape parameters, the joints and
directions without a new traverse) is kept from the prior; the uncertainty that
follows is carried into ``sigma_model``: ``sqrt(sigma_model^2 + v)``, ``v`` the posterior
variance of ``log s + g lambda`` (``g`` a full-range traverse's load gradient) averaged over
random workspace poses, so a load sensitivity the new traverses left at its prior widens it
(a joint and direction with no new traverse gets ``drift`` added instead).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..clock import age_days
from ..measurements import StepSize, Traverse
from ..models import JointModel, NonPhysicalError, PrismaticParams, RotaryParams
from ..models.families import FamilyModel, FamilyParams
from ..units import DIMENSIONLESS_PARAMETERS
from .design import workspace_poses
from .intervals import DEFAULT_SIGMA, STEP_NOISE, model_sigma, prediction_sd
from .result import Calibration, CalibrationError, Provenance, _constant_step, _day_of, _group

__all__ = [
    "DRIFT_PRIOR", "DEFAULT_SIGMA", "STEP_NOISE", "ScaleUpdate", "update_calibration", "scaled_model", "model_sigma",
    "prediction_sd", "day_drift",
]

DRIFT_PRIOR = 0.15
"""Default prior standard deviation of the day-to-day change of a joint's step scale (relative)."""


def day_drift(cal: Calibration) -> float:
    """The relative change of step scale a calibration carries into today: 0 for one made today
    (:func:`stickslip.clock.today`), :data:`DRIFT_PRIOR` for one from another or an unknown day.

    The one rule behind ``move``'s dead reckoning (:meth:`~stickslip.motion.tracking.JointTrack.fresh`),
    ``plan``'s and ``predict --interval``'s intervals: they add it to the model's relative error in quadrature.
    """
    return 0.0 if age_days(cal.day) == 0 else DRIFT_PRIOR

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


def scaled_model(model: JointModel, factor: float) -> JointModel:
    """``model`` with every step multiplied by ``factor`` (shape parameters unchanged)."""
    p = model.params
    if isinstance(model, FamilyModel):
        return model.map_params(lambda fp: fp.scaled(factor))
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


LOAD_PRIOR = 0.10
"""Default prior standard deviation of a day's change of a joint's load sensitivity (relative):
friction (humidity, wear) changes how much a given load changes the step, in both directions."""

_LOAD_TERMS = {"c", "e", "f", "h", "d", "t2", "m"}


def load_scaled(model: JointModel, factor: float) -> JointModel:
    """``model`` with every gravity-load term (c, e, f, h, m; rotary d, t2, e, f) multiplied by ``factor``."""
    p = model.params
    if isinstance(model, FamilyModel):

        def loaded(fp: FamilyParams) -> FamilyParams:
            vals = tuple(
                v * factor if n in _LOAD_TERMS else v for (n, _), v in zip(fp.names(), fp.values, strict=True)
            )
            return FamilyParams(fp.family, fp.joint, vals, fp.scale)

        return model.map_params(loaded)
    if isinstance(p, PrismaticParams):
        return JointModel(model.joint, model.direction, PrismaticParams(p.a, p.b, p.c * factor))
    if isinstance(p, RotaryParams):
        return JointModel(
            model.joint, model.direction, RotaryParams(p.gamma0, (p.d[0] * factor, p.d[1] * factor), p.knots)
        )
    raise TypeError(f"cannot scale a model with parameters {type(p).__name__}")


WORKSPACE_POSES = 64
"""Random workspace poses (:func:`~.design.workspace_poses`, seed 0) over which an update's uncertainty is
averaged into the constant ``sigma_model``: the load sensitivity's part of it differs from pose to pose."""


def _load_gradients(model: JointModel, poses: Sequence[kin.Pose]) -> NDArray[np.float64]:
    """``d log gamma_avg / d lambda`` of full-range traverses of ``model`` at ``poses`` (poses where the model
    stalls are left out)."""
    spec = kin.JOINTS[model.joint]
    ends = (spec.lower, spec.upper) if model.direction == "+" else (spec.upper, spec.lower)
    loaded = load_scaled(model, 1.0 + 1e-4)
    out: list[float] = []
    for p in poses:
        try:
            a, b = (float(m.average_gamma(*ends, *p)) for m in (model, loaded))
        except NonPhysicalError:
            continue
        out.append((math.log(b) - math.log(a)) / 1e-4)
    return np.array(out)


def _workspace_variance(model: JointModel, k: int, post_cov: NDArray[np.float64]) -> float:
    """Mean over :data:`WORKSPACE_POSES` random poses of the posterior variance of ``log gamma`` of direction
    ``k``'s full-range traverse: its log step scale's, its load sensitivity's times the pose's load gradient
    squared, and their covariance (at a pose without load only the first remains)."""
    g = _load_gradients(model, workspace_poses(model.joint, WORKSPACE_POSES))
    if g.size == 0:
        return float(post_cov[k, k])
    var = post_cov[k, k] + g**2 * post_cov[-1, -1] + 2.0 * g * post_cov[k, -1]
    return float(np.mean(np.maximum(var, 0.0)))


def _average(model: JointModel, ts: Sequence[Traverse]) -> np.ndarray:
    cols = {k: np.array([float(getattr(t, k)) for t in ts]) for k in ("start", "end", "q1", "q2", "q3", "theta", "psi")}
    return np.asarray(
        model.average_gamma(cols["start"], cols["end"], cols["q1"], cols["q2"], cols["q3"], cols["theta"], cols["psi"]),
        dtype=float,
    )


def _posterior(
    prior: Calibration,
    groups: dict[tuple[int, str], list[Traverse]],
    j: int,
    dirs: list[str],
    sig: dict[str, float],
    drift: float,
    load_drift: float,
    extra_var: dict[tuple[int, str], list[float]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Posterior mean and covariance of joint ``j``'s log step scales (one per direction) and its shared
    log load sensitivity, from the new traverses' log ratios to the prior's predictions (Gaussian, linearised).
    """
    rows: list[list[float]] = []
    resid: list[float] = []
    weights: list[float] = []
    for k, d in enumerate(dirs):
        ts = groups.get((j, d), [])
        if not ts:
            continue
        m0 = prior.models[(j, d)]
        base = _average(m0, ts)
        h = 1e-4
        grad = (np.log(_average(load_scaled(m0, 1.0 + h), ts)) - np.log(base)) / h
        meas = np.array([t.gamma for t in ts])
        extra = (extra_var or {}).get((j, d), [0.0] * len(ts))
        for r, g, ev in zip(np.log(meas / base), grad, extra, strict=True):
            row = [0.0] * (len(dirs) + 1)
            row[k] = 1.0
            row[-1] = float(g)
            rows.append(row)
            resid.append(float(r))
            weights.append(1.0 / (sig[d] ** 2 + ev))
    p0 = np.diag([1.0 / drift**2] * len(dirs) + [1.0 / load_drift**2])
    if rows:
        H, r_, w = np.array(rows), np.array(resid), np.array(weights)
        prec = p0 + H.T @ (H * w[:, None])
        post_cov = np.linalg.inv(prec)
        mean = post_cov @ (H.T @ (w * r_))
    else:
        post_cov, mean = np.linalg.inv(p0), np.zeros(len(dirs) + 1)
    return mean, post_cov


def update_calibration(
    prior: Calibration,
    traverses: Sequence[Traverse],
    drift: float = DRIFT_PRIOR,
    day: str | None = None,
    source: str | None = None,
    load_drift: float = LOAD_PRIOR,
    step_sizes: Sequence[StepSize] = (),
) -> tuple[Calibration, list[ScaleUpdate]]:
    """Update ``prior`` with new ``traverses`` (as few as one per joint and direction).

    Returns the updated calibration (method ``"<prior method> + update"``) and the
    update of each joint and direction. Raises :class:`CalibrationError` when a traverse
    is of a joint and direction the prior does not have (there is nothing to update).

    ``step_sizes`` (step sizes measured at poses, by a camera) count as traverses over
    their few steps, each with the variance ``sigma_model² + (sigma / gamma)²``: the
    model's error at that pose and the measurement's own.
    """
    if not drift > 0 or not math.isfinite(drift):
        raise ValueError(f"drift = {drift!r} must be a positive relative standard deviation")
    traverses, extra_var = _with_step_sizes(traverses, step_sizes)
    groups = _group(traverses)
    if not groups:
        raise CalibrationError("no new traverses to update the calibration with")
    _check_prior_has(prior, groups)
    state = _Updating.of(prior, len(traverses))
    for j in sorted({jj for jj, _ in prior.models}):
        _update_joint(state, prior, groups, j, drift, load_drift, extra_var or None)
    consts = {k: _constant_step(k[0], k[1], m) for k, m in state.models.items()}
    all_ts = list(traverses)
    prov = dataclasses.replace(
        Provenance.of(all_ts, source, len(all_ts), state.notes),
        extra={
            "prior": {"day": prior.day, "method": prior.method, "created": prior.created},
            "updates": [u.as_dict() for u in state.updates],
        },
    )
    cal = Calibration(state.models, state.stderr, consts, _day_of(all_ts, day), f"{prior.method} + update", prov)
    cal.sigma_model.update(state.sigma)
    cal.covariance.update(state.cov)
    cal.selection.update(prior.selection)
    return cal, state.updates


def _with_step_sizes(
    traverses: Sequence[Traverse], step_sizes: Sequence[StepSize]
) -> tuple[Sequence[Traverse], dict[tuple[int, str], list[float]]]:
    """The traverses with the step sizes appended as short ones, and each one's extra relative variance.

    Without step sizes the extra variances are empty (every traverse has the model's error alone).
    """
    extra_var: dict[tuple[int, str], list[float]] = {}
    if step_sizes:
        extra_var = {k: [0.0] * len(v) for k, v in _group(traverses).items()}
        for r in step_sizes:
            extra_var.setdefault((r.joint, r.direction), []).append(r.relative_sigma**2)
        traverses = [*traverses, *(r.as_traverse() for r in step_sizes)]
    return traverses, extra_var


def _check_prior_has(prior: Calibration, groups: dict[tuple[int, str], list[Traverse]]) -> None:
    """:class:`CalibrationError` naming each joint and direction with new traverses but no prior model."""
    if not prior.models:
        raise CalibrationError(
            f"the prior calibration ({prior.method or 'no method'}) has no step-size model to update (a stage's "
            "mean steps are recalibrated from their traverses: stickslip calibrate TABLE --rig RIG --arm NAME)"
        )
    missing = sorted(k for k in groups if k not in prior.models)
    if missing:
        have = ", ".join(f"{j}{d}" for j, d in sorted(prior.models))
        raise CalibrationError(
            "the prior calibration has no model for "
            + ", ".join(f"joint {j}{d}" for j, d in missing)
            + f" (it has: {have}); calibrate those from their own traverses, or leave their rows out (a camera's "
            "step sizes: stickslip camera calibrate --joints 3,2 measures no joint 1)"
        )


@dataclass
class _Updating:
    """The updated calibration's parts, filled joint by joint (copies of the prior's to begin with)."""

    models: dict[tuple[int, str], JointModel]
    sigma: dict[tuple[int, str], float]
    cov: dict[tuple[int, str], NDArray[np.float64]]
    stderr: dict[tuple[int, str], NDArray[np.float64] | None]
    updates: list[ScaleUpdate]
    notes: list[str]

    @classmethod
    def of(cls, prior: Calibration, n_traverses: int) -> _Updating:
        note = f"updated from the calibration of {prior.day or '?'} ({prior.method}) with {n_traverses} traverses"
        return cls(
            dict(prior.models), dict(prior.sigma_model), dict(prior.covariance), dict(prior.stderr), [], [note]
        )

    def rescale_errors(self, key: tuple[int, str], factor: float) -> None:
        """Scale the covariance and standard errors of a paper model's dimensional parameters by ``factor``."""
        model = self.models[key]
        if key in self.cov and not isinstance(model, FamilyModel):
            names = model.params.names()
            fvec = np.array([1.0 if n in DIMENSIONLESS_PARAMETERS else factor for n, _ in names])
            self.cov[key] = self.cov[key] * np.outer(fvec, fvec)
        se = self.stderr.get(key)
        if se is not None and not isinstance(model, FamilyModel):
            names = model.params.names()
            self.stderr[key] = np.array(
                [x if n in DIMENSIONLESS_PARAMETERS else x * factor for x, (n, _) in zip(se, names, strict=True)]
            )


def _update_joint(
    state: _Updating,
    prior: Calibration,
    groups: dict[tuple[int, str], list[Traverse]],
    j: int,
    drift: float,
    load_drift: float,
    extra_var: dict[tuple[int, str], list[float]] | None,
) -> None:
    """Joint ``j``'s step scales (one per direction) and load sensitivity, from its posterior, into ``state``."""
    dirs = sorted(d for jj, d in prior.models if jj == j)
    sig = {d: model_sigma(prior, j, d) for d in dirs}
    mean, post_cov = _posterior(prior, groups, j, dirs, {d: sig[d][0] for d in dirs}, drift, load_drift, extra_var)
    lam = float(mean[-1])
    for k, d in enumerate(dirs):
        key = (j, d)
        s0, assumed = sig[d]
        n_new = len(groups.get(key, []))
        factor = math.exp(float(mean[k]))
        sd = math.sqrt(float(post_cov[k, k]))
        if n_new == 0 and abs(lam) < 1e-12:
            state.sigma[key] = math.hypot(s0, drift)
            state.notes.append(f"joint {j}{d}: no new traverse; kept from the prior, uncertainty widened by the drift")
            continue
        state.models[key] = scaled_model(load_scaled(prior.models[key], 1.0 + lam), factor)
        state.rescale_errors(key, factor)
        state.sigma[key] = math.sqrt(s0**2 + _workspace_variance(prior.models[key], k, post_cov))
        if n_new:
            state.updates.append(ScaleUpdate(j, d, n_new, factor, sd))
        state.notes.append(
            f"joint {j}{d}: step scale x{factor:.4f} (σ {sd * 100:.2g} %), load sensitivity x{1 + lam:.4f}, "
            f"from {n_new} traverse(s)" + (" (prior model error assumed)" if assumed else "")
        )
