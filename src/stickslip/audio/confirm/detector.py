"""The confirming detector: the fast path's fires held until they persisted (:class:`ConfirmedStopDetector`).

It wraps a fast-path detector (:class:`~stickslip.audio.change.TemplateDetector`, or the
version-1 :class:`~stickslip.audio.comparators.BandDetector`) with the same interface
(samples in through :meth:`~ConfirmedStopDetector.feed`, :class:`StopEvent` s out) and holds
each fire as *provisional*: it is emitted once the stop persisted (:mod:`.persistence`), the
stepping did not merely stop (:mod:`.pause`), the change was on the step clock's lines
(:mod:`.clocked`: not sound added between them), the step clock agrees where asked
(:mod:`.sync`, opt-in), and flagged ``onset_uncertain`` where the evidence doubts its onset
(:mod:`.onset`). A fire that does not persist is dropped and the fast path un-latched at once,
so it hears the next stop; its template was frozen since the fire, so the rejected span never
enters it. A pause restarts the detector where the stepping comes back (:mod:`.resume`), as
for a new recording, so that the stepping that resumes is learned afresh. The late path (:mod:`.late`, opt-in) adds
stops the fast path never heard.

What it costs: nothing in accuracy - a traverse counts its steps to the event's ``onset_s``
(the fire's), and ``detected_at_s`` stays the fire time, so the latency is the fast path's -
but the traverse steps ``confirm_s`` longer against the stop (harmless on a stick-slip
joint, whose slider just slips) and takes that much longer. The emitted event carries
``confirmed_at_s`` (the end of the window) and ``confirmed_s`` (the window).

Two edges: the stream ends while a fire is provisional (:meth:`~ConfirmedStopDetector.finish`
emits it if what was heard of its window meets the same rule, with ``confirmed_s`` the time
heard); and a fire heard at once when the fast path is un-latched (a real stop that began
inside a rejected fire's window): when the stop began is not known, only that it was before
the un-latching, and the event is flagged ``onset_uncertain``. Interference that runs
straight into a real stop, without a pause of ``gap_s``, cannot be told apart: the event then
keeps the interference's onset.

The decision is made at the end of the window, at a frame counted from the stream start,
and the fast path is fed exactly up to it; the fast path holds its latch from the fire's own
frame (``hold_on_fire``), not from the end of the piece in which this wrapper hears of the
fire. So the events do not depend on how the stream is cut into blocks.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..change import TemplateDetector
from ..comparators import BandDetector
from ..events import StopDetector, StopEvent, check_step_rate, sample_block
from ..features.stepclock import LineChange
from ..tuningfile import Tuning
from .chain import Fire, FireChain
from .checks import WindowChecks
from .clocked import CLOCKED, ClockedParams, OnClock
from .evidence import FrameLog, KeptSamples
from .inside import INSIDE, Held, InsideParams
from .late import LATE, LateParams, LatePath, late_event
from .onset import ONSET, OnsetJudge, OnsetParams
from .pause import PAUSE, PauseParams, Stopped
from .persistence import PERSISTENCE, PersistenceParams, Windows, check_confirm_s, persisted, stoplike_throughout
from .sync import SYNC, SyncParams

__all__ = ["ConfirmLog", "ConfirmParams", "ConfirmedStopDetector", "FastPath", "confirming"]

#: the detectors whose fires can be confirmed: they keep per-frame evidence
FastPath = TemplateDetector | BandDetector
#: the stops a piece of the stream gave
Events = list[StopEvent]


@dataclass(frozen=True)
class ConfirmParams:
    """The confirmation's parameters, one dataclass per part."""

    persistence: PersistenceParams = field(default_factory=lambda: PERSISTENCE)
    onset: OnsetParams = field(default_factory=lambda: ONSET)
    pause: PauseParams = field(default_factory=lambda: PAUSE)
    sync: SyncParams = field(default_factory=lambda: SYNC)
    late: LateParams = field(default_factory=lambda: LATE)
    #: the stop's signature on the step clock's lines (None: not asked)
    clocked: ClockedParams | None = field(default_factory=lambda: CLOCKED)
    #: a stop that began inside a rejected fire's window, found on the clock's lines (None: not looked for)
    inside: InsideParams | None = field(default_factory=lambda: INSIDE)


