"""Averaging model families by cross-validation on held-out poses (docs/models.md §3).

For each joint, every family of :mod:`stickslip.models.families` (and its variant with terms
shared by + and -) that the traverses can identify, with at least two poses per parameter
of a direction, is fitted to both directions. The poses are split into folds whose
held-out poses are as far from the poses their refit keeps as new poses of the workspace
are from the calibration's (:func:`~.folds.cv_folds`, nearest-neighbour distance
matching), and each fold is left out in turn: every family is refitted without it (from its
fit on all traverses) and predicts the fold's traverses.

With ``auto`` the families are averaged with pseudo-BMA+ weights from those held-out errors
(:func:`averaging_weights`), with a prior that puts half the weight on the paper's form
(:data:`PAPER_PRIOR`): where the held-out poses cannot tell the families apart, the
average stays near the paper's model. The average's own held-out error is measured
honestly (the weights used for a fold are computed without it); from it and the average's
residuals, its error model gives the error expected at new poses of the workspace, and if
that is larger than the paper's form's (from the form's own residuals and held-out errors),
the calibration falls back to the paper's form and says so. The error model of the
intervals (:func:`error_model`) comes from the residuals of the model returned and its
held-out errors against their distance from the poses kept; ``sigma_model`` is that
error's RMS over new poses of the workspace.

Asked for one family, that one is fitted and cross-validated the same way. A joint and
direction with too few poses for any family beyond the constant step falls back to it:
calibration never stops for lack of data once every joint and direction present has one
traverse. On a long table the choice is made on a sample of the poses and the families
chosen are refitted to every traverse (:data:`SELECTION_ROWS`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..measurements import Traverse
from ..models.families import FamilyModel, FamilyParams, FamilySpec, families_for, family_spec
from .drift import EndBias, SessionDrift, end_bias, session_drifts
from .errormodel import Predictive
from .family_fit import FamilyProblem, JointFit, full_rank, shared_names
from .folds import cv_folds, workspace_coordinates, workspace_pose_array
from .groups import JointData, TraverseGroups, group_traverses, nearest
from .intervals import STEP_NOISE, relative_sd
from .result import Calibration, CalibrationError, Provenance, _constant_step, _day_of

__all__ = [
    "CVScore",
    "JointSelection",
    "select_joint",
    "calibrate_families",
    "averaging_weights",
    "MIN_WEIGHT",
    "PAPER_PRIOR",
    "Progress",
]

Progress = Callable[[float, str], None]
"""A progress callback: ``(fraction done in [0, 1], what is being done)``."""

MIN_WEIGHT = 0.01
"""Families with a smaller weight are left out of the average (and the rest renormalised)."""

PAPER_PRIOR = 0.5
"""Prior weight of the paper's form (its variants together) in the average; the other families
share the rest equally. It decides only where the held-out errors cannot (a difference of ~2
in summed log density overturns it)."""

REFIT_ITERATIONS = 6
"""Levenberg-Marquardt iterations of a refit without one fold, started from the fit on all
traverses (a refit converges in 2-4; the cap bounds the cost)."""

EXACT_REFIT_ROWS = 400
"""Up to this many traverses of a joint, a fold's refit iterates (:data:`REFIT_ITERATIONS`); above,
it is one Gauss-Newton step from the fit on all traverses, in closed form (a fold is a small share
of the data, so one step lands close to the refit: a test checks it)."""

FULL_REFIT_ITERATIONS = 1
"""Levenberg-Marquardt steps of a chosen family's refit to every traverse of a long table, from its
fit on the sample. The sample's fit is close already: on a history of 1e5 traverses one step lands
within 4e-4 (relative) of the converged refit's predictions (two: 6e-6; the day-to-day scatter of a
step is ~3 %), and each step is a pass over every traverse (docs/models-log.md)."""

GROWTH = 2.0
"""How the model's error grows with the distance ``d`` from the calibrated poses in the intervals'
error model (:func:`error_model`): ``slope d^GROWTH``. 2: an interpolation error (a smooth misfit
between nodes grows with the square of the distance to the nearest); the linear growth used before
carried the held-out poses' errors, made at about twice new poses' distances, over in proportion
and made the intervals too wide (docs/models-log.md)."""

SELECTION_ROWS = 1500
"""Above this many traverses of a joint, the families are cross-validated and weighed on a seeded
sample of its poses (all traverses of each pose sampled, about this many), and the families chosen
are then refitted to every traverse: the choice costs the same on any table, the fits grow linearly."""


@dataclass(frozen=True)
class CVScore:
    """Cross-validation of one family (both directions of a joint).

    Attributes
    ----------
    family : str
        The selection's label: the family's name, ``+shared`` for the shared variant.
    n_params : int
    status : str
        ``"ok"``, or why the family was not scored (``"not identifiable"``, ``"too few poses"``).
    cv_rms, cv_max : float
        Root-mean-square and largest |relative error| of the predictions of held-out regions (nan if
        not scored).
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


