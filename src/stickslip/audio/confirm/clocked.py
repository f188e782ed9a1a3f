"""Is the change on the step clock? A stop changes the joint's own clicks; added sound does not.

At an end stop the controller keeps stepping: the joint's sound is still a train of clicks
at the step rate, and the stop changes *that* sound (a shorter slip, the end stop ringing:
louder in some sub-bands, quieter in others). Music, a radio, a voice or a fan is not in
step with the clock: it adds power between the step clock's harmonic lines and, on
average, none on them. The level detector cannot tell the two apart where the stop's
signature is a rise (a louder stop): any sound added in those sub-bands fits it.

So a fire that persisted must also show the stop's signature on the lines. Over the tuning's
sub-bands whose signature moves by ``min_signature_db`` or more, the power on the step
clock's lines above the continuum beside them
(:func:`~stickslip.audio.features.stepclock.line_powers`) is measured over the stepping
before the fire and over the window's first samples, at the step rate commanded (or, untold,
heard in the stepping); the stepping before the fire is the reference the confirmation keeps
(for a fire soon after a rejected one, the stepping before the first of them). Per sub-band
the change ``dL_b`` (dB, each side floored at ``floor_share`` of the larger), kept where the
lines stood ``min_line_z`` standard deviations over their noise before the fire and were
sharp there (``min_sharpness`` of the power in a comb four times wider: a rough clock smears
its higher harmonics, and what is left on the narrow lines is not the joint's sound alone).
Each sub-band is read on the narrowest of ``combs`` on which its lines are sharp (heard, as
before, on the widest): first a line 3 bins of the window wide, the comb an average in step
with the clock over the window resolves, on which music's partials beside a clean clock's
lines stay out; then 0.4 % of the line's frequency, for a clock whose lines wander wider.
And where the tuned stop's change was on the lines itself (the tuning's continuum between
the lines moved no further in the stop's direction than its level, plus
``max_continuum_excess_db``: a stop that rattles out of step with the clock changes the
continuum, not the lines, and is not judged there); the *lines' stop-likeness* is the
least-squares fit of the tuned signature ``delta`` to them,

    a_L = sum_b delta_b dL_b / sum_b delta_b^2,

1 for a stop like the tuning's, 0 for a change that is all off the clock. A fire whose
``a_L`` is under ``min_a`` is not a stop. No verdict (the fire stands on the other rules)
when the tuning has no continuum signature (made before it was stored), when the sub-bands
kept hold less than ``min_covered`` of the signature's sum of squares (one sub-band's
estimate is not the stop's signature), the rate is not known or is more than
``max_rate_off`` from the tuning's (the lines then sample the arm's narrow modes elsewhere,
and the tuned signature is not what the stop does on them), where more than
``max_ref_stoplike`` of the reference's frames were already stop-like and no stepping is
kept (a stop heard late began there: the reference is the stop, not stepping), or where less
than ``min_s`` of stepping or ``min_after_s`` of the window was heard. The lines are immune
to what is added between them, so the tuned signature is fitted as tuned (no masking). It
runs once per fire that persisted, never per frame.

**Affirmed at another rate.** Beyond ``max_rate_off`` the tuned signature is not what the
stop does on the lines, and a reading under ``min_a`` is no evidence against a stop: no veto
on it there. But both readings at ``min_affirm`` still say the joint's own sound changed as the
tuned stop changes it, which no added sound does: with the commanded rate told, a fire the
levels cannot confirm (:mod:`stickslip.audio.change.drops`: at a rate where the stop lowers
nothing worth checking) may be affirmed so up to ``affirm_window`` from the tuning's rate
(as the fit's ``commanded_window``). Nothing untold.

**Unmoved at another rate.** What does hold there, whatever the signature, is that a stop
changes the joint's own clicks, so it moves their lines somewhere, while sound added out of
step with the clock leaves them in phase as they were (the stepping goes on through a false
stop). So with the rate told (the controller's clock, not a guess), off the tuning's rate and
within ``affirm_window``, where the comb could judge the tuned stop's sub-bands, a fire whose
lines in phase moved less than ``min_moved_db`` RMS over every sub-band whose lines were locked
before (:func:`lines_moved_db`) is not a stop. Where the comb could not judge them (the tuned stop's
sub-bands hold no sharp line at this rate), only the tuning's fine continuum can say whether the stop
changes the lines read there at all: the same veto holds where the signature predicted at the rate
(:class:`~stickslip.audio.features.fine.SignaturePredictor`) moves the locked sub-bands
``min_pred_moved_db`` RMS or more (:meth:`ClockedCheck.predicted_moved_db`); where it predicts less
(a stop whose change at this rate lies off those lines) or cannot predict, no veto.

**The stepping's lines as one model** (``lines_model``). In place of the half second before each fire, the
stepping's lines modelled across the listening (:mod:`.stepping_lines`, :meth:`ClockedCheck.model_stepping`) are the
reference off the tuning's rate, the rate told: under the same reading conditions (a comb verdict, or the predicted
move), a fire whose window has a piece within ``model_max_z`` spreads of the model is not a stop; read also where
the fire's own reference was stop-like. Until the model holds ``model_min_spans`` (the first seconds of listening),
``min_moved_db`` and ``min_pred_moved_db`` judge as above (without them a radio from the first sample is counted a
stop at 0.4 s). A model whose lines were locked in fewer than ``model_min_bands`` sub-bands reads one line's level,
no RMS over the stop's signature: sound on that line scatters it either way, so its reading within does not veto, it
flags the stop (:func:`model_thin`). Told the rate, once a span is heard within ``told_held_tol`` of it and in step
there (a clean clock), the lines are read at the told rate, not at a line music pulled off it
(:meth:`ClockedCheck.hear_held`). Where the pieces after the one within depart from the model to the window's end,
the stop may have begun there (``model_inside``; :func:`.inside.stop_departed`), emitted once its lines still depart
past the window's end (``model_hold_s``: a stop holds while the stepping goes on; music or speech changes back). A
fire the model lets through whose lines held under ``model_in_step`` of the model's own share in phase is flagged
(:meth:`ClockedCheck.in_step_reading`, asked by :meth:`.checks.WindowChecks.onset_doubt`): at an end stop the joint
steps on into it and its lines stay in step, only their level moves; music or speech on them moves it out of step.
Not where its lines still depart from the model by ``model_in_step_hold_z`` past the window (read as the hold above,
the event held till then): a stop that rattles out of step stays changed, music changes back. A jittered step clock
turns each line's phase within a frame, so its share in phase falls under ``model_min_share`` with no other sound:
such a span is taken too where each line holds what the followed clock's own wander leaves it (``model_expect``;
:func:`expected_held`). A fire the levels rejected (it did not persist: music masking a stop's drops) whose window
departs from the model by ``model_max_z`` in every span, and whose lines still depart past the window (the hold
above), is a stop, flagged: its onset, the fire's, is not known (``model_rejected``;
:func:`.inside.departed_throughout`); so is a window cut short by a fire inside it, which persistence never judges
(``model_refired``; :func:`.inside.held_refired`). The per-fire vetoes only veto, and under speech or music they
seldom can (the lines move with the added sound, or are not read): so once the model could have been ready and was
not (its spans' lines held under ``model_min_share`` in phase: sound of another kind on them, or a jittered clock),
a stop it did not read is flagged, not counted, unless both readings affirm it against the stepping just before its
fire (``model_unjudged``; :meth:`ClockedCheck.unjudged`, asked by :meth:`.checks.WindowChecks.onset_doubt`). Before
then, a stop no reading of the lines judged at all (the per-fire vetoes gave no verdict) stands on the levels alone:
flagged too (``model_unjudged_early``).

**The stepping kept.** Music that lifts the stop's sub-bands for half a second before a fire
makes that reference stop-like too, and the check could not judge it. So every ``span_s``
of the stream (counted from its start) whose frames were at most ``kept_stoplike``
stop-like, every one heard, is kept, and where the fire's own reference is over
``max_ref_stoplike`` stop-like the latest kept that ended no more than ``kept_age_s``
before it is the reference instead (a stop heard late is then judged against the stepping
before it). Where none was kept either, the check gives no verdict, and a stop
confirmed so has no stepping before it to place it by: it is flagged ``onset_uncertain``
(``onset_ref_stoplike``; :meth:`.checks.WindowChecks.onset_doubt`), as it may have begun there.
So is a stop confirmed with under ``min_s`` of stepping heard before its fire (the stream
began near it, the change detector still learning; ``onset_short_ref``): nothing places it.
A stop whose onset is the start of listening is not (the warm-up judged that listening began
at the stop, :mod:`~stickslip.audio.change.start`: no change after the start is claimed).

**In phase with the steps.** A note on or beside one of the few lines a joint is judged on adds
power the comb counts as the joint's. So the same sub-bands are also read in phase with the
steps' clock, followed from the sound (:mod:`~stickslip.audio.features.lockin`, in frames of
``locked_frame_s``): a note off its line turns against the clock and leaves little in phase,
while a stop changes the steps' own sound, all of it in phase. A sub-band is read where its
lines held ``min_locked`` of their power in phase before the fire; the signature is fitted as
above (:func:`locked_stop_likeness`), and a fire whose reading in phase is under ``min_a`` is
not a stop either (it can only veto).

**A long window in spans.** A window that persisted over more than one span (2 s, after a
rejected fire) is read in up to ``window_pieces`` spans against the reference, the median
``a_L`` kept: a stop's lines stay changed while the joint steps into it, a note of music on a
line moves on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..features.fine import SignaturePredictor, signature_predictor
from ..features.lockin import demodulate, follow_clock, locked_powers
from ..features.stepclock import STEP_CLOCK, Periodogram, StepClockParams, line_powers, periodogram, rate_near_hz
from ..paramfield import param
from ..tuningfile import Tuning
from .stepping_lines import SteppingLines

__all__ = [
    "CLOCKED",
    "ClockedCheck",
    "ClockedParams",
    "LockedReader",
    "OnClock",
    "lines_moved_db",
    "lines_stop_likeness",
    "locked_reader",
    "locked_stop_likeness",
    "turned_frames",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class ClockedParams:
    """The stop's signature on the step clock's lines: a fire whose change is off the clock is not a stop."""

    min_a: float = param(
        0.25, "", "the lines' stop-likeness a fire must reach (music, a radio: mostly under 0.15; stops: 0.3 and more)"
    )
    min_signature_db: float = param(
        3.0, "dB", "sub-bands the tuned stop moves less than this are not judged (their lines hardly change)"
    )
    min_line_z: float = param(
        3.0, "standard deviations", "a sub-band is judged only where its lines stood this far over their noise before"
    )
    min_sharpness: float = param(
        0.85, "", "and where they held this share of a comb four times wider's power (a rough clock smears them)"
    )
    combs: tuple[float, ...] = param(
        (0.0, 0.004),
        "of the line's frequency",
        "lines read narrowest first (0: 3 bins, what the window resolves): music beside a clean clock's lines is out",
    )
    max_continuum_excess_db: float = param(
        3.0, "dB", "judged only where the tuned stop moved the continuum no further than its level, plus this"
    )
    min_covered: float = param(
        0.5, "", "no verdict unless the sub-bands judged hold this share of the signature's sum of squares"
    )
    floor_share: float = param(0.01, "", "each side of a change is floored at this share of the larger (+-20 dB)")
    commanded_tol: float = param(0.03, "", "the rate is heard within this share of the commanded one (else taken)")
    told_held_tol: float = param(
        0.002,
        "of the told rate",
        "rate told: once a span offered to the model is heard this near it, its lines holding model_min_share in "
        "phase there (a clean clock), the clock is the told rate: the lines are read there, not at a line found "
        "nearer a fire (a 0.48 s span resolves 0.19 % at 1100 Hz; a crystal's stepping heard 0.08 % off at most; "
        "music, a stop in the reference pulled it 0.7-3.2 %; 0: not)",
    )
    max_rate_off: float = param(
        0.01, "", "not judged this far from the tuning's rate: the lines sample the arm's modes elsewhere (as the fit)"
    )
    affirm_window: float = param(
        0.25,
        "of the tuning's rate",
        "rate told: beyond max_rate_off and within this, the lines may affirm a stop; veto only unmoved (as the fit)",
    )
    min_moved_db: float = param(
        1.0,
        "dB",
        "rate told, off the tuning's: a fire whose lines in phase moved less (RMS) is not a stop (true stops: 2.4+)",
    )
    min_pred_moved_db: float = param(
        3.0,
        "dB",
        "no comb verdict there: unmoved lines veto where the stop predicted at the rate moves them this RMS (0: not)",
    )
    lines_model: bool = param(
        True,
        "",
        "rate told, off the tuning's: a fire is judged against the stepping's lines modelled across the listening, "
        "once ready; min_moved_db / min_pred_moved_db only until then (False: those always)",
    )
    model_tau_s: float = param(
        60.0, "s", "the model forgets stepping this long ago (outlives a song unheard; the joint's sound drifts slower)"
    )
    model_min_spans: float = param(
        4.0, "spans", "the model judges once it holds this weight of accepted stepping (a spread needs a few)"
    )
    model_floor_db: float = param(0.3, "dB", "the model's spread is floored at this (a few spans may agree by chance)")
    model_lag_s: float = param(
        2.5, "s", "a span is modelled this long after it ended: any fire over it judged first (window 2 s, gap, span)"
    )
    model_min_share: float = param(
        0.9,
        "",
        "a span is modelled where its lines held this share in phase (stepping alone: 0.97-1; speech, music less)",
    )
    model_expect: bool = param(
        True,
        "",
        "a span whose lines held under model_min_share in phase is modelled too where each line kept the share the "
        "followed clock's own wander predicts (a jittered clock; False: only the in-phase share gates)",
    )
    model_expect_min: float = param(
        0.9, "", "each line's share in phase over the share predicted from the clock's wander, at least this"
    )
    model_expect_c: float = param(
        0.2, "", "line k keeps exp(-c (2 pi k)^2 var) in phase, var the wander per frame (random walk within: 1/6)"
    )
    model_max_z: float = param(
        3.0, "spreads", "a fire whose lines after it sit within this RMS of the model is not a stop (the stepping's)"
    )
    model_min_bands: int = param(
        2,
        "sub-bands",
        "a fire the model reads within model_max_z on fewer locked sub-bands is not vetoed but flagged: one line's "
        "level, no RMS over the stop's signature (speech on it: a stop's pieces 0.6-7.3 spreads) (0: every veto)",
    )
    model_in_step: float = param(
        0.85,
        "of the model's share",
        "a fire the model let through whose lines held under this of the model's share in phase is flagged: the "
        "lines out of step (true stops 0.92 of it and more; music, speech 0.84 and less; 0: not)",
    )
    model_added_db: float = param(
        3.0,
        "dB",
        "and where their power out of phase rose this over the stepping's: added (music, speech +7.6 dB and more; "
        "a stop lowering its lines into the room's noise lowers the share, adds nothing: -2.4 dB and less)",
    )
    model_inside: bool = param(
        True,
        "",
        "a fire the model vetoed whose later pieces depart from it to the window's end: a stop found inside there",
    )
    model_max_spread_s: float = param(
        0.2,
        "s",
        "and the fit places that change within this (stops: 0.02-0.08 s; speech, music drifting: 0.34-0.82 s)",
    )
    model_edge_s: float = param(
        0.06,
        "s",
        "and its best split leaves this much of the fitted stretch after it: nearer its end the change lies at or "
        "past the end, not inside; dropped (stops found inside: 0.12 s and more; music, radio: 0.02-0.055 s; 0: not)",
    )
    model_hold_s: float = param(
        0.48,
        "s",
        "and its lines still depart from the model (model_max_z) in every piece over this long after the window's "
        "end: a stop holds while stepping goes on (stops: 7.2+), sound changes back (0.3-1.8); held till then (0: not)",
    )
    model_hold_piece_s: float = param(
        0.24, "s", "that hold is read in pieces this long, the least z kept (half a span: sound that changed back)"
    )
    model_in_step_hold_z: float = param(
        8.0,
        "spreads",
        "a fire flagged out of step (model_in_step) whose lines depart from the model by this in every piece over "
        "model_hold_s after its window is a stop, not flagged (held till then: the simulator's stops 16.9+; music 4.4)",
    )
    model_rejected: bool = param(
        True,
        "",
        "a fire the levels rejected whose window departs from the model (model_max_z) in every span, and still past "
        "it (model_hold_s), is a stop, flagged: its onset unknown (stops under music 6.6+; the hour's rejected none)",
    )
    model_refired: bool = param(
        True,
        "",
        "a window cut short by a refire is read as model_rejected reads a rejected one (stops under music 5.9+, past "
        "it 6.1+; the hour's joint 3: 7 of 109 departed, 3.1-7.2, all back past it, 0.3-1.7)",
    )
    model_rejected_early: bool = param(
        True,
        "",
        "before the model is ready, model_rejected reads a rejected window against the spans of stepping already "
        "offered that ended before its fire, model_min_spans of them counted (the lag: the rates bench's stops at 2 s)",
    )
    model_confirmed_early: bool = param(
        True,
        "",
        "before the model is ready, a stop confirmed is held model_hold_s past its window and read against every span "
        "offered before its onset (the stepping as heard, sound and all; model_min_spans counted): flagged where its "
        "lines came back within model_max_z (speech over the radio 0.80; the rates bench's right stops 5.0+)",
    )
    model_onset: bool = param(
        True,
        "",
        "rate told, off the tuning's, the model's lines place an onset as max_onset_off_s does at the rate: a stop "
        "found departed refitted over every departed piece, a confirmed stop the model read over two pieces either "
        "side; a change farther than that and its spread flags it (music's 0.49, drive's 0.15 s; stops 0-15 ms)",
    )
    model_onset_early: bool = param(
        True,
        "",
        "model_onset before the model is ready too (it has not read the fire): its lines, known from the first span, "
        "place the onset (the rates bench's stops come 2 s in, the model ready at about 5 s: never asked there)",
    )
    model_unjudged: bool = param(
        True,
        "",
        "rate told, off the tuning's: a stop the model did not read though it heard model_min_spans spans (their "
        "lines not the joint's alone) is flagged unless both readings reach min_affirm (False: counted)",
    )
    model_unjudged_early: bool = param(
        True,
        "",
        "model_unjudged before the model could be ready too, for a stop no reading of the lines judged at all (the "
        "per-fire vetoes gave no verdict): the levels alone counted it (False: not asked then)",
    )
    max_ref_stoplike: float = param(
        0.5, "", "not judged where more of the reference's frames were stop-like: a stop heard late began there"
    )
    onset_ref_stoplike: float = param(
        0.5, "", "a stop confirmed on a reference more stop-like, none kept, is flagged: it may begin there (1: not)"
    )
    onset_short_ref: bool = param(
        True, "", "a stop confirmed with under min_s of stepping heard before its fire is flagged (False: not)"
    )
    onset_short_span: bool = param(
        True,
        "",
        "onset_short_ref's bar the reference's own span (SyncParams.span_s) where the stream's start cut it short: "
        "a stop whose fire came before a whole reference was heard is flagged (sound changing 0.2-0.4 s into "
        "listening, 6 counted on the lines-model bench; False: min_s)",
    )
    kept_age_s: float = param(
        30.0, "s", "a reference stop-like to the levels is replaced by stepping kept no longer ago (0: none kept)"
    )
    kept_stoplike: float = param(
        0.1, "", "stepping is kept every span where at most this share of its frames was stop-like"
    )
    window_pieces: int = param(
        4, "spans", "a longer window is read in up to this many spans, the median a_L kept (music moves, a stop stays)"
    )
    locked_frame_s: float = param(
        0.02, "s", "the lines are read in phase with the clock followed, in frames this long (0: not; 20 steps)"
    )
    locked_harmonics: int = param(12, "lines", "the clock is followed on the step rate's first lines, this many")
    locked_slew: float = param(
        0.04, "cycles", "the followed clock moves at most this from frame to frame (a jittering step clock)"
    )
    locked_reacquire: float = param(
        1.5, "", "or jumps where the lines match this many times better (a burst restarted the clock's phase)"
    )
    locked_memory: float = param(
        0.05, "", "the followed clock's template and line powers take this share of each frame (about 20 frames)"
    )
    locked_grid: int = param(41, "offsets", "the clock's offsets tried within the slew each frame")
    locked_whole: int = param(100, "offsets", "and over the whole cycle, to re-acquire (0.01 cycles apart)")
    min_locked: float = param(
        0.5, "", "a sub-band is read in phase where its lines held this share of their power in phase before"
    )
    min_affirm: float = param(
        0.5, "", "a fire stop-like throughout but not hot is a stop where both readings reach this (a fan masks drops)"
    )
    onset_read_s: float = param(
        0.1, "s", "a stop's lines are read in phase this long from its onset: under min_a, it is doubted (0: not)"
    )
    min_s: float = param(0.2, "s", "not judged on less stepping before the fire (listening began near it)")
    min_after_s: float = param(0.1, "s", "nor on less of the window (a recording that ends sooner)")


CLOCKED = ClockedParams()


@dataclass(frozen=True)
class OnClock:
    """What the check measured on one fire."""

    #: the lines' stop-likeness (NaN: no verdict)
    a: float
    #: the step rate the lines were read at, Hz
    rate_hz: float
    #: the sub-bands judged
    bands: int
    #: how long before the fire's own reference the kept stepping it was judged against ended, s (NaN: its own)
    kept_s: float = math.nan
    #: the lines' stop-likeness read in phase with the clock followed (NaN: not read, or no verdict)
    locked: float = math.nan
    #: how far the lines in phase moved, whatever the signature: RMS over the sub-bands locked before, dB (NaN: not
    #: read; read only with the rate told, off the tuning's rate)
    moved_db: float = math.nan
    #: the lines after the fire against the stepping's modelled across the listening: RMS, in spreads (NaN: not read;
    #: read only with ``lines_model``, the rate told, off the tuning's rate)
    still_z: float = math.nan
    #: where the model read the fire and let it through (``still_z`` at least ``model_max_z``): the locked sub-bands'
    #: mean share of their lines' power in phase over the window's first piece, and the model's own over the stepping
    #: it modelled, and how far their power out of phase rose over the stepping's, dB (NaN: not read)
    in_step: float = math.nan
    model_share: float = math.nan
    added_db: float = math.nan


def lines_stop_likeness(
    before: FloatArray,
    after: FloatArray,
    sample_rate: float,
    rate_hz: float,
    edges_hz: Sequence[float],
    signature_db: Sequence[float],
    continuum_db: Sequence[float],
    p: ClockedParams = CLOCKED,
) -> tuple[float, int]:
    """The lines' stop-likeness ``a_L`` from ``before`` to ``after`` and the number of sub-bands judged.

    Parameters
    ----------
    before, after : array
        The stepping before the fire and the window after it (samples; the longer is cut to the shorter: ``before``
        keeps its end, ``after`` its start).
    sample_rate : float
        Samples per second, Hz.
    rate_hz : float
        The step rate whose harmonic lines are read, Hz.
    edges_hz, signature_db : sequence of float
        The sub-bands' edges (Hz, one more than sub-bands) and the stop's signature on them (dB per sub-band).
    continuum_db : sequence of float
        The tuned stop's change of the continuum between the lines, dB per sub-band: where it moved further in the
        stop's direction than the level did (by ``max_continuum_excess_db``), the stop's change was off the lines
        (a stop that rattles out of step) and the sub-band is not judged.
    p : ClockedParams
        The check's parameters.

    Returns
    -------
    (float, int)
        ``a_L`` (dimensionless: 1 a stop like the tuned one on the lines, 0 no change on them; NaN where no sub-band
        was judged) and how many sub-bands were judged.
    """
    judged, whole = _judged(signature_db, continuum_db, p)
    bands = [(float(edges_hz[i]), float(edges_hz[i + 1])) for i in judged]
    if not bands:
        return math.nan, 0
    n = min(before.size, after.size)
    b, a = before[before.size - n :], after[:n]
    pb, pa = periodogram(b), periodogram(a)  # one spectrum a side, read on every comb
    reads = [_comb_read(pb, pa, sample_rate, rate_hz, bands, tol) for tol in p.combs]
    num = den = 0.0
    used = 0
    for j, i in enumerate(judged):
        delta = float(signature_db[i])
        held = reads[-1][j]  # the widest comb, which holds all of a line's power
        if not held[0] > p.min_line_z * math.sqrt(held[2]):
            continue  # no lines heard there before the fire (a narrower comb finds no line that this one misses)
        for p0, p1, var, wide in (r[j] for r in reads):
            if not p0 > p.min_line_z * math.sqrt(var):
                continue  # too few of the line's bins on this comb
            if not p0 >= p.min_sharpness * wide:
                continue  # the lines are wider than this comb (a rough clock; sound beside them): a wider one
            num += delta * _change_db(p0, p1, p.floor_share)
            den += delta**2
            used += 1
            break
    if den == 0.0 or den < p.min_covered * whole:
        return math.nan, used
    return num / den, used


def _change_db(p0: float, p1: float, floor_share: float) -> float:
    """The change from power ``p0`` to ``p1``, dB, each side floored at ``floor_share`` of the larger."""
    top = max(p0, p1) * floor_share
    return 10.0 * math.log10(max(p1, top) / max(p0, top))


def _judged(signature_db: Sequence[float], continuum_db: Sequence[float], p: ClockedParams) -> tuple[list[int], float]:
    """The sub-bands the check judges (the tuned stop moved them, on the lines) and the signature's sum of squares
    over every sub-band it moved, dB^2."""
    moved = [i for i, delta in enumerate(signature_db) if abs(delta) >= p.min_signature_db]
    whole = sum(float(signature_db[i]) ** 2 for i in moved)
    if len(continuum_db) != len(signature_db):
        return [], whole
    on = [
        math.copysign(1.0, d) * c <= abs(d) + p.max_continuum_excess_db
        for d, c in zip(signature_db, continuum_db, strict=True)
    ]
    return [i for i in moved if on[i]], whole  # the tuned stop's change was on the lines there


def turned_frames(
    x: FloatArray, sr: float, rate_hz: float, ks: Sequence[int], p: ClockedParams = CLOCKED
) -> ComplexArray:
    """The lines ``ks`` of ``x`` demodulated in frames of ``locked_frame_s`` and turned by the clock followed
    (frames x lines): the joint's lines keep one phasor from frame to frame, sound of another clock turns."""
    z, off = _followed(x, sr, rate_hz, ks, p)
    k = np.asarray(ks, dtype=np.float64)
    return np.asarray(z * np.exp(-2j * np.pi * np.outer(off, k)), dtype=np.complex128)


