"""An hour of stepping with speech, music and a radio, rendered as a stream in blocks (an eleventh generator).

Written for issue 35 (item 6) before the detector was judged on it, and never used to tune
the detector. The joint is the tenth generator's (:mod:`fan_sound`: slip pulses of finite
length through a bank of resonators, heard through a 100 Hz high-pass), but rendered block
by block with the filters' states carried over, so an hour never sits in memory. Over it,
from another view than the battery's sources (no recorded or espeak-ng speech, no sampled
music):

* **speech**: a source-filter talker. A glottal pulse train (80-260 Hz, the pitch falling
  over each phrase, 1 % jitter) through three formant resonators whose frequencies jump
  from vowel to vowel (F1 300-850, F2 850-2500, F3 2300-3300 Hz), syllables of 120-320 ms
  under a raised-cosine envelope, a fricative (white noise high-passed at 3.5 kHz) before
  one syllable in three, words of 1-4 syllables, phrases of 2-8 words and silences of
  0.2-1.2 s between phrases;
* **music**: notes of an equal-tempered scale (110-1760 Hz) with 8 harmonics falling as
  ``1/k`` and a bright attack, 0.15-1.2 s long with an exponential decay, two or three
  voices at once, and a snare-like noise burst on one beat in four;
* **a radio**: speech and music together through a 150-5000 Hz channel, compressed
  (``tanh``) and with a little hiss, like a small loudspeaker across the room.

The hour is a sequence of spans of 15-90 s (``span_s``), each with one of: nothing added, speech, music,
the radio, or speech over the radio, at -12 to +3 dB re the stepping's RMS; they start and
stop within the stream. Levels: the stepping is -30 dBFS RMS, pink room noise 35 dB under it.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from fan_sound import SR, STEP_DB, Arm
from scipy.signal import butter, lfilter

KINDS = ("nothing", "speech", "music", "radio", "speech over the radio")
#: each source's RMS while it plays (measured over 30 s of each): its level is set relative to the stepping's
RMS = {"speech": 0.75, "music": 0.99, "radio": 0.41, "speech over the radio": 0.54}


@dataclass(frozen=True)
class Hour:
    """``dur`` s of ``arm`` stepping at ``rate`` Hz with no stop, speech, music and a radio over it."""

    arm: Arm
    rate: float = 1000.0
    dur: float = 3600.0
    seed: int = 0
    block_s: float = 1.0
    span_s: tuple[float, float] = (15.0, 90.0)
    kinds: tuple[str, ...] = KINDS
    jitter: float = 0.004
    snr_db: float = 35.0


class _Filter:
    """An IIR filter whose state is carried from block to block."""

    def __init__(self, b: np.ndarray, a: np.ndarray) -> None:
        self.b, self.a = np.asarray(b, dtype=np.float64), np.asarray(a, dtype=np.float64)
        self.zi = np.zeros(max(len(self.a), len(self.b)) - 1)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        y, self.zi = lfilter(self.b, self.a, x, zi=self.zi)
        return np.asarray(y, dtype=np.float64)


def _resonator(f: float, q: float, g: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    r = np.exp(-np.pi * f / (q * SR))
    return np.array([g * (1.0 - r)]), np.array([1.0, -2.0 * r * np.cos(2 * np.pi * f / SR), r * r])


class _Stepping:
    """The joint's stepping, block by block: pulses through the arm's resonators and the microphone."""

    def __init__(self, h: Hour, rng: np.random.Generator) -> None:
        a = h.arm.draw()
        self.h, self.rng = h, rng
        n = max(2, int(round(a.tau * SR)))
        self.pulse = _Filter(np.sin(np.pi * (np.arange(n) + 0.5) / n), np.array([1.0]))
        self.modes = [_Filter(*_resonator(f, q, g)) for f, q, g in zip(a.f, a.q, a.g, strict=True)]
        self.mic = _Filter(np.array([1.0, -1.0]), np.array([1.0, -np.exp(-2 * np.pi * 100.0 / SR)]))
        self.next_t = float(rng.uniform(0, 1 / h.rate))
        self.scale = 1.0

    def __call__(self, t0: float, n: int) -> np.ndarray:
        x = np.zeros(n)
        t1 = t0 + n / SR
        while self.next_t < t1:
            x[min(n - 1, int(round((self.next_t - t0) * SR)))] += 1.0 + 0.15 * self.rng.standard_normal()
            self.next_t += (1.0 + self.h.jitter * self.rng.standard_normal()) / self.h.rate
        force = self.pulse(x)
        y = sum((m(force) for m in self.modes), np.zeros(n))
        return self.mic(y) * self.scale


class _Overlap:
    """Events (syllables, notes) of finite length added into a running buffer, emitted block by block."""

    def __init__(self) -> None:
        self.buf = np.zeros(0)
        self.t0 = 0  # sample index of buf[0]

    def add(self, start: int, w: np.ndarray) -> None:
        end = start - self.t0 + w.size
        if end > self.buf.size:
            self.buf = np.concatenate([self.buf, np.zeros(end - self.buf.size)])
        self.buf[start - self.t0 : end] += w

    def take(self, n: int) -> np.ndarray:
        if self.buf.size < n:
            self.buf = np.concatenate([self.buf, np.zeros(n - self.buf.size)])
        out, self.buf = self.buf[:n].copy(), self.buf[n:]
        self.t0 += n
        return out


def _envelope(n: int, attack: int) -> np.ndarray:
    e = np.ones(n)
    k = min(attack, n // 2)
    if k > 0:
        ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(k) / k)
        e[:k], e[n - k :] = ramp, ramp[::-1]
    return e


class _Talker:
    """Source-filter speech, syllable by syllable (unit RMS while talking, about)."""

    VOWELS = ((730, 1090, 2440), (270, 2290, 3010), (530, 1840, 2480), (570, 840, 2410), (300, 870, 2240),
              (660, 1720, 2410), (440, 1020, 2240), (490, 1350, 1690))  # fmt: skip

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.out = _Overlap()
        self.next = 0  # sample of the next syllable
        self.f0 = float(rng.uniform(90.0, 220.0))
        self.left_in_phrase = 0
        self.phrase_syll = 1

    def _syllable(self, start: int) -> int:
        rng = self.rng
        if self.left_in_phrase == 0:
            self.phrase_syll = int(rng.integers(4, 20))
            self.left_in_phrase = self.phrase_syll
            self.f0 = float(np.clip(self.f0 * np.exp(rng.normal(0, 0.15)), 80.0, 260.0))
            start += int(rng.uniform(0.2, 1.2) * SR)  # the silence between phrases
        fall = 1.0 - 0.25 * (1 - self.left_in_phrase / self.phrase_syll)  # the pitch falls over the phrase
        self.left_in_phrase -= 1
        n = int(rng.uniform(0.12, 0.32) * SR)
        f0 = self.f0 * fall
        period = SR / f0
        t, src = 0.0, np.zeros(n)
        while t < n:
            src[int(t)] = 1.0
            t += period * (1.0 + 0.01 * rng.standard_normal())
        src = lfilter([1.0], [1.0, -0.95], src)  # the glottal pulse's roll-off
        f1, f2, f3 = (v * rng.uniform(0.92, 1.08) for v in self.VOWELS[int(rng.integers(len(self.VOWELS)))])
        v = sum(lfilter(*_resonator(f, q, g), src) for f, q, g in ((f1, 6.0, 1.0), (f2, 10.0, 0.5), (f3, 14.0, 0.3)))
        w = np.asarray(v, dtype=np.float64) * _envelope(n, int(0.03 * SR))
        w /= np.sqrt(np.mean(w**2)) + 1e-12
        if rng.uniform() < 1 / 3:  # a fricative before the vowel
            m = int(rng.uniform(0.06, 0.14) * SR)
            b, a = butter(4, 3500.0 / (SR / 2), "high")
            fr = lfilter(b, a, rng.standard_normal(m)) * _envelope(m, int(0.02 * SR))
            fr *= 0.6 / (np.sqrt(np.mean(fr**2)) + 1e-12)
            self.out.add(start, fr)
            start += m
        self.out.add(start, w)
        gap = int(rng.uniform(0.01, 0.08) * SR) if self.left_in_phrase % 3 else int(rng.uniform(0.08, 0.2) * SR)
        return start + n + gap

    def __call__(self, n: int) -> np.ndarray:
        while self.next < self.out.t0 + n:
            self.next = self._syllable(max(self.next, self.out.t0))
        return self.out.take(n)


class _Band:
    """Notes with harmonics, two or three voices, a snare on one beat in four (unit RMS, about)."""

    TABLE = 4096  # samples in one period's table

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.out = _Overlap()
        self.beat = float(rng.uniform(0.3, 0.6))  # s
        self.next = [0, 0, 0]
        self.voices = int(rng.integers(2, 4))
        self.beats = 0
        self.next_beat = 0

    def _note(self, start: int) -> int:
        rng = self.rng
        f = 110.0 * 2 ** (int(rng.integers(0, 49)) / 12)
        n = int(self.beat * int(rng.choice([1, 1, 2, 3])) * SR * rng.uniform(0.8, 1.0))
        t = np.arange(n) / SR
        ks = [k for k in range(1, 9) if k * f < 18_000]
        one = np.arange(self.TABLE) / self.TABLE  # one period, its harmonics at random phases
        table = sum(np.sin(2 * np.pi * k * one + rng.uniform(0, 6.3)) / k for k in ks)
        w = np.asarray(table)[(np.arange(n) * (f * self.TABLE / SR)).astype(np.int64) % self.TABLE]
        decay = np.exp(-t / rng.uniform(0.15, 0.8)) * (1.0 + np.exp(-t / 0.01))  # the attack brighter
        w = np.asarray(w, dtype=np.float64) * decay * _envelope(n, int(0.004 * SR))
        self.out.add(start, 0.7 * w / (np.sqrt(np.mean(w**2)) + 1e-12))
        return start + int(n * rng.uniform(0.9, 1.1))

    def _snare(self, start: int) -> None:
        m = int(0.15 * SR)
        s = self.rng.standard_normal(m) * np.exp(-np.arange(m) / (0.04 * SR))
        self.out.add(start, 1.2 * s)

    def __call__(self, n: int) -> np.ndarray:
        end = self.out.t0 + n
        while True:  # the events in time order, whatever the blocks (the random draws in one order)
            v = int(np.argmin(self.next[: self.voices]))
            if min(self.next[v], self.next_beat) >= end:
                break
            if self.next[v] <= self.next_beat:
                self.next[v] = self._note(self.next[v])
            else:
                if self.beats % 4 == 2:
                    self._snare(self.next_beat)
                self.beats += 1
                self.next_beat += int(self.beat * SR)
        return self.out.take(n)


class _Radio:
    """Speech and music through a small loudspeaker's channel, compressed, with hiss."""

    def __init__(self, rng: np.random.Generator, speech: bool, music: bool) -> None:
        talk, band, self.rng = rng.spawn(3)  # each its own draws: the same samples whatever the blocks
        self.talk = _Talker(talk) if speech else None
        self.band = _Band(band) if music else None
        b, a = butter(2, (150.0 / (SR / 2), 5000.0 / (SR / 2)), "band")
        self.channel = _Filter(b, a)

    def __call__(self, n: int) -> np.ndarray:
        x = np.zeros(n)
        if self.talk is not None:
            x += self.talk(n)
        if self.band is not None:
            x += 0.5 * self.band(n)
        y = np.tanh(1.5 * self.channel(x)) / 1.2 + 0.02 * self.rng.standard_normal(n)
        return np.asarray(y, dtype=np.float64)


