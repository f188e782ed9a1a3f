"""The calibration day as a guided run: the paper's 14 traverses, one after the other, then the calibration.

:func:`calibration_day` is the workflow behind the page's guided calibration (and any
front end that walks an operator through the day): for each traverse of
:data:`DAY_PLAN` (the paper's poses, :data:`~stickslip.procedures.demo.CALIBRATION_PLAN`,
each in ``+`` then ``-``) it asks the operator to set the pose (``set_pose``: on a real
arm a person tilts the base and places the other joints; the simulator is placed by the
traverse itself), measures the traverse with :func:`stickslip.procedures.session.traverse`
(the device lock, the write-ahead journal, the row stored, the joint re-referenced at the
stop it reached), reports progress and the level of the band the limit switch listens to
(the end-stop meter), and at the end calibrates from the day's rows (the paper's Eqs. 4-6
and the exact rotary inversion, :func:`stickslip.calibration.calibrate`) and stores the
calibration with the traverses it used.

A day that stops part-way (a STOP, a device error, a stop not heard) keeps every traverse
measured before it; ``start_at`` and ``done`` resume it from the next one.

:func:`simulator_tunings` tunes the limit switch of a simulated arm from its own
labelled recordings (as ``stickslip demo`` does), on a copy of the arm on the virtual
clock so that the arm being calibrated does not move.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol
from urllib.parse import urlsplit

from .. import kinematics as kin
from ..audio.confirm import CONFIRM_S
from ..audio.detector import Tuning
from ..audio.meter import BandMeter
from ..calibration import Calibration, calibrate
from ..clock import check_day_label
from ..devices.base import Controller, PoseSettable, device_key, open_device, redact_url
from ..measurements import Traverse
from ..sim.urls import virtual_clock_url
from ..units import format_position
from .conditions import conditions_of
from .demo import CALIBRATION_PLAN
from .move import LockStore
from .session import TraverseRequest, TraverseStore, traverse
from .traverse import TraverseResult

__all__ = [
    "DAY_PLAN",
    "DayProgress",
    "DayRequest",
    "DayResult",
    "DayStore",
    "DayTraverse",
    "calibration_day",
    "simulator_tunings",
]


@dataclass(frozen=True)
class DayTraverse:
    """One traverse of the day: ``joint`` in ``direction`` with the other joints and the tilt at ``fixed``.

    Attributes
    ----------
    joint : int
    direction : str
        ``"+"`` (lower stop to upper) or ``"-"``.
    fixed : tuple of (str, float)
        The other joints and the tilt: ``("q2", rad)``, ``("q3", m)``, ``("theta", rad)``, ...
    """

    joint: int
    direction: str
    fixed: tuple[tuple[str, float], ...]

    @property
    def pose(self) -> kin.Pose:
        """The pose of the row (the moving joint at the stop it starts from; rad, m)."""
        spec = kin.joint_spec(self.joint)
        start = spec.lower if self.direction == "+" else spec.upper
        values = {**dict(self.fixed), f"q{self.joint}": start}
        return kin.Pose(**values)

    def describe(self) -> str:
        """One line for the operator: which joint, which way, and the pose to set (display units)."""
        parts = []
        for name, value in self.fixed:
            if name.startswith("q"):
                parts.append(f"{name} = {format_position(value, int(name[1]))}")
            else:
                parts.append(f"{name} = {math.degrees(value):.0f} deg")
        way = "lower stop to upper" if self.direction == "+" else "upper stop to lower"
        return f"joint {self.joint} {self.direction} ({way}) with " + ", ".join(parts)

    def as_dict(self) -> dict[str, object]:
        """JSON shape (SI): joint, direction, the fixed pose and the description."""
        return {
            "joint": self.joint, "direction": self.direction, "fixed": dict(self.fixed), "describe": self.describe(),
        }


_ORDER = ("q1", "q2", "q3", "theta", "psi")

DAY_PLAN: tuple[DayTraverse, ...] = tuple(
    DayTraverse(joint, direction, tuple(sorted(pose.items(), key=lambda kv: _ORDER.index(kv[0]))))
    for joint, pose in CALIBRATION_PLAN
    for direction in "+-"
)
"""The day's 14 traverses in the order measured: the paper's calibration poses, each ``+`` then ``-``."""


class DayStore(TraverseStore, LockStore, Protocol):
    """What :func:`calibration_day` needs of a store: traverses, the kept state, the lock, calibrations."""

    def add_calibration(self, cal: Calibration, device: str = ..., traverse_ids: Sequence[int] = ...) -> int: ...


@dataclass(frozen=True)
class DayRequest:
    """A calibration day on one device.

    Attributes
    ----------
    device : str
        Controller URL.
    day : str
        Session label (ISO date preferred).
    tunings : mapping of int to Tuning
        The limit switch of each joint the day traverses (2 and 3).
    burst : int
        Steps per burst between checks of the limit switch.
    confirm_s : float
        How long a stop must persist before it is taken, s.
    audio_input : str or int or None
        Sound-card input for a controller without a microphone of its own.
    start_at : int
        Index into the plan to begin at (resuming a day; 0 from the start).
    plan : tuple of DayTraverse
        The traverses, in the order measured (default :data:`DAY_PLAN`, the paper's).
    """

    device: str
    day: str
    tunings: Mapping[int, Tuning]
    burst: int = 2000
    confirm_s: float = CONFIRM_S
    audio_input: str | int | None = None
    start_at: int = 0
    plan: tuple[DayTraverse, ...] = DAY_PLAN


@dataclass(frozen=True)
class DayProgress:
    """Where a day is, for a progress display.

    Attributes
    ----------
    index : int
        The traverse under way (0-based index into :data:`DAY_PLAN`).
    total : int
        Traverses in the day (14).
    stage : str
        ``"pose"`` (waiting for the pose to be set), ``"traversing"``, ``"measured"``
        (this traverse is done), ``"calibrating"``.
    traverse : DayTraverse
    steps : int
        Steps commanded in the measured direction so far.
    device_s : float
        Device time the traverse has taken, s.
    level_db : float or None
        Level of the band the limit switch listens to, dBFS (the end-stop meter); ``None``
        where the audio is not available to the procedure (a sound card).
    band_hz : tuple of 2 floats or None
        That band, Hz.
    gamma : float or None
        The measured traverse's average step, m or rad (stage ``"measured"``).
    row : Traverse or None
        The measured row (stage ``"measured"``), and ``traverse_id`` its id in the store:
        what a resumed day passes back as ``done``.
    traverse_id : int or None
    """

    index: int
    total: int
    stage: str
    traverse: DayTraverse
    steps: int = 0
    device_s: float = 0.0
    level_db: float | None = None
    band_hz: tuple[float, float] | None = None
    gamma: float | None = None
    row: Traverse | None = None
    traverse_id: int | None = None

    def as_dict(self) -> dict[str, object]:
        """JSON shape (SI)."""
        return {
            "index": self.index, "total": self.total, "stage": self.stage, "traverse": self.traverse.as_dict(),
            "steps": self.steps, "device_s": self.device_s, "level_db": self.level_db,
            "band_hz": list(self.band_hz) if self.band_hz else None, "gamma": self.gamma,
        }


@dataclass(frozen=True)
class DayResult:
    """A finished day: its traverses, the calibration made from them and its id in the store."""

    results: tuple[TraverseResult, ...]
    rows: tuple[Traverse, ...]
    calibration: Calibration
    calibration_id: int
    traverse_ids: tuple[int, ...] = field(default=())

    def as_dict(self) -> dict[str, object]:
        """JSON shape (SI): the calibration's parameters (with standard errors) and the rows."""
        params = [{**p.to_dict(), "label": p.label} for p in self.calibration.parameters()]
        rows = [
            {"joint": r.joint, "direction": r.direction, "steps": r.steps, "start": r.start, "end": r.end}
            for r in self.rows
        ]
        return {
            "calibration_id": self.calibration_id, "day": self.calibration.day, "method": self.calibration.method,
            "parameters": params, "traverses": rows, "report": self.calibration.report(),
        }


class _Ids:
    """A store that remembers the ids of the traverses added through it (for the calibration's provenance)."""

    def __init__(self, store: DayStore):
        self.store = store
        self.ids: list[int] = []

    def add_traverse(self, t: Traverse, device: str = "sim://", how: str = "audio") -> int:
        tid = self.store.add_traverse(t, device=device, how=how)
        self.ids.append(tid)
        return tid

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        self.store.set_state(device, key, value_json)

    def get_state(self, device: str, key: str, default: Any = None) -> Any:
        return self.store.get_state(device, key, default)

    def acquire_lock(self, device: str, holder: dict[str, Any]) -> dict[str, Any] | None:
        return self.store.acquire_lock(device, holder)

    def release_lock(self, device: str, pid: int) -> None:
        self.store.release_lock(device, pid)


class _Tapped:
    """A microphone whose blocks also go to ``tap`` (the meter); everything else is the microphone's own.

    The traverse reads a virtual microphone's clock (``t_s``, ``skip_to``) to keep the
    audio in step with the device; those pass through untouched.
    """

    def __init__(self, mic: Any, tap: Callable[[Any], None]):
        self._mic = mic
        self._tap = tap

    def __getattr__(self, name: str) -> Any:
        return getattr(self._mic, name)

    def __call__(self) -> list[Any]:
        blocks: list[Any] = list(self._mic())
        for b in blocks:
            self._tap(b)
        return blocks

    def __iter__(self) -> Iterator[Any]:
        for b in self._mic:
            self._tap(b)
            yield b


class _Metered:
    """The controller with its virtual microphone tapped by a :class:`BandMeter` (the end-stop meter).

    Everything else is the controller's own: the capabilities it has (a pose to set, a
    clock, a microphone) are the ones it answers to.
    """

    def __init__(self, dev: Controller, meter: BandMeter, on_level: Callable[[float], None]):
        self._dev = dev
        self._meter = meter
        self._on_level = on_level

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._dev, name)
        if name != "microphone":
            return attr

        def tap(block: Any) -> None:
            self._on_level(self._meter.feed(block).level_db)

        def microphone(*args: Any, **kwargs: Any) -> _Tapped:
            return _Tapped(attr(*args, **kwargs), tap)

        return microphone


