"""The calibration day as a Bluesky plan: traverse end stop to end stop in the paper's poses, then calibrate.

:func:`calibration_day` measures, for every ``(joint, pose)`` of ``poses`` and in each
direction, the steps between the joint's end stops (the stop is heard by the limit
switch: :func:`stickslip.procedures.traverse.measure_traverse`), keeps each traverse in
the database and re-references the joint at the stop it reached
(:func:`stickslip.procedures.session.record_traverse`), and emits one event per traverse
(the manipulator's :class:`~stickslip.bluesky.manipulator.TraverseReadout`: joint,
direction, steps, average step ``gamma``, the pose). It then calibrates
(:func:`stickslip.calibration.calibrate`), keeps the calibration, emits it as one event
in the ``calibration`` stream, gives it to the manipulator's axes and returns it.

The poses are placed by the controller when it can be placed (the simulator,
:class:`~stickslip.devices.base.PoseSettable`); a real arm's base tilt cannot be set by
a program, so on a real arm the plan refuses (measure with ``stickslip traverse``).
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
from collections.abc import Callable, Generator, Mapping, Sequence
from typing import Any, TypeVar

import bluesky.plan_stubs as bps
import bluesky.preprocessors as bpp
from bluesky.utils import Msg

from .. import kinematics as kin
from ..audio.detector import Tuning, detector_for
from ..calibration import Calibration, calibrate
from ..clock import check_day_label, today_label
from ..devices.base import Controller, PoseSettable
from ..devices.positions import StateStore, load_state, save_state
from ..measurements import Traverse
from ..procedures.conditions import conditions_of
from ..procedures.demo import CALIBRATION_PLAN
from ..procedures.move import device_lock
from ..procedures.session import record_traverse, traverse_on_device
from ..procedures.traverse import TraverseResult, measure_traverse
from ..sim.arm import SimulatedMM3A
from ..sim.oracle import OracleStopDetector
from .axis import DeviceLink
from .manipulator import StickSlipManipulator

__all__ = ["PAPER_POSES", "calibration_day"]

PAPER_POSES: tuple[tuple[int, dict[str, float]], ...] = CALIBRATION_PLAN
"""The paper's calibration traverses: ``(joint, pose of the other joints and the tilt)``
(rad, rad, m; tilt rad), each traversed ``+`` then ``-`` (7 poses, 14 traverses)."""

DETECTORS = ("audio", "oracle")
T = TypeVar("T")


class _Switch:
    """The limit switch for each joint: tuned audio or the simulator's oracle, or given tunings."""

    def __init__(self, ctrl: Controller, detector: str | Mapping[int, Tuning]):
        self.ctrl = ctrl
        self.kind = detector if isinstance(detector, str) else "tunings"
        self.tunings: dict[int, Tuning] = {} if isinstance(detector, str) else dict(detector)
        self.mic: Any = None
        if isinstance(detector, str):
            if detector not in DETECTORS:
                raise ValueError(
                    f"detector must be one of {DETECTORS} or a {{joint: Tuning}} mapping, got {detector!r}"
                )
            if not isinstance(ctrl, SimulatedMM3A):
                raise ValueError(
                    f"detector={detector!r} tunes itself on the simulator only; on a real arm give the "
                    f"joints' tunings ({{joint: Tuning.load(path)}}, from `stickslip tune`)"
                )

    def measure(self, joint: int, direction: str, pose: kin.Pose, day: str, burst: int) -> TraverseResult:
        """One traverse of ``joint`` in ``direction`` at ``pose`` (blocking)."""
        ctrl = self.ctrl
        if self.kind == "tunings":
            if joint not in self.tunings:
                raise ValueError(
                    f"no limit-switch tuning for joint {joint} (tunings are for joints {sorted(self.tunings)})"
                )
            tuning = self.tunings[joint]
            return traverse_on_device(ctrl, joint, direction, pose, day, tuning, burst_steps=burst, progress=False)
        assert isinstance(ctrl, SimulatedMM3A)
        ctrl.set_pose(**{k: v for k, v in pose._asdict().items() if k != f"q{joint}"})
        if self.kind == "oracle":
            if self.mic is None:
                self.mic = ctrl.microphone(silent=True)
            det: Any = OracleStopDetector(ctrl, joint, delay_s=0.03, t0_s=ctrl.clock_s)
        else:
            if joint not in self.tunings:
                from ..audio.tuning import tune

                samples, rate, stop_at = ctrl.labelled_recording(joint, "+", before_s=2.0, after_s=1.0)
                self.tunings[joint] = tune(samples, rate, stop_at, joint=joint, step_rate_hz=ctrl.frequency(joint))
            if self.mic is None:
                self.mic = ctrl.microphone()
            det = detector_for(self.tunings[joint], ctrl.clock_s)
        return measure_traverse(
            ctrl, joint, direction, detector=det, audio_blocks=self.mic, pose=pose, day=day, burst_steps=burst
        )


