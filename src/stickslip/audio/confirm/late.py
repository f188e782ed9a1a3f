"""A stop the fast path never hears, found late on the step clock (opt-in: ``late=True``).

The change detector (:mod:`stickslip.audio.change`) hears a stop within 30-50 ms, but some
stops it never hears: a stop whose rise the template absorbed (a second instrument in the
stop's band), or one that departs from stepping in a direction the tuning never saw
(trained on a duller stop, a brighter one; trained on a quieter stop, a louder one). A
traverse then steps on until the guard stops it: no count at all. Every stop changes the
joint's *step-synchronous* sound (:mod:`stickslip.audio.features.stepclock`: the power on
each harmonic line of the step rate), and a change line by line over 0.24 s of the stop
separates stops from interference when the two lines that changed most are dropped (a
voice's or a radio's harmonics on the comb for a syllable or a note). :class:`LatePath` is
that measure run as a *second source of events* (:class:`LateParams` names the numbers):

* The stream is cut into chunks of ``chunk_s`` (sample ranges counted from the stream start:
  the verdicts do not depend on how the stream is cut into blocks). At the end of each chunk
  ``j`` the lines of the step rate (heard every ``rate_every`` chunks on the latest two) in
  the tuning's stepping band are measured on it.
* *Changed*: chunk ``j`` against chunks ``j - 3`` and ``j - 2`` (the stepping, 0.48 s; chunk
  ``j - 1`` is skipped: the stop may have begun in it), per line in standard deviations, the
  squares summed less the ``trim`` largest, as a normal deviate: at least ``min_z``; the two
  chunks of stepping agree with each other within ``steady_z``.
* *Persisted*: chunk ``j + 1`` against the same stepping, at least ``min_z`` too, a line kept
  in the sum moved by ``min_change_db`` or more on both, and the step rate did not move
  (``rate_moved``: a stop does not change it; a drifting clock walks the lines off the comb).
* *Sharp enough to judge*: the lines before held ``min_sharpness`` of the power of a comb
  four times wider, ``min_share`` of the band's, and stood ``min_line_snr`` standard
  deviations over their noise: otherwise no verdict (no event).
* *When it began*: the lines that moved, on frames of ``onset_frame_s`` every
  ``onset_hop_s``, projected on the change (:func:`onset_change_point`), and the step in
  that series fitted by least squares: the onset. Where the fit does not pin it within
  ``onset_tol_s``, the event carries ``onset_uncertain`` (a traverse refuses it).

The event is emitted at the end of chunk ``j + 1``: 0.5-0.75 s after the stop, where a stop
the fast path hears is emitted 0.5 s after it. It says it was found late
(``StopEvent.found_late``). It only adds stops the fast path did not give: it judges nothing
while the fast path holds a fire, is latched on a stop, or fired within the stretch it would
compare; once it has fired, it is latched (the fast path's fires on the same stop are
swallowed) until the lines are back where they were before the stop.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..events import StopEvent
from ..features.stepclock import STEP_CLOCK, Lines, chi2_as_z, line_powers, line_z, periodogram, step_rate_hz
from ..paramfield import param

__all__ = ["LATE", "LateJudgement", "LateParams", "LatePath", "late_event", "onset_change_point", "rate_moved"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LateParams:
    """When the late path calls a change of the step clock's lines a stop."""

    chunk_s: float = param(
        0.24, "s", "the chunks the stream is cut into (4 Hz: a syllable's harmonic seldom on a line)"
    )
    rate_every: int = param(8, "chunks", "the step rate is heard again this often, on the latest two chunks")
    trim: int = param(2, "lines", "the lines that changed most are dropped before the sum (a voice's two harmonics)")
    min_z: float = param(7.0, "standard deviations", "the trimmed sum, as a normal deviate, on both chunks after")
    min_change_db: float = param(1.0, "dB", "a line kept in the sum moved by this much on both")
    moved_z: float = param(3.0, "standard deviations", "a line that moved this far counts as moved")
    min_sharpness: float = param(
        0.8, "", "no verdict unless the lines before held this share of a comb four times wider's power ..."
    )
    min_share: float = param(0.05, "", "... and this share of the band's power ...")
    min_line_snr: float = param(
        10.0, "standard deviations", "... and stood this far over their noise (room sound: none)"
    )
    steady_z: float = param(4.0, "standard deviations", "the two chunks of stepping compared agree within this")
    rate_moved: float = param(
        0.0015, "of the rate", "the rate on the chunks after is the stepping's to this (stops: 0.09 % at most)"
    )
    max_wait: int = param(10, "chunks", "a stop found waits this long for the fast path's decision (2 s windows)")
    release_z: float = param(3.0, "standard deviations", "released once two chunks running are this near the stepping")
    onset_frame_s: float = param(0.02, "s", "when the stop began: frames of this length ...")
    onset_hop_s: float = param(0.005, "s", "... every this long")
    onset_tol_s: float = param(0.025, "s", "an onset the fit does not pin within this is uncertain")


