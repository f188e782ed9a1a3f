"""Fig. 4 after the paper: the step of prismatic joint 3 against ζ = ψ − q2, per tilt θ, per day."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from .. import kinematics as kin
from ..joints import joint_spec
from ._plotting import ANGLE_TOL, key
from .panels import MODEL_ONLY, Curve, Panel, StepFigure, pose_label, predictions

if TYPE_CHECKING:  # pragma: no cover
    from ..calibration import Calibration
    from ..measurements import Traverse
    from ..models import JointModel

__all__ = ["prismatic_data"]

_N = 241  # points along a model line
MODEL_ONLY_TILTS = (0.0, -math.pi / 3, -math.pi / 2)
"""θ (rad) of the model lines drawn when there are no joint-3 traverses."""


def prismatic_data(
    calibration: Calibration, traverses: Sequence[Traverse], sample: Mapping[str, str] | None = None
) -> StepFigure:
    """Joint-3 traverses per day and direction, each pose beside its model line (Eq. 3).

    Every tilt in the data gets a model line: traverses at one ``(q1, theta, psi)``
    make a line over the whole range of q2 (the paper's experiment 1), even a single
    traverse; traverses at one ``(q1, theta, q2)`` with several ``psi`` make a line over
    ``psi`` (experiment 2). ``x`` is ``zeta = psi - q2`` (rad). Without joint-3
    traverses the model alone is drawn at ``theta = 0, -pi/3, -pi/2`` (``psi = 0``)
    in one :data:`~stickslip.report.panels.MODEL_ONLY` row.
    """
    panels: list[Panel] = []
    ts3 = [t for t in traverses if joint_spec(t.joint).prismatic]
    days = sorted({t.day for t in ts3})
    for d in ("+", "-"):
        try:
            model = calibration.model(3, d)
        except KeyError:
            continue
        if not days:
            panels.append(Panel(MODEL_ONLY, d, [_q2_line(model, 0.0, th, 0.0) for th in MODEL_ONLY_TILTS]))
        for day in days:
            sel = [t for t in ts3 if t.day == day and t.direction == d]
            panels.append(Panel(day, d, _curves(calibration, model, sel)))
    panels.sort(key=lambda p: (p.day, p.direction != "+"))
    return StepFigure(3, "Fig. 4: prismatic joint 3", "ζ = ψ − q2", panels, dict(sample or {}))


def _curves(calibration: Calibration, model: JointModel, ts: Sequence[Traverse]) -> list[Curve]:
    """The curves of one day and direction: ψ-varied groups first claimed, then one line per (q1, θ, ψ)."""
    by_tq: dict[tuple[float, float, float], list[Traverse]] = {}
    by_tp: dict[tuple[float, float, float], list[Traverse]] = {}
    for t in ts:
        by_tp.setdefault((key(t.q1, ANGLE_TOL), key(t.theta, ANGLE_TOL), key(t.psi, ANGLE_TOL)), []).append(t)
    claimed: set[int] = set()
    for grp in by_tp.values():
        if len({key(t.q2, ANGLE_TOL) for t in grp}) == 1:  # one q2 at this tilt: maybe part of a ψ sweep
            t0 = grp[0]
            by_tq.setdefault((key(t0.q1, ANGLE_TOL), key(t0.theta, ANGLE_TOL), key(t0.q2, ANGLE_TOL)), []).extend(grp)
    out: list[Curve] = []
    # groups are found by rounded keys; lines are drawn at the first traverse's exact pose
    for _, grp in sorted(by_tq.items(), key=lambda kv: (-kv[0][1], kv[0][2])):
        if len({key(t.psi, ANGLE_TOL) for t in grp}) < 2:
            continue
        claimed.update(id(t) for t in grp)
        t0 = grp[0]
        out.append(_psi_line(calibration, model, grp, t0.q1, t0.theta, t0.q2))
    for _, grp in sorted(by_tp.items(), key=lambda kv: (-kv[0][1], kv[0][2])):
        rest = [t for t in grp if id(t) not in claimed]
        if rest:
            t0 = rest[0]
            out.append(_with_data(calibration, _q2_line(model, t0.q1, t0.theta, t0.psi), rest))
    return out


def _q2_line(model: JointModel, q1: float, theta: float, psi: float) -> Curve:
    """Eq. (3) over the whole range of q2 at one tilt, against ``zeta = psi - q2``."""
    spec2 = kin.joint_spec(2)
    q2 = np.linspace(spec2.lower, spec2.upper, _N)
    fixed = {"q1": q1} if abs(q1) > ANGLE_TOL else {}
    label = pose_label(theta, psi, **fixed)
    return Curve(label, psi - q2, np.asarray(model.gamma(q1, q2, 0.0, theta, psi), dtype=float))


def _psi_line(
    calibration: Calibration, model: JointModel, ts: Sequence[Traverse], q1: float, theta: float, q2: float
) -> Curve:
    """Eq. (3) over the measured range of ψ at one (θ, q2) (the paper's experiment 2)."""
    psis = [t.psi for t in ts]
    lo, hi = min(psis), max(psis)
    pad = 0.05 * (hi - lo)
    ps = np.linspace(lo - pad, hi + pad, _N)
    label = f"θ = {math.degrees(theta):.0f}°, q2 = {math.degrees(q2):.0f}° (ψ varied)"
    line = Curve(label, ps - q2, np.asarray(model.gamma(q1, q2, 0.0, theta, ps), dtype=float))
    return _with_data(calibration, line, ts)


def _with_data(calibration: Calibration, line: Curve, ts: Sequence[Traverse]) -> Curve:
    """``line`` with the traverses measured in its pose."""
    return Curve(
        line.label,
        line.x_model,
        line.gamma_model,
        np.array([t.psi - t.q2 for t in ts]),
        np.array([t.gamma for t in ts]),
        predictions(calibration, ts),
        np.zeros(len(ts)),
    )