def _followed(
    x: FloatArray, sr: float, rate_hz: float, ks: Sequence[int], p: ClockedParams
) -> tuple[ComplexArray, FloatArray]:
    """The lines ``ks`` of ``x`` demodulated in frames of ``locked_frame_s`` (frames x lines) and the clock followed
    through the first ``locked_harmonics`` lines: its phase offset per frame, in periods."""
    clock = [k for k in range(1, p.locked_harmonics + 1) if k * rate_hz < sr / 2]
    both = sorted(set(clock) | set(ks))
    z = demodulate(x, sr, rate_hz, both, max(1, int(round(p.locked_frame_s * sr))))
    off = follow_clock(z[:, [both.index(k) for k in clock]], clock, p.locked_slew, p.locked_reacquire,
                       p.locked_memory, p.locked_grid, p.locked_whole)  # fmt: skip
    return z[:, [both.index(k) for k in ks]], off


def _in_phase(
    x: FloatArray, sr: float, rate_hz: float, ks: list[int], p: ClockedParams
) -> tuple[FloatArray, FloatArray]:
    """Per line ``ks``: the power in phase with the clock followed over ``x``, and the power in all."""
    z, off = _followed(x, sr, rate_hz, ks, p)
    return locked_powers(z, ks, off)


def expected_held(x: FloatArray, sr: float, rate_hz: float, ks: list[int], p: ClockedParams) -> float:
    """The least over the lines ``ks`` of the share of each line's power held in phase over ``x`` against the share a
    clock wandering as the followed one did would leave it: ``exp(-c (2 pi k)^2 var)``, ``var`` the variance of the
    followed clock's offset from frame to frame (cycles^2; robust: the median square over 0.455), ``c``
    ``model_expect_c``. Stepping alone on a jittered clock: about 1; sound of another kind on a line lowers it
    (NaN: no frames or no power)."""
    z, off = _followed(x, sr, rate_hz, ks, p)
    if off.size < 2:
        return math.nan
    held, whole = locked_powers(z, ks, off)
    d = (np.diff(off) + 0.5) % 1.0 - 0.5
    var = float(np.median(d**2)) / 0.455
    k = np.asarray(ks, dtype=np.float64)
    expected = np.exp(-p.model_expect_c * (2.0 * np.pi * k) ** 2 * var)
    if not np.all(whole > 0.0):
        return math.nan
    return float(np.min(held / whole / np.maximum(expected, 1e-9)))


