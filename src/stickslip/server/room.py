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
import contextlib
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import kinematics as kin
from ..audio.detector import Tuning
from ..calibration import Calibration
from ..clock import now_utc, today_label
from ..devices.base import Controller, DeviceError, KnowsTruePosition, device_key, open_device, redact_url
from ..devices.positions import DeviceState, load_state
from ..motion.reach import borrow_joint1
from ..procedures import named
from ..procedures.day import DAY_PLAN, DayProgress, DayRequest, DayTraverse, calibration_day, simulator_tunings
from ..procedures.jog import JogRequest, JogStatus, jog
from ..procedures.move import (
    DeviceBusy,
    MoveRefused,
    MoveRequest,
    PoseUpdate,
    TargetOutOfRange,
    device_lock,
    is_simulator,
    move,
    step_joint,
)
from ..procedures.observe import Observation, observe
from ..procedures.reach import BORROWED_JOINT1, ReachRequest, reach
from ..procedures.session import TraverseRequest, traverse
from ..procedures.traverse import TraverseError
from ..procedures.where import state_rows, where
from ..storage import Store, StoreError
from ..units import format_position, format_spread, format_step
from .owned import HeldStore, OwnedController
from .pad import IDLE_END_S, PadKeys

__all__ = [
    "Busy", "Conflict", "ControlRoom", "Motion", "NotFound", "Refused", "RoomOptions", "Unavailable", "one_line",
    "refusal",
]

log = logging.getLogger("stickslip.server")

MAX_BURST_S = 0.2
"""Longest burst, s: a controller that does not cut a burst short on STOP finishes it within this,
and the positions on the page move on after every burst."""

START_TIMEOUT_S = 30.0
"""How long a request waits for its motion's procedure to check its input, s."""

_KEEP_MOTIONS = 50
_KEEP_EVENTS = 500


@contextlib.contextmanager
def refusals() -> Iterator[None]:
    """Raise a procedure's refusal (a move refused, a bad value, a device error) as the room's :class:`Refused`."""
    try:
        yield
    except Refused:
        raise
    except (MoveRefused, DeviceBusy, KeyError, ValueError, DeviceError, StoreError) as e:
        raise refusal(e) from None


def one_line(e: BaseException | str) -> str:
    """An exception's message as one line, without secrets (a ``KeyError``'s quotes removed)."""
    text = str(e.args[0]) if isinstance(e, KeyError) and e.args else str(e)
    text = " ".join(text.split()) or type(e).__name__
    return redact_url(text)


class Refused(ValueError):
    """A request the procedure (or the room) refused before anything moved; ``status`` is the HTTP status."""

    status = 422


class Busy(Refused):
    """Another motion holds the manipulator (the message names it)."""

    status = 409


class NotFound(Refused):
    """No such motion, or no such named position."""

    status = 404


class Conflict(Refused):
    """The request is well formed, but the manipulator's state refuses it (an uncertain joint, no calibration)."""

    status = 409


class Unavailable(Refused):
    """The device did not answer, or refused the command."""

    status = 503


def refusal(e: BaseException) -> Refused:
    """A procedure's refusal as the room's, with its HTTP status: 409 for the state, 422 for the value, 503 device."""
    if isinstance(e, Refused):
        return e
    text = one_line(e)
    if isinstance(e, TargetOutOfRange):
        return Refused(text)
    if isinstance(e, (MoveRefused, DeviceBusy, KeyError)):
        return Conflict(text)
    if isinstance(e, DeviceError):
        return Unavailable(text)
    return Refused(text)


