"""Check traverses: the misfit at new poses, measured, scales the intervals (docs/models.md §4).

A calibration's error model infers its error at new poses from the cross-validation's held-out
poses, which are the design's edge poses with their leverage; new poses lie between calibrated
ones. A few traverses at random poses of the workspace (:func:`~.design.check_poses`), measured
in the same session after the calibration's traverses and *not* fitted, show the error there
directly: each one's standardized error ``z = (predicted / measured - 1) / sd`` has mean square 1
where the intervals are right. Per joint (both directions together, as the error model is
made), the intervals' standard deviation is multiplied by ``s`` with

    s^2 = (nu_0 + sum z^2) / (nu_0 + m)

over the ``m`` poses checked in a direction: the mean square of ``z`` pooled with the error
model's own (1) counted as ``nu_0`` traverses (:attr:`CheckParams.prior_traverses`). A few
traverses say little, so the scale moves only part of the way. Repeats at one pose in one
direction share that pose's model error, which is most of ``z`` between poses: they count
once, their ``z^2`` averaged (three repeats at a pose the model misses by 3 sd say what one
says, not three times as much).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..measurements import Traverse
from .errormodel import MAX_RELATIVE_SD, Predictive
from .groups import pose_keys
from .intervals import relative_sd
from .result import Calibration, CalibrationError

__all__ = ["CheckParams", "CHECK", "CheckScale", "check_scales", "apply_check", "fitted_pose", "repeated_row",
           "other_day", "unusable"]


@dataclass(frozen=True)
class CheckParams:
    """How much check traverses move the intervals."""

    prior_traverses: float = 8.0
    """``nu_0``, traverses (1): the error model's own scale counts as this many check traverses, the prior of
    ``s^2`` a chi-square over ``nu_0`` degrees of freedom, relative sd ``sqrt(2 / nu_0)``. The true scale (the
    mean square of ``z`` over 128 validation traverses a joint and day) lay 0.42-3.13, 0.50 RMS about 1, over
    the three development arms' 108 joint-days: ``sqrt(2 / 8)`` (docs/models-log.md, issue 33, seventeenth
    round)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.prior_traverses) and self.prior_traverses >= 0.0):
            raise ValueError(f"prior_traverses must be a finite count >= 0, got {self.prior_traverses!r}")


CHECK = CheckParams()


@dataclass(frozen=True)
class CheckScale:
    """One joint's check: ``traverses`` used at ``poses`` poses and directions (repeats counted once), the RMS over
    those poses of the relative errors and of the intervals' ``sd`` there (1), the RMS of ``z``, and the scale
    ``s`` applied to the joint's intervals."""

    joint: int
    traverses: int
    poses: int
    rms_error: float
    rms_sd: float
    rms_z: float
    scale: float

    def as_dict(self) -> dict[str, object]:
        return {"traverses": self.traverses, "poses": self.poses, "rms_error": self.rms_error, "rms_sd": self.rms_sd,
                "rms_z": self.rms_z, "scale": self.scale}


def _pose_key(t: Traverse) -> tuple[int, tuple[float, ...]]:
    """The joint and the pose a traverse of it was measured at, keyed as the calibration's groups key it."""
    row = np.array([[t.q1, t.q2, t.q3, t.theta, t.psi]], dtype=float)
    return t.joint, tuple(pose_keys(t.joint, row)[0].tolist())


def fitted_pose(check: Sequence[Traverse], fitted: Sequence[Traverse]) -> str | None:
    """Why ``check`` cannot check a calibration fitted on ``fitted`` (None if it can): a check traverse at a
    pose the fit measured (one pose as :func:`~.groups.pose_keys` keys them) shows the fit's residual there,
    not its error between poses, and would narrow the intervals."""
    seen = {_pose_key(t) for t in fitted}
    for i, t in enumerate(check, 1):
        if _pose_key(t) in seen:
            return (f"check traverse {i} (joint {t.joint}, {t.direction}) is at a pose the calibration's traverses "
                    "measured: check traverses lie at new poses (stickslip suggest --check), else they show the "
                    "fit's residual, not its error between poses (docs/models.md §4)")
    return None