@dataclass(frozen=True)
class JointSelection:
    """What :func:`select_joint` decided for one joint.

    Attributes
    ----------
    fit : JointFit
        The family whose parameters are shown (the one chosen, or the average's heaviest).
    scores : list of CVScore
    reason : str
        One line for people: what was chosen and why.
    mixture : dict
        ``label -> (weight, fit)`` of an average (empty for one family).
    cv_errors : ndarray
        Held-out relative errors of the model returned (every traverse of a region left out;
        empty when not cross-validated).
    fallback : bool
        Whether the average was expected to err more at new poses than the paper's form, which is
        returned (:meth:`_Evidence.expected`).
    n_folds : int
        Folds left out in turn (0: not cross-validated).
    floor, slope : float
        :func:`error_model` of the model returned (relative, 1; slope per unit of load-space
        distance); ``nan`` when not cross-validated.
    cv_distance : ndarray
        The distance of each held-out traverse's pose to the nearest pose its refit kept
        (load coordinates, 1), in the order of ``cv_errors``.
    sample : int
        Traverses the choice was made on when that was a sample (0: all of them).
    compared : tuple of float
        The RMS relative errors the average and the paper's form were expected to make at new
        poses of the workspace when ``auto`` compared them (``nan`` when it did not).
    """

    fit: JointFit
    scores: list[CVScore]
    reason: str
    mixture: dict[str, tuple[float, JointFit]]
    cv_errors: NDArray[np.float64]
    fallback: bool = False
    n_folds: int = 0
    floor: float = math.nan
    slope: float = math.nan
    cv_distance: NDArray[np.float64] = field(default_factory=lambda: np.empty(0))
    sample: int = 0
    compared: tuple[float, float] = (math.nan, math.nan)

    @property
    def cv_rms(self) -> float:
        e = self.cv_errors
        return float(np.sqrt(np.mean(e**2))) if e.size and np.all(np.isfinite(e)) else float("nan")


# ----------------------------------------------------------------------------- weights


def averaging_weights(
    errors: Mapping[str, NDArray[np.float64]],
    ids: NDArray[np.int64],
    draws: int = 1000,
    seed: int = 0,
    prior: Mapping[str, float] | None = None,
) -> dict[str, float]:
    """Pseudo-BMA+ weights of families from their held-out errors (Yao et al. 2018).

    Each family's held-out relative errors ``e`` get a normal predictive density with its
    own CV variance ``s² = mean(e²)``; the log densities are summed per unit left out
    (``ids``: the region of each error), ``elpd_k = sum_i lp_ik``. Weights
    ``∝ prior_k exp(elpd_k)`` would trust the CV estimate fully and pick one family almost
    always; pseudo-BMA+ averages them over Bayesian-bootstrap draws of the units
    (Dirichlet(1) weights ``α``, ``w = E_α[softmax(log prior + m Σ_i α_i lp_ik)]``), which
    accounts for how uncertain the comparison is with few regions. ``prior`` (default
    uniform) is normalised over the families given. Deterministic (fixed ``seed``).
    """
    labels = sorted(errors)
    if len(labels) == 1:
        return {labels[0]: 1.0}
    groups, inv = np.unique(ids, return_inverse=True)
    lp = np.empty((len(labels), len(groups)))
    for k, lab in enumerate(labels):
        e = np.asarray(errors[lab], dtype=float)
        s2 = max(float(np.mean(e**2)), 1e-12)
        point = -0.5 * math.log(2 * math.pi * s2) - 0.5 * e**2 / s2
        lp[k] = np.bincount(inv, weights=point, minlength=len(groups))
    pri = np.array([1.0 if prior is None else max(float(prior.get(lab, 0.0)), 1e-300) for lab in labels])
    log_prior = np.log(pri / pri.sum())
    rng = np.random.default_rng(seed)
    alpha = rng.dirichlet(np.ones(len(groups)), draws)  # (draws, units)
    z = len(groups) * alpha @ lp.T + log_prior  # (draws, families)
    z -= z.max(axis=1, keepdims=True)
    w = np.exp(z)
    w /= w.sum(axis=1, keepdims=True)
    mean = w.mean(axis=0)
    mean[mean < MIN_WEIGHT] = 0.0
    mean /= mean.sum()
    return {lab: float(x) for lab, x in zip(labels, mean, strict=True) if x > 0.0}


