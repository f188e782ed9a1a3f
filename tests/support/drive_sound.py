"""A seventh, independent sound generator: the piezo's drive sings, and it does not stop at the stop.

Written in session 27, from a view of the sound the six generators before it leave out, and
never used to tune the detector. A stick-slip controller drives the piezo with a sawtooth
(a slow ramp: the stick; a fast fall: the slip). The piezo stack and its mount radiate that
drive themselves, as a loudspeaker would, whether or not the slider moves; what the end
stop changes is only the *mechanical* part, the slider's slip against its rail. So the
sound is two parts:

* **the drive** (``drive_db`` re the slip part's RMS, -10 to +10 dB): the sawtooth's
  voltage (the fall lasts ``fall_us``, 2-20 µs), differentiated once (the stack's
  velocity: a line spectrum flat in harmonic number up to ``1 / (2 fall)``) and heard
  through the mount: three resonances drawn log-uniform over 1-10 kHz, Q 5-20, plus a
  direct path band-passed over 0.5-8 kHz (first order each side). Rendered
  as its Fourier series, it is strictly periodic at the exact rate (a crystal clock) and
  *identical before and after the stop*;
* **the slip** (the slider's): an impulse per step, late on the drive's fall by a
  mechanical lag (50-150 µs) that jitters ±``jitter_us`` µs, its strength scattered ±25 %,
  ringing four arm modes drawn log-uniform over 1.5-12 kHz, Q 8-40 (their amplitudes
  falling as 1/f^0.5 to 1/f^1.5, drawn);
* **at the stop** (``stop_at``, abrupt: the step after it) the slip part becomes one of:
  ``blocked`` (the slider held: the arm's modes hear the slip 6-12 dB weaker and the
  stop's own contact mode rings, 2-8 kHz, Q 20-40, at the arm modes' level); ``muted``
  (the slip all but vanishes, -20 dB: only the drive and a faint rattle remain);
  ``spectral`` (the same energy, the arm modes moved up 5-10 % and their Q halved);
* **noise**: pink at ``snr_db`` re the whole stepping sound.

Levels: the stepping sound before the stop is -28 dBFS RMS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

SR = 48_000
STEP_DB = -28.0
KINDS = ("blocked", "muted", "spectral")


@dataclass(frozen=True)
class Arm:
    """One manipulator: its mount's and arm's modes, lag, stop contact (drawn from ``seed``)."""

    seed: int = 1
    kind: str = "blocked"


@dataclass(frozen=True)
class Scene:
    """One recording: stepping at ``rate`` Hz from 0 s, against the stop from ``stop_at`` s (None: never)."""

    arm: Arm = Arm()
    rate: float = 1000.0
    stop_at: float | None = 2.0
    dur: float = 3.0
    drive_db: float = 0.0
    fall_us: float = 5.0
    jitter_us: float = 15.0
    snr_db: float = 35.0
    seed: int = 0


def _draws(arm: Arm) -> dict[str, np.ndarray | float]:
    rng = np.random.default_rng(7000 + arm.seed)
    return {
        "mount_f": np.exp(rng.uniform(np.log(1000.0), np.log(10_000.0), 3)),
        "mount_q": rng.uniform(5.0, 20.0, 3),
        "arm_f": np.exp(rng.uniform(np.log(1500.0), np.log(12_000.0), 4)),
        "arm_q": rng.uniform(8.0, 40.0, 4),
        "tilt": float(rng.uniform(0.5, 1.5)),
        "lag_s": float(rng.uniform(50e-6, 150e-6)),
        "blocked_db": float(rng.uniform(-12.0, -6.0)),
        "contact_f": float(np.exp(rng.uniform(np.log(2000.0), np.log(8000.0)))),
        "contact_q": float(rng.uniform(20.0, 40.0)),
        "shift": float(rng.uniform(1.05, 1.10)),
    }


def _ring(x: np.ndarray, f: float, q: float, sr: int) -> np.ndarray:
    """``x`` through one two-pole resonance at ``f`` Hz of quality ``q``, unit peak gain."""
    r = np.exp(-np.pi * f / q / sr)
    w = 2 * np.pi * f / sr
    b = [(1 - r) * np.sqrt(1 - 2 * r * np.cos(2 * w) + r * r)]  # unit gain at resonance
    return np.asarray(lfilter(b, [1.0, -2 * r * np.cos(w), r * r], x))


def _bank(x: np.ndarray, fs: np.ndarray, qs: np.ndarray, amps: np.ndarray, sr: int) -> np.ndarray:
    return np.asarray(sum(a * _ring(x, float(f), float(q), sr) for f, q, a in zip(fs, qs, amps, strict=True)))


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else 0.0


def _drive(s: Scene, d: dict[str, np.ndarray | float], n: int, sr: int) -> np.ndarray:
    """The sawtooth's velocity through the mount, as its Fourier series at the exact rate (a crystal clock).

    A ramp from 0 to 1 over ``T - fall`` then back over ``fall`` has, as its second derivative, two impulses of
    strength ``J = 1 / (T - fall) + 1 / fall`` and opposite sign, ``T - fall`` apart: harmonic ``k`` of it is
    ``J / T (1 - exp(-2 pi i k (T - fall) / T))``, of the velocity that over ``2 pi i k / T``. Each harmonic goes
    through the mount's three resonances (analog, unit peak gain) and a direct path band-passed over 0.5-8 kHz, up
    to 0.45 of the sample rate.
    """
    period = 1.0 / s.rate
    fall = min(max(s.fall_us * 1e-6, 1e-7), 0.5 * period)
    jump = 1.0 / (period - fall) + 1.0 / fall
    k = np.arange(1, int(0.45 * sr / s.rate) + 1)
    f = k * s.rate
    # the velocity's series: the acceleration's over 2 pi i f (flat in k up to 1 / (2 fall))
    a_k = jump / period * (1 - np.exp(-2j * np.pi * k * (period - fall) / period)) / (2j * np.pi * f)
    mf, mq = np.asarray(d["mount_f"]), np.asarray(d["mount_q"])
    h = np.sum(1.0 / (1.0 + 1j * mq[:, None] * (f[None, :] / mf[:, None] - mf[:, None] / f[None, :])), axis=0)
    h = h + 0.3 * (1j * f / 500.0) / (1.0 + 1j * f / 500.0) / (1.0 + 1j * f / 8000.0)
    key = (s.rate, fall, sr, mf.tobytes(), mq.tobytes())
    kept = _DRIVES.get(key)
    if kept is not None and kept.size >= n:  # every sample depends on its own time only: a prefix is the same bits
        return kept[:n].copy()
    t = np.arange(n) / sr
    c = a_k * h
    out = np.zeros(n)
    for kk, ck in zip(k, c, strict=True):
        out += np.real(ck * np.exp(2j * np.pi * kk * s.rate * t))
    if len(_DRIVES) >= 64:
        _DRIVES.pop(next(iter(_DRIVES)))
    _DRIVES[key] = out.copy()
    return out


_DRIVES: dict[tuple[float, float, int, bytes, bytes], np.ndarray] = {}
"""The longest drive made so far per rate, fall and mount (a test draws many recordings of one arm at
several drive levels and lengths; the series over all harmonics is most of a recording's cost)."""


def _slips(s: Scene, d: dict[str, np.ndarray | float], n: int, sr: int, rng: np.random.Generator) -> np.ndarray:
    """Impulses late on each fall by the lag, jittered, their strength scattered, as fractional-delay taps."""
    period = 1.0 / s.rate
    k = np.arange(int(s.dur / period) + 2)
    times = (k + 1) * period + float(d["lag_s"]) + rng.uniform(-1, 1, k.size) * s.jitter_us * 1e-6
    amps = 1.0 + rng.uniform(-0.25, 0.25, k.size)
    x = np.zeros(n)
    pos = times * sr
    i = np.floor(pos).astype(int)
    frac = pos - i
    ok = (i >= 0) & (i + 1 < n)
    np.add.at(x, i[ok], amps[ok] * (1 - frac[ok]))
    np.add.at(x, i[ok] + 1, amps[ok] * frac[ok])
    return x


def render(s: Scene) -> np.ndarray:
    """The recording, float64 at 48 kHz, mono."""
    if s.arm.kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {s.arm.kind!r}")
    sr = SR
    n = int(round(s.dur * sr))
    d = _draws(s.arm)
    rng = np.random.default_rng(s.seed)
    taps = _slips(s, d, n, sr, rng)
    af, aq = np.asarray(d["arm_f"]), np.asarray(d["arm_q"])
    amps = (af / af[0]) ** -float(d["tilt"])
    before = _bank(taps, af, aq, amps, sr)
    slip_rms = _rms(before[: int(min(s.dur, 1.0) * sr)])
    drive = _drive(s, d, n, sr)
    drive *= slip_rms * 10 ** (s.drive_db / 20) / max(_rms(drive), 1e-300)
    if s.stop_at is None:
        slip = before
    else:
        k0 = int(round(s.stop_at * sr))
        after_taps = np.where(np.arange(n) >= k0, taps, 0.0)
        taps_before = taps - after_taps
        slip = _bank(taps_before, af, aq, amps, sr)
        if s.arm.kind == "blocked":
            g = 10 ** (float(d["blocked_db"]) / 20)
            contact = _ring(after_taps, float(d["contact_f"]), float(d["contact_q"]), sr)
            contact *= np.max(amps) / max(np.max(np.abs(contact)), 1e-300) * np.max(np.abs(before))
            after = g * _bank(after_taps, af, aq, amps, sr) + g * contact
        elif s.arm.kind == "muted":
            after = 0.1 * _bank(after_taps, af, aq, amps, sr)
        else:  # spectral: same energy, modes up and damped
            after = _bank(after_taps, af * float(d["shift"]), aq / 2, amps, sr)
            seg = slice(k0, min(n, k0 + sr))
            after *= _rms(before[seg]) / max(_rms(after[seg]), 1e-300)
        slip = slip + after
    x = slip + drive
    ref = x[: int(min(s.dur, 1.5 if s.stop_at is None else min(s.stop_at, 1.5)) * sr)]
    white = rng.standard_normal(n)
    pink = np.asarray(
        lfilter(
            [0.049922035, -0.095993537, 0.050612699, -0.004408786], [1, -2.494956002, 2.017265875, -0.522189400], white
        )
    )
    pink *= _rms(ref) * 10 ** (-s.snr_db / 20) / max(_rms(pink), 1e-300)
    x = x + pink
    return np.asarray(x * (10 ** (STEP_DB / 20) / max(_rms(x[: ref.size]), 1e-300)), dtype=np.float64)


def tuning_scene(arm: Arm, drive_db: float = 0.0) -> Scene:
    """The recording ``tune`` learns from: 2 s of stepping at 1000 Hz, then 1.5 s against the stop."""
    return Scene(arm=arm, rate=1000.0, stop_at=2.0, dur=3.5, drive_db=drive_db, seed=10_000 + arm.seed)