def locked_stop_likeness(
    before: FloatArray,
    pieces: Sequence[FloatArray],
    sample_rate: float,
    rate_hz: float,
    edges_hz: Sequence[float],
    signature_db: Sequence[float],
    continuum_db: Sequence[float],
    p: ClockedParams = CLOCKED,
) -> float:
    """The lines' stop-likeness read in phase with the steps' clock, followed from the sound (:mod:`.lockin`).

    As :func:`lines_stop_likeness`, on the same sub-bands, but each line's power is the power in phase with the
    clock followed over each stretch, ``before`` and every piece of the window alike: a note on or beside a line
    is not in phase with the steps and adds little, a stop changes the steps' own sound and all of it is in
    phase. A sub-band is read where its lines held ``min_locked`` of their power in phase before; no verdict (NaN)
    where those hold less than ``min_covered`` of the signature's sum of squares. The median over the pieces.
    """
    reader = locked_reader(before, sample_rate, rate_hz, edges_hz, signature_db, continuum_db, p)
    if reader is None:
        return math.nan
    return float(np.median([reader.read(x) for x in pieces]))


@dataclass(frozen=True)
class LockedReader:
    """What :func:`locked_stop_likeness` reads of one stretch against the stepping, that read once."""

    #: the lines' stop-likeness in phase over a stretch of samples (dimensionless)
    read: Callable[[FloatArray], float]
    #: the lines read (multiples of the rate), in the sub-bands whose lines were locked before
    lines: tuple[int, ...]


