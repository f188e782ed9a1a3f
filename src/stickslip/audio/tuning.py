"""Tune the end-stop detector from a labelled recording.

:func:`tune` makes a spectral-template tuning (:mod:`.template`; see
:func:`tune` for how). :func:`tune_band` is the band-power tuner of tuning files
version 1, kept for comparison and old workflows; what follows describes it.

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
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import median_filter, percentile_filter, rank_filter

from .detector import StopDetector, Tuning, _band_bins, default_frame, frame_power_spectra
from .template import CHUNK, QUANTILE, fit_departure, subband_edges, subband_levels_db

FloatArray = NDArray[np.float64]
#: share of the sub-bands a frame's fit may drop (those with the most unexplained excess)
TRIM_FRACTION = 0.1
#: lowest threshold on the stop-likeness (0 stepping, 1 the tuned stop)
MIN_THRESHOLD = 0.4
#: default hold: how long a stop must last before the detector fires, s
HOLD_S = 0.016

#: drop thresholds: this many times the worst drop of the stepping part ...
DROP_MARGIN = 1.6
#: ... and at least these (broad, local), spreads
DROP_FLOOR = (0.6, 1.5)

_DEFAULT_MAX_DIPS: int = Tuning(band_hz=(1000.0, 2000.0), threshold_db=0.0).max_dips

__all__ = ["TuningError", "candidate_bands", "tune", "tune_band"]


class TuningError(ValueError):
    """The recording cannot give a usable tuning (the message says why)."""


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


# --------------------------------------------------------------------------------------
# the spectral-template tuner


@dataclass(frozen=True)
class _Candidate:
    name: str
    bands: tuple[int, ...]  # sub-band indices (contiguous)
    margin: float
    threshold: float
    residual_max: float
    trim: int
    step_hi: float
    stop_lo: float
    contrast_db: float


def stepping_band(
    x: FloatArray,
    sample_rate: int,
    frame: int,
    hop: int,
    f_min_hz: float = 300.0,
    f_max_frac: float = 0.42,
    range_db: float = 25.0,
) -> tuple[float, float]:
    """Where the stepping sound is: the span of frequencies within ``range_db`` of its spectral peak, Hz.

    Measured on the mean power spectrum of ``x`` (stepping only), smoothed over 1/6
    octave; limited to ``f_min_hz`` .. ``f_max_frac`` of the sample rate (0.42 fs keeps
    clear of the anti-aliasing filter's roll-off).
    """
    p = frame_power_spectra(x[: min(x.size, 20 * sample_rate)], frame, hop).mean(axis=0)
    f = np.fft.rfftfreq(frame, 1 / sample_rate)
    c = np.concatenate(([0.0], np.cumsum(p)))
    lo_i = np.searchsorted(f, f * 2 ** (-1 / 12))
    hi_i = np.minimum(np.searchsorted(f, f * 2 ** (1 / 12), side="right"), f.size)
    smooth = (c[hi_i] - c[lo_i]) / np.maximum(hi_i - lo_i, 1)
    ok = (f >= f_min_hz) & (f <= f_max_frac * sample_rate)
    db = 10 * np.log10(smooth + 1e-30)
    peak = float(db[ok].max())
    inside = np.flatnonzero(ok & (db >= peak - range_db))
    lo, hi = float(f[inside[0]]), float(f[inside[-1]])
    # at least two octaves, within the allowed span
    while hi / max(lo, 1.0) < 4.0 and (lo > f_min_hz or hi < f_max_frac * sample_rate):
        lo, hi = max(f_min_hz, lo / 1.1), min(f_max_frac * sample_rate, hi * 1.1)
    return max(lo, f_min_hz), min(hi, f_max_frac * sample_rate)


def _decided(a: FloatArray, rho: FloatArray, rmax: float, hold: int, window: int) -> FloatArray:
    """What the detector decides on: the ``hold``-th largest usable stop-likeness in each window of frames."""
    use = np.where(rho <= rmax, a, -10.0)
    if use.size < window:
        return np.full_like(use, -10.0)
    return np.asarray(rank_filter(use, rank=window - hold, size=window, origin=(window - 1) // 2), dtype=np.float64)


def _spans(mask: NDArray[np.bool_], t: FloatArray, gap_s: float = 0.05) -> list[tuple[float, float]]:
    """Merge the times where ``mask`` holds into (start, end) spans, s."""
    out: list[tuple[float, float]] = []
    for ti in t[mask]:
        if out and ti - out[-1][1] <= gap_s:
            out[-1] = (out[-1][0], float(ti))
        else:
            out.append((float(ti), float(ti)))
    return out


def _fmt_spans(spans: list[tuple[float, float]], limit: int = 6) -> str:
    s = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in spans[:limit])
    return s + (f" and {len(spans) - limit} more" if len(spans) > limit else "")


def _change_point(a: FloatArray, t_end: FloatArray, label_s: float, search_s: float, hold: int) -> float | None:
    """First time near the label from which the stop-likeness stays above 0.5 for 60 ms, s."""
    above = a >= 0.5
    n_keep = max(hold, 1)
    ok = np.flatnonzero((t_end >= label_s - search_s) & (t_end <= label_s + search_s))
    if ok.size == 0:
        return None
    # run length of 'above' from each frame on
    run = np.zeros(a.size + 1, dtype=np.int64)
    for i in range(a.size - 1, -1, -1):
        run[i] = run[i + 1] + 1 if above[i] else 0
    need = max(n_keep, int(round(0.06 / max(float(np.median(np.diff(t_end))), 1e-9))))
    starts_run = np.ones(a.size, dtype=bool)
    starts_run[1:] = ~above[:-1]  # a genuine rise, not the middle of a change that began earlier
    hits = ok[(run[ok] >= need) & starts_run[ok]]
    if hits.size == 0:
        return None
    i = int(hits[0])
    # interpolate where a crossed 0.5 between frame i-1 and i
    if i > 0 and a[i] > a[i - 1]:
        frac = (0.5 - a[i - 1]) / (a[i] - a[i - 1])
        return float(t_end[i - 1] + np.clip(frac, 0, 1) * (t_end[i] - t_end[i - 1]))
    return float(t_end[i])


def tune(
    samples: NDArray[np.floating] | FloatArray,
    sample_rate: int,
    stop_at_s: float,
    joint: int | None = None,
    *,
    frame: int | None = None,
    hop: int | None = None,
    hold_s: float = HOLD_S,
    release_s: float = 0.25,
    guard_s: float = 0.03,
    min_part_s: float = 0.25,
    f_min_hz: float = 300.0,
    max_stepping_s: float = 20.0,
    max_stopped_s: float = 10.0,
    per_octave: float = 3.0,
    label_tolerance_s: float = 0.02,
    search_s: float = 0.5,
    self_check: bool = True,
    seed: int = 0,
    min_band_hz: float | None = None,
) -> Tuning:
    """Learn the stepping sound's spectral template and the end stop's departure from it.

    Parameters
    ----------
    samples : numpy.ndarray
        Mono recording (float, full scale 1.0), or (samples, channels), mixed to mono.
        It must start with stepping (the detector learns the template from the first
        0.15 s), reach the stop at ``stop_at_s`` and keep stepping against it.
    sample_rate : int
        Its sample rate, Hz.
    stop_at_s : float
        The labelled time the joint reached the stop, s from the start.
    joint : int, optional
        Joint the recording belongs to (stored in the tuning).
    frame, hop : int, optional
        Frame length and hop, samples (default about 10.7 ms and a quarter of it).
    hold_s : float
        Time a stop must last before the detector fires, s.
    release_s : float
        Time the stop-likeness must stay low before the detector re-arms, s.
    guard_s : float
        Frames this close to the stop belong to neither part, s.
    min_part_s : float
        Each part (stepping, stop) must be at least this long, s.
    f_min_hz : float
        Lowest frequency of the template, Hz (below it: hum, footsteps, doors).
    max_stepping_s, max_stopped_s : float
        Analyse at most this much before and after the stop, s.
    per_octave : float
        Sub-bands per octave of the template.
    label_tolerance_s : float
        Warn when the sound changes further than this from ``stop_at_s``, s.
    search_s : float
        Look for the change this far either side of ``stop_at_s``, s; refuse when
        nothing changes there.
    self_check : bool
        Run the tuned detector on the recording with interference injected and store
        the expected false alarms per hour and latency in ``Tuning.checks``.
    seed : int
        Seed of the injected interference.
    min_band_hz : float, optional
        Accepted for the version-1 command line; the template spans the stepping band.

    Returns
    -------
    Tuning
        ``method == "template"``; ``checks`` holds the self-check and any warnings
        (``checks["warnings"]``, e.g. a stop label that disagrees with the sound).

    Raises
    ------
    TuningError
        The recording is too short, the stop label is outside it or nothing changes
        near it, the two parts sound alike, or no template both fires once at the
        stop and stays quiet while stepping (the message names the time spans that
        spoil it).

    Notes
    -----
    1. The template spans the stepping sound's measured band (:func:`stepping_band`,
       never above 0.42 fs), cut into ``per_octave`` sub-bands per octave.
    2. Stepping is summarised per sub-band by its median level and spread (1.4826
       MAD); the stop's *signature* is the median level of the stop part minus that of
       the stepping part, per sub-band, in dB.
    3. Where the sound actually changes is found from the signature (the first time
       near the label after which the stop-likeness stays above 0.5 for 60 ms); a
       disagreement with the label beyond ``label_tolerance_s`` is a warning, and the
       parts and the onset lag are then taken from the sound, not the label.
    4. Candidates (all sub-bands, and 1- and 2-octave sub-ranges around where the stop
       departs most) are scored on their *worst* frames: the largest stop-likeness the
       detector would decide on anywhere in the stepping part (knocks and speech
       included) against the stop part's 5th percentile. The threshold goes half-way.
    5. Candidates are verified best first by running the detector over the
       recording: it must fire once, at the stop. The first that passes wins (among
       the passing ones, the self-check with injected interference breaks ties).
    """
    x, sample_rate = _recording(samples, sample_rate, stop_at_s, min_part_s, guard_s)
    from .guard import block_problem

    problem = block_problem(x[: int(stop_at_s * sample_rate)])
    if problem is not None:
        raise TuningError(f"the stepping part of the recording is {problem}: nothing to learn from")
    frame = int(frame or default_frame(sample_rate))
    hop = int(hop or max(1, frame // 4))
    hold = max(1, int(math.ceil(hold_s * sample_rate / hop - 1e-9)))
    window = hold + _DEFAULT_MAX_DIPS
    warnings: list[str] = []

    first = max(0, int((stop_at_s - max_stepping_s) * sample_rate) // hop * hop)
    last = min(x.size, int((stop_at_s + max_stopped_s) * sample_rate))
    seg = x[first:last]
    t_first = first / sample_rate
    f_lo, f_hi = stepping_band(x[first : int((stop_at_s - 0.15) * sample_rate)], sample_rate, frame, hop, f_min_hz)
    edges = subband_edges(f_lo, f_hi, sample_rate, frame, per_octave)
    V = subband_levels_db(seg, sample_rate, frame, hop, edges)
    starts = t_first + np.arange(V.shape[0]) * hop / sample_rate
    ends = starts + (frame - 1) / sample_rate

    # 1. where the sound changes (from a provisional signature of frames well away from the label)
    change = _sound_change(V, starts, ends, stop_at_s, guard_s, edges, window, hold, search_s, frame, sample_rate)
    stop_s = stop_at_s
    if abs(change - stop_at_s) > label_tolerance_s:
        warnings.append(
            f"the labelled stop ({stop_at_s:.3f} s) disagrees with the sound, which changes at "
            f"{change:.3f} s ({1e3 * (change - stop_at_s):+.0f} ms); tuned on the sound's change"
        )
        stop_s = change
    g = max(guard_s, abs(change - stop_at_s) + guard_s) if stop_s == stop_at_s else guard_s

    stepping = ends < stop_s - g
    stopped = starts >= stop_s + g
    if stepping.sum() < 2 * CHUNK or stopped.sum() < window:
        raise TuningError(f"too little stepping before or stop after {stop_s:.3f} s to tune on")
    sigma = np.maximum(1.4826 * np.median(np.abs(V[stepping] - np.median(V[stepping], axis=0)), axis=0), 1.0)
    # departures as the detector sees them: from a template that follows the stepping sound
    # (a causal running low quantile over tau_s), frozen at the stop
    base = _running_template(V, stepping, hop / sample_rate)
    D = V - base
    delta = np.median(D[stopped], axis=0)
    mu_step = base[int(np.flatnonzero(stepping)[-1])]

    # 2. candidates, scored on their worst stepping frames
    candidates = _candidates(D, sigma, delta, stepping, stopped, hold, window)
    if not candidates:
        raise TuningError("no sub-band of the stepping sound changes at the stop")
    # the whole template first unless a sub-range separates clearly better: more sub-bands, more to
    # tell a stop from a voice or a second instrument by
    candidates.sort(key=lambda c: (c.name != "all sub-bands" or c.margin < 0.3, -c.margin))

    # 3. verify best first; walk down the ranking
    passing: list[tuple[Tuning, float, float]] = []
    failures: list[str] = []
    for cand in candidates[:8]:
        if cand.margin <= 0.05:
            break
        tu = _make_tuning(cand, edges, delta, sigma, sample_rate, frame, hop, hold_s, release_s, joint, mu_step)
        b0, b1 = cand.bands[0], cand.bands[-1] + 1
        tu = replace(tu, drop_threshold=_drop_threshold(D[:, b0:b1], sigma[b0:b1], stepping, hold, window))
        events = StopDetector(tu).feed(x)
        near = [e for e in events if stop_s - g <= e.detected_at_s <= stop_s + 0.2]
        if len(events) == 1 and len(near) == 1:
            ev = near[0]
            passing.append((tu, ev.onset_s - stop_s, ev.detected_at_s - stop_s))
            if len(passing) >= 3:
                break
        else:
            where = ", ".join(f"{e.detected_at_s:.3f} s" for e in events[:6]) or "never"
            failures.append(f"{cand.name} fired {where}")
    if not passing:
        raise _no_template(candidates[0], D, delta, sigma, hold, window, stepping, ends, failures)
    # 4. self-check with interference; the quietest passing candidate wins
    return _pick(passing, x, sample_rate, frame, stop_s, g, seed, self_check, warnings, stop_at_s, change)


def _recording(
    samples: NDArray[np.floating] | FloatArray, sample_rate: int, stop_at_s: float, min_part_s: float, guard_s: float
) -> tuple[FloatArray, int]:
    """A labelled recording as mono float64 and its rate, or :class:`TuningError` saying what is wrong with it."""
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim == 2:
        x = x.mean(axis=1)
    if x.ndim != 1:
        raise TuningError(f"expected mono samples, got an array of shape {np.shape(samples)}")
    sample_rate = int(sample_rate)
    if not 8_000 <= sample_rate <= 192_000:
        raise TuningError(f"sample rate {sample_rate} Hz is outside 8000-192000 Hz")
    if not np.all(np.isfinite(x)):
        raise TuningError("the recording holds non-finite samples (NaN or infinity)")
    duration = x.size / sample_rate
    lo_ok, hi_ok = min_part_s + guard_s, duration - min_part_s - guard_s
    if not (math.isfinite(stop_at_s) and lo_ok <= stop_at_s <= hi_ok):
        if hi_ok < lo_ok:
            raise TuningError(
                f"the recording is {duration:.3f} s long; tuning needs at least "
                f"{2 * (min_part_s + guard_s):.2f} s ({min_part_s} s of stepping and of stop)"
            )
        raise TuningError(
            f"stop-at {stop_at_s:g} s must lie within {lo_ok:.3f}..{hi_ok:.3f} s of this "
            f"{duration:.3f} s recording (at least {min_part_s} s of stepping before, "
            "and of the stop after)"
        )
    return x, sample_rate


def _sound_change(
    V: FloatArray,
    starts: FloatArray,
    ends: FloatArray,
    stop_at_s: float,
    guard_s: float,
    edges: list[float],
    window: int,
    hold: int,
    search_s: float,
    frame: int,
    sample_rate: int,
) -> float:
    """Where the sound actually changes near the label ``stop_at_s`` (s), from a provisional signature.

    Raises :class:`TuningError` when the two parts sound alike, or nothing changes within
    ``search_s`` of the label (naming where the sound does change, if it does).
    """
    far = 0.15
    step_far = ends < stop_at_s - far
    stop_far = starts >= stop_at_s + far
    if step_far.sum() < 8 or stop_far.sum() < 8:
        step_far, stop_far = ends < stop_at_s - guard_s, starts >= stop_at_s + guard_s
    mu_step = np.percentile(V[step_far], 100 * QUANTILE, axis=0)  # what the detector's template tracks
    sigma = np.maximum(1.4826 * np.median(np.abs(V[step_far] - np.median(V[step_far], axis=0)), axis=0), 1.0)
    delta0 = np.median(V[stop_far], axis=0) - mu_step
    strength = float(np.sqrt(np.mean((delta0 / sigma) ** 2)))
    if strength < 1.0:
        k = int(np.argmax(np.abs(delta0)))
        raise TuningError(
            f"the stepping and stopped parts sound alike: nothing changes near the labelled stop at {stop_at_s:g} s "
            f"(no sub-band of "
            f"{edges[0]:.0f}-{edges[-1]:.0f} Hz changes by more than {abs(delta0[k]):.1f} dB, "
            f"at {edges[k]:.0f}-{edges[k + 1]:.0f} Hz); check --stop-at and that the recording reaches the end stop"
        )
    trim_all = (len(edges) - 1) // 5
    a0, _ = fit_departure(V - mu_step, delta0, sigma, trim_all)
    a0s = np.asarray(median_filter(a0, size=window), dtype=np.float64)
    change = _change_point(a0s, ends, stop_at_s, search_s, hold)
    if change is None:
        elsewhere = _change_point(a0s, ends, stop_at_s, float(ends[-1] - ends[0]), hold)
        where = (
            f"; the sound changes at {elsewhere - 0.5 * frame / sample_rate:.3f} s"
            if elsewhere is not None and abs(elsewhere - stop_at_s) > search_s
            else ""
        )
        raise TuningError(
            f"nothing changes near the labelled stop at {stop_at_s:g} s (searched +-{search_s:g} s){where}: "
            "check --stop-at (seconds from the start of the recording) and that the joint reached its end stop"
        )
    # the change point is found on frames that end after it; its time is the frame's end minus the
    # part of the frame the stop must fill to lift a to 0.5: about half a frame
    change -= 0.5 * frame / sample_rate
    return change


def _no_template(
    best: _Candidate,
    D: FloatArray,
    delta: FloatArray,
    sigma: FloatArray,
    hold: int,
    window: int,
    stepping: NDArray[np.bool_],
    ends: FloatArray,
    failures: list[str],
) -> TuningError:
    """The refusal when no candidate verified: which time spans of the stepping sound like the stop."""
    sub = list(best.bands)
    a, rho = fit_departure(D[:, sub], delta[sub], sigma[sub], best.trim)
    dec = _decided(a, rho, best.residual_max, hold, window)
    bad = stepping & (dec >= min(best.threshold, 0.5))
    spans = _spans(bad, ends)
    hint = (
        f"the stepping part sounds like the stop at {_fmt_spans(spans)}"
        if spans
        else "the stop does not stay distinct long enough"
    )
    return TuningError(
        f"no template both stays quiet while stepping and fires once at the stop ({'; '.join(failures[:3])}); "
        f"{hint}: cut those spans out of the recording or record again"
    )


def _pick(
    passing: list[tuple[Tuning, float, float]],
    x: FloatArray,
    sample_rate: int,
    frame: int,
    stop_s: float,
    g: float,
    seed: int,
    self_check: bool,
    warnings: list[str],
    stop_at_s: float,
    change: float,
) -> Tuning:
    """Of the verified candidates, the first whose self-check with interference does not clearly fail.

    Its onset lag and latency are the medians over the clean and the injected runs; the
    self-check, the warnings and both stop times go into ``Tuning.checks``.
    """
    results: list[tuple[int, int, Tuning, float, float, dict[str, Any]]] = []
    for tu, lag, lat in passing:
        checks: dict[str, Any] = _self_check(tu, x, sample_rate, stop_s, g, seed) if self_check else {}
        # the ranking stands unless the self-check fails clearly (more than one false alarm, or a stop missed)
        failed = int(checks.get("false_alarms", 0) > 1 or checks.get("stops_found") != checks.get("stops"))
        results.append((failed, len(results), tu, lag, lat, checks))
        if not failed:
            break
    results.sort(key=lambda r: (r[0], r[1]))
    _, _, tu, lag, lat, checks = results[0]
    checks = dict(checks)
    # the onset lag and latency from every run that found the stop (one recording's crossing can
    # be nudged by a syllable or a knock; the median of the clean and the injected runs is not)
    lag = float(np.median([lag, *checks.pop("onset_lags_s", [])]))
    lat = float(np.median([lat, *checks.pop("latencies_s", [])]))
    # frames end after the samples they hold: the crossing cannot come before the onset, nor later than a
    # frame after it (a negative lag means something in the recording rose before the stop did)
    lag = float(np.clip(lag, 0.0, frame / sample_rate))
    checks["warnings"] = warnings
    checks["stop_at_label_s"] = float(stop_at_s)
    checks["stop_at_sound_s"] = round(float(change), 4)
    if self_check and checks.get("false_alarms", 0):
        warnings.append(
            f"with interference injected the detector gave {checks['false_alarms']} false alarms in "
            f"{checks['checked_s']:.0f} s (about {checks['false_alarms_per_hour']:.0f} per hour)"
        )
    return replace(tu, onset_lag_s=round(lag, 6), latency_measured_s=round(lat, 6), checks=checks)


def _drop_threshold(
    D: FloatArray, sigma: FloatArray, stepping: NDArray[np.bool_], hold: int, window: int
) -> tuple[float, float]:
    """Broad and local drop thresholds (spreads): well above the worst the stepping part reaches.

    The stepping part's drops (:class:`~stickslip.audio.template.DropMeter`, decided as the
    detector decides: ``hold`` of ``window`` frames) at their worst, times
    :data:`DROP_MARGIN`, and at least :data:`DROP_FLOOR`.
    """
    from .template import DropMeter

    z = np.clip(D, -40.0, 40.0) / sigma
    broad, local = DropMeter.drops(DropMeter(z.shape[1])(z))
    out = []
    for s, floor in zip((broad, local), DROP_FLOOR, strict=True):
        worst = float(_decided(s, np.zeros_like(s), 1.0, hold, window)[stepping].max())
        out.append(round(max(DROP_MARGIN * worst, floor), 3))
    return out[0], out[1]


def _running_template(V: FloatArray, stepping: NDArray[np.bool_], hop_s: float, tau_s: float = 0.5) -> FloatArray:
    """Per frame, the low quantile of the stepping levels over the preceding ``tau_s``; frozen after stepping ends."""
    idx = np.flatnonzero(stepping)
    last = int(idx[-1]) + 1
    W = max(CHUNK, int(round(tau_s / hop_s)))
    head = V[:last]
    pad = np.concatenate((np.repeat(np.percentile(head[:W], 100 * QUANTILE, axis=0)[None, :], W, axis=0), head))
    run = percentile_filter(pad, 100 * QUANTILE, size=(W, 1), origin=((W - 1) // 2, 0))[W:]
    out = np.empty_like(V)
    out[:last] = run
    out[last:] = run[-1]
    return np.asarray(out, dtype=np.float64)


def _candidates(
    D: FloatArray,
    sigma: FloatArray,
    delta: FloatArray,
    stepping: NDArray[np.bool_],
    stopped: NDArray[np.bool_],
    hold: int,
    window: int,
) -> list[_Candidate]:
    nb = delta.size
    strength = np.abs(delta) / sigma
    sets: dict[tuple[int, ...], str] = {tuple(range(nb)): "all sub-bands"}
    for k in np.argsort(-strength)[:3].tolist():
        for half in (1, 3):
            lo, hi = max(0, k - half), min(nb, k + half + 1)
            if hi - lo >= 2:
                sets.setdefault(tuple(range(lo, hi)), f"sub-bands {lo}-{hi - 1}")
    out = []
    for bands, name in sets.items():
        sub = list(bands)
        if float(np.sqrt(np.mean((delta[sub] / sigma[sub]) ** 2))) < 1.0:
            continue
        trim = int(len(sub) * TRIM_FRACTION)
        a, rho = fit_departure(D[:, sub], delta[sub], sigma[sub], trim)
        rho_stop = rho[stopped]
        rmax = float(max(4.0, 1.5 * np.percentile(rho_stop, 95), 2.0 * np.percentile(rho[stepping], 50)))
        dec = _decided(a, rho, rmax, hold, window)
        step_hi = float(dec[stepping].max())
        stop_lo = float(np.percentile(dec[stopped], 5))
        margin = stop_lo - max(step_hi, 0.0)
        thr = float(np.clip(max(step_hi, 0.0) + 0.4 * margin, MIN_THRESHOLD, 0.7))
        if not max(step_hi, 0.0) < thr < stop_lo:
            thr = max(step_hi, 0.0) + 0.4 * margin
        out.append(
            _Candidate(name, bands, margin, thr, rmax, trim, step_hi, stop_lo, float(np.sqrt(np.sum(delta[sub] ** 2))))
        )
    return out


def _make_tuning(
    c: _Candidate,
    edges: list[float],
    delta: FloatArray,
    sigma: FloatArray,
    sample_rate: int,
    frame: int,
    hop: int,
    hold_s: float,
    release_s: float,
    joint: int | None,
    stepping_levels: FloatArray,
) -> Tuning:
    b0, b1 = c.bands[0], c.bands[-1] + 1
    sub_edges = tuple(edges[b0 : b1 + 1])
    return Tuning(
        band_hz=(sub_edges[0], sub_edges[-1]),
        threshold_db=round(c.threshold, 4),
        sample_rate=sample_rate,
        frame=frame,
        hop=hop,
        hold_s=hold_s,
        hysteresis_db=round(0.5 * c.threshold, 4),
        release_s=release_s,
        onset_lag_s=0.0,
        joint=joint,
        contrast_db=round(c.contrast_db, 2),
        margin_db=round(c.margin, 4),
        stepping_db=round(c.step_hi, 4),
        stopped_db=round(c.stop_lo, 4),
        method="template",
        edges_hz=sub_edges,
        signature_db=tuple(round(float(v), 3) for v in delta[b0:b1]),
        spread_db=tuple(round(float(v), 3) for v in sigma[b0:b1]),
        residual_max=round(c.residual_max, 3),
        trim=c.trim,
        stepping_levels_db=tuple(round(float(v), 3) for v in stepping_levels[b0:b1]),
    )


def _self_check(
    tu: Tuning, x: FloatArray, sample_rate: int, stop_s: float, guard_s: float, seed: int
) -> dict[str, Any]:
    """Run ``tu`` on the recording with interference injected; count false alarms and stops found."""
    from . import inject

    rng = np.random.default_rng(seed)
    n_stop = int(stop_s * sample_rate)
    lo, hi = tu.band_hz
    from scipy.signal import butter, sosfilt

    sos = butter(4, [lo, min(hi, 0.49 * sample_rate)], btype="band", fs=sample_rate, output="sos")
    rms = float(np.sqrt(np.mean(sosfilt(sos, x[:n_stop]) ** 2)))
    n = x.size
    variants = {
        "knocks": x + inject.knocks(n, sample_rate, rms, rng),
        "babble": x + inject.babble(n, sample_rate, rms, rng),
        "second click train": x + inject.click_train(n, sample_rate, rms, rng),
        "gain +20 dB": x * 10.0,
        "gain -20 dB": x * 0.1,
    }
    false_alarms = 0
    found = 0
    lat: list[float] = []
    lags: list[float] = []
    per: dict[str, int] = {}
    for name, y in variants.items():
        events = StopDetector(tu).feed(y)
        hits = [e for e in events if stop_s - guard_s <= e.detected_at_s <= stop_s + 0.2]
        fa = len(events) - min(1, len(hits))
        per[name] = fa
        false_alarms += fa
        if hits:
            found += 1
            lat.append(hits[0].detected_at_s - stop_s)
            lags.append(hits[0].onset_s - stop_s)
    checked_s = len(variants) * stop_s
    return {
        "false_alarms": false_alarms,
        "checked_s": round(checked_s, 3),
        "false_alarms_per_hour": round(false_alarms / checked_s * 3600.0, 1),
        "false_alarms_by_interference": per,
        "stops": len(variants),
        "stops_found": found,
        "latency_median_s": round(float(np.median(lat)), 4) if lat else None,
        "onset_lags_s": [round(v, 5) for v in lags],
        "latencies_s": [round(v, 5) for v in lat],
    }