def _check_request(request: DayRequest, done: Sequence[tuple[Traverse, int]]) -> None:
    """``ValueError`` for a day that cannot run: a joint without a tuning, ``start_at`` or ``done`` not fitting."""
    plan = request.plan
    missing = sorted({t.joint for t in plan[request.start_at:]} - set(request.tunings))
    if missing:
        raise ValueError(f"the calibration day needs a limit-switch tuning of joint(s) {missing} (stickslip tune)")
    if not 0 <= request.start_at < len(plan):
        raise ValueError(f"start_at = {request.start_at} is outside 0..{len(plan) - 1}")
    if len(done) != request.start_at:
        raise ValueError(f"resuming at traverse {request.start_at + 1} needs the {request.start_at} rows before it")


def calibration_day(
    store: DayStore,
    request: DayRequest,
    *,
    set_pose: Callable[[int, DayTraverse], None] = lambda _i, _t: None,
    progress: Callable[[DayProgress], None] = lambda _p: None,
    done: Sequence[tuple[Traverse, int]] = (),
    opener: Callable[[str], Controller] | None = None,
) -> DayResult:
    """Measure the day's traverses from ``request.start_at`` on, then calibrate and store the calibration.

    ``set_pose(index, traverse)`` is called before each traverse (a front end waits there
    for the operator to set the pose on a real arm; it returns at once for a simulator,
    which the traverse places). ``progress`` gets a :class:`DayProgress` after every burst
    and at each stage. ``done`` holds ``(row, id)`` of the traverses measured before
    ``start_at`` (a resumed day). Raises what :func:`~.session.traverse` raises (a device
    error, a stop not heard: :class:`~.traverse.TraverseError`), ``ValueError`` for a bad
    request (a joint without a tuning, ``start_at`` out of range), before anything moves.
    """
    day = check_day_label(request.day)
    plan = request.plan
    _check_request(request, done)
    open_dev = opener or open_device
    rows = [r for r, _ in done]
    ids = _Ids(store)
    ids.ids.extend(i for _, i in done)
    results: list[TraverseResult] = []
    total = len(plan)
    for index in range(request.start_at, total):
        t = plan[index]
        progress(DayProgress(index, total, "pose", t))
        set_pose(index, t)
        tuning = request.tunings[t.joint]
        meter = BandMeter(int(tuning.sample_rate), band_hz=tuning.band_hz)
        level: list[float | None] = [None]

        def on_level(db: float, level: list[float | None] = level) -> None:
            level[0] = db

        def metered(url: str, meter: BandMeter = meter, on_level: Callable[[float], None] = on_level) -> Any:
            return _Metered(open_dev(url), meter, on_level)

        def burst_done(
            steps: int, device_s: float, t: DayTraverse = t, index: int = index,
            level: list[float | None] = level, band: tuple[float, float] = tuning.band_hz,
        ) -> None:
            progress(DayProgress(index, total, "traversing", t, steps, device_s, level[0], band))

        progress(DayProgress(index, total, "traversing", t, band_hz=tuning.band_hz))
        result = traverse(
            ids,
            TraverseRequest(
                request.device, t.joint, t.direction, t.pose, day, tuning, audio_input=request.audio_input,
                burst=request.burst, confirm_s=request.confirm_s,
            ),
            progress=burst_done,
            opener=metered,
        )
        results.append(result)
        rows.append(result.traverse)
        progress(DayProgress(
            index, total, "measured", t, result.commanded_steps, result.elapsed_device_s, level[0], tuning.band_hz,
            gamma=result.gamma, row=result.traverse, traverse_id=ids.ids[-1],
        ))
    progress(DayProgress(total - 1, total, "calibrating", plan[-1]))
    key = device_key(request.device)
    cal = calibrate(rows, day=day, source=key)
    dev = open_dev(request.device)
    try:
        cal = dataclasses.replace(cal, conditions=conditions_of(dev, request.device, joints=(2, 3)))
    finally:
        dev.close()
    cal_id = store.add_calibration(cal, key, ids.ids)
    return DayResult(tuple(results), tuple(rows), cal, cal_id, tuple(ids.ids))


def simulator_tunings(url: str, joints: Sequence[int] = (2, 3)) -> dict[int, Tuning]:
    """The limit switch of each joint of the simulated arm ``url`` names, tuned from its own labelled recordings.

    The recordings are made on a copy of the arm on the virtual clock (the same seed and
    day, so the same sounds), so the arm ``url`` drives does not move and no time passes
    on it. ``ValueError`` if ``url`` is not a simulator's.
    """
    from ..audio.tuning import tune

    parts = urlsplit(url)
    if parts.scheme not in ("sim", "sim+physics"):
        raise ValueError(f"{redact_url(url)} is not a simulator: give the tunings of a real arm (stickslip tune)")
    sim = open_device(virtual_clock_url(url))
    if not isinstance(sim, PoseSettable) or not hasattr(sim, "labelled_recording"):
        raise ValueError(f"{redact_url(url)} opens no simulated arm that can record itself")
    out: dict[int, Tuning] = {}
    try:
        for joint in joints:
            samples, rate, stop_at = sim.labelled_recording(joint, "+", before_s=2.0, after_s=1.0)
            out[joint] = tune(samples, rate, stop_at, joint=joint, step_rate_hz=sim.frequency(joint))
    finally:
        sim.close()
    return out