def locked_reader(
    before: FloatArray,
    sample_rate: float,
    rate_hz: float,
    edges_hz: Sequence[float],
    signature_db: Sequence[float],
    continuum_db: Sequence[float],
    p: ClockedParams = CLOCKED,
) -> LockedReader | None:
    """What :func:`locked_stop_likeness` reads of one stretch against ``before``, ``before`` read once (None: no
    verdict on any stretch)."""
    judged, whole = _judged(signature_db, continuum_db, p)
    lk = _locked_bands(before, sample_rate, rate_hz, edges_hz, judged, p)
    if lk is None:
        return None
    den = sum(float(signature_db[i]) ** 2 for i in lk.keep)
    if den == 0.0 or den < p.min_covered * whole:
        return None

    def read(x: FloatArray) -> float:
        l1, _ = _in_phase(x, sample_rate, rate_hz, lk.ks, p)
        num = 0.0
        for i in lk.keep:
            num += float(signature_db[i]) * _change_db(lk.held(lk.l0, i), lk.held(l1, i), p.floor_share)
        return num / den

    return LockedReader(read, tuple(k for i in lk.keep for k in lk.lines[i]))


@dataclass(frozen=True)
class _Locked:
    """The lines of each sub-band read in phase over the stepping, and the sub-bands whose lines were locked."""

    ks: list[int]  #: every line read (multiples of the rate), in order
    lines: dict[int, list[int]]  #: each sub-band's lines
    l0: FloatArray  #: the lines' power in phase over the stepping
    keep: list[int]  #: the sub-bands whose lines held ``min_locked`` of their power in phase

    def held(self, v: FloatArray, i: int) -> float:
        """The power ``v`` (one value per line of :attr:`ks`) summed over sub-band ``i``'s lines."""
        return sum(float(v[self.ks.index(k)]) for k in self.lines[i])