@dataclass(frozen=True)
class RoomOptions:
    """What the room opens and how it drives.

    Attributes
    ----------
    device : str
        Controller URL (``sim://?realtime=1`` by default: the simulator in real time).
    db : Path or None
        The database (None: the default, as the command line's).
    calibration : Path or None
        Calibration JSON; None: the latest stored for the device, if any.
    tunings : mapping of int to Tuning
        Limit-switch tunings for traverses and the calibration day (a simulator is tuned
        from its own recordings when none are given).
    geometry : Geometry
        The arm's offset and length.
    max_age_days : int
        A calibration older than this is warned about.
    max_burst_s : float
        Longest burst, s (:data:`MAX_BURST_S`).
    jog_max_rate : float
        Most steps per second of any joint while jogging (the three joints share one
        controller: 300 steps/s each fit a 1 kHz controller's time).
    jog_idle_end_s : float
        A jog session with nothing held for this long ends, s (then a move may run).
    """

    device: str = "sim://?realtime=1"
    db: Path | None = None
    calibration: Path | None = None
    tunings: Mapping[int, Tuning] = field(default_factory=dict)
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY
    max_age_days: int = 0
    max_burst_s: float = MAX_BURST_S
    jog_max_rate: float = 300.0
    jog_idle_end_s: float = IDLE_END_S


class Motion:
    """One motion the room runs in its own thread: what it is, its state, its result."""

    def __init__(self, ident: int, kind: str, what: str, path: list[list[float]] | None = None):
        self.id = ident
        self.kind = kind
        self.what = what
        self.path = path
        self.status = "starting"  # -> running -> done | stopped | failed; or refused
        self.error: str | None = None
        self.refusal: Refused | None = None
        self.result: dict[str, Any] | None = None
        self.progress: dict[str, Any] | None = None
        self.started_at = now_utc().isoformat(timespec="seconds")
        self.t0 = time.monotonic()
        self.t_end: float | None = None
        self.stop_requested: float | None = None
        self.warnings: list[str] = []
        self._started = threading.Event()
        self.finished = threading.Event()

    @property
    def active(self) -> bool:
        """Still running (or starting)."""
        return not self.finished.is_set()

    def as_dict(self, full: bool = True) -> dict[str, Any]:
        """JSON shape: id, kind, what, status, times, error, warnings; with ``full`` the result and the path."""
        end = self.t_end if self.t_end is not None else time.monotonic()
        out: dict[str, Any] = {
            "id": self.id, "kind": self.kind, "what": self.what, "status": self.status, "error": self.error,
            "started_at": self.started_at, "elapsed_s": round(end - self.t0, 3), "progress": self.progress,
            "warnings": list(self.warnings),
        }
        if full:
            out["result"] = self.result
            out["path"] = self.path
        return out


