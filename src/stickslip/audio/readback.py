"""End stops from a position read-back: the position stops changing while the joint steps.

A third kind of sensor for the limit switch, beside sound and vibration: a capacitive
sensor or an encoder on the slider. It is fed position samples the way the audio
detector is fed sound, and implements the same :class:`~stickslip.audio.events.StopDetector`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .events import StopEvent

__all__ = ["ReadbackStopDetector"]


class ReadbackStopDetector:
    """End stops from a position read-back: the position stops changing while stepping.

    Feed it position samples (any unit, sampled at ``sample_rate``) the way the audio
    detector is fed sound; it fires when the position has moved less than
    ``min_motion`` over the last ``window_s`` after having moved, and estimates the
    onset as the time of the last sample that still moved. A controller whose "counter"
    counts the steps *issued* (NanoControl's ``counterread``) cannot serve: it keeps
    counting against the stop; only a sensor of the slider's position can.

    Parameters
    ----------
    sample_rate : float
        Position samples per second, Hz.
    min_motion : float
        Smallest change of position over ``window_s`` that counts as moving (position unit).
    window_s : float
        Stall time that makes a stop, s (the latency is about this).
    t0_s : float
        Stream time of the first sample, s.
    """

    uses_audio = False  # the no-signal guard is for sound and vibration, not positions

    def __init__(self, sample_rate: float, min_motion: float, window_s: float = 0.02, t0_s: float = 0.0) -> None:
        if not (sample_rate > 0 and min_motion > 0 and window_s > 0):
            raise ValueError("sample_rate, min_motion and window_s must be > 0")
        self.sample_rate = float(sample_rate)
        self.min_motion = float(min_motion)
        self.window_s = float(window_s)
        self.reset(t0_s)

    @property
    def latency_s(self) -> float:
        """Typical detected_at - onset, s."""
        return self.window_s

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Forget everything; the next sample is at stream time ``t0_s`` (positions ignore the step rate)."""
        self._t0 = float(t0_s)
        self._n = 0
        self._recent: list[float] = []
        self._anchor: float | None = None
        self._anchor_i = 0
        self._moved = False
        self.latched = False

    def feed(self, block: NDArray[np.floating[Any]] | list[float]) -> list[StopEvent]:
        """Consume position samples; return the stops that fired."""
        out: list[StopEvent] = []
        w = max(2, int(round(self.window_s * self.sample_rate)))
        for v in np.asarray(block, dtype=np.float64).ravel().tolist():
            i = self._n
            self._n += 1
            if self._anchor is None or abs(v - self._anchor) >= self.min_motion:
                if self._anchor is not None:
                    self._moved = True
                    self.latched = False
                self._anchor, self._anchor_i = v, i
                continue
            if self._moved and not self.latched and i - self._anchor_i >= w:
                self.latched = True
                out.append(
                    StopEvent(
                        detected_at_s=self._t0 + i / self.sample_rate,
                        onset_s=self._t0 + self._anchor_i / self.sample_rate,
                        level_db=0.0,
                    )
                )
        return out
