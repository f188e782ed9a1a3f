"""JSON fields of a calibration beyond format version 1: model families, covariances,
model errors and the family selection (docs/models.md §4). Older files have none of
them and load unchanged."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..models import JointModel, direction_label
from ..models.families import FamilyModel, FamilyParams, family_spec
from ..records import check_unit, finite_number
from .errormodel import MAX_RELATIVE_SD, Predictive

__all__ = ["ExtFields", "ext_fields", "read_ext_fields"]


class ExtFields(Protocol):
    """What these fields are read from and written into: a :class:`~.result.Calibration`."""

    models: dict[tuple[int, str], JointModel]
    stderr: dict[tuple[int, str], NDArray[np.float64] | None]
    covariance: dict[tuple[int, str], NDArray[np.float64]]
    sigma_model: dict[tuple[int, str], float]
    selection: dict[tuple[int, str], dict[str, object]]
    predictive: dict[tuple[int, str], Predictive]


MAX_POSES = 10_000
"""Calibrated poses an ``uncertainty`` entry may list (a calibration writes at most 400)."""


def _key(j: int, d: str) -> dict[str, object]:
    return {"joint": j, "direction": d}


def ext_fields(cal: ExtFields) -> dict[str, object]:
    """``families``, ``uncertainty`` and ``selection`` entries for :meth:`Calibration.to_dict`."""
    fams: list[dict[str, object]] = []
    for (j, d), m in sorted(cal.models.items()):
        if not isinstance(m, FamilyModel):
            continue
        p = m.params
        se = cal.stderr.get((j, d))
        fams.append(
            {
                **_key(j, d),
                "family": p.family,
                "scale": p.scale,
                "parameters": [
                    {
                        "name": name,
                        "q3": q3,
                        "value": float(v),
                        "stderr": None if se is None or not math.isfinite(float(se[i])) else float(se[i]),
                        "unit": p.unit(name),
                    }
                    for i, ((name, q3), v) in enumerate(zip(p.names(), p.values, strict=True))
                ],
            }
        )
        if m.members:  # a model average: every family with its weight (docs/models.md §3)
            labels = m.member_labels or (None,) * len(m.members)
            fams[-1]["members"] = [
                {
                    "weight": float(w),
                    "family": mp.family,
                    **({"label": lab} if lab else {}),  # e.g. normal+shared: which variant of the family
                    "scale": mp.scale,
                    "parameters": [
                        {"name": name, "q3": q3, "value": float(v), "unit": mp.unit(name)}
                        for (name, q3), v in zip(mp.names(), mp.values, strict=True)
                    ],
                }
                for (w, mp), lab in zip(m.members, labels, strict=True)
            ]
    unc = _uncertainty_entries(cal)
    out: dict[str, object] = {}
    if fams:
        out["families"] = fams
    if unc:
        out["uncertainty"] = unc
    if cal.selection:
        out["selection"] = [{**_key(*k), **v} for k, v in sorted(cal.selection.items())]
    return out


def _uncertainty_entries(cal: ExtFields) -> list[dict[str, object]]:
    """The ``uncertainty`` entries: per joint and direction the model error, the covariance and the error
    model of the intervals (docs/models.md §4): ``sqrt(floor^2 + (slope d^exponent)^2 + drift^2 + drift_sd^2)``,
    ``d`` the load-space distance to the nearest of the calibrated ``poses`` (q1, q2, q3, theta, psi; SI),
    ``drift`` the bias the fit leaves at the session's end (written only where it is not zero)."""
    unc: list[dict[str, object]] = []
    for key in sorted(set(cal.sigma_model) | set(cal.covariance) | set(cal.predictive)):
        s = cal.sigma_model.get(key)
        c = cal.covariance.get(key)
        pr = cal.predictive.get(key)
        unc.append(
            {
                **_key(*key),
                "sigma_model": None if s is None or not math.isfinite(s) else float(s),
                "covariance": None if c is None else np.asarray(c, dtype=float).tolist(),
                **({"floor": pr.floor, "slope": pr.slope, "exponent": pr.exponent,
                    "poses": np.asarray(pr.poses, dtype=float).tolist()}
                   if pr is not None else {}),
                **({"drift": pr.drift, "drift_sd": pr.drift_sd}
                   if pr is not None and (pr.drift or pr.drift_sd) else {}),
            }
        )
    return unc