class ControlRoom:
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
        self.options = options
        self.url = options.device
        self.key = device_key(options.device)
        self._factory = store_factory or (lambda: Store.open(options.db))
        self.store = HeldStore(self._factory, self._saw_state)
        self._lock = threading.RLock()
        self._ids = itertools.count(1)
        self._events: collections.deque[dict[str, Any]] = collections.deque(maxlen=_KEEP_EVENTS)
        self._event_ids = itertools.count(1)
        self._motions: collections.OrderedDict[int, Motion] = collections.OrderedDict()
        self._motion: Motion | None = None
        self._pad: PadKeys | None = None
        self._jog_status: JogStatus | None = None
        self._day: dict[str, Any] | None = None  # the day's progress, rows done, waiting for a pose
        self._day_pose = threading.Event()
        self._level: dict[str, Any] | None = None
        self.stops: list[tuple[float, float | None]] = []
        """``(when STOP was received, when the last step was sent after it)``, monotonic s (for benchmarks)."""
        self._tunings: dict[int, Tuning] = dict(options.tunings)
        self._holder: dict[str, Any] | None = None
        self._lock_cm: Any = None
        main = self.store.store()
        self._state = load_state(main, self.key)
        self.calibration, self.calibration_source = self._first_calibration(main)
        self._take_device_lock(main)
        try:
            dev = (opener or open_device)(options.device)
        except BaseException:
            self._release_device_lock()
            raise
        self.owned = OwnedController(dev)
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
        """STOP, wait briefly for the motion to end, release the lock, close the controller and the store."""
        self.stop()
        m = self._motion
        if m is not None:
            m.finished.wait(2.0)
        self.owned.shutdown()
        self._release_device_lock()
        self.store.close_all()

    # ------------------------------------------------------------ events and state

    def event(self, level: str, text: str) -> dict[str, Any]:
        """Record an event (``info``, ``warning``, ``error``) for the live view and the log."""
        e = {"id": next(self._event_ids), "at": now_utc().isoformat(timespec="seconds"), "level": level,
             "text": redact_url(text)}
        with self._lock:
            self._events.append(e)
        getattr(log, "warning" if level == "warning" else "error" if level == "error" else "info")(e["text"])
        return e

    def events_after(self, after: int) -> list[dict[str, Any]]:
        """The events with an id above ``after`` (oldest first; the last 500 are kept)."""
        with self._lock:
            return [e for e in self._events if e["id"] > after]

    @property
    def last_event_id(self) -> int:
        """The id of the newest event (0 if none)."""
        with self._lock:
            return self._events[-1]["id"] if self._events else 0

    def _saw_state(self, device: str, value: dict[str, Any]) -> None:
        if device != self.key:
            return
        try:
            st = load_state(_OneValue(value), device)
        except ValueError:
            return
        with self._lock:
            self._state = st

    def state(self) -> DeviceState:
        """The kept state as last saved (from memory)."""
        with self._lock:
            return self._state

    def snapshot(self) -> dict[str, Any]:
        """The live view: joints ± sd, the tip ± sd, the simulator's truth, the motion, jog, day, audio level."""
        state = self.state()
        rows = state_rows(state)
        with self._lock:
            running = self._motion is not None and self._motion.active
        geom = self.options.geometry
        q = [state.positions[j] for j in (1, 2, 3)]
        sd = []
        for j, r in zip((1, 2, 3), rows, strict=True):
            spec = kin.joint_spec(j)
            r["lower"], r["upper"] = spec.lower, spec.upper
            s = r.get("sd")
            if j in state.uncertain:
                lo, hi = state.uncertain[j]
                s = (hi - lo) / math.sqrt(12.0)  # spread of a position known only to lie in [lo, hi]
                r["uncertain_display"] = f"{format_position(lo, j)} to {format_position(hi, j)}"
                if running:  # a burst in flight (journalled before it is sent): moving, not lost
                    r["source"] = "moving"
            sd.append(float(s) if isinstance(s, (int, float)) else 0.0)
            shown = j not in state.uncertain  # an uncertain joint shows its bounds instead
            r["sd_display"] = format_spread(float(s), j) if shown and isinstance(s, (int, float)) else None
        tip = [float(v) for v in kin.tip(q, geom)]
        tip_sd = [float(v) for v in kin.tip_sd(q, sd, geom)]
        truth = None
        dev = self.owned.dev
        if isinstance(dev, KnowsTruePosition):
            tq = [float(dev.position(j)) for j in (1, 2, 3)]
            truth = {"q": tq, "tip": [float(v) for v in kin.tip(tq, geom)],
                     "display": [format_position(v, j) for j, v in zip((1, 2, 3), tq, strict=True)]}
        with self._lock:
            m = self._motion
            motion = m.as_dict(full=False) if m is not None else None
            if motion is not None:
                motion["path"] = m.path if m is not None and m.active else None
            jog_status = _jog_dict(self._jog_status) if self._pad is not None and self._jog_status else None
            day = {k: v for k, v in self._day.items() if k != "done_rows"} if self._day is not None else None
            level = dict(self._level) if self._level is not None else None
        return {
            "device": self.key, "model": self.info.model, "joints": rows, "tip": tip, "tip_sd": tip_sd, "truth": truth,
            "theta": state.theta, "psi": state.psi,
            "moving": bool(m is not None and m.active and m.status == "running"),
            "motion": motion, "jog": jog_status, "day": day, "audio": level,
            "calibration": self.calibration_summary(),
        }

    def calibration_summary(self) -> dict[str, Any] | None:
        """The calibration in use: day, method, joints, where it came from (None without one)."""
        cal = self.calibration
        if cal is None:
            return None
        return {"day": cal.day, "method": cal.method, "joints": sorted(cal.joints), "source": self.calibration_source}

    def calibration_detail(self) -> dict[str, Any]:
        """The calibration in use: summary, parameters with standard errors (SI), its report."""
        cal = self.calibration
        if cal is None:
            return {"calibration": None}
        params = [{**p.to_dict(), "label": p.label} for p in cal.parameters()]
        return {"calibration": self.calibration_summary(), "parameters": params, "report": cal.report()}

    def history(self) -> dict[str, Any]:
        """The device's sessions (``stickslip history``) and its calibrations."""
        try:
            s = self.store.store()
            return {"device": self.key, "sessions": s.history(self.key), "calibrations": s.calibrations(self.key)}
        finally:
            self.store.close_thread()

    def anova(self) -> dict[str, Any]:
        """The ANOVA of the device's stored traverses (:func:`stickslip.analysis.anova`, as ``stickslip anova``)."""
        from ..analysis import anova

        try:
            traverses = self.store.store().traverses(device=self.key)
        finally:
            self.store.close_thread()
        if not traverses:
            return {"traverses": 0, "tests": [], "skipped": [],
                    "report": f"no traverses stored for {self.key} yet: run the calibration day"}
        try:
            with refusals():
                res = anova(traverses)
        except ImportError as e:
            raise Conflict(f"the ANOVA needs the stats extra (pip install 'stickslip[stats]'): {one_line(e)}") from None
        return {"traverses": len(traverses), "tests": res.rows(), "skipped": res.skipped, "report": res.report()}

    # ------------------------------------------------------------ motions

    def motion(self, ident: int) -> Motion:
        """The motion ``ident`` (:class:`NotFound` if unknown, or forgotten: the last 50 are kept)."""
        with self._lock:
            m = self._motions.get(ident)
        if m is None:
            raise NotFound(f"no motion {ident} (the last {_KEEP_MOTIONS} are kept)")
        return m

    def current(self) -> Motion | None:
        """The motion running now, if any."""
        with self._lock:
            m = self._motion
        return m if m is not None and m.active else None

    def launch(
        self, kind: str, what: str, body: Callable[[Motion, Callable[[], None]], dict[str, Any] | None],
        path: list[list[float]] | None = None,
    ) -> Motion:
        """Run ``body(motion, ready)`` in its own thread as the manipulator's one motion.

        Waits until the procedure calls ``ready()`` (its input checked, nothing sent yet) or
        ends; a refusal before ``ready`` is raised as :class:`Refused` (the slot is free
        again). :class:`Busy` if another motion runs.
        """
        with self._lock:
            cur = self._motion
            if cur is not None and cur.active:
                raise Busy(
                    f"{cur.what} is running (motion {cur.id}, {time.monotonic() - cur.t0:.0f} s); one motion at a "
                    "time: wait for it, or press STOP"
                )
            m = Motion(next(self._ids), kind, what, path)
            self._motion = m
            self._motions[m.id] = m
            while len(self._motions) > _KEEP_MOTIONS:
                self._motions.popitem(last=False)
        self.owned.resume()
        threading.Thread(target=self._run, args=(m, body), name=f"motion-{m.id}", daemon=True).start()
        m._started.wait(START_TIMEOUT_S)
        if m.status == "refused":
            raise m.refusal or Refused(m.error or "refused")
        return m

    def _run(self, m: Motion, body: Callable[[Motion, Callable[[], None]], dict[str, Any] | None]) -> None:
        def ready() -> None:
            if m.status == "starting":
                m.status = "running"
                self.event("info", f"{m.what}: started")
            m._started.set()

        try:
            result = body(m, ready)
            m.result = result
            failure = (result or {}).get("failure")
            if failure:
                m.error = str(failure)
                m.status = "stopped" if m.stop_requested is not None else "failed"
            else:
                m.status = "stopped" if m.stop_requested is not None and m.kind in ("jog", "day") else "done"
        except (Refused, MoveRefused, DeviceBusy, KeyError, ValueError, DeviceError, TraverseError, StoreError) as e:
            m.error = one_line(e)
            if m.status == "starting":
                m.status = "refused"
                m.refusal = refusal(e)
            else:
                m.status = "stopped" if m.stop_requested is not None else "failed"
        except Exception as e:  # noqa: BLE001 - never a traceback to a client: one line, the log has the rest
            m.error = f"internal error: {one_line(e)}"
            m.status = "failed" if m.status != "starting" else "refused"
            log.exception("motion %d (%s) failed", m.id, redact_url(m.what))
        finally:
            m.t_end = time.monotonic()
            if m.stop_requested is not None:
                last = getattr(self.owned.dev, "last_step_s", None)
                self.stops.append((m.stop_requested, last if isinstance(last, float) else None))
            self.store.close_thread()
            m._started.set()
            m.finished.set()
            if m.status == "refused":
                self.event("warning", f"{m.what}: refused: {m.error}")
            elif m.status in ("failed", "stopped"):
                self.event("error" if m.status == "failed" else "warning", f"{m.what}: {m.status}: {m.error}")
            else:
                self.event("info", f"{m.what}: done")

    def _warn(self, m: Motion) -> Callable[[str], None]:
        def warn(message: str) -> None:
            m.warnings.append(one_line(message))
            self.event("warning", f"{m.what}: {message}")

        return warn

    def _opener(self, url: str) -> Controller:
        return self.owned

    def _need_calibration(self, what: str, borrow: bool = False) -> tuple[Calibration, bool]:
        cal = self.calibration
        if cal is None:
            raise Conflict(
                f"no calibration for {self.key}: {what} plans its steps with one; run the calibration day "
                "(the page's Calibrate panel, or POST /api/day) or start the server with --calibration CAL.json"
            )
        if borrow:
            return borrow_joint1(cal)
        return cal, False

    def _burst(self, joint: int = 3) -> int:
        """Steps per burst: what the joint makes in ``max_burst_s`` of wall-clock time (1000 on the virtual clock)."""
        extra = self.info.extra
        if "sample_rate_hz" in extra and not extra.get("realtime"):
            return 1000  # the simulator on its virtual clock: a burst takes no time
        try:
            hz = float(self.owned.frequency(joint)) * float(extra.get("speed", 1.0))  # type: ignore[arg-type]
        except (DeviceError, ValueError, TypeError):
            return 200
        return max(1, min(65535, int(hz * self.options.max_burst_s)))

    # ------------------------------------------------------------ the verbs

    def stop(self) -> dict[str, Any]:
        """STOP: no further burst, the controller told to stop now, a jog or a day ended. Never refused."""
        t = time.monotonic()
        self.owned.halt()
        with self._lock:
            m = self._motion
            pad = self._pad
            running = m is not None and m.active
            if running and m is not None and m.stop_requested is None:
                m.stop_requested = t
            self._day_pose.set()  # a day waiting for a pose wakes up to find the STOP
        if pad is not None:
            pad.end()
        what = m.what if running and m is not None else None
        self.event("warning", f"STOP: {what} stopped" if what else "STOP (nothing was moving)")
        return {"stopped": what, "motion": m.id if running and m is not None else None}

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
            r = move(self.store, req, cal, warn=self._warn(m), ready=ready, opener=self._opener)
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
            q[joint - 1] = q0[joint - 1] + (target - q0[joint - 1]) * k / 32
            pts.append([float(v) for v in kin.tip(q, self.options.geometry)])
        return pts

    def step(self, joint: int, steps: int) -> Motion:
        """Raw steps, no calibration (:func:`~stickslip.procedures.move.step_joint`): the joint is then uncertain."""
        if steps == 0:
            raise Refused("steps: 0 steps moves nothing")

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
            r = reach(self.store, req, cal, borrowed, warn=self._warn(m), ready=ready, opener=self._opener)
            out = dict(r.as_dict())
            out["failure"] = r.failure()
            return out

        return self.launch("reach", what, body, [start, [float(v) for v in end]])

    def jog_hold(self, direction: str, speed: int | None = None) -> dict[str, Any]:
        """A jog key held (or its keep-alive); starts a session if none runs (:func:`~stickslip.procedures.jog.jog`).

        Jog is refused while another motion runs (:class:`Busy`: "jog is disabled while a
        plan runs").
        """
        with self._lock:
            pad = self._pad
        if pad is not None:
            pad.hold(direction, speed)
            return {"jog": "held", "direction": direction}
        cur = self.current()
        if cur is not None:
            raise Busy(f"jog is disabled while a plan runs: {cur.what} (motion {cur.id}); wait for it or press STOP")
        cal, borrowed = self._need_calibration("jogging", borrow=True)
        new_pad = PadKeys(idle_end_s=self.options.jog_idle_end_s)
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
                r = jog(self.store, req, cal, keys=lambda: new_pad, show=show, warn=self._warn(m), ready=ready,
                        opener=self._opener)
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
        """Let go of the jog key: the tip stops at once; the session ends soon after by itself, or now if ``end``."""
        with self._lock:
            pad = self._pad
            m = self._motion
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
            ready()
            r = traverse(self.store, TraverseRequest(self.url, joint, direction, st.pose, today_label(), tuning),
                         progress=lambda steps, t: self._progress(m, {"steps": steps, "device_s": t}),
                         on_warning=self._warn(m), opener=self._opener)
            return {"steps": r.steps, "gamma": r.gamma, "unit": kin.joint_spec(joint).unit,
                    "row": {"start": r.traverse.start, "end": r.traverse.end, "steps": r.traverse.steps}}

        return self.launch("traverse", f"traverse of joint {joint}{direction}", body)

    def _progress(self, m: Motion, p: dict[str, Any]) -> None:
        m.progress = p

    def _tuning(self, joint: int) -> Tuning:
        if joint not in self._tunings:
            if not is_simulator(self.url):
                raise Conflict(
                    f"no limit-switch tuning of joint {joint}: start the server with --tuning {joint}=FILE "
                    "(stickslip tune makes one)"
                )
            self._tunings.update(simulator_tunings(self.url, (joint,)))
        return self._tunings[joint]

    # ------------------------------------------------------------ the calibration day

    def day_start(self, day: str | None = None, resume: bool = False) -> Motion:
        """Start (or resume) the guided calibration day (:func:`~stickslip.procedures.day.calibration_day`)."""
        with self._lock:
            before = self._day
        done: list[tuple[Any, int]] = []
        label = day or today_label()
        if resume:
            if before is None or not before.get("done"):
                raise Conflict("no calibration day to resume: start one")
            done = list(before["done_rows"])
            label = str(before["day_label"])
        tunings = {j: self._tuning(j) for j in sorted({t.joint for t in DAY_PLAN})}
        request = DayRequest(self.url, label, tunings, burst=self._burst(2) * 5, start_at=len(done))
        simulator = is_simulator(self.url)

        def set_pose(index: int, t: DayTraverse) -> None:
            if simulator:
                return  # the traverse places the simulated arm
            with self._lock:
                if self._day is not None:
                    self._day["waiting_for_pose"] = True
                self._day_pose.clear()
            self.event("info", f"calibration day: set the pose for traverse {index + 1}: {t.describe()}")
            while not self._day_pose.wait(0.5):
                pass
            with self._lock:
                if self._day is not None:
                    self._day["waiting_for_pose"] = False
            if self.owned.halted:
                raise Refused("stopped (STOP) while waiting for the pose")

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            ready()
            def progress(p: DayProgress) -> None:
                d = p.as_dict()
                with self._lock:
                    if self._day is not None:
                        self._day["progress"] = d
                        if p.stage == "measured" and p.row is not None and p.traverse_id is not None:
                            self._day["done"] = p.index + 1
                            self._day["done_rows"].append((p.row, p.traverse_id))
                if p.stage == "measured" and p.gamma is not None:
                    joint = p.traverse.joint
                    self.event("info", f"traverse {p.index + 1} of {p.total} measured: joint {joint}"
                               f"{p.traverse.direction}, {p.steps} steps commanded, average step "
                               f"{format_step(p.gamma, joint)}")
                    self._level = {"level_db": p.level_db, "band_hz": d["band_hz"]} if p.level_db is not None else None
                m.progress = d

            try:
                r = calibration_day(self.store, request, set_pose=set_pose, progress=progress, done=done,
                                    opener=self._opener)
            finally:
                with self._lock:
                    self._level = None
            self.calibration = r.calibration
            self.calibration_source = f"the calibration day {label} (id {r.calibration_id})"
            out = r.as_dict()
            with self._lock:
                if self._day is not None:
                    self._day["result"] = out
            return out

        with self._lock:
            self._day = {"day_label": label, "total": len(DAY_PLAN), "done": len(done), "waiting_for_pose": False,
                         "progress": None, "plan": [t.as_dict() for t in DAY_PLAN], "simulator": simulator,
                         "done_rows": list(done), "result": None}
        return self.launch("day", f"calibration day {label}", body)

    def day_pose_set(self) -> dict[str, Any]:
        """The operator has set the pose the day waits for (a real arm)."""
        with self._lock:
            waiting = self._day is not None and self._day.get("waiting_for_pose")
        if not waiting:
            raise Conflict("the calibration day is not waiting for a pose")
        self._day_pose.set()
        return {"day": "pose set"}

    def day(self) -> dict[str, Any]:
        """The day's plan, progress and result (``{"day": None}`` before one started)."""
        with self._lock:
            d = dict(self._day) if self._day is not None else None
        if d is not None:
            d.pop("done_rows", None)
        return {"day": d}

    # ------------------------------------------------------------ named positions

    def positions(self) -> list[dict[str, object]]:
        """The named positions of the device."""
        try:
            with refusals():
                return [p.as_dict() for p in named.positions(self.store, self.url)]
        finally:
            self.store.close_thread()

    def save_position(self, name: str) -> dict[str, object]:
        """Keep the current positions under ``name`` (refused while a motion runs)."""
        cur = self.current()
        if cur is not None:
            raise Busy(f"{cur.what} is running: a position is saved only while nothing moves")
        try:
            with refusals():
                p = named.save_position(self.store, self.url, name)
        finally:
            self.store.close_thread()
        self.event("info", f"position {name!r} saved")
        return p.as_dict()

    def delete_position(self, name: str) -> dict[str, object]:
        """Forget the named position ``name`` (:class:`NotFound` if there is none)."""
        try:
            named.delete_position(self.store, self.url, name)
        except KeyError as e:
            raise NotFound(one_line(e)) from None
        finally:
            self.store.close_thread()
        return {"deleted": name}

    def go_to(self, name: str) -> Motion:
        """Drive back to the named position ``name`` (:func:`~stickslip.procedures.named.go_to`), as a motion."""
        cal, _ = self._need_calibration("going to a position", borrow=True)
        known = {str(p["name"]): p for p in self.positions()}
        if name not in known:
            raise NotFound(f"{self.key} has no position named {name!r}")
        q_to = known[name]["q"]
        st = self.state()
        path = None
        if isinstance(q_to, list):
            q0 = [st.positions[j] for j in (1, 2, 3)]
            path = [[float(v) for v in kin.tip([a + (b - a) * k / 16 for a, b in zip(q0, q_to, strict=True)],
                                                self.options.geometry)] for k in range(17)]

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            r = named.go_to(self.store, self.url, name, cal, burst=self._burst(), warn=self._warn(m), ready=ready,
                            opener=self._opener)
            out = r.as_dict()
            out["failure"] = r.failure()
            return out

        return self.launch("goto", f"go to {name!r}", body, path)


class _OneValue:
    """A state store holding one device's kept positions (to read what a procedure just saved)."""

    def __init__(self, value: dict[str, Any]):
        self.value = value

    def get_state(self, device: str, key: str, default: Any = None) -> Any:
        return self.value if key == "positions" else default

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        raise AssertionError("read only")


def _jog_dict(s: JogStatus) -> dict[str, Any]:
    return {
        "q": list(s.q), "tip": list(s.tip), "speed": s.speed, "velocity": list(s.velocity), "rates": list(s.rates),
        "sent": list(s.sent), "message": s.message,
    }
