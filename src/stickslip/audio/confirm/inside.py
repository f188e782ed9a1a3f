"""A stop that began inside a rejected fire's window, found on the joint's own clock.

A fire that does not persist is rejected at its window's end (2 s after a rejected fire:
:mod:`.persistence`), and the fast path listens again. A stop that began inside that window
was heard at best at the un-latching, its onset unknown (flagged: :mod:`.chain`), and not
at all where the levels had learned sound that was not the joint's (the tenth generator:
another instrument stepping in bursts at 730 Hz from the first sample; the joint alone
then reads stop-like to the levels, and its stop does not).

The traverse knows the rate it commands, and the joint's own clicks are in step with it: the
step clock's lines read in phase with the clock followed from the sound (:mod:`.clocked`)
hold the joint's sound alone, whatever else steps at another rate (its lines turn against
the clock and leave little in phase). So at a rejected window's end its samples are read so,
in pieces of ``piece_s``, against the chain's stepping (the clocked check's reference). A
stop began inside it where

* the pieces from one of them to the window's end each read ``min_affirm`` or more in phase
  (``ClockedParams``), ``min_run_s`` of them at least (half a second: a note of music within
  0.05 % of a line stays in phase over a piece, and turns away over a span), and a piece
  before them read under ``min_a`` (the joint stepping inside the window: else the fire was
  the stop, judged as it);
* its onset is where the joint's lines changed (:func:`onset_in_phase`: a step fitted to
  the frames turned by the clock followed, over the two pieces around the first affirmed
  one's start and a piece either side), ``min_run_s`` at least before the window's end;
* from that onset to the window's end both readings of the clocked check, on the comb and
  in phase, reach ``min_affirm`` (a fire the levels cannot confirm is affirmed so) and the
  stepping went on (not a pause: :mod:`.pause`, checked by the caller).

Off the tuning's rate, the rate told, the stepping's lines modelled (:mod:`.stepping_lines`) read a window too:
inside one whose fire they vetoed (:func:`stop_departed`), and, where the levels rejected the fire and the model
did not, over all of it (:func:`departed_throughout`: a stop whose drops music masked; flagged, its onset not known);
so too a window cut short where the fast path fired again inside it (:func:`held_refired`).

The event then carries ``found_late`` (``detected_at_s`` the window's end, when it was found)
and, where the fit's spread exceeds ``max_onset_off_s`` (it does not pin where the stop
began), ``onset_uncertain``. It runs only at a rejected window's end (or the stream's, while
a window is pending), never per frame. The same fit around a confirmed stop's onset flags it
where the lines changed more than ``max_onset_off_s`` and more than the spread away
(:meth:`.checks.WindowChecks.onset_doubt`).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..events import StopEvent
from ..paramfield import param
from .chain import Fire
from .clocked import ClockedCheck, ClockedParams, OnClock, turned_frames
from .pause import PauseCheck
from .stepping_lines import SteppingLines

__all__ = [
    "INSIDE",
    "Held",
    "Inside",
    "InsideParams",
    "departed_throughout",
    "early_model",
    "held_inside",
    "held_refired",
    "onset_in_phase",
    "still_departed",
    "stop_departed",
    "stop_inside",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class InsideParams:
    """A stop that began inside a rejected fire's window, found on the step clock's lines read in phase."""

    piece_s: float = param(
        0.1, "s", "the window is read in phase in pieces this long (5 of the lines' 20 ms frames: 100 steps at 1 kHz)"
    )
    min_run_s: float = param(
        0.48, "s", "and from the onset to the window's end (a span: a note within 0.05 % of a line turns in it)"
    )
    scan_s: float = param(
        0.005, "s", "the lines' step is fitted on frames started this far apart (a fifth of the 25 ms a count allows)"
    )
    max_onset_off_s: float = param(
        0.025, "s", "an onset the step's fit does not pin within this is uncertain; a confirmed stop's this far off too"
    )
    spread_var: float = param(
        4.0, "variances", "the splits whose misfit is within this many residual variances of the best: the spread"
    )


INSIDE = InsideParams()


@dataclass(frozen=True)
class Inside:
    """A stop found inside a rejected window."""

    #: its onset, samples from the start of the samples read
    onset: int
    #: how far the splits that fit about as well reach from it, samples
    spread: int
    #: the clocked check's readings from the onset to the window's end
    on_clock: OnClock


def stop_inside(
    x: FloatArray, lead: int, clocked: ClockedCheck, heard_hz: float, p: InsideParams = INSIDE
) -> Inside | None:
    """The stop that began inside the rejected window ``x[lead:]`` (samples; ``x[:lead]`` before it), or None.

    ``clocked`` holds the chain's stepping (its reference) and the commanded rate; ``heard_hz`` the step rate heard
    in that stepping (Hz; NaN: none). See the module docstring.
    """
    cp, ref, sr = clocked.p, clocked.ref, clocked.sample_rate
    if not clocked.enabled or ref is None or ref.size < cp.min_s * sr or clocked.ref_stoplike > cp.max_ref_stoplike:
        return None  # as the clocked check: no stepping to compare with
    rate = clocked.rate(heard_hz)
    piece = int(round(p.piece_s * sr))
    if not math.isfinite(rate) or piece <= 0 or lead < piece:
        return None
    reader = clocked.reader(rate)
    if reader is None:
        return None
    n = (x.size - lead) // piece
    got = [reader.read(x[lead + i * piece : lead + (i + 1) * piece]) for i in range(n)]
    j = n
    while j > 0 and got[j - 1] >= cp.min_affirm:  # NaN ends the run
        j -= 1
    stepping = [g for g in got[:j] if math.isfinite(g)]
    if (n - j) * piece < p.min_run_s * sr or not stepping or not min(stepping) < cp.min_a:
        return None
    lo = lead + (j - 2) * piece  # the two pieces around the first affirmed one's start, and a piece either side
    t, spread = onset_in_phase(x[lo : lead + (j + 1) * piece], sr, rate, reader.lines, cp, p)
    if t < 0 or x.size - (lo + t) < p.min_run_s * sr:
        return None
    on = clocked.judge(x[lo + t :], heard_hz)
    if not clocked.affirms(on):
        return None
    assert on is not None
    return Inside(lo + t, spread, on)


def stop_departed(x: FloatArray, lead: int, clocked: ClockedCheck, p: InsideParams = INSIDE) -> Inside | None:
    """Off the tuning's rate, the stop that began inside a window ``x[lead:]`` whose fire the stepping's lines
    modelled vetoed (``lines_model``; :meth:`~.clocked.ClockedCheck.model_z`), or None.

    The window is read in the model's pieces (``span_s``); its fire was vetoed because a piece sat within
    ``model_max_z`` of the stepping. Where the pieces after it, to the window's end, each depart from the model
    (``model_max_z`` or more: the lines changed and stayed so, ``min_run_s`` at least), the joint stopped there:
    its onset is fitted on the model's lines turned by its clock (:func:`onset_in_phase`, over the last piece
    within and the first departed), as a stop found inside a rejected window (the caller checks it is not a pause).
    Sound over the stepping can depart before the stop does (music 3.04 spreads in the piece before the stop's):
    with ``model_onset`` the fit is repeated over every departed piece to the window's end, and where it places the
    lasting change more than ``max_onset_off_s`` and its spread away, the find's spread is that distance (flagged).
    A stop changes the lines at once; sound added over them drifts in and out. So the fit must place the change
    within ``model_max_spread_s``, else none was found; and inside the stretch fitted, ``model_edge_s`` at least
    before its end: a best split nearer the end is a boundary optimum (the change lies at or past the end, often with
    no spread at all), not an onset found, and the window stays vetoed (a stop there still sounds after it and is
    judged again). A find is held until its lines were read past the window's end (``model_hold_s``;
    :func:`still_departed`, :class:`Held`): sound over the stepping departs too, and changes back.
    """
    cp, sr, m, n = clocked.p, clocked.sample_rate, clocked.model, clocked.model_n
    if m is None or n <= 0 or not (clocked.models_lines() and clocked.model_ready()):
        return None
    w = x[lead:]
    k = min(cp.window_pieces, w.size // n)
    zs = [m.z_of(m.levels(w[i * n : (i + 1) * n])[0], cp.model_min_spans, cp.model_floor_db) for i in range(k)]
    j = k
    while j > 0 and zs[j - 1] >= cp.model_max_z:  # NaN ends the run
        j -= 1
    if j == k or j == 0 or not zs[j - 1] < cp.model_max_z or (k - j) * n < p.min_run_s * sr:
        return None  # no departure to the window's end, or none from stepping within it
    lo = lead + (j - 1) * n
    t, spread = onset_in_phase(x[lo : lead + (j + 1) * n], sr, clocked.model_hz, m.ks, cp, p)
    if t < 0 or spread > cp.model_max_spread_s * sr or lead + k * n - (lo + t) < p.min_run_s * sr:
        return None
    if 2 * n - t < cp.model_edge_s * sr:
        return None  # the best split at the stretch's end: the fit found no change inside it
    if cp.model_onset and k - j > 1:  # the lasting change fitted over every departed piece: elsewhere, uncertain
        u, s = onset_in_phase(x[lo : lead + k * n], sr, clocked.model_hz, m.ks, cp, p)
        if u >= 0 and abs(u - t) > max(p.max_onset_off_s * sr, s):
            spread = max(spread, abs(u - t))
    return Inside(lo + t, spread, OnClock(math.nan, clocked.model_hz, 0, still_z=float(min(zs[j:]))))


def departed_throughout(w: FloatArray, clocked: ClockedCheck, early: SteppingLines | None = None) -> float:
    """The least z over the spans of a window ``w`` (samples) the levels rejected, read against the stepping's lines
    modelled as :func:`stop_departed` reads them (up to ``window_pieces`` spans of the model's length), spreads (NaN:
    no model ready, or not one whole span). At or over ``model_max_z`` the lines departed from the stepping in every
    span: a stop the levels did not hold (music masking its drops; ``model_rejected``), held until its lines are read
    past the window (:func:`still_departed`) and emitted flagged, its onset (the fire's) not known. ``early``: read
    against that model instead, the spans offered before the model was ready (:func:`early_model`)."""
    cp, m, n = clocked.p, clocked.model if early is None else early, clocked.model_n
    ready = clocked.model_ready() or early is not None
    if m is None or n <= 0 or w.size < n or not (clocked.models_lines() and ready):
        return math.nan
    k = min(cp.window_pieces, w.size // n)
    need = 0.0 if early is not None else cp.model_min_spans  # (early: the spans counted by early_model)
    return float(np.min([m.z_of(m.levels(w[i * n : (i + 1) * n])[0], need, cp.model_floor_db) for i in range(k)]))


def early_model(clocked: ClockedCheck, before: int, every: bool = False) -> SteppingLines | None:
    """Before the stepping's lines modelled are ready (``model_lag_s``: a span is modelled only once any fire over it
    was judged), the model with every span already offered that ended by absolute sample ``before`` (a fire's onset:
    stepping, as the fire's own reference is) and was stepping accepted, where ``model_min_spans`` spans are counted
    so (``model_rejected_early``; the tuning's stops in the rates bench come 2 s into listening, the model ready at
    about 5 s). None: not so, the model ready, or the lines not modelled (:meth:`.ClockedCheck.models_lines`).
    ``every``: every span offered, accepted or not (the stepping as heard, sound on it and all;
    ``model_confirmed_early``, :func:`held_early`)."""
    cp, m, sr = clocked.p, clocked.model, clocked.sample_rate
    on = cp.model_confirmed_early if every else cp.model_rejected_early
    if not on or m is None or clocked.model_ready() or not clocked.models_lines():
        return None
    got = [(t, level, share) for t, level, share, alone in clocked.pending if (alone or every) and t * sr <= before]
    if math.ceil(m.weight) + len(got) < math.ceil(cp.model_min_spans):
        return None
    early = copy.deepcopy(m)
    for t, level, share in got:
        early.add(level, share, t)
    return early


def still_departed(x: FloatArray, clocked: ClockedCheck, early: SteppingLines | None = None) -> float:
    """After a window a stop was found departed in (:func:`stop_departed`), the samples ``x`` that followed it read
    against the stepping's lines modelled in pieces of ``model_hold_piece_s``: the least z over them, spreads (NaN:
    no model, or not one whole piece). At an end stop the joint steps on into it until the traverse stops commanding:
    its lines stay departed; music, speech or a radio over the stepping change and change back (``model_hold_s``).
    ``early``: against that model instead (:func:`early_model`)."""
    cp, m = clocked.p, clocked.model if early is None else early
    n = int(round(cp.model_hold_piece_s * clocked.sample_rate))
    if m is None or n <= 0 or x.size < n:
        return math.nan
    need = 0.0 if early is not None else cp.model_min_spans
    pieces = [x[i * n : (i + 1) * n] for i in range(x.size // n)]
    return float(np.min([m.z_of(m.levels(v)[0], need, cp.model_floor_db) for v in pieces]))


@dataclass(frozen=True)
class Held:
    """A stop found departed from the stepping's lines modelled (:func:`stop_departed`), held, its fast path latched,
    until its lines are read ``model_hold_s`` past the window's end (:func:`still_departed`); or a stop confirmed
    whose lines were out of step at its fire (``doubt``: :meth:`.checks.WindowChecks.out_of_step`), held so too: a
    stop where they depart by ``model_in_step_hold_z`` past the window, else emitted flagged for that doubt; or a fire
    the levels rejected whose lines departed in every span of its window (``flagged``: ``model_rejected``), held so too
    and emitted flagged where they still depart by ``model_max_z``."""

    #: the fire whose window held it (rejected; confirmed, with a ``doubt``)
    fire: Fire
    #: the event it is, as found at the window's end
    event: StopEvent
    #: how it was found inside the window (None: the fire's own stop, confirmed)
    found: Inside | None
    #: the window's end and the hold's, samples fed
    end: int
    until: int
    #: why the confirmed stop is doubted unless its lines stay departed past the window (None: found inside)
    doubt: str | None = None
    #: why the stop found is flagged whatever is read past the window (``model_rejected``; None: not so)
    flagged: str | None = None
    #: the window was cut short by a fire that stays pending beside the hold (``model_refired``): dropped if the hold
    #: emits a stop, judged as it comes if not
    beside: bool = False
    #: the model the window was read against where the stepping's modelled was not yet ready (:func:`early_model`;
    #: None: the stepping's modelled)
    early: SteppingLines | None = None
    #: with a :attr:`doubt`: flagged only where its lines read back within ``model_max_z`` (not where none was read;
    #: :func:`held_early`), not unless they reach ``model_in_step_hold_z``
    back: bool = False

    def judged(self, x: FloatArray, t0_s: float, clocked: ClockedCheck) -> tuple[StopEvent | None, float]:
        """Read on ``x``, the samples fed from :attr:`end` (to :attr:`until`, or the stream's end): the event, emitted
        when its hold was heard (None: its lines changed back, not a stop), and the least z read (NaN: none read,
        the stream ended: the event flagged). No hold (:attr:`until` at :attr:`end`): the event as found. With a
        :attr:`doubt`: the event, flagged unless the least z reached ``model_in_step_hold_z``."""
        if self.until <= self.end:
            return self.event, math.nan
        z = still_departed(x, clocked, self.early)
        need = clocked.p.model_max_z if self.doubt is None or self.back else clocked.p.model_in_step_hold_z
        if z < need and self.doubt is None:
            return None, z
        t = t0_s + (self.end + x.size) / clocked.sample_rate
        e = self.event
        flag = e.onset_uncertain or (z < need if self.back else not z >= need)  # (NaN: none read)
        return replace(e, detected_at_s=t, confirmed_at_s=t, confirmed_s=t - e.onset_s, onset_uncertain=flag), z


def held_out_of_step(fire: Fire, ev: StopEvent, why: str | None, end: int, clocked: ClockedCheck | None) -> Held | None:
    """``ev``, confirmed on ``fire`` whose window ended at sample ``end``, held where its lines out of step with the
    steps (``why``: :meth:`.checks.WindowChecks.out_of_step`) alone doubt it: a stop once they still depart from the
    stepping's lines modelled by ``model_in_step_hold_z`` over ``model_hold_s`` past the window (an end stop stays
    changed while the joint steps on into it, even one that rattles out of step; music changes back). None: not held."""
    if why is None or clocked is None:
        return None
    return Held(fire, ev, None, end, end + int(round(clocked.p.model_hold_s * clocked.sample_rate)), why)


def held_early(fire: Fire, ev: StopEvent, at: tuple[int, int], clocked: ClockedCheck | None) -> Held | None:
    """``ev``, confirmed on ``fire`` before the stepping's lines modelled were ready (``at``: its window's end and its
    onset, absolute samples), held ``model_hold_s`` past the window and read there against every span offered before
    its onset (:func:`early_model` with ``every``: the stepping as heard, the sound on it too; the model's own reading
    needs a few seconds of stepping accepted, and speech or music from the first seconds leaves too few). At an end
    stop the joint steps on into it and its lines stay changed; speech or music over the stepping changes them and
    changes back: where the pieces past the window read within ``model_max_z`` of that stepping (the model's own bar
    for "the stepping's"), the stop is flagged, never dropped (``model_confirmed_early``). None: not held (flagged
    already, no such model, or the hold off)."""
    if clocked is None or ev.onset_uncertain or clocked.p.model_hold_s <= 0.0:
        return None
    early = early_model(clocked, at[1], every=True)
    if early is None:
        return None
    why = "confirmed before the stepping's lines modelled were ready; its lines came back to the stepping's past it"
    end, hold = at[0], int(round(clocked.p.model_hold_s * clocked.sample_rate))
    return Held(fire, ev, None, end, end + hold, why, early=early, back=True)


def held_inside(
    x: FloatArray,
    lead: int,
    fire: Fire,
    at: tuple[int, float, float],
    clocked: ClockedCheck,
    pause: PauseCheck,
    on_clock: OnClock | None,
    p: InsideParams = INSIDE,
) -> Held | None:
    """The stop that began inside ``fire``'s rejected window ``x[lead:]`` (``x[:lead]`` before it; ``at``: the
    absolute sample of ``x[lead]``, the stream's start time, s, and the sample rate, Hz), held until it may be emitted:
    found on the joint's clock (:func:`stop_inside`: at once), else, where the stepping's lines modelled vetoed the fire
    (``on_clock``), departed from them (:func:`stop_departed`: once its lines were read ``model_hold_s`` past the
    window); else, where the model did not veto it, a window departed from them in every span (``model_rejected``:
    :func:`_rejected_departed`, held so too, flagged); none where the stepping stopped from its onset (``pause``) or
    nothing was found."""
    start, t0_s, sr = at
    cp = clocked.p
    got, hold = stop_inside(x, lead, clocked, pause.before_hz, p), 0
    if got is None and cp.model_inside and clocked.model_vetoed(on_clock):  # the stepping's lines modelled
        got, hold = stop_departed(x, lead, clocked, p), int(round(cp.model_hold_s * sr))
    end = start - lead + x.size
    if got is None and cp.model_rejected and cp.model_hold_s > 0.0 and not clocked.model_vetoed(on_clock):
        return _rejected_departed(x[lead:], fire, (end, t0_s, sr), clocked, pause)
    if got is None or pause.stopped(x[got.onset :]) is not None:
        return None
    onset_s, found_s = t0_s + (start - lead + got.onset) / sr, t0_s + end / sr
    uncertain = got.spread > p.max_onset_off_s * sr
    ev = StopEvent(found_s, onset_s, fire.ev.level_db, found_s, found_s - onset_s, uncertain, found_late=True)
    return Held(fire, ev, got, end, end + hold)


def _rejected_departed(
    w: FloatArray,
    fire: Fire,
    at: tuple[int, float, float],
    clocked: ClockedCheck,
    pause: PauseCheck,
    why: str = "the levels did not hold it",
) -> Held | None:
    """``fire``'s window ``w`` (the levels rejected it; ``at``: the absolute sample after it, the stream's start time,
    s, and the sample rate, Hz), held as a stop, flagged (``why`` the window was not confirmed), where its lines
    departed from the stepping's modelled in every span (:func:`departed_throughout`) and the stepping went on (not a
    pause). None: not so. Not asked whether its lines stayed in step (``model_in_step``): a stop that lowers them into
    the room's noise under music reads out of step (the fifth generator's damped arm, 1 % jitter, 1100 Hz: 0.35 of the
    model's 0.81, +4.8 dB)."""
    end, t0_s, sr = at
    on = fire.ev.onset_s
    early = early_model(clocked, int(round((on - t0_s) * sr)))  # (None: the model ready, or too few spans)
    z = departed_throughout(w, clocked, early)
    if not z >= clocked.p.model_max_z or pause.stopped(w) is not None:  # (NaN: not read)
        return None
    found_s = t0_s + end / sr
    ev = StopEvent(found_s, on, fire.ev.level_db, found_s, found_s - on, True, found_late=True)
    read = "the stepping's" if early is None else "the stepping's heard before it"
    why = f"{why}; its lines departed from {read} in every span (z {z:.1f}): onset unknown"
    return Held(fire, ev, None, end, end + int(round(clocked.p.model_hold_s * sr)), flagged=why, early=early)


