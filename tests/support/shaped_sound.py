"""A fifth sound generator for the tuner's candidate choice: steps as noise bursts, shaped in the frequency domain.

Another view than the simulator's, ``alien_sound``'s, ``battery_sound``'s and
``modal_sound``'s (resonators ringing in the time domain): here the joint's sound is
described only by its *spectral envelope*. Every step is a 0.3 ms burst of white noise
(amplitude +-15 %, timing jitter 1 % of the period); the bursts of each state are summed
into one stream and that stream is given its envelope by one FFT. The states:

* **stepping**: a smooth envelope over 0.8-14 kHz, tilted -3 dB per octave, with a
  +-3 dB ripple;
* **dull moments while stepping** (``dull_share`` of the stepping time, in stretches of
  ``dull_s``): the slider catches, and everything above ``drop_from_hz`` is ``dull_db``
  quieter for a moment (the stepping's own variation, which a tuning must not take for a
  stop);
* **the stop**: ``rise_db`` more in a third of an octave around ``rise_hz`` (a contact
  mode rings) and ``drop_db`` less above ``drop_from_hz`` (the contact damps the high
  modes): a stop that adds sound in a few sub-bands and lowers others; in
  ``weak_drop_share`` of it (stretches of ``dull_s``) the contact damps them only by
  ``weak_drop_db`` (the damping comes and goes, the ring stays).

Interference: a *whistle* (a tone at ``rise_hz`` with 5 Hz vibrato, in bursts of 0.25 s)
that adds sound where the stop does, at ``whistle_db`` re the stepping's power in that
third of an octave.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SR = 48_000


@dataclass(frozen=True)
class Arm:
    """One recording of a joint stepping into its stop."""

    stop_at: float | None = 2.0
    dur: float = 3.0
    rate: float = 1000.0
    rise_hz: float = 3000.0
    rise_db: float = 12.0
    drop_from_hz: float = 6000.0
    drop_db: float = -8.0
    dull_share: float = 0.0
    dull_s: float = 0.06
    dull_db: float = -8.0
    weak_drop_share: float = 0.0
    weak_drop_db: float = -2.0
    whistle_db: float | None = None
    whistle_at: tuple[float, ...] = (0.8, 1.4)
    seed: int = 0
    sr: int = SR


def _envelope(a: Arm, f: np.ndarray, state: str) -> np.ndarray:
    """Amplitude envelope per FFT bin of one state ("step", "dull", "stop")."""
    db = np.where((f >= 800) & (f <= 14000), -3.0 * np.log2(np.maximum(f, 1.0) / 800.0), -60.0)
    db += 3.0 * np.sin(2 * np.pi * np.log2(np.maximum(f, 1.0) / 800.0) * 1.3)
    high = f >= a.drop_from_hz
    if state == "dull":
        db = db + np.where(high, a.dull_db, 0.0)
    elif state in ("stop", "weak"):
        third = np.abs(np.log2(np.maximum(f, 1.0) / a.rise_hz)) <= 1 / 6
        drop = a.drop_db if state == "stop" else a.weak_drop_db
        db = db + np.where(third, a.rise_db, 0.0) + np.where(high, drop, 0.0)
    return np.asarray(10 ** (db / 20), dtype=np.float64)


def render(a: Arm) -> np.ndarray:
    """The recording (mono float64, the stepping at about -30 dBFS RMS)."""
    rng = np.random.default_rng(a.seed)
    sr, n = a.sr, int(a.dur * a.sr)
    dull = np.zeros(n, dtype=bool)
    if a.dull_share > 0:
        t = rng.uniform(0.3, 0.6)
        end = a.stop_at if a.stop_at is not None else a.dur
        while t < end - 0.1:
            if rng.random() < a.dull_share / (a.dull_share + (1 - a.dull_share)):
                dull[int(t * sr) : int(min(t + a.dull_s, end - 0.1) * sr)] = True
            t += a.dull_s * rng.uniform(1.0, 2.0)
    weak = np.zeros(n, dtype=bool)  # moments of the stop whose contact damps the high modes less
    if a.weak_drop_share > 0 and a.stop_at is not None:
        t = a.stop_at + 0.05
        while t < a.dur:
            if rng.random() < a.weak_drop_share:
                weak[int(t * sr) : int((t + a.dull_s) * sr)] = True
            t += a.dull_s
    streams = {k: np.zeros(n) for k in ("step", "dull", "stop", "weak")}
    m = max(2, int(0.0003 * sr))
    burst_env = np.exp(-np.arange(m) / (0.25 * m))
    t = 0.0
    while t < a.dur:
        i = int(t * sr)
        if a.stop_at is not None and t >= a.stop_at:
            state = "weak" if weak[min(i, n - 1)] else "stop"
        else:
            state = "dull" if dull[min(i, n - 1)] else "step"
        j = min(n, i + m)
        streams[state][i:j] += (1 + 0.15 * rng.standard_normal()) * rng.standard_normal(j - i) * burst_env[: j - i]
        t += (1 + 0.01 * rng.standard_normal()) / a.rate
    f = np.fft.rfftfreq(n, 1 / sr)
    x = sum(np.fft.irfft(np.fft.rfft(s) * _envelope(a, f, k), n) for k, s in streams.items())
    x = np.asarray(x, dtype=np.float64)
    step_end = int((a.stop_at if a.stop_at is not None else a.dur) * sr)
    rms = float(np.sqrt(np.mean(x[:step_end] ** 2)))
    x *= 10 ** (-30 / 20) / rms
    if a.whistle_db is not None:
        # the stepping's power in the third of an octave around rise_hz
        X = np.fft.rfft(x[:step_end])
        third = np.abs(np.log2(np.maximum(np.fft.rfftfreq(step_end, 1 / sr), 1.0) / a.rise_hz)) <= 1 / 6
        p_band = 2 * float(np.sum(np.abs(X[third]) ** 2)) / step_end**2
        amp = np.sqrt(2 * p_band * 10 ** (a.whistle_db / 10))
        tt = np.arange(n) / sr
        tone = amp * np.sin(2 * np.pi * a.rise_hz * tt + 0.01 * a.rise_hz / 5 * np.sin(2 * np.pi * 5 * tt))
        gate = np.zeros(n)
        r = int(0.01 * sr)
        for t0 in a.whistle_at:
            i0, i1 = int(t0 * sr), int((t0 + 0.25) * sr)
            gate[i0:i1] = 1.0
            gate[i0 : i0 + r] = np.linspace(0, 1, r)
            gate[i1 - r : i1] = np.linspace(1, 0, r)
        x += tone * gate
    return x
