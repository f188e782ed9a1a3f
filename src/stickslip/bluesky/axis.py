"""One joint of a stick-slip manipulator as an ophyd-async device (Movable, Locatable, Stoppable, Readable).

:class:`StickSlipAxis` moves a joint the way ``stickslip move`` does, with the same
procedure's pieces: the position kept for the device in the database
(:func:`~stickslip.devices.positions.load_state`), the move planned with the day's
tracked step scale (:func:`~stickslip.procedures.move.plan_tracked`: the calibration's
step-size model in that pose, scaled by what ``stickslip observe`` taught the joint's
Kalman track), the burst loop with its write-ahead journal
(:func:`~stickslip.procedures.move.drive`), the kept end and grown uncertainty
(:func:`~stickslip.procedures.move.settle`) and the one-process-per-device lock
(:func:`~stickslip.procedures.move.device_lock`). A move made here is seen by
``stickslip where`` and the other way round.

Positions are SI: m for the prismatic joint 3, rad for the rotary joints 1 and 2; the
units are in ``describe()``. The MM3A has no sensors, so the readback is the
*dead-reckoned* position (the model's prediction for the steps sent), not a measurement.

Blocking controller calls run in a worker thread (one move at a time per controller);
the event loop stays free for :meth:`StickSlipAxis.stop`, which makes the loop send no
further burst and tells the controller to stop. A stop is prompt by design, not by the
controller's good will: on a controller that steps in real time a burst lasts at most
``max_burst_s`` (0.2 s by default; the burst is shortened to ``frequency * max_burst_s``
steps), so even a controller that ignores ``stop`` finishes its burst within that, and
:meth:`~StickSlipAxis.stop` returns within :data:`STOP_RETURN_S` (0.5 s). After a stop the kept position is
honest: exact (to the model) when the stop fell between bursts, else *uncertain*
between the last confirmed position and the interrupted burst's end (the ``uncertain``
signal is true and the next move refuses until the joint is re-referenced).
"""

from __future__ import annotations

import asyncio
import math
import os
import threading
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from bluesky.protocols import Checkable, Locatable, Location, Reading, Stoppable
from ophyd_async.core import (
    Array1D,
    Device,
    DeviceConnector,
    StandardReadable,
    WatchableAsyncStatus,
    WatcherUpdate,
    soft_signal_r_and_setter,
)
from ophyd_async.core import StandardReadableFormat as Format

from .. import kinematics as kin
from ..calibration import Calibration
from ..devices.base import (
    BurstStopped,
    Controller,
    DeviceError,
    DeviceInfo,
    PoseSettable,
    VirtualClock,
    check_device_url,
    device_key,
    open_device,
)
from ..devices.identity import ControllerChanged, check_controller
from ..devices.positions import DeviceState, StateStore, load_state, save_state, where_set_command
from ..motion.planning import Planner
from ..procedures.arms import on_store
from ..procedures.closed_loop import FINDING_TIP, CameraLoop, move_seen
from ..procedures.move import (
    DeviceBusy,
    MoveOutcome,
    MoveRefused,
    MoveRequest,
    claimed,
    device_lock,
    drive,
    failure_text,
    joint_line,
    plan_tracked,
    reference_problem,
    settle,
)
from ..procedures.rigstop import RigStopWatch
from ..rig.guard import Guard
from ..storage import Store, StoreError, resolve_database
from ..units import format_position, position_display_unit

__all__ = ["DeviceLink", "MoveError", "StickSlipAxis", "MAX_BURST_S", "STOP_RETURN_S"]

MAX_BURST_S = 0.2
"""Default longest burst on a controller that steps in real time, s: the longest a stop can
wait for a burst in flight on a controller that does not cut bursts short."""
STOP_RETURN_S = 0.5
"""The longest :meth:`StickSlipAxis.stop` waits, s: for the burst in flight (at most
``max_burst_s``) and the controller's ``stop``; the margin, 0.3 s at the default, is for
the controller's answer and one journal write to the database."""

