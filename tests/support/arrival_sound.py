"""A fifth, independent sound generator: the stop arrives over a few steps, in a room, under a wandering clock.

Written in round 8b to ask one question of the confirmed detector - is a stop ever
counted at a wrong time without the ``onset_uncertain`` flag? - from another view of the
physics than the four generators before it (the simulator's, ``alien_sound``,
``battery_sound``, ``modal_sound``), and never used to tune the detector:

* **a slip is a force pulse, not an impulse**: a half-sine of 0.2-0.8 ms (drawn per arm)
  drives five structural modes drawn log-uniform over 1.5-14 kHz with their own Q; the
  contact point wanders from step to step, so each step's sound is its own mix of two
  such rings (a step-to-step spectral variation the other generators do not have);
* **the stop arrives as the joint decelerates against it**: over ``arrive_steps`` steps
  the slip's ring crossfades (raised cosine) from the stepping's to the stop's, the
  steps getting weaker as the slider loads the stop; the true stop (what a traverse
  should count to) is the middle of the crossfade, ``stop_at``. The stop's own sound is
  one of three contact views: ``stiff`` (the contact adds a stiff mode of its own and
  the slider's ring is damped to 0.6), ``damped`` (the contact damps every mode: Q
  halved, 0.5 in amplitude), ``shifted`` (the contact pins the arm: every mode moves up
  by 4-12 %, same energy);
* **the clock**: a nominal rate whose period jitters by ``jitter`` (a fraction, per
  step) and wanders slowly (a sum of two sinusoids of periods 0.7-4 s, ``wander`` of
  the rate peak to peak) - not the battery's linear ramp;
* **the room**: the sound reaches the microphone through a room (direct path plus an
  exponentially decaying reverberation tail of T60 ``t60_s``, 0.05-0.4 s, at
  ``reverb_db`` re the direct path), so a stop's onset is smeared by the room too;
  pink noise at ``snr_db``;
* **interference around the stop**: one burst starting at ``stop_at + burst_from``
  (``burst_from`` -0.5 to +0.4 s: just before, across, or just after the stop) lasting
  ``burst_s``, at ``burst_db`` re the stepping RMS, of one kind: ``hiss`` (band-passed
  noise over 3-12 kHz, an air jet or a fricative), ``chirp`` (a tone gliding over
  1.5-9 kHz, a squeak), ``voice`` (a harmonic complex at 110-260 Hz through two formants
  with a fricative tail), ``clatter`` (a run of 4-12 short knocks), or ``none``.

Levels: the stepping sound before the stop is -30 dBFS RMS (before the room's gain).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, fftconvolve, lfilter, sosfilt

SR = 48_000
STOP_KINDS = ("stiff", "damped", "shifted")
BURSTS = ("none", "hiss", "chirp", "voice", "clatter")
STEP_DB = -30.0


@dataclass(frozen=True)
class Arm:
    """One arm: its modes and its slip's force pulse (drawn from ``seed``)."""

    seed: int = 1
    stop_kind: str = "stiff"


@dataclass(frozen=True)
class Scene:
    """One recording of an arm stepping into its stop (``stop_at`` None: never)."""

    arm: Arm = Arm()
    rate: float = 1000.0
    stop_at: float | None = 2.0
    dur: float = 3.0
    arrive_steps: int = 4
    jitter: float = 0.01
    wander: float = 0.0
    t60_s: float = 0.15
    reverb_db: float = -10.0
    snr_db: float = 35.0
    burst: str = "none"
    burst_from: float = 0.0  # the burst starts this long after the stop (negative: before it), s
    burst_s: float = 0.3
    burst_db: float = 0.0
    seed: int = 0
    sr: int = SR


def _ring(sr: int, f: np.ndarray, q: np.ndarray, w: np.ndarray, pulse_s: float, length_s: float = 0.015) -> np.ndarray:
    """The modes' response to a half-sine force pulse of ``pulse_s``."""
    t = np.arange(int(length_s * sr)) / sr
    h = np.zeros_like(t)
    for fi, qi, wi in zip(f, q, w, strict=True):
        if fi < 0.45 * sr:
            h += wi * np.exp(-np.pi * fi / qi * t) * np.sin(2 * np.pi * fi * t)
    m = max(2, int(round(pulse_s * sr)))
    pulse = np.sin(np.pi * (np.arange(m) + 0.5) / m)
    out = np.convolve(h, pulse)[: t.size]
    return np.asarray(out / np.sqrt(np.sum(out**2)), dtype=np.float64)


