"""What the room hears: a synthetic soundscape of a stick-slip arm stepping.

The simulated MM3A's virtual microphone and the audio tests use :class:`Soundscape`.
Everything it renders is a pure function of *absolute stream time* (sample index
``round(t * sample_rate)``) and the seed, so a stream can be rendered block by block
and the blocks join exactly.

The sound model (invented, but physically plausible):

* **a step** is a short broadband click (the slip: a fast release of the piezo)
  filtered by three joint-specific structural resonances that ring for 1-2 ms;
* **a step against an end stop** moves nothing: the slider is slammed into the stop
  and the stop rattles. It keeps a weaker click, plus a narrow-band rattle in a
  joint-specific band (joint 1 about 6.3 kHz, joint 2 about 8.2 kHz, joint 3 about
  4.6 kHz) that rings for several ms and bounces once, synchronous with the steps;
* **room**: pinkish background noise, 50 Hz mains hum with harmonics, occasional
  knocks on the table (a low thump with a short bright contact click), and optionally
  speech-like babble (voiced syllables with formants, and some fricatives).

All levels are dBFS (RMS relative to a full-scale sine amplitude of 1.0 is not used:
"dB" here is ``10 log10(mean square)``). ``gain_db`` scales everything, like a
microphone preamplifier.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

__all__ = [
    "JOINT_SOUNDS",
    "JointSound",
    "Soundscape",
    "render_traverse_recording",
]

_REF_RATE_HZ = 1000.0  # step rate at which the levels below hold
_MASK64 = np.uint64(0xFFFFFFFFFFFFFFFF)


@dataclass(frozen=True)
class JointSound:
    """Acoustic signature of one joint.

    Parameters
    ----------
    click_modes_hz : tuple of float
        Structural resonances excited by every step, Hz.
    click_decay_s : tuple of float
        Their 1/e decay times, s.
    click_weights : tuple of float
        Their relative amplitudes.
    stop_hz : float
        Centre of the end-stop rattle, Hz.
    stop_decay_s : float
        1/e decay of the rattle, s.
    click_db : float
        Stepping level at 1 kHz stepping, dBFS (mean square).
    stop_db : float
        Rattle level at 1 kHz stepping against the stop, dBFS.
    """

    click_modes_hz: tuple[float, ...]
    click_decay_s: tuple[float, ...]
    click_weights: tuple[float, ...]
    stop_hz: float
    stop_decay_s: float
    click_db: float = -26.0
    stop_db: float = -24.0


#: The three joints of an MM3A-type arm (1, 2 rotary; 3 prismatic).
JOINT_SOUNDS: dict[int, JointSound] = {
    1: JointSound(
        (1800.0, 4100.0, 11500.0), (1.8e-3, 1.2e-3, 0.6e-3), (1.0, 0.8, 0.5), 6300.0, 4e-3
    ),
    2: JointSound(
        (2400.0, 5000.0, 12500.0), (1.6e-3, 1.0e-3, 0.5e-3), (1.0, 0.7, 0.5), 8200.0, 3.5e-3
    ),
    3: JointSound(
        (1200.0, 2700.0, 9800.0), (2.2e-3, 1.4e-3, 0.7e-3), (1.0, 0.8, 0.4), 4600.0, 4.5e-3
    ),
}


def _splitmix(x: np.ndarray) -> np.ndarray:
    """Vectorised splitmix64 finaliser: a good integer hash (uint64 in, uint64 out)."""
    with np.errstate(over="ignore"):
        z = (x + np.uint64(0x9E3779B97F4A7C15)) & _MASK64
        z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & _MASK64
        z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & _MASK64
        return z ^ (z >> np.uint64(31))


def _hash_uniform(seed: int, tag: int, idx: np.ndarray) -> np.ndarray:
    """Uniform [0, 1) numbers that depend only on (seed, tag, integer index)."""
    key = np.uint64((seed * 1_000_003 + tag * 7919) & 0xFFFFFFFFFFFFFFFF)
    with np.errstate(over="ignore"):
        h = _splitmix(idx.astype(np.int64).view(np.uint64) ^ key)
        h = _splitmix(h + key)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def _modes(
    t: FloatArray, freqs: Sequence[float], decays: Sequence[float], weights: Sequence[float], phase: float = 0.0
) -> FloatArray:
    out = np.zeros_like(t)
    for f, tau, w in zip(freqs, decays, weights, strict=True):
        out += w * np.exp(-t / tau) * np.sin(2 * np.pi * f * t + phase)
    return out


def _normalise(kernel: np.ndarray, level_db: float, sample_rate: int) -> np.ndarray:
    """Scale a per-step kernel so that stepping at 1 kHz gives ``level_db`` mean square."""
    energy = float(np.sum(kernel**2))
    target = 10 ** (level_db / 10) * sample_rate / _REF_RATE_HZ
    out: FloatArray = kernel * np.sqrt(target / energy)
    return out


@lru_cache(maxsize=16)
def _noise_tables(sample_rate: int, seed: int, noise_db: float) -> tuple[np.ndarray, np.ndarray]:
    """Two seeded tables of pinkish room noise (-3 dB/octave above 100 Hz), shaped in the
    frequency domain so each wraps seamlessly. Summed at coprime lengths (2**18 and
    3**11) they repeat only after hours, and a block's noise is two cheap look-ups."""
    tables = []
    for tag, size in ((10, 1 << 18), (11, 3**11)):
        rng = np.random.default_rng([seed & 0xFFFFFFFF, tag])
        spec = np.fft.rfft(rng.standard_normal(size))
        f = np.fft.rfftfreq(size, 1 / sample_rate)
        spec *= np.sqrt(1000.0 / np.maximum(f, 100.0))
        x = np.fft.irfft(spec, size)
        x *= 10 ** (noise_db / 20) / np.sqrt(2 * np.mean(x**2))
        x.flags.writeable = False
        tables.append(x)
    return tables[0], tables[1]


