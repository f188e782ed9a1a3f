"""Choosing a model family by leave-one-pose-out cross-validation (docs/models.md §3).

For each joint and direction, every family of :mod:`stickslip.families` that the
traverses can identify is fitted; then each *pose* (the fixed joints and the tilt; the
+ and - traverses of a pose are separate groups) is left out in turn, the family is
refitted on the rest and predicts the left-out traverses. The family with the
smallest root-mean-square relative CV error is chosen, except that a simpler family
within 5 % of that error is preferred (fewer parameters, less to go wrong outside the
data). A joint and direction with too few poses for any family beyond the constant
step falls back to it: calibration never stops for lack of data once every joint and
direction present has one traverse.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..families import FamilyModel, FamilyParams, FamilySpec, families_for, family_spec
from ..measurements import Traverse
from .families import FamilyFit, fit_family, predict_columns, traverse_columns
from .result import Calibration, CalibrationError, _constant_step, _day_of, _group, _provenance

__all__ = ["CVScore", "select_family", "calibrate_families", "pose_groups", "PREFER_SIMPLER"]

PREFER_SIMPLER = 1.05
"""A simpler family is chosen when its CV error is within this factor of the best."""


@dataclass(frozen=True)
class CVScore:
    """Cross-validation of one family for one joint and direction.

    Attributes
    ----------
    family : str
    n_params : int
    status : str
        ``"ok"``, or why the family was not scored (``"not identifiable"``, ``"too few poses"``).
    cv_rms, cv_max : float
        Root-mean-square and largest |relative error| of left-out predictions (nan if not scored).
    fit_rms : float
        RMS relative residual of the fit on all traverses.
    """

    family: str
    n_params: int
    status: str
    cv_rms: float
    cv_max: float
    fit_rms: float

    def as_dict(self) -> dict[str, object]:
        def num(x: float) -> float | None:
            return None if not np.isfinite(x) else float(x)

        return {
            "family": self.family,
            "n_params": self.n_params,
            "status": self.status,
            "cv_rms": num(self.cv_rms),
            "cv_max": num(self.cv_max),
            "fit_rms": num(self.fit_rms),
        }


def pose_groups(joint: int, ts: Sequence[Traverse]) -> NDArray[np.int64]:
    """Index of each traverse's pose (the fixed joints and tilt, to 1e-4), for leave-one-pose-out."""
    keys: dict[tuple[float, ...], int] = {}
    out = []
    for t in ts:
        vals = [t.q1, t.q2, t.q3, t.theta, t.psi]
        vals[joint - 1] = 0.0
        key = tuple(round(v, 4) for v in vals)
        out.append(keys.setdefault(key, len(keys)))
    return np.array(out, dtype=np.int64)


def _cv(spec: FamilySpec, joint: int, ts: Sequence[Traverse], full: FamilyFit) -> tuple[float, float]:
    cols = traverse_columns(ts)
    groups = pose_groups(joint, ts)
    errs = np.full(len(ts), np.nan)
    for g in np.unique(groups):
        test = groups == g
        train = [t for t, m in zip(ts, test, strict=True) if not m]
        fit = fit_family(spec, joint, train, x0=full.values, cols=cols.subset(~test))
        if not fit.identifiable:
            return np.nan, np.nan
        held = cols.subset(test)
        pred = predict_columns(spec, joint, fit.values, held)
        errs[test] = pred / held.gamma - 1.0
    if not np.all(np.isfinite(errs)):
        return np.inf, np.inf
    return float(np.sqrt(np.mean(errs**2))), float(np.max(np.abs(errs)))


