"""Confirm an end stop by its persistence under continued stepping.

A real end stop lasts as long as the controller keeps stepping into it; interference
that looks like the stop for a moment (a held chord, a voice's fricatives in the stop's
sub-band, babble over a run of weaker steps) does not. :class:`ConfirmedStopDetector`
wraps a :class:`~stickslip.audio.detector.StopDetector` with the same interface
(samples in through :meth:`~ConfirmedStopDetector.feed`, :class:`StopEvent` s out) and
holds each fire as *provisional*: it is emitted only once the stop persisted for
``confirm_s``: of the frames of the next ``confirm_s`` after the fire, at least
``min_share`` were stop-like (the stop-likeness at or above the tuning's threshold, by
the fit or by the drop channel), no run of the others lasted :data:`GAP_S`, and at least
``min_hot`` were *hot* (the detector's full verdict: also the fit's residual and the
drops the stop shows in proportion). A voice over a stop-like sub-band keeps the
stop-likeness up for seconds but seldom shows the stop's drops with it; a stop shows
both, as long as the joint steps into it (what this does not remove: continuous talk
over a joint whose stop lowers little else, which fires again and again until one
window persists; docs/audio.md gives the numbers). A fire that does not persist is dropped
and the inner detector un-latched at once, so it hears the next stop; its template was
frozen since the fire, so the rejected span never enters it. A fire that comes within
:data:`RECENT_S` of a rejected one must persist for :data:`AFTER_REJECT_S`: the
interference is still going on.

What it costs: nothing in accuracy - a traverse counts its steps to the event's
``onset_s`` (the fire's, unchanged), and ``detected_at_s`` stays the fire time, so the
latency is the detector's - but the traverse steps ``confirm_s`` longer against the stop
(``confirm_s`` x the step rate extra steps, :data:`AFTER_REJECT_S` just after a rejected
fire: harmless on a stick-slip joint, whose slider just slips) and takes that much longer.
The emitted event carries ``confirmed_at_s`` (the end of the window) and ``confirmed_s``
(the window).

The decision is made at the end of the window, at a frame counted from the stream
start, and the inner detector is fed exactly up to it, so the events do not depend on
how the stream is cut into blocks.

**The step clock (opt-in: ``step_clock=True``; round 6, line by line since round 7).**
Every sound the joint makes is a train of clicks at the step rate, at the stop too;
interference is not in step with it. With ``step_clock`` a fire that persisted must also
have changed the joint's *step-synchronous* sound somewhere in the stepping band (the
tuning's sub-bands, end to end): the power on each harmonic line of the step rate, above
the continuum between them (:func:`~stickslip.audio.stepclock.line_change`), over the
:data:`SYNC_SPAN_S` of stepping that end :data:`SYNC_GAP_S` before the fire (for a fire soon
after a rejected one, the stepping before the first of them) against the first
:data:`SYNC_SPAN_S` of the window, at the rate heard in the stepping. The lines' changes,
each in standard deviations of its estimate, are summed as squares (the largest dropped: a
voice's harmonic on a line), so a stop that raises some lines and lowers others does
not cancel; the sum, as a normal deviate, must reach :data:`MIN_SYNC_Z`, and a line kept
in it must have moved by :data:`MIN_SYNC_CHANGE_DB` or more (a precisely measured change
of a fraction of a dB is not a stop). No verdict (the fire stands on persistence) when the
lines were not sharp before the fire (:data:`MIN_SYNC_SHARPNESS`: a rough clock smears its
higher harmonics) or held less than :data:`MIN_SYNC_SHARE` of the band's power, when no
rate or too few lines are heard, or when less than :data:`SYNC_MIN_S` of stepping or
:data:`SYNC_MIN_AFTER_S` of the window was heard. Measured (docs/audio.md, "The step
clock"): the true stops of the battery's generator and of the project's simulator, the
false alarms of both hour benches and under talk. It stays off by default: a rough clock
just sharp enough to be judged (the random arms' arm 3: 0.88-0.89, against 0.9) carries
stops whose lines hardly change, and a veto there would lose them.

**A pause is not an end stop (session 28).** A fire that persisted is dropped when the
stepping itself stopped (:mod:`stickslip.audio.stopped`): the window's sound in the
detector's band fell 20 dB or more below the stepping's before the fire (and 12 dB beyond
the tuned stop's own change) with no stepping heard in it (the step rate's envelope lines).
The detector is then restarted at the window's end, as for a new recording, so that the
stepping that resumes is learned afresh; ``stopped_log`` says where and why. A traverse
whose controller halted is then ended by the no-signal guard, recording nothing.

Two edges, and what happens:

* **The stream ends while a fire is provisional** (a recording that stops less than
  ``confirm_s`` after the stop): :meth:`~ConfirmedStopDetector.finish` emits it if the
  frames heard after the fire so far meet the same rule (none heard: it is emitted, as
  nothing contradicts it), with ``confirmed_s`` the time actually heard (less than
  ``confirm_s``: the flag that it was confirmed by the end of the recording).
* **A fire heard at once when the detector is un-latched** (a real stop that began
  inside a rejected fire's window, or a stop whose own first window failed, under loud
  talk): when the stop began is not known, only that it was before the un-latching.
  The event is emitted with ``onset_uncertain`` set, and a traverse refuses it (measure
  again) rather than count to a guess. Interference that runs straight into a real stop,
  without a pause of :data:`GAP_S`, cannot be told apart: the event then keeps the
  interference's onset (as without confirmation).

**When did the confirmed stop begin? (round 8b)** A window that persisted says a stop is
there, not that it began at the fire's onset. :meth:`ConfirmedStopDetector._onset_doubt`
asks the same per-frame evidence, and flags the event ``onset_uncertain`` (a traverse
refuses it) where the fire was not the stop's beginning: a gap after the fire as long as
its hold, a fire under :data:`ONSET_FIRE_LEVEL` of the stop's stop-likeness, a stop-like
run at the stop's level that began more than :data:`ONSET_TOL_S` before the onset (a stop
heard late), or a stop heard again after a rejected fire whose window was covered
(:data:`ONSET_COVERED_A`) or over which the template was learned anew. Measured in
docs/audio.md ("When did the stop begin?"); ``onset_log`` says why, per flagged event.

**The climb to the onset (round 9a).** :meth:`ConfirmedStopDetector._rise` follows the
stop-likeness back from the crossing that set the onset to where it left the stepping's
level: a climb slower than :data:`ONSET_SLOW_S` (a reverberant room, a stop that barely
clears the threshold) is flagged; over a stepping near the threshold (a rate far from the
tuning's) a first crossing more than :data:`ONSET_TOL_S` before the onset is flagged; and
over clean stepping, where the stop was hot and held but the hold began again (its drops
flickered as the room's tail decayed), the onset is taken back to that first hot frame
(``retime_log``). ``detected_at_s`` stays the fire's.

**The late path (opt-in: ``late=True``; round 12a, :mod:`.late`).** A second source of
events beside the fires: a stop the fast path never heard, found on the step clock's lines
0.5-0.75 s after it, its onset estimated back (``found_late``; ``onset_uncertain`` where the
change point does not pin it within 25 ms). It judges nothing while the fast path is latched
on a stop it confirmed; a stop it finds while the fast path holds a fire waits for that
decision; after it fires, the fast path's fires on the same stop are swallowed
(``late_swallowed``). Its chunk ends are sample counts from the stream start, where the feed
stops to judge: the events do not depend on the block size.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .detector import StopDetector, StopEvent, Tuning
from .late import LatePath
from .stepclock import LineChange, line_change, step_rate_hz
from .stopped import BEFORE_QUANTILE, Stopped, band_filter, band_power, stepping_stopped, tuned_change_db

__all__ = [
    "AFTER_REJECT_S",
    "CONFIRM_S",
    "GAP_S",
    "MIN_HOT",
    "MIN_SHARE",
    "MIN_SYNC_CHANGE_DB",
    "MIN_SYNC_SHARE",
    "MIN_SYNC_SHARPNESS",
    "MIN_SYNC_Z",
    "ONSET_BACK_DIPS",
    "ONSET_BACK_LEVEL",
    "ONSET_BACK_MAX_S",
    "ONSET_BASE_GAP_S",
    "ONSET_BASE_S",
    "ONSET_CLEAN_S",
    "ONSET_COVERED_A",
    "ONSET_FIRE_LEVEL",
    "ONSET_HELD_DIPS",
    "ONSET_QUIET",
    "ONSET_RISE_SHARE",
    "ONSET_SLOW_S",
    "ONSET_STEPPING_CAP",
    "ONSET_STEPPING_PCT",
    "ONSET_TOL_S",
    "RECENT_S",
    "ConfirmedStopDetector",
    "check_confirm_s",
    "confirming",
    "step_clock_verdict",
]

#: how long a stop must persist after the detector fired before it is emitted, s (measured: docs/audio.md)
CONFIRM_S = 0.5
#: share of the frames in that window that must be stop-like (measured: docs/audio.md)
MIN_SHARE = 0.7
#: ... and no run of frames that are not stop-like may last this long in it, s: the stop went away
#: (longest seen inside a true stop: 40 ms in the battery, 88 ms under talk at +3 dB over joint P's stop)
GAP_S = 0.15
#: ... and this share of them must be *hot*: the detector's full verdict (the fit's residual, the drops the
#: stop shows in proportion, or the drop channel), not the stop-likeness alone (measured: docs/audio.md)
MIN_HOT = 0.25
#: a fire this soon after a rejected one (the end of its window) gets the longer window :data:`AFTER_REJECT_S`:
#: the interference goes on, and continuous talk gives fire after fire until one window persists, s
RECENT_S = 2.0
#: the window of such a fire, s (measured: docs/audio.md)
AFTER_REJECT_S = 2.0
#: the onset check (round 8b): an onset this far from where the evidence says the stop may have begun is wrong by more
#: than a traverse tolerates, s
ONSET_TOL_S = 0.025
#: ... a stop-like run that ends in the fire but began more than ONSET_TOL_S before its onset, at a stop-likeness at
#: least this share of the window's (the stop's), was the stop, heard late: interference hid its full verdict
ONSET_BACK_LEVEL = 0.8
#: ... dips of at most this many frames that are not stop-like do not end that run
ONSET_BACK_DIPS = 3
#: ... a fire whose stop-likeness (over its hold) was under this share of the stop-likeness in the second half of the
#: window was not the sound that persisted (a template lagging a drifting rate, a knock just before the stop)
ONSET_FIRE_LEVEL = 1.0 / 3.0
#: ... a rejected window whose frames that were not stop-like had a median stop-likeness at or below this (half the
#: stop's signature the other way: sound added where the stop lowers it) was *covered*, not back to stepping (about 0):
#: the stop may have been there under it, and a stop confirmed later is uncertain until clean stepping is heard
ONSET_COVERED_A = -0.5
#: ... clean stepping: this long a run of frames neither stop-like nor covered (stop-likeness above ONSET_COVERED_A), s
ONSET_CLEAN_S = 0.15
#: ... a slow rise: the stop-likeness climbed from the stepping's level to the threshold over more than this, s (the
#: crossing then comes late by most of the climb: arm 2's duller stop at the far microphone, a climb of 24 ms, +28 ms;
#: right stops climb over up to 19 ms in the fifth generator's rooms): the stepping's level is its median over this
#: long, s, ...
ONSET_BASE_S = 0.2
#: ... the climb that is slow, s
ONSET_SLOW_S = 0.02
#: ... ending this long before the crossing, s
ONSET_BASE_GAP_S = 0.05
#: ... and the rise runs back over the frames at least this share of the way from the stepping's level to the stop's
ONSET_RISE_SHARE = 0.25
#: ... an onset is taken back to the climb's first crossing only where the stepping's level was at most this many
#: thresholds (the detector's own "quiet": a stepping near the threshold crosses it by chance)
ONSET_QUIET = 0.3
#: ... and by no more than this, s (further back, the stop-like run is no longer the stop's climb: flagged)
ONSET_BACK_MAX_S = 0.1
#: ... a slow rise's climb is measured only over frames above this percentile of the stepping's stop-likeness (over
#: ONSET_BASE_S), where that is higher than ONSET_RISE_SHARE of the way: a frame within the stepping's own range is no
#: sign the stop began (round 11b: a stepping at another rate than the tuning's flickers to 0.5-1.4 thresholds) ...
ONSET_STEPPING_PCT = 95.0
#: ... but never above this share of the way from the stepping's level (its median) to the stop's
ONSET_STEPPING_CAP = 0.5
#: ... to a hot frame after which the climb held: no run of more than this many frames under its level
ONSET_HELD_DIPS = 1
#: longest window accepted, s (a traverse steps this long into the stop)
MAX_CONFIRM_S = 5.0
#: the step clock: the step clock's lines in the stepping band must have changed between the stepping before the
#: fire and the window after it by at least this much, as a normal deviate (their trimmed chi-square, line by line:
#: :func:`~stickslip.audio.stepclock.line_change`; interference adds no line power, but noise to its estimate)
MIN_SYNC_Z = 4.0
#: ... and a line kept in that sum must have moved by at least this much, dB, up or down (measured: docs/audio.md,
#: "The step clock")
MIN_SYNC_CHANGE_DB = 1.0
#: ... judged only where the clock's lines in the band were sharp before the fire: at least this share of
#: their power in a comb 4 times wider lies in the comb (a rough clock smears the lines of its higher harmonics, and
#: a stop's sound then falls beside the comb as much as interference does; measured: docs/audio.md)
MIN_SYNC_SHARPNESS = 0.9
#: ... and where the lines held at least this share of the band's power before the fire
MIN_SYNC_SHARE = 0.05
#: ... judged on this long a stretch on each side, s
SYNC_SPAN_S = 0.48
#: ... the stepping ends this long before the fire (the hold and the onset lag: the stop is not in it), s
SYNC_GAP_S = 0.06
#: ... and not on less stepping before the fire than this, s (listening began at the stop: no verdict)
SYNC_MIN_S = 0.2
#: ... nor on less of the window than this, s (a recording that ends sooner: no verdict)
SYNC_MIN_AFTER_S = 0.1


def check_confirm_s(confirm_s: float) -> float:
    """``confirm_s`` as a float, or ``ValueError`` naming the accepted range (0 = no confirmation)."""
    try:
        c = float(confirm_s)
    except (TypeError, ValueError):
        raise ValueError(f"confirm_s = {confirm_s!r} is not a number of seconds") from None
    if not (math.isfinite(c) and 0.0 <= c <= MAX_CONFIRM_S):
        raise ValueError(f"confirm_s = {confirm_s!r} s is outside [0, {MAX_CONFIRM_S:g}] (0: no confirmation)")
    return c


class ConfirmedStopDetector:
    """A :class:`StopDetector` whose fires are emitted only once the stop persisted.

    Parameters
    ----------
    inner : StopDetector
        The detector whose fires are confirmed (it is reset, and from now on owned by
        this wrapper).
    confirm_s : float
        Confirmation window after a fire, s (> 0).
    min_share : float
        Share of the window's frames that must be stop-like, in (0, 1].
    min_hot : float
        Share of the window's frames that must be *hot* (the detector's full verdict),
        in [0, 1].
    after_reject_s : float or None
        The window of a fire within :data:`RECENT_S` of a rejected one, s (at least
        ``confirm_s``; None: ``confirm_s``).
    step_clock : bool
        Also ask that the joint's step-synchronous sound changed, line by line, somewhere
        in the stepping band (see the module: the step clock). Off by default: on a rough
        clock just sharp enough to be judged a stop may hardly change the lines
        (docs/audio.md).
    late : bool
        Also run the late path (:mod:`.late`, round 12a): a stop the fast path never heard,
        found on the step clock's lines 0.5-0.75 s after it, its onset estimated back
        (``StopEvent.found_late``). Off by default (docs/audio.md, "Round 12a").

    Examples
    --------
    >>> import numpy as np
    >>> det = ConfirmedStopDetector(StopDetector(Tuning(band_hz=(5600, 7100), threshold_db=-50)))
    >>> det.feed(np.zeros(4800, dtype=np.float32)), det.finish()
    ([], [])
    """

    #: the no-signal guard applies: this detector listens to samples
    uses_audio = True

    def __init__(
        self,
        inner: StopDetector,
        confirm_s: float = CONFIRM_S,
        min_share: float = MIN_SHARE,
        min_hot: float = MIN_HOT,
        after_reject_s: float | None = AFTER_REJECT_S,
        step_clock: bool = False,
        late: bool = False,
    ) -> None:
        c = check_confirm_s(confirm_s)
        if c <= 0.0:
            raise ValueError("confirm_s must be > 0 for a ConfirmedStopDetector (use the StopDetector itself for 0)")
        if not (isinstance(min_share, (int, float)) and 0.0 < float(min_share) <= 1.0):
            raise ValueError(f"min_share = {min_share!r} is outside (0, 1]")
        if not (isinstance(min_hot, (int, float)) and 0.0 <= float(min_hot) <= 1.0):
            raise ValueError(f"min_hot = {min_hot!r} is outside [0, 1]")
        self.inner = inner
        self.confirm_s = c
        self.min_share = float(min_share)
        self.min_hot = float(min_hot)
        tu = inner.tuning
        self._H, self._F, self._sr = int(tu.hop), int(tu.frame), int(tu.sample_rate)
        #: the window, frames
        self.window_frames = max(1, int(round(c * self._sr / self._H)))
        #: the window of a fire that comes within RECENT_S of a rejected one, frames (interference goes on)
        a = c if after_reject_s is None else max(c, check_confirm_s(after_reject_s))
        self.after_reject_frames = max(self.window_frames, int(round(a * self._sr / self._H)))
        self._recent_frames = int(round(RECENT_S * self._sr / self._H))
        self._refire_frames = int(tu.hold_frames) + int(tu.max_dips) + 1
        #: a run of this many frames that are not stop-like ends a stop
        self.gap_frames = max(int(tu.hold_frames) + int(tu.max_dips), int(round(GAP_S * self._sr / self._H)))
        self._lag = float(tu.onset_lag_s)
        #: how far back from a fire the onset check looks, frames (always kept by _absorb, whatever the block size)
        self._look = self.after_reject_frames + 4 * self._refire_frames - 2
        self._hold_frames = int(tu.hold_frames) + int(tu.max_dips)
        self._levels = tu.method == "template"  # margins + 1 are a / threshold (a band tuning's are dB)
        #: the band the step clock is judged on (Hz; empty: no step-clock check)
        self.sync_bands: list[tuple[float, float]] = _stepping_band(tu) if step_clock else []
        self._span = int(round(SYNC_SPAN_S * self._sr))
        self._gap = int(round(SYNC_GAP_S * self._sr))
        # samples kept: the stepping before a fire and the longest window after it
        self._keep = self._span + self._gap + self._F + (self.after_reject_frames + 2) * self._H
        # a pause is not an end stop (stickslip.audio.stopped): the detector's band and the tuned stop's change there
        edges = tu.edges_hz if tu.method == "template" and tu.edges_hz else tu.band_hz
        self._stop_sos = band_filter((float(edges[0]), float(edges[-1])), self._sr)
        self._tuned_db = tuned_change_db(tu.stepping_levels_db, tu.signature_db)
        band = _stepping_band(tu)
        #: the late path (round 12a, :mod:`.late`): stops the fast path never heard, found on the step clock's lines
        self.late: LatePath | None = LatePath(self._sr, band, inner._t0) if late and band else None
        self.reset(inner._t0)

    def reset(self, t0_s: float = 0.0) -> None:
        """Forget everything; the next sample fed is at stream time ``t0_s``."""
        self.inner.reset(t0_s)
        self.inner.evidence = []
        self.inner.hot_evidence = []
        self._t0 = float(t0_s)
        self._fed = 0
        self._margins: list[float] = []
        self._hot: list[bool] = []
        self._base = 0  # frame index of _margins[0] and _hot[0]
        self._pending: tuple[StopEvent, int, int] | None = None  # the fire, its frame, its window (frames)
        self._last_reject: int | None = None
        self._rejected_at: int | None = None
        self._covered_at: int | None = None  # the end of the latest rejected window that was covered (_onset_doubt)
        self._rejected_fire: int | None = None  # the frame of the latest rejected fire since the last confirmed one
        #: the fires dropped since the last reset (they did not persist)
        self.rejected: list[StopEvent] = []
        self._chunks: list[NDArray[np.float64]] = []  # the latest samples, from absolute sample _chunks0 on
        self._chunks0 = 0
        self._chunks_n = 0
        self._ref: NDArray[np.float64] | None = None  # the stepping before the fire that began the current chain
        self._before_power = math.nan  # in-band power of that stepping (full scale 1), and its step rate, Hz
        self._before_hz = math.nan
        #: per fire that persisted but was the stepping stopping, not an end stop: (its ``detected_at_s``, why)
        self.stopped_log: list[tuple[float, Stopped]] = []
        self._pause_at: float | None = None  # stream time at which a pause was heard: restart there
        #: per fire the step clock was measured on: (its ``detected_at_s``, what was measured)
        self.step_clock_log: list[tuple[float, LineChange]] = []
        #: per confirmed stop whose onset the evidence doubts: (its ``detected_at_s``, why; see :meth:`_onset_doubt`)
        self.onset_log: list[tuple[float, str]] = []
        #: per confirmed stop whose rise was judged: (its ``detected_at_s``, the climb, s; see :meth:`_rise`)
        self.rise_log: list[tuple[float, float]] = []
        #: per confirmed stop whose onset was taken back to its first crossing: (``detected_at_s``, the fire's onset,
        #: the onset emitted), s (see :meth:`_rise`)
        self.retime_log: list[tuple[float, float, float]] = []
        self._retimed: float | None = None  # the onset _onset_doubt took back, for _confirmed
        #: the fast path's fires swallowed while the late path was latched on a stop it found (not counted twice)
        self.late_swallowed: list[StopEvent] = []
        if self.late is not None:
            self.late.reset(t0_s)

    # --- the detector's interface -------------------------------------------------------------
    @property
    def tuning(self) -> Tuning:
        """The inner detector's tuning."""
        return self.inner.tuning

    @property
    def latency_s(self) -> float:
        """Typical detected_at - true onset, s: the inner detector's (``detected_at_s`` is the fire time)."""
        return self.inner.latency_s

    @property
    def ready(self) -> bool:
        """False while the inner detector is still learning the stepping sound."""
        return self.inner.ready

    @property
    def latched(self) -> bool:
        """True while a stop is being heard (provisional or confirmed)."""
        return self.inner.latched

    @property
    def level(self) -> float:
        """The latest frame's level (see :attr:`StopDetector.level`)."""
        return self.inner.level

    @property
    def levels_seen(self) -> int:
        """Frames heard since the last reset."""
        return self.inner.levels_seen

    @property
    def pending(self) -> StopEvent | None:
        """The fire being confirmed, or None."""
        return None if self._pending is None else self._pending[0]

    def feed(self, block: NDArray[Any]) -> list[StopEvent]:
        """Consume a block of mono samples; return the stops confirmed in it."""
        x = np.asarray(block)
        if x.ndim != 1:
            raise ValueError(f"feed expects a 1-D mono block, got shape {x.shape}")
        out: list[StopEvent] = []
        pos = 0
        late = self.late
        while pos < x.size:
            take = min(self._room(), x.size - pos)
            # the late path judges at the end of each of its chunks, from the fast path's state there. Idle (no fire
            # held, not latched, warmed up), the fast path can change that state within a piece of _room() samples
            # only by firing, and a fire's window ends beyond the piece: the piece is fed whole and the chunk ends in
            # it judged afterwards, each after the fires that came before it. Otherwise the feed stops at the next one.
            idle = late is not None and self._pending is None and not self.inner.latched and self.inner.ready
            if late is not None and not idle:
                take = min(take, late.next_stop(self._fed) - self._fed)
            fed0 = self._fed
            events = self.inner.feed(x[pos : pos + take])
            v = self._keep_samples(x[pos : pos + take])
            if late is not None:  # the late path copies what it keeps
                late.push(v if np.all(np.isfinite(v)) else np.nan_to_num(v, nan=0.0, posinf=1.0, neginf=-1.0))
            pos += take
            self._fed += take
            self._absorb()
            if late is not None:
                ends = range(late.next_stop(fed0), self._fed + 1, late.chunk)
                fires = sorted(events, key=self._fire_frame)
                for b in ends:
                    while fires and self._fire_frame(fires[0]) * self._H + self._F <= b:
                        out += self._fired(fires.pop(0))
                    out += self._late_step(late, b)
                events = fires
            for ev in events:
                out += self._fired(ev)
            out += self._decide()
        return out

    def _late_step(self, late: LatePath, at: int) -> list[StopEvent]:
        """The late path's chunk ended at sample ``at``: a stop the fast path never heard, or nothing (:mod:`.late`).

        Where ``at`` is inside the piece just fed (an idle fast path), the fast path was idle there unless it had
        fired since: held, not stopped, ready."""
        held = self._pending is not None
        if at != self._fed:
            return self._late_event(late.step(at, held, False, True), at)
        return self._late_event(late.step(at, held, self.inner.latched and not held, self.inner.ready), at)

    def _late_event(self, got: tuple[float, float, bool] | None, when: int) -> list[StopEvent]:
        """The late path's stop as an event, emitted at sample count ``when`` (None: no event)."""
        if got is None:
            return []
        at_s, onset_s, uncertain = got
        if not math.isfinite(onset_s):
            onset_s, uncertain = at_s, True
        return [
            StopEvent(
                detected_at_s=at_s,
                onset_s=onset_s,
                # the stop-likeness of the latest frame by then (template tunings: margins + 1 are a / threshold)
                level_db=(self._margin(min((when - self._F) // self._H, self.inner.frames_seen - 1)) + 1.0)
                * float(self.inner.tuning.threshold_db),
                confirmed_at_s=max(at_s, self._t0 + when / self._sr),
                confirmed_s=at_s - onset_s if not uncertain else None,
                onset_uncertain=uncertain,
                found_late=True,
            )
        ]

    def finish(self) -> list[StopEvent]:
        """The stream ended: the provisional stop, if what was heard of its window persisted (see the module);
        else a stop the late path found and held back while the fast path was deciding."""
        out = self._finish_fast()
        if self.late is not None and not out:
            out = self._late_event(self.late.finish(), self._fed)
        return out

    def _finish_fast(self) -> list[StopEvent]:
        if self._pending is None:
            return []
        ev, fire, _ = self._pending
        self._pending = None
        heard = self.inner.frames_seen - 1 - fire
        if not (
            self._persisted(*self._window(fire, heard))
            and self._in_step(ev, fire, heard)
            and not self._stepping_stopped(ev, fire, heard)
        ):
            self.rejected.append(ev)
            self._pause_at = None
            return []
        return [self._confirmed(ev, fire, heard)]

    # --- internals ----------------------------------------------------------------------------
    def _frame_end_s(self, i: int) -> float:
        return self._t0 + (i * self._H + self._F - 1) / self._sr

    def _room(self) -> int:
        """Samples the inner detector may take now: up to the pending window's end, else W frames."""
        if self._pending is None:
            return self._H * self.window_frames  # a fire in these frames has its window end beyond them
        end = self._pending[1] + self._pending[2]  # the window's last frame
        return max(1, end * self._H + self._F - self._fed)

    def _absorb(self) -> None:
        ev, hot = self.inner.evidence, self.inner.hot_evidence
        if ev:
            self._margins.extend(ev)
            ev.clear()
        if hot:
            self._hot.extend(hot)
            hot.clear()
        keep = 2 * self.after_reject_frames + 4 * self._refire_frames
        extra = len(self._margins) - keep
        if extra > 4 * keep:  # trim now and then, not every block
            del self._margins[:extra]
            del self._hot[:extra]
            self._base += extra

    def _window(self, fire: int, n: int) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Margins and hot flags of the ``n`` frames after frame ``fire``."""
        lo, hi = max(fire + 1 - self._base, 0), max(fire + 1 - self._base + n, 0)
        m = np.nan_to_num(np.asarray(self._margins[lo:hi], dtype=np.float64), nan=-1.0)
        return m, np.asarray(self._hot[lo:hi], dtype=bool)

    def _fire_frame(self, ev: StopEvent) -> int:
        end = int(round((ev.detected_at_s - self._t0) * self._sr))
        return (end - (self._F - 1)) // self._H

    def _fired(self, ev: StopEvent) -> list[StopEvent]:
        out: list[StopEvent] = []
        fire = self._fire_frame(ev)
        if self.late is not None:
            if self.late.latched:  # the late path found this stop already: not counted twice
                self.late_swallowed.append(ev)
                return out
        if self._pending is not None:  # the inner released and fired again inside the window: no persistence
            self.rejected.append(self._pending[0])
            self._last_reject = self._rejected_fire = self._pending[1]
            if self._covered(self._window(self._pending[1], fire - self._pending[1])[0]):
                self._covered_at = self._pending[1]  # what broke it covered the stop: this fire may be the same stop
            self._pending = None
        if self._rejected_at is not None and self._continues_from_rejection(fire):
            # the stop-like sound had not gone away since the rejected window: the stop may have begun inside
            # it, or before it; when, is not known
            ev = replace(ev, onset_uncertain=True)
        self._rejected_at = None
        recent = self._last_reject is not None and fire - self._last_reject <= self._recent_frames
        if not recent or not math.isfinite(self._before_power):
            self._hear_before(fire)
        if self.sync_bands and (not recent or self._ref is None):
            # the stepping before this fire is the reference (a fire soon after a rejected one keeps its chain's:
            # the interference may have been going on since)
            end = fire * self._H + self._F - self._gap
            self._ref = self._samples(end - self._span, end)
        self._pending = (ev, fire, self.after_reject_frames if recent else self.window_frames)
        self.inner.hold(True)  # the window decides whether this was a stop: the inner does not re-arm meanwhile
        return out

    def _continues_from_rejection(self, fire: int) -> bool:
        """No gap of :attr:`gap_frames` between the last rejected window's end and frame ``fire``?"""
        assert self._rejected_at is not None
        if fire - self._rejected_at <= self._refire_frames:
            return True  # heard at once on un-latching
        m, _ = self._window(self._rejected_at - 1, fire - self._rejected_at)  # frames rejected_at .. fire - 1
        return self._longest_gap(m >= 0.0) < self.gap_frames

    @staticmethod
    def _longest_gap(ok: NDArray[np.bool_]) -> int:
        """The longest run of False in ``ok``."""
        edges = np.flatnonzero(np.diff(np.concatenate(([1], ok.astype(np.int8), [1]))))
        return int(np.max(edges[1::2] - edges[0::2])) if edges.size else 0

    def _decide(self) -> list[StopEvent]:
        if self._pending is None:
            return []
        ev, fire, window = self._pending
        last = fire + window
        if self.inner.frames_seen <= last:
            return []
        self._pending = None
        self.inner.hold(False)
        if (
            self._persisted(*self._window(fire, window))
            and self._in_step(ev, fire, window)
            and not self._stepping_stopped(ev, fire, window)
        ):
            return [self._confirmed(ev, fire, window)]
        self.rejected.append(ev)
        if self._pause_at is not None:
            self._restart_after_pause()
            return []
        self.inner.unlatch()
        self._rejected_at = self._last_reject = last
        self._rejected_fire = fire
        if self._covered(self._window(fire, window)[0]):
            self._covered_at = last
        return []

    def _keep_samples(self, x: NDArray[Any]) -> NDArray[np.float64]:
        """Keep a copy of ``x`` (damaged samples are mended when read, :meth:`_samples`); the copy."""
        v = np.array(x, dtype=np.float64)
        self._chunks.append(v)
        self._chunks_n += v.size
        if self._chunks_n > 2 * self._keep:  # trim now and then, not every block
            whole = np.concatenate(self._chunks)[-self._keep :]
            self._chunks0 += self._chunks_n - whole.size
            self._chunks, self._chunks_n = [whole], whole.size
        return v

    def _samples(self, lo: int, hi: int) -> NDArray[np.float64]:
        """The kept samples with absolute indices lo .. hi - 1 (those still kept)."""
        whole = np.concatenate(self._chunks) if len(self._chunks) != 1 else self._chunks[0]
        self._chunks = [whole]
        a, b = max(lo - self._chunks0, 0), max(min(hi - self._chunks0, whole.size), 0)
        if b <= a:
            return np.zeros(0)
        v = whole[a:b]
        return v if np.all(np.isfinite(v)) else np.nan_to_num(v, nan=0.0, posinf=1.0, neginf=-1.0)

    def _in_step(self, ev: StopEvent, fire: int, frames: int) -> bool:
        """Did the joint's step-synchronous sound change, line by line (see the module)? No verdict: True."""
        if not self.sync_bands or self._ref is None:
            return True
        start = fire * self._H + self._F  # the first sample after the fire's frame
        after = self._samples(start, start + min(self._span, frames * self._H))
        if self._ref.size < SYNC_MIN_S * self._sr or after.size < SYNC_MIN_AFTER_S * self._sr:
            return True
        n = min(self._ref.size, after.size)
        got = line_change(self._ref[-n:], after[:n], self._sr, self.sync_bands)
        self.step_clock_log.append((ev.detected_at_s, got))
        return step_clock_verdict(got) is not False

    def _hear_before(self, fire: int) -> None:
        """Measure the stepping before the fire at frame ``fire``: its in-band power and step rate."""
        end = fire * self._H + self._F - self._gap
        before = self._samples(end - self._span, end)
        if before.size < SYNC_MIN_S * self._sr:
            self._before_power = self._before_hz = math.nan
            return
        self._before_power = band_power(before, self._stop_sos, self._sr, BEFORE_QUANTILE)
        hz = step_rate_hz(before, self._sr)
        tuned = self.inner.tuning.step_rate_hz
        self._before_hz = hz if math.isfinite(hz) else (float(tuned) if tuned else math.nan)

    def _stepping_stopped(self, ev: StopEvent, fire: int, frames: int) -> bool:
        """Was the fire the stepping stopping (a pause), not an end stop (see stickslip.audio.stopped)?"""
        start = fire * self._H + self._F
        after = self._samples(start, start + frames * self._H)
        got = stepping_stopped(self._before_power, after, self._stop_sos, self._sr, self._before_hz, self._tuned_db)
        if got is None:
            return False
        self.stopped_log.append((ev.detected_at_s, got))
        self._pause_at = self._t0 + self._fed / self._sr
        return True

    def _restart_after_pause(self) -> None:
        """The stepping stopped: hear what follows afresh, as a new recording (the logs are kept)."""
        t, self._pause_at = self._pause_at, None
        assert t is not None
        rejected, stopped = self.rejected, self.stopped_log
        self.reset(t)
        self.rejected, self.stopped_log = rejected, stopped

    def _persisted(self, m: NDArray[np.float64], hot: NDArray[np.bool_]) -> bool:
        """Did the stop persist over the window's margins ``m`` and hot flags? (none heard: nothing contradicts it)"""
        if m.size == 0:
            return True
        ok = m >= 0.0
        if float(np.mean(ok)) < self.min_share or float(np.mean(hot)) < self.min_hot:
            return False
        return self._longest_gap(ok) < self.gap_frames

    def _confirmed(self, ev: StopEvent, fire: int, frames: int) -> StopEvent:
        """The event of the fire at frame ``fire`` confirmed over ``frames``; flagged where its onset is doubted."""
        self._retimed = None
        if self.late is not None:  # the fast path gave this stop: the late path judges nothing before it
            self.late.note_busy((fire + frames) * self._H + self._F)
        why = None if ev.onset_uncertain else self._onset_doubt(ev, fire, frames)
        self._covered_at = self._rejected_fire = None
        if why is None and self._retimed is not None:
            self.retime_log.append((ev.detected_at_s, ev.onset_s, self._retimed))
            ev = replace(ev, onset_s=self._retimed)
        if why is not None:
            self.onset_log.append((ev.detected_at_s, why))
            ev = replace(ev, onset_uncertain=True)
        return replace(ev, confirmed_at_s=self._frame_end_s(fire + frames), confirmed_s=frames * self._H / self._sr)

    def _onset_doubt(self, ev: StopEvent, fire: int, frames: int) -> str | None:
        """Why the stop that persisted may not have begun at the fire's onset (None: nothing says so).

        The window persisted: a stop is there. Whether it began at ``onset_s`` is a second
        question, asked of the same per-frame evidence around the fire (round 8b,
        docs/audio.md "When did the stop begin?"):

        * *a gap after the fire*: in the first half of the window, the frames were not
          stop-like for as long as the hold that fired (``hold_frames + max_dips``): the
          sound that fired went away, and the stop that persisted may have begun after it
          (a knock or a drift's false fire just before the stop);
        * *a fire weaker than the stop*: the stop-likeness over the fire's hold was under
          :data:`ONSET_FIRE_LEVEL` of that over the window's second half (template
          tunings): what fired was not the sound that persisted;
        * *a stop heard late*: the run of stop-like frames (dips of up to
          :data:`ONSET_BACK_DIPS` frames) that ends in the fire began more than
          :data:`ONSET_TOL_S` before the onset, at a stop-likeness of at least
          :data:`ONSET_BACK_LEVEL` of the window's (template tunings): the stop was
          there, and interference (a voice filling the sub-bands it empties) held its full
          verdict back;
        * *a stop covered before*: a fire was rejected since the last confirmed stop, its
          window *covered* (:data:`ONSET_COVERED_A`), and no :data:`ONSET_CLEAN_S` of
          clean stepping was heard between it and this fire: the rejected fire may have
          been this stop (a hiss over it broke its persistence);
        * *a template learned anew since a rejected fire* (the template fitted nothing for
          an update period: ``TemplateState.relearned`` in :mod:`.template`): it may have
          learned the stop, and the stop is then heard only when the interference over it
          ends.

        The evidence is looked at back to ``after_reject_frames + 4 x (hold + dips + 1)``
        frames before the fire (about 2.1 s at 48 kHz), which :meth:`_absorb` always keeps:
        the verdict does not depend on how the stream is cut into blocks.
        """
        if self._covered_at is not None and fire - self._covered_at <= self._look:
            between, _ = self._window(self._covered_at, fire - self._hold_frames - self._covered_at)
            clean = (between < 0.0) & (between > self._covered_margin)
            clean_frames = max(1, int(round(ONSET_CLEAN_S * self._sr / self._H)))
            if between.size < clean_frames or self._longest_gap(~clean) < clean_frames:
                return "a stop covered before"
        st = self.inner._template
        if self._rejected_fire is not None and st is not None and fire - self._rejected_fire <= self._look:
            lo_s = self._rejected_fire * self._H + self._F - 1
            if any(lo_s < end <= fire * self._H + self._F - 1 for end in st.relearned):
                return "a template learned anew since a rejected fire"
        m, _ = self._window(fire, frames)
        if m.size == 0:
            return None
        half = m[: max(1, min(m.size, self.window_frames // 2))]
        if self._longest_gap(half >= 0.0) >= self._hold_frames:
            return "a gap after the fire"
        if not self._levels:
            return None
        win = m[: self.window_frames] + 1.0
        late = win[win.size // 2 :]
        if late.size >= 2:
            lo = max(fire + 1 - self._hold_frames - self._base, 0)
            at_fire = np.asarray(self._margins[lo : max(fire + 4 - self._base, 0)], dtype=np.float64)
            at_fire = at_fire[np.isfinite(at_fire)]  # a fire at the warm-up's end (listening began at the stop): none
            weak = ONSET_FIRE_LEVEL * float(np.median(late))
            if at_fire.size * 2 >= self._hold_frames and float(np.median(at_fire + 1.0)) < weak:
                return "a fire weaker than the stop"
        # walk back from the fire over the stop-like run
        lo = max(self._base, fire - self._look)
        k = self._run_start(fire, lo, 0.0)
        began = self._frame_end_s(k) - self._lag
        on = max(k + 1, min(fire, int((ev.onset_s + self._lag - self._t0) * self._sr - self._F + 1) // self._H + 1))
        if ev.onset_s - began > ONSET_TOL_S:
            before, _ = self._window(k - 1, on - k)
            if before.size and float(np.median(before + 1.0)) >= ONSET_BACK_LEVEL * float(np.median(win)):
                return "a stop heard late"
        return self._rise(ev, fire, float(np.median(late)) if late.size else math.nan)

    def _rise(self, ev: StopEvent, fire: int, stop_level: float) -> str | None:
        """The stop-likeness's climb to the onset (round 9a): a doubt, or the onset taken back (:attr:`_retimed`).

        The crossing that set ``onset_s`` is in frame ``c``. The stepping's level ``b0`` is
        the median stop-likeness (in thresholds) over :data:`ONSET_BASE_S` ending
        :data:`ONSET_BASE_GAP_S` before it, the stop's ``stop_level``. Walking back from
        ``c`` over the frames at least :data:`ONSET_RISE_SHARE` of the way from the one to
        the other (dips of up to :data:`ONSET_BACK_DIPS` frames do not end the walk), the
        climb began at frame ``k``; it first reached the threshold at frame ``f0``.

        * *a stepping near the threshold*: ``b0`` over :data:`ONSET_QUIET` thresholds (the
          step rate far from the tuning's, a template gone stale: the stepping crosses the
          threshold by chance), and the crossing at ``f0`` more than :data:`ONSET_TOL_S`
          before the onset;
        * *taken back* (a clean stepping): ``f1``, the first hot frame after which the
          climb held (never under its level for more than :data:`ONSET_HELD_DIPS` frames
          running), is before ``c`` (the stop was hot, then wavered, or its drops showed
          only in flickers, and the hold began again): the onset is the crossing at
          ``f1``, if that is no more than :data:`ONSET_BACK_MAX_S` back (else *a stop
          heard late*);
        * *a slow rise* (clean stepping): from the end of the frame before ``k`` to the end
          of ``f0``, or to the crossing the onset is then taken from, whichever is later,
          took more than :data:`ONSET_SLOW_S` (a reverberant room's tail filling the
          sub-bands the stop empties, a stop that barely clears the threshold, a slow
          arrival): the crossing comes late by an unknown share of the climb. The climb is
          measured from where the stop-likeness left the stepping's own range: the walk
          above, over frames also above the stepping's :data:`ONSET_STEPPING_PCT`
          percentile (over the same span; at most :data:`ONSET_STEPPING_CAP` of the way to
          the stop's level). A stepping at another rate than the tuning's flickers up to the
          threshold and over it, and its flicker is not the stop's climb (round 11b). The
          climb is kept in :attr:`rise_log`.

        Nothing is judged (None) where the levels are not known: no stepping heard before
        the onset, or a stop no higher than the stepping.
        """
        if not math.isfinite(stop_level):
            return None
        cross = ev.onset_s + self._lag
        c = int(math.floor(((cross - self._t0) * self._sr - self._F + 1) / self._H)) + 1  # first frame ending after it
        c = min(c, fire)
        base_n = max(1, int(round(ONSET_BASE_S * self._sr / self._H)))
        lo = c - int(round(ONSET_BASE_GAP_S * self._sr / self._H)) - base_n
        if lo < max(fire - self._look, self._base):  # only what _absorb always keeps: no dependence on block sizes
            return None
        base = np.asarray(self._margins[lo - self._base : lo + base_n - self._base], dtype=np.float64)
        base = base[np.isfinite(base)]
        if base.size * 2 < base_n:
            return None  # listening began about now: no stepping to rise from
        b0 = float(np.median(base + 1.0))
        if not stop_level > b0:
            return None
        # as a margin; a stepping under the template (a below 0) is no lower a start: its frames would all continue it
        level = max(b0, 0.0) + ONSET_RISE_SHARE * (stop_level - max(b0, 0.0)) - 1.0
        k = self._run_start(c, lo, level)
        f0 = next((i for i in range(k, c + 1) if self._margin(i) >= 0.0), c)
        if b0 > ONSET_QUIET:
            # a stepping near the threshold (the step rate far from the tuning's, a template gone stale) crosses it by
            # chance: only where the first crossing of the climb says the onset came late is it a doubt
            late_by = ev.onset_s - self._crossing_s(f0)
            return "a stepping near the threshold" if late_by > ONSET_TOL_S else None
        # the first hot frame (the full verdict: not a burst's rise) from which the climb held to c, never under its
        # level for more than ONSET_HELD_DIPS frames running (a hot frame of stepping before a slow arrival does not)
        below = np.array([self._margin(i) < level for i in range(k, c + 1)], dtype=bool)
        f1 = next(
            (
                i
                for i in range(k, c)
                if self._hot[i - self._base] and self._longest_gap(~below[i - k :]) <= ONSET_HELD_DIPS
            ),
            c,
        )
        onset = self._crossing_s(f1) if f1 < c else ev.onset_s
        if ev.onset_s - onset > ONSET_BACK_MAX_S:
            return "a stop heard late"
        # the climb: from the end of the frame before it to its first frame over the threshold, or to the crossing the
        # onset is taken from, whichever is later (a stop that barely clears the threshold crosses it late, or early and
        # again later)
        # ... and it begins where the stop-likeness left the stepping's own range (round 11b: at another step rate than
        # the tuning's the stepping flickers to 0.5-1.4 thresholds, and a walk back over it measured its flicker as the
        # stop's climb); the walk above, which finds the frame the onset is taken back to, is not changed
        hi = float(np.percentile(base + 1.0, ONSET_STEPPING_PCT))
        k = self._run_start(c, lo, max(level, min(hi, ONSET_STEPPING_CAP * (b0 + stop_level)) - 1.0))
        f0 = next((i for i in range(k, c + 1) if self._margin(i) >= 0.0), c)
        climb = max(self._frame_end_s(f0), min(onset, ev.onset_s) + self._lag) - self._frame_end_s(k - 1)
        self.rise_log.append((ev.detected_at_s, climb))
        if climb > ONSET_SLOW_S:
            return f"a slow rise ({1e3 * climb:.0f} ms from the stepping's level to the threshold)"
        if onset < ev.onset_s:
            self._retimed = onset
        return None

    def _run_start(self, k: int, lo: int, level: float) -> int:
        """The first frame of the run that ends in frame ``k``, walking back no further than ``lo``: frames whose margin
        is at least ``level``, dips under it of up to :data:`ONSET_BACK_DIPS` frames not ending the run."""
        while k > lo:
            if self._margin(k - 1) >= level:
                k -= 1
                continue
            j = k - 1
            while j >= lo and self._margin(j) < level and k - j <= ONSET_BACK_DIPS:
                j -= 1
            if j >= lo and self._margin(j) >= level and k - 1 - j <= ONSET_BACK_DIPS:
                k = j
                continue
            break
        return k

    def _crossing_s(self, f: int) -> float:
        """The onset of a crossing of the threshold in frame ``f``: interpolated from the frame before, less the lag."""
        m0, m1 = self._margin(f - 1), self._margin(f)
        frac = (0.0 - m0) / (m1 - m0) if m0 < 0.0 < m1 else 1.0
        return self._frame_end_s(f) - (1.0 - frac) * self._H / self._sr - self._lag

    @property
    def _covered_margin(self) -> float:
        """The margin of a stop-likeness of :data:`ONSET_COVERED_A` (template tunings; -inf for a band tuning)."""
        if not self._levels:
            return -math.inf
        return ONSET_COVERED_A / float(self.inner.tuning.threshold_db) - 1.0

    def _covered(self, m: NDArray[np.float64]) -> bool:
        """Were the frames of a rejected window that were not stop-like covered (see :data:`ONSET_COVERED_A`)?"""
        low = m[m < 0.0]
        return bool(low.size) and float(np.median(low)) <= self._covered_margin

    def _margin(self, i: int) -> float:
        """The margin of frame ``i`` (-1 where it is not kept or NaN)."""
        j = i - self._base
        if not 0 <= j < len(self._margins):
            return -1.0
        v = self._margins[j]
        return v if math.isfinite(v) else -1.0


def _stepping_band(tu: Tuning) -> list[tuple[float, float]]:
    """The template's span, the band where stepping is heard, Hz ([] for a band tuning of version 1)."""
    if tu.method != "template" or tu.edges_hz is None:
        return []
    return [(float(tu.edges_hz[0]), float(tu.edges_hz[-1]))]


def step_clock_verdict(got: LineChange) -> bool | None:
    """The step clock's verdict on a fire: True (the lines changed), False (they did not) or None (no verdict).

    None where the lines before the fire were not sharp (:data:`MIN_SYNC_SHARPNESS`), held
    less than :data:`MIN_SYNC_SHARE` of the band's power, or nothing was measured (NaN).
    """
    if not (got.sharpness_before >= MIN_SYNC_SHARPNESS and got.share_before >= MIN_SYNC_SHARE):
        return None  # the clock's lines are smeared there, or hold next to nothing (or NaN)
    if not (math.isfinite(got.change_z) and math.isfinite(got.change_db)):
        return None
    return got.change_z >= MIN_SYNC_Z and abs(got.change_db) >= MIN_SYNC_CHANGE_DB


def confirming(detector: Any, confirm_s: float = CONFIRM_S, step_clock: bool = False, late: bool = False) -> Any:
    """``detector`` wrapped in a :class:`ConfirmedStopDetector`, where that applies.

    ``confirm_s`` 0 gives the detector back unchanged (the old behaviour); so does a
    detector that already confirms, or one that does not listen to samples (the
    simulator's oracle, a position read-back): only a :class:`StopDetector` has the
    per-frame evidence to confirm with. The wrapper listens with a fresh detector of the
    same tuning; ``detector`` itself is left as it was. ``step_clock`` True also asks the
    step clock (:class:`ConfirmedStopDetector`; off by default); ``late`` True also runs the
    late path (:mod:`.late`: stops the fast path never heard; off by default).
    """
    c = check_confirm_s(confirm_s)
    if c == 0.0 or not isinstance(detector, StopDetector):
        return detector
    return ConfirmedStopDetector(StopDetector(detector.tuning, detector._t0), c, step_clock=step_clock, late=late)
