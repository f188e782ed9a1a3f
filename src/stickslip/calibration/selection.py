"""Averaging (or choosing) model families by leave-one-pose-out cross-validation (docs/models.md §3).

For each joint, every family of :mod:`stickslip.models.families` (and its variant with terms
shared by + and -) that the traverses can identify, with at least two poses per
parameter of a direction, is fitted to both directions; then each *pose* (the fixed
joints and the tilt) beyond the paper's calibration poses is left out in turn, the
family is refitted on the rest and predicts the left-out traverses. With ``auto`` the
families are averaged with pseudo-BMA+ weights from those left-out errors
(:func:`averaging_weights`); asked for one family, that one is fitted. A joint and
direction with too few poses for any family beyond the constant step falls back to it:
calibration never stops for lack of data once every joint and direction present has one
traverse.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..measurements import Traverse
from ..models.families import FamilyModel, FamilyParams, FamilySpec, families_for, family_spec
from .family_fit import (
    Columns,
    FamilyFit,
    JointFit,
    fit_family,
    fit_joint,
    predict_columns,
    shared_names,
    traverse_columns,
)
from .result import Calibration, CalibrationError, Provenance, _constant_step, _day_of, _group

__all__ = [
    "CVScore", "select_family", "select_joint", "calibrate_families", "pose_groups", "averaging_weights",
    "PREFER_SIMPLER", "MIN_WEIGHT",
]

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
    weight : float
        The family's weight in the model average (0 if not in it; 1 if chosen alone).
    """

    family: str
    n_params: int
    status: str
    cv_rms: float
    cv_max: float
    fit_rms: float
    weight: float = 0.0

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
            "weight": float(self.weight),
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


def _criterion(s: CVScore) -> float:
    """What the selection minimises: the mean of the CV RMS and the CV largest error.

    The largest left-out error guards against a family that fits the poses it has and
    swings between them; the RMS keeps one unlucky pose from deciding alone.
    """
    return 0.5 * (s.cv_rms + s.cv_max)


def _anchor_groups(
    joint: int, by_dir: Mapping[str, Sequence[Traverse]], groups: dict[str, NDArray[np.int64]]
) -> frozenset[int]:
    """Pose groups at the paper's calibration poses: they anchor every family and are not held out
    (when at least three other poses are), so CV measures prediction at new poses in the workspace."""
    from .paper import only_paper_poses

    out = set()
    for d, ts in by_dir.items():
        for t, g in zip(ts, groups[d], strict=True):
            if only_paper_poses([t]) or (joint != 1 and _at_paper_pose(t)):
                out.add(int(g))
    return frozenset(out)


def _at_paper_pose(t: Traverse) -> bool:
    from .paper import PRISMATIC_PAPER_POSES, ROTARY_PAPER_POSES

    tol = 1e-3
    if abs(t.q1) > tol:
        return False
    if t.joint == 3:
        return any(abs(t.q2 - a) <= tol and abs(t.theta - b) <= tol and abs(t.psi - c) <= tol
                   for a, b, c in PRISMATIC_PAPER_POSES.values())
    return any(abs(t.q3 - a) <= 1e-5 and abs(t.theta - b) <= tol and abs(t.psi - c) <= tol
               for a, b, c in ROTARY_PAPER_POSES)


def _joint_pose_groups(joint: int, by_dir: Mapping[str, Sequence[Traverse]]) -> dict[str, NDArray[np.int64]]:
    keys: dict[tuple[float, ...], int] = {}
    out: dict[str, NDArray[np.int64]] = {}
    for d, ts in sorted(by_dir.items()):
        idx = []
        for t in ts:
            vals = [t.q1, t.q2, t.q3, t.theta, t.psi]
            vals[joint - 1] = 0.0
            idx.append(keys.setdefault(tuple(round(v, 4) for v in vals), len(keys)))
        out[d] = np.array(idx, dtype=np.int64)
    return out


def _cv_joint(
    spec: FamilySpec,
    joint: int,
    cols: dict[str, Columns],
    groups: dict[str, NDArray[np.int64]],
    full: JointFit,
    anchors: frozenset[int] = frozenset(),
) -> tuple[float, float]:
    rms, mx, _, _ = _cv_joint_errors(spec, joint, cols, groups, full, anchors)
    return rms, mx