def select_family(
    joint: int, ts: Sequence[Traverse], candidates: Sequence[str] | None = None
) -> tuple[FamilyFit, list[CVScore], str]:
    """Fit every identifiable family and pick one by leave-one-pose-out CV.

    Returns ``(fit of the chosen family on all traverses, scores, reason)``.
    """
    specs = families_for(joint) if candidates is None else [family_spec(joint, c) for c in candidates]
    n_poses = len(set(pose_groups(joint, ts).tolist()))
    scores: list[CVScore] = []
    fits: dict[str, FamilyFit] = {}
    for spec in specs:
        p = spec.n_params
        if n_poses < p + 1 and spec.name != "constant":
            scores.append(CVScore(spec.name, p, f"too few poses ({n_poses} for {p} parameters)", np.nan, np.nan,
                                  np.nan))
            continue
        fit = fit_family(spec, joint, ts)
        if not fit.identifiable:
            scores.append(CVScore(spec.name, p, "not identifiable from these poses", np.nan, np.nan, fit.rms))
            continue
        fits[spec.name] = fit
        if n_poses >= 2:
            rms, mx = _cv(spec, joint, ts, fit)
        else:
            rms, mx = np.nan, np.nan
        status = "ok" if np.isfinite(rms) else "not identifiable without one of the poses"
        scores.append(CVScore(spec.name, p, status, rms, mx, fit.rms))
    scored = [s for s in scores if s.status == "ok"]
    if scored:
        best = min(scored, key=lambda s: s.cv_rms)
        chosen = min(
            (s for s in scored if s.cv_rms <= PREFER_SIMPLER * best.cv_rms), key=lambda s: (s.n_params, s.cv_rms)
        )
        reason = f"smallest leave-one-pose-out error ({chosen.cv_rms * 100:.2g} % RMS over {n_poses} poses)"
        if chosen.family != best.family:
            reason = (
                f"within {100 * (PREFER_SIMPLER - 1):.0f} % of the best CV error ({best.family}: "
                f"{best.cv_rms * 100:.2g} %) with fewer parameters ({chosen.cv_rms * 100:.2g} % RMS)"
            )
        return fits[chosen.family], scores, reason
    if fits:  # identifiable but not cross-validatable (a single pose): the simplest
        name = min(fits, key=lambda k: fits[k].spec.n_params)
        return fits[name], scores, f"only {n_poses} pose: the simplest identifiable family, not cross-validated"
    raise CalibrationError(f"joint {joint}: no model family can be fitted to these traverses")


def calibrate_families(
    traverses: Sequence[Traverse],
    day: str | None = None,
    source: str | None = None,
    model: str = "auto",
) -> Calibration:
    """Calibrate every joint and direction with a family chosen by CV (``model="auto"``) or a named one.

    The calibration records, per joint and direction, the family, the covariance of its
    parameters, the CV error of every family (``selection``) and the relative model
    error ``sigma_model`` (the chosen family's CV RMS error, or its fit RMS when it could
    not be cross-validated) that prediction intervals use.
    """
    groups = _group(traverses)
    if not groups:
        raise CalibrationError("no traverses to calibrate from")
    models: dict[tuple[int, str], FamilyModel] = {}
    stderr: dict[tuple[int, str], NDArray[np.float64] | None] = {}
    cov: dict[tuple[int, str], NDArray[np.float64]] = {}
    sigma: dict[tuple[int, str], float] = {}
    selection: dict[tuple[int, str], dict[str, object]] = {}
    notes: list[str] = []
    for (j, d), ts in sorted(groups.items()):
        candidates = None if model == "auto" else [model]
        fit, scores, reason = select_family(j, ts, candidates)
        params = FamilyParams(fit.spec.name, j, tuple(float(v) for v in fit.values))
        models[(j, d)] = FamilyModel(j, d, params)
        if fit.cov is not None:
            cov[(j, d)] = fit.cov
            stderr[(j, d)] = np.sqrt(np.clip(np.diag(fit.cov), 0.0, None))
        else:
            stderr[(j, d)] = None
        chosen = next(s for s in scores if s.family == fit.spec.name)
        sig = chosen.cv_rms if np.isfinite(chosen.cv_rms) else fit.rms
        sigma[(j, d)] = float(sig) if sig > 0 else float("nan")
        selection[(j, d)] = {"chosen": fit.spec.name, "reason": reason, "scores": [s.as_dict() for s in scores]}
        notes.append(f"joint {j}{d}: family {fit.spec.name} — {reason}")
    for (j, d), m in models.items():
        try:
            m.params.check_physical()
        except ValueError as e:
            notes.append(f"joint {j}{d}: {e} (outside the calibrated poses)")
    consts = {k: _constant_step(k[0], k[1], m) for k, m in models.items()}
    method = "families (" + ", ".join(f"{j}{d} {m.family}" for (j, d), m in sorted(models.items())) + ")"
    cal = Calibration(
        dict(models), stderr, consts, _day_of(traverses, day), method,
        _provenance(traverses, source, len(traverses), notes),
    )
    cal.covariance.update(cov)
    cal.sigma_model.update(sigma)
    cal.selection.update(selection)
    return cal
