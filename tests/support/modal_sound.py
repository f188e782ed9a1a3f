"""A fourth, independent sound generator: each slip rings the arm's own modes, drawn at random.

Written after the detector, from another view than the simulator's, ``alien_sound``'s
and ``battery_sound``'s, and never used to tune it:

* **the arm**: ``joint_seed`` draws seven structural modes, log-uniform over 1.2-16 kHz,
  each with its own Q (15-60) and weight. A slip is a unit impulse; its sound is the
  12 ms ring of those modes, *added* step after step (overlap-add of one kernel, so the
  rings of successive steps overlap and beat), amplitude +-20 %, timing jitter 2 % of
  the step period (a far rougher clock than the other generators');
* **the stop**, four kinds: ``quieter`` (the slider no longer slips: every ring at 0.45),
  ``duller`` (the contact damps the high modes: a 3 kHz low-pass, +2.3 dB below it),
  ``spectral`` (the contact redistributes the ring over the modes: their weights in
  reverse order, the kernel's energy kept) and ``louder`` (two contact modes of their
  own, 2-9 kHz, ring over the steps, which go down to 0.7);
* **room**: pink-ish noise at ``snr_db``; a *voice* made in the time domain (a glottal
  pulse train at 95-230 Hz with vibrato, through three formant resonators that glide
  from vowel to vowel, in syllables of 80-300 ms with pauses) that may start at the
  first sample, so that it is heard while the detector learns the stepping sound; a
  second instrument (its own modes, stepping at 613 Hz from 0.7 s); knocks; a door
  slam; a fan with 120 Hz hum.

Levels are relative to the stepping sound's RMS; the recording is scaled to a 0.5 peak.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, lfilter

SR = 48_000
KINDS = ("quieter", "duller", "spectral", "louder")


def _modes(rng: np.random.Generator, n: int, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f = np.exp(rng.uniform(np.log(lo), np.log(hi), n))
    return f, rng.uniform(15, 60, n), rng.uniform(0.3, 1.0, n)


def _ring(sr: int, f: np.ndarray, q: np.ndarray, w: np.ndarray, length_s: float = 0.012) -> np.ndarray:
    t = np.arange(int(length_s * sr)) / sr
    out = np.zeros_like(t)
    for fi, qi, wi in zip(f, q, w, strict=True):
        if fi < 0.48 * sr:
            out += wi * np.exp(-np.pi * fi / qi * t) * np.sin(2 * np.pi * fi * t)
    return out


def kernels(joint_seed: int, kind: str, sr: int = SR) -> tuple[np.ndarray, np.ndarray]:
    """The ring of one slip while stepping, and against the stop."""
    jr = np.random.default_rng(joint_seed)
    f, q, w = _modes(jr, 7, 1200, 16000)
    step = _ring(sr, f, q, w)
    if kind == "quieter":
        stop = 0.45 * step
    elif kind == "duller":
        b, a = butter(2, 3000 / (sr / 2))
        stop = lfilter(b, a, step) * 1.3
    elif kind == "spectral":
        stop = _ring(sr, f, q, w[::-1].copy())
        stop *= np.sqrt(np.sum(step**2) / np.sum(stop**2))
    elif kind == "louder":
        fm, qm, wm = _modes(jr, 2, 2000, 9000)
        stop = 0.7 * step + _ring(sr, fm, qm, 1.5 * wm)
    else:
        raise ValueError(f"unknown stop kind {kind!r}")
    return step, stop


def voice(n: int, sr: int, rng: np.random.Generator, start_s: float = 0.0) -> np.ndarray:
    """Syllables of a synthetic voice (unit RMS over its voiced part) from ``start_s``."""
    out = np.zeros(n)
    t = start_s
    formants = ((700, 1200, 2600), (300, 2300, 3000), (500, 900, 2400), (400, 2000, 2800), (650, 1700, 2500))
    while t < n / sr:
        dur = rng.uniform(0.08, 0.3)
        i0, i1 = int(t * sr), min(n, int((t + dur) * sr))
        if i1 - i0 > 16:
            m = i1 - i0
            tt = np.arange(m) / sr
            f0 = rng.uniform(95, 230) * (1 + 0.03 * np.sin(2 * np.pi * 5.5 * tt))
            phase = np.cumsum(f0) / sr
            src = np.diff(np.floor(phase), prepend=0.0)  # one pulse per glottal period
            src = lfilter([1.0], [1.0, -0.95], src)  # the glottal pulse's low-pass tilt
            syl = np.zeros(m)
            fa, fb = formants[rng.integers(len(formants))], formants[rng.integers(len(formants))]
            for k in range(3):  # the formants glide from one vowel to the next (in four pieces)
                for j, seg in enumerate(np.array_split(np.arange(m), 4)):
                    fk = fa[k] + (fb[k] - fa[k]) * (j + 0.5) / 4
                    r = np.exp(-np.pi * (60 + 40 * k) / sr)
                    b, a = [1 - r], [1, -2 * r * np.cos(2 * np.pi * fk / sr), r * r]
                    syl[seg] += lfilter(b, a, src[seg]) / (k + 1)
            if rng.random() < 0.3:  # a fricative: noise above 4 kHz
                b, a = butter(2, 4000 / (sr / 2), "high")
                syl += 0.5 * np.std(syl) * lfilter(b, a, rng.standard_normal(m))
            env = np.sin(np.pi * np.arange(m) / m) ** 0.5
            out[i0:i1] += syl * env
        t += dur + rng.uniform(0.03, 0.25)
    voiced = out[out != 0]
    return out / (np.std(voiced) if voiced.size else 1.0)


@dataclass(frozen=True)
class Scene:
    """One recording: the joint, the stop, the room."""

    joint_seed: int = 1
    kind: str = "spectral"
    stop_at: float | None = 3.0
    dur: float = 6.0
    rate: float = 1000.0
    snr_db: float = 25.0
    voice_db: float | None = None  # the voice's RMS re the stepping's, dB; None: no voice
    voice_from: float = 0.0
    instrument: bool = False
    knocks: bool = False
    door: bool = False
    fan: bool = False
    sr: int = SR
    seed: int = 0


def render(s: Scene) -> np.ndarray:
    """The scene's samples (mono, float64, peak 0.5)."""
    rng = np.random.default_rng(s.seed)
    sr, n = s.sr, int(s.dur * s.sr)
    k_step, k_stop = kernels(s.joint_seed, s.kind, sr)
    x = np.zeros(n + k_step.size)
    t = 0.0
    while t < s.dur:
        i = int(t * sr)
        k = k_step if s.stop_at is None or t < s.stop_at else k_stop
        x[i : i + k.size] += (1 + 0.2 * rng.standard_normal()) * k
        t += (1 + 0.02 * rng.standard_normal()) / s.rate
    x = x[:n]
    p = float(np.mean(x[: int(min(s.stop_at or s.dur, s.dur) * sr)] ** 2))
    noise = lfilter([1.0, -0.98], [1.0], rng.standard_normal(n))
    x += noise * np.sqrt(p / np.mean(noise**2) / 10 ** (s.snr_db / 10))
    tt = np.arange(n) / sr
    if s.voice_db is not None:
        x += voice(n, sr, rng, s.voice_from) * np.sqrt(p) * 10 ** (s.voice_db / 20)
    if s.instrument:
        f2, q2, w2 = _modes(np.random.default_rng(99), 5, 1500, 12000)
        k2 = _ring(sr, f2, q2, w2)
        t2 = 0.7
        while t2 < s.dur:
            i = int(t2 * sr)
            m = min(k2.size, n - i)
            x[i : i + m] += 0.6 * k2[:m]
            t2 += 1 / 613.0
    if s.knocks:
        for tk in rng.uniform(0.5, s.dur - 0.3, 6):
            i, m = int(tk * sr), int(0.05 * sr)
            x[i : i + m] += 8 * np.sqrt(p) * rng.standard_normal(m) * np.exp(-np.arange(m) / (0.006 * sr))
    if s.door:
        i, m = int(rng.uniform(1.0, s.dur - 1) * sr), int(0.4 * sr)
        b, a = butter(2, 400 / (sr / 2))
        th = lfilter(b, a, rng.standard_normal(m))
        x[i : i + m] += 30 * np.sqrt(p) * th / np.std(th) * np.exp(-np.arange(m) / (0.08 * sr))
    if s.fan:
        b, a = butter(2, [200 / (sr / 2), 2000 / (sr / 2)], "band")
        fan = lfilter(b, a, rng.standard_normal(n))
        x += fan / np.std(fan) * np.sqrt(p) * 0.7 + 0.3 * np.sqrt(p) * np.sin(2 * np.pi * 120 * tt)
    return np.asarray(x / np.max(np.abs(x)) * 0.5, dtype=float)
