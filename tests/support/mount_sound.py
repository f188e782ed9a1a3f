"""A ninth, independent generator: an accelerometer on the arm's mount, read by a 5 kHz bridge.

Written for issue 35 before the detector was changed for it, from a view of the physics the
other generators leave out, and never used to tune the detector:

* **the slip is a force, not a sound**: each step the slider's velocity jumps and decays
  (a sawtooth: a slip of ``slip_us`` µs, then the stick), and the reaction on the mount is the
  slider's mass times its acceleration - a short pulse of one sign, then a long weak one of the
  other (the stick phase), whose strength scatters ±15 % and whose timing jitters 1 % of the
  period;
* **the mount is two masses on springs** (the arm's base on the table, the stage on the base):
  two modes, ``f1`` and ``f2`` (drawn 250-600 Hz and 900-1800 Hz) with their damping, computed
  as a two-degree-of-freedom system in state space, not as a bank of resonators; the sensor
  sits on the upper mass;
* **at the stop** the slider is blocked against the end stop: the slip pulse falls to
  ``blocked_gain`` of its strength, and the blocked slider stiffens the upper stage: ``f2``
  moves up by ``stiffen`` and its damping doubles;
* **the sensor and the bridge**: a MEMS accelerometer (white noise, an AC-coupling high-pass at
  5 Hz), read at 50 kHz, low-passed by an 8th-order Butterworth at 2 kHz and decimated to 5 kHz,
  quantised to 12 bits of a ±2 g range;
* **a pause**: the controller halts for ``pause_s`` at ``pause_at`` (the sensor's noise only);
* **another instrument nearby**: a second stick-slip slider on its own mount (drawn from
  ``seed + 100``) on the same table, stepping at ``other_rate`` in bursts of ``other_burst_s``
  every ``other_every_s``, heard ``other_db`` under the arm's stepping (the table carries it).

Levels: m/s^2; about 0.5 m/s^2 RMS while stepping. Units: s, Hz.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, cont2discrete, lfilter, sosfilt, sosfiltfilt, ss2tf

FloatArray = NDArray[np.float64]
FS_IN = 50_000  # the bridge's internal rate, Hz
FS_OUT = 5_000  # what it sends, Hz


@dataclass(frozen=True)
class Mount:
    """One arm on its mount (its draws come from ``seed``)."""

    seed: int = 1
    blocked_gain: float = 0.5
    stiffen: float = 0.15


@dataclass(frozen=True)
class Scene:
    """A recording: stepping at ``rate`` Hz into the stop at ``stop_at`` s (None: no stop)."""

    mount: Mount = Mount()
    rate: float = 700.0
    stop_at: float | None = 6.0
    dur: float = 7.0
    pause_at: float | None = None
    pause_s: float = 0.4
    noise: float = 0.01  # the sensor's noise, m/s^2 RMS at 5 kHz
    seed: int = 0
    other_rate: float | None = None  # another instrument stepping nearby, Hz (None: none)
    other_db: float = -6.0  # its level in its bursts, dB re the arm's stepping
    other_burst_s: float = 0.3
    other_every_s: float = 1.1


def _modes(m: Mount) -> tuple[float, float, float, float]:
    rng = np.random.default_rng(1000 + m.seed)
    return float(rng.uniform(250, 600)), float(rng.uniform(900, 1800)), float(rng.uniform(0.02, 0.05)), float(
        rng.uniform(0.02, 0.06)
    )


def _mount_response(force: FloatArray, f1: float, f2: float, z1: float, z2: float) -> FloatArray:
    """The upper mass's acceleration under ``force`` on it: two masses, two springs, two dampers (state space)."""
    m1, m2 = 1.0, 0.3  # base and stage, kg
    # springs chosen so that the uncoupled modes sit near f1 (base on table) and f2 (stage on base)
    k1 = m1 * (2 * np.pi * f1) ** 2
    k2 = m2 * (2 * np.pi * f2) ** 2
    c1 = 2 * z1 * np.sqrt(k1 * m1)
    c2 = 2 * z2 * np.sqrt(k2 * m2)
    # x = [x1, x2, v1, v2]; the force acts on mass 2
    A = np.array(
        [
            [0, 0, 1, 0],
            [0, 0, 0, 1],
            [-(k1 + k2) / m1, k2 / m1, -(c1 + c2) / m1, c2 / m1],
            [k2 / m2, -k2 / m2, c2 / m2, -c2 / m2],
        ]
    )
    B = np.array([[0.0], [0.0], [0.0], [1.0 / m2]])
    C = A[3:4, :]  # the acceleration of mass 2 ...
    D = B[3:4, :]  # ... including the force's direct term
    # held over each 20 us sample (zero-order hold), as a digital filter
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, D), 1.0 / FS_IN, method="zoh")
    num, den = ss2tf(Ad, Bd, Cd, Dd)
    return np.asarray(lfilter(num[0], den, force), dtype=np.float64)


