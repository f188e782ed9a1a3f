"""An onset whose stop-like run broke before the fire: the run it began may not be the stop's.

The fifth generator's arm 7, shifted stop (``tests/support/arrival_sound.py``), tuned on its own 1000 Hz recording,
steps at 1200 Hz, told, into its stop at 2 s, as ``benchmarks/bench_audio_rates.py --rates 800,1200 --commanded``
renders it. At 20 % off the tuning's rate the stepping flickers hot for a few frames now and then (1.752, 1.867 s);
one such flicker crossed at 1.973 s, and the stop's frames followed within the hold's window (8 frames), so the hold
kept the flicker's crossing as the onset: counted 27 ms early. Between that crossing and the fire, 3 frames running
were not stop-like, more than the tuning's ``max_dips`` (2), and the stepping in the 0.2 s before the crossing was hot
by itself in 4 frames: with ``OnsetParams.break_check`` the event is flagged (a traverse refuses it, never counts it).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from arrival_sound import Arm, Scene, render, tuning_scene
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedParams
from stickslip.audio.confirm.onset import ONSET
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR, STOP_S, RATE = 48_000, 2.0, 1200.0


def _heard(check: bool) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    arm = Arm(7, "shifted")
    tu = tune(render(tuning_scene(arm)), SR, 2.0, seed=0)
    y = render(Scene(arm=arm, rate=RATE, seed=int(RATE)))
    # (model_confirmed_early off: held past its window, this stop's lines read 1.91 against the spans before it, within
    # model_max_z, and that stage would flag it too; so would model_onset_early, the lines placing the change 65 ms
    # after the onset; this test pins the break)
    off = ClockedParams(model_confirmed_early=False, model_onset_early=False)
    p = ConfirmParams(onset=replace(ONSET, break_check=check), clocked=off)
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish(), det


def test_an_onset_before_a_break_in_the_stop_like_run_is_flagged() -> None:
    before, _ = _heard(False)
    assert [(round(e.onset_s, 4), e.onset_uncertain) for e in before] == [(1.9733, False)]
    assert before[0].onset_s - STOP_S < -0.025  # counted early: silently wrong
    after, det = _heard(True)
    assert [(round(e.onset_s, 4), e.onset_uncertain) for e in after] == [(1.9733, True)]  # flagged: no count
    why = "a break before the fire (3 frames not stop-like after the onset; the stepping before it hot in 4 frames)"
    assert det.log.onset == [(after[0].detected_at_s, why)]
