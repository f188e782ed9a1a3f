"""A fire on a flicker of the stepping, the stop after its break: the break asked past the fire too.

The fifth generator's arm 3, shifted stop (``tests/support/arrival_sound.py``), tuned on its own 1000 Hz recording,
steps at 1100 Hz, untold, into its stop at 2 s, as ``benchmarks/bench_audio_rates.py`` renders it (the rates bench's
one early count untold). At 10 % off the tuning's rate the stepping sits near the threshold (its median 0.58
thresholds) and flickers hot for 2-4 frames; one flicker held 7 hot frames of 9 and fired at 1.984 s, 16 ms before
the stop. Then 5 frames running were not stop-like, and the stop's frames followed: its window (0.5 s) persisted,
and the onset, the flicker's crossing, was counted 41 ms early. ``OnsetParams.break_check`` read only between the
onset's crossing and the fire, where the run broke for 1 frame; ``break_past_fire`` reads on over one hold (8
frames) past the fire: 5 frames, more than the tuning's ``max_dips`` (2), over a stepping hot by itself in 14 frames
of the 0.2 s before the crossing: flagged (a traverse refuses it, never counts it). The told rate's rules flag this
stop too (``model_unjudged_early``); untold, only the levels' and the onset's rules stand.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from arrival_sound import Arm, Scene, render, tuning_scene
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.onset import ONSET
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR, STOP_S, RATE = 48_000, 2.0, 1100.0


def _heard(past: bool, check: bool = True) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    arm = Arm(3, "shifted")
    tu = tune(render(tuning_scene(arm)), SR, 2.0, seed=0)
    y = render(Scene(arm=arm, rate=RATE, seed=int(RATE)))[: int(2.6 * SR)]
    p = ConfirmParams(onset=replace(ONSET, break_check=check, break_past_fire=past))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=None)  # untold: the lines' rules need the rate
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish(), det


def test_a_fire_on_a_flicker_before_the_stop_is_flagged() -> None:
    before, det = _heard(False)
    assert [(round(e.onset_s, 4), round(e.detected_at_s, 4), e.onset_uncertain) for e in before] == [
        (1.9594, 1.984, False)
    ]
    assert before[0].onset_s - STOP_S < -0.025  # counted early: silently wrong
    assert det.log.onset == []
    after, det = _heard(True)
    assert [(round(e.onset_s, 4), e.onset_uncertain) for e in after] == [(1.9594, True)]  # flagged: no count
    why = (
        "a break within a hold after the fire (5 frames not stop-like after the onset; the stepping before it hot in"
        " 14 frames)"
    )
    assert det.log.onset == [(after[0].detected_at_s, why)]


def test_the_break_past_the_fire_is_part_of_the_break_check() -> None:
    events, det = _heard(True, check=False)  # break_check off: nothing is asked past the fire either
    assert [e.onset_uncertain for e in events] == [False]
    assert det.log.onset == []