def _locked_bands(
    before: FloatArray,
    sample_rate: float,
    rate_hz: float,
    edges_hz: Sequence[float],
    bands: Sequence[int],
    p: ClockedParams,
) -> _Locked | None:
    """The lines of the sub-bands ``bands`` read in phase over ``before`` (None: no line, or no in-phase reading)."""
    lines = {
        i: [k for k in range(1, int(sample_rate / 2 / rate_hz) + 1) if edges_hz[i] <= k * rate_hz < edges_hz[i + 1]]
        for i in bands
    }
    ks = sorted({k for v in lines.values() for k in v})
    if not ks or p.locked_frame_s <= 0.0:
        return None
    l0, w0 = _in_phase(before, sample_rate, rate_hz, ks, p)
    every = _Locked(ks, lines, l0, list(bands))
    held = every.held
    return _Locked(ks, lines, l0, [i for i in bands if held(w0, i) > 0.0 and held(l0, i) >= p.min_locked * held(w0, i)])


def lines_moved_db(
    before: FloatArray,
    pieces: Sequence[FloatArray],
    sample_rate: float,
    rate_hz: float,
    edges_hz: Sequence[float],
    p: ClockedParams = CLOCKED,
) -> float:
    """How far the joint's lines moved, whatever the stop's signature: the RMS over the sub-bands whose lines held
    ``min_locked`` of their power in phase over ``before`` of their change in phase (dB, floored as
    :func:`_change_db`), the median over the ``pieces``; NaN where no sub-band's lines were locked.

    The tuned signature may not be what a stop does on the lines at another rate (they sample the arm's narrow
    modes elsewhere), but a stop changes the joint's own clicks, so it moves its lines somewhere; sound added
    between them, out of step with the clock, leaves them in phase as they were (the step rate told: the
    controller's clock).
    """
    if not pieces:
        return math.nan
    lk = _locked_bands(before, sample_rate, rate_hz, edges_hz, range(len(edges_hz) - 1), p)
    if lk is None or not lk.keep:
        return math.nan
    changes = []
    for x in pieces:
        l1, _ = _in_phase(x, sample_rate, rate_hz, lk.ks, p)
        changes.append([_change_db(lk.held(lk.l0, i), lk.held(l1, i), p.floor_share) for i in lk.keep])
    d = np.median(np.asarray(changes, dtype=np.float64), axis=0)
    return float(np.sqrt(np.mean(d**2)))


def _comb_read(
    b: Periodogram, a: Periodogram, sr: float, rate_hz: float, bands: list[tuple[float, float]], tol: float
) -> list[tuple[float, float, float, float]]:
    """Per band, on a comb of half-width ``tol`` of each line's frequency (at least 3 bins): the lines' power before
    and after, its noise's variance before, and the power before on a comb ``sharp_width`` times wider (NaN: none)."""
    comb = StepClockParams(comb_tol=tol)
    lb, _ = line_powers(b, sr, rate_hz, bands, params=comb)
    la, _ = line_powers(a, sr, rate_hz, bands, params=comb)
    lw, _ = line_powers(b, sr, rate_hz, bands, STEP_CLOCK.sharp_width, params=comb)
    nan = (math.nan,) * 4
    if not lb.power.size == la.power.size == lw.power.size:
        return [nan for _ in bands]
    out = []
    for j in range(len(bands)):
        on = lb.band == j
        sums = tuple(float(np.sum(v[on])) for v in (lb.power, la.power, lb.var, lw.power))
        out.append((sums[0], sums[1], sums[2], sums[3]) if on.any() else nan)
    return out