def _cv_joint_errors(
    spec: FamilySpec,
    joint: int,
    cols: dict[str, Columns],
    groups: dict[str, NDArray[np.int64]],
    full: JointFit,
    anchors: frozenset[int] = frozenset(),
) -> tuple[float, float, NDArray[np.float64], NDArray[np.int64]]:
    """CV RMS and largest error, and the left-out relative errors with their pose group (in a fixed order)."""
    all_groups = np.unique(np.concatenate(list(groups.values())))
    held_out = [g for g in all_groups if g not in anchors]
    if len(held_out) < 3:
        held_out = list(all_groups)
    none = (np.nan, np.nan, np.empty(0), np.empty(0, dtype=np.int64))
    errs = {d: np.full(len(cols[d]), np.nan) for d in cols}
    for g in held_out:
        train = {d: cols[d].subset(groups[d] != g) for d in cols}
        if any(len(c) == 0 for c in train.values()):
            return none
        fit = fit_joint(spec, joint, train, full.shared, x0=full.values)
        if not fit.identifiable:
            return none
        for d in cols:
            test = groups[d] == g
            if np.any(test):
                held = cols[d].subset(test)
                errs[d][test] = predict_columns(spec, joint, fit.values[d], held) / held.gamma - 1.0
    keep = {d: np.isin(groups[d], held_out) for d in sorted(errs)}
    e = np.concatenate([errs[d][keep[d]] for d in sorted(errs)])
    ids = np.concatenate([groups[d][keep[d]] for d in sorted(errs)])
    if not np.all(np.isfinite(e)):
        return np.inf, np.inf, e, ids
    return float(np.sqrt(np.mean(e**2))), float(np.max(np.abs(e))), e, ids


MIN_WEIGHT = 0.01
"""Families with a smaller weight are left out of the average (and the rest renormalised)."""


def averaging_weights(
    errors: Mapping[str, NDArray[np.float64]], ids: NDArray[np.int64], draws: int = 1000, seed: int = 0
) -> dict[str, float]:
    """Pseudo-BMA+ weights of families from their leave-one-pose-out errors (Yao et al. 2018).

    Each family's left-out relative errors ``e`` get a normal predictive density with
    its own CV variance ``s² = mean(e²)``; the log densities are summed per pose (the
    unit left out), ``elpd_k = sum_i lp_ik``. Weights ``∝ exp(elpd_k)`` would trust the
    CV estimate fully and pick one family almost always; pseudo-BMA+ averages them over
    Bayesian-bootstrap draws of the poses (Dirichlet(1) weights ``α``,
    ``w = E_α[softmax(m Σ_i α_i lp_ik)]``), which accounts for how uncertain the CV
    comparison is with ~10 poses. Deterministic (fixed ``seed``).
    """
    labels = sorted(errors)
    if len(labels) == 1:
        return {labels[0]: 1.0}
    groups = np.unique(ids)
    lp = np.empty((len(labels), len(groups)))
    for k, lab in enumerate(labels):
        e = np.asarray(errors[lab], dtype=float)
        s2 = max(float(np.mean(e**2)), 1e-12)
        point = -0.5 * math.log(2 * math.pi * s2) - 0.5 * e**2 / s2
        lp[k] = [float(np.sum(point[ids == g])) for g in groups]
    rng = np.random.default_rng(seed)
    alpha = rng.dirichlet(np.ones(len(groups)), draws)  # (draws, poses)
    z = len(groups) * alpha @ lp.T  # (draws, families)
    z -= z.max(axis=1, keepdims=True)
    w = np.exp(z)
    w /= w.sum(axis=1, keepdims=True)
    mean = w.mean(axis=0)
    mean[mean < MIN_WEIGHT] = 0.0
    mean /= mean.sum()
    return {lab: float(x) for lab, x in zip(labels, mean, strict=True) if x > 0.0}


