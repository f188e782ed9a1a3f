"""A sixth, independent sound generator: a slender arm whose tip the stop pins.

Written in round 9b to ask whether a stop that *only shifts the spectrum* is heard, from
another view of the physics than ``arrival_sound``'s ``shifted`` stop (five modes all
moved up by one factor) and never used to tune the detector:

* **the arm is an Euler-Bernoulli beam**, clamped at the joint and free at the tip while
  it steps: its modes are the roots of ``1 + cos(b) cosh(b) = 0`` (``b = beta L``: 1.875,
  4.694, 7.855, ... then ``(2n - 1) pi / 2``), ``f_n = f_1 (b_n / b_1)**2``. The arm is
  slender (``f_1`` 2-5 Hz), so the audible modes (1.5-14 kHz) are of order 10-50, dense
  and each with its own shape;
* **at the stop the tip is pinned** (the contact holds it): the modes become those of a
  clamped-pinned beam, roots of ``tan(b) = tanh(b)`` (3.927, 7.069, ... ``(4n + 1) pi / 4``):
  mode ``n`` moves up by ``((4n + 1) / (4n - 2))**2 - 1``, about ``1.5 / n`` (9 % at
  order 16, 3 % at order 50) - a shift that *falls with frequency*, not one factor
  for all; the mode shapes change with it, so how strongly the slip excites each mode
  and the microphone hears it changes too. How loud the stop is: ``Scene.stop_scale``
  (below);
* **a slip is an impulse** (a tap) at a point ``x_e`` along the arm, heard as the
  velocity at ``x_m``; every mode rings with the same Q (15-60); modes under 200 Hz
  (the arm's slow sway) are left out;
* **the clock** jitters per step (``jitter``, a fraction of the period), the slips'
  strength varies +-20 %, pink noise at ``snr_db``; no room, no interference.

Levels: the stepping sound before the stop is -30 dBFS RMS. The stop's loudness against it, ``Scene.stop_scale``:

* ``"recording"`` (the default; the convention the generator was written with): each recording's stop is scaled to
  sound as loud as *that recording's* stepping (their RMS at the microphone), so that at the tuning's rate only the
  spectrum changes. At another step rate the stepping's and the stop's lines fall on the modes differently, so this
  factor moves with the rate: a gain on the stop of -7 to +11 dB against the tuning recording's (audio49) that no
  property of the arm sets;
* ``"arm"`` (the physical view): the stop's factor is fixed per arm, the one the arm's tuning recording
  (:func:`tuning_scene`) gives, and every recording of the arm uses it. A stop's loudness is set by its source (the
  same slips through the pinned arm's modes), not by how loud the stepping happens to be at the rate; the stop's
  RMS against the stepping then follows the two sets of modes at the rate's lines. At the tuning recording the two
  modes render the same samples.

Every random draw is the same in both modes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.optimize import brentq
from scipy.signal import fftconvolve, lfilter

SR = 48_000
STEP_DB = -30.0
#: modes below this are left out (the arm's slow sway: below the detector's 300 Hz floor, and, ringing long, they
#: would hold most of a slip's energy)
F_LOW_HZ = 200.0
#: how the stop's loudness is set (module docstring): per recording (the default) or fixed per arm
STOP_SCALES = ("recording", "arm")


@dataclass(frozen=True)
class Beam:
    """One arm: its fundamental, Q, tap and microphone points (drawn from ``seed``)."""

    seed: int = 1


@dataclass(frozen=True)
class Scene:
    """One recording of the arm stepping into its stop at ``stop_at`` s (None: never)."""

    beam: Beam = Beam()
    rate: float = 1000.0
    stop_at: float | None = 2.0
    dur: float = 3.5
    jitter: float = 0.01
    snr_db: float = 35.0
    seed: int = 0
    sr: int = SR
    #: one of :data:`STOP_SCALES`: the stop scaled to this recording's stepping RMS, or by the arm's fixed factor
    stop_scale: str = "recording"


def _free(b: float) -> float:
    """Clamped-free frequency equation, ``cos(b) + 1 / cosh(b)`` (zero at a mode; finite at any ``b``)."""
    return float(np.cos(b) + 1.0 / np.cosh(b))


def _pinned(b: float) -> float:
    """Clamped-pinned frequency equation, ``sin(b) - cos(b) tanh(b)``."""
    return float(np.sin(b) - np.cos(b) * np.tanh(b))


def roots(pinned: bool, n: int) -> np.ndarray:
    """The first ``n`` roots ``b_k = beta_k L`` of the clamped-free (or clamped-pinned) beam."""
    out = []
    for k in range(1, n + 1):
        guess = (4 * k + 1) * np.pi / 4 if pinned else (2 * k - 1) * np.pi / 2
        out.append(brentq(_pinned if pinned else _free, guess - 0.4, guess + 0.4))
    return np.asarray(out)


def shapes(b: np.ndarray, pinned: bool, x: np.ndarray) -> np.ndarray:
    """Mode shapes (modes x points) at ``x`` (fractions of the length), unit RMS over the arm.

    ``w = cos(bx) - s sin(bx) - [cosh(bx) - s sinh(bx)]`` with ``s`` from the tip's
    condition; the bracket, ``((1 - s) e^(bx) + (1 + s) e^(-bx)) / 2``, is formed from
    ``1 - s`` written without the cancelling hyperbolic terms (they reach 1e80 here).
    """
    bb = b[:, None]
    c, si, e = np.cos(bb), np.sin(bb), np.exp(-bb)
    if pinned:  # w(L) = 0
        s = (np.cosh(bb) - c) / (np.sinh(bb) - si)
        one_minus = 2 * (c - si - e) / (1 - e**2 - 2 * si * e)
    else:  # w''(L) = 0
        s = (c + np.cosh(bb)) / (si + np.sinh(bb))
        one_minus = 2 * (si - c - e) / (1 - e**2 + 2 * si * e)
    xx = np.asarray(x, dtype=np.float64)[None, :]
    bracket = 0.5 * (one_minus * np.exp(bb * (xx - 1)) + (1 + s) * np.exp(-bb * xx))
    return np.asarray(np.cos(bb * xx) - s * np.sin(bb * xx) - bracket)


def beam_modes(beam: Beam, sr: int = SR) -> dict[str, Any]:
    """Stepping's and the stop's modes from :data:`F_LOW_HZ` to 0.45 fs: frequencies (Hz), gains (tap x microphone
    shapes) and orders (``step_n``, ``stop_n``: mode ``n`` of the free arm becomes mode ``n`` of the pinned one); Q."""
    r = np.random.default_rng(20_000 + beam.seed)
    f1 = float(np.exp(r.uniform(np.log(2.0), np.log(5.0))))
    q = float(r.uniform(15.0, 60.0))
    x_e, x_m = float(r.uniform(0.1, 0.45)), float(r.uniform(0.55, 0.9))
    n = int(np.sqrt(0.45 * sr / f1 / 0.70)) // 2 + 3
    grid = np.linspace(0.0, 1.0, 8001)
    out: dict[str, Any] = {"q": q, "f1": f1}
    b1 = roots(False, 1)[0]
    for name, pinned in (("step", False), ("stop", True)):
        b = roots(pinned, n)
        f = f1 * (b / b1) ** 2
        rms = np.sqrt(np.mean(shapes(b, pinned, grid) ** 2, axis=1))
        w = shapes(b, pinned, np.array([x_e, x_m])) / rms[:, None]
        keep = (f > F_LOW_HZ) & (f < 0.45 * sr)
        out[f"{name}_f"], out[f"{name}_g"] = f[keep], (w[:, 0] * w[:, 1])[keep]
        out[f"{name}_n"] = np.flatnonzero(keep) + 1  # the modes' orders
    return out


def _kernel(f: np.ndarray, g: np.ndarray, q: float, sr: int, length_s: float = 0.06) -> np.ndarray:
    """The velocity at the microphone after a unit tap: each mode a decaying cosine."""
    t = np.arange(int(length_s * sr)) / sr
    w = 2 * np.pi * f[:, None]
    return np.asarray(np.sum(g[:, None] * np.exp(-w / (2 * q) * t) * np.cos(w * t), axis=0))


def _parts(s: Scene, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The stepping's and the stop's sound, unscaled (the clock, jitter and slip strengths drawn from ``rng``)."""
    sr, n = s.sr, int(round(s.dur * s.sr))
    m = beam_modes(s.beam, sr)
    q = float(m["q"])
    k_step = _kernel(m["step_f"], m["step_g"], q, sr)
    k_stop = _kernel(m["stop_f"], m["stop_g"], q, sr)
    times, t = [], float(rng.uniform(0, 1 / s.rate))
    while t < s.dur:
        times.append(t)
        t += (1.0 + s.jitter * rng.standard_normal()) / s.rate
    tt = np.asarray(times)
    amp = rng.uniform(0.8, 1.2, tt.size)
    idx = np.minimum((tt * sr).astype(np.int64), n - 1)
    stopped = np.zeros(tt.size, dtype=bool) if s.stop_at is None else tt >= s.stop_at
    parts = []
    for kern, sel in ((k_step, ~stopped), (k_stop, stopped)):
        train = np.zeros(n)
        np.add.at(train, idx[sel], amp[sel])
        parts.append(fftconvolve(train, kern)[:n])
    return parts[0], parts[1]


