"""The recording chain between the arm and the file: a room, a microphone, a sound card.

Every other generator in ``tests/`` makes the arm's sound as if the microphone touched it.
This module is written from the other end: whatever the arm sounds like, a real recording
has passed through

* **a room** (:func:`room`): the microphone hears the direct sound and, after a pre-delay,
  the room's reverberation, an exponentially decaying noise tail that reaches -60 dB after
  ``rt60_s``. How far the microphone is from the arm is ``drr_db``, the direct sound's
  power over the reverberation's: about +20 dB a few cm from the arm, +10 dB at 20-30 cm,
  0 dB at the room's critical distance (about 0.5-1 m in a lab);
* **a microphone** (:func:`headset`): a band-pass, 2nd-order, 200-7000 Hz (a headset or
  webcam capsule);
* **mains and an offset** (:func:`mains`): 50 Hz hum with its 3rd harmonic, and a DC offset;
* **automatic gain control** (:func:`agc`): an envelope follower on 1 ms blocks with an
  attack and a release time constant, and a gain that holds the level at a target (up to a
  maximum gain). A fast one (attack 20 ms) is what many laptop and webcam microphones do; a
  slow one (``rate_db_s``, dB per second at most) is what a sound server's does.

All are plain functions of samples (float arrays in, float arrays out, the length kept).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, fftconvolve, sosfilt


def room(x: np.ndarray, sr: int, rt60_s: float, drr_db: float, seed: int = 0, predelay_s: float = 0.003) -> np.ndarray:
    """``x`` as a microphone in a room hears it: the direct sound plus a reverberant tail."""
    rng = np.random.default_rng(seed)
    n = int(rt60_s * sr)
    t = np.arange(n) / sr
    tail = rng.standard_normal(n) * np.exp(-6.91 * t / rt60_s)  # -60 dB at rt60_s (power: 10^-6)
    tail[: int(predelay_s * sr)] = 0.0
    tail *= np.sqrt(10 ** (-drr_db / 10) / np.sum(tail**2))
    tail[0] = 1.0  # the direct sound
    return np.asarray(fftconvolve(np.asarray(x, float), tail)[: len(x)], float)


def headset(x: np.ndarray, sr: int, lo_hz: float = 200.0, hi_hz: float = 7000.0) -> np.ndarray:
    """A headset or webcam capsule: a 2nd-order band-pass."""
    sos = butter(2, [lo_hz, min(hi_hz, 0.45 * sr)], "bandpass", fs=sr, output="sos")
    return np.asarray(sosfilt(sos, np.asarray(x, float)))


def mains(x: np.ndarray, sr: int, hum_db: float = -3.0, dc: float = 0.02) -> np.ndarray:
    """50 Hz hum (and its 3rd harmonic, 8 dB under) at ``hum_db`` re the RMS of ``x``, and a DC offset."""
    x = np.asarray(x, float)
    t = np.arange(x.size) / sr
    a = np.sqrt(np.mean(x**2)) * 10 ** (hum_db / 20) * np.sqrt(2)
    hum = np.sin(2 * np.pi * 50 * t) + 10 ** (-8 / 20) * np.sin(2 * np.pi * 150 * t + 1.0)
    return np.asarray(x + dc + a * hum, float)


def agc(
    x: np.ndarray,
    sr: int,
    attack_s: float = 0.02,
    release_s: float = 0.5,
    max_gain_db: float = 30.0,
    rate_db_s: float | None = None,
    target: float = 0.1,
) -> np.ndarray:
    """Automatic gain control: the level held at ``target`` RMS.

    A one-pole envelope follower on 1 ms blocks (``attack_s`` when the level rises,
    ``release_s`` when it falls); the gain is ``target`` over the envelope, at most
    ``max_gain_db``; with ``rate_db_s`` it moves towards that at most so many dB per
    second (a slow AGC). The first 0.1 s set the starting gain, as if it had run before.
    """
    x = np.asarray(x, float)
    b = max(1, int(0.001 * sr))
    nb = x.size // b + 1
    pad = np.concatenate((x, np.zeros(nb * b - x.size)))
    level = np.sqrt(np.mean(pad.reshape(nb, b) ** 2, axis=1)) + 1e-12
    ka, kr = np.exp(-b / (attack_s * sr)), np.exp(-b / (release_s * sr))
    env = float(np.sqrt(np.mean(x[: int(0.1 * sr)] ** 2))) + 1e-12
    g_max = 10 ** (max_gain_db / 20)
    g = min(target / env, g_max)
    step = None if rate_db_s is None else 10 ** (rate_db_s * b / sr / 20)
    gains = np.empty(nb)
    for i, v in enumerate(level):
        k = ka if v > env else kr
        env = k * env + (1 - k) * v
        want = min(target / env, g_max)
        g = want if step is None else float(np.clip(want, g / step, g * step))
        gains[i] = g
    centres = (np.arange(nb) + 0.5) * b
    return x * np.interp(np.arange(x.size), centres, gains)
