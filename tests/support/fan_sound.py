"""A tenth, independent sound generator: slip pulses through a bank of resonators, a fan that spins up, pauses.

Written for issue 35 (item 6) before the detector was changed for it, from another view of
the physics than the other generators, and never used to tune the detector:

* **a slip is a force pulse of finite length**: a half-sine of ``tau`` (60-120 µs) whose
  spectrum falls off above ``1 / tau`` with nulls at ``1.5 / tau``, ``2.5 / tau``, ...;
  the arm is a bank of second-order resonators (8-14 modes, 1.2-15 kHz, Q 10-60, each
  with its own gain), driven by the pulses and heard through a first-order 100 Hz
  high-pass (the microphone);
* **at the stop the slider is blocked**: each slip is cut short (``tau`` times
  ``stop_tau``, 0.45-0.75: the spectrum moves up) and its force changes by ``stop_gain``
  (-6 to +4 dB), and the end stop's own body rings (two more resonators, 2-9 kHz);
* **a fan switched on at ``fan_at``** spins up as ``1 - exp(-t / spin_s)``; its sound
  follows the fan laws: blade-pass tone (``blades`` x the shaft rate) and two harmonics
  whose amplitude grows as the speed squared, and turbulent broadband noise (low-passed
  at 2.5 kHz) whose power grows as the speed to the fifth; at full speed its RMS is
  ``fan_db`` relative to the stepping's;
* **pauses**: spans ``(start_s, length_s)`` with no steps (the controller halts and
  resumes), the arm ringing down into the room's noise;
* the clock jitters per step by ``jitter`` of the period; pink room noise at ``snr_db``
  under the stepping.

Levels: the stepping sound is -30 dBFS RMS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import fftconvolve, lfilter

SR = 48_000
STEP_DB = -30.0


@dataclass(frozen=True)
class Drawn:
    """An arm's modes (Hz, Q, peak gain), its slip (s), its stop's change and the end stop's own modes."""

    f: np.ndarray
    q: np.ndarray
    g: np.ndarray
    tau: float
    stop_tau: float
    stop_gain: float
    end_f: np.ndarray
    end_g: np.ndarray


@dataclass(frozen=True)
class Arm:
    """One arm and its end stop, drawn from ``seed``."""

    seed: int

    def draw(self) -> Drawn:
        rng = np.random.default_rng(10_000 + self.seed)
        n = int(rng.integers(8, 15))
        return Drawn(
            f=np.exp(rng.uniform(np.log(1200.0), np.log(15_000.0), n)),
            q=rng.uniform(10.0, 60.0, n),
            g=10 ** (rng.uniform(-12.0, 0.0, n) / 20),
            tau=float(rng.uniform(60e-6, 120e-6)),
            stop_tau=float(rng.uniform(0.45, 0.75)),
            stop_gain=float(10 ** (rng.uniform(-6.0, 4.0) / 20)),
            end_f=np.exp(rng.uniform(np.log(2000.0), np.log(9000.0), 2)),
            end_g=10 ** (rng.uniform(-9.0, -3.0, 2) / 20),
        )


@dataclass(frozen=True)
class Scene:
    """A recording: ``arm`` stepping at ``rate`` Hz, reaching its stop at ``stop_at`` s (None: never)."""

    arm: Arm
    rate: float = 1000.0
    stop_at: float | None = 2.0
    dur: float = 3.2
    fan_at: float | None = None
    fan_db: float = 0.0
    spin_s: float = 0.4
    blades: int = 7
    shaft_hz: float = 40.0
    pauses: tuple[tuple[float, float], ...] = ()
    jitter: float = 0.004
    snr_db: float = 35.0
    seed: int = 0


def _resonators(x: np.ndarray, f: np.ndarray, q: np.ndarray, g: np.ndarray) -> np.ndarray:
    """``x`` through a bank of two-pole resonators (peak gain ``g``) in parallel."""
    out = np.zeros_like(x)
    for fi, qi, gi in zip(f, q, g, strict=True):
        r = np.exp(-np.pi * fi / (qi * SR))
        a = [1.0, -2.0 * r * np.cos(2 * np.pi * fi / SR), r * r]
        out += lfilter([gi * (1.0 - r)], a, x)
    return out