LATE = LateParams()


@dataclass(frozen=True)
class LateJudgement:
    """What the late path measured on one candidate (kept in :attr:`LatePath.log`)."""

    #: the stream time of the end of the chunk after the skipped one, s
    at_s: float
    #: the step rate the lines were taken at, Hz
    rate_hz: float
    #: the trimmed deviate of the chunk after the skipped one, and of the next (persistence)
    z: float
    z_next: float
    #: the largest change of a line kept, dB (0 when none moved by moved_z standard deviations)
    change_db: float
    #: the lines before: sharpness and share of the band's power
    sharpness: float
    share: float
    #: the onset estimated back, stream time, s, and how far the fit leaves it open, s
    onset_s: float
    onset_spread_s: float
    #: "fired", or why not
    verdict: str


def rate_moved(before_hz: float, after_hz: float) -> float:
    """How far the step rate moved, as a fraction: the ratio of the two against the nearest of 1, 2, 3, 1/2, 1/3, 3/2,
    2/3 (the rate is heard at a multiple or a fraction of itself where the envelope's lines are stronger there); inf
    where either is not heard."""
    if not (math.isfinite(before_hz) and math.isfinite(after_hz) and before_hz > 0 and after_hz > 0):
        return math.inf
    r = after_hz / before_hz
    return min(abs(r / q - 1.0) for q in (1.0, 2.0, 3.0, 0.5, 1.0 / 3.0, 1.5, 2.0 / 3.0))


def _trimmed(z: FloatArray, trim: int) -> tuple[float, NDArray[np.int64]]:
    keep = np.argsort(-(z**2), kind="stable")[trim:]
    return chi2_as_z(float(np.sum(z[keep] ** 2)), int(keep.size)), np.asarray(keep, dtype=np.int64)


def _mean_lines(a: Lines, b: Lines) -> Lines:
    """Two estimates of the same lines averaged (their noise variance halved)."""
    return Lines(
        a.freq_hz,
        0.5 * (a.power + b.power),
        0.25 * (a.var + b.var),
        0.25 * (a.floor + b.floor),  # line_z's scatter term 4 P floor: halved as the average's variance is
        a.bins,
        a.band,
    )


def _db(before: Lines, after: Lines, keep: NDArray[np.int64], z: FloatArray, moved_z: float) -> float:
    top = np.maximum(np.maximum(before.power, after.power), 0.0)
    db = 10 * np.log10(np.maximum(after.power, 0.01 * top + 1e-300) / np.maximum(before.power, 0.01 * top + 1e-300))
    moved = keep[np.abs(z[keep]) >= moved_z]
    return float(db[moved[np.argmax(np.abs(db[moved]))]]) if moved.size else 0.0


