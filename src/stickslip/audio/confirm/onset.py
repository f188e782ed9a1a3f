"""When did the confirmed stop begin? The same per-frame evidence, asked a second question.

A window that persisted says a stop is there, not that it began at the fire's onset. A
traverse counts its steps to the onset, so an onset the evidence doubts is flagged
``onset_uncertain`` (the traverse refuses it: measure again) rather than counted to
(:meth:`OnsetJudge.doubt`):

* *a stop covered before*: a fire was rejected since the last confirmed stop, its window
  *covered* (the frames that were not stop-like had a median stop-likeness at or below
  ``covered_a``: sound added where the stop lowers it), and no ``clean_s`` of clean
  stepping was heard between it and this fire: the rejected fire may have been this stop;
* *a template learned anew since a rejected fire*: it may have learned the stop;
* *a gap after the fire*: in the window's first half the frames were not stop-like for as
  long as the hold: the sound that fired went away (a knock or a drift just before the stop);
* *a break before the fire*: between the onset's crossing and the fire, more frames running were
  not stop-like than the hold's ``max_dips`` (a stop's own dips, tuned), over a stepping that was
  hot by itself in the ``base_s`` before the crossing: the run the onset began may be one of its
  flickers, not the one that fired (off the tuning's rate the stepping flickers hot for a few
  frames; the hold keeps such a flicker's crossing when the stop's frames follow within its window);
  with ``break_past_fire`` *a break within a hold after the fire* too: the fire itself on such a
  flicker, the stop's frames after the break (shorter than the hold: no *gap after the fire*);
* *a fire weaker than the stop*: the stop-likeness over the fire's hold was under
  ``fire_level`` of that over the window's second half;
* *a stop heard late*: the stop-like run that ends in the fire (dips of ``back_dips``
  frames) began more than ``tol_s`` before the onset, at ``back_level`` of the window's
  stop-likeness: interference held the full verdict back;
* the climb to the onset (:meth:`OnsetJudge.rise`): a climb from the stepping's level to
  the threshold slower than ``slow_s`` (a reverberant room, a stop that barely clears the
  threshold) is *a slow rise*; over a stepping near the threshold (``quiet``), a first
  crossing more than ``tol_s`` before the onset is *a stepping near the threshold*; over
  clean stepping, where the stop was hot and held but the hold began again, the onset is
  taken back to that first hot frame (no more than ``back_max_s``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..events import StopEvent
from ..paramfield import param
from ..tuningfile import Tuning
from .evidence import FrameLog
from .persistence import longest_gap

__all__ = ["ONSET", "OnsetJudge", "OnsetParams", "OnsetVerdict"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class OnsetParams:
    """When the evidence doubts a confirmed stop's onset, or takes it back."""

    tol_s: float = param(0.025, "s", "an onset this far from where the evidence says the stop began is wrong")
    back_level: float = param(
        0.8, "of the window's a", "a stop-like run at this share of the stop's level that began before was the stop"
    )
    back_dips: int = param(3, "frames", "dips this short do not end a stop-like run")
    fire_level: float = param(
        1.0 / 3.0, "of the window's a", "a fire under this share of the stop-likeness that persisted was not the stop"
    )
    covered_a: float = param(
        -0.5, "stop-likeness", "a rejected window whose other frames sat at or below this was covered, not stepping"
    )
    clean_s: float = param(0.15, "s", "clean stepping: this long a run neither stop-like nor covered")
    base_s: float = param(0.2, "s", "the stepping's level is its median stop-likeness over this long ...")
    base_gap_s: float = param(0.05, "s", "... ending this long before the crossing")
    slow_s: float = param(
        0.02, "s", "a climb from the stepping's level to the threshold slower than this comes late (+28 ms on 24 ms)"
    )
    rise_share: float = param(0.25, "", "the climb runs over frames at least this share of the way to the stop")
    quiet: float = param(
        0.3, "thresholds", "an onset is taken back only over a stepping this quiet (nearer: it crosses by chance)"
    )
    back_max_s: float = param(0.1, "s", "and by no more than this (further back the run is no longer the climb)")
    stepping_pct: float = param(
        95.0, "percentile", "the climb is measured from above this percentile of the stepping's stop-likeness ..."
    )
    stepping_cap: float = param(
        0.5, "", "... never above this share of the way to the stop (another rate flickers to 0.5-1.4 thresholds)"
    )
    held_dips: int = param(1, "frames", "a hot frame after which the climb held: no run under its level longer")
    break_check: bool = param(
        True, "", "doubt an onset whose stop-like run broke (over max_dips) before the fire, the stepping hot by itself"
    )
    break_past_fire: bool = param(
        True, "", "ask the break also over one hold past the fire (a fire on a flicker, the stop after its break)"
    )