def _stepping_band(tu: Tuning) -> list[tuple[float, float]]:
    """The template's span, the band where stepping is heard, Hz ([] for a band tuning of version 1)."""
    if tu.method != "template" or tu.edges_hz is None:
        return []
    return [(float(tu.edges_hz[0]), float(tu.edges_hz[-1]))]


@dataclass
class ConfirmLog:
    """What a confirming detector noted since it was made or reset (a pause's restart keeps ``rejected``,
    ``stopped`` and ``restarts``)."""

    #: the fires dropped: they did not persist (or were a pause)
    rejected: list[StopEvent] = field(default_factory=list)
    #: per fire that persisted but was the stepping stopping, not an end stop: (its ``detected_at_s``, why)
    stopped: list[tuple[float, Stopped]] = field(default_factory=list)
    #: per fire the step clock was measured on: (its ``detected_at_s``, what was measured)
    step_clock: list[tuple[float, LineChange]] = field(default_factory=list)
    #: per confirmed stop whose onset the evidence doubts: (its ``detected_at_s``, why; :mod:`.onset`)
    onset: list[tuple[float, str]] = field(default_factory=list)
    #: per confirmed stop whose rise was judged: (its ``detected_at_s``, the climb, s)
    rise: list[tuple[float, float]] = field(default_factory=list)
    #: per confirmed stop whose onset was taken back to its first crossing: (``detected_at_s``, the fire's onset, the
    #: onset emitted), s
    retime: list[tuple[float, float, float]] = field(default_factory=list)
    #: the fast path's fires swallowed while the late path was latched on a stop it found (not counted twice)
    late_swallowed: list[StopEvent] = field(default_factory=list)
    #: per fire that persisted whose change was judged on the step clock's lines: (its ``detected_at_s``, what)
    clocked: list[tuple[float, OnClock]] = field(default_factory=list)
    #: per pause: (the stream time it was judged at, the stream time the stepping came back and was heard afresh), s
    restarts: list[tuple[float, float]] = field(default_factory=list)
    #: per stop found inside a rejected fire's window (:mod:`.inside`): (the fire's ``detected_at_s``, the onset
    #: found, its spread; s)
    inside: list[tuple[float, float, float]] = field(default_factory=list)
    #: per stop found departed from the stepping's lines modelled, held past its window (``model_hold_s``): (the
    #: fire's ``detected_at_s``, the least z read after the window's end, NaN: none): a stop from ``model_max_z`` on
    held: list[tuple[float, float]] = field(default_factory=list)

    def note_held(self, h: Held, ev: StopEvent | None, z: float, sample_rate: float) -> None:
        """The stop held inside ``h.fire``'s rejected window judged: ``ev`` the event emitted (None: none), ``z`` the
        least z read past the window (NaN: none); ``sample_rate``, Hz."""
        t = h.fire.ev.detected_at_s
        self.held += [(t, z)] if h.until > h.end else []
        why = h.doubt if h.doubt is not None else h.flagged  # (its lines changed back, none read, or levels rejected)
        if why is not None and ev is not None and ev.onset_uncertain:
            self.onset.append((ev.detected_at_s, why))
        if ev is not None and h.found is not None:
            self.clocked.append((t, h.found.on_clock))
            self.inside.append((t, ev.onset_s, h.found.spread / sample_rate))


