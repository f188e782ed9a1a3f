"""One entry point: :func:`calibrate` picks the paper's procedure or least squares per
joint and direction (``method="auto"``) and merges the parts."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from ..measurements import Traverse
from .groups import TraverseGroups, group_traverses
from .lsq import calibrate_lsq
from .paper import calibrate_paper, paper_applicable
from .result import Calibration, Provenance, _day_of
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
    """
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