POSE_UNITS = "rad, rad, m, rad, rad"
"""Units of the ``pose`` signal's five elements ``q1, q2, q3, theta, psi``."""


class MoveError(RuntimeError):
    """A move was refused or failed; the message says why and what the kept position is."""


class _Stopped(Exception):
    """Raised inside the burst loop when a stop was requested (``partial``: during a burst)."""

    def __init__(self, partial: bool):
        super().__init__("stopped")
        self.partial = partial


class DeviceLink:
    """One controller and database shared by the axes of one manipulator.

    The controller is opened once (lazily, from its URL) and kept open; moves through it
    run one at a time (an :class:`asyncio.Lock` in this process, the database lock
    between processes).

    Parameters
    ----------
    device : str or Controller
        A controller URL (``sim://``, ``mm3a:///dev/ttyUSB0``, ...) or an open
        controller (its ``info.url`` names it in the database).
    db : path or str, optional
        The database: an SQLite file or a ``postgresql://`` URL (default ``$STICKSLIP_DB``,
        else the user's data folder).
    """

    def __init__(self, device: str | Controller, db: str | os.PathLike[str] | None = None):
        if isinstance(device, str):
            check_device_url(device)  # a URL without a scheme is never the simulator (its key was sim://)
            self.url = device
            self._ctrl: Controller | None = None
        else:
            self.url = device.info.url
            self._ctrl = device
        self.owned = isinstance(device, str)
        self.key = device_key(self.url)
        self.db: Path | str | None = None if db is None else resolve_database(db)
        self.lock = asyncio.Lock()
        self._open_lock = threading.Lock()

    def store(self) -> Store:
        """The database, opened for one unit of work (close it after; SQLite is per thread)."""
        return Store.open(self.db)

    def load(self) -> DeviceState:
        """The kept state of the device (positions, tilt, journal)."""
        with self.store() as store:
            return load_state(store, self.key)

    def controller(self) -> Controller:
        """The open controller; opened on first use (a simulator is placed at the kept pose)."""
        with self._open_lock:
            if self._ctrl is None:
                ctrl = open_device(self.url)
                if isinstance(ctrl, PoseSettable):  # a fresh simulator starts where the positions say
                    ctrl.set_pose(*self.load().pose)
                self._ctrl = ctrl
            return self._ctrl

    def checked(self, store: StateStore, state: DeviceState, publish: Callable[[DeviceState], None]) -> Controller:
        """The open controller, if it is the one ``state``'s positions were kept for (devices.identity); else
        every joint of ``state`` is left uncertain (saved, published) and :class:`MoveError` says so."""
        dev = self.controller()
        try:
            check_controller(store, self.url, dev, [state])
        except ControllerChanged as e:
            publish(state)
            raise MoveError(str(e)) from None
        return dev

    def close(self) -> None:
        """Close the controller if this link opened it."""
        with self._open_lock:
            if self._ctrl is not None and self.owned:
                try:
                    self._ctrl.close()
                except DeviceError:
                    pass
                self._ctrl = None