def onset_change_point(
    x: FloatArray, sample_rate: float, freqs_hz: FloatArray, weights: FloatArray, p: LateParams = LATE
) -> tuple[float, float]:
    """When the lines ``freqs_hz`` changed in ``x``: the step fitted to their projection, and its spread.

    Frames of ``onset_frame_s`` (Hann) every ``onset_hop_s``; per frame, the power at each
    line (a DFT at its frequency) weighted by ``weights`` (the line's change over its
    variance: a matched filter) and summed. A step (two means) is fitted by least squares;
    the change is where the frame centres cross it (a frame's power ramps as its window
    slides over the change, symmetric about its centre). The spread: how far from the best
    split the splits reach whose misfit exceeds the best by no more than 4 times the
    residual variance per frame (x 4 for the frames' overlap).

    Returns
    -------
    (float, float)
        The change, s from the start of ``x``, and the spread, s; NaN, inf where ``x`` is
        shorter than 8 frames or nothing is weighted.
    """
    sr = float(sample_rate)
    n = int(round(p.onset_frame_s * sr))
    h = max(1, int(round(p.onset_hop_s * sr)))
    v = np.asarray(x, dtype=np.float64).ravel()
    m = (v.size - n) // h + 1 if v.size >= n else 0
    if m < 8 or freqs_hz.size == 0 or not np.any(weights != 0):
        return math.nan, math.inf
    idx = np.arange(n)[None, :] + h * np.arange(m)[:, None]
    frames = v[idx] * np.hanning(n)[None, :]
    e = np.exp(-2j * np.pi * np.outer(np.arange(n), freqs_hz) / sr)  # n x lines
    power = np.abs(frames @ e) ** 2  # frames x lines
    y = power @ weights
    c1, c2 = np.cumsum(y), np.cumsum(y**2)
    k = np.arange(1, m)  # split before frame k: frames 0..k-1 | k..m-1
    left = c2[k - 1] - c1[k - 1] ** 2 / k
    right = (c2[-1] - c2[k - 1]) - (c1[-1] - c1[k - 1]) ** 2 / (m - k)
    sse = left + right
    best = int(np.argmin(sse))
    var = float(sse[best]) / max(m - 2, 1)
    near = np.flatnonzero(sse - sse[best] <= 4.0 * 4.0 * var)
    spread = float(np.max(np.abs(near - best))) * h / sr
    kb = int(k[best])
    # the last frame before and the first after the split: their centres bracket the change
    t = (0.5 * (kb - 1 + kb) * h + 0.5 * n) / sr
    return t, spread


def late_event(got: tuple[float, float, bool], level: float, emitted_s: float) -> StopEvent:
    """The late path's stop (``(at_s, onset_s, uncertain)`` from :meth:`LatePath.step`) as an event.

    ``level`` is the fast path's latest level, ``emitted_s`` the stream time it is emitted
    at, s. An onset that is not finite is the find's time, uncertain.
    """
    at_s, onset_s, uncertain = got
    if not math.isfinite(onset_s):
        onset_s, uncertain = at_s, True
    return StopEvent(
        detected_at_s=at_s,
        onset_s=onset_s,
        level_db=level,
        confirmed_at_s=max(at_s, emitted_s),
        confirmed_s=at_s - onset_s if not uncertain else None,
        onset_uncertain=uncertain,
        found_late=True,
    )


class _Chunks:
    """The latest samples of the stream, in one array refilled now and then (absolute indices)."""

    def __init__(self, keep: int) -> None:
        self.keep = keep
        self._arr = np.zeros(3 * keep)  # the latest samples, _arr[:_buf_n]
        self._buf0 = 0  # absolute index of _arr[0]
        self._buf_n = 0

    def push(self, x: FloatArray) -> None:
        n = int(x.size)
        if n == 0:
            return
        keep = self.keep
        if self._buf_n + n > self._arr.size:  # full: the latest ``keep`` samples to the front (now and then)
            tail = max(0, min(keep, self._buf_n + n) - n)
            self._arr[:tail] = self._arr[self._buf_n - tail : self._buf_n].copy()
            self._buf0 += self._buf_n - tail
            self._buf_n = tail
            if self._buf_n + n > self._arr.size:
                self._arr = np.concatenate((self._arr[: self._buf_n], np.zeros(n + keep)))
        self._arr[self._buf_n : self._buf_n + n] = x
        self._buf_n += n

    def get(self, lo: int, hi: int) -> FloatArray:
        """The kept samples with absolute indices lo .. hi - 1 (empty if not all of them are kept)."""
        a, b = lo - self._buf0, hi - self._buf0
        if a < 0 or b > self._buf_n:
            return np.zeros(0)
        return self._arr[a:b]


#: a candidate: its chunk, the stepping's lines, the change per line, its deviate and the lines kept
_Candidate = tuple[int, Lines, FloatArray, float, NDArray[np.int64]]