def lines_at(tuning: Tuning, rate: float, p: ClockedParams) -> SteppingLines | None:
    """An empty model of the stepping's lines read at ``rate`` (Hz): per tuned sub-band, the lines in it (None: none
    in any)."""
    sr, edges = float(tuning.sample_rate), tuning.edges_hz
    assert edges is not None
    top, bands = int(sr / 2 / rate), range(len(edges) - 1)
    lines = {i: [k for k in range(1, top + 1) if edges[i] <= k * rate < edges[i + 1]] for i in bands}
    lines = {i: v for i, v in lines.items() if v}
    if not lines:
        return None
    ks = sorted({k for v in lines.values() for k in v})

    def in_phase(y: FloatArray, r: float = rate, ks: list[int] = ks) -> tuple[FloatArray, FloatArray]:
        return _in_phase(y, sr, r, ks, p)

    return SteppingLines(in_phase, lines, ks, p.model_tau_s, p.min_locked)


def in_step_at(x: FloatArray, tuning: Tuning, rate: float, p: ClockedParams) -> bool:
    """Whether the lines of ``x`` read at ``rate`` (Hz) held ``model_min_share`` of their power in phase, over the
    tuned sub-bands (stepping alone on a clock in step with that rate; a rough clock smears them, 0.5-0.6)."""
    m = lines_at(tuning, rate, p)
    return m is not None and float(np.mean(m.levels(x)[1])) >= p.model_min_share