class _Interruptible:
    """A :class:`Controller` that sends no burst once ``stop`` is set, and says whether one was cut short.

    ``atomic``: the controller completes a burst at once (a simulator on a virtual
    clock), so a stop during its call never cuts it. ``rig_stop()``: why the rig's STOP stops
    this arm (:func:`rig_stop`), read before each burst; the burst is then refused with
    :class:`~stickslip.devices.base.BurstStopped` (no step made: the position kept exact), as
    ``stickslip move --rig`` refuses it.
    """

    def __init__(
        self, dev: Controller, stop: threading.Event, atomic: bool, rig_stop: Callable[[], str | None] | None = None
    ):
        self.dev = dev
        self.stop_event = stop
        self.atomic = atomic
        self.rig_stop = rig_stop
        self.sent = 0
        self.joint = 0  # the joint of the last burst asked for

    @property
    def info(self) -> DeviceInfo:
        return self.dev.info

    def set_frequency(self, joint: int, hz: float) -> None:
        self.dev.set_frequency(joint, hz)

    def frequency(self, joint: int) -> float:
        return self.dev.frequency(joint)

    def step(self, joint: int, n: int) -> None:
        self.joint = joint
        if self.stop_event.is_set():
            raise _Stopped(partial=False)
        why = None if self.rig_stop is None else self.rig_stop()
        if why is not None:
            raise BurstStopped(why, 0)
        self.dev.step(joint, n)
        if self.stop_event.is_set() and not self.atomic:
            raise _Stopped(partial=True)
        self.sent += n

    def stop(self, joint: int | None = None) -> None:
        self.dev.stop(joint)

    def settings(self) -> dict[str, object]:
        return self.dev.settings()

    def close(self) -> None:
        self.dev.close()


def rig_stop(store: StateStore, guard: Guard | None) -> Callable[[], str | None] | None:
    """For an arm of a rig (``guard``): why the rig's STOP, pressed for another arm since now, stops this move
    (:class:`~stickslip.procedures.rigstop.RigStopWatch`), else ``None``; ``None`` without a rig."""
    if guard is None:
        return None
    watch = RigStopWatch(guard.rig, guard.arm)
    watch.begin(store)
    return lambda: watch.stopped(store)


def bounded_burst(dev: Controller, joint: int, burst: int, max_burst_s: float) -> int:
    """Steps per burst so that one burst lasts at most ``max_burst_s`` (s) at the joint's frequency.

    A controller on a virtual clock (the simulator) completes a burst at once, so its
    burst is not shortened. A frequency the controller cannot tell leaves ``burst``.
    A burst is at least one step, so below ``1 / max_burst_s`` Hz (5 Hz at the default)
    a burst lasts one step's period, longer than ``max_burst_s``.
    """
    if isinstance(dev, VirtualClock):
        return burst
    try:
        hz = float(dev.frequency(joint))
    except DeviceError:
        return burst
    if not (math.isfinite(hz) and hz > 0):
        return burst
    return max(1, min(burst, int(hz * max_burst_s)))


async def halt(link: DeviceLink, joint: int | None, task: asyncio.Future[Any] | None) -> None:
    """Tell the controller to stop and wait for the move's worker ``task``, at most :data:`STOP_RETURN_S` in all.

    The caller has already set the stop event (no further burst is sent). The controller's
    ``stop`` runs in a thread; neither it nor the task is waited for past the deadline
    (the move's status still settles the kept position when its burst ends).
    """
    if task is None:
        return

    def tell() -> None:
        try:
            link.controller().stop(joint)
        except DeviceError:
            pass  # the burst loop sends nothing more either way

    told = asyncio.ensure_future(asyncio.to_thread(tell))
    await asyncio.wait([task, told], timeout=STOP_RETURN_S)


def check_arm_device(key: str, guard: Guard | None) -> None:
    """:class:`MoveError` unless an axis kept under ``key`` is the arm its ``guard`` names (its key the rig's
    :meth:`~stickslip.rig.Rig.state_key` of that arm): its claim would be kept where the other arms do not read it,
    and it would be checked as that arm at rest. Joint and tip moves (:func:`hold_claim`) and the closed loop."""
    if guard is not None and guard.fresh is not None and key != guard.rig.state_key(guard.arm):
        raise MoveError(
            f"arm {guard.arm!r} of the rig is kept under {guard.rig.state_key(guard.arm)!r}, and this axis's device "
            f"under {key!r}: give the axis the arm's controller as the rig file names it "
            "(an arm that shares its controller is not driven by a Bluesky axis)"
        )