def held_refired(
    w: FloatArray, fire: Fire, at: tuple[int, float, float], clocked: ClockedCheck, pause: PauseCheck
) -> Held | None:
    """``fire``'s window ``w``, cut short where the fast path fired again inside it (``at``: the absolute sample after
    it, the stream's start time, s, and the sample rate, Hz), held as :func:`_rejected_departed` holds a window the
    levels rejected (``model_refired``): where its lines departed from the stepping's modelled in every span (one
    span at least) and still depart past it, a stop, flagged. The fire that cut it stays pending beside the hold
    (:attr:`Held.beside`): a hold that does not emit changes nothing else. Persistence never judges such a window,
    and under music that fires again every half second or so a stop can lie in nothing but such windows (the tenth
    generator's arm 3, 950 Hz, music +3 dB: two windows across the stop, 11.3 and 13.5 spreads off). None: not so, or
    not read (no model ready, the rate at the tuning's, under one span)."""
    cp = clocked.p
    if not (cp.model_refired and cp.model_hold_s > 0.0):
        return None
    got = _rejected_departed(w, fire, at, clocked, pause, "cut short by a fire inside it")
    return None if got is None else replace(got, beside=True)


def onset_in_phase(
    x: FloatArray, sr: float, rate_hz: float, lines: Sequence[int], cp: ClockedParams, p: InsideParams = INSIDE
) -> tuple[int, int]:
    """Where in ``x`` the joint's ``lines`` changed, samples, and the spread of that estimate, samples (-1 and the
    length of ``x``: not fitted).

    The lines demodulated in frames and turned by the clock followed (:func:`~.clocked.turned_frames`) keep one
    phasor per line while the joint steps and another once it is stopped; sound of another clock turns and only
    scatters them. A step (two means per line, each line weighted to unit power) is fitted by least squares, on
    frames started every ``scan_s`` within one frame; the best split of the best-fitting series is the onset and the
    splits within ``spread_var`` residual variances of its misfit its spread. Linear in the frames: a piece part
    stepping and part stopped reads in between, whichever way the stop moves the lines.
    """
    frame = max(1, int(round(cp.locked_frame_s * sr)))
    best = (math.inf, -1, x.size)
    for o in range(0, frame, max(1, int(round(p.scan_s * sr)))):
        z = turned_frames(x[o:], sr, rate_hz, lines, cp)
        m = z.shape[0]
        if m < 4:
            continue
        w = 1.0 / np.maximum(np.mean(np.abs(z) ** 2, axis=0), 1e-300)
        s1, s2 = np.cumsum(z, axis=0), np.cumsum(np.abs(z) ** 2, axis=0)
        k = np.arange(1, m)
        left = (s2[k - 1] - np.abs(s1[k - 1]) ** 2 / k[:, None]) @ w
        right = ((s2[-1] - s2[k - 1]) - np.abs(s1[-1] - s1[k - 1]) ** 2 / (m - k)[:, None]) @ w
        sse = left + right
        b = int(np.argmin(sse))
        var = float(sse[b]) / max(m - 2, 1)
        near = np.flatnonzero(sse - sse[b] <= p.spread_var * var)
        if float(sse[b]) / m < best[0]:
            best = (float(sse[b]) / m, o + int(k[b]) * frame, int(np.max(np.abs(near - b))) * frame)
    return best[1], best[2]
