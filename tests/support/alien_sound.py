"""A second, independent sound generator for the audio tests (not stickslip's synth).

Different physics on purpose: clicks ring two joint resonances; at the stop the clicks
turn dull and the stop rings at its own two frequencies with random strength; pinkish
room noise, 50 Hz hum with harmonics, knocks (a low thump and a contact click), and
speech-like babble (voiced syllables with formants, some fricatives). The detector is
tuned on one recording and judged on others it has not seen.
"""

from __future__ import annotations

import numpy as np

JOINT_SOUNDS = {  # (stepping resonances, stop resonances), Hz
    "A": ((2200, 3900), (5600, 7100)),
    "B": ((1500, 2900), (3300, 4400)),
    "C": ((3000, 5200), (1800, 2600)),
}


def _ring(n: int, sr: int, f: float, tau: float, rng: np.random.Generator) -> np.ndarray:
    t = np.arange(n) / sr
    return np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) * np.exp(-t / tau)


def recording(joint: str, rate: float, stop_at: float | None, dur: float, seed: int, gain_db: float = 0.0,
              knocks: bool = True, babble: bool = True, sr: int = 48_000) -> np.ndarray:
    """Stepping at ``rate`` Hz, against the stop from ``stop_at`` s (None: never), ``dur`` s long."""
    rng = np.random.default_rng(seed)
    f_step, f_stop = JOINT_SOUNDS[joint]
    n = int(dur * sr)
    x = np.zeros(n)
    L = int(0.004 * sr)
    tl = np.arange(L) / sr
    starts = (np.arange(0.2, dur - 0.01, 1 / rate) * sr).astype(int)
    starts = starts[starts + L <= n]
    at_stop = np.zeros(starts.size, bool) if stop_at is None else starts >= stop_at * sr
    for c0 in range(0, starts.size, 4096):  # clicks in chunks, each with its own phases
        s, stop = starts[c0 : c0 + 4096], at_stop[c0 : c0 + 4096]
        m = s.size

        def ring(f: float, tau: float, m: int = m) -> np.ndarray:
            # sin(wt + ph) e^(-t/tau) = (sin wt cos ph + cos wt sin ph) e^(-t/tau)
            ph = rng.uniform(0, 2 * np.pi, (m, 1))
            env = np.exp(-tl / tau)
            out: np.ndarray = np.cos(ph) * (np.sin(2 * np.pi * f * tl) * env) + np.sin(ph) * (
                np.cos(2 * np.pi * f * tl) * env
            )
            return out

        step = 0.05 * ring(f_step[0], 6e-4) + 0.03 * ring(f_step[1], 4e-4)
        step[:, :24] += 0.02 * rng.standard_normal((m, 24))
        a = rng.uniform(0.4, 1.0, (m, 1))
        hit = 0.025 * ring(f_step[0], 4e-4) + a * (0.07 * ring(f_stop[0], 1.2e-3) + 0.04 * ring(f_stop[1], 9e-4))
        clicks = np.where(stop[:, None], hit, step)
        for j in range(L):  # clicks overlap only across chunks of L samples: add column by column
            np.add.at(x, s + j, clicks[:, j])
    w = np.cumsum(rng.standard_normal(n))  # brown noise, then its 0.1 s moving average removed
    c = np.concatenate(([0.0], np.cumsum(w)))
    k = 2400
    lo, hi = np.clip(np.arange(n) - k, 0, n), np.clip(np.arange(n) + k + 1, 0, n)
    w -= (c[hi] - c[lo]) / (hi - lo)
    x += 0.002 * w / np.std(w) + 0.001 * rng.standard_normal(n)
    t = np.arange(n) / sr
    for amp, f, ph in ((0.004, 50, 0.0), (0.002, 150, 1.0), (0.001, 250, 0.0)):  # mains hum
        x += amp * np.sin(2 * np.pi * f * t + ph)
    if knocks:
        for tk in rng.uniform(0.5, dur - 0.5, int(dur / 2.5)):
            i, m = int(tk * sr), int(0.08 * sr)
            knock = 0.3 * _ring(m, sr, rng.uniform(80, 220), 0.015, rng)
            knock[:96] += 0.15 * rng.standard_normal(96)
            x[i : i + m] += knock[: n - i]
    if babble:
        t0 = 0.3
        while t0 < dur - 0.5:
            seg = rng.uniform(0.15, 0.4)
            i0, m = int(t0 * sr), int(seg * sr)
            f0, tt = rng.uniform(100, 220), np.arange(m) / sr
            v = sum(np.sin(2 * np.pi * f0 * h * tt) / h for h in range(1, 30))
            for F in (rng.uniform(300, 900), rng.uniform(900, 2500), rng.uniform(2500, 3500)):
                v += 0.5 * np.sin(2 * np.pi * F * tt) * np.abs(np.sin(2 * np.pi * f0 * tt))
            if rng.random() < 0.3:
                v += 3 * rng.standard_normal(m) * np.sin(np.pi * np.arange(m) / m) ** 2
            x[i0 : i0 + m] += 0.01 * v * np.sin(np.pi * np.arange(m) / m) ** 2
            t0 += seg + rng.uniform(0.05, 0.5)
    return (x * 10 ** (gain_db / 20)).astype(np.float32)