def _paper_prior(labels: Sequence[str]) -> dict[str, float]:
    """:data:`PAPER_PRIOR` shared by the paper's form's variants, the rest shared by the others."""
    paper = [lab for lab in labels if lab.partition("+")[0] == "paper"]
    rest = [lab for lab in labels if lab not in paper]
    if not paper or not rest:
        return {lab: 1.0 / len(labels) for lab in labels}
    return {**{lab: PAPER_PRIOR / len(paper) for lab in paper}, **{lab: (1 - PAPER_PRIOR) / len(rest) for lab in rest}}


# ----------------------------------------------------------------------------- cross-validation


def _cross_validate(
    prob: FamilyProblem, fit: JointFit, folds: NDArray[np.int64], n_folds: int
) -> NDArray[np.float64]:
    """Held-out relative errors of every traverse (directions in ``prob.dirs`` order), each predicted
    by the family refitted without its fold; empty if the family is not identifiable without one."""
    data = prob.data
    region = {d: folds[data.pose[d]] for d in prob.dirs}
    errs = {d: np.full(data.gamma[d].size, np.nan) for d in prob.dirs}
    exact = data.n_rows() <= EXACT_REFIT_ROWS
    for k in range(n_folds):
        train = {d: region[d] != k for d in prob.dirs}
        if not any(np.any(~t) for t in train.values()):
            continue
        rows = np.concatenate([train[d] for d in prob.dirs])
        if exact:
            x, _, jac, n_data = prob.solve(fit.x, train, REFIT_ITERATIONS)
            ok = int(rows.sum()) >= prob.n_params and full_rank(jac[:n_data][rows])
        else:
            x, ok = prob.one_step(fit, ~rows)
        if not ok:
            return np.empty(0)
        for d in prob.dirs:
            test = ~train[d]
            if np.any(test):
                errs[d][test] = prob.average(x, d, test) / data.gamma[d][test] - 1.0
    return np.concatenate([errs[d] for d in prob.dirs])


def _stats(e: NDArray[np.float64]) -> tuple[float, float]:
    if not e.size:
        return math.nan, math.nan
    if not np.all(np.isfinite(e)):
        return math.inf, math.inf
    return float(np.sqrt(np.mean(e**2))), float(np.max(np.abs(e)))


def _honest_mixture(
    errors: Mapping[str, NDArray[np.float64]], ids: NDArray[np.int64], prior: Mapping[str, float]
) -> NDArray[np.float64]:
    """The average's held-out errors with the weights for each fold computed without it."""
    out = np.empty_like(next(iter(errors.values())))
    for k in np.unique(ids):
        rest, here = ids != k, ids == k
        w = averaging_weights({lab: e[rest] for lab, e in errors.items()}, ids[rest], prior=prior)
        out[here] = sum((wt * errors[lab][here] for lab, wt in w.items()), np.zeros(int(here.sum())))
    return out


def held_out_distances(coords: NDArray[np.float64], folds: NDArray[np.int64]) -> NDArray[np.float64]:
    """Each pose's distance (load coordinates, 1) to the nearest pose outside its fold: how far the
    refit that predicted it had to reach."""
    out = np.full(len(coords), np.nan)
    for k in np.unique(folds):
        here = folds == k
        if np.all(here):
            continue
        out[here] = nearest(coords[here], coords[~here])[0]
    return out


def error_model(
    cv_errors: NDArray[np.float64], cv_distance: NDArray[np.float64], residuals: NDArray[np.float64]
) -> tuple[float, float]:
    """``(floor, slope)`` of the relative error at a new pose, ``sd(x) = sqrt(floor^2 + (slope d(x)^2)^2)``
    with ``d(x)`` its distance to the nearest calibrated pose in the load space.

    At a calibrated pose the error is the model's residual there (``floor^2 = mean(r^2)``); a
    held-out pose at distance ``d_i`` from the poses its refit kept erred by ``e_i``, so
    ``slope^2 = max(0, mean(e^2) - floor^2) / mean(d^4)``: the model's error between poses
    grows with the square of the distance (:data:`GROWTH`), as the error of interpolating a
    smooth function between nodes does, so that the errors measured at the held-out poses,
    farther from the rest than new poses are from the calibrated ones, are not carried
    over in proportion. Both are multiplied by ``t_{0.975, n-1} / 1.96`` (Student's t for
    the ``n`` held-out traverses they are estimated from), so that ``1.96 sd`` is the 95 %
    interval.
    """
    from scipy.special import stdtrit

    ok = np.isfinite(cv_errors) & np.isfinite(cv_distance)
    floor2 = float(np.mean(residuals**2)) if residuals.size else 0.0
    n = int(ok.sum())
    if n < 3:
        return math.sqrt(floor2), 0.0
    d4 = float(np.mean(cv_distance[ok] ** (2 * GROWTH)))
    slope2 = max(0.0, float(np.mean(cv_errors[ok] ** 2)) - floor2) / d4 if d4 > 0 else 0.0
    t = float(stdtrit(n - 1, 0.975)) / 1.959963984540054
    return t * math.sqrt(floor2), t * math.sqrt(slope2)