def arm_kernels(arm: Arm, sr: int = SR) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rings of a slip at the two ends of the contact point's wander, stepping and at the stop."""
    r = np.random.default_rng(10_000 + arm.seed)
    f = np.exp(r.uniform(np.log(1500.0), np.log(14000.0), 5))
    q = r.uniform(12.0, 50.0, 5)
    wa, wb = r.uniform(0.2, 1.0, 5), r.uniform(0.2, 1.0, 5)
    pulse = r.uniform(0.2e-3, 0.8e-3)
    step_a, step_b = _ring(sr, f, q, wa, pulse), _ring(sr, f, q, wb, pulse)
    if arm.stop_kind == "stiff":
        fs, qs = r.uniform(2500.0, 9000.0, 1), r.uniform(30.0, 80.0, 1)
        extra = _ring(sr, fs, qs, np.ones(1), pulse)
        stop_a, stop_b = 0.6 * step_a + 1.2 * extra, 0.6 * step_b + 1.2 * extra
    elif arm.stop_kind == "damped":
        stop_a, stop_b = 0.5 * _ring(sr, f, q / 2, wa, pulse), 0.5 * _ring(sr, f, q / 2, wb, pulse)
    elif arm.stop_kind == "shifted":
        up = r.uniform(1.04, 1.12)
        stop_a, stop_b = _ring(sr, f * up, q, wa, pulse), _ring(sr, f * up, q, wb, pulse)
    else:
        raise ValueError(f"unknown stop kind {arm.stop_kind!r}")
    return step_a, step_b, stop_a, stop_b


def step_times(s: Scene, rng: np.random.Generator) -> np.ndarray:
    """The slips' times, s: a jittered clock whose rate wanders slowly."""
    p1, p2 = rng.uniform(0.7, 4.0, 2)
    ph1, ph2 = rng.uniform(0, 2 * np.pi, 2)
    times, t = [], float(rng.uniform(0, 1 / s.rate))
    while t < s.dur:
        times.append(t)
        wob = 0.25 * s.wander * (np.sin(2 * np.pi * t / p1 + ph1) + np.sin(2 * np.pi * t / p2 + ph2))
        t += (1.0 + s.jitter * rng.standard_normal()) / (s.rate * (1.0 + wob))
    return np.asarray(times)


