"""Driving a straight tip move: the segments of a :class:`~stickslip.motion.reach.ReachPlan`, joint by joint.

Each joint's steps in a segment go through :func:`stickslip.procedures.move.drive`
(the write-ahead journal: *in flight* before a burst, the dead-reckoned end after it),
so a straight move has exactly the safety of single-joint moves: the positions are kept
after every burst, and a link drop, crash or Ctrl-C leaves the joint being stepped
*uncertain* with bounds, never silently wrong. The caller holds the device lock
(:func:`stickslip.procedures.move.device_lock`).

The dead reckoning inside a segment is the planner's own (:class:`stickslip.motion.reach.JointStepper`
in the pose of that moment), so the kept positions after each segment are the plan's
predicted ``q``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from ..calibration import Calibration
from ..devices.base import Controller
from ..devices.positions import DeviceState
from ..motion.reach import JointStepper, ReachPlan
from .move import drive

__all__ = ["ReachOutcome", "drive_reach"]


@dataclass
class ReachOutcome:
    """What :func:`drive_reach` did.

    Attributes
    ----------
    segments_done : int
        Segments completed (all joints confirmed).
    sent : list of int
        Signed steps confirmed per joint (1, 2, 3) over the whole move.
    error : str or None
        The device error that stopped the move, if any.
    joint : int or None
        The joint being stepped when it stopped.
    """

    segments_done: int = 0
    sent: list[int] = field(default_factory=lambda: [0, 0, 0])
    error: str | None = None
    joint: int | None = None


def drive_reach(
    dev: Controller,
    state: DeviceState,
    plan: ReachPlan,
    calibration: Calibration,
    save: Callable[[DeviceState], None],
    burst: int = 1000,
    on_segment: Callable[[int, DeviceState], None] | None = None,
) -> ReachOutcome:
    """Send ``plan``'s segments to ``dev``, joint 1, then 2, then 3 in each, journalling every burst.

    ``state`` must hold the plan's start (its positions are updated as the arm moves);
    ``save(state)`` stores it (one transaction); ``on_segment(k, state)`` is called
    after segment ``k`` (0-based) is done. A :class:`~stickslip.devices.base.DeviceError`
    stops the move and is returned in the outcome; any other exception propagates with
    the journal saved.
    """
    start = tuple(state.positions[j] for j in (1, 2, 3))
    if any(abs(a - b) > 1e-12 * max(1.0, abs(b)) for a, b in zip(start, plan.q_start, strict=True)):
        raise ValueError(f"the device's kept positions {start} are not the plan's start {plan.q_start}")
    out = ReachOutcome()
    for k, seg in enumerate(plan.segments):
        for j in (1, 2, 3):
            n = seg.steps[j - 1]
            if n == 0:
                continue
            stepper = JointStepper(calibration, j, state.pose, plan.step_model)
            q_from = state.positions[j]

            def reckon(m: int, stepper: JointStepper = stepper, q_from: float = q_from) -> float:
                return stepper.position_after(q_from, m)

            moved = drive(dev, state, j, n, burst, reckon, save)
            out.sent[j - 1] += moved.sent
            if moved.error is not None:
                out.error, out.joint = moved.error, j
                return out
        out.segments_done = k + 1
        if on_segment is not None:
            on_segment(k, state)
    return out