def _forces(s: Scene, n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """The slips' reaction force before the stop and at it (two streams, so the mount can differ), N."""
    period = 1.0 / s.rate
    times = np.arange(0.0, s.dur, period) + rng.normal(0.0, 0.01 * period, int(np.ceil(s.dur * s.rate)))
    times = times[(times >= 0) & (times < s.dur - 0.01)]
    if s.pause_at is not None:
        times = times[(times < s.pause_at) | (times >= s.pause_at + s.pause_s)]
    amp = rng.uniform(0.85, 1.15, times.size)
    slip = max(2, int(round(25e-6 * FS_IN)))
    stick = int(0.6 * period * FS_IN)
    pulse = np.concatenate((np.sin(np.pi * np.arange(slip) / slip), -np.full(stick, 2.0 * slip / (np.pi * stick))))
    before, at = np.zeros(n), np.zeros(n)
    for t0, a in zip(times, amp, strict=True):
        i = int(t0 * FS_IN)
        blocked = s.stop_at is not None and t0 >= s.stop_at
        seg = pulse[: n - i] * a * (s.mount.blocked_gain if blocked else 1.0)
        (at if blocked else before)[i : i + seg.size] += seg
    return before, at


def _other(s: Scene, n: int, rng: np.random.Generator) -> FloatArray:
    """Another instrument on the table: its slips in bursts, through its own mount, at ``other_db``."""
    assert s.other_rate is not None
    starts = np.arange(rng.uniform(0.0, s.other_every_s), s.dur, s.other_every_s)
    bursts = [np.arange(t, min(t + s.other_burst_s, s.dur - 0.01), 1.0 / s.other_rate) for t in starts]
    other = Scene(mount=Mount(s.mount.seed + 100), rate=s.other_rate, stop_at=None, dur=s.dur)
    force = np.zeros(n)
    slip = max(2, int(round(25e-6 * FS_IN)))
    pulse = np.sin(np.pi * np.arange(slip) / slip)
    for t0 in np.concatenate(bursts) if bursts else []:
        i = int(t0 * FS_IN)
        force[i : i + slip] += pulse[: n - i] * rng.uniform(0.85, 1.15)
    z = _mount_response(force, *_modes(other.mount))
    on = np.abs(force) > 0
    rms = float(np.sqrt(np.mean(z[np.convolve(on, np.ones(int(0.01 * FS_IN)), "same") > 0] ** 2))) if on.any() else 1.0
    return z * 0.5 * 10 ** (s.other_db / 20) / max(rms, 1e-12)


def render(s: Scene) -> FloatArray:
    """The bridge's samples at 5 kHz, m/s^2."""
    rng = np.random.default_rng(s.seed)
    n = int(s.dur * FS_IN)
    f1, f2, z1, z2 = _modes(s.mount)
    before, at = _forces(s, n, rng)
    y = _mount_response(before, f1, f2, z1, z2)
    if s.stop_at is not None:
        y = y + _mount_response(at, f1, f2 * (1 + s.mount.stiffen), z1, 2 * z2)
    y *= 0.5 / max(float(np.std(y[: int(min(s.stop_at or s.dur, s.dur) * FS_IN)])), 1e-12)
    if s.other_rate is not None:
        y = y + _other(s, n, rng)
    y = sosfilt(butter(1, 5.0, btype="highpass", fs=FS_IN, output="sos"), y)
    y = sosfiltfilt(butter(8, 2000.0, fs=FS_IN, output="sos"), y)[:: FS_IN // FS_OUT]
    y = y + s.noise * rng.standard_normal(y.size)
    lsb = 2 * 9.81 / 2**11  # 12 bits over +-2 g
    return np.asarray(np.round(y / lsb) * lsb, dtype=np.float64)


def write_csv(path: object, x: FloatArray) -> None:
    """The bridge's log: a rate comment, then one sample per line (m/s^2)."""
    with open(str(path), "w", encoding="utf-8") as f:
        f.write(f"# accelerometer on the mount, m/s^2\n# sample_rate_hz={FS_OUT}\n")
        f.write("\n".join(f"{v:.4f}" for v in x) + "\n")
