"""The control room: one process owns the manipulator, and every request calls one library procedure.

:class:`ControlRoom` opens the controller, the store and the calibration once and holds
the device's lock for as long as it runs. Each verb parses nothing (the web layer has
done that) and calls exactly one procedure, the one the command line calls for the same
verb: :func:`~stickslip.procedures.move.move`, :func:`~stickslip.procedures.reach.reach`,
:func:`~stickslip.procedures.jog.jog`, :func:`~stickslip.procedures.where.where`,
:func:`~stickslip.procedures.observe.observe`, :func:`~stickslip.procedures.session.traverse`,
:func:`~stickslip.procedures.move.step_joint`, :func:`~stickslip.procedures.day.calibration_day`,
the named positions of :mod:`stickslip.procedures.named`.

Safety:

* **One motion at a time.** A motion (a move, a reach, a jog session, a traverse, the
  calibration day) takes the manipulator's one slot; a second is refused with what is
  running (:class:`Busy`), never queued.
* **STOP preempts everything** (:meth:`ControlRoom.stop`): no further burst is sent, the
  controller is told to stop now, a jog session and the calibration day end. The kept
  positions stay honest (the move journal): exact where the controller says how far a
  burst went, uncertain over the burst otherwise.
* **Refusals before anything moves**: a motion's request is checked by its procedure
  before its first burst; :meth:`ControlRoom.launch` waits for that and raises the
  procedure's refusal as :class:`Refused`, with its one line.

The live view (:meth:`ControlRoom.snapshot`) is built from memory (the state each
procedure saves is seen as it is saved), so it costs no database read.
"""

from __future__ import annotations

import collections
import itertools
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from .. import kinematics as kin
from ..calibration import Calibration
from ..clock import today_label
from ..devices.base import Controller, KnowsTruePosition, device_key, open_device, redact_url
from ..devices.positions import load_state
from ..procedures.arms import arm_opener
from ..procedures.jog import JogRequest, JogStatus, jog
from ..procedures.move import DeviceBusy, MoveRequest, PoseUpdate, device_lock, move, step_joint
from ..procedures.observe import Observation, observe
from ..procedures.reach import BORROWED_JOINT1, ReachRequest, reach
from ..procedures.rigstop import RigStopWatch
from ..procedures.session import TraverseRequest, traverse
from ..procedures.where import where
from ..rig import Rig
from ..storage import Store
from ..units import format_position
from .day import CalibrationDay
from .owned import HeldStore, OwnedController
from .pad import PadKeys
from .positions import NamedPositions
from .slot import (
    KEEP_EVENTS,
    MAX_BURST_S,
    START_TIMEOUT_S,
    Busy,
    Conflict,
    Motion,
    NotFound,
    Presses,
    Refused,
    RoomOptions,
    Unavailable,
    one_line,
    refusal,
    refusals,
)
from .stopping import Stopping
from .view import LiveView

__all__ = [
    "MAX_BURST_S", "START_TIMEOUT_S", "Busy", "Conflict", "ControlRoom", "Motion", "NotFound", "Refused",
    "RoomOptions", "Unavailable", "one_line", "refusal", "serve_problem",
]

log = logging.getLogger("stickslip.server")


def serve_problem(rig: Rig, arm: str | None) -> str | None:
    """Why the room cannot serve ``arm`` of ``rig`` (one line), or ``None``.

    The room's procedures plan an MM3A's joints and keep positions per controller, so an
    ``xyz`` arm, or one that shares its controller with another arm, is not served yet.
    """
    a = rig.arm(arm)
    if a.kind != "mm3a":
        return (f"--rig: arm {a.name!r} is a stage ({a.kind}); the server plans an MM3A's joints, so it serves "
                "MM3A arms only for now (drive the stage from the command line)")
    if rig.state_key(a.name) != device_key(a.controller):
        return (f"--rig: arm {a.name!r} shares its controller with another arm; the server keeps positions per "
                "controller, so it serves arms on a controller of their own only for now")
    return None