def _read_family(rec: dict[str, object], j: int, where: str) -> tuple[FamilyParams, list[float | None]]:
    """One family's parameters (and standard errors) from a ``families`` entry or one of its members."""
    spec = family_spec(j, str(rec["family"]))
    params = rec["parameters"]
    if not isinstance(params, list) or len(params) != spec.n_params:
        raise ValueError(f"{where}: family {spec.name} has {spec.n_params} parameters")
    by_name = {(str(p["name"]), None if p.get("q3") is None else round(float(p["q3"]), 9)): p for p in params}
    values = []
    ses_raw = []
    for name, q3 in spec.names:
        p = by_name[(name, None if q3 is None else round(q3, 9))]
        values.append(finite_number(p["value"], f"{where} {name}"))
        ses_raw.append(p.get("stderr"))
    ses = [None if x is None else finite_number(x, f"{where} stderr") for x in ses_raw]
    if any(x is not None and x < 0 for x in ses):
        raise ValueError(f"{where}: a standard error is negative")
    scale = finite_number(rec.get("scale", 1.0), f"{where} scale")
    if not scale > 0:
        raise ValueError(f"{where}: scale must be > 0, got {scale!r}")
    fp = FamilyParams(spec.name, j, tuple(values), scale)
    for name, q3 in spec.names:
        check_unit(by_name[(name, None if q3 is None else round(q3, 9))].get("unit"), fp.unit(name), f"{where} {name}")
    return fp, ses


def _read_predictive(rec: dict[str, object], where: str) -> Predictive:
    """The interval's error model of an ``uncertainty`` entry; ``ValueError`` names what is wrong."""
    try:
        floor = finite_number(rec["floor"], f"{where}.floor")
        slope = finite_number(rec["slope"], f"{where}.slope")
        raw = rec["poses"]
    except KeyError as e:
        raise ValueError(f"{where}: floor, slope and poses go together ({e} is missing)") from None
    if not isinstance(raw, list) or not 0 < len(raw) <= MAX_POSES:
        raise ValueError(f"{where}.poses must be a list of 1 to {MAX_POSES} poses")
    if not all(isinstance(p, list) and len(p) == 5 for p in raw):
        raise ValueError(f"{where}.poses: each pose is [q1, q2, q3, theta, psi] (SI)")
    poses = np.array([[finite_number(v, f"{where}.poses") for v in p] for p in raw], dtype=float)
    if np.any(np.abs(poses) > 10.0):
        raise ValueError(f"{where}.poses: a value is beyond 10 (rad or m): not a pose")
    exponent = finite_number(rec.get("exponent", 1.0), f"{where}.exponent")  # files before it: linear
    if exponent not in (1.0, 2.0):
        raise ValueError(f"{where}.exponent must be 1 or 2 (how the error grows with the distance), got {exponent!r}")
    drift = finite_number(rec.get("drift", 0.0), f"{where}.drift")  # files before it: no drift term
    drift_sd = finite_number(rec.get("drift_sd", 0.0), f"{where}.drift_sd")
    out = Predictive(floor, slope, poses, exponent, drift, drift_sd)
    bad = out.problem()
    if bad is not None:
        raise ValueError(f"{where}: {bad}")
    return out


def _read_uncertainty(cal: ExtFields, unc: object) -> None:
    """The ``uncertainty`` entries: model errors, covariances, the intervals' error models."""
    if not isinstance(unc, list):
        raise ValueError("uncertainty must be a list")
    for i, rec in enumerate(unc):
        if not isinstance(rec, dict):
            raise ValueError(f"uncertainty[{i}] must be an object")
        try:
            key = (int(rec["joint"]), direction_label(rec["direction"]))
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"uncertainty[{i}]: bad joint or direction ({e})") from None
        s = rec.get("sigma_model")
        if s is not None:
            sv = finite_number(s, f"uncertainty[{i}].sigma_model")
            if not 0.0 <= sv < MAX_RELATIVE_SD:
                raise ValueError(f"uncertainty[{i}].sigma_model must be in [0, {MAX_RELATIVE_SD:g}), got {sv!r}")
            cal.sigma_model[key] = sv
        c = rec.get("covariance")
        if c is not None:
            try:
                arr = np.asarray(c, dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"uncertainty[{i}].covariance must be a matrix of numbers") from None
            m = cal.models.get(key)
            n = len(m.params.names()) if m is not None else -1
            if arr.shape != (n, n) or not np.all(np.isfinite(arr)):
                raise ValueError(f"uncertainty[{i}].covariance must be a finite {n}x{n} matrix")
            bad = _covariance_problem(arr)
            if bad is not None:
                raise ValueError(f"uncertainty[{i}].covariance {bad}")
            cal.covariance[key] = arr
        if any(k in rec for k in ("floor", "slope", "poses")):
            cal.predictive[key] = _read_predictive(rec, f"uncertainty[{i}]")