def hold_claim(
    stack: ExitStack, store: StateStore, state: DeviceState, guard: Guard | None, path: Sequence[Sequence[float]],
    calibration: Calibration,
) -> None:
    """Check ``path`` against the rig's other arms as kept now and claim its range, as ``stickslip move --rig`` does
    ("mark, then check": :func:`~stickslip.procedures.move.claimed`), until ``stack`` closes (the move ends, is
    refused, stopped or fails); :class:`MoveError` if refused (nothing claimed, nothing sent)."""
    check_arm_device(state.device, guard)
    try:
        stack.enter_context(claimed(store, state, on_store(guard, store), path, calibration))
    except MoveRefused as e:
        raise MoveError(str(e)) from None


class _Held:
    """The link's controller as a closed-loop move sees it: steps through the stop-aware proxy, never closed."""

    def __init__(self, proxy: _Interruptible, dev: Controller):
        self._proxy = proxy
        self._dev = dev

    def step(self, joint: int, n: int) -> None:
        self._proxy.step(joint, n)

    def close(self) -> None:
        pass  # the link keeps it open for the next move

    def __getattr__(self, name: str) -> Any:
        return getattr(self._dev, name)


@dataclass(frozen=True)
class _MoveResult:
    steps: int
    sent: int
    stopped: bool
    state: DeviceState


def check_burst(burst: object) -> int:
    """``burst`` as steps per burst; ``ValueError`` unless an integer in 1..65535."""
    if isinstance(burst, bool) or not isinstance(burst, int) or not 1 <= burst <= 65535:
        raise ValueError(f"burst must be an integer number of steps in 1..65535, got {burst!r}")
    return burst


def check_max_burst_s(seconds: object) -> float:
    """``seconds`` as the longest burst, s; ``ValueError`` unless in (0, 0.4] (a stop must return within 0.5 s)."""
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not 0 < float(seconds) <= 0.4:
        raise ValueError(
            f"max_burst_s must be a duration in (0, 0.4] s (a stop returns within {STOP_RETURN_S} s), got {seconds!r}"
        )
    return float(seconds)


class _AxisConnector(DeviceConnector):
    """Connects the soft signals, then opens the controller and reads the kept position."""

    async def connect_real(self, device: Device, timeout: float, force_reconnect: bool) -> None:
        await super().connect_real(device, timeout, force_reconnect)
        if isinstance(device, StickSlipAxis):
            await device.refresh(open_controller=True)


def _kept_after_stop(store: StateStore, key: str, joint: int) -> DeviceState:
    """The kept state after a closed-loop move stopped before a burst: the confirmed position stands (not after the
    steps out to find the tip, which leave the joint uncertain), saved."""
    state = load_state(store, key)
    if FINDING_TIP not in state.why.get(joint, ""):
        state.set_position(joint, state.positions[joint], state.sources[joint])
    save_state(store, state)
    return state


def _followed(camera: CameraLoop, seen: tuple[float, float] | None) -> CameraLoop:
    """The camera loop of the next move: its tip pixel where this move last saw the tip, or found again (``None``)
    when it was not seen at the end; a loop given no tip finds it at every move anyway.

    ``CameraLoop(tip=...)`` gives the tip's pixel *now*; after a move the tip is elsewhere and the first move's
    pixel lies on the shaft (a scan's second point stopped "the fit did not settle").
    """
    return replace(camera, tip=seen) if camera.tip is not None else camera


