"""Figs. 6 and 10 after the paper: average steps of a rotary joint over intervals, per day.

Every traverse of the joint is a measured point: its average step at the midpoint of
the traversed interval, with a horizontal bar across the interval (a π/6 interval as
in the paper's Fig. 6, or the full range as in its calibration), beside the model's
exact average over the same interval and the pointwise model, Eq. (8), as a line.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ._plotting import ANGLE_TOL, LENGTH_TOL, key
from .panels import MODEL_ONLY, Curve, Panel, StepFigure, pose_label, predictions

if TYPE_CHECKING:  # pragma: no cover
    from ..calibration import Calibration
    from ..measurements import Traverse
    from ..models import JointModel

__all__ = ["rotary_interval_data", "pi6_intervals"]

_N = 361  # points along a model line
_Pose = tuple[float, float, float, float]  # q1 (or q2 for joint 1), q3, theta, psi


def pi6_intervals(joint: int) -> list[tuple[float, float]]:
    """The paper's π/6 intervals over the range of a rotary joint, ``(lo, hi)`` in rad."""
    spec = kin.joint_spec(joint)
    n = int(round(spec.span / (math.pi / 6)))
    edges = np.linspace(spec.lower, spec.upper, n + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def rotary_interval_data(
    calibration: Calibration, traverses: Sequence[Traverse], joint: int = 2, sample: Mapping[str, str] | None = None
) -> StepFigure:
    """Traverses of rotary ``joint`` per day and direction, grouped by pose, with the model.

    Groups: ``(q1, q3, theta, psi)`` for joint 2 (``(q2, q3, theta, psi)`` for joint 1).
    ``x`` is ``zeta = psi - q2`` for joint 2 (rad) and ``q1`` itself for joint 1.
    Without traverses of the joint the model alone is drawn: its exact average over
    each π/6 interval at ``q3 = 0`` and 12 mm, ``theta = psi = 0``, in one
    :data:`~stickslip.report.panels.MODEL_ONLY` row.
    """
    if not kin.joint_spec(joint).rotary:
        raise ValueError(f"joint {joint} is not rotary")
    ts = [t for t in traverses if t.joint == joint]
    days = sorted({t.day for t in ts})
    panels: list[Panel] = []
    for d in ("-", "+"):
        try:
            model = calibration.model(joint, d)
        except KeyError:
            continue
        if not days:
            panels.append(Panel(MODEL_ONLY, d, [_model_only(model, joint, q3) for q3 in (0.0, kin.Q3_MAX)]))
        for day in days:
            sel = [t for t in ts if t.day == day and t.direction == d]
            panels.append(Panel(day, d, _curves(calibration, model, joint, sel)))
    panels.sort(key=lambda p: (p.day, p.direction != "-"))
    x_label = "ζ = ψ − q2" if joint == 2 else "q1"
    return StepFigure(joint, f"Figs. 6/10: rotary joint {joint}", x_label, panels, dict(sample or {}))


def _pose(joint: int, t: Traverse) -> _Pose:
    other = t.q1 if joint == 2 else t.q2
    return (key(other, ANGLE_TOL), key(t.q3, LENGTH_TOL), key(t.theta, ANGLE_TOL), key(t.psi, ANGLE_TOL))


def _x(joint: int, q: NDArray[np.float64], psi: float) -> NDArray[np.float64]:
    """The plotted coordinate of joint position ``q`` (rad)."""
    return psi - q if joint == 2 else q


def _curves(calibration: Calibration, model: JointModel, joint: int, ts: Sequence[Traverse]) -> list[Curve]:
    groups: dict[_Pose, list[Traverse]] = {}
    for t in ts:
        groups.setdefault(_pose(joint, t), []).append(t)
    out: list[Curve] = []
    for _, grp in sorted(groups.items(), key=lambda kv: (kv[0][2] != 0.0, kv[0][1], kv[0][2], kv[0][3])):
        t0 = grp[0]  # groups are found by rounded keys; the line is drawn at the exact pose
        pose = (t0.q1 if joint == 2 else t0.q2, t0.q3, t0.theta, t0.psi)
        line = _pointwise(model, joint, pose)
        lo = np.array([min(t.start, t.end) for t in grp])
        hi = np.array([max(t.start, t.end) for t in grp])
        x_mid = _x(joint, (lo + hi) / 2, pose[3])
        out.append(
            Curve(
                line.label,
                line.x_model,
                line.gamma_model,
                x_mid,
                np.array([t.gamma for t in grp]),
                predictions(calibration, grp),
                (hi - lo) / 2,
            )
        )
    return out


def _pointwise(model: JointModel, joint: int, pose: _Pose) -> Curve:
    """Eq. (8) along the whole range of ``joint`` in one pose."""
    other, q3, th, ps = pose
    qq = np.linspace(kin.joint_spec(joint).lower, kin.joint_spec(joint).upper, _N)
    if joint == 2:
        g = model.gamma(other, qq, q3, th, ps)
        fixed = {"q1": other} if abs(other) > ANGLE_TOL else {}
    else:
        g = model.gamma(qq, other, q3, th, ps)
        fixed = {"q2": other}
    label = pose_label(th, ps, q3=q3, **fixed)
    return Curve(label, _x(joint, qq, ps), np.asarray(g, dtype=float))


def _model_only(model: JointModel, joint: int, q3: float) -> Curve:
    """The model's exact average over each π/6 interval, at ``theta = psi = 0`` (no data)."""
    other = 0.0 if joint == 2 else -math.pi / 2  # joint 1: arm outstretched
    line = _pointwise(model, joint, (other, q3, 0.0, 0.0))
    ivs = pi6_intervals(joint)
    lo, hi = np.array([a for a, _ in ivs]), np.array([b for _, b in ivs])
    start, end = (lo, hi) if model.direction == "+" else (hi, lo)
    q1, q2 = (other, 0.0) if joint == 2 else (0.0, other)
    avg = np.asarray(model.average_gamma(start, end, q1, q2, q3, 0.0, 0.0), dtype=float)
    x_mid = _x(joint, (lo + hi) / 2, 0.0)
    return Curve(line.label + " (model only)", line.x_model, line.gamma_model, x_mid, np.zeros(0), avg, (hi - lo) / 2)