def _pulse(tau: float) -> np.ndarray:
    n = max(2, int(round(tau * SR)))
    return np.asarray(np.sin(np.pi * (np.arange(n) + 0.5) / n), dtype=np.float64)


def _steps(s: Scene, n: int, rng: np.random.Generator) -> np.ndarray:
    """Sample index of every step (the pauses left out)."""
    t, times = float(rng.uniform(0, 1 / s.rate)), []
    while t < n / SR:
        if not any(a <= t < a + d for a, d in s.pauses):
            times.append(t)
        t += (1.0 + s.jitter * rng.standard_normal()) / s.rate
    idx = np.asarray(np.round(np.asarray(times) * SR), dtype=np.int64)
    return idx[idx < n]  # a step within half a sample of the end rounds past it


def _pink(n: int, rng: np.random.Generator) -> np.ndarray:
    w = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / SR)
    w[1:] /= np.sqrt(f[1:])
    w[0] = 0.0
    y = np.fft.irfft(w, n)
    return np.asarray(y / np.sqrt(np.mean(y**2)), dtype=np.float64)


def _fan(s: Scene, n: int, rng: np.random.Generator) -> np.ndarray:
    """The fan's sound, unit RMS at full speed (zero before it is switched on)."""
    assert s.fan_at is not None
    t = np.arange(n) / SR
    on = np.maximum(t - s.fan_at, 0.0)
    speed = np.where(t >= s.fan_at, 1.0 - np.exp(-on / s.spin_s), 0.0)  # share of full speed
    bpf = s.blades * s.shaft_hz * speed
    phase = 2 * np.pi * np.cumsum(bpf) / SR
    tone = np.sin(phase + 1.0) + np.sin(2 * phase + 2.0) / 2 + np.sin(3 * phase + 3.0) / 3
    tone = tone / np.sqrt(1.0 + 1 / 4 + 1 / 9) * np.sqrt(2.0)  # unit RMS at full speed
    noise = lfilter([0.06], [1.0, -0.94], rng.standard_normal(n))  # turbulence: low-passed (2.5 kHz corner)
    noise = noise / np.sqrt(np.mean(noise**2))
    y = 0.6 * speed**2 * tone + 0.8 * speed**2.5 * noise  # amplitude ~ speed^2 (tone), power ~ speed^5 (turbulence)
    return np.asarray(y / np.sqrt(0.36 + 0.64), dtype=np.float64)


def render(s: Scene) -> np.ndarray:
    """The recording, float32 mono at 48 kHz."""
    a = s.arm.draw()
    rng = np.random.default_rng(s.seed)
    n = int(s.dur * SR)
    idx = _steps(s, n, rng)
    amp = 1.0 + 0.15 * rng.standard_normal(idx.size)
    stop = n if s.stop_at is None else int(s.stop_at * SR)
    free, blocked = np.zeros(n), np.zeros(n)
    pre = idx < stop
    np.add.at(free, idx[pre], amp[pre])
    np.add.at(blocked, idx[~pre], amp[~pre] * a.stop_gain)
    at_stop = fftconvolve(blocked, _pulse(a.tau * a.stop_tau))[:n]
    force = fftconvolve(free, _pulse(a.tau))[:n] + at_stop
    y = _resonators(force, a.f, a.q, a.g) + _resonators(at_stop, a.end_f, np.full(2, 30.0), a.end_g)
    y = lfilter([1.0, -1.0], [1.0, -np.exp(-2 * np.pi * 100.0 / SR)], y)  # the microphone's 100 Hz high-pass
    ref = y[: min(stop, n)]
    ref = ref[ref != 0.0] if np.any(ref != 0.0) else y
    scale = 10 ** (STEP_DB / 20) / float(np.sqrt(np.mean(ref**2)))
    y = y * scale
    step_rms = 10 ** (STEP_DB / 20)
    y = y + step_rms * 10 ** (-s.snr_db / 20) * _pink(n, rng)
    if s.fan_at is not None:
        y = y + step_rms * 10 ** (s.fan_db / 20) * _fan(s, n, rng)
    return np.asarray(y, dtype=np.float32)


def tuning_scene(arm: Arm) -> Scene:
    """The arm's tuning recording: 2 s of stepping at 1000 Hz, then 1.2 s at the stop; a quiet room."""
    return Scene(arm=arm, stop_at=2.0, dur=3.2, seed=1)