def repeated_row(check: Sequence[Traverse]) -> str | None:
    """Why ``check`` cannot be used as it stands (None if it can): a check traverse listed twice, equal in every
    column, would count as two measurements and narrow the intervals as if it had been traversed twice (a table
    appended to itself: from 6 check traverses a joint's scale 0.82, the same rows twice 0.73)."""
    first: dict[Traverse, int] = {}
    for i, t in enumerate(check, 1):
        j = first.setdefault(t, i)
        if j != i:
            return (f"check traverse {i} repeats check traverse {j} in every column (joint {t.joint}, {t.direction}, "
                    f"{t.steps} steps): a check table lists each traverse once (docs/models.md §4)")
    return None


def other_day(check: Sequence[Traverse], day: str) -> str | None:
    """Why ``check`` cannot check a calibration of session ``day`` (None if it can): a check traverse of another
    day measures the step's drift between sessions as well as the fit's error between poses."""
    for i, t in enumerate(check, 1):
        if t.day != day:
            return (f"check traverse {i} (joint {t.joint}, {t.direction}) is of day {t.day!r}, the calibration of day "
                    f"{day!r}: check traverses are measured in the calibration's session (docs/models.md §4)")
    return None


def _pose_terms(cal: Calibration, ts: Sequence[Traverse]) -> tuple[int, list[tuple[float, float, float]]]:
    """Check traverses ``ts`` of one joint and direction: how many have a finite error and ``sd``, and for each
    pose among them (first met first) the mean over its repeats of ``e^2``, ``sd^2`` and ``z^2``."""
    t0 = ts[0]
    pred = cal.predict_many(ts)
    cols = [np.array([getattr(t, k) for t in ts], dtype=float) for k in ("q1", "q2", "q3", "theta", "psi")]
    sd = relative_sd(cal, t0.joint, t0.direction, *cols)
    e = pred / np.array([t.gamma for t in ts]) - 1.0
    ok = np.isfinite(e) & np.isfinite(sd) & (sd > 0)
    e, sd = e[ok], sd[ok]
    pose = [tuple(k.tolist()) for k in pose_keys(t0.joint, np.column_stack(cols))[ok]]  # as the fit's groups
    terms = []
    for key in dict.fromkeys(pose):
        at = [i for i, p in enumerate(pose) if p == key]
        terms.append((float(np.mean(e[at] ** 2)), float(np.mean(sd[at] ** 2)),
                      float(np.mean(e[at] ** 2 / sd[at] ** 2))))
    return len(pose), terms


def check_scales(cal: Calibration, check: Sequence[Traverse], params: CheckParams = CHECK) -> dict[int, CheckScale]:
    """The scale of each joint's intervals from ``check`` (traverses not in ``cal``'s fit), for the joints
    with an error model (:class:`~.errormodel.Predictive`) in a direction checked and a finite prediction
    at some check traverse; repeats at one pose in one direction count once (the module's docstring)."""
    out: dict[int, CheckScale] = {}
    for j in sorted({t.joint for t in check}):
        n, terms = 0, list[tuple[float, float, float]]()
        for d in "+-":
            ts = [t for t in check if t.joint == j and t.direction == d]
            if ts and (j, d) in cal.predictive:
                k, more = _pose_terms(cal, ts)
                n, terms = n + k, terms + more
        if not terms:
            continue
        e2, sd2, z2 = (np.array(c) for c in zip(*terms, strict=True))
        m = len(terms)
        s = math.sqrt((params.prior_traverses + float(z2.sum())) / (params.prior_traverses + m))
        out[j] = CheckScale(j, n, m, math.sqrt(float(e2.mean())), math.sqrt(float(sd2.mean())),
                            math.sqrt(float(z2.mean())), s)
    return out