def select_joint(
    joint: int,
    by_dir: Mapping[str, Sequence[Traverse]],
    candidates: Sequence[str] | None = None,
    average: bool | None = None,
) -> tuple[JointFit, list[CVScore], str, dict[str, tuple[float, JointFit]], float]:
    """Fit every identifiable family (separate and with shared terms) to both directions of
    ``joint`` and weigh or pick them by leave-one-pose-out CV over both directions.

    ``candidates`` names families, ``"name+shared"`` for the shared variant. With
    ``average`` (the default when no candidates are named) the cross-validated families
    are averaged with :func:`averaging_weights`; otherwise one is picked (the smallest mean
    of CV RMS and largest error, a simpler one within 5 %). Returns ``(fit of the chosen
    or most weighted family, scores, reason, {label: (weight, fit)} of the average or empty,
    CV RMS error of what is returned)``.
    """
    if average is None:
        average = candidates is None
    cv_errors: dict[str, NDArray[np.float64]] = {}
    cv_ids: NDArray[np.int64] = np.empty(0, dtype=np.int64)
    cols = {d: traverse_columns(ts) for d, ts in sorted(by_dir.items()) if ts}
    groups = _joint_pose_groups(joint, {d: by_dir[d] for d in cols})
    anchors = _anchor_groups(joint, {d: by_dir[d] for d in cols}, groups)
    poses = {d: len(set(g.tolist())) for d, g in groups.items()}
    n_poses = len(set(np.concatenate(list(groups.values())).tolist()))
    variants: list[tuple[FamilySpec, tuple[str, ...]]] = []
    if candidates is None:
        for spec in families_for(joint):
            variants.append((spec, ()))
            sh = shared_names(spec)
            if sh and len(cols) == 2:
                variants.append((spec, sh))
    else:
        for c in candidates:
            name, _, tail = c.partition("+")
            spec = family_spec(joint, name)
            variants.append((spec, shared_names(spec) if tail == "shared" and len(cols) == 2 else ()))
    scores: list[CVScore] = []
    fits: dict[str, JointFit] = {}
    for spec, sh in variants:
        label = spec.name + ("+shared" if sh else "")
        own = sum(1 for n, _ in spec.names if n not in sh)
        n_sh = spec.n_params - own
        # at least two poses per parameter of a direction (a shared one counts half): fewer, and a
        # family fits the poses it has and swings between them (the benchmark's worst cases)
        need = math.ceil(2 * (own + n_sh / max(len(cols), 1))) if candidates is None else own + 1  # asked for: fit it
        short = [d for d in cols if poses[d] < need] if spec.name != "constant" else []
        p_total = own * len(cols) + n_sh
        if short:
            scores.append(CVScore(label, p_total, f"too few poses in {', '.join(short)} (needs {need})", np.nan, np.nan,
                                  np.nan))
            continue
        fit = fit_joint(spec, joint, cols, sh)
        if not fit.identifiable:
            scores.append(CVScore(label, p_total, "not identifiable from these poses", np.nan, np.nan, fit.rms))
            continue
        fits[label] = fit
        if n_poses >= 2:
            rms, mx, e, ids = _cv_joint_errors(spec, joint, cols, groups, fit, anchors)
        else:
            rms, mx, e, ids = np.nan, np.nan, np.empty(0), np.empty(0, dtype=np.int64)
        status = "ok" if np.isfinite(rms) else "not identifiable without one of the poses"
        if status == "ok":
            cv_errors[label] = e
            cv_ids = ids
        scores.append(CVScore(label, p_total, status, rms, mx, fit.rms))
    scored = [s for s in scores if s.status == "ok"]
    if scored and average and len(scored) > 1:
        weights = averaging_weights(cv_errors, cv_ids)
        mix = sum(w * cv_errors[lab] for lab, w in weights.items())
        assert isinstance(mix, np.ndarray)
        scores = [dataclasses.replace(sc, weight=weights.get(sc.family, 0.0)) for sc in scores]
        top = max(weights, key=lambda k: weights[k])
        mix_rms, mix_max = float(np.sqrt(np.mean(mix**2))), float(np.max(np.abs(mix)))
        parts = ", ".join(f"{lab} {w:.2f}" for lab, w in sorted(weights.items(), key=lambda kv: -kv[1]))
        reason = (
            f"average of {len(weights)} famil{'y' if len(weights) == 1 else 'ies'} weighted by their "
            f"leave-one-pose-out predictive density (pseudo-BMA+: {parts}); CV of the average: RMS "
            f"{mix_rms * 100:.2g} %, max {mix_max * 100:.2g} % over {n_poses} poses"
        )
        return fits[top], scores, reason, {lab: (w, fits[lab]) for lab, w in weights.items()}, mix_rms
    if scored:
        best = min(scored, key=_criterion)
        chosen = min(
            (s for s in scored if _criterion(s) <= PREFER_SIMPLER * _criterion(best)),
            key=lambda s: (s.n_params, _criterion(s)),
        )
        reason = (
            f"smallest leave-one-pose-out error (RMS {chosen.cv_rms * 100:.2g} %, max {chosen.cv_max * 100:.2g} % "
            f"over {n_poses} poses)"
        )
        if chosen.family != best.family:
            reason = (
                f"within {100 * (PREFER_SIMPLER - 1):.0f} % of the best CV error ({best.family}) with fewer "
                f"parameters (RMS {chosen.cv_rms * 100:.2g} %, max {chosen.cv_max * 100:.2g} %)"
            )
        scores = [dataclasses.replace(sc, weight=1.0 if sc.family == chosen.family else 0.0) for sc in scores]
        return fits[chosen.family], scores, reason, {}, chosen.cv_rms
    if fits:
        name = min(fits, key=lambda k: fits[k].n_params)
        reason = f"{n_poses} pose(s): the simplest identifiable family, not cross-validated"
        return fits[name], scores, reason, {}, float("nan")
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
    for j in sorted({j for j, _ in groups}):
        by_dir = {d: groups[(j, d)] for (jj, d) in groups if jj == j}
        candidates = None if model == "auto" else [model]
        fit, scores, reason, mixture, cv_rms = select_joint(j, by_dir, candidates)
        sig = cv_rms if np.isfinite(cv_rms) else fit.rms
        for d in sorted(by_dir):
            params = FamilyParams(fit.spec.name, j, tuple(float(v) for v in fit.values[d]))
            ranked = sorted(mixture.items(), key=lambda kv: -kv[1][0])
            members = tuple(
                (w, FamilyParams(f.spec.name, j, tuple(float(v) for v in f.values[d]))) for _, (w, f) in ranked
            )
            averaged = len(members) > 1
            models[(j, d)] = FamilyModel(
                j,
                d,
                params,
                members=members if averaged else (),
                member_labels=tuple(lab for lab, _ in ranked) if averaged else (),
            )
            c = fit.cov[d]
            if c is not None:
                cov[(j, d)] = c
                stderr[(j, d)] = np.sqrt(np.clip(np.diag(c), 0.0, None))
            else:
                stderr[(j, d)] = None
            sigma[(j, d)] = float(sig) if sig > 0 else float("nan")
            selection[(j, d)] = {
                "chosen": fit.label, "shared": list(fit.shared), "reason": reason,
                "scores": [s.as_dict() for s in scores],
                "weights": {lab: w for lab, (w, _) in mixture.items()} if len(mixture) > 1 else {fit.label: 1.0},
            }
        notes.append(f"joint {j}: family {fit.label} — {reason}")
    for (j, d), m in models.items():
        try:
            m.check_physical()
        except ValueError as e:
            notes.append(f"joint {j}{d}: {e} (outside the calibrated poses)")
    consts = {k: _constant_step(k[0], k[1], m) for k, m in models.items()}
    labels = {
        j: (f"average of {len(models[(j, d)].members)}, mostly " if models[(j, d)].members else "")
        + str(selection[(j, d)]["chosen"])
        for (j, d) in selection
    }
    method = "families (" + ", ".join(f"{j} {lab}" for j, lab in sorted(labels.items())) + ")"
    cal = Calibration(
        dict(models), stderr, consts, _day_of(traverses, day), method,
        Provenance.of(traverses, source, len(traverses), notes),
    )
    cal.covariance.update(cov)
    cal.sigma_model.update(sigma)
    cal.selection.update(selection)
    return cal
