"""A no-signal guard for the audio limit switch: is the input alive at all?

A dead or unplugged microphone gives digital silence, a constant (a DC offset) or, with a
broken preamplifier, a signal pinned at full scale. A stop detector that compares band
levels can fire on such input within milliseconds, and a traverse would then record a
bogus step count. The guard looks at each block before the detector does and raises
:class:`NoSignalError` once the input has been dead for ``hold_s`` without a break.

Thresholds (samples are floats in [-1, 1], full scale 1):

* silence: peak amplitude below ``floor`` (default 1e-6, -120 dBFS; a real microphone's
  self-noise is far above it);
* constant: peak-to-peak below ``floor`` (a DC offset, however large);
* clipping: more than ``clip_share`` of the samples at or beyond ``clip_level`` of the
  block's peak: pinned at its rails, wherever they are (a float file may go past 1 without
  clipping; an analog stage may clip below full scale); rails below ``quiet_rails``
  (-60 dBFS) are silence in which only the converter's last bits toggle (a 16-bit file's
  least step is 3e-5, -90 dBFS);
* no stepping (when the commanded step rate ``step_hz`` is given): in every window of
  ``window_s`` for ``no_step_s`` without a break, the envelope of the sound (the
  first-differenced signal squared, so hum and thumps count little) shows no line at the
  step rate (within ``line_tolerance``) at least ``min_line_db`` above its neighbourhood
  (:func:`step_line_db`). A microphone that hears the room but not the joint - unplugged
  from the arm's mount, pointed away, a preamplifier's hiss - trips this.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft
from numpy.typing import ArrayLike

from ..features.stepclock import band_envelope_spectrum
from ..paramfield import param

__all__ = ["GUARD", "GuardParams", "NoSignalError", "SignalGuard", "block_problem", "non_finite", "step_line_db"]


@dataclass(frozen=True)
class GuardParams:
    """When the input is dead, or hears no stepping (the defaults of :class:`SignalGuard`)."""

    floor: float = param(1e-6, "full scale", "a block whose peak (or peak-to-peak) is under this is silent (-120 dBFS)")
    quiet_rails: float = param(
        1e-3, "full scale", "a signal pinned at rails under this is silence with the last bits toggling (-60 dBFS)"
    )
    clip_level: float = param(0.999, "of the peak", "samples at or beyond this share of the block's peak are at a rail")
    clip_share: float = param(0.5, "", "a block with more than this share of its samples at a rail is clipping")
    hold_s: float = param(0.2, "s", "the input must be dead this long without a break before the guard trips")
    no_step_s: float = param(1.0, "s", "no stepping line this long (at the commanded rate): the guard trips")
    window_s: float = param(0.25, "s", "audio judged at a time for the stepping line")
    min_line_db: float = param(8.0, "dB", "the step-rate line must stand this clear (noise: 7 dB median, 8+ in 1/4)")
    line_tolerance: float = param(0.03, "of the rate", "the step-rate line is looked for this near the commanded rate")


GUARD = GuardParams()


class NoSignalError(RuntimeError):
    """The audio input is dead (silence, a constant or clipping throughout)."""


def block_problem(block: ArrayLike, floor: float = GUARD.floor, p: GuardParams = GUARD) -> str | None:
    """Why ``block`` carries no usable signal ("silence", "a constant", "clipping"), or ``None`` if it is alive.

    Read in the block's own precision (a float32 block is not copied to float64): its
    largest and smallest sample are exact either way, and a NaN or an infinity shows in them.
    """
    x = np.asarray(block).ravel()
    if x.size == 0:
        return None
    if x.dtype.kind != "f":  # integers (whose abs can overflow), booleans: as float64
        x = x.astype(np.float64)
    lo, hi = float(x.min()), float(x.max())
    if not (np.isfinite(lo) and np.isfinite(hi)):  # NaN propagates into both; an infinity is one of them
        return "non-finite samples"
    peak = max(abs(lo), abs(hi))
    if peak < floor:
        return "silence"
    if hi - lo < floor:
        return "a constant"
    # stuck at its rails, wherever they are (a float file may go past 1 unclipped; an analog stage may clip below
    # full scale) - but rails this low are the converter's last bits toggling over silence (a 16-bit file's least
    # step is 3e-5), not a clipped sound. The rail is compared in float64 whatever the block's type.
    rail = np.float64(p.clip_level * peak)
    if np.count_nonzero(np.abs(x) >= rail) / x.size > p.clip_share:
        return "silence: only the converter's last bits toggle" if peak < p.quiet_rails else "clipping"
    return None


def non_finite(block: ArrayLike) -> tuple[int, int | None]:
    """How many samples of ``block`` are NaN or infinite, and the index of the first (None if none)."""
    bad = ~np.isfinite(np.asarray(block, dtype=np.float64).ravel())
    count = int(np.count_nonzero(bad))
    return count, (int(np.argmax(bad)) if count else None)


def step_line_db(x: ArrayLike, sample_rate: float, step_hz: float, tolerance: float = GUARD.line_tolerance) -> float:
    """How far the step-rate line stands above the envelope spectrum around it, dB.

    The envelope is the first-differenced signal squared (a click train's envelope has
    lines at the step rate and its multiples); the line is the largest bin within
    ``tolerance`` of ``step_hz``, compared with the median of the bins from 0.5 to 1.5
    times ``step_hz`` outside that range. Stepping gives tens of dB; noise, speech and
    hum a few. Needs at least 20 step periods of samples (else returns ``inf``: no verdict).
    """
    v = np.asarray(x, dtype=np.float64).ravel()
    sr = float(sample_rate)
    if not (step_hz > 0 and v.size >= 20 * sr / step_hz and step_hz < sr / 4):
        return float("inf")
    f, p = band_envelope_spectrum(v, sr)
    near = np.abs(f - step_hz) <= tolerance * step_hz
    around = (f >= 0.5 * step_hz) & (f <= 1.5 * step_hz) & ~near
    if not near.any() or not around.any():
        return float("inf")
    return float(10 * np.log10((p[near].max() + 1e-300) / (np.median(p[around]) + 1e-300)))


@dataclass
class SignalGuard:
    """Raise :class:`NoSignalError` when the input stays dead for ``hold_s`` seconds.

    Parameters
    ----------
    sample_rate : float
        Samples per second of the blocks, Hz.
    hold_s : float
        How long the input must be dead without a break before the guard trips, s.
    floor : float
        Amplitude below which a block is silent (full scale 1).
    step_hz : float, optional
        The commanded step rate, Hz; when given, the guard also trips when the sound shows
        no stepping at that rate for ``no_step_s`` (see the module docstring).
    no_step_s : float
        How long without a stepping line before the guard trips, s.
    window_s : float
        Length of audio judged at a time for the stepping line, s (rounded up by a few samples to a
        length whose FFT is fast; what the blocks bring beyond it goes into the next window).
    min_line_db : float
        The step-rate line must stand this far above its neighbourhood, dB.
    """

    sample_rate: float
    hold_s: float = GUARD.hold_s
    floor: float = GUARD.floor
    dead_s: float = 0.0
    step_hz: float | None = None
    no_step_s: float = GUARD.no_step_s
    window_s: float = GUARD.window_s
    min_line_db: float = GUARD.min_line_db
    no_step_for_s: float = 0.0

    def __post_init__(self) -> None:
        self._window: list[np.ndarray] = []
        self._window_n = 0
        # Every window judged is exactly this long, the rest carried into the next: the envelope's FFT
        # (one sample shorter, the first difference) then has a length with small prime factors. A window
        # of whatever the blocks add up to (12 blocks of 1024: an FFT of 12287 = 11 x 1117) took 15 times
        # as long and was a fifth of a simulated traverse's CPU time (benchmarks/bench_audio_speed.py).
        self._window_len = int(sfft.next_fast_len(max(int(self.window_s * self.sample_rate), 2) - 1, real=True)) + 1

    def check(self, block: ArrayLike) -> bool:
        """Account for one block: ``True`` if it is alive, ``False`` if it is dead.

        An event the detector reports on a dead block is not a stop (its level statistics
        can call silence one); once the input has been dead for ``hold_s`` without a break,
        :class:`NoSignalError`.
        """
        x = np.asarray(block)
        problem = block_problem(x, self.floor)
        if problem is None:
            self.dead_s = 0.0
            if self.step_hz:
                self._check_stepping(x)
            return True
        self.dead_s += x.shape[0] / self.sample_rate
        if self.dead_s >= self.hold_s:
            raise NoSignalError(
                f"no signal from the audio input: {problem} for {self.dead_s:.2f} s "
                "(is the microphone plugged in, switched on and not muted?); nothing was recorded"
            )
        return False

    def restart_stepping_check(self) -> None:
        """Forget the audio judged for stepping (call when stepping (re)starts after a pause)."""
        self._window, self._window_n, self.no_step_for_s = [], 0, 0.0

    def _check_stepping(self, x: np.ndarray) -> None:
        assert self.step_hz is not None
        mono = np.asarray(x, dtype=np.float64)
        self._window.append(mono if mono.ndim == 1 else mono.reshape(x.shape[0], -1).mean(axis=1))
        self._window_n += x.shape[0]
        n = self._window_len
        if self._window_n < n:
            return
        joined = np.concatenate(self._window)
        whole = joined.size // n * n  # a block longer than a window gives several
        rest = joined[whole:]
        self._window, self._window_n = ([rest], rest.size) if rest.size else ([], 0)
        for w in joined[:whole].reshape(-1, n):
            self._judge(w)

    def _judge(self, w: np.ndarray) -> None:
        assert self.step_hz is not None
        line = step_line_db(w, self.sample_rate, self.step_hz)
        if line >= self.min_line_db:
            self.no_step_for_s = 0.0
            return
        self.no_step_for_s += w.size / self.sample_rate
        if self.no_step_for_s >= self.no_step_s:
            raise NoSignalError(
                f"no stepping sound at {self.step_hz:g} Hz in the audio input for {self.no_step_for_s:.2f} s "
                f"(the step-rate line is {line:.0f} dB above its neighbourhood, {self.min_line_db:g} dB needed): "
                "is the microphone near the joint and is the controller stepping? nothing was recorded"
            )