def _span_source(kind: str, rng: np.random.Generator) -> object:
    if kind == "speech":
        return _Talker(rng)
    if kind == "music":
        return _Band(rng)
    if kind == "radio":
        return _Radio(rng, speech=False, music=True)
    if kind == "speech over the radio":
        return _Radio(rng, speech=True, music=True)
    return None


def over_stepping(y: np.ndarray, kind: str, db: float, rng: np.random.Generator, before: int) -> np.ndarray:
    """``y`` with the hour's ``kind`` (a key of :data:`RMS`) added over its whole length at ``db`` re the RMS of its
    first ``before`` samples (the stepping's before its stop), drawn from ``rng``: as the noise bench, the lines-model
    bench and the tests built on them add it (the sum in ``y``'s precision or float64, not cast)."""
    rms = float(np.sqrt(np.mean(y[:before] ** 2)))
    src = _span_source(kind, rng)
    return y + src(y.size) * rms * 10 ** (db / 20) / RMS[kind]  # type: ignore[operator,no-any-return]


def spans(h: Hour) -> list[tuple[float, float, str, float]]:
    """The hour's spans: (start s, end s, what is added, its level dB re the stepping's RMS)."""
    rng = np.random.default_rng(h.seed + 7)
    out, t, i = [], 0.0, int(rng.integers(len(h.kinds)))
    while t < h.dur:
        d = float(rng.uniform(*h.span_s))
        out.append((t, min(h.dur, t + d), h.kinds[i % len(h.kinds)], float(rng.uniform(-12.0, 3.0))))
        t += d
        i += int(rng.integers(1, len(h.kinds))) if len(h.kinds) > 1 else 0
    return out


