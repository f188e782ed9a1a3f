"""The tip's ``x, y, z`` as ophyd-async pseudo-axes over the three joints of one arm.

:class:`Tip` holds three :class:`TipAxis` children, ``x``, ``y`` and ``z``: the tip's
position in the base frame before the base tilt (docs/design.md §9, docs/taskspace.md),
metres. The readback is the forward kinematics (:func:`stickslip.kinematics.tip`) of
the three joints' kept (dead-reckoned) positions; a move is a straight tip move planned
by the task-space planner (:func:`stickslip.motion.reach.plan_reach`) from the kept pose and
driven joint by joint, burst by burst, with the write-ahead journal
(:func:`stickslip.procedures.reach.drive_reach`), exactly as ``stickslip reach`` does.

Moving one coordinate keeps the other two at their *targets*: the last tip target this
device moved to, as long as the joints are still where that move left them (so a scan of
``x`` does not let ``y`` and ``z`` wander by the rounding of whole steps); else (a joint
was moved on its own, or by another process) at the tip's current readback.

Errors behave as the joint axes': a target the straight line cannot reach (a joint range,
joint 1's axis) fails the status with :class:`ValueError` before any step is sent; a
refused or failed move fails it with :class:`~stickslip.bluesky.axis.MoveError`; a stop
sends no further burst and returns within :data:`~stickslip.bluesky.axis.STOP_RETURN_S`.
"""

from __future__ import annotations

import asyncio
import math
import threading
import warnings
from collections.abc import AsyncIterator, Callable
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

import numpy as np
from bluesky.protocols import Checkable, Locatable, Location, Reading, Stoppable
from ophyd_async.core import (
    StandardReadable,
    WatchableAsyncStatus,
    WatcherUpdate,
    soft_signal_r_and_setter,
)
from ophyd_async.core import StandardReadableFormat as Format

from .. import kinematics as kin
from ..calibration import Calibration
from ..devices.base import DeviceError, VirtualClock
from ..devices.positions import DeviceState, load_state, save_state, where_set_command
from ..motion.reach import ReachPlan, borrow_joint1
from ..procedures.move import DeviceBusy, MoveRefused, device_lock
from ..procedures.reach import (
    BORROWED_JOINT1,
    ReachRequest,
    check_referenced,
    drive_reach,
    joint_path,
    plan_from_state,
)
from ..rig.guard import Guard
from ..storage import StoreError
from .axis import (
    DeviceLink,
    MoveError,
    _Interruptible,
    _Stopped,
    bounded_burst,
    check_burst,
    check_max_burst_s,
    halt,
    hold_claim,
    rig_stop,
)

__all__ = ["Tip", "TipAxis", "BORROWED_JOINT1"]

COORDINATES = ("x", "y", "z")
_MAX_COORDINATE = 1.0  # m: nothing on a micromanipulator is a metre away; catches unit slips (µm given as m)


Vec3 = tuple[float, float, float]


def _positions(state: DeviceState) -> Vec3:
    return (float(state.positions[1]), float(state.positions[2]), float(state.positions[3]))


@dataclass(frozen=True)
class _TipResult:
    plan: ReachPlan | None
    segments_done: int
    stopped: bool
    state: DeviceState