class ControlRoom(LiveView, CalibrationDay, NamedPositions, Stopping):
    """The manipulator, its store and its calibration, owned by one process (see the module docstring).

    Parameters
    ----------
    options : RoomOptions
    opener : callable, optional
        Opens the controller (default :func:`~stickslip.devices.base.open_device`).
    store_factory : callable, optional
        Opens the database (default: ``Store.open(options.db)``).
    """

    def __init__(
        self,
        options: RoomOptions,
        opener: Callable[[str], Controller] | None = None,
        store_factory: Callable[[], Store] | None = None,
    ):
        if options.rig is not None and (problem := serve_problem(options.rig, options.arm)) is not None:
            raise ValueError(problem)
        self.options = options
        self.url = options.device
        self.key = device_key(options.device)
        self._factory = store_factory or (lambda: Store.open(options.db))
        self.store = HeldStore(self._factory, self._saw_state)
        self._lock = threading.RLock()
        self._ids = itertools.count(1)
        self._events = collections.deque(maxlen=KEEP_EVENTS)
        self._event_ids = itertools.count(1)
        self._motions = collections.OrderedDict()
        self._motion = None
        self._pad = None
        self._jog_latched = False  # STOP ended a jog: no new one until its key is let go (an e-stop latches)
        self._jog_status = None
        self._day = None  # the day's progress, rows done, waiting for a pose
        self._day_pose = threading.Event()
        self._level = None
        self.stops = []
        self._presses = Presses()
        self._tunings = dict(options.tunings)
        self._holder: dict[str, Any] | None = None
        self._lock_cm: Any = None
        main = self.store.store()
        self._state = load_state(main, self.key)
        self.calibration, self.calibration_source = self._first_calibration(main)
        self._take_device_lock(main)
        if options.rig is not None:
            opener = arm_opener(options.rig, options.arm, opener or open_device)
        try:
            dev = (opener or open_device)(options.device)
        except BaseException:
            self._release_device_lock()
            raise
        self.owned = OwnedController(dev)
        self._rig_watch = None
        if options.rig is not None:  # the rig's STOP, pressed on any arm's page, read before each burst
            self._rig_watch = RigStopWatch(options.rig, options.rig.arm(options.arm).name)
            self.owned.before_burst = self._rig_poll
        self.info = dev.info
        if isinstance(dev, KnowsTruePosition) and hasattr(dev, "set_pose"):
            dev.set_pose(*self._state.pose)  # the simulator starts where the kept positions say
        self.event("info", f"serving {redact_url(self.url)} ({self.info.model})")

    # ------------------------------------------------------------ lifetime

    def _first_calibration(self, store: Store) -> tuple[Calibration | None, str]:
        if self.options.calibration is not None:
            return Calibration.load(self.options.calibration), str(self.options.calibration)
        cal = store.latest_calibration(self.key)
        return (cal, f"the latest stored for {self.key}") if cal is not None else (None, "none")

    def _take_device_lock(self, store: Store) -> None:
        cm = device_lock(store, self.key)
        try:
            self._holder = cm.__enter__()
        except DeviceBusy as e:
            raise DeviceBusy(str(e).replace("wait for it to finish", "stop it first")) from None
        self._lock_cm = cm

    def _release_device_lock(self) -> None:
        if self._lock_cm is not None:
            cm, self._lock_cm = self._lock_cm, None
            try:
                cm.__exit__(None, None, None)
            except Exception as e:  # noqa: BLE001 - at exit: say it, do not die of it
                log.warning("could not release the device lock: %s", one_line(e))

    def close(self) -> None:
        """STOP (this arm's, not the rig's), wait briefly for the motion to end, release the lock, close the
        controller and the store."""
        self._stop_here(None)
        m = self._motion
        if m is not None:
            m.finished.wait(2.0)
        self.owned.shutdown()
        self._release_device_lock()
        self.store.close_all()

    # ------------------------------------------------------------ the verbs

    def where(
        self, references: list[tuple[int, float]] | None = None, pose: PoseUpdate | None = None
    ) -> dict[str, Any]:
        """The kept positions (:func:`~stickslip.procedures.where.where`), after recording references or a pose.

        Refused while a motion runs if it would record anything (:class:`Busy`).
        """
        refs = references or []
        pose = pose or PoseUpdate()
        if refs or pose != PoseUpdate():
            cur = self.current()
            if cur is not None:
                raise Busy(f"{cur.what} is running: positions are recorded only while nothing moves")
        try:
            with refusals():
                result = where(self.store, self.url, references=refs, pose=pose, offline=True)
        finally:
            self.store.close_thread()
        out = result.as_dict()
        out["answers"] = self.info.model
        if refs or pose != PoseUpdate():
            self.event("info", f"recorded {', '.join(result.changed)}")
        return out

    def move(self, joint: int, by: float | None, to: float | None, pose: PoseUpdate | None = None) -> Motion:
        """A planned move of one joint (:func:`~stickslip.procedures.move.move`), run as a motion."""
        cal, _ = self._need_calibration("a move")
        amount = f"by {format_position(by, joint)}" if by is not None else f"to {format_position(to or 0.0, joint)}"
        req = MoveRequest(self.url, joint, by=by, to=to, burst=self._burst(joint), pose=pose or PoseUpdate(),
                          max_age_days=self.options.max_age_days)
        path = self._joint_path(joint, by, to)

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            r = move(self.store, replace(req, guard=self._guard()), cal, warn=self._warn(m), ready=ready,
                     opener=self._opener)
            out = r.as_dict()
            out["failure"] = r.failure()
            return out

        return self.launch("move", f"move of joint {joint} {amount}", body, path)

    def _joint_path(self, joint: int, by: float | None, to: float | None) -> list[list[float]] | None:
        st = self.state()
        q0 = [st.positions[j] for j in (1, 2, 3)]
        target = (q0[joint - 1] + by) if by is not None else to
        if target is None or not math.isfinite(target):
            return None
        pts = []
        for k in range(33):
            q = list(q0)
            q[joint - 1] = q0[joint - 1] + (target - q0[joint - 1]) * (k / 32)  # k / 32 exact: no overflow
            pts.append([float(v) for v in kin.tip(q, self.options.geometry)])
        return pts

    def step(self, joint: int, steps: int) -> Motion:
        """Raw steps, no calibration (:func:`~stickslip.procedures.move.step_joint`): the joint is then uncertain."""
        if steps == 0:
            raise Refused("steps: 0 steps moves nothing")
        if self.options.rig is not None:
            raise Conflict("raw steps are refused with a rig: they are not planned, so the rig's envelope cannot "
                           "check where they go; move the joint by or to an amount instead")

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            r = step_joint(self.store, self.url, joint, steps, burst=self._burst(joint), ready=ready,
                           opener=self._opener)
            out = r.as_dict()
            out["failure"] = r.outcome.error
            return out

        return self.launch("step", f"{steps:+d} raw steps of joint {joint}", body)

    def reach(self, to: tuple[float, float, float] | None, by: tuple[float, float, float] | None) -> Motion:
        """A straight tip move (:func:`~stickslip.procedures.reach.reach`), run as a motion."""
        cal, borrowed = self._need_calibration("a tip move", borrow=True)
        req = ReachRequest(self.url, to=to, by=by, geometry=self.options.geometry, burst=self._burst(),
                           max_age_days=self.options.max_age_days)
        st = self.state()
        start = [float(v) for v in kin.tip([st.positions[j] for j in (1, 2, 3)], self.options.geometry)]
        end = list(to) if to is not None else [s + d for s, d in zip(start, by or (0.0, 0.0, 0.0), strict=True)]
        what = "tip move " + (
            "to (" + ", ".join(f"{v * 1e6:.1f}" for v in end) + ") µm" if to is not None
            else "by (" + ", ".join(f"{v * 1e6:+.1f}" for v in (by or (0, 0, 0))) + ") µm"
        )

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            r = reach(self.store, replace(req, guard=self._guard()), cal, borrowed, warn=self._warn(m), ready=ready,
                      opener=self._opener)
            out = dict(r.as_dict())
            out["failure"] = r.failure()
            return out

        return self.launch("reach", what, body, [start, [float(v) for v in end]])

    def jog_hold(self, direction: str, speed: int | None = None) -> dict[str, Any]:
        """A jog key held (or its keep-alive); starts a session if none runs (:func:`~stickslip.procedures.jog.jog`).

        Jog is refused while another motion runs (:class:`Busy`: "jog is disabled while a
        plan runs"), and after a STOP that ended a jog until its key is let go (:meth:`jog_release`):
        a script's keep-alives, or a key still held, do not start the arm again.
        """
        with self._lock:
            pad, latched = self._pad, self._jog_latched
        if pad is not None:
            pad.hold(direction, speed)
            return {"jog": "held", "direction": direction}
        if latched:
            raise Busy("STOP ended the jog: let go of the jog key (release) before jogging again")
        cur = self.current()
        if cur is not None:
            raise Busy(f"jog is disabled while a plan runs: {cur.what} (motion {cur.id}); wait for it or press STOP")
        cal, borrowed = self._need_calibration("jogging", borrow=True)
        new_pad = PadKeys(hold_s=self.options.jog_hold_s, idle_end_s=self.options.jog_idle_end_s)
        new_pad.hold(direction, speed)  # the first key: checked before the session starts
        req = JogRequest(self.url, self.options.geometry, speed=speed or 4, max_rate=self.options.jog_max_rate,
                         hold=new_pad.hold_s, max_age_days=self.options.max_age_days)

        def show(status: JogStatus) -> None:
            with self._lock:
                self._jog_status = status

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            if borrowed:
                self._warn(m)(BORROWED_JOINT1)
            try:
                r = jog(self.store, replace(req, guard=self._guard()), cal, keys=lambda: new_pad, show=show,
                        warn=self._warn(m), ready=ready, opener=self._opener)
            finally:
                with self._lock:
                    if self._pad is new_pad:
                        self._pad = None
            return {"sent": list(r.status.sent), "message": r.status.message, "failure": r.error,
                    "deadman": new_pad.deadman}

        with self._lock:
            self._pad = new_pad
            self._jog_status = None
        try:
            m = self.launch("jog", "jog", body)
        except Refused:
            with self._lock:
                if self._pad is new_pad:
                    self._pad = None
            raise
        return {"jog": "started", "direction": direction, "motion": m.id}

    def jog_release(self, end: bool = False) -> dict[str, Any]:
        """Let go of the jog key: the tip stops at once; the session ends soon after by itself, or now if ``end``.

        It also unlatches a jog STOP ended (:meth:`stop`): the next press starts a jog again.
        """
        with self._lock:
            pad = self._pad
            m = self._motion
            self._jog_latched = False
        if pad is not None:
            pad.end() if end else pad.release()
        out: dict[str, Any] = {"jog": "released" if pad is not None else "idle"}
        if pad is not None and m is not None and m.kind == "jog":
            out["motion"] = m.id
        return out

    def observe(self, joint: int, q: float, sd: float | None, at_stop: bool, force: bool) -> dict[str, Any]:
        """A measured position into the joint's track (:func:`~stickslip.procedures.observe.observe`)."""
        cur = self.current()
        if cur is not None:
            raise Busy(f"{cur.what} is running: a position is observed only while nothing moves")
        try:
            with refusals():
                r = observe(self.store, self.url, Observation(joint, q, sd, at_stop, force))
        finally:
            self.store.close_thread()
        self.event("info", f"joint {joint} observed at {format_position(q, joint)}")
        return r.as_dict()

    def traverse(self, joint: int, direction: str) -> Motion:
        """One traverse timed by the limit switch (:func:`~stickslip.procedures.session.traverse`), in the kept pose."""
        tuning = self._tuning(joint)
        st = self.state()

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            self.check_sweep(joint, direction, [st.positions[j] for j in (1, 2, 3)], st)
            ready()
            r = traverse(self.store, TraverseRequest(self.url, joint, direction, st.pose, today_label(), tuning),
                         progress=lambda steps, t: self._progress(m, {"steps": steps, "device_s": t}),
                         on_warning=self._warn(m), opener=self._opener)
            return {"steps": r.steps, "gamma": r.gamma, "unit": kin.joint_spec(joint).unit,
                    "row": {"start": r.traverse.start, "end": r.traverse.end, "steps": r.traverse.steps}}

        return self.launch("traverse", f"traverse of joint {joint}{direction}", body)

    def _progress(self, m: Motion, p: dict[str, Any]) -> None:
        m.progress = p