# ----------------------------------------------------------------------------- one joint


def select_joint(
    data: JointData,
    candidates: Sequence[str] | None = None,
    average: bool | None = None,
    progress: Progress | None = None,
) -> JointSelection:
    """Fit every identifiable family (separate and with shared terms) to both directions of one joint,
    cross-validate each on held-out poses, and average them (or fit the one asked for).

    ``candidates`` names families, ``"name+shared"`` for the shared variant. With ``average``
    (the default when no candidates are named) the families are averaged with
    :func:`averaging_weights` and the paper's form as the prior's favourite; the average
    is replaced by the paper's form when it is expected to err more at new poses.
    """
    if average is None:
        average = candidates is None
    if data.n_rows() > SELECTION_ROWS:
        return _select_on_sample(data, candidates, average, progress)
    variants = _variants(data.joint, len(data.dirs), candidates)
    design = cv_folds(data.coords, workspace_coordinates(data.joint))
    ev = _Evidence(data, design.folds, design.n_folds)
    known: dict[tuple[str, str, float | None], float] = {}
    for step, (spec, sh) in enumerate(variants):
        if progress is not None:
            progress(step / len(variants), f"joint {data.joint}: {spec.name}{'+shared' if sh else ''}")
        fit = ev.score(spec, sh, candidates is None, known)
        if fit is not None and spec.name == "paper" and not sh:  # where the other families start
            known = {(d, n, None if k is None else round(k, 9)): float(v)
                     for d in data.dirs for (n, k), v in zip(spec.names, fit.values[d], strict=True)}
    if progress is not None:
        progress(1.0, f"joint {data.joint}: weighing")
    return _decide(ev, average)


def _variants(joint: int, n_dirs: int, candidates: Sequence[str] | None) -> list[tuple[FamilySpec, tuple[str, ...]]]:
    """The families to fit (every one of ``joint``, or those named) and the terms each shares."""
    out: list[tuple[FamilySpec, tuple[str, ...]]] = []
    if candidates is None:
        for spec in families_for(joint):
            out.append((spec, ()))
            sh = shared_names(spec)
            if sh and n_dirs == 2:
                out.append((spec, sh))
        return out
    for c in candidates:
        name, _, tail = c.partition("+")
        spec = family_spec(joint, name)
        out.append((spec, shared_names(spec) if tail == "shared" and n_dirs == 2 else ()))
    return out


