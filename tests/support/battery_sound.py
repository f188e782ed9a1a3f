"""A third, independent sound generator for the audio battery (neither the simulator's nor alien_sound's).

Other sound design on purpose:

* **stepping**: every step is an impulse (amplitude +-20 %, timing jitter 20 us) that
  excites a bank of modal resonators (two-pole IIR filters, constant Q), four modes per
  joint; the controller's step clock runs at ``rate`` Hz;
* **the stop**, five kinds: ``louder`` (the stop adds a strong mode of its own),
  ``quieter`` (the stop soaks up the impulse: -8 dB on every mode), ``duller`` (the
  modes above 4 kHz vanish, -20 dB), ``brighter`` (the modes above 4 kHz ring +12 dB
  louder) and ``spectral`` (the contact stiffens: the second mode moves down by a
  fifth, the level stays the same); the stop may fade in over ``fade_s`` (the contact
  builds up gradually) or be there from the first sample (``stop_at=0``);
* **the step clock** may drift linearly by ``drift`` (a fraction: 0.1 is from -10 % to
  +10 % of ``rate`` over the recording);
* **room**: white noise through a first-order low-pass; optional white noise at a set
  SNR; a fan (low-passed noise, blade-pass lines at 87 Hz and harmonics, a motor whine
  near 3.1 kHz); 60 Hz mains hum with odd harmonics; knocks (a 40-150 Hz table mode and
  a broadband contact burst); a door slam (a 35-70 Hz thump ringing 0.2 s, a rattle of
  frame modes, a latch click); a second instrument stepping at another rate through its
  own modes; speech from ``espeak-ng`` (if installed) or a formant babble built in the
  frequency domain; clipping; 44.1 kHz or 22.05 kHz; 8-bit quantisation; stereo (the
second channel delayed and quieter).

Levels: the stepping sound is -28 dBFS RMS at 0 dB gain; interference levels are set
relative to the stepping RMS.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy.signal import lfilter, resample_poly

MODES = {  # joint: (stepping modes (Hz, bandwidth Hz, gain), the louder stop's own mode)
    "P": (((1700, 120, 1.0), (3300, 200, 0.8), (6100, 300, 0.6), (9400, 500, 0.5)), (5200, 150, 2.0)),
    "Q": (((2100, 150, 1.0), (4500, 250, 0.7), (7600, 400, 0.5), (11800, 700, 0.4)), (3600, 120, 2.2)),
}
SECOND = ((2600, 180, 1.0), (5400, 260, 0.7), (8800, 400, 0.5))
STEP_DB = -28.0


@dataclass(frozen=True)
class Scene:
    """One recording: stepping at ``rate`` Hz from 0 s, against the stop from ``stop_at`` s (None: never)."""

    joint: str = "P"
    rate: float = 1000.0
    stop_at: float | None = 2.0
    dur: float = 3.0
    seed: int = 0
    sr: int = 48_000
    stop_kind: str = "louder"
    gain_db: float = 0.0
    snr_db: float | None = None
    knocks_every_s: float | None = None
    door_at: float | None = None
    speech: str | None = None  # "espeak", "espeak2" (a second talker: another voice, pitch and text) or "babble"
    speech_db: float = -3.0
    second_rate: float | None = None
    second_from: float = 0.0
    fan: bool = False
    hum: bool = False
    clip_x_rms: float | None = None  # clip at this many times the stepping RMS
    stereo: bool = False
    fade_s: float = 0.0  # the stop fades in over this long, s
    drift: float = 0.0  # the step rate drifts linearly from (1 - drift) to (1 + drift) times rate
    bits: int | None = None  # quantise to this many bits (full scale 1)
    music: bool = False  # a radio: chords of harmonic tones with vibrato and note changes (added in round 2)
    music_db: float = -3.0
    silence: bool = False
    constant: float | None = None


def _res(x: np.ndarray, f: float, bw: float, sr: int) -> np.ndarray:
    r = np.exp(-np.pi * bw / sr)
    return np.asarray(lfilter([1 - r], [1, -2 * r * np.cos(2 * np.pi * f / sr), r * r], x), dtype=float)


def _bank(x: np.ndarray, modes: Sequence[tuple[float, float, float]], sr: int) -> np.ndarray:
    return sum((g * _res(x, f, bw, sr) for f, bw, g in modes if f < 0.45 * sr), np.zeros_like(x))


def _impulses(
    n: int, sr: int, rate: float, rng: np.random.Generator, t0: float = 0.0, drift: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    if drift:  # the clock's phase is the integral of a rate that ramps linearly over the recording
        dur = n / sr
        tt = np.arange(n + 1) / sr
        phase = rate * ((1 - drift) * tt + drift * tt**2 / dur)
        t = np.interp(np.arange(np.ceil(rate * t0), phase[-1]), phase, tt)
    else:
        t = np.arange(t0, n / sr, 1 / rate)
    t = t + rng.normal(0, 20e-6, t.size)
    t = t[(t >= 0) & (t < n / sr)]
    return t, rng.uniform(0.8, 1.2, t.size)


def _train(n: int, sr: int, times: np.ndarray, amps: np.ndarray) -> np.ndarray:
    x = np.zeros(n)
    np.add.at(x, np.minimum((times * sr).astype(np.int64), n - 1), amps)
    return x


_TALKERS = {
    "espeak": (
        [],
        "Please hand me the tweezers. The sample is mounted, the chamber is vented, "
        "and the coffee is getting cold. Seven, eight, nine, ten.",
    ),
    # a second talker (added in round 2, never developed against): a female voice, high pitch, faster, other words
    "espeak2": (
        ["-v", "en+f3", "-p", "85", "-s", "200"],
        "Did you see the seminar announcement? The speaker "
        "moved to room four hundred and twelve, and the projector is broken again, so bring a laptop.",
    ),
}


@lru_cache(maxsize=4)
def espeak_speech(sr: int, talker: str = "espeak") -> np.ndarray | None:
    """A few sentences spoken by espeak-ng, at ``sr``; None when espeak-ng is not installed."""
    exe = shutil.which("espeak-ng")
    if exe is None:
        return None
    opts, text = _TALKERS[talker]
    out = subprocess.run(
        [exe, "--stdout", "-s", "170", *opts, text], capture_output=True, check=True, timeout=30
    ).stdout
    # a RIFF WAV at 22050 Hz, 16-bit mono: find the data chunk
    i = out.find(b"data")
    pcm = np.frombuffer(out[i + 8 :], dtype="<i2").astype(np.float64) / 32768.0
    rate = int.from_bytes(out[24:28], "little")
    g = np.gcd(sr, rate)
    return np.asarray(resample_poly(pcm, sr // g, rate // g))


def _babble(n: int, sr: int, rng: np.random.Generator) -> np.ndarray:
    """Formant babble built per syllable in the frequency domain (harmonics weighted by formant peaks)."""
    out = np.zeros(n)
    i = 0
    while i < n:
        m = int(rng.uniform(0.1, 0.3) * sr)
        f = np.fft.rfftfreq(m, 1 / sr)
        f0 = rng.uniform(100, 250)
        spec = np.zeros(f.size, complex)
        formants = [(rng.uniform(300, 800), 90), (rng.uniform(900, 2200), 130), (rng.uniform(2300, 3300), 200)]
        for h in range(1, int(4000 / f0)):
            k = int(round(h * f0 * m / sr))
            if k < f.size:
                env = sum(1 / (1 + ((h * f0 - F) / B) ** 2) for F, B in formants)
                spec[k] = env / h**0.5 * np.exp(1j * rng.uniform(0, 6.3))
        syl = np.fft.irfft(spec, m) * np.hanning(m)
        out[i : i + m] += syl[: n - i] / (np.std(syl) + 1e-12)
        i += m + int(rng.uniform(0.05, 0.3) * sr)
    return out


def _music(n: int, sr: int, rng: np.random.Generator) -> np.ndarray:
    """A radio: three-note chords of harmonic tones (12 harmonics, 1/h), 5.5 Hz vibrato, a chord every 0.25-0.6 s."""
    out = np.zeros(n)
    t_all = np.arange(n) / sr
    i = 0
    while i < n:
        m = min(int(rng.uniform(0.25, 0.6) * sr), n - i)
        t = t_all[i : i + m]
        root = 110.0 * 2 ** (rng.integers(0, 24) / 12)
        env = np.minimum(1.0, np.minimum(t - t[0], t[-1] - t + 1 / sr) / 0.02)
        for semis in (0, rng.choice((3, 4)), 7):
            f0 = root * 2 ** (semis / 12)
            ph = 2 * np.pi * f0 * (t + 0.015 * np.sin(2 * np.pi * 5.5 * t) / (2 * np.pi * 5.5))  # +-1.5 %
            for h in range(1, 13):
                if h * f0 < 0.45 * sr:
                    out[i : i + m] += env * np.sin(h * ph + rng.uniform(0, 6.3)) / h
        i += m
    return out


def render(s: Scene) -> tuple[np.ndarray, int]:
    """The recording of a scene: float32 samples (n,) or (n, 2) for stereo, and the sample rate."""
    sr, n = s.sr, int(round(s.dur * s.sr))
    rng = np.random.default_rng(s.seed)
    if s.silence:
        return np.zeros(n, np.float32), sr
    if s.constant is not None:
        return np.full(n, s.constant, np.float32), sr
    modes, stop_mode = MODES[s.joint]
    times, amps = _impulses(n, sr, s.rate, rng, drift=s.drift)
    if s.stop_at is None:
        w = np.zeros(times.size)
    elif s.fade_s > 0:
        w = np.clip((times - s.stop_at) / s.fade_s, 0.0, 1.0)
    else:
        w = (times >= s.stop_at).astype(float)
    step = _bank(_train(n, sr, times, amps * (1 - w)), modes, sr)
    stop_train = _train(n, sr, times, amps * w)
    if s.stop_at is not None and s.stop_at < 0.2:  # starts at the stop: the stepping level from a stepping rendering
        step_ref = _bank(_train(n, sr, times, amps), modes, sr)
    else:
        step_ref = step[: int(min(s.stop_at or s.dur, s.dur) * sr)]
    if s.stop_kind == "louder":
        stop = _bank(stop_train, modes, sr) * 0.7 + _bank(stop_train, (stop_mode,), sr)
    elif s.stop_kind == "quieter":
        stop = _bank(stop_train, modes, sr) * 10 ** (-8 / 20)
    elif s.stop_kind == "duller":
        stop = _bank(stop_train, [(f, bw, g * (0.1 if f > 4000 else 1.0)) for f, bw, g in modes], sr)
    elif s.stop_kind == "brighter":
        stop = _bank(stop_train, [(f, bw, g * (4.0 if f > 4000 else 1.0)) for f, bw, g in modes], sr)
    elif s.stop_kind == "spectral":
        moved = [(f * (0.8 if k == 1 else 1.0), bw, g) for k, (f, bw, g) in enumerate(modes)]
        stop = _bank(stop_train, moved, sr)
        full = stop[stop != 0] if (s.stop_at or 0.0) >= 0.2 else _bank(_train(n, sr, times, amps), moved, sr)
        stop *= np.sqrt(np.mean(step_ref[: int(0.9 * step_ref.size)] ** 2) / max(np.mean(full**2), 1e-30))
    else:
        raise ValueError(s.stop_kind)
    x = step + stop
    ref = np.sqrt(np.mean(step_ref**2))
    scale = 10 ** (STEP_DB / 20) / ref
    x *= scale
    rms = 10 ** (STEP_DB / 20)
    x += lfilter([0.1], [1, -0.9], rng.standard_normal(n)) * 10 ** (-65 / 20) / 0.23
    if s.snr_db is not None:
        x += rng.standard_normal(n) * rms * 10 ** (-s.snr_db / 20)
    t = np.arange(n) / sr
    if s.fan:
        fan = lfilter([0.05], [1, -0.95], rng.standard_normal(n))
        fan = fan / np.std(fan) * rms * 10 ** (-10 / 20)
        for k in range(1, 6):
            fan += rms * 10 ** (-14 / 20) / k * np.sin(2 * np.pi * 87.0 * k * t + k)
        fan += rms * 10 ** (-18 / 20) * np.sin(2 * np.pi * 3100.0 * t + 0.3 * np.sin(2 * np.pi * 0.7 * t))
        x += fan
    if s.hum:
        for k, db in ((1, -6), (3, -14), (5, -20), (7, -24), (9, -28), (15, -30)):
            x += rms * 10 ** (db / 20) * np.sin(2 * np.pi * 60.0 * k * t + 0.5 * k)
    if s.knocks_every_s:
        L = int(0.25 * sr)
        tl = np.arange(L) / sr
        for t0 in np.arange(0.4, s.dur - 0.1, s.knocks_every_s) + rng.uniform(-0.05, 0.05):
            i0 = int(t0 * sr)
            knock = np.sin(2 * np.pi * rng.uniform(40, 150) * tl) * np.exp(-tl / 0.06)
            burst = rng.standard_normal(L) * np.exp(-tl / 0.003)
            knock = knock + 0.6 * (burst - lfilter([0.2], [1, -0.8], burst))
            knock *= rms * 10 ** (rng.uniform(6, 20) / 20) / np.max(np.abs(knock))
            x[i0 : i0 + L] += knock[: n - i0]
    if s.door_at is not None:
        L = int(0.8 * sr)
        tl = np.arange(L) / sr
        d = np.sin(2 * np.pi * rng.uniform(35, 70) * tl) * np.exp(-tl / 0.2)
        rattle = sum(_res(rng.standard_normal(L), f, 60, sr) for f in rng.uniform(300, 2000, 5))
        d += 0.8 * rattle / np.max(np.abs(rattle)) * np.exp(-tl / 0.04)
        d[: int(0.002 * sr)] += rng.standard_normal(int(0.002 * sr))
        d *= rms * 10 ** (26 / 20) / np.max(np.abs(d))
        i0 = int(s.door_at * sr)
        x[i0 : i0 + L] += d[: n - i0]
    if s.second_rate is not None:
        tt, aa = _impulses(n, sr, s.second_rate, rng, s.second_from)
        y = _bank(_train(n, sr, tt, aa), SECOND, sr)
        x += y / (np.std(y[int(s.second_from * sr) :]) + 1e-30) * rms * 10 ** (-3 / 20)
    if s.music:
        mu = _music(n, sr, rng)
        x += mu / np.std(mu) * rms * 10 ** (s.music_db / 20)
    if s.speech is not None:
        sp = espeak_speech(sr, s.speech) if s.speech.startswith("espeak") else _babble(n, sr, rng)
        if sp is None:
            raise RuntimeError("espeak-ng is not installed")
        sp = np.resize(sp, n) if sp.size < n else sp[:n]
        voiced = np.abs(sp) > 1e-4
        sp = sp / np.sqrt(np.mean(sp[voiced] ** 2)) * rms * 10 ** (s.speech_db / 20)
        x += np.roll(sp, int(rng.integers(n)))
    x *= 10 ** (s.gain_db / 20)
    if s.clip_x_rms is not None:
        c = s.clip_x_rms * rms * 10 ** (s.gain_db / 20)
        x = np.clip(x, -c, c)
    if s.bits is not None:
        q = 2.0 ** (s.bits - 1)
        x = np.clip(np.round(x * q), -q, q - 1) / q
    if s.stereo:
        delay = 7
        r = np.concatenate((np.zeros(delay), x[:-delay])) * 0.6 + rng.standard_normal(n) * 10 ** (-70 / 20)
        return np.stack((x, r), axis=1).astype(np.float32), sr
    return x.astype(np.float32), sr


def variant(s: Scene, **kw: object) -> Scene:
    """A copy of a scene with some fields changed."""
    return replace(s, **kw)  # type: ignore[arg-type]  # test helper: fields by name
