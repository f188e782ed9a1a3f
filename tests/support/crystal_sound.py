"""A twelfth, independent generator: a crystal-clocked controller stepping in bursts, music placed on its lines.

Written for issue 35 (item 6) before the step clock's check was changed for it, from another
view of the step timing than the tenth and eleventh generators (whose step intervals are
drawn one after the other with 0.4 % jitter, so the step times wander as a random walk), and
never used to tune the detector ([docs/step-timing.md](../../docs/step-timing.md) says what the
public sources say about step timing, and what none of them says):

* **the step clock is a divided crystal**: a 16 MHz crystal (off by ``ppm`` parts per
  million) counted down by the integer ``round(16 MHz / rate)`` (the realised rate is not
  quite the set one), its frequency drifting slowly (a thermal cycle: ``drift_ppm`` over
  ``drift_period_s``) and each step's edge jittering by ``edge_ns`` without accumulating;
* **the steps come in bursts** (``burst_steps``, as a traverse sends them) separated by
  gaps of ``gap_ms`` (a serial round trip); each burst restarts the divider, so the
  clock's phase starts afresh at every burst;
* **each step's amplitude** varies by ``amp_spread`` (one standard deviation) and the rail's
  friction changes it slowly (+-1 dB over seconds);
* **the joint** is a modal body with a constant loss factor (every mode loses the same share
  of its energy per cycle: higher modes ring shorter), heard through the step's sound as
  one kernel; a step's sub-sample time is kept (a windowed-sinc fractional delay);
* **at the stop** the slider is blocked against the end stop: the stiffer contact moves the
  lowest modes up, damps the modes above ``clamp_hz`` twice as much, and the slider
  rebounds (a second, opposite click ``rebound_us`` later);
* **music placed on the lines**: notes whose partial ``m`` lands on the joint's step line
  ``k`` (``k`` times the realised rate) or beside it (``offset`` of the line's frequency:
  0, 0.05 %, 0.2 %, 0.5 % or 1.5 %, either side), some with vibrato, at ``line_db`` re
  the stepping's own power on that line, over ordinary music (equal-tempered notes with
  six harmonics) in the same spans. The generator knows the joint's lines (a speaker
  cannot, but music is often close enough: this is the worst case, on purpose).

Levels: the stepping is -30 dBFS RMS, a room noise 35 dB under it. Streams are rendered in
blocks whatever their length (the same samples whatever the blocks).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.signal import fftconvolve, lfilter

SR = 48_000
STEP_DB = -30.0
XTAL_HZ = 16e6
KERNEL_S = 0.04
TAPS = 16  # the fractional delay's windowed sinc
OFFSETS = (0.0, 0.0005, 0.002, 0.005, 0.015)  # a placed note's partial off its line, share of the line's frequency
KINDS = ("nothing", "music", "music on the lines")


@dataclass(frozen=True)
class Body:
    """A joint's modes (Hz, loss factor, gain) and its stop's change."""

    f: np.ndarray
    eta: np.ndarray
    g: np.ndarray
    stiffen: float  # the lowest three modes move up by this factor at the stop
    clamp_hz: float  # modes above this are damped twice as much at the stop
    rebound: float  # the rebound click's amplitude, share of the step's (opposite sign)
    rebound_us: float


@dataclass(frozen=True)
class Joint:
    """One joint and its end stop, drawn from ``seed``."""

    seed: int

    def draw(self) -> Body:
        rng = np.random.default_rng(77_000 + self.seed)
        n = int(rng.integers(10, 17))
        f = np.sort(np.exp(rng.uniform(np.log(1000.0), np.log(16_000.0), n)))
        return Body(
            f=f,
            eta=np.full(n, float(rng.uniform(0.004, 0.02))) * rng.uniform(0.7, 1.4, n),
            g=10 ** (rng.uniform(-15.0, 0.0, n) / 20) * (f / 1000.0) ** -0.25,
            stiffen=float(rng.uniform(1.03, 1.08)),
            clamp_hz=float(rng.uniform(3000.0, 8000.0)),
            rebound=float(rng.uniform(0.3, 0.7)),
            rebound_us=float(rng.uniform(60.0, 250.0)),
        )


@dataclass(frozen=True)
class Clock:
    """The controller's step clock: a divided crystal, its drift and edge jitter, bursts with gaps."""

    rate: float = 1000.0
    ppm: float = 30.0
    drift_ppm: float = 5.0
    drift_period_s: float = 600.0
    edge_ns: float = 20.0
    burst_steps: int | None = 2000  # None: one continuous burst
    gap_ms: tuple[float, float] = (2.0, 15.0)

    def divider(self) -> int:
        """The crystal's ticks per step."""
        return int(round(XTAL_HZ / self.rate))

    def realised_hz(self) -> float:
        """The step rate the divider makes from the crystal's mean frequency, Hz."""
        return XTAL_HZ * (1.0 + self.ppm * 1e-6) / self.divider()


