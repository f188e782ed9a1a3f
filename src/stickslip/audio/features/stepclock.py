"""The step clock heard in the sound: the step rate, and how step-synchronous a band is.

Every sound a stepping joint makes - stepping and stopped alike - is a train of clicks at
the controller's step rate: at an end stop the drive keeps stepping, and each step still
slips and clicks. The *envelope* of such a sound (the band-passed signal, squared) is
periodic at the step rate: its spectrum has lines at the rate and its multiples. A voice,
a radio, a fan or a second instrument at another rate is not synchronous with it.

Two measures over a stretch of samples (tens to hundreds of ms):

* :func:`step_rate_hz`, the step rate heard: the strongest line of the envelope spectrum
  (first-differenced signal squared, as the guard's
  :func:`~stickslip.audio.sources.guard.step_line_db`) between ``rate_lo_hz`` and
  ``rate_hi_hz`` (:class:`StepClockParams`), refined by its harmonics, Hz;
* :func:`synchrony`, the share of a band's envelope fluctuation that lies on the lines at
  the step rate and its first ``harmonics`` multiples (within ``line_tol`` of each,
  at least two bins), against all of it from 20 Hz to just above the last line: 1 for a
  clean click train through the joint's modes, near 0 for noise or a voice.

Both are plain functions of a stretch of samples: they do not depend on how a stream was
cut into blocks. Units: Hz for rates, dimensionless shares.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft as sfft

from ..paramfield import param

__all__ = [
    "STEP_CLOCK",
    "rate_near_hz",
    "LineChange",
    "Lines",
    "StepClockParams",
    "SyncChange",
    "band_envelope_spectrum",
    "chi2_as_z",
    "clear_rates_hz",
    "line_change",
    "line_power",
    "line_powers",
    "line_z",
    "Periodogram",
    "periodogram",
    "rate_prominence_db",
    "step_rate_hz",
    "synchronous_change_db",
    "synchrony",
    "widen_bands",
]


@dataclass(frozen=True)
class StepClockParams:
    """How the step clock is heard: the rate, its harmonic lines and their change."""

    rate_lo_hz: float = param(
        250.0, "Hz", "slowest step rate looked for (the controllers' 700-1400 Hz, and slower arms)"
    )
    rate_hi_hz: float = param(2500.0, "Hz", "fastest step rate looked for")
    harmonics: int = param(3, "lines", "harmonics of the step rate counted as synchronous (synchrony)")
    sub_line_db: float = param(
        8.0, "dB", "lines at a third (with two thirds) or a half (with three halves) this clear make that the rate"
    )
    half_line_db: float = param(10.0, "dB", "a line at half the winner alone must stand this clear to be the rate")
    widen: float = param(2.0, "step rates", "a sub-band is widened to this many rates before its lines are counted")
    comb_tol: float = param(
        0.004, "of the line's frequency", "half-width of a harmonic line in the signal's spectrum (at least 3 bins)"
    )
    sharp_width: float = param(4.0, "combs", "the comb that tells how sharp the lines are is this many times wider")
    flank: float = param(4.0, "half-widths", "the continuum under a line is read on its flanks out to this far")
    line_tol: float = param(
        0.02, "of the line's frequency", "half-width of an envelope line (a rough clock widens the k-th line k times)"
    )
    trim_lines: int = param(
        1, "lines", "the lines that changed most are dropped before the sum (a voice's harmonic on one line)"
    )
    line_z: float = param(3.0, "standard deviations", "a kept line that moved this far reports its change in dB")
    min_lines: int = param(6, "lines", "no verdict on fewer lines (a rate heard at twice the step rate leaves 5)")


STEP_CLOCK = StepClockParams()

FloatArray = NDArray[np.float64]


@functools.lru_cache(maxsize=16)
def _hann(n: int) -> FloatArray:
    """``np.hanning(n)``, kept (the late path asks for the same few lengths again and again); read-only."""
    w = np.hanning(n)
    w.flags.writeable = False
    return w


def _median(v: FloatArray) -> float:
    """``np.median`` of a small 1-D array, without its overhead (the same value: the middle one, or the mean of two)."""
    a = np.sort(v)
    n = a.size
    return float(a[n // 2]) if n % 2 else float((a[n // 2 - 1] + a[n // 2]) / 2)


def band_envelope_spectrum(
    x: ArrayLike, sample_rate: float, bands_hz: Sequence[tuple[float, float]] | None = None
) -> tuple[FloatArray, FloatArray]:
    """Power spectrum of the envelope of ``x`` restricted to ``bands_hz`` (all of it if None).

    The band signal is ``x`` with every FFT bin outside the bands zeroed (no bands: the
    first difference of ``x``, as the guard's envelope); its envelope is its square, less
    its mean, under a Hann window. Returns the frequencies (Hz) and powers (arbitrary
    unit, the same for every call on stretches of one length).
    """
    v = np.asarray(x, dtype=np.float64).ravel()
    sr = float(sample_rate)
    if bands_hz is None:
        y = np.diff(v)
    else:
        spec = sfft.rfft(v * _hann(v.size))
        f = np.fft.rfftfreq(v.size, 1 / sr)
        keep = np.zeros(f.size, dtype=bool)
        for lo, hi in bands_hz:
            keep |= (f >= lo) & (f < hi)
        spec[~keep] = 0.0
        y = sfft.irfft(spec, v.size)
    e = y**2
    e = (e - e.mean()) * _hann(e.size)
    p = np.abs(sfft.rfft(e)) ** 2
    return np.asarray(np.fft.rfftfreq(e.size, 1 / sr), dtype=np.float64), np.asarray(p, dtype=np.float64)


def _line_mask(f: FloatArray, centre_hz: float, tol: float) -> NDArray[np.bool_]:
    df = float(f[1] - f[0]) if f.size > 1 else 1.0
    return np.asarray(np.abs(f - centre_hz) <= max(tol * centre_hz, 2.0 * df), dtype=bool)


def _prominence_db(f: FloatArray, p: FloatArray, centre_hz: float, tol: float) -> float:
    """The power within ``tol`` (a share of ``centre_hz``) of it over what the continuum around it would put there, dB.

    The continuum: the median bin of 0.75-1.25 x ``centre_hz`` outside, divided by ln 2 (the median of noise's
    periodogram bins is ln 2 of their mean). Integrated, so a line smeared by a rough clock counts in full; noise
    alone gives 0 dB give or take 1-2.
    """
    near = _line_mask(f, centre_hz, tol)
    around = (f >= 0.75 * centre_hz) & (f <= 1.25 * centre_hz) & ~near
    if not near.any() or not around.any():
        return float("-inf")
    floor = float(np.median(p[around])) / math.log(2.0) * np.count_nonzero(near)
    return float(10 * np.log10((float(np.sum(p[near])) + 1e-300) / (floor + 1e-300)))


def step_rate_hz(
    x: ArrayLike,
    sample_rate: float,
    lo_hz: float | None = None,
    hi_hz: float | None = None,
    params: StepClockParams = STEP_CLOCK,
) -> float:
    """The step rate heard in ``x``, Hz: the envelope spectrum's strongest line in [lo, hi] (default: the params').

    The default ``hi`` is also under a quarter of the sample rate: the envelope (the signal
    squared) holds twice the signal's frequencies, and what lies beyond the Nyquist frequency
    folds back as lines that are no step rate (an accelerometer at 5 kHz stepping at 700 Hz
    showed its strongest line at 5000 - 4 x 700 = 2200 Hz). A sound card at 10 kHz and more
    keeps the default range.

    Each candidate bin is scored by the log power of its first three harmonics (a line at
    half the rate, or 1.5 times it, lacks some of them); a line at a third or a half of the
    winner heard clearly is taken instead (:func:`_fraction`: an envelope can be stronger at
    two or three times the rate); the winner is refined by the power-weighted mean
    frequency over its line. NaN when ``x`` is shorter than 20 periods of ``lo_hz`` or silent.
    """
    lo_hz = params.rate_lo_hz if lo_hz is None else lo_hz
    sr = float(sample_rate)
    hi_hz = min(params.rate_hi_hz, sr / 4) if hi_hz is None else hi_hz
    spectrum = _envelope_spectrum(x, sr, lo_hz)
    return float("nan") if spectrum is None else _strongest_rate_hz(*spectrum, lo_hz, hi_hz, params)


def _envelope_spectrum(x: ArrayLike, sr: float, lo_hz: float) -> tuple[FloatArray, FloatArray] | None:
    """:func:`band_envelope_spectrum` of ``x``; None where ``x`` is shorter than 20 periods of ``lo_hz`` or silent."""
    v = np.asarray(x, dtype=np.float64).ravel()
    if v.size < 20 * sr / lo_hz or not np.any(v != v[0]):
        return None
    return band_envelope_spectrum(v, sr)


def _strongest_rate_hz(f: FloatArray, p: FloatArray, lo_hz: float, hi_hz: float, params: StepClockParams) -> float:
    """:func:`step_rate_hz` read off the envelope spectrum ``p`` at frequencies ``f``, Hz (NaN: no line in range)."""
    df = float(f[1] - f[0])
    sel = np.flatnonzero((f >= lo_hz) & (f <= hi_hz))
    if sel.size == 0:
        return float("nan")
    # each candidate scored by the log power of its first three harmonics (each the largest bin within 2 bins):
    # a line at 1.5 or 2 times the rate, or half of it, lacks some of them
    logp = np.log(p + 1e-300 + 1e-12 * float(np.max(p)))
    score = np.zeros(sel.size)
    for k in (1, 2, 3):
        idx = np.minimum(k * sel, f.size - 1)
        score += np.maximum.reduce([logp[np.clip(idx + j, 0, f.size - 1)] for j in range(-2 * k, 2 * k + 1)])
    i = _fraction(f, p, int(sel[int(np.argmax(score))]), lo_hz, params)
    w = max(2, int(round(0.01 * f[i] / df)))
    j0, j1 = max(i - w, 0), min(i + w + 1, f.size)
    total = float(np.sum(p[j0:j1]))
    if not total > 0.0:
        return float("nan")
    return float(np.sum(f[j0:j1] * p[j0:j1]) / total)


def clear_rates_hz(x: ArrayLike, sample_rate: float, piece: int, min_db: float) -> list[float]:
    """The step rate heard in each ``piece`` samples of ``x`` (:func:`step_rate_hz`), Hz, where it is heard clearly.

    A piece's rate counts where its envelope line stands ``min_db`` over the continuum
    around it (:func:`_prominence_db`; noise alone gives 0-2 dB); unheard and unclear pieces
    are left out. One clock heard throughout gives one rate (give or take its drift); a
    second instrument stepping in bursts, louder than the first while it steps, gives its
    own rate in the pieces it fills.
    """
    v = np.asarray(x, dtype=np.float64).ravel()
    sr = float(sample_rate)
    lo_hz, hi_hz = STEP_CLOCK.rate_lo_hz, min(STEP_CLOCK.rate_hi_hz, sr / 4)  # step_rate_hz's defaults
    out: list[float] = []
    for i in range(0, v.size - piece + 1, max(1, piece)):
        spectrum = _envelope_spectrum(v[i : i + piece], sr, lo_hz)  # made once: the rate and its prominence
        if spectrum is None:
            continue
        rate = _strongest_rate_hz(*spectrum, lo_hz, hi_hz, STEP_CLOCK)
        if math.isfinite(rate) and _prominence_db(*spectrum, rate, STEP_CLOCK.line_tol) >= min_db:
            out.append(rate)
    return out


def rate_prominence_db(x: ArrayLike, sample_rate: float, rate_hz: float) -> float:
    """How far the envelope's line at ``rate_hz`` stands over the continuum around it in ``x``, dB
    (:func:`_prominence_db` on the spectrum :func:`clear_rates_hz` reads; noise alone 0-2 dB; NaN where ``x`` is too
    short or silent): is a clock at that rate heard in ``x``, whatever else is louder."""
    spectrum = _envelope_spectrum(x, float(sample_rate), STEP_CLOCK.rate_lo_hz)
    if spectrum is None:
        return float("nan")
    return _prominence_db(*spectrum, float(rate_hz), STEP_CLOCK.line_tol)


def _fraction(f: FloatArray, p: FloatArray, i: int, lo_hz: float, params: StepClockParams) -> int:
    """The bin of the step rate given the envelope's strongest line in bin ``i``: that line, or a third or a half of it.

    The clicks' envelope may be stronger at two or three times the rate than at the rate
    (modes that beat there). A third: its line and the one at two thirds both stand
    ``sub_line_db`` clear (chance does not do that). A half: its line by ``half_line_db``
    (one line cleared 8 dB by chance: joint Q's brighter stop at 1000 Hz was heard at
    500 Hz; a true half stands 24-27 dB clear on the battery's joint P at 700-750 Hz, but
    only 11.7-13.6 dB through the fourth generator's rough clock, arm 3 at 882 Hz), or the
    half and three halves both ``sub_line_db`` clear (arm 3 at 1115 Hz: its half 9.8 dB
    clear, the line at three halves 18.2 dB).
    """
    tol = params.line_tol
    for div in (3, 2):
        sub = f[i] / div
        if div == 3:
            heard = sub >= lo_hz and min(_prominence_db(f, p, c, tol) for c in (sub, 2 * sub)) >= params.sub_line_db
        else:
            half = _prominence_db(f, p, sub, tol) if sub >= lo_hz else -math.inf
            heard = half >= params.half_line_db or min(half, _prominence_db(f, p, 3 * sub, tol)) >= params.sub_line_db
        if heard:
            j = int(np.argmin(np.abs(f - f[i] / div)))
            j0, j1 = max(j - 2, 0), min(j + 3, f.size)
            return j0 + int(np.argmax(p[j0:j1]))
    return i


def synchrony(
    x: ArrayLike,
    sample_rate: float,
    rate_hz: float,
    bands_hz: Sequence[tuple[float, float]] | None = None,
    params: StepClockParams = STEP_CLOCK,
) -> float:
    """Share of the band envelope's fluctuation on the lines at ``rate_hz`` and its multiples.

    Parameters
    ----------
    x : array_like
        Samples (at least 20 step periods).
    sample_rate : float
        Samples per second, Hz.
    rate_hz : float
        The step rate, Hz (:func:`step_rate_hz`).
    bands_hz : sequence of (lo, hi), optional
        The bands whose envelope is judged, Hz (None: the whole first-differenced signal).

    Returns
    -------
    float
        In [0, 1]: the envelope power within ``line_tol`` of the first
        ``harmonics`` multiples of ``rate_hz`` over the power from 20 Hz to
        ``(harmonics + 0.5) * rate_hz``; NaN for a rate that is not finite, a stretch
        too short, or a silent band.
    """
    v = np.asarray(x, dtype=np.float64).ravel()
    sr = float(sample_rate)
    if not (np.isfinite(rate_hz) and rate_hz > 0 and v.size >= 20 * sr / rate_hz):
        return float("nan")
    f, p = band_envelope_spectrum(v, sr, bands_hz)
    span = (f >= 20.0) & (f <= (params.harmonics + 0.5) * rate_hz)
    total = float(np.sum(p[span]))
    if not total > 0.0:
        return float("nan")
    lines = np.zeros(f.size, dtype=bool)
    for k in range(1, params.harmonics + 1):
        lines |= _line_mask(f, k * rate_hz, params.line_tol)
    return float(np.sum(p[span & lines]) / total)


def widen_bands(
    bands_hz: Sequence[tuple[float, float]], rate_hz: float, sample_rate: float, params: StepClockParams = STEP_CLOCK
) -> list[tuple[float, float]]:
    """``bands_hz`` each widened about its centre to at least ``widen`` x ``rate_hz``, merged where they meet, Hz.

    A sub-band narrower than the step rate may hold no harmonic of it at all (joint P's
    5.2 kHz mode between the 1160 Hz lines at 4640 and 5800 Hz): the stop's sound is on
    the nearest lines, outside the sub-band. Kept within 50 Hz - 0.48 ``sample_rate``.
    """
    out = []
    for lo, hi in bands_hz:
        if hi - lo < params.widen * rate_hz:
            c = 0.5 * (lo + hi)
            lo, hi = c - params.widen * rate_hz / 2, c + params.widen * rate_hz / 2
        out.append((max(50.0, float(lo)), min(0.48 * float(sample_rate), float(hi))))
    out.sort()
    merged: list[tuple[float, float]] = []
    for lo, hi in out:
        if merged and lo <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(hi, merged[-1][1]))
        elif hi > lo:
            merged.append((lo, hi))
    return merged


class Lines(NamedTuple):
    """The harmonic lines of a step rate in some bands, one entry per line (:func:`line_powers`)."""

    #: the line's frequency, k x the step rate, Hz
    freq_hz: FloatArray
    #: its power above the continuum, mean-square units of the signal (a sine of amplitude A on it: A^2 / 2)
    power: FloatArray
    #: the variance of that estimate for a continuum alone (its noise), squared mean-square units
    var: FloatArray
    #: the continuum under the line, per frequency bin, mean-square units
    floor: FloatArray
    #: the bins the line spans
    bins: NDArray[np.int64]
    #: the index (in the bands asked for) of the band the line was found in; a line on an edge two bands share
    #: comes once for each
    band: NDArray[np.int64]


@dataclass(frozen=True)
class Periodogram:
    """A stretch's one-sided, Hann-windowed power spectrum (:func:`periodogram`), made once for the
    several readings :func:`line_powers` takes of the same samples (another comb, a wider one)."""

    #: the power per rfft bin, mean-square units of the signal (the bins sum to the mean square)
    power: FloatArray
    #: the samples it was made from
    n: int


def periodogram(x: ArrayLike) -> Periodogram:
    """The power spectrum :func:`line_powers` reads the lines from, for ``x`` (a stretch of samples)."""
    v = np.asarray(x, dtype=np.float64).ravel()
    if v.size == 0:
        return Periodogram(np.zeros(0), 0)
    w = _hann(v.size)
    p = 2.0 * np.abs(sfft.rfft(v * w)) ** 2 / (v.size * float(np.sum(w**2)))  # one-sided: bins sum to the mean square
    return Periodogram(p, int(v.size))


def line_powers(
    x: ArrayLike | Periodogram,
    sample_rate: float,
    rate_hz: float,
    bands_hz: Sequence[tuple[float, float]],
    width: float = 1.0,
    params: StepClockParams = STEP_CLOCK,
) -> tuple[Lines, float]:
    """Power of ``x`` on each harmonic line of ``rate_hz`` in ``bands_hz``, above the continuum; the bands' power.

    Per harmonic ``k * rate_hz`` in a band: the Hann-windowed power within
    ``h = max(3 bins, comb_tol * k * rate_hz)`` of it, less the continuum under it (the
    mean of the median bins of its two flanks, h to ``flank`` h away: a straight
    line through the flanks, so a sloping noise spectrum is not taken for a line) times
    the bins counted (a median of noise's periodogram bins is ln 2 of their mean: it is
    divided by ln 2). Not clipped at 0 (clipping would turn noise into line power). The
    variance for a continuum alone: ``4 x bins x continuum^2`` (periodogram bins of noise
    scatter by their mean, neighbours under a Hann window are correlated, and the
    continuum is itself an estimate). ``width`` multiplies ``h`` (a wider comb, for how
    sharp the lines are). Empty arrays and NaN for a rate that is not finite or a stretch
    shorter than 20 step periods. ``x``: the samples, or their :func:`periodogram` when
    several readings are taken of the same samples.
    """
    spec = x if isinstance(x, Periodogram) else None
    v = np.zeros(0) if spec is not None else np.asarray(x, dtype=np.float64).ravel()
    size = spec.n if spec is not None else int(v.size)
    sr = float(sample_rate)
    freq: list[float] = []
    power: list[float] = []
    var: list[float] = []
    floors: list[float] = []
    bins: list[int] = []
    band: list[int] = []
    if not (np.isfinite(rate_hz) and rate_hz > 0 and size >= 20 * sr / rate_hz):
        e = np.zeros(0)
        return Lines(e, e, e, e, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)), float("nan")
    p = (spec if spec is not None else periodogram(v)).power
    bands = tuple((float(lo), float(hi)) for lo, hi in bands_hz)
    in_bands, lines = _line_grid(size, sr, float(rate_hz), bands, float(width), params.comb_tol, params.flank)
    whole = 0.0
    for inb in in_bands:
        whole += float(np.sum(p[inb]))
    for j, c, near, left, right in lines:
        # the median of noise's periodogram bins is ln 2 of their mean (they scatter exponentially)
        floor = 0.5 * (_median(p[left]) + _median(p[right])) / math.log(2.0)
        n = int(near.size)
        freq.append(c)
        power.append(float(np.sum(p[near])) - floor * n)
        var.append(4.0 * n * floor**2)
        floors.append(floor)
        bins.append(n)
        band.append(j)
    lines_ = Lines(_f64(freq), _f64(power), _f64(var), _f64(floors), np.asarray(bins, dtype=np.int64),
                   np.asarray(band, dtype=np.int64))
    return lines_, whole


_Grid = tuple[list[NDArray[np.intp]], list[tuple[int, float, NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]]]


@functools.lru_cache(maxsize=64)
def _line_grid(
    n: int,
    sr: float,
    rate_hz: float,
    bands: tuple[tuple[float, float], ...],
    width: float,
    comb_tol: float,
    flank: float,
) -> _Grid:
    """The bins of :func:`line_powers` for a stretch of ``n`` samples: per band, its bins; per line (found in a band and
    with both flanks), the band's index, its frequency and the bins of the line and of its two flanks. Kept: the late
    path asks for the same stretch length and rate again and again."""
    f = np.fft.rfftfreq(n, 1 / sr)
    df = float(f[1] - f[0])
    in_bands: list[NDArray[np.intp]] = []
    lines: list[tuple[int, float, NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]] = []
    for j, (lo, hi) in enumerate(bands):
        inb = (f >= lo) & (f < hi)
        in_bands.append(np.flatnonzero(inb))
        for k in range(max(1, int(math.ceil(lo / rate_hz))), int(math.floor(hi / rate_hz)) + 1):
            c = k * rate_hz
            half = width * max(3 * df, comb_tol * c)
            near = (np.abs(f - c) <= half) & inb
            left = (f < c - half) & (f >= c - flank * half)
            right = (f > c + half) & (f <= c + flank * half)
            if near.any() and left.any() and right.any():
                lines.append((j, c, np.flatnonzero(near), np.flatnonzero(left), np.flatnonzero(right)))
    return in_bands, lines


def _f64(values: list[float]) -> FloatArray:
    return np.asarray(values, dtype=np.float64)


def line_power(
    x: ArrayLike, sample_rate: float, rate_hz: float, bands_hz: Sequence[tuple[float, float]], width: float = 1.0
) -> tuple[float, float, float]:
    """The lines of :func:`line_powers` summed: their power, its standard deviation and the bands' whole power.

    Returns
    -------
    (float, float, float)
        Line power, its standard deviation (the lines' variances added) and the bands'
        whole power, mean-square units of ``x`` (a sine of amplitude A on a line gives
        A^2 / 2); NaNs for a rate that is not finite or a stretch shorter than 20 step
        periods.
    """
    lines, whole = line_powers(x, sample_rate, rate_hz, bands_hz, width)
    if not np.isfinite(whole):
        return float("nan"), float("nan"), float("nan")
    return float(np.sum(lines.power)), math.sqrt(float(np.sum(lines.var))), whole


class SyncChange(NamedTuple):
    """What :func:`synchronous_change_db` measured (NaN: not measured)."""

    #: the step rate heard before, Hz
    rate_hz: float
    #: change of the line power, dB (each side floored at 1 % of the larger: -20 to +20 dB at most)
    change_db: float
    #: the same change in standard deviations of its noise (:func:`line_power`), signed
    change_z: float
    #: share of the bands' power that lies on the step clock's lines before
    share_before: float
    #: how sharp the lines are before: their power in the comb over that in a comb ``sharp_width`` times
    #: wider (1 for a clean clock; a rough clock spreads its higher harmonics wider than the comb)
    sharpness_before: float


def synchronous_change_db(
    before: ArrayLike, after: ArrayLike, sample_rate: float, bands_hz: Sequence[tuple[float, float]]
) -> SyncChange:
    """How much the step-synchronous power in the bands changed from ``before`` to ``after``.

    ``before`` (the stepping) and ``after`` should be of equal length. The rate is heard
    on ``before`` alone and used for both (a stop does not change it; a louder clock that
    comes with the interference must not be taken for the joint's); each band is widened
    to ``widen`` step rates (:func:`widen_bands`). Interference adds no power on the
    lines (it is not synchronous with the clock), only noise to their estimate; a stop
    that is louder there adds power, one that is quieter takes it away. NaN fields (no
    verdict) when no rate is heard or there is no line power on either side.
    """
    a = np.asarray(before, dtype=np.float64).ravel()
    b = np.asarray(after, dtype=np.float64).ravel()
    sr = float(sample_rate)
    nan = float("nan")
    rate = step_rate_hz(a, sr)
    if not np.isfinite(rate):
        return SyncChange(rate, nan, nan, nan, nan)
    bands = widen_bands(bands_hz, rate, sr)
    (p0, s0, w0), (p1, s1, _) = line_power(a, sr, rate, bands), line_power(b, sr, rate, bands)
    share = p0 / w0 if w0 > 0 else nan
    wide = line_power(a, sr, rate, bands, STEP_CLOCK.sharp_width)[0]
    sharp = p0 / wide if wide > 0 else nan
    top = max(p0, p1)
    if not (np.isfinite(top) and top > 0.0):
        return SyncChange(rate, nan, nan, share, sharp)
    db = float(10 * np.log10(max(p1, 0.01 * top) / max(p0, 0.01 * top)))
    sd = math.hypot(s0, s1)
    z = (p1 - p0) / sd if sd > 0 else math.copysign(math.inf, p1 - p0) if p1 != p0 else 0.0
    return SyncChange(rate, db, float(z), float(share), float(sharp))


class LineChange(NamedTuple):
    """What :func:`line_change` measured (NaN: not measured)."""

    #: the step rate heard before, Hz
    rate_hz: float
    #: how far the lines changed, as a standard normal deviate: the trimmed chi-square of the per-line changes
    #: (``trim_lines`` largest dropped) against its degrees of freedom (Wilson-Hilferty), dimensionless
    change_z: float
    #: the largest change, dB, of a line kept in that sum that moved by ``line_z`` standard deviations or more
    #: (each side floored at 1 % of the larger: -20 to +20 dB at most; 0 when none did), signed
    change_db: float
    #: lines judged (in the sum) and lines found in the bands
    dof: int
    lines: int
    #: share of the bands' power that lies on the step clock's lines before
    share_before: float
    #: how sharp the lines are before: their power in the comb over that in a comb ``sharp_width`` times
    #: wider (1 for a clean clock; a rough clock spreads its higher harmonics wider than the comb)
    sharpness_before: float


def chi2_as_z(chi2: float, dof: int) -> float:
    """A chi-square value with ``dof`` degrees of freedom as a standard normal deviate (Wilson-Hilferty, 1931).

    ``((chi2 / dof)^(1/3) - (1 - 2 / (9 dof))) / sqrt(2 / (9 dof))``: within 0.11 of the exact
    deviate for 3 degrees of freedom and more, out to 4 standard deviations, and below it beyond
    (0.35 below at 6 for 3 degrees of freedom; tested against scipy). NaN for ``dof`` < 1 or a
    chi-square that is not finite.
    """
    if dof < 1 or not math.isfinite(chi2):
        return float("nan")
    v = 2.0 / (9.0 * dof)
    return float(((max(chi2, 0.0) / dof) ** (1.0 / 3.0) - (1.0 - v)) / math.sqrt(v))


def line_z(before: Lines, after: Lines) -> FloatArray:
    """Each line's change from ``before`` to ``after`` in standard deviations of the change's estimate.

    The variance: both estimates' noise (:attr:`Lines.var`) plus each line's scatter under
    that noise, ``2 x P x continuum`` for independent bins, doubled for the Hann window's
    correlated neighbours (``4 P floor`` per side, P clipped at 0). The lines must be the
    same (the same rate and bands); 0 where the variance is 0.
    """
    if before.power.shape != after.power.shape:
        raise ValueError(f"{before.power.size} lines before and {after.power.size} after: not the same lines")
    var = before.var + after.var
    var = var + 4.0 * (np.maximum(before.power, 0.0) * before.floor + np.maximum(after.power, 0.0) * after.floor)
    d = after.power - before.power
    return np.asarray(np.divide(d, np.sqrt(var), out=np.zeros(d.size), where=var > 0), dtype=np.float64)


def line_change(
    before: ArrayLike,
    after: ArrayLike,
    sample_rate: float,
    bands_hz: Sequence[tuple[float, float]],
    trim: int | None = None,
    rate_hz: float | None = None,
    params: StepClockParams = STEP_CLOCK,
) -> LineChange:
    """How much the step clock's lines in ``bands_hz`` changed from ``before`` to ``after``, line by line.

    The rate is heard on ``before`` alone and used for both (a stop does not change it).
    Per harmonic line k (:func:`line_powers`) the change ``d_k = P_after - P_before`` is
    set against its standard deviation: the two estimates' noise (continuum alone) plus
    the line's own scatter under that noise, ``2 x P x continuum`` per side, doubled for
    the Hann window's correlated neighbours (``4 P floor``). A stop changes the joint's
    sound on many lines, up on some and down on others; a sum over the lines
    can cancel, a sum of squares cannot: ``sum (d_k / s_k)^2`` is chi-square with one
    degree of freedom per line when nothing changed. Interference adds no power on the
    lines on average, but a voice's or a radio's harmonic that sits on a line for a
    syllable or a note does, in one stretch and not the other: the ``trim_lines``
    largest terms are dropped before the sum is compared with its degrees of freedom
    (the lines left; the trimmed sum is smaller than a chi-square of that many, so the
    deviate errs towards "nothing changed"). ``before`` and ``after`` may differ in
    length (each line's estimate is a mean square). NaN fields (no verdict) when no rate
    is heard or fewer than ``min_lines`` lines are found. ``trim`` lines are dropped
    (``trim_lines`` by default; the late path drops 2); ``rate_hz``, if
    given, is used instead of the rate heard on ``before`` (Hz).
    """
    trim = params.trim_lines if trim is None else trim
    if not (isinstance(trim, int) and trim >= 0):
        raise ValueError(f"trim = {trim!r} must be a whole number of lines, 0 or more")
    a = np.asarray(before, dtype=np.float64).ravel()
    b = np.asarray(after, dtype=np.float64).ravel()
    sr = float(sample_rate)
    nan = float("nan")
    rate = step_rate_hz(a, sr) if rate_hz is None else float(rate_hz)
    if not (np.isfinite(rate) and rate > 0.0):
        return LineChange(rate, nan, nan, 0, 0, nan, nan)
    pa = periodogram(a)
    l0, w0 = line_powers(pa, sr, rate, bands_hz)
    l1, _ = line_powers(b, sr, rate, bands_hz)
    p0 = float(np.sum(l0.power))
    wide = float(np.sum(line_powers(pa, sr, rate, bands_hz, params.sharp_width)[0].power))
    share = p0 / w0 if w0 > 0 else nan
    sharp = p0 / wide if wide > 0 else nan
    k = int(l0.power.size)
    if k != l1.power.size or k < max(params.min_lines, trim + 2):
        return LineChange(rate, nan, nan, 0, k, share, sharp)
    z = line_z(l0, l1)
    keep = np.argsort(-(z**2), kind="stable")[trim:]
    dof = k - trim
    top = np.maximum(np.maximum(l0.power, l1.power), 0.0)
    db = 10 * np.log10(np.maximum(l1.power, 0.01 * top + 1e-300) / np.maximum(l0.power, 0.01 * top + 1e-300))
    moved = keep[np.abs(z[keep]) >= params.line_z]
    change_db = float(db[moved[np.argmax(np.abs(db[moved]))]]) if moved.size else 0.0
    return LineChange(rate, chi2_as_z(float(np.sum(z[keep] ** 2)), dof), change_db, dof, k, share, sharp)


def rate_near_hz(x: ArrayLike | None, sample_rate: float, commanded_hz: float | None, tol: float) -> float:
    """The step rate heard in ``x``, Hz (NaN: none), near the commanded rate where it is known.

    Without a commanded rate: :func:`step_rate_hz` over its whole range (``x`` ``None``:
    NaN). With one: the strongest line within ``commanded_hz x (1 +/- tol)``, and the
    commanded rate itself where none is heard there (``tol``: a fraction, e.g. 0.25).
    """
    if commanded_hz is None:
        return math.nan if x is None else step_rate_hz(x, sample_rate)
    lo, hi = (1 - tol) * commanded_hz, (1 + tol) * commanded_hz
    heard = math.nan if x is None else step_rate_hz(x, sample_rate, lo, hi)
    return heard if math.isfinite(heard) else commanded_hz
