"""The tuner's candidates: where the stepping is heard, its sub-bands, and templates scored on their worst frames.

The recording's stepping part is summarised per sub-band by its median level and spread
(1.4826 MAD); the stop's *signature* is the median level of the stop part minus the
stepping's, as the detector sees it: against a template that follows the stepping (a causal
running low quantile), frozen at the stop. Candidates (all sub-bands, and 1- and 2-octave
sub-ranges around where the stop departs most) are scored on their *worst* frames: the
largest stop-likeness the detector would decide on anywhere in the stepping part (knocks
and speech included) against the stop part's 5th percentile. The threshold goes
``threshold_share`` of the way between them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import percentile_filter, rank_filter

from ..change.drops import DROPS, DropMeter
from ..change.fit import fit_departure
from ..change.template import TEMPLATE
from ..features.spectra import frame_power_spectra
from ..tuningfile import Tuning
from .params import TUNE, TuneParams

__all__ = ["Candidate", "candidates", "checks_drops", "decided", "drop_threshold", "make_tuning", "running_template",
           "stepping_band"]  # fmt: skip

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Candidate:
    """A template to verify: its sub-bands and how it separated the two parts."""

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
    range_db: float = TUNE.range_db,
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


def running_template(V: FloatArray, stepping: NDArray[np.bool_], hop_s: float, tau_s: float = 0.5) -> FloatArray:
    """Per frame, the low quantile of the stepping levels over the preceding ``tau_s``; frozen after stepping ends."""
    q = 100 * TEMPLATE.quantile
    idx = np.flatnonzero(stepping)
    last = int(idx[-1]) + 1
    W = max(TEMPLATE.chunk, int(round(tau_s / hop_s)))
    head = V[:last]
    pad = np.concatenate((np.repeat(np.percentile(head[:W], q, axis=0)[None, :], W, axis=0), head))
    # sub-band by sub-band: a 1-D rank filter selects the same element as the 2-D one with a (W, 1) footprint, and
    # scipy's 1-D path is tens of times faster (the 2-D filter was a tenth of the tuner's time)
    run = np.empty_like(pad)
    for b in range(pad.shape[1]):
        run[:, b] = percentile_filter(np.ascontiguousarray(pad[:, b]), q, size=W, origin=(W - 1) // 2)
    run = run[W:]
    out = np.empty_like(V)
    out[:last] = run
    out[last:] = run[-1]
    return np.asarray(out, dtype=np.float64)


def decided(a: FloatArray, rho: FloatArray, rmax: float, hold: int, window: int) -> FloatArray:
    """What the detector decides on: the ``hold``-th largest usable stop-likeness in each window of frames."""
    use = np.where(rho <= rmax, a, -10.0)
    if use.size < window:
        return np.full_like(use, -10.0)
    return np.asarray(rank_filter(use, rank=window - hold, size=window, origin=(window - 1) // 2), dtype=np.float64)


def _subsets(delta: FloatArray, sigma: FloatArray) -> dict[tuple[int, ...], str]:
    """All sub-bands, and the 1- and 2-octave sub-ranges around the three where the stop departs most."""
    nb = delta.size
    strength = np.abs(delta) / sigma
    sets: dict[tuple[int, ...], str] = {tuple(range(nb)): "all sub-bands"}
    for k in np.argsort(-strength)[:3].tolist():
        for half in (1, 3):
            lo, hi = max(0, k - half), min(nb, k + half + 1)
            if hi - lo >= 2:
                sets.setdefault(tuple(range(lo, hi)), f"sub-bands {lo}-{hi - 1}")
    return sets


def candidates(
    D: FloatArray,
    sigma: FloatArray,
    delta: FloatArray,
    stepping: NDArray[np.bool_],
    stopped: NDArray[np.bool_],
    hold: int,
    window: int,
    p: TuneParams = TUNE,
) -> list[Candidate]:
    """The candidates over departures ``D`` (frames x sub-bands, dB), scored on their worst frames."""
    out = []
    for bands, name in _subsets(delta, sigma).items():
        sub = list(bands)
        if float(np.sqrt(np.mean((delta[sub] / sigma[sub]) ** 2))) < 1.0:
            continue
        trim = int(len(sub) * p.trim_fraction)
        a, rho = fit_departure(D[:, sub], delta[sub], sigma[sub], trim)
        rho_stop = rho[stopped]
        rmax = float(max(4.0, 1.5 * np.percentile(rho_stop, 95), 2.0 * np.percentile(rho[stepping], 50)))
        dec = decided(a, rho, rmax, hold, window)
        step_hi = float(dec[stepping].max())
        stop_lo = float(np.percentile(dec[stopped], 5))
        margin = stop_lo - max(step_hi, 0.0)
        thr = float(np.clip(max(step_hi, 0.0) + p.threshold_share * margin, p.min_threshold, p.max_threshold))
        if not max(step_hi, 0.0) < thr < stop_lo:
            thr = max(step_hi, 0.0) + p.threshold_share * margin
        contrast = float(np.sqrt(np.sum(delta[sub] ** 2)))
        out.append(Candidate(name, bands, margin, thr, rmax, trim, step_hi, stop_lo, contrast))
    return out


def make_tuning(
    c: Candidate,
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
    """The template tuning of candidate ``c``, over its sub-bands of ``edges``."""
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


def checks_drops(tu: Tuning) -> bool:
    """Whether the detector of ``tu`` checks that what the stop lowers is lower (its drops are informative).

    The detector's own rule (:mod:`stickslip.audio.change.drops`): the signature's drops, in
    spreads, each capped at ``cap``, add up (RMS-summed) to at least ``informative``.
    """
    assert tu.signature_db is not None and tu.spread_db is not None
    g = np.maximum(np.minimum(np.asarray(tu.signature_db), 0.0) / np.asarray(tu.spread_db), -DROPS.cap)
    return float(g @ g) >= DROPS.informative**2


def drop_threshold(
    D: FloatArray, sigma: FloatArray, stepping: NDArray[np.bool_], hold: int, window: int, p: TuneParams = TUNE
) -> tuple[float, float]:
    """Broad and local drop thresholds (spreads): well above what the stepping part reaches.

    For each statistic (:class:`~stickslip.audio.change.drops.DropMeter`), the largest of
    ``drop_margin`` times the worst the stepping part reaches (decided as the detector
    decides: ``hold`` of ``window`` frames), its median plus ``drop_tail`` robust standard
    deviations (1.4826 MAD: a traverse is longer than the tuning recording, and steps that
    are all a little weaker for a while lower every sub-band together), and ``drop_floor``.
    """
    z = np.clip(D, -40.0, 40.0) / sigma
    m = DropMeter(z.shape[1])(z)
    broad, local = DropMeter.drops(m)
    signed = -np.median(m, axis=1)  # the broad statistic before it is clipped at 0
    out = []
    for s, raw, floor in zip((broad, local), (signed, local), p.drop_floor, strict=True):
        worst = float(decided(s, np.zeros_like(s), 1.0, hold, window)[stepping].max())
        r = raw[stepping]
        med = float(np.median(r))
        tail = med + p.drop_tail * 1.4826 * float(np.median(np.abs(r - med)))
        out.append(round(max(p.drop_margin * worst, tail, floor), 3))
    return out[0], out[1]