class Soundscape:
    """What the room hears at ``sample_rate``: steps, end-stop rattles and the room.

    Parameters
    ----------
    sample_rate : int
        Samples per second, Hz (8 kHz to 192 kHz).
    seed : int
        Seeds the room (noise, knocks, babble) and the per-step jitter.
    gain_db : float
        Microphone gain applied to everything, dB.
    noise_db : float
        Room noise level, dBFS (mean square).
    hum : bool
        Add 50 Hz mains hum and its harmonics (about -50 dBFS).
    knocks_per_min : float
        Mean rate of knocks on the table, per minute (Poisson).
    babble : bool
        Add speech-like babble from people talking in the room.
    babble_db : float
        Babble level while someone talks, dBFS.

    Notes
    -----
    :meth:`render` depends only on absolute time: rendering ``[0, 1 s)`` in one call
    equals rendering it in any split (to float rounding).
    """

    #: how long a step's sound rings, s: pass events from ``t0 - tail_s`` on
    tail_s: float = 0.012

    _KNOCK_S = 0.25
    _KNOCK_SEG_S = 1.0
    _SYL_SEG_S = 0.25
    _SYL_MAX_S = 0.30
    _RATTLE_JITTER_S = 5e-4

    def __init__(
        self,
        sample_rate: int = 48_000,
        seed: int = 0,
        gain_db: float = 0.0,
        noise_db: float = -62.0,
        hum: bool = True,
        knocks_per_min: float = 4.0,
        babble: bool = False,
        babble_db: float = -38.0,
    ) -> None:
        if not 8_000 <= int(sample_rate) <= 192_000:
            raise ValueError(f"sample_rate {sample_rate} Hz is outside the allowed 8000-192000 Hz")
        if not -60.0 <= gain_db <= 60.0:
            raise ValueError(f"gain_db {gain_db} dB is outside the allowed -60..60 dB")
        if not 0.0 <= knocks_per_min <= 600.0:
            raise ValueError(
                f"knocks_per_min {knocks_per_min} is outside the allowed 0..600 per min"
            )
        self.sample_rate = int(sample_rate)
        self.seed = int(seed)
        self.gain_db = float(gain_db)
        self.noise_db = float(noise_db)
        self.hum = bool(hum)
        self.knocks_per_min = float(knocks_per_min)
        self.babble = bool(babble)
        self.babble_db = float(babble_db)
        self._gain = 10 ** (self.gain_db / 20)
        self._tail = int(round(self.tail_s * self.sample_rate))
        self._jit = int(round(self._RATTLE_JITTER_S * self.sample_rate))
        self._kernels = {j: self._joint_kernels(j) for j in JOINT_SOUNDS}
        self._noise_a, self._noise_b = _noise_tables(self.sample_rate, self.seed, self.noise_db)
        self._knock_len = int(round(self._KNOCK_S * self.sample_rate))
        self._hum_table: np.ndarray | None = None
        self._syl_cache: dict[int, tuple[int, np.ndarray] | None] = {}
        from scipy.signal import butter

        hi_f = min(7000.0, 0.45 * self.sample_rate)
        self._fric_sos = butter(2, [3500.0, hi_f], btype="band", fs=self.sample_rate, output="sos")

    # ------------------------------------------------------------------ kernels
    def _joint_kernels(self, joint: int) -> tuple[np.ndarray, np.ndarray]:
        """(click kernel, rattle kernel) of one joint; the rattle starts up to 0.5 ms late."""
        js = JOINT_SOUNDS[joint]
        sr = self.sample_rate
        t = np.arange(self._tail) / sr
        rng = np.random.default_rng(1000 + joint)  # the arm's own sound, same every day
        burst = rng.standard_normal(self._tail) * np.exp(-t / 1.2e-4)
        click = _modes(t, js.click_modes_hz, js.click_decay_s, js.click_weights) + 0.08 * burst
        click = _normalise(click, js.click_db, sr)
        # rattle: the stop rings, and the slider bounces once ~0.6 ms later
        tr = t[: self._tail - self._jit]
        ring = np.exp(-tr / js.stop_decay_s) * np.sin(2 * np.pi * js.stop_hz * tr)
        ring *= 1 + 0.3 * np.sin(2 * np.pi * 340.0 * tr)  # buzz: the bounce beats the ring
        lag = int(round(6e-4 * sr))
        bounce = np.zeros_like(ring)
        bounce[lag:] = 0.5 * ring[: ring.size - lag]
        rattle = _normalise(ring + bounce, js.stop_db, sr)
        return click, rattle

    # ------------------------------------------------------------------ render
    def render(
        self,
        t0_s: float,
        n: int,
        step_times_s: Sequence[float] | np.ndarray = (),
        step_joints: Sequence[int] | np.ndarray | int = (),
        step_at_stop: Sequence[bool] | np.ndarray | bool = (),
    ) -> np.ndarray:
        """Render ``n`` samples starting at absolute stream time ``t0_s``.

        Parameters
        ----------
        t0_s : float
            Stream time of the first sample, s (taken as sample ``round(t0_s * rate)``).
        n : int
            Number of samples.
        step_times_s : array of float
            Absolute times of the steps, s. Include steps from ``t0_s - tail_s`` on,
            their sound rings into this block; steps outside are ignored.
        step_joints : array of int or int
            Joint (1, 2, 3) of each step.
        step_at_stop : array of bool or bool
            Whether each step hit the end stop (moved nothing, rattled the stop).

        Returns
        -------
        numpy.ndarray
            float32 mono samples.
        """
        n = int(n)
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        sr = self.sample_rate
        s0 = int(round(t0_s * sr))
        out = np.zeros(n, dtype=np.float64)
        if n == 0:
            return out.astype(np.float32)
        times = np.atleast_1d(np.asarray(step_times_s, dtype=np.float64))
        if times.size:
            joints = np.broadcast_to(np.asarray(step_joints, dtype=np.int64), times.shape)
            stops = np.broadcast_to(np.asarray(step_at_stop, dtype=bool), times.shape)
            bad = ~np.isin(joints, list(JOINT_SOUNDS))
            if bad.any():
                raise ValueError(f"step_joints must be 1, 2 or 3; got {joints[bad][0]}")
            self._add_steps(out, s0, times, joints, stops)
        self._add_noise(out, s0)
        if self.hum:
            self._add_hum(out, s0)
        if self.knocks_per_min > 0:
            self._add_knocks(out, s0)
        if self.babble:
            self._add_babble(out, s0)
        out *= self._gain
        return out.astype(np.float32)

    def _add_steps(
        self, out: FloatArray, s0: int, times: FloatArray, joints: NDArray[np.int64], stops: NDArray[np.bool_]
    ) -> None:
        from scipy.signal import oaconvolve

        n, L = out.size, self._tail
        idx = np.rint(times * self.sample_rate).astype(np.int64)
        keep = (idx > s0 - L) & (idx < s0 + n)
        if not keep.any():
            return
        idx, joints, stops = idx[keep], joints[keep], stops[keep]
        # per-step jitter, a pure function of the step's sample index: click amplitude
        # +-25 %; at the stop the click is halved and the stop rattles, its amplitude
        # +-40 % and its start 0-0.5 ms late (the slider meets the stop a little
        # differently every time, which also smears the step-rate harmonics)
        amp = 0.75 + 0.5 * _hash_uniform(self.seed, 1, idx)
        amp = np.where(stops, 0.5 * amp, amp)
        base = s0 - L + 1
        for j in np.unique(joints):
            click, rattle = self._kernels[int(j)]
            sel = joints == j
            train = np.zeros(n + L - 1)
            np.add.at(train, idx[sel] - base, amp[sel])
            out += oaconvolve(train, click, mode="valid")
            sel &= stops
            if sel.any():
                r_idx = idx[sel] + np.floor(
                    _hash_uniform(self.seed, 8, idx[sel]) * (self._jit + 1)
                ).astype(np.int64)
                r_amp = 0.6 + 0.8 * _hash_uniform(self.seed, 9, idx[sel])
                base_r = s0 - rattle.size + 1
                ok = (r_idx >= base_r) & (r_idx < s0 + n)
                train = np.zeros(n + rattle.size - 1)
                np.add.at(train, r_idx[ok] - base_r, r_amp[ok])
                out += oaconvolve(train, rattle, mode="valid")

    def _add_noise(self, out: FloatArray, s0: int) -> None:
        i = s0 + np.arange(out.size)
        out += self._noise_a[i % self._noise_a.size]
        out += self._noise_b[i % self._noise_b.size]

    def _hum(self, t: np.ndarray) -> np.ndarray:
        h = np.zeros_like(t)
        for k, db in ((1, -50.0), (2, -62.0), (3, -56.0), (5, -64.0)):
            h += np.sqrt(2) * 10 ** (db / 20) * np.sin(2 * np.pi * 50.0 * k * t + 0.7 * k)
        return h

    def _add_hum(self, out: FloatArray, s0: int) -> None:
        sr = self.sample_rate
        if sr % 50 == 0:  # exactly periodic in samples: look one 20 ms period up
            period = sr // 50
            if self._hum_table is None:
                self._hum_table = self._hum(np.arange(period) / sr)
            out += self._hum_table[(s0 + np.arange(out.size)) % period]
        else:
            out += self._hum((s0 + np.arange(out.size)) / sr)

    def _knock_kernel(self, u: np.ndarray) -> np.ndarray:
        """One knock: a low thump plus a brief bright contact click; ``u`` shapes it."""
        sr = self.sample_rate
        t = np.arange(self._knock_len) / sr
        f0 = 90.0 + 80.0 * u[0]
        thump = _modes(t, (f0, 2.7 * f0, 7.9 * f0), (0.04, 0.02, 0.008), (1.0, 0.5, 0.25))
        rng = np.random.default_rng(int(u[1] * 2**31))
        contact = rng.standard_normal(t.size) * np.exp(-t / 4e-4) * 0.35
        return thump + contact

    def _add_knocks(self, out: FloatArray, s0: int) -> None:
        sr, n = self.sample_rate, out.size
        seg = int(round(self._KNOCK_SEG_S * sr))
        first = (s0 - self._knock_len) // seg
        last = (s0 + n - 1) // seg
        lam = self.knocks_per_min / 60.0 * self._KNOCK_SEG_S
        for k in range(first, last + 1):
            rng = np.random.default_rng([self.seed & 0xFFFFFFFF, 3, k + (1 << 40)])
            count = rng.poisson(lam)
            for _ in range(count):
                start = k * seg + int(rng.integers(seg))
                level_db = rng.uniform(-30.0, -14.0)  # peak level of the thump, dBFS
                u = rng.random(2)
                lo, hi = max(start, s0), min(start + self._knock_len, s0 + n)
                if lo >= hi:
                    continue
                kern = self._knock_kernel(u) * 10 ** (level_db / 20)
                out[lo - s0 : hi - s0] += kern[lo - start : hi - start]

    def _syllable(self, k: int) -> tuple[int, np.ndarray] | None:
        """Syllable ``k`` of the babble (start sample, samples) or None; cached."""
        if k in self._syl_cache:
            return self._syl_cache[k]
        from scipy.signal import lfilter, sosfilt

        sr = self.sample_rate
        seg = int(round(self._SYL_SEG_S * sr))
        rng = np.random.default_rng([self.seed & 0xFFFFFFFF, 4, k + (1 << 40)])
        talking = _hash_uniform(self.seed, 5, np.array([k // 12]))[0] < 0.7  # 3 s turns
        result = None
        if talking and rng.random() < 0.85:
            dur = int(rng.uniform(0.08, self._SYL_MAX_S) * sr)
            start = k * seg + int(rng.integers(seg // 4))
            t = np.arange(dur) / sr
            env = np.sin(np.pi * t / (dur / sr)) ** 2
            # voiced: a glottal pulse train (gliding pitch) through three formants
            f0 = rng.uniform(95.0, 230.0) * (1 + rng.uniform(-0.2, 0.2) * t / t[-1])
            pulses = np.zeros(dur)
            pulses[np.flatnonzero(np.diff(np.floor(np.cumsum(f0 / sr)), prepend=0.0))] = 1.0
            pulses = lfilter([1.0], [1.0, -0.9], pulses)  # glottal roll-off
            voiced = np.zeros(dur)
            for fm_lo, fm_hi, bw in ((300, 850, 90.0), (900, 2300, 120.0), (2400, 3200, 180.0)):
                fm = rng.uniform(fm_lo, fm_hi)
                r = np.exp(-np.pi * bw / sr)
                a = [1.0, -2 * r * np.cos(2 * np.pi * fm / sr), r * r]
                voiced += lfilter([1.0 - r], a, pulses)
            voiced /= np.sqrt(np.mean(voiced**2)) + 1e-30
            syl = voiced * env
            if rng.random() < 0.3:  # a fricative ('s', 'f'): band noise 3.5-7 kHz, weaker
                noise = rng.standard_normal(dur)
                syl = syl + 0.25 * sosfilt(self._fric_sos, noise) * env
            result = (start, syl * 10 ** (self.babble_db / 20))
        if len(self._syl_cache) > 64:
            self._syl_cache.clear()
        self._syl_cache[k] = result
        return result

    def _add_babble(self, out: FloatArray, s0: int) -> None:
        sr, n = self.sample_rate, out.size
        seg = int(round(self._SYL_SEG_S * sr))
        maxlen = int(round(self._SYL_MAX_S * sr)) + seg // 4
        for k in range((s0 - maxlen) // seg, (s0 + n - 1) // seg + 1):
            syl = self._syllable(k)
            if syl is None:
                continue
            start, x = syl
            lo, hi = max(start, s0), min(start + x.size, s0 + n)
            if lo < hi:
                out[lo - s0 : hi - s0] += x[lo - start : hi - start]


def render_traverse_recording(
    joint: int,
    step_hz: float,
    stop_at_s: float,
    duration_s: float,
    seed: int = 0,
    **soundscape_kwargs: Any,
) -> tuple[NDArray[np.float32], int]:
    """A labelled recording of one traverse's end: stepping, then stepping against the stop.

    Parameters
    ----------
    joint : int
        Joint 1, 2 or 3.
    step_hz : float
        Step rate, Hz (1-10000).
    stop_at_s : float
        Time the joint reaches its stop, s; every step from then on hits the stop.
        Use ``stop_at_s >= duration_s`` for stepping only.
    duration_s : float
        Length of the recording, s.
    seed : int
        Seed of the room and the per-step jitter.
    **soundscape_kwargs
        Passed to :class:`Soundscape` (``sample_rate``, ``gain_db``, ``babble``, ...).

    Returns
    -------
    (numpy.ndarray, int)
        float32 mono samples and the sample rate, Hz.
    """
    if joint not in JOINT_SOUNDS:
        raise ValueError(f"joint must be 1, 2 or 3, got {joint}")
    if not 1.0 <= step_hz <= 10_000.0:
        raise ValueError(f"step_hz {step_hz} Hz is outside the allowed 1-10000 Hz")
    if not duration_s > 0:
        raise ValueError(f"duration_s must be > 0 s, got {duration_s}")
    scape = Soundscape(seed=seed, **soundscape_kwargs)
    sr = scape.sample_rate
    n = int(round(duration_s * sr))
    # the controller's clock: steps start at a seed-dependent phase
    phase = _hash_uniform(seed, 7, np.array([joint]))[0] / step_hz
    times = phase + np.arange(int(np.ceil(duration_s * step_hz)) + 1) / step_hz
    times = times[times < duration_s]
    at_stop = times >= stop_at_s
    out = np.empty(n, dtype=np.float32)
    block = sr  # render second by second: bounded memory
    for b0 in range(0, n, block):
        t0 = b0 / sr
        m = min(block, n - b0)
        sel = (times >= t0 - scape.tail_s) & (times < t0 + m / sr)
        out[b0 : b0 + m] = scape.render(t0, m, times[sel], joint, at_stop[sel])
    return out, sr
