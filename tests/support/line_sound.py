"""An eighth generator, written for round 12a from another view: the stepping as its harmonic lines.

The battery's and the later generators build a click train in time (a slip rings the arm's
modes, step after step). A train of identical clicks at the step rate ``r`` *is* a sum of
lines at ``k r`` whose amplitudes are the click's spectrum there; this generator writes the
sound that way: ``x(t) = sum_k A_k cos(2 pi k r t + phi_k)``, with ``A_k`` the arm's smooth
envelope (a few resonances) times a per-line factor (the fine structure of the click: where
the slider touches), plus noise. Two kinds of stop:

* ``"damped"`` (for tuning): the lines above :data:`DAMP_FROM_HZ` fall by :data:`DAMP_DB`
  (a stop that a level template hears);
* ``"reshuffled"``: the click's fine structure changes and its broad spectrum does not: every
  line gets a new per-line factor and phase, rescaled so that each group of three neighbouring
  lines keeps its power. Band levels barely move; the lines do. A stop the level template
  cannot hear, by construction - and one the step clock should.

The stop is abrupt at ``stop_at`` (the new click from the first period on). Units: s, Hz, dB.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SR = 48_000
#: the damped stop: lines above this fall, Hz ...
DAMP_FROM_HZ = 4000.0
#: ... by this much, dB
DAMP_DB = 8.0


@dataclass(frozen=True)
class Scene:
    seed: int
    rate_hz: float = 1000.0
    stop_at: float | None = 2.0
    dur: float = 3.0
    kind: str = "reshuffled"  # "damped" or "reshuffled"
    snr_db: float = 30.0
    #: per-line factor's spread, dB (the click's fine structure)
    fine_db: float = 4.0
    #: the arm: seed of its resonances (the same arm for tuning and test)
    arm: int = 1


def _envelope(arm: int, f: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(10_000 + arm)
    h = np.zeros_like(f)
    for _ in range(4):
        fc = float(np.exp(rng.uniform(np.log(1500.0), np.log(10_000.0))))
        q = float(rng.uniform(5.0, 15.0))
        h += 1.0 / np.sqrt(1.0 + (q * (f / fc - fc / np.maximum(f, 1.0))) ** 2)
    return h


def render(s: Scene) -> np.ndarray:
    """The scene's samples (float32, mono, :data:`SR`)."""
    rng = np.random.default_rng(s.seed)
    n = int(round(s.dur * SR))
    t = np.arange(n) / SR
    k = np.arange(1, int(11_500 // s.rate_hz) + 1)
    f = k * s.rate_hz
    env = _envelope(s.arm, f)
    fine = 10 ** (rng.normal(0.0, s.fine_db, k.size) / 20)
    amp0 = env * fine
    ph0 = rng.uniform(0, 2 * np.pi, k.size)
    amp1, ph1 = amp0.copy(), ph0.copy()
    if s.kind == "damped":
        amp1 = np.where(f >= DAMP_FROM_HZ, amp0 * 10 ** (-DAMP_DB / 20), amp0)
    elif s.kind == "reshuffled":
        amp1 = env * 10 ** (rng.normal(0.0, s.fine_db, k.size) / 20)
        ph1 = rng.uniform(0, 2 * np.pi, k.size)
        for g in range(0, k.size, 3):  # each group of three neighbouring lines keeps its power
            sl = slice(g, g + 3)
            amp1[sl] *= np.sqrt(np.sum(amp0[sl] ** 2) / np.sum(amp1[sl] ** 2))
    else:
        raise ValueError(f"unknown stop kind {s.kind!r}")
    stop_n = n if s.stop_at is None else int(round(s.stop_at * SR))
    x = np.zeros(n)
    for a0, p0, a1, p1, fk in zip(amp0, ph0, amp1, ph1, f, strict=True):
        x[:stop_n] += a0 * np.cos(2 * np.pi * fk * t[:stop_n] + p0)
        x[stop_n:] += a1 * np.cos(2 * np.pi * fk * t[stop_n:] + p1)
    x *= 0.1 / np.sqrt(np.mean(x[:stop_n] ** 2))
    x += 0.1 * 10 ** (-s.snr_db / 20) * rng.standard_normal(n)
    return x.astype(np.float32)