class _Evidence:
    """What the cross-validation of one joint's families found: each family's score, fit and held-out errors."""

    def __init__(self, data: JointData, folds: NDArray[np.int64], n_folds: int) -> None:
        self.data, self.folds, self.n_folds = data, folds, n_folds
        self.poses = {d: data.poses_of(d) for d in data.dirs}
        cv = n_folds >= 2
        self.ids = np.concatenate([folds[data.pose[d]] for d in data.dirs]) if cv else np.empty(0, dtype=np.int64)
        dist = held_out_distances(data.coords, folds) if cv else np.empty(0)
        self.row_dist = np.concatenate([dist[data.pose[d]] for d in data.dirs]) if cv else np.empty(0)
        self.scores: list[CVScore] = []
        self.fits: dict[str, JointFit] = {}
        self.cv_errors: dict[str, NDArray[np.float64]] = {}
        self._ws_d4: float | None = None

    def score(self, spec: FamilySpec, sh: tuple[str, ...], strict: bool,
              known: dict[tuple[str, str, float | None], float]) -> JointFit | None:
        """Fit and cross-validate one family; its fit if it is identifiable. ``strict``: at least two poses
        per parameter of a direction (a shared one counts half): fewer, and a family fits the poses it has
        and swings between them (a family asked for by name needs one more pose than parameters)."""
        dirs = self.data.dirs
        label = spec.name + ("+shared" if sh else "")
        own = sum(1 for n, _ in spec.names if n not in sh)
        n_sh = spec.n_params - own
        need = math.ceil(2 * (own + n_sh / max(len(dirs), 1))) if strict else own + 1
        short = [d for d in dirs if self.poses[d] < need] if spec.name != "constant" else []
        p_total = own * len(dirs) + n_sh
        if short:
            why = f"too few poses in {', '.join(short)} (needs {need})"
            self.scores.append(CVScore(label, p_total, why, math.nan, math.nan, math.nan))
            return None
        prob = FamilyProblem(spec, self.data, sh)
        fit = prob.fit(prob.initial(known))
        if not fit.identifiable:
            self.scores.append(CVScore(label, p_total, "not identifiable from these poses", math.nan, math.nan,
                                       fit.rms))
            return None
        self.fits[label] = fit
        e = _cross_validate(prob, fit, self.folds, self.n_folds) if self.n_folds >= 2 else np.empty(0)
        rms, mx = _stats(e)
        status = "ok" if np.isfinite(rms) else (
            "not identifiable without one of the folds" if self.n_folds >= 2 else "not cross-validated")
        if status == "ok":
            self.cv_errors[label] = e
        self.scores.append(CVScore(label, p_total, status, rms, mx, fit.rms))
        return fit

    def residuals(self, mix: Mapping[str, float]) -> NDArray[np.float64]:
        """The relative residuals of the weighted mixture ``mix`` of fits (traverses in direction order)."""
        return sum((w * np.concatenate(list(self.fits[lab].residuals.values())) for lab, w in mix.items()),
                   np.zeros(self.data.n_rows()))

    def expected(self, mix: Mapping[str, float], e: NDArray[np.float64]) -> float:
        """The RMS relative error the mixture ``mix`` (held-out errors ``e``) is expected to make at new poses
        of the workspace: its :func:`error_model` (in-sample floor, growth from the held-out errors) at each
        workspace pose's distance to the nearest calibrated pose (docs/models.md §3)."""
        if self._ws_d4 is None:
            d = nearest(workspace_coordinates(self.data.joint), self.data.coords)[0]
            self._ws_d4 = float(np.mean(d ** (2 * GROWTH)))
        floor, slope = error_model(e, self.row_dist, self.residuals(mix))
        return math.sqrt(floor**2 + slope**2 * self._ws_d4)

    def chosen(self, mix: dict[str, float], e: NDArray[np.float64], reason: str,
               fallback: bool = False, expected: tuple[float, float] = (math.nan, math.nan)) -> JointSelection:
        """The selection of the mixture ``mix`` (one family: weight 1) whose held-out errors are ``e``
        (``expected``: the average's and the paper's form's expected errors at new poses, when compared)."""
        floor, slope = error_model(e, self.row_dist, self.residuals(mix))
        top = max(mix, key=lambda k: mix[k])
        members = {lab: (w, self.fits[lab]) for lab, w in mix.items()} if len(mix) > 1 else {}
        scores = [dataclasses.replace(sc, weight=mix.get(sc.family, 0.0)) for sc in self.scores]
        return JointSelection(self.fits[top], scores, reason, members, e, fallback, self.n_folds, floor, slope,
                              self.row_dist, compared=expected)


def _select_on_sample(
    data: JointData, candidates: Sequence[str] | None, average: bool, progress: Progress | None
) -> JointSelection:
    """:func:`select_joint` on a sample of the poses (:data:`SELECTION_ROWS`), then the families it
    chose refitted to every traverse, from their fits on the sample."""
    sub = data.sample(SELECTION_ROWS)

    def part(frac: float, what: str) -> None:
        if progress is not None:
            progress(0.8 * frac, what)

    sel = select_joint(sub, candidates, average, part)
    mix = {lab: w for lab, (w, _) in sel.mixture.items()} or {sel.fit.label: 1.0}
    sample_fits = {lab: f for lab, (_, f) in sel.mixture.items()} or {sel.fit.label: sel.fit}
    full: dict[str, JointFit] = {}
    for n, (lab, f) in enumerate(sample_fits.items()):
        if progress is not None:
            progress(0.8 + 0.2 * n / len(sample_fits), f"joint {data.joint}: {lab} on all {data.n_rows()} traverses")
        full[lab] = FamilyProblem(f.spec, data, f.shared).fit(f.x, max_iter=FULL_REFIT_ITERATIONS)
    resid = sum((w * np.concatenate(list(full[lab].residuals.values())) for lab, w in mix.items()),
                np.zeros(data.n_rows()))
    floor, slope = error_model(sel.cv_errors, sel.cv_distance, resid) if sel.n_folds else (math.nan, math.nan)
    top = max(mix, key=lambda k: mix[k])
    reason = f"{sel.reason}; chosen on {sub.n_rows()} of the {data.n_rows()} traverses, refitted to all"
    return dataclasses.replace(
        sel, fit=full[top], mixture={lab: (w, full[lab]) for lab, (w, _) in sel.mixture.items()}, reason=reason,
        floor=floor, slope=slope, sample=sub.n_rows(),
    )


