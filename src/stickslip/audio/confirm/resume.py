"""After a pause: where the stepping comes back, the point from which the detector listens afresh.

A pause (:mod:`.pause`) is judged at the end of the fire's confirmation window. The
stepping may still be paused there: a detector restarted at that point learned its
template in its warm-up from the room's silence and the first few steps that came back,
and the stepping's return was a lasting rise over that template, fitted as a stop (the
tenth generator's arm 3: a false stop 0.1 s after the stepping came back). So the restart
waits for the stepping: :class:`Resumption` reads the sound after the pause in pieces of
``piece_s`` through the detector's band-pass, counted from the point the pause was judged,
and the detector restarts at the first of ``resume_pieces`` pieces in a row that each are

* within ``back_db`` of the stepping's level before the pause (the pause's own rule for
  "the stepping is back", :func:`~.pause.stepping_stopped`), or
* ``rise_db`` over the quietest piece heard since the pause (the stepping came back at
  another gain: the microphone was moved while nothing stepped).

The samples before that point are heard by nothing: while the stepping is paused there is
no stop to hear. Where the stepping is already back when the pause is judged (a pause
shorter than the window), the restart is at that point, as it was before this wait. The
pieces are counted from the point the pause was judged and the band-pass keeps its state
from piece to piece, so the restart does not depend on how the stream is cut into blocks.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import sosfilt

from .pause import PAUSE, PauseCheck, PauseParams

__all__ = ["AfterPause", "Resumption"]


class Resumption:
    """Waits, after a pause, for the stepping to come back (see the module docstring).

    Parameters
    ----------
    sos : numpy.ndarray
        The detector's band-pass (:func:`~.pause.band_filter`).
    sample_rate : float
        Samples per second, Hz.
    p : PauseParams
    """

    def __init__(self, sos: NDArray[np.float64], sample_rate: float, p: PauseParams = PAUSE) -> None:
        self.sos, self.p = sos, p
        self.n = max(1, int(round(p.piece_s * float(sample_rate))))
        self.start(math.nan)
        self.waiting = False

    def start(self, before_power: float) -> None:
        """The pause was judged here: wait for the stepping (``before_power``: its in-band power before the pause)."""
        self.waiting = True
        #: the in-band power a piece must reach to be the stepping back (full scale 1; inf: the rise alone decides)
        known = math.isfinite(before_power) and before_power > 0.0
        self._back = before_power * 10.0 ** (-self.p.back_db / 10.0) if known else math.inf
        self._zi = np.zeros((self.sos.shape[0], 2))
        self._raw: list[NDArray[Any]] = []  # the samples since the first piece of the current run
        self._part = np.zeros(0)  # the filtered samples of the piece being heard
        self._floor = math.inf  # the quietest piece since the pause, full scale 1
        self._run = 0  # pieces in a row that were the stepping back
        self._seen = 0  # samples heard since the pause
        self._run_at = 0  # where the current run began, samples since the pause

    def push(self, x: NDArray[Any]) -> tuple[int, NDArray[Any]] | None:
        """Hear ``x``; once the stepping is back, where to restart and the samples from there on.

        Returns
        -------
        tuple of (int, numpy.ndarray) or None
            Where to restart, samples since the pause was judged, and the samples from there to
            the end of ``x`` (as given, of its dtype); ``None``: still waiting (all of ``x`` is
            heard and, but for the current run's samples, forgotten).
        """
        x = np.asarray(x)  # kept as given: the detector hears the same samples it would have
        if x.size == 0:
            return None
        y, self._zi = sosfilt(self.sos, x.astype(np.float64), zi=self._zi)
        self._raw.append(x)
        at = 0  # samples of ``y`` read
        while at < y.size:
            take = min(self.n - self._part.size, y.size - at)
            self._part = np.concatenate([self._part, y[at : at + take]])
            at += take
            if self._part.size < self.n:
                break
            power = float(np.mean(self._part**2))
            piece_at = self._seen + at - self.n  # the piece's first sample, since the pause
            self._part = np.zeros(0)
            if self._hear_piece(power, piece_at):
                return self._restart(x)
        self._seen += x.size
        self._forget()
        return None

    def _hear_piece(self, power: float, piece_at: int) -> bool:
        """One piece heard: True when it completes a run of ``resume_pieces`` pieces of stepping."""
        back = power >= self._back or power >= self._floor * 10.0 ** (self.p.rise_db / 10.0)
        self._floor = min(self._floor, power)
        if not back:
            self._run = 0
            return False
        if self._run == 0:
            self._run_at = piece_at
        self._run += 1
        return self._run >= self.p.resume_pieces

    def _restart(self, x: NDArray[Any]) -> tuple[int, NDArray[Any]]:
        """The run is complete (in ``x``, the samples just heard): the restart point and the samples from it on."""
        self.waiting = False
        kept = np.concatenate(self._raw)
        first = self._seen + x.size - kept.size  # the first kept sample, since the pause
        at, self._raw = self._run_at, []
        return at, kept[at - first :]

    def _forget(self) -> None:
        """Keep only the samples the current run (or the piece being heard) began in."""
        keep_from = self._run_at if self._run else self._seen - self._part.size
        kept = np.concatenate(self._raw) if self._raw else np.zeros(0)
        first = self._seen - kept.size
        self._raw = [kept[max(0, keep_from - first) :]]


class AfterPause:
    """The restart after a pause: where the pause was judged, then the wait for the stepping (:class:`Resumption`).

    Parameters
    ----------
    pause : PauseCheck
        The pause judgement: its band-pass, and the stepping's level before the fire.
    p : PauseParams
    """

    def __init__(self, pause: PauseCheck, p: PauseParams = PAUSE) -> None:
        self.pause = pause
        self.resumption = Resumption(pause.sos, pause.sample_rate, p)
        self.reset()

    def reset(self) -> None:
        #: the stream time a pause was judged at, s (None: none since the last restart)
        self.judged_s: float | None = None
        self.resumption.waiting = False

    @property
    def waiting(self) -> bool:
        """True from the pause's verdict until the stepping is back."""
        return self.resumption.waiting

    def wait(self) -> bool:
        """The window was rejected: wait for the stepping if it was a pause (True), else nothing (False)."""
        if self.judged_s is None:
            return False
        self.resumption.start(self.pause.before_power)
        return True

    def push(self, x: NDArray[Any]) -> tuple[float, float, NDArray[Any]] | None:
        """Hear ``x``; once the stepping is back: (the pause judged, the restart, stream times in s; the samples from
        the restart to the end of ``x``). ``None``: still waiting."""
        got = self.resumption.push(x)
        if got is None or self.judged_s is None:
            return None
        at, rest = got
        judged, self.judged_s = self.judged_s, None
        return judged, judged + at / self.pause.sample_rate, rest
