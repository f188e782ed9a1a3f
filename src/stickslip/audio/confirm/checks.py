"""The checks a fire that persisted must pass besides persistence, on the samples kept around it.

* the step clock agrees, where asked (:mod:`.sync`, opt-in);
* the stepping did not merely stop (:mod:`.pause`); if it did, the detector waits for it to
  come back (:mod:`.resume`);
* the change was on the step clock's lines, not sound added between them (:mod:`.clocked`).

Each compares the window after the fire with the stepping before it: ``span_s`` of samples
ending ``gap_s`` before the fire's frame (``SyncParams``). A fire soon after a rejected one
keeps its chain's reference: the interference may have been going on since.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..events import StopEvent
from ..features.stepclock import LineChange
from ..tuningfile import Tuning
from .chain import Fire
from .clocked import ClockedCheck, ClockedParams, OnClock, model_thin
from .evidence import FrameLog, KeptSamples
from .inside import Held, InsideParams, held_early, held_inside, held_out_of_step, held_refired, onset_in_phase
from .pause import PauseCheck, PauseParams, Stopped
from .resume import AfterPause
from .sync import SyncCheck, SyncParams, step_clock_verdict

__all__ = ["Verdicts", "WindowChecks"]


class Verdicts(Protocol):
    """Where the checks note what they measured, per fire (its ``detected_at_s``, what): the confirming detector's
    log."""

    step_clock: list[tuple[float, LineChange]]
    stopped: list[tuple[float, Stopped]]
    clocked: list[tuple[float, OnClock]]


class WindowChecks:
    """The step clock's, the pause's and the clocked check, on the samples ``kept`` (see the module docstring).

    Parameters
    ----------
    tuning : Tuning
        The fast path's tuning.
    kept : KeptSamples
        The latest samples of the stream, counted from its start (the confirming detector's).
    sync_bands : list of (float, float)
        The band the step clock is judged on, Hz (empty: not asked).
    pause, sync : PauseParams, SyncParams
    clocked : ClockedParams or None
        None: the change is not judged on the step clock's lines.
    """

    def __init__(
        self,
        tuning: Tuning,
        kept: KeptSamples,
        sync_bands: list[tuple[float, float]],
        pause: PauseParams,
        sync: SyncParams,
        clocked: ClockedParams | None,
        inside: InsideParams | None = None,
    ) -> None:
        self.kept, self.p_sync = kept, sync
        self._H, self._F, sr = int(tuning.hop), int(tuning.frame), int(tuning.sample_rate)
        self.span, self.gap = int(round(sync.span_s * sr)), int(round(sync.gap_s * sr))
        self.min_before = sync.min_s * sr
        self.pause = PauseCheck(tuning, pause)
        self.after = AfterPause(self.pause, pause)
        self.sync = SyncCheck(sync_bands, sr, sync)
        self.clocked = ClockedCheck(tuning, clocked) if clocked is not None else None
        #: where the joint's sound read in phase steps, against a confirmed stop's onset (None: not read)
        self.inside = inside
        #: what the clocked check measured on the fire last judged (None: not judged)
        self.on_clock: OnClock | None = None
        #: where the fire last heard's own reference began, absolute sample (under 0: the stream's start cut it)
        self.ref_start = 0

    def reset(self, step_rate_hz: float | None) -> None:
        self._next_keep = 0  # the next stretch offered to the clocked check as stepping to keep begins here
        self.ref_start = 0
        for part in (self.pause, self.after, self.sync):
            part.reset()
        if self.clocked is not None:
            self.clocked.reset(step_rate_hz)

    def _ref_end(self, fire: int) -> int:
        """Where the reference before the fire at frame ``fire`` ends, absolute sample: ``gap_s`` before the fire's
        first sample (it begins ``span_s`` earlier, under 0 where the stream's start cut it)."""
        return fire * self._H + self._F - self.gap

    def before(self, fire: int) -> NDArray[np.float64]:
        """The stepping before the fire at frame ``fire``: ``span_s`` ending ``gap_s`` before it (as kept)."""
        end = self._ref_end(fire)
        return self.kept.get(end - self.span, end)

    def after_fire(self, fire: int, n: int) -> NDArray[np.float64]:
        """The ``n`` samples kept from the first sample after the fire's frame ``fire``."""
        start = fire * self._H + self._F
        return self.kept.get(start, start + n)

    def hear_before(self, fire: int, recent: bool, frames: FrameLog) -> None:
        """The stepping before the fire at frame ``fire`` is each check's reference (``recent``: a fire soon after
        a rejected one, which keeps its chain's reference where there is one)."""
        end = self._ref_end(fire)
        self.ref_start = end - self.span  # (under 0: this fire's, cut by the start)
        if not recent or not math.isfinite(self.pause.before_power):
            self.pause.hear_before(self.before(fire), self.min_before)
        if self.sync.bands and (not recent or self.sync.ref is None):
            self.sync.ref = self.before(fire)
        if self.clocked is not None and (not recent or self.clocked.ref is None):
            g, sp = self.gap // self._H, self.span // self._H
            self.clocked.hear_before(self.before(fire), frames.between(fire - g - sp, fire - g), end)

    def keep_stepping(self, fed: int, frames: FrameLog) -> None:
        """Every ``span_s`` of the stream (from its start) that ended by sample ``fed``, offered to the clocked check
        as stepping to keep, with its frames' margins (the frames that lie wholly in it)."""
        if self.clocked is None or self.clocked.p.kept_age_s <= 0.0:
            return
        while self._next_keep + self.span <= fed:
            lo, hi = self._next_keep, self._next_keep + self.span
            margins = frames.between(-(-lo // self._H), (hi - self._F) // self._H + 1)
            self.clocked.keep(hi, self.kept.get(lo, hi), margins)
            self._next_keep = hi

    def passed(self, ev: StopEvent, fire: int, frames: int, log: Verdicts, now_s: float, affirm: bool = False) -> bool:
        """The fire at frame ``fire``, which persisted over ``frames``: the step clock agrees, the stepping went on
        (else the pause is noted as judged at ``now_s``, s) and the change was on the clock's lines.

        ``affirm``: a fire stop-like throughout but not hot (:func:`.persistence.stoplike_throughout`): it passes only
        where the clocked check affirms it (both readings of the lines at ``min_affirm``), asked first, and then the
        others."""
        self.on_clock = None
        if affirm:
            return self._on_clock(ev, fire, frames, log, True) and self._others(ev, fire, frames, log, now_s)
        return self._others(ev, fire, frames, log, now_s) and self._on_clock(ev, fire, frames, log, False)

    def _others(self, ev: StopEvent, fire: int, frames: int, log: Verdicts, now_s: float) -> bool:
        return self._in_step(ev, fire, frames, log) and not self._stepping_stopped(ev, fire, frames, log, now_s)

    def onset_doubt(self, onset: int, hold_in_step: bool = False) -> str | None:
        """Why a confirmed stop whose onset is at absolute sample ``onset`` may not have begun there: its lines, read
        in phase over ``onset_read_s`` from it, do not show the stop (under ``min_a``: the fire came before the
        stop, and the stop came in its window); or the stepping before the fire was over ``onset_ref_stoplike``
        stop-like with none kept, or under ``min_s`` of stepping was heard before it (``onset_short_ref``; with
        ``onset_short_span``, under its own ``span_s`` where the stream's start cut it short; the
        stream began near it; not an onset at listening's start, which :mod:`~stickslip.audio.change.start`
        judged): no stepping to place it by, it may have begun there; or the stepping's lines modelled read its fire
        within ``model_max_z`` on fewer than ``model_min_bands`` locked sub-bands (too few to veto it:
        :func:`~.clocked.model_thin`); or the stepping's lines modelled read its fire
        and let it through, but its lines held under ``model_in_step`` of the model's share in phase and their power
        out of phase rose ``model_added_db`` (not in step with the steps, as a stop's stay: sound of another kind
        added on them; :meth:`out_of_step`, not asked with ``hold_in_step``: the caller reads it past the window);
        or, the rate told and off the tuning's, the
        stepping's lines modelled could have judged its fire and did not, nor do the lines affirm it
        (:meth:`~.clocked.ClockedCheck.unjudged`): the levels alone counted it. None: they do, or nothing was read."""
        if self.clocked is None:
            return None
        c = self.clocked
        if c.enabled and c.ref_stoplike > c.p.onset_ref_stoplike:  # no stepping heard before it to place it by
            return f"the stepping before it {100 * c.ref_stoplike:.0f} % stop-like, none kept: it may have begun there"
        heard = 0 if c.ref is None else c.ref.size
        cut = c.p.onset_short_span and self.ref_start < 0 and math.isnan(c.ref_age_s)  # (not a kept span)
        short = c.p.onset_short_ref and heard < (self.span if cut else c.p.min_s * c.sample_rate)  # too little known
        if c.enabled and short and onset > 0:  # (at the start of listening: the warm-up judged it began at the stop)
            return f"only {heard / c.sample_rate:.2f} s of stepping heard before it: it may have begun there"
        if c.enabled and model_thin(c, self.on_clock):  # the model read it within on one line: it cannot veto
            assert self.on_clock is not None
            return (
                f"the stepping's lines modelled on {len(c.model.locked_bands()) if c.model else 0} locked sub-band(s)"
                f" read it within (z {self.on_clock.still_z:.2f}): too few to veto"
            )
        step = self.out_of_step()
        if step is not None and not (hold_in_step and c.p.model_in_step_hold_z > 0.0 and c.p.model_hold_s > 0.0):
            return step
        if c.enabled and c.unjudged(onset, self.on_clock):  # off the tuning's rate: nothing but the levels counted it
            return "off the tuning's rate, neither the stepping's lines modelled nor the lines in phase affirm it"
        x = self.kept.get(onset, onset + int(round(c.p.onset_read_s * c.sample_rate)))
        a = c.at_onset(x, self.on_clock)
        if math.isfinite(a) and a < c.p.min_a:
            return f"the stop not in phase with the steps at its onset (a {a:.2f})"
        return self._step_elsewhere(onset)

    def held_out_of_step(self, fire: Fire, ev: StopEvent, end: int, t0_s: float = 0.0) -> Held | None:
        """``ev``, confirmed on ``fire`` (its window ended at sample ``end``; onset doubts asked with ``hold_in_step``),
        held where its lines out of step alone doubt it (:func:`.inside.held_out_of_step`), or, before the model is
        ready, to read them past the window (:func:`.inside.held_early`; ``t0_s``: the stream's start). None: now."""
        got = held_out_of_step(fire, ev, None if ev.onset_uncertain else self.out_of_step(), end, self.clocked)
        on = int(round((ev.onset_s - t0_s) * self.clocked.sample_rate)) if self.clocked is not None else 0
        return got if got is not None else held_early(fire, ev, (end, on), self.clocked)

    def held_inside(self, fire: Fire, fed: int, t0_s: float, held: Held | None) -> Held | None:
        """A stop that began inside ``fire``'s rejected window (:func:`.inside.held_inside`; ``fed``: the samples
        heard, ``t0_s``: the stream's start, s), held until emitted; None: none; ``held`` where not read (not all kept:
        the stream began inside the lead), or no clocked check or no inside search."""
        c, p = self.clocked, self.inside
        if c is None or p is None:
            return held
        start = fire.frame * self._H + self._F  # the window's first sample
        end = min((fire.frame + fire.window) * self._H + self._F, fed)
        lead = int(round(p.piece_s * c.sample_rate))
        x = self.kept.get(start - lead, end)
        if x.size != end - start + lead:
            return held
        return held_inside(x, lead, fire, (start, t0_s, c.sample_rate), c, self.pause, self.on_clock, p)

    def held_refired(self, fire: Fire, refire: int, t0_s: float) -> Held | None:
        """``fire``'s window, cut short where the fast path fired again at frame ``refire`` (``t0_s``: the stream's
        start, s), held as a stop whose lines departed from the stepping's modelled in every span, beside the fire
        that cut it, which stays pending (:func:`.inside.held_refired`). None: not so, no clocked check or no inside
        search (``ConfirmParams.inside``), or its samples not all kept."""
        cut = Fire(fire.ev, fire.frame, refire - fire.frame)
        c, start, end = self.clocked, cut.frame * self._H + self._F, cut.end(self._H, self._F)
        x = self.kept.get(start, end)
        if c is None or self.inside is None or x.size != end - start:
            return None
        return held_refired(x, cut, (end, t0_s, c.sample_rate), c, self.pause)

    def out_of_step(self) -> str | None:
        """Why the fire last judged may be sound added on the stepping's lines, not a stop: the stepping's lines
        modelled read it and let it through, but its lines held under ``model_in_step`` of the model's share in phase
        and their power out of phase rose ``model_added_db``. None: they did not, or nothing was read."""
        c, got = self.clocked, self.on_clock
        if c is None or not c.enabled or got is None:
            return None
        low = got.in_step < c.p.model_in_step * got.model_share  # (NaN: not read)
        if low and got.added_db >= c.p.model_added_db:  # and sound added on them
            return (
                f"lines {got.in_step:.2f} in phase at the fire, the stepping's {got.model_share:.2f}, power out of"
                f" phase {got.added_db:+.1f} dB: not in step"
            )
        return None

    def _step_elsewhere(self, onset: int) -> str | None:
        """Why the stop at absolute sample ``onset`` may have begun elsewhere: the joint's lines, turned by the clock
        followed, changed more than ``max_onset_off_s`` from it and further than the change's spread
        (:func:`.inside.onset_in_phase`, over two pieces either side; read where the comb judged the fire, as
        :meth:`~.clocked.ClockedCheck.at_onset`; off the tuning's rate, ``model_onset``, on the stepping's lines
        modelled where the model read the fire: the seventh generator's spectral arm under music, 1100 Hz, a fire
        0.14 s into the stop, the lines changed 145 ms before its onset; with ``model_onset_early`` also before the
        model is ready). None: they did not, or it was not read."""
        c, p, got = self.clocked, self.inside, self.on_clock
        if c is None or p is None or p.max_onset_off_s <= 0.0 or got is None:
            return None
        sr = c.sample_rate
        piece = int(round(p.piece_s * sr))
        x = self.kept.get(onset - 2 * piece, onset + 2 * piece)
        if x.size != 4 * piece:
            return None
        if c.at_tuned_rate(got.rate_hz) and math.isfinite(got.a):
            reader = c.reader(got.rate_hz)
            if reader is None:
                return None
            rate, lines = got.rate_hz, reader.lines
        elif (
            c.p.model_onset
            and c.model is not None
            and (math.isfinite(got.still_z) or (c.p.model_onset_early and not c.model_ready()))
        ):  # the model read the fire, or (``model_onset_early``) it is not ready yet: its lines are known
            rate, lines = c.model_hz, tuple(c.model.ks)
        else:
            return None  # an affirmation at another rate: the tuned signature places no onset there
        t, spread = onset_in_phase(x, sr, rate, lines, c.p, p)
        off_s = (t - 2 * piece) / sr
        if t >= 0 and abs(off_s) > max(p.max_onset_off_s, spread / sr):  # off by more than the fit could be
            return f"the joint's lines changed {1e3 * off_s:+.0f} ms from the onset (in phase with the steps)"
        return None

    def _in_step(self, ev: StopEvent, fire: int, frames: int, log: Verdicts) -> bool:
        """Did the joint's step-synchronous sound change, line by line (:mod:`.sync`)? No verdict: True."""
        if not self.sync.bands or self.sync.ref is None:
            return True
        got = self.sync.judge(self.after_fire(fire, min(self.span, frames * self._H)))
        if got is None:
            return True
        log.step_clock.append((ev.detected_at_s, got))
        return step_clock_verdict(got, self.p_sync) is not False

    def _stepping_stopped(self, ev: StopEvent, fire: int, frames: int, log: Verdicts, now_s: float) -> bool:
        """Was the fire the stepping stopping (a pause), not an end stop (:mod:`.pause`)?"""
        got = self.pause.stopped(self.after_fire(fire, frames * self._H))
        if got is None:
            return False
        log.stopped.append((ev.detected_at_s, got))
        self.after.judged_s = now_s
        return True

    def _on_clock(self, ev: StopEvent, fire: int, frames: int, log: Verdicts, affirm: bool) -> bool:
        """Did the joint's own clicks show the stop's signature (:mod:`.clocked`)? No verdict: True, unless it must
        ``affirm`` the stop."""
        if self.clocked is None:
            return not affirm
        pieces = self.clocked.p.window_pieces
        after = self.after_fire(fire, min(pieces * self.span, frames * self._H))
        got = self.clocked.judge(after, self.pause.before_hz, affirm)
        if got is not None:
            log.clocked.append((ev.detected_at_s, got))
        self.on_clock = got
        return self.clocked.affirms(got) if affirm else self.clocked.verdict(got)