class _TipDriver:
    """What the three coordinates share: the link, the target, the stop, the planning (not a Device)."""

    def __init__(
        self,
        link: DeviceLink,
        calibration: Callable[[], Calibration | None],
        geometry: kin.Geometry,
        burst: int,
        max_burst_s: float,
        segment: float,
        guard: Guard | None = None,
    ) -> None:
        self.link = link
        self.guard = guard  # a rig's envelope: every tip move's whole path checked first, as `stickslip reach --rig`
        self.calibration = calibration
        self.geometry = geometry
        self.burst = burst
        self.max_burst_s = max_burst_s
        self.segment = segment
        self.target: Vec3 | None = None  # the last tip target moved to, m
        self.q_after: Vec3 | None = None  # the kept joints that move left
        self.stop_event = threading.Event()
        self.stop_success = False
        self.task: asyncio.Future[_TipResult] | None = None
        self.observers: list[Callable[[DeviceState], None]] = []
        self.setpoints: list[Callable[[Vec3], None]] = []

    def publish(self, state: DeviceState) -> None:
        for observe in self.observers:
            observe(state)

    def tip_of(self, state: DeviceState) -> Vec3:
        x, y, z = (float(v) for v in kin.tip(_positions(state), self.geometry))
        return (x, y, z)

    def base(self, state: DeviceState) -> Vec3:
        """The tip target the other coordinates keep: the last target if the joints are where it left them."""
        if self.target is not None and self.q_after == _positions(state):
            return self.target
        return self.tip_of(state)

    def aim(self, state: DeviceState, index: int, value: float) -> Vec3:
        goal = list(self.base(state))
        goal[index] = value
        return (goal[0], goal[1], goal[2])

    def _calibration(self) -> tuple[Calibration, bool]:
        cal = self.calibration()
        if cal is None:
            raise MoveError(
                "the tip has no calibration: give the manipulator one, or run the calibration_day plan first"
            )
        return borrow_joint1(cal)

    def plan(self, state: DeviceState, goal: Vec3) -> tuple[ReachPlan, Calibration]:
        """The straight move from the kept pose to ``goal`` (``ValueError`` if it cannot be made; nothing sent).

        Planned as ``stickslip reach`` plans (:func:`stickslip.procedures.reach.plan_from_state`).
        """
        cal, borrowed = self._calibration()
        try:
            check_referenced(state, self.link.url, cal)
        except MoveRefused as e:
            raise MoveError(str(e)) from None
        request = ReachRequest(self.link.url, to=goal, geometry=self.geometry, segment=self.segment)

        def warn(message: str) -> None:
            warnings.warn(message, UserWarning, stacklevel=4)

        try:
            plan = plan_from_state(cal, borrowed, state, request, warn)
        except KeyError as e:  # a joint or direction the move needs is not calibrated
            raise MoveError(str(e).strip("'\"")) from None
        return plan, cal

    def move_sync(self, goal: Vec3, publish: Callable[[DeviceState], None]) -> _TipResult:
        """The whole tip move, in a worker thread: lock, plan from the kept state, drive, record."""
        link = self.link
        with link.store() as store, device_lock(store, link.key), ExitStack() as claim:
            state = load_state(store, link.key)
            plan, cal = self.plan(state, goal)
            hold_claim(claim, store, state, self.guard, joint_path(plan), cal)  # mark, then check, as reach --rig
            publish(state)
            if not any(plan.total_steps):
                self.target, self.q_after = goal, _positions(state)
                return _TipResult(plan, len(plan.segments), False, state)
            dev = link.controller()
            proxy = _Interruptible(dev, self.stop_event, isinstance(dev, VirtualClock), rig_stop(store, self.guard))
            burst = min(bounded_burst(dev, j, self.burst, self.max_burst_s) for j in (1, 2, 3))
            done = 0

            def save(st: DeviceState) -> None:
                save_state(store, st)
                publish(st)

            def segment_done(k: int, st: DeviceState) -> None:
                nonlocal done
                done = k + 1

            try:
                outcome = drive_reach(proxy, state, plan, cal, save, burst, on_segment=segment_done)
            except _Stopped as s:
                if not s.partial:  # the next burst was never sent: back to the confirmed position
                    j = proxy.joint
                    state.set_position(j, state.positions[j], state.sources[j])
                    save(state)
                return _TipResult(plan, done, True, state)
            if outcome.error is not None:
                raise MoveError(self.failure_text(outcome.error, outcome.segments_done, plan, outcome.joint, state))
            self.target, self.q_after = goal, _positions(state)
            return _TipResult(plan, len(plan.segments), False, state)

    @staticmethod
    def failure_text(error: str, done: int, plan: ReachPlan, joint: int | None, state: DeviceState) -> str:
        j = joint or 0
        if j in state.uncertain:
            lo, hi = state.uncertain[j]
            unit = kin.joint_spec(j).unit
            kept = (
                f"joint {j}'s position is now uncertain, between {lo:.9g} and {hi:.9g} {unit}; re-reference it "
                f"({where_set_command(state.device, j)} at the lower stop) before the next move"
            )
        else:
            kept = "the dead-reckoned positions are kept"
        return f"{error}; stopped in segment {done + 1} of {len(plan.segments)}; {kept}"