def _covariance_problem(c: NDArray[np.float64]) -> str | None:
    """Why ``c`` is not a fit's covariance (symmetric, positive variances, no negative eigenvalue beyond
    rounding), or None: ``suggest`` inverts it (a negated one ended in "math domain error", a zero one read
    as nothing known)."""
    scale = float(np.max(np.abs(c)))
    if not np.all(np.diag(c) > 0.0):
        return "must have positive variances on its diagonal"
    if float(np.max(np.abs(c - c.T))) > 1e-9 * scale:
        return "must be symmetric"
    d = np.sqrt(np.diag(c))
    if float(np.min(np.linalg.eigvalsh(c / np.outer(d, d)))) < -1e-9:  # as a correlation: units apart
        return "must be positive semi-definite (a negative eigenvalue)"
    return None


def _read_members(
    members_raw: object, j: int, where: str, fp: FamilyParams
) -> tuple[list[tuple[float, FamilyParams]], list[str]]:
    """A model average's members (weight, family) and their labels, checked against the shown ``fp``."""
    if not isinstance(members_raw, list) or not members_raw:
        raise ValueError(f"{where}: members must be a non-empty list")
    members: list[tuple[float, FamilyParams]] = []
    member_labels: list[str] = []
    for k, mrec in enumerate(members_raw):
        mw = f"{where}.members[{k}]"
        if not isinstance(mrec, dict):
            raise ValueError(f"{mw} must be an object")
        w = finite_number(mrec["weight"], f"{mw} weight")
        if not 0.0 < w <= 1.0:
            raise ValueError(f"{mw}: weight must be in (0, 1], got {w!r}")
        members.append((w, _read_family(mrec, j, mw)[0]))
        lab = mrec.get("label")
        if lab is not None:
            fam = members[-1][1].family
            if lab not in (fam, fam + "+shared"):
                raise ValueError(f"{mw}: label {lab!r} is not {fam!r} or {fam + '+shared'!r}")
            member_labels.append(lab)
    total = sum(w for w, _ in members)
    if abs(total - 1.0) > 1e-6:
        raise ValueError(f"{where}: the members' weights must sum to 1, got {total!r}")
    _, heaviest = max(members, key=lambda m: m[0])
    if (heaviest.family, heaviest.values, heaviest.scale) != (fp.family, fp.values, fp.scale):
        # the parameters shown (show, --json) are the heaviest member's; the step is the members'
        raise ValueError(
            f"{where}: the parameters are not those of the member with the largest weight "
            f"({heaviest.family}): the file was edited by hand or is damaged"
        )
    return members, member_labels


def _read_families_entry(cal: ExtFields, rec: object, where: str) -> None:
    """One ``families`` entry: the joint and direction's family model and its standard errors."""
    if not isinstance(rec, dict):
        raise ValueError(f"{where} must be an object")
    members: list[tuple[float, FamilyParams]] = []
    member_labels: list[str] = []
    try:
        j = int(rec["joint"])
        d = direction_label(rec["direction"])
        if j not in (1, 2, 3):
            raise ValueError(f"{where}: joint must be 1, 2 or 3, got {j!r}")
        fp, ses = _read_family(rec, j, where)
        members_raw = rec.get("members")
        if members_raw is not None:
            members, member_labels = _read_members(members_raw, j, where, fp)
    except (KeyError, TypeError) as e:
        raise ValueError(f"{where}: missing or malformed field {e}") from None
    labels_known = len(member_labels) == len(members)  # files before the labels have none
    cal.models[(j, d)] = FamilyModel(
        j, d, fp, members=tuple(members), member_labels=tuple(member_labels) if labels_known else ()
    )
    cal.stderr[(j, d)] = (
        None if all(x is None for x in ses) else np.array([np.nan if x is None else float(x) for x in ses])
    )


def _read_selection(cal: ExtFields, sel: object) -> None:
    """The ``selection`` entries: per joint and direction, how its family was chosen."""
    if not isinstance(sel, list):
        raise ValueError("selection must be a list")
    for i, rec in enumerate(sel):
        try:
            key = (int(rec["joint"]), direction_label(rec["direction"]))
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"selection[{i}]: bad joint or direction ({e})") from None
        cal.selection[key] = {k: v for k, v in rec.items() if k not in ("joint", "direction")}


def read_ext_fields(cal: ExtFields, data: dict[str, object]) -> None:
    """Fill ``cal`` from the ``families``, ``uncertainty`` and ``selection`` entries; ``ValueError`` on bad ones."""
    fams = data.get("families") or []
    if not isinstance(fams, list):
        raise ValueError("families must be a list")
    for i, rec in enumerate(fams):
        _read_families_entry(cal, rec, f"families[{i}]")
    _read_uncertainty(cal, data.get("uncertainty") or [])
    _read_selection(cal, data.get("selection") or [])