def unusable(cal: Calibration, check: Sequence[Traverse], params: CheckParams = CHECK) -> str | None:
    """Why no traverse of ``check`` can check ``cal`` (None if one can): a check asked for and used nowhere
    (every traverse of a joint or direction without an error model, e.g. ``--method paper``, or of a joint the
    calibration lacks) must not pass for a check."""
    if not check or check_scales(cal, check, params):
        return None
    asked = ", ".join(f"{j}{d}" for j, d in sorted({(t.joint, t.direction) for t in check}))
    have = ", ".join(f"{j}{d}" for j, d in sorted(cal.predictive)) or "none (a calibration by the paper's method)"
    return (f"none of the {len(check)} check traverse(s) can check this calibration: they are of {asked}; the "
            f"joints and directions with intervals to scale are {have} (docs/models.md §4)")


def apply_check(cal: Calibration, check: Sequence[Traverse], params: CheckParams | None = None) -> Calibration:
    """``cal`` with each checked joint's intervals scaled by :func:`check_scales` (every term of its error
    model: floor, growth, drift), its ``sigma_model`` recomputed, the check recorded in ``selection``
    (``"check"``) and a note per joint. Joints without an error model or without check traverses are
    as they were (a note says so for a joint checked in vain). The predictions are unchanged."""
    from .selection import workspace_sigma

    p = CHECK if params is None else params
    if not check:
        return cal
    scales = check_scales(cal, check, p)
    predictive = dict(cal.predictive)
    selection = {k: dict(v) for k, v in cal.selection.items()}
    notes = list(cal.provenance.notes)
    for j, c in scales.items():
        for d in "+-":
            pr = predictive.get((j, d))
            if pr is None:
                continue
            predictive[(j, d)] = dataclasses.replace(pr, floor=pr.floor * c.scale, slope=pr.slope * c.scale,
                                                     drift=pr.drift * c.scale, drift_sd=pr.drift_sd * c.scale)
            if (j, d) in selection:
                selection[(j, d)]["check"] = c.as_dict()
        counted = "" if c.poses == c.traverses else f" ({c.poses} counted: repeats at one pose count once)"
        notes.append(f"joint {j}: {c.traverses} check traverse(s) at new poses{counted} erred RMS "
                     f"{100 * c.rms_error:.2g} % where the intervals expected {100 * c.rms_sd:.2g} %: "
                     f"intervals scaled by {c.scale:.2f} (docs/models.md §4)")
    for j in sorted({t.joint for t in check} - set(scales)):
        why = "no error model for this joint" if j in cal.joints else f"no joint {j}"
        notes.append(f"joint {j}: check traverses not used: the calibration has {why}")
    out = dataclasses.replace(cal, predictive=predictive, selection=selection,
                              provenance=dataclasses.replace(cal.provenance, notes=tuple(notes)))
    sigma = dict(cal.sigma_model)
    for key in predictive:
        if key[0] in scales:
            sigma[key] = workspace_sigma(out, *key)
            _check_readable(scales[key[0]], predictive[key], sigma[key])
            if key in selection:
                selection[key]["sigma_workspace"] = sigma[key]
    return dataclasses.replace(out, sigma_model=sigma)


def _check_readable(c: CheckScale, scaled: Predictive, sigma: float) -> None:
    """:class:`~.result.CalibrationError` where ``c``'s scale takes the intervals beyond what a calibration keeps
    (:meth:`~.errormodel.Predictive.problem`, :data:`~.errormodel.MAX_RELATIVE_SD`): check traverses that far
    from the predictions measured another joint, direction, unit or arm, not this calibration's error."""
    if scaled.problem() is None and sigma < MAX_RELATIVE_SD:
        return
    raise CalibrationError(
        f"joint {c.joint}: {c.traverses} check traverse(s) erred RMS {100 * c.rms_error:.3g} % where the intervals "
        f"expected {100 * c.rms_sd:.2g} %: scaled by {c.scale:.3g} the intervals would exceed {MAX_RELATIVE_SD:g} "
        "times the step; check the table's joints, directions, units and step counts (docs/models.md §4)")