class TipAxis(StandardReadable, Locatable[float], Stoppable, Checkable[float]):
    """One coordinate of the tip (``x``, ``y`` or ``z``), m, base frame: a pseudo-axis over the three joints.

    Made by :class:`Tip` (``manipulator.tip.x`` ...), not on its own.

    Signals
    -------
    readback : m
        The coordinate of the forward kinematics of the kept (dead-reckoned) joints (hinted).
    setpoint : m
        The coordinate of the last tip target.
    """

    def __init__(self, driver: _TipDriver, index: int, name: str = "") -> None:
        self._driver = driver
        self.index = index
        self.coordinate = COORDINATES[index]
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.readback, self._set_readback = soft_signal_r_and_setter(float, math.nan, units="m")
        with self.add_children_as_readables(Format.UNCACHED_SIGNAL):
            self.setpoint, self._set_setpoint = soft_signal_r_and_setter(float, math.nan, units="m")
        super().__init__(name=name)

    def set_name(self, name: str, *, child_name_separator: str | None = None) -> None:
        super().set_name(name, child_name_separator=child_name_separator)
        self.readback.set_name(name)  # the readback's data key is the axis's name (as ophyd motors do)

    def __repr__(self) -> str:
        return f"TipAxis(name={self.name!r}, coordinate={self.coordinate!r}, unit='m')"

    def _publish(self, state: DeviceState) -> None:
        tip = self._driver.tip_of(state)
        self._set_readback(tip[self.index])

    def _show_target(self, goal: Vec3) -> None:
        self._set_setpoint(goal[self.index])

    async def refresh(self) -> DeviceState:
        """Read the kept joints from the database into the tip's signals."""
        try:
            state = await asyncio.to_thread(self._driver.link.load)
        except (StoreError, ValueError) as e:
            raise MoveError(str(e)) from None
        self._driver.publish(state)
        if math.isnan(await self.setpoint.get_value()):
            self._set_setpoint(self._driver.base(state)[self.index])
        return state

    async def read(self) -> dict[str, Reading[Any]]:
        """The signals, the kept position read in first (another process may have moved a joint): no stale event."""
        await self.refresh()
        return await super().read()

    async def locate(self) -> Location[float]:
        """Setpoint (the last target's coordinate) and readback (of the dead-reckoned joints), m."""
        await self.refresh()
        return Location(setpoint=await self.setpoint.get_value(), readback=await self.readback.get_value())

    def target_problem(self, value: object) -> str | None:
        """Why ``value`` cannot be a target coordinate, before the kept pose is read (``None`` if it may be)."""
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            return f"the target of tip {self.coordinate} must be a number in m, got {value!r}"
        v = float(value)
        if not (math.isfinite(v) and abs(v) <= _MAX_COORDINATE):
            return (
                f"the target tip {self.coordinate} = {v!r} m is not a position within {_MAX_COORDINATE:g} m of the "
                f"base; {self.name or 'the tip axis'} takes metres (e.g. 21e-3 for 21 mm)"
            )
        return None

    async def check_value(self, value: float) -> None:
        """Raise ``ValueError`` (nothing moves) if the tip cannot reach ``value`` with the other coordinates kept."""
        problem = self.target_problem(value)
        if problem:
            raise ValueError(problem)
        try:
            state = await asyncio.to_thread(self._driver.link.load)
        except (StoreError, ValueError) as e:
            raise MoveError(str(e)) from None
        goal = self._driver.aim(state, self.index, float(value))
        kin.inverse(goal, self._driver.geometry, near=_positions(state))  # OutOfReach, SingularPose: ValueErrors

    def set(self, value: float) -> WatchableAsyncStatus[float]:
        """Move the tip in a straight line until this coordinate is ``value`` (m), the others kept.

        The status fails with :class:`ValueError` for a target the line cannot reach
        (nothing is sent), :class:`MoveError` for a refused or failed move, and
        ``RuntimeError`` after ``stop(success=False)``.
        """
        self._driver.stop_event.clear()
        self._driver.stop_success = False
        return self._set(value)

    @WatchableAsyncStatus.wrap
    async def _set(self, value: float) -> AsyncIterator[WatcherUpdate[float]]:
        await self.check_value(value)
        driver = self._driver
        driver._calibration()
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[DeviceState] = asyncio.Queue()

        def publish(state: DeviceState) -> None:  # from the worker thread
            loop.call_soon_threadsafe(queue.put_nowait, state)

        async with driver.link.lock:
            state = await self.refresh()
            goal = driver.aim(state, self.index, float(value))
            initial = driver.tip_of(state)[self.index]
            for show in driver.setpoints:
                show(goal)
            task = asyncio.ensure_future(asyncio.to_thread(driver.move_sync, goal, publish))
            driver.task = task
            try:
                while True:
                    getter = asyncio.ensure_future(queue.get())
                    await asyncio.wait([task, getter], return_when=asyncio.FIRST_COMPLETED)
                    if not getter.done():
                        getter.cancel()
                        break
                    st = getter.result()
                    driver.publish(st)
                    yield WatcherUpdate(
                        current=driver.tip_of(st)[self.index], initial=initial, target=goal[self.index],
                        name=self.name, unit="m",
                    )
                while not queue.empty():
                    driver.publish(queue.get_nowait())
                try:
                    result = task.result()
                except (DeviceBusy, StoreError, DeviceError) as e:
                    raise MoveError(str(e).strip("'\"")) from None
            except asyncio.CancelledError:  # the status was cancelled: send no further burst
                driver.stop_event.set()
                raise
            finally:
                driver.task = None
        driver.publish(result.state)
        if result.stopped and not driver.stop_success:
            n = 0 if result.plan is None else len(result.plan.segments)
            raise RuntimeError(
                f"{self.name or 'the tip'} was stopped after {result.segments_done} of {n} segments; "
                + _where(result.state)
            )

    async def stop(self, success: bool = False) -> None:
        """Stop now: no further burst is sent and the controller is told to stop (every channel).

        Returns once the move's worker has finished, at the latest after
        :data:`~stickslip.bluesky.axis.STOP_RETURN_S` (0.5 s). With ``success=False``
        the move's status fails; with ``True`` it completes.
        """
        self._driver.stop_success = success
        self._driver.stop_event.set()
        await halt(self._driver.link, None, self._driver.task)


