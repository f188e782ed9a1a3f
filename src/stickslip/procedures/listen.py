"""Listening for end stops in a stream of blocks: the loop behind ``stickslip listen``.

:func:`listen_blocks` feeds a finite stream (a recording read in blocks) through a tuned,
confirming detector and keeps what a person must be told about the stream besides the
stops: samples that are not numbers (a damaged file), a stream with no signal in it, one
too short to learn the stepping from, and the step rate heard in its first second
against the tuning's. :func:`listen_live` feeds a live stream (a microphone, a serial
vibration sensor) until it ends or Ctrl-C, handing each stop on as it is confirmed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..audio.confirm import CONFIRM_S, ConfirmedStopDetector, confirming
from ..audio.detector import StopEvent, Tuning
from ..audio.detector import detector_for as stop_detector_for
from ..audio.sources.guard import block_problem, non_finite

__all__ = ["ListenReport", "ListenSettings", "TuningMismatch", "detector_for", "listen_blocks", "listen_live"]


@dataclass(frozen=True)
class ListenSettings:
    """How stops are confirmed: ``confirm_s`` (s; 0: every fire), the step clock asked, the late path run.

    ``step_rate_hz`` is the step rate the controller commands, Hz (None: not told): the
    detector hears the step clock near it (:meth:`~stickslip.audio.events.StopDetector.reset`).
    """

    confirm_s: float = CONFIRM_S
    step_clock: bool = False
    late: bool = False
    step_rate_hz: float | None = None


class TuningMismatch(ValueError):
    """The tuning cannot be used at the stream's sample rate (``rate``, Hz)."""

    def __init__(self, rate: float, message: str):
        super().__init__(message)
        self.rate = rate


def detector_for(tuning: Tuning, rate: float, settings: ListenSettings) -> Any:
    """The detector ``settings`` ask for at ``rate`` (Hz); :class:`TuningMismatch` if the tuning does not fit it."""
    try:
        base = stop_detector_for(tuning.for_sample_rate(int(rate)))
        det = confirming(base, settings.confirm_s, step_clock=settings.step_clock, late=settings.late)
        det.reset(0.0, settings.step_rate_hz)
        return det
    except ValueError as e:
        raise TuningMismatch(rate, str(e)) from None


@dataclass(frozen=True)
class ListenReport:
    """What a finite stream held: the stops, the pauses in stepping, and what was wrong with the stream.

    Attributes
    ----------
    events : tuple of StopEvent
        The stops heard (confirmed, unless ``confirm_s`` was 0).
    stopped : tuple of (float, object)
        Where the stepping stopped (s) without an end stop, and the judgement.
    samples : int
        Samples heard (0: an empty or truncated stream).
    sample_rate : float
        Hz (the stream's; the tuning's if the stream was empty).
    non_finite : int
        Samples that are NaN or infinite.
    first_non_finite_s : float or None
        Where the first of them is, s.
    dead : bool
        No block carried a signal (silence, a constant, clipping).
    problems : tuple of str
        What the dead blocks were (``"silence"``, ...).
    heard_step_hz : float or None
        The step rate heard in the first second (NaN where nothing could be heard); ``None``
        when the tuning does not know its own step rate.
    """

    events: tuple[StopEvent, ...]
    stopped: tuple[tuple[float, Any], ...]
    samples: int
    sample_rate: float
    non_finite: int
    first_non_finite_s: float | None
    dead: bool
    problems: tuple[str, ...]
    heard_step_hz: float | None

    def warnings(self, name: str, tuning: Tuning) -> list[str]:
        """The warnings about the stream ``name`` (a file), one line each, in the order a person reads them."""
        out = []
        warmup_s = tuning.warmup_s if tuning.method == "template" else 0.0
        if self.samples < (warmup_s + tuning.hold_s) * self.sample_rate:
            lasts_ms = 1e3 * self.samples / self.sample_rate
            n = self.samples
            out.append(
                f"{name} lasts only {lasts_ms:.{1 if lasts_ms >= 0.1 else 4}f} ms ({n} sample{'s' if n != 1 else ''}): "
                f"less than the {1e3 * warmup_s:.0f} ms of stepping the detector learns from before it can hear a "
                "stop (unless the recording starts at the stop)"
            )
        if self.heard_step_hz is not None:
            why = tuning.step_rate_problem(self.heard_step_hz, f"{name}: the joint steps")
            if why is not None:
                out.append(why)
        if self.dead:
            out.append(f"{name} carries no signal ({', '.join(self.problems)})")
        if self.non_finite:
            many = self.non_finite != 1
            out.append(
                f"{name}: {self.non_finite} {'samples are not numbers' if many else 'sample is not a number'} "
                f"(NaN or infinity), the first at {self.first_non_finite_s:.4f} s: the file is damaged there "
                "(heard as 0 for NaN, full scale for infinity)"
            )
        return out