ONSET = OnsetParams()


@dataclass
class OnsetVerdict:
    """What the evidence says of a confirmed stop's onset."""

    #: why the onset is doubted (None: nothing says so)
    why: str | None = None
    #: the onset taken back to the climb's first held hot frame, stream time, s (None: the fire's stands)
    retimed: float | None = None
    #: the climb from the stepping's level to the threshold, s (None: not measured)
    climb: float | None = None


@dataclass(frozen=True)
class _Base:
    """The stepping before a crossing: the first frame of its span, its stop-likeness (thresholds) and median."""

    lo: int
    levels: FloatArray
    b0: float


class OnsetJudge:
    """The onset questions for one confirming detector (see the module docstring).

    Parameters
    ----------
    tuning : Tuning
        The fast path's tuning (its hold, onset lag, threshold and method).
    log : FrameLog
        The per-frame evidence the confirming detector keeps.
    window_frames : int
        The confirmation window, frames.
    look : int
        How far back from a fire the evidence is kept whatever the block size, frames.
    p : OnsetParams
    """

    def __init__(self, tuning: Tuning, log: FrameLog, window_frames: int, look: int, p: OnsetParams = ONSET) -> None:
        self.log, self.window_frames, self.look, self.p = log, window_frames, look, p
        self.hold_frames = int(tuning.hold_frames) + int(tuning.max_dips)
        self.max_dips = int(tuning.max_dips)
        self.lag = float(tuning.onset_lag_s)
        self.levels = tuning.method == "template"  # margins + 1 are a / threshold (a band tuning's are dB)
        self.threshold = float(tuning.threshold_db)

    @property
    def covered_margin(self) -> float:
        """The margin of a stop-likeness of ``covered_a`` (template tunings; -inf for a band tuning)."""
        if not self.levels:
            return -math.inf
        return self.p.covered_a / self.threshold - 1.0

    def covered(self, m: FloatArray) -> bool:
        """Were the frames of a rejected window that were not stop-like covered (see ``covered_a``)?"""
        low = m[m < 0.0]
        return bool(low.size) and float(np.median(low)) <= self.covered_margin

    def doubt(
        self,
        ev: StopEvent,
        fire: int,
        frames: int,
        covered_at: int | None,
        rejected_fire: int | None,
        relearned: list[int],
    ) -> OnsetVerdict:
        """Why the stop that persisted over ``frames`` after frame ``fire`` may not have begun at ``ev.onset_s``.

        ``covered_at`` is the end of the latest rejected window that was covered,
        ``rejected_fire`` the frame of the latest rejected fire since the last confirmed
        stop, ``relearned`` the samples at which the template was learned anew.
        """
        why = self._before_fire(fire, covered_at, rejected_fire, relearned)
        if why is not None:
            return OnsetVerdict(why)
        m, _ = self.log.window(fire, frames)
        if m.size == 0:
            return OnsetVerdict()
        half = m[: max(1, min(m.size, self.window_frames // 2))]
        if longest_gap(half >= 0.0) >= self.hold_frames:
            return OnsetVerdict("a gap after the fire")
        broke = self._break_before(ev, fire, frames)
        if broke is not None:
            return OnsetVerdict(
                f"a break {broke[2]} the fire ({broke[0]} frames not stop-like after the onset; the stepping before it"
                f" hot in {broke[1]} frames)"
            )
        if not self.levels:
            return OnsetVerdict()
        win = m[: self.window_frames] + 1.0
        late = win[win.size // 2 :]
        if late.size >= 2 and self._weak_fire(fire, late):
            return OnsetVerdict("a fire weaker than the stop")
        if self._heard_late(ev, fire, win):
            return OnsetVerdict("a stop heard late")
        return self.rise(ev, fire, float(np.median(late)) if late.size else math.nan)

    def _before_fire(
        self, fire: int, covered_at: int | None, rejected_fire: int | None, relearned: list[int]
    ) -> str | None:
        """A rejected fire before this one that may have been this stop: covered, or learned by the template."""
        log = self.log
        if covered_at is not None and fire - covered_at <= self.look:
            between, _ = log.window(covered_at, fire - self.hold_frames - covered_at)
            clean = (between < 0.0) & (between > self.covered_margin)
            clean_frames = max(1, int(round(self.p.clean_s * log.sample_rate / log.hop)))
            if between.size < clean_frames or longest_gap(~clean) < clean_frames:
                return "a stop covered before"
        if rejected_fire is not None and self.levels and fire - rejected_fire <= self.look:
            lo_s = rejected_fire * log.hop + log.frame - 1
            if any(lo_s < end <= fire * log.hop + log.frame - 1 for end in relearned):
                return "a template learned anew since a rejected fire"
        return None

    def _break_before(self, ev: StopEvent, fire: int, frames: int) -> tuple[int, int, str] | None:
        """The longest run of frames not stop-like between the onset's crossing and the fire (``break_past_fire``: to
        one hold past it, within the ``frames`` that persisted), where longer than the tuning's ``max_dips``, and the
        hot frames of the stepping before the crossing (``base_s`` ending ``base_gap_s`` before it), where it had any:
        it flickers hot by itself, and the run the onset began may be a flicker; and where the break lies ("before",
        or "within a hold after": the fire itself on the flicker). None: no such break, a stepping never hot, the check
        off, or the frames not kept."""
        log = self.log
        if not self.p.break_check:
            return None
        cross = ev.onset_s + self.lag
        c = int(math.floor(((cross - log.t0) * log.sample_rate - log.frame + 1) / log.hop)) + 1  # first frame after
        lo = max(c, log.base, fire - self.look)
        base = self._base(c, fire)
        if lo >= fire or base is None:
            return None
        hi = fire + (min(self.hold_frames, frames) if self.p.break_past_fire else 0)
        held = np.array([log.margin(i) >= 0.0 for i in range(lo, hi + 1)], dtype=bool)
        run = longest_gap(held)
        base_n = max(1, int(round(self.p.base_s * log.sample_rate / log.hop)))
        hot = sum(log.hot(i) for i in range(base.lo, base.lo + base_n))
        if run <= self.max_dips or hot == 0:
            return None
        return run, hot, "before" if longest_gap(held[: fire + 1 - lo]) > self.max_dips else "within a hold after"

    def _weak_fire(self, fire: int, late: FloatArray) -> bool:
        """Was the stop-likeness over the fire's hold under ``fire_level`` of the window's second half?"""
        at_fire = self.log.between(fire + 1 - self.hold_frames, fire + 4)
        at_fire = at_fire[np.isfinite(at_fire)]  # a fire at the warm-up's end (listening began at the stop): none
        weak = self.p.fire_level * float(np.median(late))
        return at_fire.size * 2 >= self.hold_frames and float(np.median(at_fire + 1.0)) < weak

    def _heard_late(self, ev: StopEvent, fire: int, win: FloatArray) -> bool:
        """Did the stop-like run that ends in the fire begin ``tol_s`` or more before the onset, at the stop's level?"""
        log, p = self.log, self.p
        lo = max(log.base, fire - self.look)
        k = log.run_start(fire, lo, 0.0, p.back_dips)
        began = log.end_s(k) - self.lag
        sr, F, H = log.sample_rate, log.frame, log.hop
        on = max(k + 1, min(fire, int((ev.onset_s + self.lag - log.t0) * sr - F + 1) // H + 1))
        if ev.onset_s - began > p.tol_s:
            before, _ = log.window(k - 1, on - k)
            return bool(before.size) and float(np.median(before + 1.0)) >= p.back_level * float(np.median(win))
        return False

    def _base(self, c: int, fire: int) -> _Base | None:
        """The stepping's level before the crossing in frame ``c`` (None: not kept, or listening began about now)."""
        log, p = self.log, self.p
        base_n = max(1, int(round(p.base_s * log.sample_rate / log.hop)))
        lo = c - int(round(p.base_gap_s * log.sample_rate / log.hop)) - base_n
        if lo < max(fire - self.look, log.base):  # only what is always kept: no dependence on block sizes
            return None
        base = log.between(lo, lo + base_n)
        base = base[np.isfinite(base)]
        if base.size * 2 < base_n:
            return None  # listening began about now: no stepping to rise from
        return _Base(lo, base + 1.0, float(np.median(base + 1.0)))

    def rise(self, ev: StopEvent, fire: int, stop_level: float) -> OnsetVerdict:
        """The stop-likeness's climb to the onset: a doubt, or the onset taken back (see the module docstring).

        The crossing that set ``onset_s`` is in frame ``c``; the stepping's level ``b0`` the
        median stop-likeness (in thresholds) over ``base_s`` ending ``base_gap_s`` before it,
        the stop's ``stop_level``. Walking back from ``c`` over the frames at least
        ``rise_share`` of the way from the one to the other, the climb began at frame ``k``;
        it first reached the threshold at frame ``f0``. Nothing is judged where the levels
        are not known (no stepping heard before, a stop no higher than the stepping).
        """
        log, p = self.log, self.p
        if not math.isfinite(stop_level):
            return OnsetVerdict()
        cross = ev.onset_s + self.lag
        c = (
            int(math.floor(((cross - log.t0) * log.sample_rate - log.frame + 1) / log.hop)) + 1
        )  # first frame ending after
        c = min(c, fire)
        base = self._base(c, fire)
        if base is None or not stop_level > base.b0:
            return OnsetVerdict()
        b0 = base.b0
        # as a margin; a stepping under the template (a below 0) is no lower a start: its frames would all continue it
        level = max(b0, 0.0) + p.rise_share * (stop_level - max(b0, 0.0)) - 1.0
        k = log.run_start(c, base.lo, level, p.back_dips)
        f0 = next((i for i in range(k, c + 1) if log.margin(i) >= 0.0), c)
        if b0 > p.quiet:
            # a stepping near the threshold (the step rate far from the tuning's, a template gone stale) crosses it by
            # chance: only where the first crossing of the climb says the onset came late is it a doubt
            late_by = ev.onset_s - log.crossing_s(f0, self.lag)
            return OnsetVerdict("a stepping near the threshold" if late_by > p.tol_s else None)
        f1 = self._first_held_hot(k, c, level)
        onset = log.crossing_s(f1, self.lag) if f1 < c else ev.onset_s
        if ev.onset_s - onset > p.back_max_s:
            return OnsetVerdict("a stop heard late")
        climb = self._climb(ev, c, base, level, stop_level, onset)
        if climb > p.slow_s:
            return OnsetVerdict(f"a slow rise ({1e3 * climb:.0f} ms from the stepping's level to the threshold)", None,
                                climb)  # fmt: skip
        return OnsetVerdict(None, onset if onset < ev.onset_s else None, climb)

    def _first_held_hot(self, k: int, c: int, level: float) -> int:
        """The first hot frame (the full verdict: not a burst's rise) from which the climb held to ``c``: never under
        ``level`` for more than ``held_dips`` frames running (``c`` if none)."""
        log = self.log
        below = np.array([log.margin(i) < level for i in range(k, c + 1)], dtype=bool)
        return next(
            (i for i in range(k, c) if log.hot(i) and longest_gap(~below[i - k :]) <= self.p.held_dips),
            c,
        )

    def _climb(self, ev: StopEvent, c: int, base: _Base, level: float, stop_level: float, onset: float) -> float:
        """The climb, s: from the end of the frame before it to its first frame over the threshold, or to the
        crossing the onset is taken from, whichever is later. It begins where the stop-likeness left the stepping's
        own range (at another step rate the stepping flickers to 0.5-1.4 thresholds, and a walk back over it would
        measure its flicker as the stop's climb)."""
        log, p = self.log, self.p
        hi = float(np.percentile(base.levels, p.stepping_pct))
        k = log.run_start(c, base.lo, max(level, min(hi, p.stepping_cap * (base.b0 + stop_level)) - 1.0), p.back_dips)
        f0 = next((i for i in range(k, c + 1) if log.margin(i) >= 0.0), c)
        return max(log.end_s(f0), min(onset, ev.onset_s) + self.lag) - log.end_s(k - 1)
