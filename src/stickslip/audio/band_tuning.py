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

from .detector import StopDetector, Tuning, _band_bins, frame_power_spectra
from .labels import TuningError, _recording
from .tuningfile import default_frame

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
    idx = [_band_bins(b, sample_rate, frame) for b in bands]
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
    """Choose band and threshold that tell stepping from stepping against the stop.

    Parameters
    ----------
    samples : numpy.ndarray
        Mono recording (float, full scale 1.0).
    sample_rate : int
        Its sample rate, Hz.
    stop_at_s : float
        When the joint reached the stop, s from the start of the recording.
    joint : int, optional
        Joint the recording belongs to (stored in the tuning).
    frame, hop : int, optional
        Frame length and hop, samples (default about 10.7 ms and a quarter of it).
    hold_s : float
        Time the level must stay above threshold before firing, s (longer than a frame,
        so that a knock, which lights up every frame overlapping it, does not fire).
    release_s : float
        Time below threshold minus hysteresis before re-arming, s.
    guard_s : float
        Frames within this distance of ``stop_at_s`` belong to neither part, s.
    stepping_percentile, stopped_percentile : float
        Percentiles (0-100) that define the contrast.
    margin : float
        Where the threshold sits between the stepping (0) and stopped (1) levels.
    min_contrast_db : float
        Refuse to tune below this contrast, dB.
    min_part_s : float
        Each part must be at least this long, s.
    f_min_hz : float
        Lowest band centre considered, Hz.
    min_band_hz : float
        Narrowest band considered, Hz. Keep it above the highest step rate you will
        use: the steps sound as a line spectrum at multiples of the step rate, and a
        narrower band tuned at one rate can sit between two harmonics there and on
        top of one at another rate.
    rate_shift_hz : float
        Judge the stepping level of a band as the highest of the band shifted by up to
        this much either way, Hz (0, the default, judges the band as is). ``min_band_hz``
        already keeps a harmonic of any step rate inside every band; a shift is more
        conservative still, but a neighbouring stepping resonance then eats the contrast.
    max_stepping_s, max_stopped_s : float
        Analyse at most this much of the recording before and after the stop, s.
    relative : bool
        Measure the band relative to the broadband level (``f_min_hz`` to 0.9 of the
        Nyquist frequency; default), so that the threshold does not move with the
        microphone gain; ``False`` uses the absolute band level in dBFS.

    Returns
    -------
    Tuning

    Raises
    ------
    TuningError
        If ``stop_at_s`` leaves a part too short, no band separates the two parts by
        ``min_contrast_db``, or the tuned detector does not fire exactly once at the stop.
    """
    if not 0.0 < margin < 1.0:
        raise TuningError(f"margin {margin} must be between 0 and 1 (exclusive)")
    x, sample_rate = _recording(samples, sample_rate, stop_at_s, min_part_s, guard_s)
    frame = int(frame or default_frame(sample_rate))
    hop = int(hop or max(1, frame // 4))
    bands = candidate_bands(sample_rate, frame, f_min_hz, min_band_hz=min_band_hz)
    if not bands:
        raise TuningError(f"no band at least {min_band_hz:g} Hz wide fits below {sample_rate / 2:g} Hz")
    # analyse at most max_stepping_s before the stop and max_stopped_s after it
    first = max(0, int((stop_at_s - max_stepping_s) * sample_rate) // hop * hop)
    last = min(x.size, int((stop_at_s + max_stopped_s) * sample_rate))
    seg = x[first:last]
    t_first = first / sample_rate
    reference = (float(f_min_hz), round(0.9 * sample_rate / 2, 1)) if relative else None
    ref_level = _band_level_matrix(seg, sample_rate, frame, hop, [reference])[:, :1] if reference else 0.0
    hold = max(1, int(math.ceil(hold_s * sample_rate / hop - 1e-9)))
    window = hold + _DEFAULT_MAX_DIPS

    def decided(lv: np.ndarray) -> np.ndarray:
        """The level ``hold`` of every ``window`` consecutive frames reach: what the detector decides on."""
        return np.asarray(rank_filter(lv - ref_level, rank=window - hold, size=(window, 1), mode="nearest"))

    levels = decided(_band_level_matrix(seg, sample_rate, frame, hop, bands))
    starts = t_first + np.arange(levels.shape[0]) * hop / sample_rate
    ends = starts + (frame - 1) / sample_rate
    stepping_rows = ends < stop_at_s - guard_s
    stopped = levels[starts >= stop_at_s + guard_s]
    stop_lo = np.percentile(stopped, stopped_percentile, axis=0)
    # The steps sound as a line spectrum at multiples of the step rate; at another rate
    # the lines fall elsewhere in the band. Judge the stepping level by the loudest of
    # the band and its copies shifted by up to +-rate_shift_hz (half the highest step
    # rate covers every placement of the lines), so the threshold holds at any rate.
    step_hi = np.full(len(bands), -np.inf)
    for shift in np.linspace(-rate_shift_hz, rate_shift_hz, 5) if rate_shift_hz else [0.0]:
        moved = [(max(lo + shift, 0.0), min(hi + shift, sample_rate / 2)) for lo, hi in bands]
        lv = decided(_band_level_matrix(seg, sample_rate, frame, hop, moved))[stepping_rows]
        step_hi = np.maximum(step_hi, np.percentile(lv, stepping_percentile, axis=0))
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
    threshold = float(step_hi[best] + margin * c)
    tuning = Tuning(
        band_hz=band,
        threshold_db=round(threshold, 2),
        sample_rate=sample_rate,
        frame=frame,
        hop=hop,
        hold_s=hold_s,
        hysteresis_db=round(min(6.0, 0.25 * c), 2),
        release_s=release_s,
        onset_lag_s=0.0,
        joint=joint,
        contrast_db=round(c, 2),
        margin_db=round(threshold - float(step_hi[best]), 2),
        stepping_db=round(float(step_hi[best]), 2),
        stopped_db=round(float(stop_lo[best]), 2),
        reference_hz=reference,
    )
    return _verified_band(tuning, x, stop_at_s, guard_s)


def _verified_band(tuning: Tuning, x: FloatArray, stop_at_s: float, guard_s: float) -> Tuning:
    """``tuning`` if its detector fires once, at the stop, with the onset lag and latency it measured there."""
    events = StopDetector(tuning).feed(x)
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
