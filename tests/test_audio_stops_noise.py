"""A stop confirmed with no stepping heard before it to place it by is flagged (issue 35 item 6).

The tenth generator's arm 1 (``tests/support/fan_sound.py``) steps at 1200 Hz, told (the tuning's
rate: 1000 Hz), into its stop at 12 s under the hour's speech over a radio at +3 dB to the
stepping (``tests/support/hour_sound.py``), as ``benchmarks/bench_audio_stops_noise.py`` renders it.
A fire 0.57 s before the stop is confirmed, flagged (the stop came in its window), and the fast
path fires again 1.48 s into the stop: the stepping before that fire is the stop itself (over half
its frames stop-like, no stepping kept), so the detector cannot know where the stop began. Before
``ClockedParams.onset_ref_stoplike`` it was a confirmed stop 1.48 s late, unflagged. With the stepping's lines
modelled (``lines_model``) the fire 0.57 s before the stop is vetoed and the stop found inside its window
(``tests/test_audio_stops_departed.py``); the fire 1.48 s into the stop is still heard after it.
The model reads that fire and lets it through; its lines hold 0.79 in phase against the model's 0.95, with 3.6 dB
added out of phase (the stop's stepping under the speech, read against the stepping's): ``model_in_step`` flags it
too where ``onset_ref_stoplike`` does not. With the hold past the window of a stop found departed
(``model_hold_s``, on by default) the fast path stays held on that stop until 13.94 s and the fire at 13.48 s is not
heard: the hold is off here, to keep the fire these two rules judge. The model's lines place a change 140 ms before
that fire's onset, inside the stop (``model_onset``): it flags the late count too, and is off where neither rule is.
"""

from __future__ import annotations

from dataclasses import replace

from fan_sound import SR, Arm, render, tuning_scene
from noise_bench import recording
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedParams
from stickslip.audio.confirm.onset import ONSET
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

STOP_S, RATE = 12.0, 1200.0


def _heard(
    onset_ref_stoplike: float, in_step: float = ClockedParams().model_in_step, onset: bool = True
) -> tuple[list[StopEvent], list[tuple[float, str]]]:
    arm = 1
    tu = tune(render(tuning_scene(Arm(arm))), SR, 2.0)
    y = recording(arm, RATE, "speech over the radio", 3.0)
    # (model_hold_s off: with it the fast path is held on the stop found inside until its lines are read past the
    # window, 13.94 s, and the fire at 13.48 s these rules judge is not heard)
    clocked = ClockedParams(
        onset_ref_stoplike=onset_ref_stoplike, model_in_step=in_step, model_hold_s=0.0, model_onset=onset
    )
    p = ConfirmParams(clocked=clocked, onset=replace(ONSET, break_check=False))  # (it flags the late one too)
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(y) + det.finish(), det.log.onset


def test_a_stop_confirmed_on_a_stoplike_reference_with_none_kept_is_flagged() -> None:
    before, _ = _heard(1.0, 0.0, False)  # not flagged so: the silently late count
    after, why = _heard(ClockedParams().onset_ref_stoplike)
    assert [round(e.onset_s, 2) for e in before] == [12.01, 13.48]  # the first: found inside the vetoed window
    assert [e.onset_uncertain for e in before] == [False, False]
    assert [round(e.onset_s, 2) for e in after] == [12.01, 13.48]
    assert [e.onset_uncertain for e in after] == [False, True]  # the late one flagged
    assert len(why) == 1 and "none kept" in why[0][1] and abs(why[0][0] - after[1].detected_at_s) < 1e-9


def test_the_late_stop_is_flagged_by_its_lines_out_of_step_too() -> None:
    after, why = _heard(1.0)  # the stoplike reference not asked: the lines model's reading flags it
    assert [(round(e.onset_s, 2), e.onset_uncertain) for e in after] == [(12.01, False), (13.48, True)]
    assert len(why) == 1 and why[0][1].endswith("not in step") and abs(why[0][0] - after[1].detected_at_s) < 1e-9


def test_the_late_count_is_flagged_by_the_model_s_onset_alone() -> None:
    """With neither ``onset_ref_stoplike`` nor ``model_in_step``, the model's lines refitted around the late fire's
    onset (``model_onset``) place a change 140 ms before it: the late count is flagged so too."""
    got, why = _heard(1.0, 0.0)
    assert [round(e.onset_s, 2) for e in got] == [12.01, 13.48]
    assert [e.onset_uncertain for e in got] == [False, True]
    assert len(why) == 1 and "-140 ms from the onset" in why[0][1]