def step_times(c: Clock, dur: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Every step's time (s) over ``dur`` s and the index of each burst's first step."""
    n_div = c.divider()
    times: list[np.ndarray] = []
    starts: list[int] = []
    t, count = float(rng.uniform(0.0, 1.0 / c.rate)), 0
    while t < dur:
        steps = c.burst_steps or int(dur * c.rate) + 2
        k = np.arange(steps, dtype=np.float64)
        nominal = t + k * n_div / XTAL_HZ
        # the crystal's frequency over the burst: its offset and the slow thermal cycle (the phase integrates it)
        ppm = c.ppm + c.drift_ppm * np.sin(2 * np.pi * nominal / c.drift_period_s)
        tick_s = 1.0 / (XTAL_HZ * (1.0 + ppm * 1e-6))
        tb = t + np.concatenate([[0.0], np.cumsum(n_div * tick_s[:-1])]) + c.edge_ns * 1e-9 * rng.standard_normal(steps)
        tb = tb[tb < dur]
        starts.append(count)
        times.append(tb)
        count += tb.size
        if tb.size < steps:
            break
        t = float(tb[-1]) + n_div / XTAL_HZ + float(rng.uniform(*c.gap_ms)) * 1e-3
    return np.concatenate(times), np.asarray(starts, dtype=np.int64)


def kernel(b: Body, at_stop: bool) -> np.ndarray:
    """One step's sound (``KERNEL_S`` s): the body's modes rung by a unit click; at the stop, clamped and rebounding."""
    t = np.arange(int(KERNEL_S * SR)) / SR
    f = b.f.copy()
    eta = b.eta.copy()
    if at_stop:
        f[:3] *= b.stiffen
        eta[f > b.clamp_hz] *= 2.0
    ring = np.sin(2 * np.pi * np.outer(t, f)) * np.exp(-np.pi * eta * np.outer(t, f))
    h = np.asarray(ring @ b.g, dtype=np.float64)
    if at_stop:
        d = int(round(b.rebound_us * 1e-6 * SR))
        h[d:] -= b.rebound * h[: h.size - d]
    return h


def _train(times: np.ndarray, amps: np.ndarray, start: int, n: int) -> np.ndarray:
    """Impulses of ``amps`` at ``times`` (s) on samples ``start .. start + n``, each placed to its sub-sample time."""
    x = np.zeros(n + TAPS)
    pos = times * SR - start
    base = np.floor(pos).astype(np.int64)
    frac = pos - base
    j = np.arange(-TAPS // 2 + 1, TAPS // 2 + 1)
    arg = j[None, :] - frac[:, None]
    w = np.sinc(arg) * (0.5 + 0.5 * np.cos(np.pi * arg / (TAPS // 2 + 1)))
    idx = base[:, None] + j[None, :] + TAPS // 2
    ok = (idx >= 0) & (idx < x.size)
    np.add.at(x, idx[ok], (amps[:, None] * w)[ok])
    return x[TAPS // 2 : TAPS // 2 + n]


@dataclass(frozen=True)
class Note:
    """One note: start (s), length (s), fundamental (Hz), partial amplitudes, vibrato depth (share) and rate (Hz)."""

    t0: float
    dur: float
    f0: float
    amps: tuple[float, ...]
    vib: float = 0.0
    vib_hz: float = 5.5
    phase: float = 0.0


def _note_samples(nt: Note, start: int, n: int) -> np.ndarray:
    """The note on samples ``start .. start + n`` (zeros outside it)."""
    i0 = max(start, int(round(nt.t0 * SR)))
    i1 = min(start + n, int(round((nt.t0 + nt.dur) * SR)))
    out = np.zeros(n)
    if i1 <= i0:
        return out
    t = np.arange(i0, i1) / SR - nt.t0
    # the phase integrates the vibrato's frequency: f0 (1 + vib sin(2 pi vib_hz t))
    ph = nt.f0 * (t - nt.vib * np.cos(2 * np.pi * nt.vib_hz * t) / (2 * np.pi * nt.vib_hz)) + nt.phase
    env = np.minimum(1.0, t / 0.01) * np.minimum(1.0, (nt.dur - t) / 0.03) * np.exp(-t / (0.8 * nt.dur + 0.2))
    y = sum(a * np.sin(2 * np.pi * (m + 1) * ph) for m, a in enumerate(nt.amps) if (m + 1) * nt.f0 < 0.45 * SR)
    out[i0 - start : i1 - start] = np.asarray(y, dtype=np.float64) * np.maximum(env, 0.0)
    return out


@dataclass(frozen=True)
class Session:
    """``dur`` s of ``joint`` stepping on ``clock`` (stopped from ``stop_at`` s; None: never) with music spans."""

    joint: Joint
    clock: Clock = Clock()
    dur: float = 600.0
    stop_at: float | None = None
    seed: int = 0
    span_s: tuple[float, float] = (10.0, 40.0)
    kinds: tuple[str, ...] = KINDS
    music_db: tuple[float, float] = (-9.0, 3.0)  # ordinary music's RMS re the stepping's
    line_db: tuple[float, float] = (-6.0, 15.0)  # a placed partial re the stepping's own power on its line
    amp_spread: float = 0.1
    snr_db: float = 35.0
    block_s: float = 1.0


def spans(s: Session) -> list[tuple[float, float, str]]:
    """The session's spans: (start s, end s, what plays)."""
    rng = np.random.default_rng(s.seed + 11)
    out, t = [], 0.0
    while t < s.dur:
        d = float(rng.uniform(*s.span_s))
        out.append((t, min(s.dur, t + d), s.kinds[int(rng.integers(len(s.kinds)))]))
        t += d
    return out


class Stream:
    """A session rendered block by block: the step times, the notes and the scale drawn once, up front."""

    def __init__(self, s: Session) -> None:
        self.s = s
        body = s.joint.draw()
        rng = np.random.default_rng(s.seed)
        self.times, self.bursts = step_times(s.clock, s.dur, rng)
        knots = np.arange(int(s.dur / 3.0) + 2) * 3.0  # the rail's friction: a level (dB) every 3 s, lines between
        slow = np.interp(self.times, knots, rng.normal(0.0, 0.5, knots.size))
        self.amps = (1.0 + s.amp_spread * rng.standard_normal(self.times.size)) * 10 ** (slow / 20)
        self.free, self.stop = kernel(body, False), kernel(body, True)
        rate = s.clock.realised_hz()
        p = SR / rate
        spec = np.fft.rfft(self.free, 1 << 16)
        lines = np.abs(spec[np.round(np.arange(1, int(SR / 2 / rate)) * rate / SR * (1 << 16)).astype(np.int64)])
        # a step train's power: its lines (amplitude 2 |H(k rate)| / p each) and the amplitudes' spread between them
        power = float(np.sum(2 * lines**2) / p**2 + s.amp_spread**2 * np.sum(self.free**2) / p)
        self.scale = float(10 ** (STEP_DB / 20) / np.sqrt(power))
        self.spec, self.period = spec, p
        self.notes = self._notes(np.random.default_rng(s.seed + 13))
        self.room = np.random.default_rng(s.seed + 17)
        self.room_zi = np.zeros(1)

    def line_amp(self, f: float) -> float:
        """The stepping's line at ``f`` Hz (a harmonic of the realised rate): its amplitude as a sine."""
        return 2 * float(np.abs(self.spec[int(round(f / SR * (1 << 16)))])) / self.period * self.scale

    def _notes(self, rng: np.random.Generator) -> list[Note]:
        s, rate = self.s, self.s.clock.realised_hz()
        step_rms = 10 ** (STEP_DB / 20)
        out: list[Note] = []
        for t0, t1, kind in spans(s):
            t = t0
            while kind != "nothing" and t < t1 - 0.3:
                dur = float(min(rng.uniform(0.2, 1.5), t1 - t))
                if kind == "music on the lines":
                    k = int(rng.integers(int(np.ceil(1500 / rate)), int(12_000 / rate) + 1))
                    m = int(rng.integers(1, 7))
                    off = float(rng.choice(OFFSETS)) * float(rng.choice((-1.0, 1.0)))
                    f0 = k * rate * (1.0 + off) / m
                    amp = self.line_amp(k * rate) * 10 ** (rng.uniform(*s.line_db) / 20)
                    amps = tuple(amp if j == m - 1 else amp * 0.3 / (1 + abs(j - m + 1)) for j in range(6))
                    vib = 0.003 if rng.uniform() < 0.5 else 0.0
                    out.append(Note(t, dur, f0, amps, vib, float(rng.uniform(4.5, 6.5)), float(rng.uniform())))
                for _ in range(int(rng.integers(1, 3))):  # ordinary music under it: equal-tempered, six harmonics
                    f0 = 110.0 * 2 ** (int(rng.integers(0, 49)) / 12)
                    a = step_rms * 10 ** (rng.uniform(*s.music_db) / 20) * np.sqrt(2.0 / 1.5)
                    amps = tuple(a / (j + 1) for j in range(6))
                    out.append(Note(t, dur, f0, amps, 0.0, 5.0, float(rng.uniform())))
                t += dur * float(rng.uniform(0.7, 1.0))
        return out

    def block(self, start: int, n: int) -> np.ndarray:
        """Samples ``start .. start + n`` (float64): the stepping, the music and the room."""
        s = self.s
        lo = np.searchsorted(self.times, (start - len(self.free) - TAPS) / SR)  # a step's taps reach TAPS / 2 out
        hi = np.searchsorted(self.times, (start + n + TAPS) / SR)
        t, a = self.times[lo:hi], self.amps[lo:hi]
        stop_s = np.inf if s.stop_at is None else s.stop_at
        pre = start - len(self.free)
        y = np.zeros(n)
        for sel, h in ((t < stop_s, self.free), (t >= stop_s, self.stop)):
            if np.any(sel):
                x = _train(t[sel], a[sel], pre, n + len(self.free))
                y += fftconvolve(x, h)[len(self.free) : len(self.free) + n]
        y *= self.scale
        t0, t1 = start / SR, (start + n) / SR
        for nt in self.notes:
            if nt.t0 < t1 and nt.t0 + nt.dur > t0:
                y += _note_samples(nt, start, n)
        return np.asarray(y + self._room(n), dtype=np.float64)

    def _room(self, n: int) -> np.ndarray:
        """The room: white noise through a one-pole low-pass (a reddish hiss), ``snr_db`` under the stepping."""
        y, self.room_zi = lfilter([1.0], [1.0, -0.9], self.room.standard_normal(n), zi=self.room_zi)
        level = 10 ** ((STEP_DB - self.s.snr_db) / 20)
        return np.asarray(np.asarray(y, dtype=np.float64) * level * math.sqrt(1.0 - 0.81), dtype=np.float64)


def stream(s: Session, block_s: float | None = None) -> Iterator[np.ndarray]:
    """The session as float32 blocks of ``block_s`` s (the session's own by default)."""
    st = Stream(s)
    nb = int(round((block_s or s.block_s) * SR))
    total = int(round(s.dur * SR))
    for start in range(0, total, nb):
        yield np.asarray(st.block(start, min(nb, total - start)), dtype=np.float32)


def render(s: Session) -> np.ndarray:
    """The whole session, float32 mono at 48 kHz."""
    return np.concatenate(list(stream(s)))


def tuning_session(joint: Joint) -> Session:
    """The joint's tuning recording: 2 s of stepping at 1000 Hz in one burst, then 1.2 s at the stop; no music."""
    return Session(joint, Clock(burst_steps=None), dur=3.2, stop_at=2.0, seed=1, kinds=("nothing",))