def _pose(joint: int, given: Mapping[str, float], now: kin.Pose) -> kin.Pose:
    """The traverse pose: ``given`` over the current one (the moving joint's value is ignored)."""
    unknown = sorted(set(given) - set(kin.Pose._fields))
    if unknown:
        raise ValueError(f"pose keys {unknown} are not pose coordinates {kin.Pose._fields}")
    return now._replace(**{k: float(v) for k, v in given.items()})


def _keep_pose(store: StateStore, key: str, joint: int, pose: kin.Pose) -> None:
    """Record the pose the arm was placed in (all joints but ``joint``, and the tilt) as the kept positions."""
    state = load_state(store, key)
    for j in (1, 2, 3):
        if j != joint:
            state.set_position(j, pose[j - 1], "set")
    state.set_tilt(pose.theta, pose.psi)
    save_state(store, state)


async def _in_thread(link: DeviceLink, fn: Callable[[], T]) -> T:
    async with link.lock:  # one action at a time on the controller
        return await asyncio.to_thread(fn)


def calibration_day(
    manipulator: StickSlipManipulator,
    poses: Sequence[tuple[int, Mapping[str, float]]] = PAPER_POSES,
    detector: str | Mapping[int, Tuning] = "audio",
    *,
    day: str | None = None,
    burst_steps: int = 1000,
    md: Mapping[str, Any] | None = None,
) -> Generator[Msg, Any, Calibration]:
    """Measure the calibration traverses, then calibrate (a Bluesky plan; returns the :class:`Calibration`).

    Parameters
    ----------
    manipulator : StickSlipManipulator
        The arm (its controller, database and axes).
    poses : sequence of (joint, pose)
        ``(joint, {"q1": rad, "q2": rad, "q3": m, "theta": rad, "psi": rad})``; each is
        traversed ``+`` then ``-``. Default the paper's (:data:`PAPER_POSES`).
    detector : {"audio", "oracle"} or mapping
        The limit switch: ``"audio"`` tunes the audio detector on the simulator's
        sound, ``"oracle"`` is the simulator's true stop (fast; tests), a mapping
        ``{joint: Tuning}`` uses those tunings (the sound card, or the simulator's microphone).
    day : str, optional
        Session label (default: today, ``$STICKSLIP_TODAY``).
    burst_steps : int
        Steps per burst of the traverse.
    md : mapping, optional
        Extra run metadata.

    Notes
    -----
    Events: one per traverse in ``primary`` (``traverse-steps``, ``traverse-gamma`` in m
    or rad, joint, direction, start, end, pose); one in ``calibration``
    (``calibration-json``, the calibration file's JSON).

    The plan cannot be resumed: a pause (Ctrl-C) aborts it, the traverses measured so far
    kept; run it again for the day.
    """
    link = manipulator.link
    day = check_day_label(day) if day is not None else today_label()
    plan = _checked_plan(poses, burst_steps)
    ctrl: Controller = yield from _call(link, link.controller)
    if not isinstance(ctrl, PoseSettable):
        raise ValueError(
            "calibration_day places the arm in each pose, and this controller cannot be placed (a real arm's base "
            "tilt is set by hand): measure each pose with `stickslip traverse`, then `stickslip calibrate`"
        )
    switch = _Switch(ctrl, detector)
    how = f"bluesky calibration_day, {switch.kind} switch"
    metadata = _day_metadata(link.key, day, switch.kind, plan, md)
    made: list[Calibration] = []

    def inner() -> Generator[Msg, Any, None]:
        # a pause aborts (a traverse moved the arm and is kept: replaying it on resume measured it twice and
        # handed the plan None for its result)
        yield from bps.clear_checkpoint()
        rows: list[Traverse] = []
        ids: list[int] = []
        for joint, given in plan:
            for direction in "+-":
                def one(
                    joint: int = joint, given: dict[str, float] = given, direction: str = direction
                ) -> tuple[Traverse, int]:
                    now = ctrl.pose if isinstance(ctrl, SimulatedMM3A) else link.load().pose
                    pose = _pose(joint, given, now)
                    r = switch.measure(joint, direction, pose, day, burst_steps)
                    with link.store() as store, device_lock(store, link.key):
                        _keep_pose(store, link.key, joint, pose)  # the plan placed the other joints and the base
                        tid = record_traverse(store, link.url, r.traverse, how=how)
                    return r.traverse, tid

                row, tid = yield from _call(link, one)
                rows.append(row)
                ids.append(tid)
                manipulator.traverse.show(row)
                yield from bps.trigger_and_read([manipulator.traverse])

        def fit() -> Calibration:
            fitted = calibrate(rows, day=day, source=link.url)
            cal = dataclasses.replace(fitted, conditions=conditions_of(ctrl, link.url))
            with link.store() as store:
                store.add_calibration(cal, link.key, ids)
            return cal

        cal: Calibration = yield from _call(link, fit)
        manipulator.use_calibration(cal)
        manipulator.calibration_readout.show(json.dumps(cal.to_dict()), cal.method, cal.day)
        yield from bps.trigger_and_read([manipulator.calibration_readout], name="calibration")
        for axis in manipulator.axes.values():
            yield from bps.wait_for([axis.refresh])
        made.append(cal)

    yield from bpp.run_wrapper(inner(), md=metadata)  # type: ignore[no-untyped-call]  # bluesky leaves it untyped
    return made[0]