def _decide(ev: _Evidence, average: bool) -> JointSelection:
    """The average (or the paper's form where it is expected to err more at new poses), the best family, or
    without cross-validation the simplest one that fits."""
    where = f"{ev.n_folds} folds of {ev.data.n_poses} poses"
    cv = ev.cv_errors
    if len(cv) > 1 and average:
        return _average(ev, where)
    if cv:
        lab = min(cv, key=lambda k: (_stats(cv[k])[0], ev.fits[k].n_params))
        rms, mx = _stats(cv[lab])
        return ev.chosen({lab: 1.0}, cv[lab],
                         f"{lab}: held-out poses predicted with RMS {rms * 100:.2g} %, max {mx * 100:.2g} % ({where})")
    if ev.fits:
        name = min(ev.fits, key=lambda k: ev.fits[k].n_params)
        reason = f"{ev.data.n_poses} pose(s): the simplest identifiable family, not cross-validated"
        scores = [dataclasses.replace(sc, weight=1.0 if sc.family == name else 0.0) for sc in ev.scores]
        return JointSelection(ev.fits[name], scores, reason, {}, np.empty(0), False, 0)
    raise CalibrationError(f"joint {ev.data.joint}: no model family can be fitted to these traverses")


def _average(ev: _Evidence, where: str) -> JointSelection:
    """The families averaged, unless the average's expected error at new poses is above the paper's form's."""
    cv = ev.cv_errors
    prior = _paper_prior(list(cv))
    mix = averaging_weights(cv, ev.ids, prior=prior)
    honest = _honest_mixture(cv, ev.ids, prior)
    m_rms, m_max = _stats(honest)
    paper = min((lab for lab in cv if lab.partition("+")[0] == "paper"), key=lambda lab: _stats(cv[lab])[0],
                default=None)
    if paper is not None and set(mix) != {paper}:
        m_new, p_new = ev.expected(mix, honest), ev.expected({paper: 1.0}, cv[paper])
        if m_new > p_new:
            return ev.chosen({paper: 1.0}, cv[paper], (
                f"the paper's form: the average of the families is expected to err more at new poses "
                f"(RMS {m_new * 100:.2g} % against {p_new * 100:.2g} %, from each one's residuals and "
                f"held-out errors; CV RMS {m_rms * 100:.2g} % against {_stats(cv[paper])[0] * 100:.2g} %, "
                f"{where})"
            ), fallback=True, expected=(m_new, p_new))
        expected: tuple[float, float] = (m_new, p_new)
    else:
        expected = (math.nan, math.nan)
    if len(mix) == 1:
        top = next(iter(mix))
        return ev.chosen(mix, honest, f"{top}: the held-out poses weigh it alone (pseudo-BMA+); CV of the "
                         f"procedure: RMS {m_rms * 100:.2g} %, max {m_max * 100:.2g} % ({where})", expected=expected)
    parts = ", ".join(f"{lab} {w:.2f}" for lab, w in sorted(mix.items(), key=lambda kv: -kv[1]))
    return ev.chosen(mix, honest, (
        f"average of {len(mix)} families weighted by how they predicted held-out poses "
        f"(pseudo-BMA+, half the prior on the paper's form: {parts}); CV of the average: "
        f"RMS {m_rms * 100:.2g} %, max {m_max * 100:.2g} % ({where})"
    ), expected=expected)


# ----------------------------------------------------------------------------- calibration