def _heard_step_hz(opening: list[NDArray[Any]], rate: float) -> float:
    """The step rate heard in the first second (NaN if it carries no signal), Hz."""
    from ..audio.features.stepclock import step_rate_hz

    # damaged samples count as silence here: one infinity read as full scale would be the only 'click' heard
    first = np.nan_to_num(np.concatenate(opening), nan=0.0, posinf=0.0, neginf=0.0)
    return math.nan if block_problem(first) is not None else float(step_rate_hz(first, rate))


def listen_blocks(
    blocks: Iterable[tuple[NDArray[Any], float]], tuning: Tuning, settings: ListenSettings
) -> ListenReport:
    """Feed ``blocks`` (samples, rate in Hz) through a detector made from ``tuning``; the :class:`ListenReport`.

    Raises :class:`TuningMismatch` at the first block if the tuning does not fit its
    rate; whatever the source raises (``AudioSourceError``) passes through.
    """
    events: list[StopEvent] = []
    problems: set[str | None] = set()
    n_bad, first_bad_s, heard = 0, None, 0
    rate_heard = float(tuning.sample_rate)
    opening: list[NDArray[Any]] = []  # the first second: the step rate heard, against the tuning's
    det = None
    for block, rate in blocks:
        bad, first = non_finite(block)
        if bad:
            n_bad += bad
            first_bad_s = first_bad_s if first_bad_s is not None else (heard + int(first or 0)) / rate
        if heard < rate:
            opening.append(block[: int(rate) - heard])
        heard += block.size
        rate_heard = float(rate)
        if det is None:
            det = detector_for(tuning, rate, settings)
        problems.add(block_problem(np.nan_to_num(block) if bad else block))  # damage is reported apart
        events += det.feed(block)
    stopped: list[tuple[float, Any]] = []
    if isinstance(det, ConfirmedStopDetector):
        events += det.finish()
        stopped = list(det.log.stopped)
    step_hz = None
    if opening and tuning.step_rate_hz is not None:
        step_hz = _heard_step_hz(opening, rate_heard)
    dead = bool(problems) and None not in problems
    return ListenReport(
        tuple(events), tuple(stopped), heard if det is not None else 0, rate_heard, n_bad, first_bad_s, dead,
        tuple(sorted(p for p in problems if p)), step_hz,
    )


def listen_live(
    detector: Any,
    blocks: Iterable[NDArray[Any]],
    on_event: Callable[[StopEvent], None],
    on_stopped: Callable[[float, Any], None],
) -> None:
    """Feed a live stream's ``blocks`` to ``detector`` until it ends or Ctrl-C; each stop to ``on_event`` as it comes.

    ``on_stopped(t_s, why)`` is told where the stepping stopped without an end stop.
    Whatever the source raises (``AudioSourceError``) passes through.
    """
    noted = 0
    try:
        for block in blocks:
            for ev in detector.feed(block):
                on_event(ev)
            log = getattr(detector, "log", None)
            stopped = log.stopped if log is not None else ()
            for t_s, why in stopped[noted:]:
                on_stopped(t_s, why)
            noted = len(stopped)
    except KeyboardInterrupt:
        pass