class ConfirmedStopDetector:
    """A fast-path detector whose fires are emitted only once the stop persisted (see the module docstring).

    Parameters
    ----------
    inner : TemplateDetector or BandDetector
        The detector whose fires are confirmed (it is reset, and from now on owned by this wrapper).
    confirm_s : float, optional
        Confirmation window after a fire, s (> 0; default ``PersistenceParams.confirm_s``).
    step_clock : bool
        Also ask that the joint's step-synchronous sound changed (:mod:`.sync`). Off by default.
    late : bool
        Also run the late path (:mod:`.late`): stops the fast path never heard. Off by default.
    params : ConfirmParams, optional
        The confirmation's parameters.

    Examples
    --------
    >>> import numpy as np
    >>> det = ConfirmedStopDetector(BandDetector(Tuning(band_hz=(5600, 7100), threshold_db=-50)))
    >>> det.feed(np.zeros(4800, dtype=np.float32)), det.finish()
    ([], [])
    """

    #: the no-signal guard applies: this detector listens to samples
    uses_audio = True

    def __init__(self, inner: FastPath, confirm_s: float | None = None, step_clock: bool = False, late: bool = False,
                 params: ConfirmParams | None = None) -> None:
        self.params = p = params or ConfirmParams()
        c = check_confirm_s(p.persistence.confirm_s if confirm_s is None else confirm_s, p.persistence)
        if c <= 0.0:
            raise ValueError("confirm_s must be > 0 for a ConfirmedStopDetector (use the fast path itself for 0)")
        self.inner, self.confirm_s = inner, c
        inner.hold_on_fire = True  # every fire is held from its own frame on, until the window decides
        tu = inner.tuning
        self._H, self._F, self._sr = int(tu.hop), int(tu.frame), int(tu.sample_rate)
        #: the spans the confirmation judges on, frames
        self.w = w = Windows.of(tu, c, p.persistence)
        self._frames = FrameLog(self._H, self._F, self._sr, 2 * w.after_reject + 4 * w.refire)
        self._onset = OnsetJudge(tu, self._frames, w.window, w.look, p.onset)
        self._chain = FireChain(w, self._frames, self._onset)
        # samples kept: the stepping before a fire and the longest window after it
        span_gap = int(round(p.sync.span_s * self._sr)) + int(round(p.sync.gap_s * self._sr))
        self._kept = KeptSamples(span_gap + self._F + (w.after_reject + 2) * self._H)
        band = _stepping_band(tu)
        #: the checks besides persistence: the step clock (opt-in), a pause, the change on the clock's lines
        self.checks = WindowChecks(tu, self._kept, band if step_clock else [], p.pause, p.sync, p.clocked, p.inside)
        #: the late path (:mod:`.late`): stops the fast path never heard, found on the step clock's lines
        self.late: LatePath | None = LatePath(self._sr, band, inner.t0_s, p.late) if late and band else None
        self.reset(inner.t0_s)

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Forget everything; the next sample fed is at stream time ``t0_s``.

        ``step_rate_hz``: the step rate the controller commands, Hz (None: not told); the
        fast path hears the step clock near it (see ``TemplateDetector.reset``), also after
        a pause restarts the stream.
        """
        self._step_rate_hz = check_step_rate(step_rate_hz)
        self.inner.reset(t0_s, self._step_rate_hz)
        self.inner.evidence, self.inner.hot_evidence = [], []
        self._t0 = float(t0_s)
        self._fed = 0
        self._held: Held | None = None  # a stop found inside a rejected window, until it may be emitted
        self._frames.reset(t0_s)
        self._chain.reset()
        self._kept.reset()
        self.checks.reset(self._step_rate_hz)
        #: what was noted since the last reset
        self.log = ConfirmLog()
        if self.late is not None:
            self.late.reset(t0_s)

    # --- the detector's interface -------------------------------------------------------------
    @property
    def tuning(self) -> Tuning:
        """The fast path's tuning."""
        return self.inner.tuning

    @property
    def latency_s(self) -> float:
        """Typical detected_at - true onset, s: the fast path's (``detected_at_s`` is the fire time)."""
        return self.inner.latency_s

    @property
    def ready(self) -> bool:
        """False while the fast path is still learning the stepping sound (or, after a pause, waits for it)."""
        return self.inner.ready and not self.checks.after.waiting

    @property
    def latched(self) -> bool:
        """True while a stop is being heard (provisional or confirmed)."""
        return self.inner.latched

    @property
    def holding(self) -> bool:
        """True while a stop found is held until its lines are read past its window (at most ``model_hold_s``)."""
        return self._held is not None

    @property
    def sync_bands(self) -> list[tuple[float, float]]:
        """The band the step clock is judged on, Hz (empty: no step-clock check)."""
        return self.checks.sync.bands

    @property
    def pending(self) -> StopEvent | None:
        """The fire being confirmed, or None."""
        return None if self._chain.pending is None else self._chain.pending.ev

    def feed(self, block: NDArray[Any]) -> list[StopEvent]:
        """Consume a block of mono samples; return the stops confirmed in it."""
        x = sample_block(block)
        if self.checks.after.waiting:
            return self._wait(x)
        out: list[StopEvent] = []
        pos = 0
        while pos < x.size:
            take = self._take(x.size - pos)
            fed0 = self._fed
            events = self.inner.feed(x[pos : pos + take])
            v = self._kept.keep_copy(x[pos : pos + take])
            if self.late is not None:  # the late path copies what it keeps
                self.late.push(v if np.all(np.isfinite(v)) else np.nan_to_num(v, nan=0.0, posinf=1.0, neginf=-1.0))
            pos += take
            self._fed += take
            self._frames.absorb(self.inner.evidence, self.inner.hot_evidence)
            self.checks.keep_stepping(self._fed, self._frames)
            if self.late is not None:
                out, events = self._late_chunks(fed0, events, out)
            for ev in events:
                out += self._fired(ev)
            out += self._decide() + self._held_judged()
            if self.checks.after.waiting:  # a pause: what follows is heard once the stepping is back
                return out + self._wait(x[pos:])
        return out

    def _wait(self, x: NDArray[Any]) -> list[StopEvent]:
        """After a pause: hear ``x`` until the stepping is back (:mod:`.resume`), then listen afresh from there, as
        to a new recording (the logs of rejections, pauses and restarts are kept)."""
        got = self.checks.after.push(x)
        if got is None:
            return []
        judged, t, rest = got
        kept = self.log
        self.reset(t, self._step_rate_hz)
        self.log = ConfirmLog(rejected=kept.rejected, stopped=kept.stopped, restarts=[*kept.restarts, (judged, t)])
        return self.feed(rest)

    def _take(self, left: int) -> int:
        """How many of the ``left`` samples the fast path may take now: up to the pending window's end, else a window.

        The late path judges at the end of each of its chunks, from the fast path's state there. An idle fast path
        (no fire held, not latched, warmed up) can change that state within such a piece only by firing, whose window
        ends beyond it: the piece is fed whole and its chunk ends judged afterwards (:meth:`_late_chunks`).
        Otherwise the feed stops at the next chunk end.
        """
        pending = self._chain.pending
        if pending is None:
            room = self._H * self.w.window  # a fire in these frames has its window end beyond them
        else:
            end = pending.frame + pending.window  # the window's last frame
            room = max(1, end * self._H + self._F - self._fed)
        room = room if self._held is None else min(room, max(1, self._held.until - self._fed))  # (at the hold's end)
        take = min(room, left)
        late = self.late
        idle = late is not None and pending is None and not self.inner.latched and self.inner.ready
        if late is not None and not idle:
            take = min(take, late.next_stop(self._fed) - self._fed)
        return take

    def _late_chunks(self, fed0: int, events: Events, out: Events) -> tuple[Events, Events]:
        """The late path's chunk ends in the piece just fed, each judged after the fires that came before it."""
        late = self.late
        assert late is not None
        fires = sorted(events, key=self._fire_frame)
        for b in range(late.next_stop(fed0), self._fed + 1, late.chunk):
            while fires and self._fire_frame(fires[0]) * self._H + self._F <= b:
                out += self._fired(fires.pop(0))
            out += self._late_step(late, b)
        return out, fires

    def _late_step(self, late: LatePath, at: int) -> list[StopEvent]:
        """The late path's chunk ended at sample ``at``: a stop the fast path never heard, or nothing.

        Where ``at`` is inside the piece just fed (an idle fast path), the fast path was idle there unless it had
        fired since: held, not stopped, ready."""
        held = self._chain.pending is not None
        latched, ready = (False, True) if at != self._fed else (self.inner.latched and not held, self.inner.ready)
        return self._late_event(late.step(at, held, latched, ready), at)

    def _late_event(self, got: tuple[float, float, bool] | None, when: int) -> list[StopEvent]:
        """The late path's stop as an event, emitted at sample count ``when`` (None: no event)."""
        if got is None:
            return []
        # the stop-likeness of the latest frame by then (template tunings: margins + 1 are a / threshold)
        margin = self._frames.margin(min((when - self._F) // self._H, self.inner.frames_seen - 1))
        level = (margin + 1.0) * float(self.inner.tuning.threshold_db)
        return [late_event(got, level, self._t0 + when / self._sr)]

    def finish(self) -> list[StopEvent]:
        """The stream ended: the provisional stop, if what was heard of its window persisted (see the module);
        else a stop the late path found and held back while the fast path was deciding."""
        if self.checks.after.waiting:  # paused since the last pause was judged: nothing to hear
            return []
        out = self._held_judged(True) + self._finish_fast() + self._held_judged(True)
        if self.late is not None and not out:
            out = self._late_event(self.late.finish(), self._fed)
        return out

    def _finish_fast(self) -> list[StopEvent]:
        fire, self._chain.pending = self._chain.pending, None
        if fire is None:
            return []
        heard = self.inner.frames_seen - 1 - fire.frame
        if not self._holds(fire.ev, fire.frame, heard):
            self.log.rejected.append(fire.ev)
            self.checks.after.judged_s = None
            self._held = self.checks.held_inside(Fire(fire.ev, fire.frame, heard), self._fed, self._t0, self._held)
            return []
        return [self._confirmed(fire.ev, fire.frame, heard)]

    # --- internals ----------------------------------------------------------------------------
    def _fire_frame(self, ev: StopEvent) -> int:
        end = int(round((ev.detected_at_s - self._t0) * self._sr))
        return (end - (self._F - 1)) // self._H

    def _fired(self, ev: StopEvent) -> list[StopEvent]:
        fire = self._fire_frame(ev)
        if self.late is not None and self.late.latched:  # the late path found this stop already: not counted twice
            self.log.late_swallowed.append(ev)
            self.inner.hold(False)  # nothing to decide: the fast path re-arms by itself
            return []
        prev = self._chain.refired(fire)  # the fast path released and fired again inside the window: no persistence
        if prev is not None:
            self.log.rejected.append(prev.ev)
            if self._held is None:  # its window read as a rejected one's (model_refired), held beside this fire
                self._held = self.checks.held_refired(prev, fire, self._t0)
        ev = self._chain.flagged(ev, fire)
        recent = self._chain.recent(fire)
        self.checks.hear_before(fire, recent, self._frames)  # the stepping before it is each check's reference
        self._chain.start(ev, fire, recent)
        return []  # the window decides: the fast path, held since the fire's frame (hold_on_fire), waits for it

    def _holds(self, ev: StopEvent, fire: int, frames: int) -> bool:
        """The fire at frame ``fire`` persisted over ``frames`` and passed the other checks (:mod:`.checks`)."""
        now_s = self._t0 + self._fed / self._sr
        self.checks.on_clock = None  # (judged below, if at all)
        m, hot = self._frames.window(fire, frames)
        if persisted(m, hot, self.w.gap, self.params.persistence):
            return self.checks.passed(ev, fire, frames, self.log, now_s)
        # stop-like throughout but not hot (added sound masks the stop's drops): a stop only where the lines affirm it
        return stoplike_throughout(m, self.w.gap, self.params.persistence) and (
            self.checks.passed(ev, fire, frames, self.log, now_s, affirm=True)
        )

    def _decide(self) -> list[StopEvent]:
        fire = self._chain.due(self.inner.frames_seen)
        if fire is None:
            return []
        self._held = None if self._held is not None and self._held.beside else self._held  # (the window judges)
        self.inner.hold(False)
        if self._holds(fire.ev, fire.frame, fire.window):  # (held where only its lines out of step doubt it)
            ev = self._confirmed(fire.ev, fire.frame, fire.window, True)
            self._held = self.checks.held_out_of_step(fire, ev, min(fire.end(self._H, self._F), self._fed), self._t0)
            return [ev] if self._held is None else []
        self.log.rejected.append(fire.ev)
        if self.checks.after.wait():  # the stepping stopped: listen afresh where it comes back
            return []
        self._held = self.checks.held_inside(fire, self._fed, self._t0, self._held)  # (latched on a stop inside)
        self.inner.hold(self._held is not None)  # (held, not re-armed, until its lines are read past the window)
        return [] if self._held is not None else self._rejected(fire)

    def _rejected(self, fire: Fire) -> list[StopEvent]:
        """``fire``'s window held no stop: the fast path un-latched, the chain goes on from its end."""
        self.inner.unlatch()
        self._chain.rejected(fire)
        return []

    def _held_judged(self, finishing: bool = False) -> list[StopEvent]:
        """The stop held (:class:`.inside.Held`), judged at once, at its hold's end or the stream's (see there)."""
        h = self._held
        if h is None or self.checks.clocked is None or (self._fed < h.until and not finishing):
            return []
        self._held, x = None, self._kept.get(h.end, min(h.until, self._fed))
        ev, z = h.judged(x, self._t0, self.checks.clocked)
        self.log.note_held(h, ev, z, self._sr)
        if h.beside:  # (model_refired) the fire pending beside it: judged as it comes, or dropped with this stop
            if ev is None:
                return []
            self._chain.pending = None
        self.inner.hold(False)
        if ev is not None:
            self._chain.confirmed()
        return [ev] if ev is not None else self._rejected(h.fire)  # (None: its lines changed back, sound over them)

    def _confirmed(self, ev: StopEvent, fire: int, frames: int, hold: bool = False) -> StopEvent:
        """The event of the fire at frame ``fire`` confirmed over ``frames``; flagged where its onset is doubted."""
        if self.late is not None:  # the fast path gave this stop: the late path judges nothing before it
            self.late.note_busy((fire + frames) * self._H + self._F)
        verdict = None
        if not ev.onset_uncertain:
            ch = self._chain
            verdict = self._onset.doubt(ev, fire, frames, ch.covered_at, ch.rejected_fire, self.inner.relearned)
            if verdict.why is None:  # the lines in phase from the onset on (the retimed one, where taken back)
                at = ev.onset_s if verdict.retimed is None else verdict.retimed
                verdict.why = self.checks.onset_doubt(int(round((at - self._t0) * self._sr)), hold)
            if verdict.climb is not None:
                self.log.rise.append((ev.detected_at_s, verdict.climb))
        self._chain.confirmed()
        if verdict is not None and verdict.why is None and verdict.retimed is not None:
            self.log.retime.append((ev.detected_at_s, ev.onset_s, verdict.retimed))
            ev = replace(ev, onset_s=verdict.retimed)
        if verdict is not None and verdict.why is not None:
            self.log.onset.append((ev.detected_at_s, verdict.why))
            ev = replace(ev, onset_uncertain=True)
        return replace(ev, confirmed_at_s=self._frames.end_s(fire + frames), confirmed_s=frames * self._H / self._sr)


def confirming(
    detector: StopDetector, confirm_s: float | None = None, step_clock: bool = False, late: bool = False
) -> StopDetector:
    """``detector`` wrapped in a :class:`ConfirmedStopDetector`, where that applies.

    ``confirm_s`` 0 gives the detector back unchanged (every fire is a stop); so does a
    detector that already confirms, or one that does not listen to samples (the simulator's
    oracle, a position read-back): only a fast path keeps the per-frame evidence to confirm
    with. The wrapper listens with a fresh detector of the same tuning; ``detector`` itself
    is left as it was. ``step_clock`` True also asks the step clock; ``late`` True also runs
    the late path (both off by default). ``confirm_s`` None: ``PersistenceParams.confirm_s``.
    """
    c = check_confirm_s(PERSISTENCE.confirm_s if confirm_s is None else confirm_s)
    if c == 0.0 or not isinstance(detector, (TemplateDetector, BandDetector)):
        return detector
    fresh: FastPath
    if isinstance(detector, TemplateDetector):
        fresh = TemplateDetector(detector.tuning, detector.t0_s, detector.params)
    else:
        fresh = BandDetector(detector.tuning, detector.t0_s)
    return ConfirmedStopDetector(fresh, c, step_clock=step_clock, late=late)