def _where(state: DeviceState) -> str:
    if state.uncertain:
        j = min(state.uncertain)
        return (
            f"joint {j}'s position is uncertain (a burst was cut short); re-reference it "
            f"({where_set_command(state.device, j)} at the lower stop)"
        )
    q = _positions(state)
    return f"the dead-reckoned joints are q1 = {q[0]:.6g} rad, q2 = {q[1]:.6g} rad, q3 = {q[2]:.6g} m"


class Tip(StandardReadable):
    """The tip of one arm: pseudo-axes ``x``, ``y``, ``z`` (m, base frame before the tilt).

    Parameters
    ----------
    link : DeviceLink
        The arm's controller and database (shared with its joint axes).
    calibration : callable
        Returns the arm's calibration now (``None``: moves are refused); a calibration
        without joint 1 plans joint 1 with joint 2's parameters, with a warning
        (:data:`BORROWED_JOINT1`).
    geometry : Geometry
        The arm's two lengths (:class:`stickslip.kinematics.Geometry`; measure yours,
        docs/taskspace.md).
    burst : int
        Steps per burst, 1..65535.
    max_burst_s : float
        Longest burst on a controller stepping in real time, s, in (0, 0.4].
    segment : float
        Longest segment of the straight line, m (default 10 µm).
    name : str
    """

    def __init__(
        self,
        link: DeviceLink,
        calibration: Callable[[], Calibration | None],
        geometry: kin.Geometry = kin.DEFAULT_GEOMETRY,
        *,
        burst: int = 1000,
        max_burst_s: float = 0.2,
        segment: float = 10e-6,
        name: str = "",
        guard: Guard | None = None,
    ) -> None:
        if not isinstance(geometry, kin.Geometry):
            raise ValueError(f"geometry must be a stickslip.kinematics.Geometry, got {geometry!r}")
        self._driver = _TipDriver(
            link, calibration, geometry, check_burst(burst), check_max_burst_s(max_burst_s), float(segment), guard
        )
        with self.add_children_as_readables():
            self.x = TipAxis(self._driver, 0)
            self.y = TipAxis(self._driver, 1)
            self.z = TipAxis(self._driver, 2)
        for axis in (self.x, self.y, self.z):
            self._driver.observers.append(axis._publish)
            self._driver.setpoints.append(axis._show_target)
        super().__init__(name=name)

    @property
    def geometry(self) -> kin.Geometry:
        """The arm's lengths the tip is computed with."""
        return self._driver.geometry

    def observe(self, state: DeviceState) -> None:
        """Put the tip of ``state``'s kept joints into the readbacks (on the event loop)."""
        self._driver.publish(state)

    def where(self, state: DeviceState) -> Vec3:
        """The tip of ``state``'s kept joints, m."""
        return self._driver.tip_of(state)