def calibrate_families(
    traverses: Sequence[Traverse] | TraverseGroups,
    day: str | None = None,
    source: str | None = None,
    model: str = "auto",
    progress: Progress | None = None,
    provenance: Provenance | None = None,
) -> Calibration:
    """Calibrate every joint and direction with the families averaged (``model="auto"``) or a named one.

    The calibration records, per joint and direction, the family (or average), the
    covariance of its (heaviest) family's parameters, the CV error of every family
    (``selection``), the error model of its intervals (``predictive``) and the relative
    model error ``sigma_model`` (that model's RMS over new poses of the workspace, or the
    fit's RMS when it could not be cross-validated).
    """
    groups = group_traverses(traverses)
    if not groups:
        raise CalibrationError("no traverses to calibrate from")
    parts = _Parts()
    joints = groups.joints
    for n, j in enumerate(joints):

        def part(frac: float, what: str, n: int = n) -> None:
            if progress is not None:
                progress((n + frac) / len(joints), what)

        data = groups.joint_data(j)
        drifts = session_drifts(groups, j, STEP_NOISE)
        parts.add(data, select_joint(data, None if model == "auto" else [model], progress=part), drifts)
    if parts.predictive and not parts.drifted:
        parts.notes.append(NO_REPEAT_NOTE)
    for (j, d), m in parts.models.items():
        try:
            m.check_physical()
        except ValueError as e:
            parts.notes.append(f"joint {j}{d}: {e} (outside the calibrated poses)")
    consts = {k: _constant_step(k[0], k[1], m) for k, m in parts.models.items()}
    labels = {
        j: (f"average of {len(parts.models[(j, d)].members)}, mostly " if parts.models[(j, d)].members else "")
        + str(parts.selection[(j, d)]["chosen"])
        for (j, d) in parts.selection
    }
    method = "families (" + ", ".join(f"{j} {lab}" for j, lab in sorted(labels.items())) + ")"
    prov = provenance if provenance is not None else Provenance.of(groups.traverses, source, len(groups), ())
    prov = dataclasses.replace(prov, notes=(*prov.notes, *parts.notes))
    cal = Calibration(dict(parts.models), parts.stderr, consts, _day_of(groups.traverses, day), method, prov)
    cal.covariance.update(parts.cov)
    cal.sigma_model.update(parts.sigma)
    cal.selection.update(parts.selection)
    cal.predictive.update(parts.predictive)
    for key in parts.predictive:  # the model error at new poses: the interval's RMS over the workspace
        cal.sigma_model[key] = workspace_sigma(cal, *key)
        parts.selection[key]["sigma_workspace"] = cal.sigma_model[key]
    return cal


class _Parts:
    """A family calibration's pieces, joint by joint and direction by direction."""

    def __init__(self) -> None:
        self.models: dict[tuple[int, str], FamilyModel] = {}
        self.stderr: dict[tuple[int, str], NDArray[np.float64] | None] = {}
        self.cov: dict[tuple[int, str], NDArray[np.float64]] = {}
        self.sigma: dict[tuple[int, str], float] = {}
        self.selection: dict[tuple[int, str], dict[str, object]] = {}
        self.predictive: dict[tuple[int, str], Predictive] = {}
        self.notes: list[str] = []
        self.drifted = False  # a repeated pose measured some joint's drift within its session

    def add(self, data: JointData, sel: JointSelection, drifts: Mapping[str, SessionDrift | None]) -> None:
        """The models, uncertainties and selection record of one joint's directions (``drifts``: each
        direction's drift within the session, from its repeated poses, or ``None``)."""
        j, fit = data.joint, sel.fit
        sig = sel.cv_rms if np.isfinite(sel.cv_rms) else fit.rms
        ranked = sorted(sel.mixture.items(), key=lambda kv: -kv[1][0])
        cross_validated = sel.n_folds >= 2 and math.isfinite(sel.floor) and math.isfinite(sel.slope)
        kept = stored_poses(data.poses, data.coords) if cross_validated else np.empty((0, 5))
        for d in data.dirs:
            params = FamilyParams(fit.spec.name, j, tuple(float(v) for v in fit.values[d]))
            members = tuple(
                (w, FamilyParams(f.spec.name, j, tuple(float(v) for v in f.values[d]))) for _, (w, f) in ranked
            )
            averaged = len(members) > 1
            self.models[(j, d)] = FamilyModel(j, d, params, members=members if averaged else (),
                                              member_labels=tuple(lab for lab, _ in ranked) if averaged else ())
            drift = drifts.get(d)
            if cross_validated:
                bias = None if drift is None else end_bias(_late_errors(self.models[(j, d)], drift), sel.floor)
                self.predictive[(j, d)] = Predictive(sel.floor, sel.slope, kept, GROWTH,
                                                     *((0.0, 0.0) if bias is None else (bias.bias, bias.bias_sd)))
                if drift is not None and bias is not None:
                    self.notes.append(_drift_note(j, d, drift, bias))
                    self.drifted = True
            c = fit.cov[d]
            if c is not None:
                self.cov[(j, d)] = c
            self.stderr[(j, d)] = None if c is None else np.sqrt(np.clip(np.diag(c), 0.0, None))
            self.sigma[(j, d)] = float(sig) if sig > 0 else float("nan")
            self.selection[(j, d)] = {
                "chosen": fit.label, "shared": list(fit.shared), "reason": sel.reason,
                "scores": [s.as_dict() for s in sel.scores],
                "weights": {lab: w for lab, (w, _) in sel.mixture.items()} if len(sel.mixture) > 1
                else {fit.label: 1.0},
                "fallback": sel.fallback,
                "folds": sel.n_folds,
                "cv_rms": sel.cv_rms if math.isfinite(sel.cv_rms) else None,
            }
            if all(math.isfinite(v) for v in sel.compared):
                self.selection[(j, d)]["expected_rms"] = {"average": sel.compared[0], "paper": sel.compared[1]}
        self.notes.append(f"joint {j}: family {fit.label} — {sel.reason}")


