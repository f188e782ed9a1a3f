"""One entry point: :func:`calibrate` picks the paper's procedure or least squares per
joint and direction (``method="auto"``) and merges the parts."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

from ..measurements import StepSize, Traverse
from .check import apply_check, fitted_pose, other_day, repeated_row, unusable
from .groups import TraverseGroups, group_traverses
from .lsq import calibrate_lsq
from .paper import calibrate_paper, paper_applicable
from .result import Calibration, CalibrationError, Provenance, _day_of
from .selection import Progress

_OLD_METHOD_NAMES = {"seed": "paper", "seed-quadratic": "paper-quadratic"}
"""Method names of earlier versions (the paper was called "the seed"), still accepted."""


def calibrate(
    traverses: Sequence[Traverse] | TraverseGroups,
    method: str = "auto",
    day: str | None = None,
    source: str | None = None,
    model: str = "paper",
    progress: Progress | None = None,
    step_sizes: Sequence[StepSize] = (),
    check: Sequence[Traverse] = (),
) -> Calibration:
    """Calibrate every joint and direction present in ``traverses``.

    Parameters
    ----------
    traverses : sequence of Traverse
    method : {"auto", "paper", "paper-quadratic", "lsq"}
        ``auto`` uses the paper's procedure for every joint and direction whose
        calibration poses the table has, and least squares for the others (the
        calibration's method then reads e.g. ``"paper (3+ 3-), lsq (2+ 2-)"``). The names
        ``"seed"`` and ``"seed-quadratic"`` of earlier versions are still accepted.
    day : str, optional
        Session label (default: the latest day among the traverses).
    source : str, optional
        Where the traverses came from, for the provenance.
    model : str
        ``"paper"`` (default here, as before families existed; the command line defaults to
        ``"auto"``): the paper's models, calibrated by ``method``;
        ``"auto"``: the paper's procedure for every joint and direction whose traverses
        are all at the paper's calibration poses, and for the others every model family
        the data can identify, averaged by cross-validation on held-out poses
        (:func:`~stickslip.calibration.selection.calibrate_families`); or a family's name
        (docs/models.md §2) to fit that family everywhere. With ``method`` other than
        ``"auto"``, ``"auto"`` means ``"paper"`` (the method names how to calibrate the
        paper's models).
    progress : callable, optional
        ``progress(fraction, what)``, called as the model families are fitted and
        cross-validated (the part that takes seconds on a long table).
    step_sizes : sequence of StepSize
        Step sizes measured at poses (by a camera, ``stickslip camera calibrate``). Each
        joint and direction that has some is fitted by weighted least squares on the
        paper's model, its traverses and its step sizes together
        (:func:`calibrate_with_step_sizes`); the others as without them. None (the
        default): exactly the calibration without step sizes.
    check : sequence of Traverse
        Check traverses: at random poses (:func:`~.design.check_poses`), measured in the
        session after ``traverses`` and not fitted; each joint's intervals are scaled by how
        they erred (:func:`~.check.apply_check`, docs/models.md §4). The fit and its
        predictions are those without them. Empty (the default): no check. A check
        traverse at a pose ``traverses`` measured is refused (:func:`~.check.fitted_pose`), one
        listed twice (:func:`~.check.repeated_row`), one of another day than the calibration's
        (:func:`~.check.other_day`), and a check none of whose traverses has intervals to scale
        (:func:`~.check.unusable`).
    """
    if check:
        grouped = group_traverses(traverses)  # once: the calibration below takes the groups
        why = fitted_pose(check, grouped.traverses) or repeated_row(check)
        if why is not None:
            raise CalibrationError(why)
        cal = calibrate(grouped, method, day, source, model, progress, step_sizes)
        why = other_day(check, cal.day) or unusable(cal, check)
        if why is not None:
            raise CalibrationError(why)
        return apply_check(cal, check)
    if step_sizes:
        return calibrate_with_step_sizes(group_traverses(traverses).traverses, step_sizes, method, day, source, model,
                                         progress)
    groups = group_traverses(traverses)  # once: every stage below takes these groups
    traverses = groups.traverses
    method = _OLD_METHOD_NAMES.get(method, method)
    if method not in ("auto", "paper", "paper-quadratic", "lsq"):
        raise ValueError(f"unknown calibration method {method!r} (use auto, paper, paper-quadratic or lsq)")
    if model == "auto" and method != "auto":
        model = "paper"  # a method names how to calibrate the paper's models (as before families existed)
    if not groups:
        return calibrate_paper(groups, day, source)  # raises: no traverses
    prov = Provenance.of(traverses, source, len(traverses), ())  # the table hashed once
    if model != "paper":
        return _calibrate_models(groups, method, day, source, model, prov, progress)
    if method == "auto":
        seed_keys = {k for k in groups.keys if paper_applicable(groups.of(k))}
        if not seed_keys:
            method = "lsq"
        elif len(seed_keys) == len(groups.keys):
            method = "paper"
        else:
            rest = set(groups.keys) - seed_keys
            return _merge(calibrate_paper(groups.only(seed_keys), day, source, provenance=prov),
                          calibrate_lsq(groups.only(rest), day, source, provenance=prov), traverses, day, prov)
    if method == "paper":
        return calibrate_paper(groups, day, source, provenance=prov)
    if method == "paper-quadratic":
        return calibrate_paper(groups, day, source, rotary_inversion="paper-quadratic", provenance=prov)
    if method == "lsq":
        return calibrate_lsq(groups, day, source, provenance=prov)
    raise ValueError(f"unknown calibration method {method!r} (use auto, paper, paper-quadratic or lsq)")


def _merge(
    seed: Calibration, lsq: Calibration, traverses: Sequence[Traverse], day: str | None, prov: Provenance
) -> Calibration:
    """One calibration from a paper's-procedure part and a least-squares part (disjoint joints/directions)."""

    def keys(c: Calibration) -> str:
        return " ".join(f"{j}{d}" for j, d in sorted(c.models))

    notes = [
        f"the paper's procedure for {keys(seed)}; least squares for {keys(lsq)}, whose traverses are not all "
        "at the paper's calibration poses",
        *seed.provenance.notes,
        *lsq.provenance.notes,
    ]
    used = seed.provenance.rows_used + lsq.provenance.rows_used
    prov = dataclasses.replace(prov, rows_used=used, notes=tuple(notes))
    return Calibration(
        {**seed.models, **lsq.models},
        {**seed.stderr, **lsq.stderr},
        {**seed.constant_steps, **lsq.constant_steps},
        _day_of(traverses, day),
        f"paper ({keys(seed)}), lsq ({keys(lsq)})",
        prov,
    )




def _calibrate_models(
    groups: TraverseGroups,
    method: str,
    day: str | None,
    source: str | None,
    model: str,
    prov: Provenance,
    progress: Progress | None,
) -> Calibration:
    """``model="auto"`` or a family name: the paper's procedure where the data are exactly its poses,
    families elsewhere."""
    from .paper import only_paper_poses
    from .selection import calibrate_families

    if model != "auto":
        return calibrate_families(groups, day, source, model=model, progress=progress, provenance=prov)
    paper_keys = {k for k in groups.keys if only_paper_poses(groups.of(k))} if method in ("auto", "paper") else set()
    rest = set(groups.keys) - paper_keys
    if not rest:
        return calibrate_paper(groups, day, source, provenance=prov)
    fam = calibrate_families(groups if not paper_keys else groups.only(rest), day, source, model="auto",
                             progress=progress, provenance=prov)
    if not paper_keys:
        return fam
    merged = _merge(calibrate_paper(groups.only(paper_keys), day, source, provenance=prov), fam, groups.traverses,
                    day, prov)
    merged.method = merged.method.replace("lsq (", "families (")
    merged.covariance.update(fam.covariance)
    merged.sigma_model.update(fam.sigma_model)
    merged.selection.update(fam.selection)
    return merged


ASSUMED_MODEL_ERROR = {3: 0.075, 2: 0.02, 1: 0.02}
"""Relative model error (1 sigma) a traverse row is taken to carry beside a step size measured at a pose
(the values of :data:`stickslip.calibration.update.DEFAULT_SIGMA`: half the largest errors the paper reports)."""


def step_size_weight(row: StepSize) -> float:
    """A step size's weight beside traverses (weight 1): ``sigma_m / sqrt(sigma_m² + (sigma / gamma)²)``.

    Both carry the model's error ``sigma_m`` (:data:`ASSUMED_MODEL_ERROR`: the model cannot
    follow every pose); a step size carries its own measurement's too.
    """
    sm = ASSUMED_MODEL_ERROR.get(row.joint, 0.05)
    rel = row.sigma / row.gamma
    return float(sm / (sm * sm + rel * rel) ** 0.5)


def calibrate_with_step_sizes(
    traverses: Sequence[Traverse],
    step_sizes: Sequence[StepSize],
    method: str = "auto",
    day: str | None = None,
    source: str | None = None,
    model: str = "paper",
    progress: Progress | None = None,
) -> Calibration:
    """Calibrate from traverses and step sizes measured at poses.

    Each joint and direction with step sizes is fitted by least squares on the paper's
    model (:func:`calibrate_lsq`): its traverses with weight 1, each step size as a short
    traverse with weight :func:`step_size_weight`. The other joints and directions are
    calibrated from their traverses alone by :func:`calibrate` (``method``, ``model``).
    """
    keys = {(r.joint, r.direction) for r in step_sizes}
    mine = [t for t in traverses if (t.joint, t.direction) in keys]
    rest = [t for t in traverses if (t.joint, t.direction) not in keys]
    rows = mine + [r.as_traverse() for r in step_sizes]
    weights = [1.0] * len(mine) + [step_size_weight(r) for r in step_sizes]
    cam = calibrate_lsq(rows, day, source, weights=weights)
    labels = " ".join(f"{j}{d}" for j, d in sorted(keys))
    cam.method = f"lsq with step sizes ({labels})"
    note = (f"{len(step_sizes)} step size(s) measured at poses ({', '.join(sorted({r.method for r in step_sizes}))}) "
            f"beside {len(mine)} traverse(s) for {labels}, weighted by their uncertainty")
    extra = {"step_sizes": [dict(zip(("day", "joint", "direction", "q1", "q2", "q3", "theta", "psi", "gamma", "sigma",
                                      "steps", "method"), _row(r), strict=True)) for r in step_sizes]}
    if not rest:
        prov = Provenance.of(list(traverses), source, len(traverses), [note, *cam.provenance.notes])
        cam.provenance = _with_extra(prov, extra)
        cam.day = _day_of([*traverses, *(r.as_traverse() for r in step_sizes)], day)
        return cam
    other = calibrate(rest, method, day, source, model, progress)
    notes = [note, *other.provenance.notes, *cam.provenance.notes]
    merged = Calibration(
        {**other.models, **cam.models},
        {**other.stderr, **cam.stderr},
        {**other.constant_steps, **cam.constant_steps},
        _day_of(list(traverses), day),
        f"{other.method}, {cam.method}",
        _with_extra(Provenance.of(list(traverses), source, len(traverses), notes), extra),
    )
    merged.covariance.update(other.covariance)
    merged.sigma_model.update(other.sigma_model)
    merged.selection.update(other.selection)
    merged.predictive.update(other.predictive)
    return merged


def _row(r: StepSize) -> tuple[object, ...]:
    return (r.day, r.joint, r.direction, r.q1, r.q2, r.q3, r.theta, r.psi, r.gamma, r.sigma, r.steps, r.method)


def _with_extra(prov: Provenance, extra: Mapping[str, object]) -> Provenance:
    return dataclasses.replace(prov, extra={**prov.extra, **extra})
