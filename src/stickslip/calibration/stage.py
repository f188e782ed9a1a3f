"""A stage's calibration: the mean step of each joint and direction from its traverses.

A rig file's ``xyz`` arm (docs/rig.md) is planned with a constant step per joint and
direction, the pose does not enter. Each traverse gives the paper's average step
(Eq. 1, :attr:`~stickslip.measurements.Traverse.gamma`, over the length it travelled rather
than the whole range); :func:`calibrate_stage` averages them per joint and direction and writes the
constant-step calibration the stage planner reads (:class:`~stickslip.motion.planning.Planner`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from ..joints import JointSpec
from ..measurements import Traverse
from ..models import DIRECTIONS
from .result import Calibration, CalibrationError, Provenance, _day_of, _group

__all__ = ["METHOD", "MeanStep", "calibrate_stage", "check_stage", "mean_step"]

METHOD = "stage-mean"
"""The ``method`` a stage's calibration records."""


@dataclass(frozen=True)
class MeanStep:
    """The mean step of one joint in one direction, from ``count`` traverses.

    Attributes
    ----------
    value : float
        The length-weighted mean of the traverses' average steps (m, or rad for a rotary joint).
    stderr : float or None
        Its standard error from the spread of the traverses (same unit); ``None`` from one traverse.
    count : int
        Traverses averaged.
    length : float
        Length travelled by them together (m or rad).
    """

    value: float
    stderr: float | None
    count: int
    length: float


def mean_step(traverses: Sequence[Traverse]) -> MeanStep:
    """The mean step of traverses of one joint in one direction (the paper's Eq. 1, averaged).

    Each traverse ``i`` gives its average step ``gamma_i`` (:attr:`~stickslip.measurements.Traverse.gamma`,
    Eq. 1) over the length ``L_i = |end - start|`` it travelled. They are averaged with
    weights ``w_i = L_i``, the inverse of a traverse's variance when each step scatters
    independently (the variance of ``gamma_i`` is then proportional to ``1 / N_i``)::

        gamma = sum(w_i gamma_i) / sum(w_i)

    and its standard error is the weighted mean's, from the scatter of the traverses about
    it (no assumption on where the scatter comes from), with ``n / (n - 1)`` for the mean
    estimated from the same ``n`` traverses::

        se^2 = n / (n - 1) * sum(w_i^2 (gamma_i - gamma)^2) / sum(w_i)^2

    ``ValueError`` for no traverse.
    """
    if not traverses:
        raise ValueError("no traverse to average")
    lengths = [abs(t.end - t.start) for t in traverses]
    gammas = [t.gamma for t in traverses]
    total = math.fsum(lengths)
    value = math.fsum(w * g for w, g in zip(lengths, gammas, strict=True)) / total
    n = len(traverses)
    stderr = None
    if n > 1:
        spread = math.fsum((w * (g - value)) ** 2 for w, g in zip(lengths, gammas, strict=True))
        stderr = math.sqrt(n / (n - 1) * spread) / total
    return MeanStep(value, stderr, n, total)


def check_stage(joints: Mapping[int, JointSpec], arm: str = "") -> None:
    """``CalibrationError`` unless every one of ``joints`` is planned with a constant step (a stage's).

    An MM3A's joints follow the paper's load-dependent models: they are calibrated with
    :func:`~stickslip.calibration.calibrate` (``stickslip calibrate`` without ``--rig``).
    """
    paper = sorted(j for j, spec in joints.items() if spec.step_model != "constant")
    if paper:
        who = f"arm {arm!r}" if arm else "the arm"
        raise CalibrationError(
            f"{who} is an MM3A (its joints follow the paper's models, not a constant step): "
            "calibrate it without --rig"
        )


def calibrate_stage(
    traverses: Sequence[Traverse],
    joints: Mapping[int, JointSpec],
    *,
    arm: str = "",
    day: str | None = None,
    source: str | None = None,
) -> Calibration:
    """A stage arm's calibration: per joint and direction, its mean step (:func:`mean_step`).

    Parameters
    ----------
    traverses : sequence of Traverse
        The stage's traverses (positions in m, or rad for a rotary joint; the pose columns
        are not used: a stage's step does not depend on the pose).
    joints : mapping
        The arm's joints (:meth:`stickslip.rig.Arm.joint_specs`): each must be planned with a
        constant step (an ``xyz`` arm's); their kinds give the units the file is written in.
    arm : str
        The arm's name, for the messages.
    day, source : str, optional
        The session label (default: the latest in the traverses) and where they came from.

    Returns
    -------
    Calibration
        No model, a constant step with its standard error and traverse count per joint and
        direction, method ``"stage-mean"``.

    Raises
    ------
    CalibrationError
        An MM3A's joints (calibrate them with their models), a traverse of a joint the arm
        does not have, or a joint and direction without a traverse (each named).
    """
    check_stage(joints, arm)
    who = f"arm {arm!r}" if arm else "the arm"
    for i, t in enumerate(traverses, start=1):
        if t.joint not in joints:
            raise CalibrationError(
                f"traverse {i} moves joint {t.joint}, which {who} does not have "
                f"(its joints: {', '.join(map(str, sorted(joints)))})"
            )
    groups = _group(traverses)
    missing = [f"{j}{d}" for j in sorted(joints) for d in DIRECTIONS if (j, d) not in groups]
    if missing:
        raise CalibrationError(
            f"no traverse of joint {', '.join(missing)} for {who}: every joint needs one each way"
        )
    means = {key: mean_step(ts) for key, ts in sorted(groups.items())}
    notes = [
        f"joint {j}{d}: one traverse, no standard error" for (j, d), m in means.items() if m.stderr is None
    ]
    return Calibration(
        models={},
        stderr={},
        constant_steps={k: m.value for k, m in means.items()},
        day=_day_of(traverses, day),
        method=METHOD,
        provenance=Provenance.of(traverses, source, len(traverses), notes),
        kinds={j: spec.kind for j, spec in joints.items()},
        constant_stderr={k: m.stderr for k, m in means.items() if m.stderr is not None},
        constant_traverses={k: m.count for k, m in means.items()},
    )
