"""The band-power tuner of tuning files version 1 (:func:`tune_band`), kept for comparison and old workflows.

The recording holds stepping before ``stop_at_s`` and stepping against the stop after.
For every candidate band (centres 1/12 octave apart, widths 1/6 to 1 octave) tuning
measures the detector's level of every frame in both parts: by default the band level
*relative to the broadband level* (a change of microphone gain cancels, and a stop that
moves energy into its band and out of the stepping resonances moves it both ways), or
the absolute band level (``relative=False``). It judges each part the way the detector
decides: by the level that ``hold`` of every ``hold + max_dips`` consecutive frames reach
(a rank filter), not by single frames, so a lone transient does not count. A band is
scored by its *contrast*: the stopped part's low percentile (default 5th) minus the
stepping part's high percentile (default 99.5th). The band with the largest contrast wins, and the
threshold is put ``margin`` of the way from the stepping level to the stopped level
(default half-way, so a change of microphone gain of up to about a quarter of the
contrast in either direction still works). Tuning then runs the detector over the
recording to check that it fires exactly once, at the stop, and records the latency.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import rank_filter

from ..comparators import BandDetector
from ..features.spectra import band_bins, frame_power_spectra
from ..tuningfile import Tuning, default_frame
from .labels import TuningError, recording

FloatArray = NDArray[np.float64]

_DEFAULT_MAX_DIPS: int = Tuning(band_hz=(1000.0, 2000.0), threshold_db=0.0).max_dips

__all__ = ["candidate_bands", "tune_band"]


def candidate_bands(
    sample_rate: int,
    frame: int,
    f_min_hz: float = 200.0,
    widths_oct: tuple[float, ...] = (1 / 6, 1 / 3, 1 / 2, 2 / 3, 1.0, 1.5),
    min_band_hz: float = 0.0,
) -> list[tuple[float, float]]:
    """Candidate bands (low, high) in Hz, at least two bins and ``min_band_hz`` wide."""
    nyq = sample_rate / 2
    bin_hz = sample_rate / frame
    out = []
    n_centres = int(math.floor(12 * math.log2(0.95 * nyq / f_min_hz))) + 1
    for k in range(n_centres):
        c = f_min_hz * 2 ** (k / 12)
        for w in widths_oct:
            lo, hi = c * 2 ** (-w / 2), c * 2 ** (w / 2)
            if hi > 0.98 * nyq or hi - lo < max(2 * bin_hz, min_band_hz):
                continue
            out.append((round(lo, 1), round(hi, 1)))
    return out


def _band_level_matrix(
    samples: NDArray[Any], sample_rate: int, frame: int, hop: int, bands: list[tuple[float, float]], chunk: int = 4096
) -> NDArray[np.float64]:
    """frames x bands matrix of band levels, dBFS (spectra computed in chunks)."""
    idx = [band_bins(b, sample_rate, frame) for b in bands]
    n_frames = (samples.size - frame) // hop + 1
    out = np.empty((max(n_frames, 0), len(bands)))
    for f0 in range(0, n_frames, chunk):
        f1 = min(f0 + chunk, n_frames)
        seg = samples[f0 * hop : (f1 - 1) * hop + frame]
        p = frame_power_spectra(seg, frame, hop)
        c = np.concatenate((np.zeros((p.shape[0], 1)), np.cumsum(p, axis=1)), axis=1)
        for j, (i0, i1) in enumerate(idx):
            out[f0:f1, j] = c[:, i1] - c[:, i0]
    return 10 * np.log10(out + 1e-20)


def tune_band(
    samples: np.ndarray,
    sample_rate: int,
    stop_at_s: float,
    joint: int | None = None,
    *,
    frame: int | None = None,
    hop: int | None = None,
    hold_s: float = 0.016,
    release_s: float = 0.25,
    guard_s: float = 0.03,
    stepping_percentile: float = 99.5,
    stopped_percentile: float = 5.0,
    margin: float = 0.5,
    min_contrast_db: float = 6.0,
    min_part_s: float = 0.25,
    f_min_hz: float = 200.0,
    min_band_hz: float = 1400.0,
    rate_shift_hz: float = 0.0,
    max_stepping_s: float = 20.0,
    max_stopped_s: float = 10.0,
    relative: bool = True,
) -> Tuning:
    """Choose band and threshold that tell stepping from stepping against the stop (see the module docstring).

    ``samples`` (mono, full scale 1.0) at ``sample_rate`` (Hz) reach the stop at ``stop_at_s``
    (s); times are s, frequencies Hz: ``hold_s`` above threshold before firing, ``release_s``
    below it before re-arming, ``guard_s`` around the stop in neither part, each part at
    least ``min_part_s`` and at most ``max_stepping_s`` / ``max_stopped_s``. The contrast is
    the ``stopped_percentile`` of the stop part less the ``stepping_percentile`` of the
    stepping part (refused under ``min_contrast_db``); the threshold sits ``margin`` of the
    way. Bands are centred from ``f_min_hz``, at least ``min_band_hz`` wide (above the
    highest step rate: a narrower one sits between two harmonics at one rate, on one at
    another); ``rate_shift_hz`` judges the stepping at the band shifted that far either way;
    ``relative``: against the broadband level, so a gain change cancels."""
    if not 0.0 < margin < 1.0:
        raise TuningError(f"margin {margin} must be between 0 and 1 (exclusive)")
    x, sample_rate = recording(samples, sample_rate, stop_at_s, min_part_s, guard_s)
    frame = int(frame or default_frame(sample_rate))
    hop = int(hop or max(1, frame // 4))
    bands = candidate_bands(sample_rate, frame, f_min_hz, min_band_hz=min_band_hz)
    if not bands:
        raise TuningError(f"no band at least {min_band_hz:g} Hz wide fits below {sample_rate / 2:g} Hz")
    # analyse at most max_stepping_s before the stop and max_stopped_s after it
    first = max(0, int((stop_at_s - max_stepping_s) * sample_rate) // hop * hop)
    last = min(x.size, int((stop_at_s + max_stopped_s) * sample_rate))
    reference = (float(f_min_hz), round(0.9 * sample_rate / 2, 1)) if relative else None
    hold = max(1, int(math.ceil(hold_s * sample_rate / hop - 1e-9)))
    sc = _Scorer(x[first:last], first / sample_rate, sample_rate, frame, hop, hold, reference)
    stop_lo, step_hi = sc.parts(bands, stop_at_s, guard_s, stopped_percentile, stepping_percentile, rate_shift_hz)
    band, c, step, stop = _best_band(bands, stop_lo, step_hi, min_contrast_db)
    threshold = float(step + margin * c)
    tuning = Tuning(
        band_hz=band, threshold_db=round(threshold, 2), sample_rate=sample_rate, frame=frame, hop=hop, hold_s=hold_s,
        hysteresis_db=round(min(6.0, 0.25 * c), 2), release_s=release_s, onset_lag_s=0.0, joint=joint,
        contrast_db=round(c, 2), margin_db=round(threshold - step, 2), stepping_db=round(step, 2),
        stopped_db=round(stop, 2), reference_hz=reference,
    )  # fmt: skip
    return _verified_band(tuning, x, stop_at_s, guard_s)


def _best_band(
    bands: list[tuple[float, float]], stop_lo: np.ndarray, step_hi: np.ndarray, min_contrast_db: float
) -> tuple[tuple[float, float], float, float, float]:
    """The band with the largest contrast (dB), the contrast, and its stepping and stopped levels."""
    contrast = stop_lo - step_hi
    best = int(np.argmax(contrast))
    band = bands[best]
    c = float(contrast[best])
    if c < min_contrast_db:
        raise TuningError(
            f"the stepping and stopped parts sound alike: the best band, {band[0]:.0f}-"
            f"{band[1]:.0f} Hz, separates them by {c:.1f} dB, below the {min_contrast_db:g} dB "
            "needed; check --stop-at and that the recording reaches the end stop"
        )
    return band, c, float(step_hi[best]), float(stop_lo[best])


class _Scorer:
    """Band levels of a recording's segment as the detector decides on them (``hold`` of every window of frames)."""

    def __init__(
        self,
        seg: FloatArray,
        t_first: float,
        sample_rate: int,
        frame: int,
        hop: int,
        hold: int,
        reference: tuple[float, float] | None,
    ) -> None:
        self.seg, self.t_first, self.sample_rate = seg, t_first, sample_rate
        self.frame, self.hop, self.hold = frame, hop, hold
        self.window = hold + _DEFAULT_MAX_DIPS
        self.ref_level: Any = _band_level_matrix(seg, sample_rate, frame, hop, [reference])[:, :1] if reference else 0.0

    def decided(self, bands: list[tuple[float, float]]) -> np.ndarray:
        """The level ``hold`` of every ``window`` consecutive frames reach, per band: what the detector decides on."""
        lv = _band_level_matrix(self.seg, self.sample_rate, self.frame, self.hop, bands)
        w, h = self.window, self.hold
        return np.asarray(rank_filter(lv - self.ref_level, rank=w - h, size=(w, 1), mode="nearest"))

    def parts(
        self,
        bands: list[tuple[float, float]],
        stop_at_s: float,
        guard_s: float,
        stopped_percentile: float,
        stepping_percentile: float,
        rate_shift_hz: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per band: the stopped part's low percentile and the stepping part's high percentile."""
        levels = self.decided(bands)
        starts = self.t_first + np.arange(levels.shape[0]) * self.hop / self.sample_rate
        ends = starts + (self.frame - 1) / self.sample_rate
        stepping_rows = ends < stop_at_s - guard_s
        stop_lo = np.percentile(levels[starts >= stop_at_s + guard_s], stopped_percentile, axis=0)
        # The steps sound as a line spectrum at multiples of the step rate; at another rate the lines fall elsewhere in
        # the band. Judge the stepping level by the loudest of the band and its copies shifted by up to
        # +-rate_shift_hz (half the highest step rate covers every placement of the lines).
        step_hi = np.full(len(bands), -np.inf)
        for shift in np.linspace(-rate_shift_hz, rate_shift_hz, 5) if rate_shift_hz else [0.0]:
            moved = [(max(lo + shift, 0.0), min(hi + shift, self.sample_rate / 2)) for lo, hi in bands]
            lv = self.decided(moved)[stepping_rows]
            step_hi = np.maximum(step_hi, np.percentile(lv, stepping_percentile, axis=0))
        return stop_lo, step_hi


def _verified_band(tuning: Tuning, x: FloatArray, stop_at_s: float, guard_s: float) -> Tuning:
    """``tuning`` if its detector fires once, at the stop, with the onset lag and latency it measured there."""
    events = BandDetector(tuning).feed(x)
    near = [e for e in events if stop_at_s - guard_s <= e.detected_at_s <= stop_at_s + 0.2]
    if len(events) != 1 or len(near) != 1:
        where = ", ".join(f"{e.detected_at_s:.3f} s" for e in events) or "never"
        band = tuning.band_hz
        raise TuningError(
            f"band {band[0]:.0f}-{band[1]:.0f} Hz at {tuning.threshold_db:.1f} {tuning.level_unit} fired {where}; "
            f"expected once just after {stop_at_s:g} s. The recording may hold other stops "
            "or loud interference in the stepping part"
        )
    ev = near[0]
    lag = ev.onset_s - stop_at_s  # onset_s is the crossing time while onset_lag_s = 0
    return replace(tuning, onset_lag_s=round(lag, 6), latency_measured_s=round(ev.detected_at_s - stop_at_s, 6))