NO_REPEAT_NOTE = (
    "no pose was traversed twice in a session: the intervals leave out the step's drift within it "
    "(a joint warming up); traverse the first pose again at the end of the session to measure it "
    "(docs/models.md §4)"
)
"""What ``calibrate`` says when its intervals could include the drift within a session but no repeat measured it."""


def _late_errors(model: FamilyModel, drift: SessionDrift) -> NDArray[np.float64]:
    """The model's relative residuals ``predicted / measured - 1`` at the drift's late repeats (``nan``
    where it would stall there)."""
    ts = drift.late
    cols = [np.array([getattr(t, k) for t in ts], dtype=float) for k in ("start", "end", "q1", "q2", "q3",
                                                                         "theta", "psi")]
    try:
        pred = model.average_gamma(*cols)
    except ValueError:  # NonPhysicalError: no prediction, no residual
        return np.full(len(ts), np.nan)
    out: NDArray[np.float64] = pred / np.array([t.gamma for t in ts]) - 1.0
    return out


def _drift_note(joint: int, direction: str, drift: SessionDrift, bias: EndBias) -> str:
    """What ``calibrate`` says of a joint and direction's drift within the session (docs/models.md §4)."""
    return (f"joint {joint}{direction}: a pose traversed again {drift.span:.0f} traverses later stepped "
            f"{drift.change * 100:+.2f} % ({drift.pairs} repeat(s)); the calibration predicts it "
            f"{bias.residual * 100:+.2f} % off (its error at a calibrated pose: {bias.misfit * 100:.2f} %): "
            f"the intervals add the bias beyond it, {bias.term * 100:.2f} %")


MAX_STORED_POSES = 400
"""Calibrated poses kept in a calibration for the distance term of its intervals, at most (a longer
table keeps a farthest-point sample of a seeded random sample of its poses: a pose is then about
that sample's spacing from one kept, and the intervals are wider by it, which is small where the
poses are that many)."""


def stored_poses(poses: NDArray[np.float64], coords: NDArray[np.float64]) -> NDArray[np.float64]:
    """The calibrated poses an interval measures its distance from (all, or a farthest-point sample)."""
    n = len(poses)
    if n <= MAX_STORED_POSES:
        return np.asarray(poses, dtype=float).copy()
    pool = np.sort(np.random.default_rng(0).choice(n, min(n, 10 * MAX_STORED_POSES), replace=False))
    x = coords[pool]
    pick = [0]
    d = np.sum((x - x[0]) ** 2, axis=1)
    for _ in range(MAX_STORED_POSES - 1):
        k = int(np.argmax(d))
        pick.append(k)
        d = np.minimum(d, np.sum((x - x[k]) ** 2, axis=1))
    return np.asarray(poses[pool[np.sort(pick)]], dtype=float)


def workspace_sigma(cal: Calibration, joint: int, direction: str) -> float:
    """The RMS relative standard deviation of full-range traverses at random workspace poses
    (:func:`~.folds.workspace_pose_array`): the calibration's expected error at a new pose."""
    from ..joints import JOINTS

    spec = JOINTS[joint]
    lo, hi = (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)
    w = workspace_pose_array(joint)
    sd = relative_sd(cal, joint, direction, w[:, 0], w[:, 1], w[:, 2], w[:, 3], w[:, 4], start=lo, end=hi)
    return float(np.sqrt(np.mean(sd**2)))