def stream(h: Hour) -> Iterator[np.ndarray]:
    """The hour, float32 mono at 48 kHz, in blocks of ``block_s``; the stepping at -30 dBFS RMS."""
    rng = np.random.default_rng(h.seed)
    step = _Stepping(h, np.random.default_rng(h.seed + 1))
    probe = _Stepping(h, np.random.default_rng(h.seed + 2))  # one second alone sets the stepping's level
    ref = probe(0.0, SR)
    step.scale = 10 ** (STEP_DB / 20) / float(np.sqrt(np.mean(ref[SR // 4 :] ** 2)))
    step_rms = 10 ** (STEP_DB / 20)
    room = _Filter(np.array([0.049922, -0.095993, 0.050612, -0.004408]), np.array([1, -2.494956, 2.017265, -0.522189]))
    room_gain = step_rms * 10 ** (-h.snr_db / 20) / 0.0857  # the pink filter's output RMS per unit white noise
    sched = spans(h)
    k, src, gain = -1, None, 0.0
    n_block = int(round(h.block_s * SR))
    total = int(round(h.dur * SR))
    done = 0
    while done < total:
        n = min(n_block, total - done)
        t0 = done / SR
        y = step(t0, n) + room_gain * room(rng.standard_normal(n))
        added = np.zeros(n)
        pos = 0
        while pos < n:
            t = (done + pos) / SR
            while k + 1 < len(sched) and sched[k + 1][0] <= t:
                k += 1
                src = _span_source(sched[k][2], np.random.default_rng(h.seed + 100 + k))
                gain = step_rms * 10 ** (sched[k][3] / 20) / RMS.get(sched[k][2], 1.0)
            end = min(n, int(round(sched[k][1] * SR)) - done) if k >= 0 else n
            end = max(end, pos + 1)
            if src is not None:
                added[pos:end] = gain * src(end - pos)  # type: ignore[operator]
            pos = end
        yield np.asarray(y + added, dtype=np.float32)
        done += n
