"""Measure a joint's average step: count the steps between its two end stops, by ear.

The traverse procedure (docs/design.md §5), for any :class:`~stickslip.devices.base.Controller`:

1. *Drive to the start stop*: step the joint the other way until the limit switch
   hears that stop (``predrive="listen"``), or overdrive it by more steps than the
   whole range can take (``predrive="overdrive"``; no listening needed).
2. *Measure*: step in bursts in the measured direction while the
   limit switch (any :class:`~stickslip.audio.events.StopDetector`) listens to the audio recorded
   during each burst; stop at the first event.
3. *Count*: every burst is logged as ``(stream time it began, steps, frequency)``.
   The steps that moved the joint are those issued before the stop's onset; the
   rest were commanded after the stop (``steps = commanded - steps after the
   event``). Without correction the count would run to the *detection* time and
   include ``f_step x latency`` extra steps (20 steps at 1 kHz and 20 ms: 0.17 %
   of a 12 000-step traverse); with ``latency="onset"`` (default) the event's onset
   estimate is used, with ``latency="fixed"`` ``detected_at - detector.latency_s``.

A fire of the detector is only *provisional* (``confirm_s``, default
:data:`~stickslip.audio.confirm.CONFIRM_S`): the joint keeps stepping, and the stop is
taken once it persisted (:mod:`stickslip.audio.confirm`; a real stop lasts as long as the
controller steps into it, interference does not). The count still runs to the event's
onset, so this costs no accuracy, only ``confirm_s`` x the step rate extra steps against
the stop. A fire that does not persist is dropped and the traverse goes on (its steps
are counted: the joint moved).

Audio arrives through ``audio_blocks``: either a callable returning the blocks
recorded since its previous call (the simulator's
:class:`~stickslip.sim.arm.VirtualMicrophone`), or an iterator yielding
blocks as they are recorded (a live microphone). Stream time and the controller's
clock must agree: by default the clock is ``controller.clock_s`` if the controller
has one (the simulator), else the wall clock since the start of the traverse.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..audio.confirm import CONFIRM_S, ConfirmedStopDetector, confirming
from ..audio.confirm.clocked import CLOCKED
from ..audio.events import StopDetector, StopEvent
from ..audio.sources.guard import NoSignalError, SignalGuard
from ..clock import check_day_label
from ..devices.base import Controller, VirtualClock
from ..measurements import Traverse
from ..models import direction_label, direction_sign
from ..units import step_scale

__all__ = [
    "TraverseError", "TraverseResult", "check_burst_steps", "measure_traverse", "MIN_STEP_PRIOR", "MAX_STEP_PRIOR",
    "LATENCY_MODES",
]

LATENCY_MODES = ("onset", "fixed", "none")

MIN_STEP_PRIOR = {1: 15e-6, 2: 15e-6, 3: 300e-9}
"""A lower bound on a joint's step size (rad, rad, m), used to size overdrives and the
give-up limit: no MM3A-type joint steps less than this in any pose."""

MAX_STEP_PRIOR = {1: 1e-3, 2: 1e-3, 3: 10e-6}
"""An upper bound on a joint's step size (rad, rad, m): ten times the largest the paper and the stick-slip
makers report (about 1 µm and tens of µrad a step). A stop heard after fewer than the range over this many
steps cannot be the end stop: the joint could not have crossed its range (4 s of stepping at 1000 Hz on a
rotary joint of the MM3A, 1.2 s on its prismatic one)."""


class TraverseError(RuntimeError):
    """A traverse could not be completed (no stop heard, device refused, ...)."""


@dataclass(frozen=True)
class TraverseResult:
    """One measured traverse.

    Attributes
    ----------
    traverse : Traverse
        The measurement-table row (start, end = the joint's stops, ``steps`` counted).
    steps : int
        Steps that moved the joint.
    commanded_steps : int
        Steps commanded in the measured direction in total.
    steps_after_stop : int
        ``commanded_steps - steps``: steps issued after the estimated stop.
    latency_steps_corrected : int
        Steps removed by the latency correction (between the estimated onset and the
        detection), ``0`` with ``latency="none"``.
    detected_at_s, onset_s : float
        The stop event's detection and onset times, s (stream time).
    elapsed_device_s : float
        Time the measured stepping took on the device clock, s.
    frequency_hz : float
        Stepping frequency, Hz.
    predrive_steps : int
        Steps commanded to reach the start stop.
    listen_after_steps : int
        Steps commanded before the limit switch listened.
    retried : bool
        The stop came before listening began, so the traverse was measured again
        listening from the start (this result is the second measurement).
    bursts : tuple of (float, int)
        Stream time (s) each burst began and its steps, in the measured direction.
    confirmed_at_s : float or None
        Stream time the stop was confirmed by its persistence, s (None: not confirmed,
        ``confirm_s=0`` or a detector that does not listen to samples).
    unconfirmed : tuple of float
        Onsets (s, stream time) of the detector's fires in the measured direction that
        did not persist (interference) and were passed by.
    """

    traverse: Traverse
    steps: int
    commanded_steps: int
    steps_after_stop: int
    latency_steps_corrected: int
    detected_at_s: float
    onset_s: float
    elapsed_device_s: float
    frequency_hz: float
    predrive_steps: int = 0
    listen_after_steps: int = 0
    retried: bool = False
    bursts: tuple[tuple[float, int], ...] = field(default=(), repr=False)
    confirmed_at_s: float | None = None
    unconfirmed: tuple[float, ...] = ()

    @property
    def gamma(self) -> float:
        """Average step ``|end - start| / steps`` (m or rad)."""
        return self.traverse.gamma

    def report(self) -> str:
        """One line a person can read (units labelled)."""
        t = self.traverse
        scale, unit = step_scale(t.joint)
        return (
            f"joint {t.joint} {t.direction}: {self.steps} steps, "
            f"gamma = {self.gamma * scale:.2f} {unit} "
            f"({self.elapsed_device_s:.1f} s at {self.frequency_hz:g} Hz; "
            f"{self.steps_after_stop} steps after the stop, "
            f"{self.latency_steps_corrected} for latency"
            + (f"; {len(self.unconfirmed)} unconfirmed fire(s) passed by" if self.unconfirmed else "")
            + ")"
        )


def _count_before(t_s: float, bursts: list[tuple[float, int]], hz: float) -> int:
    """Steps issued before time ``t_s``: steps of a burst begun at ``b`` are at ``b + k / hz``."""
    total = 0
    for b, n in bursts:
        total += int(min(max(round((t_s - b) * hz), 0), n))
    return total


class _Listener:
    """Feeds audio to the detector up to a stream time; returns the first event.

    Keeps the stream time of the next sample (``t_s``): the source is taken to start
    at the controller clock when listening first starts, and to run continuously.
    """

    def __init__(self, detector: StopDetector, audio_blocks: Any, sample_rate: float, step_hz: float | None = None):
        self.detector = detector
        self.sample_rate = float(sample_rate)
        self._callable = callable(audio_blocks) and not isinstance(audio_blocks, Iterator)
        self.source = audio_blocks if self._callable else iter(audio_blocks)
        self.t_s = 0.0
        #: onsets (s) of the fires the detector dropped as unconfirmed, in the order heard
        self.unconfirmed: list[float] = []
        self._started = False
        self._last_block_s = 0.0
        #: the step rate the controller commands, Hz: told to the detector at every reset (it hears the step clock
        #: near it, and knows the stop at a rate farther from its tuning's)
        self.step_hz = step_hz
        # a dead input must never look like a stop; only a detector that declares it does not
        # listen to the samples (the simulator's oracle) is exempt
        listens = detector.uses_audio
        # ... and the joint's stepping must be heard at the commanded rate
        self.guard = SignalGuard(self.sample_rate, step_hz=step_hz) if listens else None

    def start(self, t0_s: float) -> None:
        """Begin listening at stream time ``t0_s``: drop older audio, reset the detector."""
        first = not self._started
        self._started = True
        if first:
            self.t_s = t0_s
        skip = getattr(self.source, "skip_to", None)
        if skip is not None:
            skip(t0_s)
            self.t_s = float(getattr(self.source, "t_s", t0_s))
        elif self._callable:
            for block in self.source():
                self.t_s += len(block) / self.sample_rate
        elif not first:
            for block in self._blocks(t0_s):
                if isinstance(block, tuple):
                    block = block[0]
                self.t_s += len(block) / self.sample_rate
        self.detector.reset(self.t_s, self.step_hz)
        if self.guard is not None:
            self.guard.restart_stepping_check()

    def _blocks(self, until_s: float) -> Iterator[NDArray[np.float32]]:
        if self._callable:
            yield from self.source()
            return
        # pull until less than one block of audio is missing (a block can only be
        # complete once the device clock has passed its end)
        while until_s - self.t_s >= max(self._last_block_s, 1e-9):
            try:
                block = next(self.source)
            except StopIteration:
                return
            if isinstance(block, tuple):  # (samples, sample_rate) pairs from file sources
                block = block[0]
            self._last_block_s = len(block) / self.sample_rate
            yield block

    def listen(self, until_s: float) -> StopEvent | None:
        """Feed the audio recorded up to ``until_s``; the first event, or ``None``."""
        for block in self._blocks(until_s):
            if isinstance(block, tuple):
                block = block[0]
            block = np.asarray(block, dtype=np.float32)
            if block.ndim > 1:
                block = block.mean(axis=1)
            confirming = self.detector if isinstance(self.detector, ConfirmedStopDetector) else None
            if self.guard is not None and confirming is not None and confirming.holding:
                # a stop found and held (a bounded wait, model_hold_s): its stepping line may sink there
                self.guard.restart_stepping_check()
            try:
                alive = self.guard is None or self.guard.check(block)
            except NoSignalError as e:
                raise TraverseError(str(e)) from None
            self.t_s += block.shape[0] / self.sample_rate
            dropped = confirming.log.rejected if confirming is not None else None
            before = len(dropped) if dropped is not None else 0
            events = self.detector.feed(block)
            if dropped is not None:
                self.unconfirmed += [float(e.onset_s) for e in dropped[before:]]
            if events and not alive:  # heard in a dead input: not a stop; start afresh, in step
                self.detector.reset(self.t_s, self.step_hz)
                continue
            if events:
                return events[0]
        return None


def _sample_rate(detector: StopDetector, audio_blocks: Any) -> float:
    for obj in (audio_blocks, getattr(detector, "tuning", None), detector):
        sr = getattr(obj, "sample_rate", None)
        if sr:
            return float(sr)
    return 48_000.0


def _progress_callback(
    progress: bool | Callable[[int, float], None], joint: int, direction: str, expected: int | None
) -> tuple[Callable[[int, float], None], Callable[[], None]]:
    """A callable ``(steps, device_s)`` and a closer, for ``progress`` True / callable / False."""
    if callable(progress):
        return progress, lambda: None
    if not progress:
        return (lambda steps, t: None), lambda: None
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    screen = Console(stderr=True)  # stdout carries the result alone (a bar there left a blank line in a pipe)
    bar = Progress(
        TextColumn(f"joint {joint} {direction}"),
        BarColumn(),
        TextColumn("{task.completed:>7.0f} steps"),
        TextColumn("{task.fields[device]:>6.1f} s on the device"),
        TimeElapsedColumn(),
        transient=True,
        console=screen,
        disable=not screen.is_terminal,
    )
    bar.start()
    task = bar.add_task("traverse", total=expected, device=0.0)

    def update(steps: int, t: float) -> None:
        bar.update(task, completed=steps, device=t)

    return update, bar.stop


def measure_traverse(
    controller: Controller,
    joint: int,
    direction: str | int,
    *,
    detector: StopDetector,
    audio_blocks: Callable[[], Iterable[np.ndarray]] | Iterable[np.ndarray],
    pose: kin.Pose,
    day: str,
    burst_steps: int = 2000,
    predrive: str = "listen",
    latency: str = "onset",
    max_steps: int | None = None,
    expected_steps: int | None = None,
    clock: Callable[[], float] | None = None,
    progress: bool | Callable[[int, float], None] = False,
    settle_s: float = 0.05,
    listen_after_steps: int = 0,
    confirm_s: float = CONFIRM_S,
) -> TraverseResult:
    """Measure a full-range traverse of ``joint``: count the steps between its end stops.

    Parameters
    ----------
    controller : Controller
        Any backend (``sim://``, ``mm3a://``, ...).
    joint : int
        1, 2 or 3.
    direction : {"+", "-"}
        ``"+"`` traverses from the lower stop to the upper one.
    detector : StopDetector
        Tuned for this joint (``feed(block) -> events``, ``reset(t0_s)``, ``latency_s``).
    audio_blocks : callable or iterable
        Audio in step with the controller: a callable returning the blocks recorded
        since its previous call, or an iterator yielding blocks (blocking) as recorded.
    pose : Pose
        The fixed pose (joints rad, rad, m; tilt rad) to write into the row.
    day : str
        Session label for the row.
    burst_steps : int
        Steps per burst (at 1 kHz, 2000 steps = 2 s between checks).
    predrive : {"listen", "overdrive", "none"}
        How to reach the start stop: step the other way until that stop is heard
        (default), or command more steps than the range can take without listening,
        or assume the joint already rests on it.
    latency : {"onset", "fixed", "none"}
        Which stop time to count to: the event's onset estimate (default), the
        detection time minus the detector's typical latency, or the raw detection time
        (no correction; the count then includes ``f_step x latency`` extra steps).
    max_steps : int, optional
        Give up (``TraverseError``) after this many steps without hearing a stop.
        Default: twice the range over :data:`MIN_STEP_PRIOR`.
    expected_steps : int, optional
        For the progress bar's total.
    clock : callable, optional
        Returns the stream time (s) now. Default: ``controller.clock_s`` if present,
        else the wall clock. After every burst the audio is heard up to the burst's
        end (``start + n / f``); with a real-time device give an iterator source, which
        blocks until the microphone has recorded that far.
    progress : bool or callable
        ``True`` shows a rich progress bar; a callable gets ``(steps, device_s)`` after
        every burst.
    settle_s : float
        Events with an onset within this time (s) of the start of the measured
        stepping are the start stop still ringing, and are ignored.
    listen_after_steps : int
        Steps to command before the limit switch starts listening (0: listen from
        the start). A stop cannot come before the range divided by the largest
        plausible step, or before, say, 80 % of the count a previous calibration
        predicts; not listening that long saves the audio processing. If the stop is
        heard as soon as listening starts (it came earlier), the traverse is measured
        again listening from the start.
    confirm_s : float
        Take a fire of the detector as the stop only once it persisted this long, s,
        while the joint keeps stepping (:mod:`stickslip.audio.confirm`; default
        :data:`~stickslip.audio.confirm.CONFIRM_S`). Costs ``confirm_s`` x the step rate
        extra steps against the stop and that much time, not accuracy (the count runs
        to the onset). 0: the first fire is the stop (the old behaviour). Ignored for a
        detector that does not listen to samples (the simulator's oracle).

    Returns
    -------
    TraverseResult
    """
    spec = kin.joint_spec(joint)
    sign = direction_sign(direction)
    label = direction_label(sign)
    _check_options(latency, predrive, burst_steps, listen_after_steps)
    day = check_day_label(day)  # before the joint moves
    detector = confirming(detector, confirm_s)  # a fresh confirming detector: the caller's is left as it was
    limit = int(max_steps) if max_steps is not None else int(2 * spec.span / MIN_STEP_PRIOR[spec.number])
    hz = float(controller.frequency(joint))
    clock = clock or _device_clock(controller)
    listener = _Listener(detector, audio_blocks, _sample_rate(detector, audio_blocks), step_hz=hz)
    run = _Run(controller, joint, sign, hz, clock, listener, burst_steps, limit)

    predrive_steps = run.to_start_stop(predrive)  # 1. to the start stop
    t_start = clock()
    update, close_bar = _progress_callback(progress, joint, label, expected_steps)
    try:  # 2. step until the end stop is heard
        event = run.until_heard(t_start, listen_after_steps, settle_s, update)
    finally:
        close_bar()
    if event is None:  # heard as soon as listening began: the stop came earlier; listen all along
        redo = measure_traverse(
            controller,
            joint,
            direction,
            detector=detector,
            audio_blocks=audio_blocks,
            pose=pose,
            day=day,
            burst_steps=burst_steps,
            predrive="listen",
            latency=latency,
            max_steps=max_steps,
            expected_steps=expected_steps,
            clock=clock,
            progress=progress,
            settle_s=settle_s,
            listen_after_steps=0,
            confirm_s=confirm_s,
        )
        return replace(redo, retried=True)

    # 3. count the steps made before the stop, latency corrected
    return run.counted(event, t_start, latency, pose, day, predrive_steps, listen_after_steps)


def check_burst_steps(burst_steps: object) -> None:
    """``ValueError`` unless ``burst_steps`` is an integer in [1, 1000000] (steps per burst between listens)."""
    if isinstance(burst_steps, bool) or not (isinstance(burst_steps, int) and 1 <= burst_steps <= 1_000_000):
        raise ValueError(f"burst_steps = {burst_steps!r} is outside [1, 1000000]")


def _check_options(latency: str, predrive: str, burst_steps: int, listen_after_steps: int) -> None:
    if latency not in LATENCY_MODES:
        raise ValueError(f"latency must be one of {', '.join(LATENCY_MODES)}, got {latency!r}")
    if predrive not in ("listen", "overdrive", "none"):
        raise ValueError(f"predrive must be 'listen', 'overdrive' or 'none', got {predrive!r}")
    check_burst_steps(burst_steps)
    if not (isinstance(listen_after_steps, int) and listen_after_steps >= 0):
        raise ValueError(f"listen_after_steps = {listen_after_steps!r} must be an integer >= 0")


def _device_clock(controller: Controller) -> Callable[[], float]:
    """Stream time (s): the controller's own clock where it has one, else the wall clock from now."""
    if isinstance(controller, VirtualClock):
        device = controller
        return lambda: float(device.clock_s)
    w0 = time.monotonic()
    return lambda: time.monotonic() - w0


def _row(spec: kin.JointSpec, sign: int, pose: kin.Pose, day: str, steps: int) -> Traverse:
    """The measurement-table row of a full-range traverse of ``spec``'s joint in direction ``sign``."""
    start, end = (spec.lower, spec.upper) if sign > 0 else (spec.upper, spec.lower)
    values = {"q1": pose.q1, "q2": pose.q2, "q3": pose.q3}
    values[f"q{spec.number}"] = start
    return Traverse(
        day=str(day),
        joint=spec.number,
        direction=direction_label(sign),
        q1=float(values["q1"]),
        q2=float(values["q2"]),
        q3=float(values["q3"]),
        theta=float(pose.theta),
        psi=float(pose.psi),
        start=start,
        end=end,
        steps=int(steps),
    )


@dataclass
class _Run:
    """One traverse's stepping: bursts sent (stream time, steps) and the steps commanded so far."""

    controller: Controller
    joint: int
    sign: int
    hz: float
    clock: Callable[[], float]
    listener: _Listener
    burst_steps: int
    limit: int
    bursts: list[tuple[float, int]] = field(default_factory=list)
    commanded: int = 0

    def to_start_stop(self, predrive: str) -> int:
        """Drive to the start stop (listening, or overdriving blind, or not at all); the steps it took."""
        steps = 0
        if predrive == "overdrive":
            spec = kin.joint_spec(self.joint)
            remaining = int(math.ceil(1.3 * spec.span / MIN_STEP_PRIOR[spec.number]))
            while remaining > 0:
                n = min(remaining, 100 * self.burst_steps)
                self.controller.step(self.joint, -self.sign * n)
                remaining -= n
                steps += n
        elif predrive == "listen":
            self.listener.start(self.clock())
            while True:
                if steps >= self.limit:
                    raise TraverseError(
                        f"joint {self.joint}: no stop heard after {steps} steps towards the start stop "
                        f"(direction {direction_label(-self.sign)}); check the tuning and the microphone"
                    )
                n = min(max(1, self.burst_steps // 4), self.limit - steps)
                b0 = self.clock()
                self.controller.step(self.joint, -self.sign * n)
                steps += n
                if self.listener.listen(max(self.clock(), b0 + n / self.hz)) is not None:
                    self.controller.stop(self.joint)
                    break
        return steps

    def _burst(self, n: int) -> float:
        b0 = self.clock()
        self.bursts.append((b0, n))
        self.controller.step(self.joint, self.sign * n)
        self.commanded += n
        return b0

    def until_heard(
        self, t_start: float, listen_after_steps: int, settle_s: float, update: Callable[[int, float], None]
    ) -> StopEvent | None:
        """Step in bursts until the end stop is heard; its event, or ``None`` if it was heard at once."""
        while self.commanded < listen_after_steps:  # the stop cannot be this close: do not listen yet
            self._burst(min(listen_after_steps - self.commanded, 50 * self.burst_steps))
            update(self.commanded, self.clock() - t_start)
        t_listen = self.clock()
        self.listener.start(t_listen)
        event = None
        while event is None:
            if self.commanded >= self.limit:
                raise TraverseError(
                    f"joint {self.joint}: no stop heard after {self.commanded} steps in direction "
                    f"{direction_label(self.sign)} ({self.commanded / self.hz:.1f} s at {self.hz:g} Hz); "
                    "check the tuning, the microphone and the joint"
                )
            n = min(self.burst_steps, self.limit - self.commanded)
            b0 = self._burst(n)
            # a real device may return before the burst is done: hear it to its end
            event = self.listener.listen(max(self.clock(), b0 + n / self.hz))
            if event is not None and listen_after_steps and float(event.onset_s) < t_listen + settle_s:
                self.controller.stop(self.joint)
                return None  # the stop was there as soon as we listened: it came before listen_after_steps
            while event is not None and float(event.onset_s) < t_start + settle_s:
                # the start stop's sound still ringing as the joint leaves it: not our stop
                self.listener.detector.reset(self.listener.t_s, self.listener.step_hz)
                event = self.listener.listen(self.clock())
            update(self.commanded, self.clock() - t_start)
        self.controller.stop(self.joint)
        return event

    def counted(
        self, event: StopEvent, t_start: float, latency: str, pose: kin.Pose, day: str, predrive_steps: int,
        listen_after_steps: int,
    ) -> TraverseResult:
        """The steps made from ``t_start`` (s) to the stop heard as ``event``, latency corrected, as the result."""
        if event.onset_uncertain:  # heard as the switch passed interference by: when did it begin?
            raise TraverseError(
                f"joint {self.joint}: the stop was heard at {event.detected_at_s:.2f} s as the limit switch passed "
                "by a sound that did not persist (interference near the stop), so when the stop began is uncertain"
                f"{_doubt(self.listener.detector, event)}; nothing recorded: keep talk and other sounds away from the "
                "arm and measure again" + _rate_hint(self.listener.detector, self.hz)
            )
        detected = float(event.detected_at_s)
        t_stop = {"onset": float(event.onset_s), "fixed": detected - float(self.listener.detector.latency_s)}.get(
            latency, detected
        )
        steps = _count_before(t_stop, self.bursts, self.hz)
        if steps <= 0:
            raise TraverseError(
                f"joint {self.joint}: the stop was heard at once ({steps} steps before it): the joint did not "
                "start from the opposite stop, or the detector fired on the start stop's sound"
            )
        fewest = _fewest_steps(self.joint)
        if steps < fewest:
            raise TraverseError(
                f"joint {self.joint}: a stop was heard after {steps} steps, fewer than the {fewest} its range takes at "
                f"the largest plausible step ({_largest_step(self.joint)}): not the end "
                "stop (interference, or the joint did not start from the opposite stop); nothing recorded"
            )
        return TraverseResult(
            traverse=_row(kin.joint_spec(self.joint), self.sign, pose, day, steps),
            steps=int(steps),
            commanded_steps=self.commanded,
            steps_after_stop=self.commanded - int(steps),
            latency_steps_corrected=_count_before(detected, self.bursts, self.hz) - int(steps),
            detected_at_s=detected,
            onset_s=float(event.onset_s),
            elapsed_device_s=self.clock() - t_start,
            frequency_hz=self.hz,
            predrive_steps=predrive_steps,
            listen_after_steps=listen_after_steps,
            bursts=tuple(self.bursts),
            confirmed_at_s=event.confirmed_at_s,
            unconfirmed=tuple(t for t in self.listener.unconfirmed if t >= t_start),
        )


def _doubt(detector: StopDetector, event: StopEvent) -> str:
    """Why the detector doubted ``event``'s onset, as its log says (``" (lines 0.58 in phase ...)"``), or ``""``
    where it keeps no log (:attr:`stickslip.audio.confirm.detector.ConfirmLog.onset`)."""
    log = getattr(getattr(detector, "log", None), "onset", None)
    why = [w for at, w in log if at == event.detected_at_s] if isinstance(log, list) else []
    return f" ({why[-1]})" if why and isinstance(why[-1], str) else ""


def _rate_hint(detector: StopDetector, hz: float) -> str:
    """Where the joint steps off its tuning's rate, what judges its stops better than measuring again: off the
    rate the stepping's lines are often not the joint's alone under speech or music, and a stop the levels
    alone heard is doubted (:mod:`stickslip.audio.confirm.clocked`)."""
    tuned = getattr(getattr(detector, "tuning", None), "step_rate_hz", None)
    if not (isinstance(tuned, float) and tuned > 0 and hz > 0) or abs(hz / tuned - 1.0) <= CLOCKED.max_rate_off:
        return ""
    return (f"; the joint steps at {hz:.4g} Hz, {100 * (hz / tuned - 1.0):+.0f} % from the tuning recording's "
            f"{tuned:.4g} Hz: a tuning recorded at {hz:.4g} Hz (stickslip tune) judges this rate's stops on its own")


def _fewest_steps(joint: int) -> int:
    """The fewest steps a traverse of ``joint`` can take: its range over :data:`MAX_STEP_PRIOR`."""
    return int(math.ceil(kin.joint_spec(joint).span / MAX_STEP_PRIOR[joint]))


def _largest_step(joint: int) -> str:
    """:data:`MAX_STEP_PRIOR` of ``joint`` for a person (µm or mrad)."""
    v = MAX_STEP_PRIOR[joint]
    return f"{v * 1e6:g} µm" if kin.joint_spec(joint).kind == "prismatic" else f"{v * 1e3:g} mrad"