class ClockedCheck:
    """The check over a stream: the stepping before a chain of fires, then each window (see the module)."""

    def __init__(self, tuning: Tuning, p: ClockedParams = CLOCKED) -> None:
        self.tuning, self.p = tuning, p
        self.enabled = (
            tuning.method == "template"
            and tuning.signature_db is not None
            and tuning.edges_hz is not None
            and tuning.continuum_signature_db is not None
        )
        self.sample_rate = int(tuning.sample_rate)
        self._predictor: SignaturePredictor | None = None  # built at the first fire that needs it
        self.reset()

    def reset(self, commanded_hz: float | None = None) -> None:
        #: the stepping before the fire that began the current chain
        self.ref: FloatArray | None = None
        #: the share of its frames that were stop-like (NaN: none measured)
        self.ref_stoplike = math.nan
        #: the stepping kept for a reference stop-like to the levels: (its end, absolute sample; its samples)
        self.kept: list[tuple[int, FloatArray]] = []
        #: how long before the current chain's own reference the kept stepping taken for it ended, s (NaN: its own)
        self.ref_age_s = math.nan
        self.commanded_hz = commanded_hz
        #: the stepping's lines modelled across the listening (``lines_model``; None: none yet)
        self.model: SteppingLines | None = None
        self.model_hz = math.nan  # the step rate the model reads the lines at, Hz
        self.model_n = 0  # the samples of each stretch it modelled
        #: the spans read but not yet modelled (``model_lag_s``): their ends, s, levels and locked shares
        self.pending: list[tuple[float, FloatArray, FloatArray, bool]] = []
        #: where the first ``model_min_spans`` spans offered to the model ended (absolute samples)
        self.offered: list[int] = []
        self.held = False  #: the clock heard at the told rate (``told_held_tol``): the lines read there

    def keep(self, end: int, samples: FloatArray, margins: FloatArray) -> None:
        """A stretch of the stream ending at absolute sample ``end`` and its frames' margins: kept as stepping where
        every frame was heard and at most ``kept_stoplike`` of them were stop-like (the latest few are kept)."""
        if self.p.kept_age_s <= 0.0 or not margins.size:
            return
        quiet = bool(np.all(np.isfinite(margins))) and float(np.mean(margins >= 0.0)) <= self.p.kept_stoplike
        if quiet:
            self.kept = [*self.kept[-7:], (end, np.array(samples, dtype=np.float64))]
        if self.models_lines():
            if len(self.offered) < math.ceil(self.p.model_min_spans):
                self.offered.append(end)
            self.model_stepping(end, np.asarray(samples, dtype=np.float64))

    def models_lines(self) -> bool:
        """Whether the stepping's lines are modelled across the listening: ``lines_model``, the rate told, off the
        tuning's rate (beyond ``max_rate_off``, within ``affirm_window``)."""
        p, told, tuned = self.p, self.commanded_hz, self.tuning.step_rate_hz
        if not (p.lines_model and self.enabled and told is not None and tuned is not None):
            return False
        return p.max_rate_off < abs(told / tuned - 1.0) <= p.affirm_window

    def model_stepping(self, end: int, x: FloatArray) -> None:
        """A span of the stream, ``x`` ending at absolute sample ``end``, into the model of the stepping's lines where
        it is stepping accepted, ``model_lag_s`` after it ended (a fire over it is judged against the model as it
        stood before): its lines held ``model_min_share`` of their power in phase (the joint's clicks alone; sound
        of another clock lowers it), or with ``model_expect`` each line the share the clock's own wander leaves it
        (:func:`expected_held`), and, once the model judges, sat within ``model_max_z`` of it (the stepping going
        on; a stop moves them). Not one heard at another rate than the model's first."""
        sr, p, tu = self.sample_rate, self.p, self.tuning
        assert self.commanded_hz is not None and tu.edges_hz is not None
        rate = self.hear_held(x)
        if not math.isfinite(rate):
            return
        if self.model is not None and (abs(rate / self.model_hz - 1.0) > p.max_rate_off or x.size != self.model_n):
            return  # not stepping at the model's rate (the rate is told: the stepping's is the first heard)
        if self.model is None:
            self.model = lines_at(tu, rate, p)
            if self.model is None:
                return
            self.model_hz, self.model_n = rate, x.size
        level, share = self.model.levels(x)
        alone = float(np.mean(share)) >= p.model_min_share or (
            p.model_expect and expected_held(x, sr, self.model_hz, self.model.ks, p) >= p.model_expect_min
        )
        self.pending = [*self.pending, (end / sr, level, share, alone)]
        while self.pending and self.pending[0][0] <= end / sr - p.model_lag_s:  # any fire over it judged by now
            t, level, share, alone = self.pending.pop(0)
            if not alone:
                continue  # sound of another clock on the lines: not the stepping's alone
            if not self.model_ready() or self.model.z_of(level, p.model_min_spans, p.model_floor_db) < p.model_max_z:
                self.model.add(level, share, t)

    def hear_held(self, x: FloatArray) -> float:
        """A span of stepping ``x``'s rate, Hz (NaN: none): the told one once heard within ``told_held_tol`` of it,
        in step there (:func:`in_step_at`; :attr:`held`: a model built off it is built again), else the line heard."""
        told, tol, p = self.commanded_hz, self.p.told_held_tol, self.p
        assert told is not None
        rate = rate_near_hz(x, self.sample_rate, told, p.commanded_tol)
        if tol > 0.0 and not self.held and abs(rate / told - 1.0) <= tol:
            self.held = in_step_at(x, self.tuning, told, p)
            if self.held and self.model is not None and abs(self.model_hz / told - 1.0) > tol:
                self.model, self.model_hz, self.model_n, self.pending = None, math.nan, 0, []
        return told if self.held else rate

    def unjudged(self, at: int, got: OnClock | None) -> bool:
        """Whether a stop confirmed at absolute sample ``at`` (its onset), its fire judged ``got``, stands on the
        levels alone off the tuning's rate (``model_unjudged``): the rate told, the model offered ``model_min_spans``
        spans that ended ``model_lag_s`` before it (it could have been ready), yet it did not read the fire (not
        ready: the lines held under ``model_min_share`` in phase, sound of another kind on them; or nothing read),
        and the lines do not affirm it (:meth:`affirms`) against the stepping just before its fire (an affirmation
        against stepping kept from long before says a stop, not that it began there). Earlier in the listening no
        model can judge: there (``model_unjudged_early``) only a stop no reading of the lines judged at all
        (``got`` None: the per-fire vetoes gave no verdict) is flagged, not one at the start of listening."""
        p = self.p
        n = math.ceil(p.model_min_spans)
        if not (p.model_unjudged and self.models_lines()):
            return False
        if len(self.offered) < n or self.offered[n - 1] > at - p.model_lag_s * self.sample_rate:
            return p.model_unjudged_early and got is None and at > 0  # too early for a model: nothing read the lines
        if got is not None and math.isfinite(got.still_z):
            return False  # the model read it (and let it through: it departs from the stepping's lines)
        return not (self.affirms(got) and got is not None and not math.isfinite(got.kept_s))

    def model_ready(self) -> bool:
        """Whether the model holds ``model_min_spans`` (weight) of stepping: until then the per-fire vetoes judge."""
        return self.model is not None and self.model.weight >= self.p.model_min_spans

    def model_vetoed(self, got: OnClock | None) -> bool:
        """Whether the fire judged ``got`` was vetoed by the stepping's lines modelled (a piece within
        ``model_max_z``)."""
        return got is not None and not self.at_tuned_rate(got.rate_hz) and got.still_z < self.p.model_max_z

    def model_z(self, after: FloatArray, a: float = math.nan) -> float:
        """The lines after the fire against the stepping's modelled: RMS in spreads, the least over up to
        ``window_pieces`` stretches as long as those modelled (NaN: no model, too little in it, under
        ``min_after_s`` of window, or where the comb gave no verdict ``a`` and the stop predicted at the rate
        moves the model's locked sub-bands under ``min_pred_moved_db``: as the per-fire vetoes, what the lines
        cannot show is not read)."""
        p, n = self.p, self.model_n
        if self.model is None or n <= 0 or after.size < p.min_after_s * self.sample_rate:
            return math.nan  # (a window cut by the stream's end is read whole: its level noisier, a veto rarer)
        if not math.isfinite(a):  # no comb verdict: read only where the stop predicted at the rate moves the lines
            pred = self.predicted_moved_db(self.model_hz, self.model.locked_bands())
            if not (p.min_pred_moved_db > 0.0 and pred >= p.min_pred_moved_db):
                return math.nan  # (a stop whose change lies off the lines read leaves them as the stepping's)
        pieces = [after[k * n : (k + 1) * n] for k in range(max(1, min(p.window_pieces, after.size // n)))]
        return self.model.z(pieces, p.model_min_spans, p.model_floor_db)

    def in_step_reading(self, after: FloatArray, z: float) -> tuple[float, float, float]:
        """Where the model read the fire and let it through (``z`` at least ``model_max_z``): the window's first
        piece's share in phase, the model's own mean share, and the power out of phase added, dB (``OnClock.in_step``,
        ``model_share``, ``added_db``; :meth:`.stepping_lines.SteppingLines.in_step`; NaN: not read)."""
        if self.model is None or not z >= self.p.model_max_z:
            return math.nan, math.nan, math.nan
        return self.model.in_step(after[: self.model_n])

    def hear_before(self, ref: FloatArray, margins: FloatArray, end: int | None = None) -> None:
        """The stepping before a fire (samples, ending at absolute sample ``end``) and its frames' margins over the
        threshold (NaN while learning). Where more than ``max_ref_stoplike`` of them were stop-like, the latest
        stepping kept that ended by then, no more than ``kept_age_s`` before, is the reference instead."""
        m = margins[np.isfinite(margins)]
        self.ref, self.ref_age_s = ref, math.nan
        self.ref_stoplike = float(np.mean(m >= 0.0)) if m.size else math.nan
        if end is None or not self.ref_stoplike > self.p.max_ref_stoplike:
            return
        oldest = end - self.p.kept_age_s * self.sample_rate
        got = [(e, v) for e, v in self.kept if oldest <= e <= end]
        if got:
            kept_end, self.ref = got[-1]
            self.ref_age_s, self.ref_stoplike = (end - kept_end) / self.sample_rate, 0.0

    def judge(self, after: FloatArray, heard_hz: float = math.nan, affirm: bool = False) -> OnClock | None:
        """The lines' stop-likeness from the stepping to the window's first samples ``after`` (None: not judged).

        ``heard_hz``: the step rate already heard in the same stepping (the pause check's, Hz; NaN: none), taken
        where it is within ``commanded_tol`` of the commanded rate or none was commanded, else heard again near it.
        ``affirm``: read for an affirmation only (:meth:`affirms`), with the rate told also at another rate
        (``affirm_window``). With the rate told and ``min_moved_db`` over 0, read there for a veto too, on how far
        the lines moved (``moved_db``; where the comb judged the tuned sub-bands) and nothing else."""
        sr, p, ref = self.sample_rate, self.p, self.ref
        if not self.enabled or after.size < p.min_after_s * sr:
            return None
        modelled = not affirm and self.models_lines() and self.model_ready()  # against the stepping's lines modelled
        if ref is None or ref.size < p.min_s * sr or self.ref_stoplike > p.max_ref_stoplike:
            # too little stepping before the fire, or the stop may have begun there (heard late): the model only
            z = self.model_z(after) if modelled else math.nan
            s, s0, added = self.in_step_reading(after, z)
            on = OnClock(math.nan, self.model_hz, 0, still_z=z, in_step=s, model_share=s0, added_db=added)
            return on if math.isfinite(z) else None
        rate = self.rate(heard_hz, affirm or self.commanded_hz is not None)
        if not math.isfinite(rate) or not (affirm or self.at_tuned_rate(rate) or p.min_moved_db > 0.0):
            return None
        tu = self.tuning
        assert tu.edges_hz is not None and tu.signature_db is not None and tu.continuum_signature_db is not None
        n = ref.size
        pieces = [after[k * n : (k + 1) * n] for k in range(max(1, min(p.window_pieces, after.size // n)))]
        got = [
            lines_stop_likeness(ref, x, sr, rate, tu.edges_hz, tu.signature_db, tu.continuum_signature_db, p)
            for x in pieces
        ]
        a, used = got[0]
        finite = [g[0] for g in got if math.isfinite(g[0])]
        if len(got) > 1 and finite:
            a = float(np.median(finite))
        veto_off = not affirm and not self.at_tuned_rate(rate)  # read for the lines' moving alone
        if veto_off and modelled:
            reader = self.reader(rate) if math.isfinite(a) else None
            locked = math.nan if reader is None else float(np.median([reader.read(x) for x in pieces]))
            z = self.model_z(after, a)
            s, s0, added = self.in_step_reading(after, z)
            on = OnClock(a, rate, used, self.ref_age_s, locked, math.nan, z, s, s0, added)  # (moved_db: not read)
            return on if math.isfinite(a) or math.isfinite(z) else None
        unjudged = veto_off and not math.isfinite(a)
        predicted = unjudged and p.min_pred_moved_db > 0.0 and self.predicted_moved_db(rate) >= p.min_pred_moved_db
        if unjudged and not predicted:
            return None  # the comb could not judge the tuned stop's sub-bands here, nor says the prediction they move
        reader = self.reader(rate)
        locked = math.nan if reader is None else float(np.median([reader.read(x) for x in pieces]))
        moved = math.nan
        if not self.at_tuned_rate(rate) and p.min_moved_db > 0.0 and (math.isfinite(a) or predicted):  # off-rate
            moved = lines_moved_db(ref, pieces, sr, rate, tu.edges_hz, p)
        return OnClock(a, rate, used, self.ref_age_s, locked, moved)

    def predicted_moved_db(self, rate_hz: float, bands: Sequence[int] | None = None) -> float:
        """How far the stop, as predicted at ``rate_hz`` (Hz) from the tuning's fine continuum, moves the sub-bands
        ``bands`` (None: those whose lines were locked in the reference): RMS of the predicted signature over them,
        dB (NaN: no prediction, no reference or no sub-band locked)."""
        tu, ref = self.tuning, self.ref
        if self._predictor is None:
            self._predictor = signature_predictor(tu)  # None: the tuning holds no fine continuum (made before it)
        if self._predictor is None or tu.edges_hz is None:
            return math.nan
        if bands is None:
            lk = None if ref is None else _locked_bands(ref, self.sample_rate, rate_hz, tu.edges_hz,
                                                        range(len(tu.edges_hz) - 1), self.p)  # fmt: skip
            bands = [] if lk is None else lk.keep
        if not bands:
            return math.nan
        pred = self._predictor.predict(rate_hz)
        return float(np.sqrt(np.mean(pred[list(bands)] ** 2)))

    def reader(self, rate_hz: float) -> LockedReader | None:
        """The lines read in phase with the clock followed at ``rate_hz`` (Hz) against the reference (the chain's
        stepping), as the tuning's signature judges them (:func:`locked_reader`; None: no reference, or no verdict)."""
        tu, ref = self.tuning, self.ref
        if ref is None:
            return None
        assert tu.edges_hz is not None and tu.signature_db is not None and tu.continuum_signature_db is not None
        sig, cont = tu.signature_db, tu.continuum_signature_db
        return locked_reader(ref, self.sample_rate, rate_hz, tu.edges_hz, sig, cont, self.p)

    def at_tuned_rate(self, rate_hz: float) -> bool:
        """Whether ``rate_hz`` (Hz) is within ``max_rate_off`` of the tuning's rate: the lines may veto there."""
        tuned = self.tuning.step_rate_hz
        return tuned is not None and math.isfinite(rate_hz) and abs(rate_hz / tuned - 1.0) <= self.p.max_rate_off

    def rate(self, heard_hz: float = math.nan, affirm: bool = False) -> float:
        """The step rate the lines are read at, Hz (NaN: not judged): ``heard_hz`` (the step rate already heard in the
        reference, Hz) where it is within ``commanded_tol`` of the commanded rate or none was commanded, else heard
        again near it (the told rate itself once the clock was heard there: :attr:`held`); not judged where that is
        more than ``max_rate_off`` from the tuning's rate or unknown (with ``affirm`` and the rate told,
        ``affirm_window``: an affirmation only)."""
        p, ref, told = self.p, self.ref, self.commanded_hz
        if ref is None:
            return math.nan
        if self.held and told is not None:  # the clock heard at the told rate: a line found off it is sound's
            rate = told
        elif math.isfinite(heard_hz) and (told is None or abs(heard_hz / told - 1.0) <= p.commanded_tol):
            rate = heard_hz
        else:
            rate = rate_near_hz(ref, self.sample_rate, told, p.commanded_tol)
        tuned = self.tuning.step_rate_hz
        off = p.max_rate_off
        if affirm and told is not None:
            off = max(off, p.affirm_window)
        if tuned is None or not (math.isfinite(rate) and abs(rate / tuned - 1.0) <= off):
            return math.nan
        return float(rate)

    def verdict(self, got: OnClock | None) -> bool:
        """False where the change is off the clock, on the lines or in phase with the clock followed; True where
        it is on it or nothing was judged."""
        if got is None:
            return True
        if not self.at_tuned_rate(got.rate_hz):
            # at another rate the tuned signature is not what the stop does on the lines: no veto on it; but lines that
            # did not move (the rate told: the controller's clock) or stay within the model's spread are the stepping's
            within = got.still_z < self.p.model_max_z and not model_thin(self, got)  # (thin: flagged, not vetoed)
            return not got.moved_db < self.p.min_moved_db and not within  # NaN: no veto
        return all(not math.isfinite(a) or a >= self.p.min_a for a in (got.a, got.locked))

    def affirms(self, got: OnClock | None) -> bool:
        """True only where both readings were made and reach ``min_affirm``: the stop's own change on the lines and
        in phase with the steps (a fire the levels cannot confirm: added sound masks the stop's drops)."""
        return got is not None and all(math.isfinite(a) and a >= self.p.min_affirm for a in (got.a, got.locked))

    def at_onset(self, x: FloatArray, got: OnClock | None) -> float:
        """The lines' stop-likeness read in phase over ``x``, the first ``onset_read_s`` from a stop's onset, against
        the same stepping, at the rate its fire was judged at (``got``; NaN: not read, or no verdict). Read only where
        the comb judged the fire too (its lines sharp: a clean clock); over a rough clock so short a reading scatters
        (the modal generator: -0.01 and 0.07 at stops whose windows read 0.53-0.92 in phase)."""
        p = self.p
        if got is None or not math.isfinite(got.a) or p.onset_read_s <= 0.0 or not self.at_tuned_rate(got.rate_hz):
            return math.nan
        if x.size < round(p.onset_read_s * self.sample_rate):
            return math.nan
        reader = self.reader(got.rate_hz)
        return math.nan if reader is None else reader.read(x)


def model_thin(check: ClockedCheck, got: OnClock | None) -> bool:
    """Whether ``check``'s model of the stepping's lines read the fire ``got`` within ``model_max_z`` on fewer than
    ``model_min_bands`` locked sub-bands: a veto it cannot carry (one line's level, not an RMS over the stop's
    signature; sound on that line scatters it either way), so the fire is not vetoed but flagged
    (:meth:`.checks.WindowChecks.onset_doubt`)."""
    m, p = check.model, check.p
    if m is None or got is None or check.at_tuned_rate(got.rate_hz) or not got.still_z < p.model_max_z:
        return False
    return len(m.locked_bands()) < p.model_min_bands