def _checked_plan(
    poses: Sequence[tuple[int, Mapping[str, float]]], burst_steps: object
) -> list[tuple[int, dict[str, float]]]:
    """``poses`` as ``[(joint, pose)]``; ``ValueError`` before anything moves for an unknown joint, no pose, or a
    ``burst_steps`` that is not a whole number of steps in 1..1000000 (``True`` is not 1)."""
    plan = [(kin.joint_spec(j).number, dict(p)) for j, p in poses]
    if not plan:
        raise ValueError("poses is empty: give (joint, pose) pairs to traverse (default: PAPER_POSES)")
    if isinstance(burst_steps, bool) or not isinstance(burst_steps, int) or not 1 <= burst_steps <= 1_000_000:
        raise ValueError(f"burst_steps must be an integer number of steps in 1..1000000, got {burst_steps!r}")
    return plan


def _day_metadata(
    device: str, day: str, detector: str, plan: list[tuple[int, dict[str, float]]], md: Mapping[str, Any] | None
) -> dict[str, Any]:
    """The calibration day's run metadata: plan name, device, day, detector, poses, and the caller's ``md``."""
    return {
        "plan_name": "calibration_day",
        "device": device,
        "day": day,
        "detector": detector,
        "poses": [[j, p] for j, p in plan],
        **dict(md or {}),
    }


def _call(link: DeviceLink, fn: Callable[[], T]) -> Generator[Msg, Any, T]:
    """Run blocking ``fn`` in a worker thread from a plan; its result (or its exception)."""
    futures = yield from bps.wait_for([lambda: _in_thread(link, fn)])
    result: T = futures[0].result()
    return result