def _burst(s: Scene, n: int, rng: np.random.Generator) -> np.ndarray:
    sr = s.sr
    m = max(1, int(s.burst_s * sr))
    t = np.arange(m) / sr
    if s.burst == "hiss":
        lo = rng.uniform(3000.0, 6000.0)
        sos = butter(4, [lo / (sr / 2), min(rng.uniform(8000.0, 12000.0), 0.45 * sr) / (sr / 2)], "band", output="sos")
        b = sosfilt(sos, rng.standard_normal(m))
    elif s.burst == "chirp":
        f0, f1 = rng.uniform(1500.0, 9000.0, 2)
        b = np.sin(2 * np.pi * np.cumsum(np.linspace(f0, f1, m)) / sr)
    elif s.burst == "voice":
        f0 = rng.uniform(110.0, 260.0) * (1 + 0.02 * np.sin(2 * np.pi * 5.0 * t))
        src = np.diff(np.floor(np.cumsum(f0) / sr), prepend=0.0)
        src = lfilter([1.0], [1.0, -0.9], src)
        b = np.zeros(m)
        for fk, bw in ((rng.uniform(400, 900), 80.0), (rng.uniform(1200, 3200), 120.0)):
            rr = np.exp(-np.pi * bw / sr)
            b += lfilter([1 - rr], [1, -2 * rr * np.cos(2 * np.pi * fk / sr), rr * rr], src)
        tail = int(0.3 * m)
        sos = butter(2, 4000 / (sr / 2), "high", output="sos")
        b[m - tail :] += 0.6 * np.std(b) * sosfilt(sos, rng.standard_normal(tail))
    elif s.burst == "clatter":
        b = np.zeros(m)
        for tk in rng.uniform(0, s.burst_s, int(rng.integers(4, 13))):
            i, k = int(tk * sr), int(0.02 * sr)
            seg = rng.standard_normal(k) * np.exp(-np.arange(k) / (0.002 * sr))
            b[i : i + k] += seg[: m - i]
    else:
        raise ValueError(f"unknown burst {s.burst!r}")
    edge = min(m // 2, int(0.005 * sr))  # 5 ms ramps: no click at its ends beyond the burst's own
    if edge > 0:
        ramp = np.sin(0.5 * np.pi * np.arange(edge) / edge) ** 2
        b[:edge] *= ramp
        b[m - edge :] *= ramp[::-1]
    return np.asarray(b / (np.sqrt(np.mean(b**2)) + 1e-30), dtype=np.float64)


def render(s: Scene) -> np.ndarray:
    """The scene's samples (mono, float32)."""
    sr, n = s.sr, int(round(s.dur * s.sr))
    rng = np.random.default_rng(s.seed)
    step_a, step_b, stop_a, stop_b = arm_kernels(s.arm, sr)
    times = step_times(s, rng)
    if s.stop_at is None:
        w = np.zeros(times.size)
    else:  # the crossfade over arrive_steps steps, centred on stop_at
        k = np.arange(times.size) - np.searchsorted(times, s.stop_at)
        half = max(s.arrive_steps, 1) / 2.0
        w = np.clip((k + half) / (2 * half), 0.0, 1.0)
        w = 0.5 - 0.5 * np.cos(np.pi * w)
    amp = rng.uniform(0.8, 1.2, times.size) * (1.0 - 0.3 * w * (1.0 - w) * 4)  # weaker while it loads the stop
    mix = rng.uniform(0.0, 1.0, times.size)  # where on the contact this slip happened
    idx = np.minimum((times * sr).astype(np.int64), n - 1)
    x = np.zeros(n)
    for kern, weight in (
        (step_a, (1 - w) * (1 - mix)),
        (step_b, (1 - w) * mix),
        (stop_a, w * (1 - mix)),
        (stop_b, w * mix),
    ):
        train = np.zeros(n)
        np.add.at(train, idx, amp * weight)
        x += fftconvolve(train, kern)[:n]
    end = n if s.stop_at is None else int(min(max(s.stop_at - 0.05, 0.2), s.dur) * sr)
    x *= 10 ** (STEP_DB / 20) / (np.sqrt(np.mean(x[:end] ** 2)) + 1e-30)
    rms = 10 ** (STEP_DB / 20)
    if s.t60_s > 0:
        L = int(s.t60_s * sr)
        tail = rng.standard_normal(L) * np.exp(-6.9 * np.arange(L) / L)
        tail *= 10 ** (s.reverb_db / 20) / np.sqrt(np.sum(tail**2))
        tail[0] += 1.0
        x = fftconvolve(x, tail)[:n]
    noise = lfilter([1.0, -0.97], [1.0], rng.standard_normal(n))
    x += noise / np.std(noise) * rms * 10 ** (-s.snr_db / 20)
    if s.burst != "none" and s.stop_at is not None:
        b = _burst(s, n, rng) * rms * 10 ** (s.burst_db / 20)
        i0 = int((s.stop_at + s.burst_from) * sr)
        lo, hi = max(i0, 0), min(i0 + b.size, n)
        if hi > lo:
            x[lo:hi] += b[lo - i0 : hi - i0]
    return np.asarray(x, dtype=np.float32)


def draw(rng: np.random.Generator, burst: str | None = None) -> Scene:
    """A random scene: arm, stop kind, rate, clock, room and a burst around the stop."""
    arm = Arm(int(rng.integers(1, 1000)), str(rng.choice(STOP_KINDS)))
    return Scene(
        arm=arm,
        rate=float(rng.uniform(800.0, 1300.0)),
        stop_at=float(rng.uniform(1.5, 2.5)),
        dur=3.5,
        arrive_steps=int(rng.integers(1, 12)),
        jitter=float(rng.uniform(0.002, 0.03)),
        wander=float(rng.uniform(0.0, 0.06)),
        t60_s=float(rng.uniform(0.05, 0.4)),
        reverb_db=float(rng.uniform(-18.0, -6.0)),
        snr_db=float(rng.uniform(20.0, 40.0)),
        burst=str(rng.choice(BURSTS)) if burst is None else burst,
        burst_from=float(rng.uniform(-0.5, 0.4)),
        burst_s=float(rng.uniform(0.05, 1.2)),
        burst_db=float(rng.uniform(-8.0, 6.0)),
        seed=int(rng.integers(1, 10**6)),
    )


def tuning_scene(arm: Arm, rate: float = 1000.0) -> Scene:
    """The arm's clean tuning recording: stepping 2 s, the stop 1.5 s, a quiet room."""
    return Scene(arm=arm, rate=rate, stop_at=2.0, dur=3.5, arrive_steps=1, jitter=0.005, t60_s=0.1, seed=7)
