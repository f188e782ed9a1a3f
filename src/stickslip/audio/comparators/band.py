"""The band-power detector of version-1 tunings (:class:`BandDetector`), kept as a comparator.

Per frame of ``frame`` samples (every ``hop`` samples) it takes a Hann-windowed rfft and the
power in the joint's band ``band_hz``, in dB relative to full scale (or relative to the
reference band ``reference_hz``, so that a microphone gain change cancels). A stop is
declared when the band level stays at or above ``threshold_db`` for ``hold_s`` (a knock
or a burst of speech is shorter; up to ``max_dips`` frames of the hold may dip below); it
then stays latched until the level has been below ``threshold_db - hysteresis_db`` for
``release_s``, so one stop gives one event. There is no look-ahead beyond one frame.

The spectral-template detector (:class:`~stickslip.audio.change.TemplateDetector`) replaced
it: a band level is moved by a microphone's distance, a voice in the band, another step
rate. ``benchmarks/bench_audio.py`` runs both on the same recordings.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..events import StopEvent
from ..features.frames import FrameCutter, bounded
from ..features.spectra import SPECTRA, band_bins, window
from ..tuningfile import Tuning

__all__ = ["BandDetector"]


class BandDetector:
    """Streaming detector of a version-1 (band) tuning: ``feed`` blocks of samples, get :class:`StopEvent` s.

    Parameters
    ----------
    tuning : Tuning
        Band, threshold and timing (its ``sample_rate`` must be the stream's).
    t0_s : float
        Stream time of the first sample fed, s.

    Examples
    --------
    >>> det = BandDetector(Tuning(band_hz=(5600, 7100), threshold_db=-50))
    >>> det.feed(np.zeros(4800, dtype=np.float32))
    []
    """

    #: the no-signal guard applies: this detector listens to samples
    uses_audio = True

    def __init__(self, tuning: Tuning, t0_s: float = 0.0) -> None:
        self.tuning = tuning
        self._w, self._scale = window(tuning.frame)
        self._i0, self._i1 = band_bins(tuning.band_hz, tuning.sample_rate, tuning.frame)
        self._ref = band_bins(tuning.reference_hz, tuning.sample_rate, tuning.frame) if tuning.reference_hz else None
        self._hold = tuning.hold_frames
        self._full = (1 << (self._hold + tuning.max_dips)) - 1
        self._release = max(1, int(math.ceil(tuning.release_s * tuning.sample_rate / tuning.hop)))
        self._cutter = FrameCutter(tuning.frame, tuning.hop)
        #: set to a list to collect every frame's margin over the threshold, dB (>= 0: the frame is stop-like)
        self.evidence: list[float] | None = None
        #: set to a list to collect every frame's verdict: the level at or above the threshold
        self.hot_evidence: list[bool] | None = None
        self.reset(t0_s)

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Forget everything; the next sample fed is at stream time ``t0_s`` (a band level ignores the step rate)."""
        self.t0_s = float(t0_s)
        self._cutter.reset()
        self.frames_seen = 0
        self._mask = 0  # bit i: frame i hops ago was above threshold
        self._latched = False
        self._below = 0
        self._prev_db = -np.inf
        self._cross_t = math.nan

    def hold(self, on: bool) -> None:
        """Ignored: this detector re-arms only when the level falls (a confirmation un-latches it)."""

    #: ignored, as :meth:`hold`
    hold_on_fire = False

    def unlatch(self) -> None:
        """Forget the latest fire and listen for the next stop from the next frame on."""
        self._latched = False
        self._below = 0
        self._mask = 0

    @property
    def latency_s(self) -> float:
        """Typical detected_at - true onset, s (for a traverse's latency correction)."""
        return self.tuning.latency_s

    @property
    def latched(self) -> bool:
        """True while a stop is being heard (after it fired, until released)."""
        return self._latched

    @property
    def level(self) -> float:
        """The latest frame's level in the tuning's unit (dBFS, or dB re the reference band)."""
        return float(self._prev_db)

    @property
    def ready(self) -> bool:
        """Always True: this detector learns nothing before it can fire."""
        return True

    @property
    def relearned(self) -> list[int]:
        """Always empty: this detector keeps no template."""
        return []

    def feed(self, block: NDArray[Any]) -> list[StopEvent]:
        """Consume a block of mono samples; return the stops that fired in it."""
        x = bounded(block)
        view = self._cutter.push(x)
        n = view.shape[0]
        events: list[StopEvent] = []
        if n > 0:
            levels = self._levels(view)
            tu = self.tuning
            if self.evidence is not None:
                self.evidence.extend((levels - tu.threshold_db).tolist())
            if self.hot_evidence is not None:
                self.hot_evidence.extend((levels >= tu.threshold_db).tolist())
            events = self._run(levels, self._cutter.ends(n))
            self.frames_seen += n
        self._cutter.advance(n)
        return events

    def _levels(self, view: NDArray[np.float64]) -> NDArray[np.float64]:
        """The band level of each frame, dBFS (or relative to the reference band: a gain change cancels)."""
        floor = SPECTRA.power_floor
        if self._ref is None:
            spec = np.fft.rfft(view * self._w, axis=1)[:, self._i0 : self._i1]
            power = (spec.real**2 + spec.imag**2).sum(axis=1) * self._scale
            return np.asarray(10 * np.log10(power + floor), dtype=np.float64)
        spec = np.fft.rfft(view * self._w, axis=1)
        p = spec.real**2 + spec.imag**2
        r0, r1 = self._ref
        band = 10 * np.log10(p[:, self._i0 : self._i1].sum(axis=1) * self._scale + floor)
        return np.asarray(band - 10 * np.log10(p[:, r0:r1].sum(axis=1) * self._scale + floor), dtype=np.float64)

    def _run(self, levels: NDArray[np.float64], ends: NDArray[np.int64]) -> list[StopEvent]:
        tu = self.tuning
        thr, rel = tu.threshold_db, tu.threshold_db - tu.hysteresis_db
        sr, H = tu.sample_rate, tu.hop
        if not self._latched and self._mask == 0 and float(levels.max()) < thr:
            self._prev_db = float(levels[-1])  # fast path: nothing near a stop
            return []
        events = []
        prev = self._prev_db
        for lev, end in zip(levels.tolist(), ends.tolist(), strict=True):
            if self._latched:
                self._below = self._below + 1 if lev < rel else 0
                if lev < rel and self._below >= self._release:
                    self._latched = False
                    self._mask = 0
            else:
                above = lev >= thr
                if above and self._mask == 0:
                    # interpolate the crossing between the previous frame and this one
                    t_end = self.t0_s + end / sr
                    if math.isfinite(prev) and prev < thr and lev > prev:
                        frac = (thr - prev) / (lev - prev)
                        self._cross_t = float(t_end - (1 - frac) * H / sr)
                    else:
                        self._cross_t = t_end
                # debounce: hold_frames above threshold among the last hold_frames + max_dips frames (a knock lights
                # fewer; a stop all)
                self._mask = ((self._mask << 1) | above) & self._full
                if above and self._mask.bit_count() >= self._hold:
                    self._latched = True
                    self._below = 0
                    events.append(StopEvent(self.t0_s + end / sr, self._cross_t - tu.onset_lag_s, float(lev)))
            prev = lev
        self._prev_db = prev
        return events
