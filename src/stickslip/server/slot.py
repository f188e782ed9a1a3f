"""The manipulator's one motion slot: the room's refusals, its motions, its events.

A motion (a move, a reach, a jog session, a traverse, the calibration day) runs in its
own thread and takes the slot; a second is refused with what is running (:class:`Busy`),
never queued. :class:`MotionSlot` is the base of the control room's parts
(:class:`~.room.ControlRoom`): it holds what they share (the store, the controller, the
lock, the kept state, the calibration) and launches a motion, records events, and
sizes a burst.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import kinematics as kin
from ..audio.detector import Tuning
from ..calibration import Calibration
from ..clock import now_utc
from ..devices.base import Controller, DeviceError, DeviceInfo, redact_text
from ..devices.identity import ControllerChanged
from ..devices.positions import DeviceState
from ..motion.reach import borrow_joint1
from ..procedures.arms import guard_for
from ..procedures.day import simulator_tunings
from ..procedures.jog import JogStatus
from ..procedures.move import DeviceBusy, MoveRefused, TargetOutOfRange, check_envelope_path, is_simulator
from ..procedures.rigstop import RigStopWatch
from ..procedures.traverse import TraverseError
from ..rig import Rig
from ..rig.guard import Guard
from ..storage import StoreError
from .owned import HeldStore, OwnedController
from .pad import HOLD_S, IDLE_END_S, PadKeys

__all__ = [
    "MAX_BURST_S", "MAX_LINE", "START_TIMEOUT_S", "Busy", "Conflict", "Motion", "MotionSlot", "NotFound", "Presses",
    "Refused", "RoomOptions", "Unavailable", "one_line", "refusal", "refusals",
]

log = logging.getLogger("stickslip.server")

MAX_BURST_S = 0.2
"""Longest burst, s: a controller that does not cut a burst short on STOP finishes it within this,
and the positions on the page move on after every burst."""

START_TIMEOUT_S = 30.0
"""How long a request waits for its motion's procedure to check its input, s."""

KEEP_MOTIONS = 50
"""Motions kept to be asked about (the oldest is forgotten first)."""

KEEP_EVENTS = 500
"""Events kept for the live view."""

MAX_LINE = 600
"""Longest error line, characters (the longest the server makes, the envelope's, is about 300): a longer one
quotes back a client's value and is cut."""


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
    text = redact_text(" ".join(text.split()) or type(e).__name__)
    if len(text) > MAX_LINE:  # a value quoted back whole: 60 kB of a client's junk in an error line
        keep = (MAX_LINE - 40) // 2  # the start and the end (the reason often follows the value)
        text = f"{text[:keep]} ...[{len(text) - 2 * keep} characters cut]... {text[-keep:]}"
    return text


