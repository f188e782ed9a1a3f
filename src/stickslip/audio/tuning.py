"""Tune the end-stop detector from a labelled recording: the spectral template (:func:`tune`).

The parts live by concept: :mod:`.labels` checks a labelled recording and finds where
its sound changes; :mod:`.verification` scores candidates, runs them over the recording
and checks them with interference injected; :mod:`.band_tuning` is the band-power tuner
of tuning files version 1 (:func:`tune_band`, kept for comparison and old workflows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import percentile_filter

from .band_tuning import _DEFAULT_MAX_DIPS, candidate_bands, tune_band
from .detector import Tuning, frame_power_spectra
from .labels import TuningError, _recording, _sound_change
from .rate_signature import fine_range_hz, fine_segment, fine_spectrum_db
from .stepclock import step_rate_hz
from .template import (
    CHUNK,
    CONTINUUM_FRAME,
    QUANTILE,
    continuum_levels_db,
    fit_departure,
    subband_edges,
    subband_levels_db,
)
from .tuningfile import default_frame
from .verification import _Candidate, _decided, _no_template, _one_stop, _pick, self_check_failed

FloatArray = NDArray[np.float64]
#: share of the sub-bands a frame's fit may drop (those with the most unexplained excess)
TRIM_FRACTION = 0.1
#: lowest threshold on the stop-likeness (0 stepping, 1 the tuned stop)
MIN_THRESHOLD = 0.4
#: default hold: how long a stop must last before the detector fires, s
HOLD_S = 0.016
#: candidates verified before the self-check picks one (more only while none checks the stop's drops)
VERIFIED = 3

#: sub-bands per octave of the template when no resolution is asked for
DEFAULT_PER_OCTAVE = 3.0
#: finer resolutions tried when the default is refused or its margin is under :data:`FINER_BELOW` (a stop that moves
#: its modes 4-12 % moves power between 1/12-octave sub-bands, within one 1/3-octave sub-band: docs/audio.md,
#: "A stop that only shifts the spectrum")
FINER_PER_OCTAVE = (6.0, 12.0)
#: a default template that separates the stop by at least this (stop-likeness) is kept without trying finer ones
FINER_BELOW = 0.8
#: a finer template replaces a coarser one only with a margin this much larger (near-ties keep fewer, wider sub-bands:
#: steadier levels, and the template every round before this one measured; at 0.1 the battery's "speech in training"
#: took 6 per octave for 0.37 against 0.25 and then missed its stop at an 8 % faster rate) ...
FINER_GAIN = 0.2
#: ... and at least this margin (the fifth generator's arm 4, shifted stop, verifies at 12 per octave with 0.21 on three
#: sub-bands and then fired seconds early in 4 of 12 recordings: a refusal is safer); it must also span at least as
#: many sub-bands (finer detail over the stop's band, not a narrower band: the fifth generator's arm 2, damped stop,
#: separated by 0.55 on 2 sub-bands at 6 per octave against 0.11 on 3, and a hiss before its stop then fired it)
FINER_MIN_MARGIN = 0.3
#: when every resolution is refused, the template spans where the stepping sound is within this much of its peak, dB,
#: not :func:`stepping_band`'s 25 dB: a stop that moves a mode at the band's edge out of it departs beyond it (the
#: fifth generator's arm 4: its 4.19 kHz mode moves to 4.50 kHz, past the 4.22 kHz edge); None: never
WIDE_RANGE_DB: float | None = 45.0

#: the fine spectrum of stepping skips the recording's first this long, s (where the stepping part is long enough:
#: a traverse's first steps may ring in differently), and that of the stop its first this long after the stop, s
FINE_SKIP_S = 0.3
FINE_SKIP_STOP_S = 0.1

#: drop thresholds: this many times the worst drop of the stepping part ...
DROP_MARGIN = 1.6
#: ... and at least the stepping part's median plus this many robust standard deviations ...
DROP_TAIL = 6.0
#: ... and at least these (broad, local), spreads
DROP_FLOOR = (1.0, 2.0)

__all__ = ["TuningError", "candidate_bands", "tune", "tune_band"]


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
    per_octave: float | None = None,
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
    per_octave : float, optional
        Sub-bands per octave of the template. None (the default) chooses: 3, and the
        finer :data:`FINER_PER_OCTAVE` when 3 is refused or separates the stop weakly
        (see Notes, 7); the choice is stored in ``Tuning.per_octave``.
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
       recording: it must fire once, at the stop. Three that pass are enough, unless
       none of them checks what the stop lowers (its drops are too small against the
       stepping's spread): then verification walks on to the first that does.
    6. Of the passing ones, the first wins unless the self-check with injected
       interference fails clearly, or a sound that adds what the stop adds (and lowers
       nothing) fires it at more levels than another
       (:func:`~stickslip.audio.verification._rise_mimicry`); a chosen template that
       such a sound fires is named in a warning.
    7. Resolution (``per_octave=None``): steps 1-6 run at 3 sub-bands per octave. When
       that is refused, or its margin is under :data:`FINER_BELOW`, they run again at
       each of :data:`FINER_PER_OCTAVE`; a finer template replaces the coarser one only
       when its self-check does not fail, it separates the stop by at least
       :data:`FINER_MIN_MARGIN` and by :data:`FINER_GAIN` more than the coarser one, on
       at least as many sub-bands.
       A stop that moves its modes a few per cent (a contact that pins the arm) moves
       power between neighbouring sub-bands 1/12 octave wide, inside one 1/3 octave
       wide (docs/audio.md, "A stop that only shifts the spectrum"). Every resolution
       tried is listed in ``checks["resolutions"]``.
    8. The chosen tuning stores the step rate heard, the continuum between its lines
       per sub-band, and the fine continuum spectra of stepping and of the stop
       (``fine_*``, :func:`~stickslip.audio.rate_signature.fine_spectrum_db`): the
       detector predicts the stop's signature from them at another step rate
       (docs/audio.md, "Round 11a").
    """
    x, sample_rate = _recording(samples, sample_rate, stop_at_s, min_part_s, guard_s)
    from .guard import block_problem

    problem = block_problem(x[: int(stop_at_s * sample_rate)])
    if problem is not None:
        raise TuningError(f"the stepping part of the recording is {problem}: nothing to learn from")
    frame = int(frame or default_frame(sample_rate))
    hop = int(hop or max(1, frame // 4))
    args = _Args(
        sample_rate, stop_at_s, joint, frame, hop, hold_s, release_s, guard_s, f_min_hz, max_stepping_s,
        max_stopped_s, label_tolerance_s, search_s, self_check, seed,
    )  # fmt: skip
    if per_octave is not None:
        return replace(_tune_at(x, args, float(per_octave)), per_octave=float(per_octave))
    return _tune_resolutions(x, args)


@dataclass(frozen=True)
class _Args:
    """:func:`tune`'s settings, as one resolution's tuning uses them."""

    sample_rate: int
    stop_at_s: float
    joint: int | None
    frame: int
    hop: int
    hold_s: float
    release_s: float
    guard_s: float
    f_min_hz: float
    max_stepping_s: float
    max_stopped_s: float
    label_tolerance_s: float
    search_s: float
    self_check: bool
    seed: int
    range_db: float = 25.0


def _tune_resolutions(x: FloatArray, args: _Args) -> Tuning:
    """Tune at :data:`DEFAULT_PER_OCTAVE`, and at :data:`FINER_PER_OCTAVE` where that is refused or weak (Notes, 7)."""
    tried: list[dict[str, Any]] = []
    best: Tuning | None = None
    first_error: TuningError | None = None
    for po in (DEFAULT_PER_OCTAVE, *FINER_PER_OCTAVE):
        if best is not None and po != DEFAULT_PER_OCTAVE and (best.margin_db or 0.0) >= FINER_BELOW:
            break
        try:
            tu = replace(_tune_at(x, args, po), per_octave=po)
        except TuningError as e:
            first_error = first_error or e
            tried.append({"per_octave": po, "refused": str(e)[:200]})
            continue
        failed, nb = _self_check_failed(tu), len(tu.signature_db or ())
        tried.append({"per_octave": po, "sub_bands": nb, "margin": tu.margin_db, "self_check_failed": failed})
        if best is None:
            if po == DEFAULT_PER_OCTAVE or (not failed and (tu.margin_db or 0.0) >= FINER_MIN_MARGIN):
                best = tu
        elif (
            not failed
            and (tu.margin_db or 0.0) >= max(FINER_MIN_MARGIN, (best.margin_db or 0.0) + FINER_GAIN)
            and nb >= len(best.signature_db or ())
        ):
            best = tu
    if best is None and WIDE_RANGE_DB is not None:
        # every resolution refused: a stop that moves the modes at the band's edge out of it is heard beyond it
        wide = replace(args, range_db=WIDE_RANGE_DB)
        try:
            tu = replace(_tune_at(x, wide, DEFAULT_PER_OCTAVE), per_octave=DEFAULT_PER_OCTAVE)
        except TuningError as e:
            tried.append({"per_octave": DEFAULT_PER_OCTAVE, "range_db": WIDE_RANGE_DB, "refused": str(e)[:200]})
        else:
            failed = _self_check_failed(tu)
            tried.append(
                {"per_octave": DEFAULT_PER_OCTAVE, "range_db": WIDE_RANGE_DB, "sub_bands": len(tu.signature_db or ()),
                 "margin": tu.margin_db, "self_check_failed": failed}
            )  # fmt: skip
            if not failed and (tu.margin_db or 0.0) >= FINER_MIN_MARGIN:
                best = tu
    if best is None:
        assert first_error is not None
        raise first_error
    checks = dict(best.checks or {})
    checks["resolutions"] = tried
    return replace(best, checks=checks)


def _self_check_failed(tu: Tuning) -> bool:
    """The tuning's self-check failed clearly, as :func:`~stickslip.audio.verification._pick` judges it."""
    return self_check_failed(tu.checks or {})


def _tune_at(x: FloatArray, args: _Args, per_octave: float) -> Tuning:
    """Steps 1-6 of :func:`tune` at ``per_octave`` sub-bands per octave."""
    sample_rate, stop_at_s, frame, hop = args.sample_rate, args.stop_at_s, args.frame, args.hop
    guard_s, hold_s, release_s, joint, seed = args.guard_s, args.hold_s, args.release_s, args.joint, args.seed
    max_stepping_s, max_stopped_s, f_min_hz = args.max_stepping_s, args.max_stopped_s, args.f_min_hz
    label_tolerance_s, search_s, self_check = args.label_tolerance_s, args.search_s, args.self_check
    hold = max(1, int(math.ceil(hold_s * sample_rate / hop - 1e-9)))
    window = hold + _DEFAULT_MAX_DIPS
    warnings: list[str] = []

    first = max(0, int((stop_at_s - max_stepping_s) * sample_rate) // hop * hop)
    last = min(x.size, int((stop_at_s + max_stopped_s) * sample_rate))
    seg = x[first:last]
    t_first = first / sample_rate
    f_lo, f_hi = stepping_band(
        x[first : int((stop_at_s - 0.15) * sample_rate)], sample_rate, frame, hop, f_min_hz, range_db=args.range_db
    )
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
        events = _one_stop(tu).feed(x)
        near = [e for e in events if stop_s - g <= e.detected_at_s <= stop_s + 0.2]
        if len(events) == 1 and len(near) == 1:
            ev = near[0]
            passing.append((tu, ev.onset_s - stop_s, ev.detected_at_s - stop_s))
            # enough to choose from, unless every one relies on the stop's rises alone: a sound that adds the same
            # looks like it; walk on to the first that also checks what the stop lowers (the self-check decides)
            if len(passing) >= VERIFIED and any(_checks_drops(t) for t, _, _ in passing):
                break
        else:
            where = ", ".join(f"{e.detected_at_s:.3f} s" for e in events[:6]) or "never"
            failures.append(f"{cand.name} fired {where}")
    if not passing:
        raise _no_template(candidates[0], D, delta, sigma, hold, window, stepping, ends, failures)
    # 4. self-check with interference; the quietest passing candidate wins
    tu = _pick(passing, x, sample_rate, frame, stop_s, g, seed, self_check, warnings, stop_at_s, change)
    # 5. the step rate, and the continuum between its lines: how a stream at another rate tells it began at the stop
    tu = _with_continuum(tu, x[first : int((stop_s - g) * sample_rate)], x[int((stop_s + g) * sample_rate) : last])
    # 6. the fine continuum spectra: the stop's signature predicted at another step rate (rate_signature.py)
    step_hi, skip = int((stop_s - g) * sample_rate), int(FINE_SKIP_S * sample_rate)
    step_lo = first + skip if step_hi - (first + skip) >= 2 * fine_segment(sample_rate) else first
    stop_lo = int((stop_s + FINE_SKIP_STOP_S) * sample_rate)
    if last - stop_lo < fine_segment(sample_rate):
        stop_lo = int((stop_s + g) * sample_rate)
    return _with_fine(tu, x[step_lo:step_hi], x[stop_lo:last])


def _with_fine(tu: Tuning, stepping: FloatArray, stopped: FloatArray) -> Tuning:
    """``tu`` with the fine continuum spectra of stepping and of the stop (:func:`~.rate_signature.fine_spectrum_db`).

    Over the sub-bands and :data:`~.rate_signature.FINE_MARGIN_BINS` detector bins
    beyond, at the step rate ``tu`` heard; levels rounded to 0.01 dB. Unchanged when no
    rate was heard or a part is shorter than one Welch segment.
    """
    assert tu.edges_hz is not None
    if tu.step_rate_hz is None:
        return tu
    lo, hi = fine_range_hz(tu.edges_hz, tu.sample_rate, tu.frame)
    step = fine_spectrum_db(stepping, tu.sample_rate, tu.step_rate_hz, lo, hi)
    stop = fine_spectrum_db(stopped, tu.sample_rate, tu.step_rate_hz, lo, hi)
    if step is None or stop is None:
        return tu
    return replace(
        tu,
        fine_start_hz=round(step[0], 6),
        fine_bin_hz=round(step[1], 9),
        fine_stepping_db=tuple(round(float(v), 2) for v in step[2]),
        fine_stopped_db=tuple(round(float(v), 2) for v in stop[2]),
    )


def _with_continuum(tu: Tuning, stepping: FloatArray, stopped: FloatArray) -> Tuning:
    """``tu`` with the step rate heard while stepping and the continuum's levels, signature and spread.

    The continuum (:func:`~stickslip.audio.template.continuum_levels_db`) is the power
    between the step clock's lines: per sub-band, its low quantile over the
    stepping part (as the detector's template), the same quantile of the stopped part less
    it, and the stepping frames' robust spread (at least 1 dB). Unchanged when no
    step rate is heard.
    """
    assert tu.edges_hz is not None
    rate = step_rate_hz(stepping, tu.sample_rate)
    if not math.isfinite(rate) or stepping.size < tu.frame or stopped.size < tu.frame:
        return tu
    Cs = continuum_levels_db(stepping, tu.sample_rate, CONTINUUM_FRAME * tu.frame, tu.frame, tu.edges_hz, rate)
    Cp = continuum_levels_db(stopped, tu.sample_rate, CONTINUUM_FRAME * tu.frame, tu.frame, tu.edges_hz, rate)
    with np.errstate(all="ignore"):
        ok = np.isfinite(Cs).all(axis=0) & np.isfinite(Cp).all(axis=0)
        level = np.full(Cs.shape[1], np.nan)
        sig = np.full(Cs.shape[1], np.nan)
        spread = np.full(Cs.shape[1], np.nan)
        if ok.any():
            level[ok] = np.percentile(Cs[:, ok], 100 * QUANTILE, axis=0)
            sig[ok] = np.percentile(Cp[:, ok], 100 * QUANTILE, axis=0) - level[ok]
            mad = np.median(np.abs(Cs[:, ok] - np.median(Cs[:, ok], axis=0)), axis=0)
            spread[ok] = np.maximum(1.4826 * mad, 1.0)

    def r(v: FloatArray) -> tuple[float, ...]:
        return tuple(round(float(e), 3) if math.isfinite(e) else math.nan for e in v)

    return replace(
        tu,
        step_rate_hz=round(float(rate), 3),
        continuum_levels_db=r(level),
        continuum_signature_db=r(sig),
        continuum_spread_db=r(spread),
    )


def _checks_drops(tu: Tuning) -> bool:
    """Whether the detector of ``tu`` checks that what the stop lowers is lower (its drops are informative).

    The detector's own rule (:mod:`.template`): the signature's drops, in spreads, each
    capped at ``NEG_CAP``, add up (RMS-summed) to at least ``NEG_INFORMATIVE``.
    """
    from .template import NEG_CAP, NEG_INFORMATIVE

    assert tu.signature_db is not None and tu.spread_db is not None
    g = np.maximum(np.minimum(np.asarray(tu.signature_db), 0.0) / np.asarray(tu.spread_db), -NEG_CAP)
    return float(g @ g) >= NEG_INFORMATIVE**2


def _drop_threshold(
    D: FloatArray, sigma: FloatArray, stepping: NDArray[np.bool_], hold: int, window: int
) -> tuple[float, float]:
    """Broad and local drop thresholds (spreads): well above what the stepping part reaches.

    For each statistic (:class:`~stickslip.audio.template.DropMeter`), the largest of
    :data:`DROP_MARGIN` times the worst the stepping part reaches (decided as the detector
    decides: ``hold`` of ``window`` frames), its median plus :data:`DROP_TAIL` robust
    standard deviations (1.4826 MAD: a traverse is longer than the tuning recording, and
    steps that are all a little weaker for a while lower every sub-band together), and
    :data:`DROP_FLOOR`.
    """
    from .template import DropMeter

    z = np.clip(D, -40.0, 40.0) / sigma
    m = DropMeter(z.shape[1])(z)
    broad, local = DropMeter.drops(m)
    signed = -np.median(m, axis=1)  # the broad statistic before it is clipped at 0
    out = []
    for s, raw, floor in zip((broad, local), (signed, local), DROP_FLOOR, strict=True):
        worst = float(_decided(s, np.zeros_like(s), 1.0, hold, window)[stepping].max())
        r = raw[stepping]
        med = float(np.median(r))
        tail = med + DROP_TAIL * 1.4826 * float(np.median(np.abs(r - med)))
        out.append(round(max(DROP_MARGIN * worst, tail, floor), 3))
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
