"""A stop confirmed in the first second of listening, before any stepping's spread exists, not affirmed: flagged.

The fifth generator's arm 1, stiff (``tests/support/arrival_sound.py``), tuned on its own 1000 Hz recording, steps
at 900 Hz, told, with the hour's "speech over the radio" at +3 dB from the first sample, as
``benchmarks/bench_audio_lines_model.py`` renders it (its stop at 20 s). The speech changed 0.52 s into listening:
the levels held the window (0.71 stop-like, 0.29 hot), the per-fire lines reading at the rate gave no veto (the lines
moved 3.65 dB, no comb verdict off the tuning's rate) and no affirmation, and neither the stepping's lines modelled
nor the copy ``model_confirmed_early`` reads past the window could exist: 2 spans offered by then, 4 needed. On main
it was counted, a silently wrong position 19.5 s before the stop. ``model_unjudged_first`` flags it: the levels
alone counted it (``model_unjudged_early``'s reason).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from arrival_sound import Arm, Scene, render, tuning_scene
from hour_sound import RMS, _span_source
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR, STOP_S, RATE = 48_000, 20.0, 900.0
KIND, DB = "speech over the radio", 3.0


def _heard(first: bool) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    arm = Arm(1, "stiff")
    tu = tune(render(tuning_scene(arm)), SR, 2.0)
    y = render(Scene(arm=arm, rate=RATE, stop_at=STOP_S, dur=STOP_S + 2.0, jitter=0.004, seed=9007))
    rms = float(np.sqrt(np.mean(y[: int(STOP_S * SR)] ** 2)))
    src = _span_source(KIND, np.random.default_rng(9007 + int(DB)))
    y = (y + src(y.size) * rms * 10 ** (DB / 20) / RMS[KIND])[: int(1.5 * SR)]  # type: ignore[operator]
    p = ConfirmParams(clocked=replace(CLOCKED, model_unjudged_first=first))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish(), det


def test_a_false_stop_in_the_first_second_is_flagged() -> None:
    before, det = _heard(False)
    assert [(round(e.onset_s, 3), round(e.detected_at_s, 3), e.onset_uncertain) for e in before] == [
        (0.522, 0.544, False)
    ]  # counted 19.5 s before the stop: silently wrong
    assert det.log.onset == []
    after, det = _heard(True)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in after] == [(0.522, True)]  # flagged: no count
    why = "off the tuning's rate, neither the stepping's lines modelled nor the lines in phase affirm it"
    assert det.log.onset == [(after[0].detected_at_s, why)]
    c = det.checks.clocked
    assert c is not None and not c.model_ready() and sum(e <= 0.522 * SR for e in c.offered) < 4  # no spread
    got = det.log.clocked[0][1]
    assert round(got.moved_db, 2) == 3.65 and np.isnan(got.a)  # read, no veto, no affirmation
