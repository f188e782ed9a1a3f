"""Interference for the tuner's self-check: knocks, babble, a second click train.

:func:`~stickslip.audio.tuning.tune` adds these to its own training recording and runs
the tuned detector on the result, so the tuning it saves says how it fared against
sounds a lab has: a knock or tap on the table (a decaying low thump with a bright contact
click), speech-like babble (voiced syllables through formants, some fricatives), a
second instrument stepping nearby at another rate (a click train through its own
resonances) and a microphone gain change. Levels are relative to the recording's own
stepping sound, so the check means the same at any gain.

:func:`shaped_noise` and :func:`bursts` make a sound *shaped like the stop's own rise*:
noise whose level in each sub-band is what the stop adds there, in bursts. It is not a
sound a lab has; it asks whether a tuning relies on rises alone (then a sound that adds
the same, a voice or a tap or another instrument in those sub-bands, looks like the
stop) or also on what the stop lowers (which no added sound can show).

Everything here is seeded and deterministic.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sfft
from scipy.signal import lfilter

__all__ = ["babble", "bursts", "click_train", "knocks", "shaped_noise"]

FloatArray = NDArray[np.float64]


def _resonance(x: FloatArray, f_hz: float, bw_hz: float, sample_rate: int) -> FloatArray:
    r = float(np.exp(-np.pi * bw_hz / sample_rate))
    a = [1.0, -2 * r * np.cos(2 * np.pi * f_hz / sample_rate), r * r]
    return np.asarray(lfilter([1.0 - r], a, x), dtype=np.float64)


def knocks(n: int, sample_rate: int, rms: float, rng: np.random.Generator, every_s: float = 0.7) -> FloatArray:
    """Knocks on the table every ``every_s`` s on average; peak about 10-25 dB above ``rms``."""
    out = np.zeros(n)
    L = int(0.12 * sample_rate)
    t = np.arange(L) / sample_rate
    count = max(1, int(n / sample_rate / every_s))
    for start in rng.integers(0, max(1, n - L), count):
        f0 = rng.uniform(70.0, 250.0)
        thump = sum(
            w * np.exp(-t / tau) * np.sin(2 * np.pi * f0 * k * t + rng.uniform(0, 6.3))
            for k, w, tau in ((1.0, 1.0, 0.03), (2.4, 0.5, 0.015), (6.1, 0.3, 0.006))
        )
        click = rng.standard_normal(L) * np.exp(-t / rng.uniform(2e-4, 1e-3))
        k = np.asarray(thump + rng.uniform(0.2, 0.8) * click, dtype=np.float64)
        k *= rms * 10 ** (rng.uniform(10.0, 25.0) / 20) / max(float(np.max(np.abs(k))), 1e-12)
        out[start : start + L] += k[: n - start]
    return out


def babble(n: int, sample_rate: int, rms: float, rng: np.random.Generator, level_db: float = -6.0) -> FloatArray:
    """Speech-like babble at ``level_db`` re ``rms`` while talking (syllables with pauses)."""
    out = np.zeros(n)
    i = int(rng.uniform(0.0, 0.2) * sample_rate)
    while i < n:
        m = int(rng.uniform(0.08, 0.35) * sample_rate)
        tt = np.arange(m) / sample_rate
        f0 = rng.uniform(90.0, 240.0) * (1 + 0.15 * rng.uniform(-1, 1) * tt / max(tt[-1], 1e-9))
        pulses = np.zeros(m)
        pulses[np.flatnonzero(np.diff(np.floor(np.cumsum(f0 / sample_rate)), prepend=0.0))] = 1.0
        src = lfilter([1.0], [1.0, -0.95], pulses)
        syl = sum(
            _resonance(src, rng.uniform(lo, hi), bw, sample_rate)
            for lo, hi, bw in ((300, 900, 80.0), (900, 2400, 120.0), (2400, 3500, 200.0))
        )
        if rng.random() < 0.35:  # a fricative
            fric = _resonance(
                rng.standard_normal(m),
                rng.uniform(min(3500, 0.3 * sample_rate), min(8000, 0.4 * sample_rate)),
                2500.0,
                sample_rate,
            )
            syl = syl + fric * (np.std(syl) / max(float(np.std(fric)), 1e-12)) * 0.5
        syl = np.asarray(syl, dtype=np.float64) * np.sin(np.pi * tt / tt[-1]) ** 2
        syl *= rms * 10 ** (level_db / 20) / max(float(np.sqrt(np.mean(syl**2))), 1e-12)
        out[i : i + m] += syl[: n - i]
        i += m + int(rng.uniform(0.03, 0.4) * sample_rate)
    return out


def click_train(
    n: int, sample_rate: int, rms: float, rng: np.random.Generator, rate_hz: float = 617.0, level_db: float = -6.0
) -> FloatArray:
    """A second instrument stepping at ``rate_hz``: clicks through two resonances of its own."""
    x = np.zeros(n)
    idx = (np.arange(0.0, n / sample_rate, 1 / rate_hz) * sample_rate).astype(np.int64)
    x[idx[idx < n]] = rng.uniform(0.7, 1.0, int(np.sum(idx < n)))
    y = sum(
        _resonance(x, f, bw, sample_rate)
        for f, bw in (
            (rng.uniform(1500, 3000), 300.0),
            (rng.uniform(min(5000, 0.3 * sample_rate), min(11000, 0.4 * sample_rate)), 600.0),
        )
    )
    y = np.asarray(y, dtype=np.float64)
    return y * rms * 10 ** (level_db / 20) / max(float(np.sqrt(np.mean(y**2))), 1e-12)


def shaped_noise(
    n: int,
    sample_rate: int,
    edges_hz: tuple[float, ...] | list[float],
    mean_square: FloatArray,
    rng: np.random.Generator,
) -> FloatArray:
    """Stationary noise whose mean square between ``edges_hz[b]`` and ``edges_hz[b + 1]`` is ``mean_square[b]``.

    Parameters
    ----------
    n : int
        Length, samples.
    sample_rate : int
        Sample rate, Hz.
    edges_hz : sequence of float
        Sub-band edges, Hz (as the detector's: a bin belongs to the band its frequency
        is at or above the lower edge of).
    mean_square : numpy.ndarray
        Mean square per sub-band (full scale 1.0); zero or less leaves the band empty.
    rng : numpy.random.Generator
        Source of the noise.

    Returns
    -------
    numpy.ndarray
        The noise, float64; nothing outside the sub-bands.
    """
    # scipy's FFT: numpy's values bit for bit, and up to twice as fast at the near-prime lengths a recording has
    w = sfft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / sample_rate)
    idx = np.searchsorted(f, np.asarray(edges_hz, dtype=np.float64), side="left")
    gain = np.zeros(f.size)
    for b, ms in enumerate(np.asarray(mean_square, dtype=np.float64).tolist()):
        i0, i1 = int(idx[b]), int(idx[b + 1])
        if i1 <= i0 or not ms > 0.0:
            continue
        have = 2.0 * float(np.sum(np.abs(w[i0:i1]) ** 2)) / n**2  # one-sided: the band's mean square
        gain[i0:i1] = np.sqrt(ms / max(have, 1e-300))
    return np.asarray(sfft.irfft(w * gain, n), dtype=np.float64)


def bursts(n: int, sample_rate: int, spans_s: list[tuple[float, float]], ramp_s: float = 0.005) -> FloatArray:
    """An envelope (0 to 1) that is 1 over each (start, duration) in ``spans_s``, s, with raised-cosine ramps."""
    env = np.zeros(n)
    r = max(1, int(ramp_s * sample_rate))
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(r) / r)
    for start, dur in spans_s:
        i0 = max(0, int(start * sample_rate))
        i1 = min(n, int((start + dur) * sample_rate))
        if i1 - i0 < 2 * r:
            continue
        env[i0:i1] = 1.0
        env[i0 : i0 + r] = ramp
        env[i1 - r : i1] = ramp[::-1]
    return env