class Presses:
    """The STOP presses seen, by the id a page gives each (the last 16): a page sends a press both on its socket
    and as ``POST /api/stop``, and the room says it once. A STOP without an id is always said."""

    def __init__(self) -> None:
        self._seen: collections.deque[str] = collections.deque(maxlen=16)
        self._lock = threading.Lock()

    def first(self, press: str | None) -> bool:
        """Whether ``press`` is a press not seen before (then it is remembered); ``None`` is always new."""
        if press is None:
            return True
        press = press[:64]  # an id, not a payload: a STOP is never refused for it
        with self._lock:
            if press in self._seen:
                return False
            self._seen.append(press)
            return True


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
    if isinstance(e, (MoveRefused, DeviceBusy, KeyError, ControllerChanged)):  # another controller: the state's
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
    jog_hold_s : float
        The dead man's switch: a held direction with no keep-alive for this long is let go, s
        (:data:`~.pad.HOLD_S`).
    rig : Rig or None
        A rig file (docs/rig.md): the room drives its arm ``arm`` (``device`` is that
        arm's controller), and every motion is checked against the rig's envelope
        before one step is sent; the rig file's named positions join the saved ones.
    arm : str or None
        The rig's arm to drive (``None``: its first).
    """

    device: str = "sim://?realtime=1"
    db: Path | str | None = None
    calibration: Path | None = None
    tunings: Mapping[int, Tuning] = field(default_factory=dict)
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY
    max_age_days: int = 0
    max_burst_s: float = MAX_BURST_S
    jog_max_rate: float = 300.0
    jog_idle_end_s: float = IDLE_END_S
    jog_hold_s: float = HOLD_S
    rig: Rig | None = None
    arm: str | None = None


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


class MotionSlot:
    """What the room's parts share, and the one motion slot: launch a motion, find it, record events.

    The attributes are set by :class:`~.room.ControlRoom` when it opens the manipulator.
    """

    options: RoomOptions
    url: str
    key: str
    store: HeldStore
    owned: OwnedController
    info: DeviceInfo
    calibration: Calibration | None
    calibration_source: str
    stops: list[tuple[float, float | None]]
    """``(when STOP was received, when the last step was sent after it)``, monotonic s (for benchmarks)."""
    _lock: threading.RLock
    _ids: Iterator[int]
    _events: collections.deque[dict[str, Any]]
    _event_ids: Iterator[int]
    _motions: collections.OrderedDict[int, Motion]
    _motion: Motion | None
    _pad: PadKeys | None
    _jog_status: JogStatus | None
    _day: dict[str, Any] | None
    _day_pose: threading.Event
    _level: dict[str, Any] | None
    _tunings: dict[int, Tuning]
    _state: DeviceState
    _rig_watch: RigStopWatch | None
    """The rig's STOP as the store keeps it (``None``: no rig), read before each burst."""

    # ------------------------------------------------------------ events and state

    def event(self, level: str, text: str) -> dict[str, Any]:
        """Record an event (``info``, ``warning``, ``error``) for the live view and the log."""
        e = {"id": next(self._event_ids), "at": now_utc().isoformat(timespec="seconds"), "level": level,
             "text": redact_text(text)}
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

    def state(self) -> DeviceState:
        """The kept state as last saved (from memory)."""
        with self._lock:
            return self._state

    # ------------------------------------------------------------ motions

    def motion(self, ident: int) -> Motion:
        """The motion ``ident`` (:class:`NotFound` if unknown, or forgotten: the last 50 are kept)."""
        with self._lock:
            m = self._motions.get(ident)
        if m is None:
            raise NotFound(f"no motion {ident} (the last {KEEP_MOTIONS} are kept)")
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
        if self._rig_watch is not None:  # the rig's STOPs pressed before this motion do not stop it
            with refusals():
                self._rig_watch.begin(self.store)
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
            while len(self._motions) > KEEP_MOTIONS:
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
            log.exception("motion %d (%s) failed", m.id, redact_text(m.what))
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

    def _guard(self) -> Guard | None:
        """The rig's envelope for the room's arm, the other arms where the store keeps them now; ``None``: no rig.

        Built in the thread that checks (a motion's own): the other arms' kept poses are
        read when the check is made, not when the server started.
        """
        rig = self.options.rig
        if rig is None:
            return None
        return guard_for(self.store, rig, self.options.arm)

    def check_sweep(self, joint: int, direction: str, q: list[float], st: DeviceState, what: str = "the traverse",
                    ) -> None:
        """Refuse a traverse of ``joint`` (``direction`` ``+``: from its lower stop to its upper) from the pose
        ``q`` (rad, rad, m) that leaves the rig's envelope: :class:`Conflict` naming the obstacle; no rig, no check.

        The path checked runs from ``q`` to the stop the traverse starts from, then to the
        other stop, with the σ kept in ``st``.
        """
        guard = self._guard()
        if guard is None:
            return
        spec = kin.joint_spec(joint)
        ends = (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)
        path = [list(q), list(q), list(q)]
        path[1][joint - 1], path[2][joint - 1] = ends
        try:
            check_envelope_path(guard, st, path, self.calibration)
        except MoveRefused as e:
            raise Conflict(f"{what} (joint {joint}{direction}, from stop to stop): {one_line(e)}") from None

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

    def _tuning(self, joint: int) -> Tuning:
        if joint not in self._tunings:
            if not is_simulator(self.url):
                raise Conflict(
                    f"no limit-switch tuning of joint {joint}: start the server with --tuning {joint}=FILE "
                    "(stickslip tune makes one)"
                )
            self._tunings.update(simulator_tunings(self.url, (joint,)))
        return self._tunings[joint]

