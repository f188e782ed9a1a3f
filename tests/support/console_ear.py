"""An ear for the NanoControl console emulator: what stands in for a microphone in the day-one guide's test.

A traverse on a real controller listens to a sound card. The console emulator steps its
simulated arm in real time but makes no sound, so for tests this module provides

* :class:`RecordingConsoleEmulator`: the emulator, keeping a log of every drive (channel,
  start on the emulator's clock, steps per interval, interval, direction, stepping
  frequency, the joint's position when it began, and when it was halted);
* :class:`ConsoleEar`: a stop detector that knows, from that log and the arm's true mean
  step, when the joint reached its end stop (an oracle, as ``stickslip.sim.oracle`` is for
  the simulator's virtual clock), mapped onto the stream time of the traverse; it can be
  made deaf (a missed stop);
* :class:`PacedSilence`: a sound card that delivers blocks of silence in real time, and
  can stand for the user's Ctrl-C after a number of blocks.

The truth it hears is the emulator's, not the code under test's: positions come from the
simulated arm and the step counts from the emulator's clock (``steps_by``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stickslip import kinematics as kin
from stickslip.audio.events import StopEvent
from stickslip.sim.console_emulator import ConsoleEmulator, steps_by

__all__ = ["ConsoleEar", "Drive", "PacedSilence", "RecordingConsoleEmulator"]


@dataclass
class Drive:
    """One drive of one channel: started at ``t0`` (emulator clock, s), halted at ``t_end`` (``None``: running)."""

    channel: str
    t0: float
    per: int
    interval: float
    sign: int
    hz: float
    q0: float
    t_end: float | None = None

    def made(self, t: float) -> int:
        """Steps made by time ``t`` (emulator clock, s)."""
        end = t if self.t_end is None else min(t, self.t_end)
        return steps_by(end - self.t0, self.per, self.interval, self.hz)

    def time_of_step(self, n: int) -> float:
        """When (emulator clock, s) the ``n``-th step was made, if the drive ran long enough."""
        lo, hi = 0.0, 1.0
        while steps_by(hi, self.per, self.interval, self.hz) < n:
            hi *= 2.0
            if hi > 1e6:
                return math.inf
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if steps_by(mid, self.per, self.interval, self.hz) >= n:
                hi = mid
            else:
                lo = mid
        return self.t0 + hi


class RecordingConsoleEmulator(ConsoleEmulator):
    """The console emulator, keeping :attr:`drives`: every drive it made, in order."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.drives: list[Drive] = []

    def _halt(self) -> None:
        now = self.clock()
        for d in self.drives:
            if d.t_end is None:
                d.t_end = now
        super()._halt()

    def _execute(self, name: str, args: list[str]) -> str | None:
        out = super()._execute(name, args)
        if name == "go":  # the previous drives were halted (the arm moved); these start now
            with self._state:
                for ch, drv in self._driving.items():
                    j = self.joints.get(ch)
                    q0 = float(self.sim.position(j)) if j else math.nan
                    self.drives.append(Drive(ch, drv.t0, drv.per, drv.interval, drv.sign, drv.hz, q0))
        return out


class ConsoleEar:
    """A stop detector for a traverse on :class:`RecordingConsoleEmulator`: it hears the joint reach a stop.

    The stream time of the traverse is the wall clock from when it began (what a
    traverse on a real controller counts); :meth:`reset` ties the two. A stop is heard
    ``delay_s`` after the step that reached it, its onset that step's time. ``deaf``: the
    stop is never heard (a microphone that fell off).
    """

    uses_audio = False
    """It never looks at the samples (silence), so the traverse's no-signal guard does not apply."""

    def __init__(
        self, emulator: RecordingConsoleEmulator, joint: int, sample_rate: int, delay_s: float = 0.03,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.emu = emulator
        self.joint = joint
        self.channel = next(c for c, j in emulator.joints.items() if j == joint)
        self.sample_rate = sample_rate
        self.delay_s = delay_s
        self.clock = clock
        self.deaf = False
        self._begins: dict[int, float] = {}  # drive index -> when it reached the stop (emulator clock, s)
        self.reset(0.0)

    @property
    def latency_s(self) -> float:
        return self.delay_s

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Stream time ``t0_s`` is now (the commanded step rate is not needed: the ear knows the step counts)."""
        self.t_s = float(t0_s)
        self.offset = self.clock() - self.t_s  # emulator clock = stream time + offset
        self._heard_upto = self.t_s

    def _runs(self) -> Iterator[tuple[float, float]]:
        """``(begin, end)`` stream times of runs of steps against an end stop of the joint."""
        spec = kin.JOINTS[self.joint]
        sim = self.emu.sim
        for k, d in enumerate(list(self.emu.drives)):
            if d.channel != self.channel or math.isnan(d.q0):
                continue
            begin = self._begins.get(k)
            if begin is None:  # a drive's start, rate and distance never change: its first step at the stop once
                stop = spec.upper if d.sign > 0 else spec.lower
                gamma = float(sim.true_mean_step(self.joint, d.sign, 0.5 * (d.q0 + stop)))
                need = max(0, math.ceil(abs(stop - d.q0) / gamma))
                begin = self._begins[k] = d.time_of_step(need) if need else d.t0
            end = math.inf if d.t_end is None else d.t_end
            if begin < end:
                yield begin - self.offset, end - self.offset

    def feed(self, block: NDArray[np.float64]) -> list[StopEvent]:
        """The stream advances by ``block``; the stop heard within it, if any."""
        t_end = self.t_s + len(block) / self.sample_rate
        self.t_s = t_end
        if self.deaf:
            return []
        out = []
        for begin, end in self._runs():
            onset = max(begin, self._heard_upto)
            if onset < end and onset + self.delay_s <= t_end:
                out.append(StopEvent(t_end, onset, 0.0))
                self._heard_upto = max(end, t_end)
        return out


class PacedSilence:
    """A sound card of silence, in real time: a block is delivered once the wall clock has passed its end.

    ``interrupt_after``: after that many blocks the user presses Ctrl-C (a
    ``KeyboardInterrupt`` from the source, as from any blocking read).
    """

    interrupt_after: int | None = None

    def __init__(self, sample_rate: int = 48_000, block: int = 1024, device: Any = None, **_: Any) -> None:
        self.sample_rate = int(sample_rate)
        self.block = int(block)
        self.overflows = 0
        self._t0 = time.monotonic()

    def start(self) -> PacedSilence:
        self._t0 = time.monotonic()
        return self

    def blocks(self) -> Iterator[NDArray[np.float32]]:
        i = 0
        dt = self.block / self.sample_rate
        while True:
            if self.interrupt_after is not None and i >= self.interrupt_after:
                raise KeyboardInterrupt
            wait = self._t0 + (i + 1) * dt - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            i += 1
            yield np.zeros(self.block, dtype=np.float32)

    def stop(self) -> None:
        pass