def _own_scale(s: Scene, x_step: np.ndarray, x_stop: np.ndarray) -> float:
    """The factor that makes this recording's stop as loud as its stepping (RMS, 0.2 s on to 0.05 s before the stop
    against 0.1 s after it to the end)."""
    assert s.stop_at is not None
    sr, n = s.sr, x_step.size
    i0 = int(s.stop_at * sr)
    i_step, i_stop = slice(int(0.2 * sr), max(int(0.2 * sr) + 1, i0 - int(0.05 * sr))), slice(i0 + int(0.1 * sr), n)
    return float(np.sqrt(np.mean(x_step[i_step] ** 2) / (np.mean(x_stop[i_stop] ** 2) + 1e-30)))


@lru_cache(maxsize=64)
def arm_stop_scale(beam: Beam, sr: int = SR) -> float:
    """The arm's fixed stop factor (``stop_scale="arm"``): the one its tuning recording's own stepping gives."""
    s = replace(tuning_scene(beam), sr=sr)
    x_step, x_stop = _parts(s, np.random.default_rng(s.seed))
    return _own_scale(s, x_step, x_stop)


def stop_factor(s: Scene, x_step: np.ndarray, x_stop: np.ndarray) -> float:
    """The factor on the scene's unscaled stop, as ``s.stop_scale`` sets it (module docstring)."""
    if s.stop_scale not in STOP_SCALES:
        raise ValueError(f"stop_scale {s.stop_scale!r}: choose from {', '.join(STOP_SCALES)}")
    if s.stop_scale == "arm":
        return arm_stop_scale(s.beam, s.sr)
    return _own_scale(s, x_step, x_stop)


def render(s: Scene) -> np.ndarray:
    """The scene's samples (mono, float32)."""
    sr, n = s.sr, int(round(s.dur * s.sr))
    rng = np.random.default_rng(s.seed)
    x_step, x_stop = _parts(s, rng)
    if s.stop_at is not None and np.any(x_stop):  # the stop's loudness: Scene.stop_scale
        x_stop *= stop_factor(s, x_step, x_stop)
    x = x_step + x_stop
    end = n if s.stop_at is None else int(max(s.stop_at - 0.05, 0.2) * sr)
    rms = 10 ** (STEP_DB / 20)
    x *= rms / (np.sqrt(np.mean(x[:end] ** 2)) + 1e-30)
    noise = lfilter([1.0, -0.97], [1.0], rng.standard_normal(n))
    x += noise / np.std(noise) * rms * 10 ** (-s.snr_db / 20)
    return np.asarray(x, dtype=np.float32)


def tuning_scene(beam: Beam, rate: float = 1000.0) -> Scene:
    """The arm's clean tuning recording: stepping 2 s, the stop 1.5 s."""
    return Scene(beam=beam, rate=rate, stop_at=2.0, dur=3.5, jitter=0.005, snr_db=40.0, seed=7)