class StickSlipAxis(StandardReadable, Locatable[float], Stoppable, Checkable[float]):
    """One joint of a stick-slip manipulator, moved with a calibrated load-aware step-size model.

    Parameters
    ----------
    device : str, Controller or DeviceLink
        Controller URL (``sim://``, ``mm3a:///dev/ttyUSB0``, ...), an open controller,
        or a :class:`DeviceLink` shared with the other axes of the arm.
    joint : int
        1, 2 (rotary, rad) or 3 (prismatic, m).
    calibration : Calibration, path or None
        The calibration (or its JSON file, from ``stickslip calibrate``); ``None``: moves
        are refused until :meth:`use_calibration` gives one (e.g. after a calibration day).
    name : str
        Device name (the readback's data key).
    burst : int
        Steps per burst, 1..65535 (as ``stickslip move --burst``); a stop takes effect
        between bursts.
    db : path or str, optional
        The database keeping positions: an SQLite file or a ``postgresql://`` URL (default
        ``$STICKSLIP_DB``, else the user's data folder).
    max_burst_s : float
        Longest burst, s (default :data:`MAX_BURST_S`, 0.2 s; in (0, 0.4]): on a controller
        that steps in real time a burst is cut to ``frequency * max_burst_s`` steps, so a
        stop returns within :data:`STOP_RETURN_S` even if the controller finishes its burst.
    from_unreferenced : bool
        Plan from a position never referenced (assumed) or uncertain, as ``stickslip move
        --from-unreferenced``; without it such a joint is refused on a real controller
        (:func:`~stickslip.procedures.move.reference_problem`).
    camera : CameraLoop, str or None
        A camera that looks at the tip (a URL with ``pixel=``, or a
        :class:`~stickslip.procedures.closed_loop.CameraLoop`): each move is then the
        closed loop of ``stickslip move --camera``
        (:func:`~stickslip.procedures.closed_loop.move_seen`), kept as ``seen``; a loop
        that stops short fails the status with its reason. A stop is taken between bursts.

    Signals
    -------
    readback : m or rad
        Dead-reckoned position (hinted).
    setpoint : m or rad
        The last target.
    last_steps : int
        Signed steps planned for the last move (0 before any).
    uncertain : bool
        The position is uncertain (an interrupted burst); re-reference the joint.
    pose : array of 5 floats
        ``q1, q2, q3`` (rad, rad, m) and the base tilt ``theta, psi`` (rad) kept for the device.
    """

    def __init__(
        self,
        device: str | Controller | DeviceLink,
        joint: int,
        calibration: Calibration | str | os.PathLike[str] | None,
        name: str = "",
        *,
        burst: int = 1000,
        db: str | os.PathLike[str] | None = None,
        max_burst_s: float = MAX_BURST_S,
        from_unreferenced: bool = False,
        camera: CameraLoop | str | None = None,
        guard: Guard | None = None,
    ) -> None:
        self.from_unreferenced = bool(from_unreferenced)
        if camera is not None and not isinstance(camera, (str, CameraLoop)):
            raise TypeError(f"camera= is a camera URL or a CameraLoop, not a {type(camera).__name__}")
        self.camera = CameraLoop(camera) if isinstance(camera, str) else camera
        self.guard = guard  # a rig's envelope (stickslip.procedures.arms.guard_for): every move (and leg) checked first
        self.spec = kin.joint_spec(joint)
        self.joint = self.spec.number
        self.burst = check_burst(burst)
        self.max_burst_s = check_max_burst_s(max_burst_s)
        self.calibration: Calibration | None = None
        if calibration is not None:
            self.use_calibration(calibration)
        self.link = device if isinstance(device, DeviceLink) else DeviceLink(device, db)
        unit = self.spec.unit
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.readback, self._set_readback = soft_signal_r_and_setter(float, math.nan, units=unit)
        with self.add_children_as_readables(Format.UNCACHED_SIGNAL):
            self.setpoint, self._set_setpoint = soft_signal_r_and_setter(float, math.nan, units=unit)
            self.last_steps, self._set_last_steps = soft_signal_r_and_setter(int, 0, units="steps")
            self.uncertain, self._set_uncertain = soft_signal_r_and_setter(bool, False)
            self.pose, self._set_pose = soft_signal_r_and_setter(
                Array1D[np.float64], np.full(5, math.nan), units=POSE_UNITS
            )
        self._stop_event = threading.Event()
        self._stop_success = False
        self._task: asyncio.Future[_MoveResult] | None = None
        self.observers: list[Callable[[DeviceState], None]] = []
        """Called on the event loop with every kept state this axis reads or writes (e.g. the tip's readbacks)."""
        super().__init__(name=name, connector=_AxisConnector())

    def set_name(self, name: str, *, child_name_separator: str | None = None) -> None:
        super().set_name(name, child_name_separator=child_name_separator)
        self.readback.set_name(name)  # the readback's data key is the axis's name (as ophyd motors do)

    def use_calibration(self, calibration: Calibration | str | os.PathLike[str]) -> None:
        """Plan moves with ``calibration`` (or its JSON file) from now on; ``ValueError`` if it lacks this joint."""
        cal = calibration if isinstance(calibration, Calibration) else Calibration.load(Path(calibration))
        if self.joint not in cal.joints:
            raise ValueError(f"joint {self.joint} is not in this calibration (it has joints {cal.joints})")
        self.calibration = cal

    def _calibration(self) -> Calibration:
        if self.calibration is None:
            raise MoveError(
                f"{self.name or f'joint {self.joint}'} has no calibration: give one (use_calibration), "
                f"or run the calibration_day plan first"
            )
        return self.calibration

    def __repr__(self) -> str:
        day = None if self.calibration is None else self.calibration.day
        return (
            f"StickSlipAxis(name={self.name!r}, device={self.link.key!r}, joint={self.joint}, "
            f"unit={self.spec.unit!r}, calibration_day={day!r})"
        )

    # ------------------------------------------------------------------ state

    def _publish(self, state: DeviceState) -> None:
        """Put the kept state into the signals and tell the observers (runs on the event loop)."""
        self.show(state)
        for observe in self.observers:
            observe(state)

    def show(self, state: DeviceState) -> None:
        """Put the kept state into this axis's signals only (runs on the event loop)."""
        self._set_readback(float(state.positions[self.joint]))
        self._set_uncertain(self.joint in state.uncertain)
        p = state.pose
        self._set_pose(np.array([p.q1, p.q2, p.q3, p.theta, p.psi], dtype=np.float64))

    async def refresh(self, open_controller: bool = False) -> DeviceState:
        """Read the kept position from the database into the signals (another process may have moved the joint)."""
        try:
            if open_controller:
                await asyncio.to_thread(self.link.controller)
            state = await asyncio.to_thread(self.link.load)
        except (StoreError, DeviceError, ValueError) as e:
            raise MoveError(str(e)) from None
        self._publish(state)
        if math.isnan(await self.setpoint.get_value()):
            self._set_setpoint(float(state.positions[self.joint]))
        return state

    async def read(self) -> dict[str, Reading[Any]]:
        """The signals, the kept position read in first (the CLI may have moved the joint): no stale event."""
        await self.refresh()
        return await super().read()

    async def locate(self) -> Location[float]:
        """Setpoint (the last target) and readback (the dead-reckoned position), m or rad."""
        await self.refresh()
        return Location(setpoint=await self.setpoint.get_value(), readback=await self.readback.get_value())

    # ------------------------------------------------------------------ checks

    def target_problem(self, value: object) -> str | None:
        """Why ``value`` cannot be a target of this joint (``None`` if it can)."""
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            return f"the target of joint {self.joint} must be a number in {self.spec.unit}, got {value!r}"
        q = float(value)
        if not math.isfinite(q):
            return f"the target of joint {self.joint} must be a finite number in {self.spec.unit}, got {q!r}"
        if not self.spec.contains(q):
            lo, hi = self.spec.lower, self.spec.upper
            shown = format_position(q, self.joint)
            return (
                f"the target {shown} ({q:.6g} {self.spec.unit}) is outside joint {self.joint}'s range "
                f"[{format_position(lo, self.joint)}, {format_position(hi, self.joint)}]; "
                f"{self.name or 'the axis'} takes SI units ({self.spec.unit}; displayed in "
                f"{position_display_unit(self.joint)})"
            )
        return None

    async def check_value(self, value: float) -> None:
        """Raise ``ValueError`` (nothing moves) if ``value`` is not a reachable target."""
        problem = self.target_problem(value)
        if problem:
            raise ValueError(problem)

    # ------------------------------------------------------------------ moving

    def _move_sync(self, target: float, publish: Callable[[DeviceState], None]) -> _MoveResult:
        """The whole move, in a worker thread: lock, plan from the kept state with its step scale, drive, record."""
        joint = self.joint
        cal = self._calibration()
        if self.camera is not None:
            return self._move_seen(target, publish, cal, self.camera)
        with self.link.store() as store, device_lock(store, self.link.key), ExitStack() as claim:
            state = load_state(store, self.link.key)
            unreferenced = self.from_unreferenced
            try:
                problem = reference_problem(state, joint, self.link.url, cal)
                if problem and not unreferenced:
                    raise MoveRefused(problem)
                plan = plan_tracked(
                    cal, state, joint, target, from_unreferenced=unreferenced,
                    assumed=problem is not None and joint not in state.uncertain,
                )
            except MoveRefused as e:
                raise MoveError(str(e)) from None
            hold_claim(claim, store, state, self.guard, joint_line(state, joint, plan.q_to), cal)
            publish(state)
            if plan.steps == 0:
                return _MoveResult(0, 0, False, state)
            dev = self.link.checked(store, state, publish)
            proxy = _Interruptible(dev, self._stop_event, isinstance(dev, VirtualClock), rig_stop(store, self.guard))
            source = state.sources[joint]

            def save(st: DeviceState) -> None:
                save_state(store, st)
                publish(st)

            burst = bounded_burst(dev, joint, self.burst, self.max_burst_s)
            try:
                moved_as = "assumed" if plan.assumed else "dead-reckoned"
                outcome = drive(proxy, state, joint, plan.steps, burst, plan.position_after, save, moved_as)
            except _Stopped as s:
                if not s.partial:  # the next burst was never sent: the confirmed position stands
                    kept = plan.position_after(proxy.sent)
                    state.set_position(joint, kept, moved_as if proxy.sent else source)
                settle(state, plan, MoveOutcome(proxy.sent, error="stopped"))
                save(state)
                return _MoveResult(plan.steps, proxy.sent, True, state)
            settle(state, plan, outcome)
            save(state)
            if outcome.error is not None and not self._stop_event.is_set():  # set: our stop, cut by the driver
                raise MoveError(failure_text(state, joint, outcome.error, outcome.sent, plan.steps))
            return _MoveResult(plan.steps, outcome.sent, outcome.error is not None, state)

    def _move_seen(
        self, target: float, publish: Callable[[DeviceState], None], cal: Calibration, camera: CameraLoop
    ) -> _MoveResult:
        """The closed-loop move (``move --camera``) through the link's controller, stop-aware between bursts."""
        check_arm_device(self.link.key, self.guard)
        dev = self.link.controller()
        with self.link.store() as store:
            proxy = _Interruptible(dev, self._stop_event, True, rig_stop(store, self.guard))  # and the rig's STOP
            request = MoveRequest(self.link.url, self.joint, to=target, burst=bounded_burst(
                dev, self.joint, self.burst, self.max_burst_s), from_unreferenced=self.from_unreferenced,
                guard=on_store(self.guard, store))  # the other arms as kept now; its legs claim (move_seen)
            try:
                result = move_seen(store, request, cal, camera, opener=lambda _url: cast(Controller, _Held(proxy, dev)))
            except _Stopped:  # before a burst was sent: the confirmed position stands
                self.camera = _followed(camera, None) if proxy.sent else camera
                state = _kept_after_stop(store, self.link.key, self.joint)
                publish(state)
                return _MoveResult(0, proxy.sent, True, state)
            except (MoveRefused, ValueError, RuntimeError) as e:
                raise MoveError(str(e)) from None
        self.camera = _followed(camera, result.looks[-1].pixel) if result.looks else camera
        publish(result.state)
        if not result.reached:
            raise MoveError(f"the closed loop stopped: {result.reason}")
        steps = sum(k.steps[self.joint - 1] for k in result.looks)
        return _MoveResult(steps, steps, False, result.state)

    def set(self, value: float) -> WatchableAsyncStatus[float]:
        """Move the joint to ``value`` (m or rad) in bursts; progress is reported after every burst.

        The status fails with :class:`ValueError` for a target outside the joint's range
        (nothing is sent), :class:`MoveError` for a refused or failed move (the message
        says what was sent and what the kept position is), and ``RuntimeError`` after
        ``stop(success=False)``.
        """
        self._stop_event.clear()  # here, not in the task: a stop() once set() has returned stops this move
        self._stop_success = False
        return self._set(value)

    @WatchableAsyncStatus.wrap
    async def _set(self, value: float) -> AsyncIterator[WatcherUpdate[float]]:
        await self.check_value(value)
        self._calibration()
        target = float(value)
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[DeviceState] = asyncio.Queue()

        def publish(state: DeviceState) -> None:  # from the worker thread
            loop.call_soon_threadsafe(queue.put_nowait, state)

        async with self.link.lock:
            initial = float((await self.refresh()).positions[self.joint])
            self._set_setpoint(target)
            task = asyncio.ensure_future(asyncio.to_thread(self._move_sync, target, publish))
            self._task = task
            try:
                while True:
                    getter = asyncio.ensure_future(queue.get())
                    waiting: list[asyncio.Future[Any]] = [task, getter]
                    await asyncio.wait(waiting, return_when=asyncio.FIRST_COMPLETED)
                    if not getter.done():
                        getter.cancel()
                        break
                    state = getter.result()
                    self._publish(state)
                    yield WatcherUpdate(
                        current=float(state.positions[self.joint]), initial=initial, target=target,
                        name=self.name, unit=self.spec.unit,
                    )
                while not queue.empty():
                    self._publish(queue.get_nowait())
                try:
                    result = task.result()
                except (DeviceBusy, StoreError, DeviceError, KeyError) as e:
                    raise MoveError(str(e).strip("'\"")) from None
            except asyncio.CancelledError:  # the status was cancelled: send no further burst
                self._stop_event.set()
                raise
            finally:
                self._task = None
        self._set_last_steps(result.steps)
        self._publish(result.state)
        if result.stopped and not self._stop_success:
            raise RuntimeError(self._stopped_text(result))

    def _stopped_text(self, result: _MoveResult) -> str:
        j = self.joint
        state = result.state
        if j in state.uncertain:
            lo, hi = state.uncertain[j]
            why = state.why[j] if FINDING_TIP in state.why.get(j, "") else "a burst was cut short"
            where = (
                f"its position is uncertain, between {format_position(lo, j)} and {format_position(hi, j)} "
                f"({why}); re-reference it ({where_set_command(state.device, j)} at the lower stop)"
            )
        else:
            where = f"its dead-reckoned position is {format_position(state.positions[j], j)}"
        return f"{self.name or f'joint {j}'} was stopped after {result.sent} of {result.steps} steps; {where}"

    async def stop(self, success: bool = False) -> None:
        """Stop now: no further burst is sent and the controller is told to stop.

        Returns once the move's worker has finished (the burst in flight: at once if the
        controller cuts it short, else within ``max_burst_s``), so the kept position and
        the signals are settled; at the latest after :data:`STOP_RETURN_S` (0.5 s). With
        ``success=False`` the move's status fails; with ``True`` it completes.
        """
        self._stop_success = success
        self._stop_event.set()
        await halt(self.link, self.joint, self._task)

    def describe_move(self, target: float) -> dict[str, Any]:
        """What a move to ``target`` (m or rad) would do from the kept state and step scale: the plan's fields (SI)."""
        state = self.link.load()
        plan = plan_tracked(self._calibration(), state, self.joint, target)
        return Planner(plan.calibration, self.joint, plan.pose).plan(plan.q_from, target).as_dict()