class LatePath:
    """The late path's state: chunks, the rate, a candidate waiting for its next chunk, the latch.

    Parameters
    ----------
    sample_rate : int
        Samples per second, Hz.
    bands_hz : sequence of (lo, hi)
        The stepping band whose lines are judged, Hz (the tuning's sub-bands end to end).
    t0_s : float
        Stream time of the first sample, s.
    p : LateParams
    """

    def __init__(
        self, sample_rate: int, bands_hz: Sequence[tuple[float, float]], t0_s: float = 0.0, p: LateParams = LATE
    ) -> None:
        self.p = p
        self.sr = int(sample_rate)
        self.bands = [(float(lo), float(hi)) for lo, hi in bands_hz]
        #: samples per chunk (even: the rate is heard on two chunks and one sample, whose difference is 2 chunks)
        self.chunk = 2 * max(1, int(round(p.chunk_s * self.sr / 2)))
        self.reset(t0_s)

    def reset(self, t0_s: float = 0.0) -> None:
        """Forget everything; the next sample pushed is at stream time ``t0_s``."""
        self.t0 = float(t0_s)
        self._kept = _Chunks((self.p.max_wait + 6) * self.chunk)
        self._lines: dict[int, Lines] = {}  # chunk -> its lines at self._rate
        self._rate = math.nan
        self._rate_chunk = -(10**9)
        self._busy_end = 0  # the latest sample at which the fast path held, was latched or fired
        self._pending: _Candidate | None = None
        self._ready: tuple[float, float, bool, int, Lines] | None = None  # a stop found, waiting for the fast path
        self._release_ref: Lines | None = None
        self._release_ok = 0
        #: True from a late event until the lines are back to the stepping before it
        self.latched = False
        #: per candidate judged: what was measured
        self.log: list[LateJudgement] = []

    # --- feeding ------------------------------------------------------------------------------
    def push(self, x: NDArray[np.float64]) -> None:
        """Keep the samples ``x`` (the next after those pushed before)."""
        self._kept.push(x)

    def _samples(self, lo: int, hi: int) -> FloatArray:
        return self._kept.get(lo, hi)

    def next_stop(self, fed: int) -> int:
        """The next sample count at which :meth:`step` must be called (the end of the current chunk)."""
        return (fed // self.chunk + 1) * self.chunk

    def note_busy(self, sample: int) -> None:
        """The fast path confirmed a stop at absolute sample ``sample``: nothing before it is judged again."""
        self._busy_end = max(self._busy_end, int(sample))

    # --- judging ------------------------------------------------------------------------------
    def _chunk_lines(self, j: int) -> Lines | None:
        got = self._lines.get(j)
        if got is None:
            x = self._samples(j * self.chunk, (j + 1) * self.chunk)
            if x.size != self.chunk or not math.isfinite(self._rate):
                return None
            got = line_powers(x, self.sr, self._rate, self.bands)[0]
            self._lines[j] = got
        return got

    def _hear_rate(self, j: int) -> None:
        """The step rate on chunks j-1 and j (and one sample before: the difference is two whole chunks)."""
        x = self._samples((j - 1) * self.chunk - 1, (j + 1) * self.chunk)
        r = step_rate_hz(x, self.sr) if x.size else math.nan
        self._rate_chunk = j
        if not (math.isfinite(r) and math.isfinite(self._rate) and abs(r - self._rate) <= 1e-3 * self._rate):
            self._rate = r
            self._lines = {}  # lines at another rate: measured again as needed

    def step(self, fed: int, held: bool, stopped: bool, ready: bool = True) -> tuple[float, float, bool] | None:
        """The chunk that ends at sample ``fed`` is complete: judge. Returns (at_s, onset_s, onset_uncertain) or None.

        ``held``: the fast path holds a fire it has not decided on (a candidate waits for the
        decision: a confirmed fire gives the stop, a rejected one leaves it to the late path);
        ``stopped``: the fast path is latched on a stop it confirmed (nothing is judged);
        ``ready``: the fast path has learned the stepping (before it has, nothing is judged: the
        stretch compared must be stepping the fast path heard, not the room before it). Samples
        pushed after ``fed`` are not used.
        """
        j = fed // self.chunk - 1
        if fed != (j + 1) * self.chunk or j < 0:
            return None
        for old in [k for k in self._lines if k < j - self.p.max_wait - 4]:
            del self._lines[old]
        if self.latched:
            self._release(j)
            return None
        if stopped or not ready:
            self._busy_end = fed
            self._pending = None
            return None
        if self._ready is not None:
            return self._emit(fed, held)
        if self._pending is not None:
            if j == self._pending[0] + 1:
                self._persisted(j)
                return self._emit(fed, held) if self._ready is not None else None
            self._pending = None
        self._pending = self._candidate(j, fed)
        return None

    def _changed(self, l3: Lines, l2: Lines, after: Lines) -> tuple[Lines, FloatArray, float, NDArray[np.int64]]:
        """The stepping (two chunks averaged), each line's change to ``after``, its trimmed deviate, the lines kept."""
        before = _mean_lines(l3, l2)
        z = line_z(before, after)
        dev, keep = _trimmed(z, self.p.trim)
        return before, z, dev, keep

    def _comparable(self, l3: Lines | None, l2: Lines | None, after: Lines | None) -> bool:
        """Three chunks' lines, as many in each, and enough of them to judge."""
        if l3 is None or l2 is None or after is None:
            return False
        if after.power.size < max(STEP_CLOCK.min_lines, self.p.trim + 2):
            return False
        return l3.power.size == l2.power.size == after.power.size

    def _candidate(self, j: int, fed: int) -> _Candidate | None:
        """Chunk ``j`` against the stepping of chunks ``j - 3`` and ``j - 2``: a candidate if the lines changed."""
        p = self.p
        if j - self._rate_chunk >= p.rate_every or not math.isfinite(self._rate):
            self._hear_rate(j)
        # the stepping (j-3, j-2) must begin after the fast path's last activity, by a chunk
        if (j - 3) * self.chunk < self._busy_end + self.chunk or not math.isfinite(self._rate):
            return None
        l3, l2, l0 = self._chunk_lines(j - 3), self._chunk_lines(j - 2), self._chunk_lines(j)
        if not self._comparable(l3, l2, l0):
            return None
        assert l3 is not None and l2 is not None and l0 is not None
        before, z, dev, keep = self._changed(l3, l2, l0)
        if not dev >= p.min_z:
            return None
        # the stepping before must itself be steady: a stepping that begins (after the room's sound, the fast path
        # warmed up on it) or whose lines walk is not a stop
        if not _trimmed(line_z(l3, l2), p.trim)[0] < p.steady_z:
            self.log.append(
                LateJudgement(
                    self.t0 + fed / self.sr, self._rate, dev, math.nan, math.nan, math.nan, math.nan, math.nan,
                    math.inf, "the stepping before was not steady",
                )
            )  # fmt: skip
            return None
        return j, before, z, dev, keep

    def _rate_held(self, cand: _Candidate, at_s: float) -> _Candidate | None:
        """The step rate, heard afresh on the stepping and on the two chunks after, did not move (a stop does not
        change it; a rate heard at a simple multiple or fraction is the same clock): the candidate, measured again
        at that rate if the lines were taken at one heard a while ago; None where it moved or no longer changed."""
        j0, before, z0, dev0, keep0 = cand
        c, p = self.chunk, self.p
        rb = step_rate_hz(self._samples((j0 - 3) * c - 1, (j0 - 1) * c), self.sr)
        ra = step_rate_hz(self._samples(j0 * c - 1, (j0 + 2) * c), self.sr)
        moved = rate_moved(rb, ra)
        if moved > p.rate_moved:
            self.log.append(
                LateJudgement(
                    at_s, rb, dev0, math.nan, math.nan, math.nan, math.nan, math.nan, math.inf,
                    f"the step rate moved ({100 * moved:.2f} %)",
                )
            )  # fmt: skip
            return None
        if abs(rb / self._rate - 1.0) > 0.25 * p.rate_moved:  # the lines were taken at a rate heard a while ago: again
            self._rate, self._rate_chunk, self._lines = rb, j0 + 1, {}
            l3, l2, after0 = self._chunk_lines(j0 - 3), self._chunk_lines(j0 - 2), self._chunk_lines(j0)
            if not self._comparable(l3, l2, after0):
                return None
            assert l3 is not None and l2 is not None and after0 is not None
            before, z0, dev0, keep0 = self._changed(l3, l2, after0)
            if not (dev0 >= p.min_z and _trimmed(line_z(l3, l2), p.trim)[0] < p.steady_z):
                return None
        return j0, before, z0, dev0, keep0

    def _sharpness(self, j0: int) -> tuple[float, float]:
        """How sharp the lines were before, and the share of the band they held: on the stepping's own samples."""
        xb = self._samples((j0 - 3) * self.chunk, (j0 - 1) * self.chunk)
        if xb.size != 2 * self.chunk:
            return math.nan, math.nan
        pb = periodogram(xb)
        lb, whole = line_powers(pb, self.sr, self._rate, self.bands)
        wide = float(np.sum(line_powers(pb, self.sr, self._rate, self.bands, STEP_CLOCK.sharp_width)[0].power))
        p0 = float(np.sum(lb.power))
        return p0 / wide if wide > 0 else math.nan, p0 / whole if whole > 0 else math.nan

    def _persisted(self, j: int) -> None:
        """The chunk after a candidate's is complete: did the change persist? A stop found is kept in ``_ready``."""
        assert self._pending is not None
        cand, self._pending = self._pending, None
        at_s = self.t0 + (j + 1) * self.chunk / self.sr
        held = self._rate_held(cand, at_s)
        if held is None:
            return
        j0, before, z0, dev0, keep0 = held
        l1 = self._chunk_lines(j0 + 1)
        after0 = self._lines.get(j0)
        if l1 is None or after0 is None or l1.power.size != before.power.size:
            return
        p = self.p
        z1 = line_z(before, l1)
        dev1, keep1 = _trimmed(z1, p.trim)
        db0, db1 = _db(before, after0, keep0, z0, p.moved_z), _db(before, l1, keep1, z1, p.moved_z)
        sharp, share = self._sharpness(j0)
        onset_s, spread = math.nan, math.inf
        if not (sharp >= p.min_sharpness and share >= p.min_share and self._stands_out(before)):
            verdict = "not sharp enough to judge"
        elif not dev1 >= p.min_z:
            verdict = "did not persist"
        elif not (abs(db0) >= p.min_change_db and abs(db1) >= p.min_change_db):
            verdict = f"changed by less than {p.min_change_db:g} dB"
        else:
            verdict = "fired"
            onset_s, spread = self._onset(j0, before, after0, l1, z0, z1)
        self.log.append(LateJudgement(at_s, self._rate, dev0, dev1, db0, sharp, share, onset_s, spread, verdict))
        if verdict == "fired":
            uncertain = not (math.isfinite(onset_s) and spread <= p.onset_tol_s)
            self._ready = (at_s, onset_s, uncertain, j0, before)

    def _onset(
        self, j0: int, before: Lines, after0: Lines, l1: Lines, z0: FloatArray, z1: FloatArray
    ) -> tuple[float, float]:
        """The onset (stream time, s) and its spread (s): the lines that moved on both chunks, weighted by their
        change over its variance (:func:`onset_change_point`)."""
        mz = self.p.moved_z
        moved = (np.abs(z0) >= mz) & (np.abs(z1) >= mz) & (np.sign(z0) == np.sign(z1))
        d = 0.5 * (after0.power + l1.power) - before.power
        var = before.var + 0.5 * (after0.var + l1.var) + 1e-300
        w = np.where(moved, d / var, 0.0)
        lo = (j0 - 2) * self.chunk
        x = self._samples(lo, (j0 + 1) * self.chunk)
        t, spread = onset_change_point(x, self.sr, before.freq_hz, w, self.p)
        return self.t0 + lo / self.sr + t, spread

    def _stands_out(self, before: Lines) -> bool:
        """The stepping's lines hold power well clear of their estimate's noise (``min_line_snr``)."""
        sd = math.sqrt(float(np.sum(before.var)))
        return sd > 0.0 and float(np.sum(before.power)) >= self.p.min_line_snr * sd

    def _emit(self, fed: int, held: bool) -> tuple[float, float, bool] | None:
        """A stop found: emitted once the fast path has no fire it is deciding on, unless it confirmed one since."""
        assert self._ready is not None
        at_s, onset_s, uncertain, j0, before = self._ready
        if held and fed - (j0 + 2) * self.chunk <= self.p.max_wait * self.chunk:
            return None  # the fast path is deciding on a fire: a confirmed one gives the stop
        self._ready = None
        if (j0 - 3) * self.chunk < self._busy_end + self.chunk or held:
            return None  # the fast path gave this stop (or held a fire for longer than any window)
        self.latched = True
        self._release_ref, self._release_ok = before, 0
        return at_s, onset_s, uncertain

    def finish(self) -> tuple[float, float, bool] | None:
        """The stream ended (after the fast path's last decision): a stop found and not yet emitted, if any."""
        if self._ready is None:
            return None
        at_s, onset_s, uncertain, j0, _ = self._ready
        self._ready = None
        if (j0 - 3) * self.chunk < self._busy_end + self.chunk:
            return None
        self.latched = True
        return at_s, onset_s, uncertain

    def _release(self, j: int) -> None:
        """Latched: released once two chunks running are back within ``release_z`` of the stepping before."""
        ref = self._release_ref
        lj = self._chunk_lines(j)
        if ref is None or lj is None or lj.power.size != ref.power.size:
            self._release_ok = 0
            return
        dev, _ = _trimmed(line_z(ref, lj), self.p.trim)
        self._release_ok = self._release_ok + 1 if dev < self.p.release_z else 0
        if self._release_ok >= 2:
            self.latched = False
            self._release_ref = None
            self._busy_end = (j + 1) * self.chunk
