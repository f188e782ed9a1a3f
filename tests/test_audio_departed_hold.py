"""A stop the stepping's lines model found inside a vetoed fire's window is emitted only once its lines were read
still departed past the window's end (``ClockedParams.model_hold_s``; :func:`stickslip.audio.confirm.inside.
still_departed`): at an end stop the joint steps on into it while the traverse commands, sound over the stepping
changes and changes back.

The case: the hour's generator (``tests/support/hour_sound.py``), development joint 3 stepping at 1100 Hz (told, off
its tuning's 1000 Hz), its draw 1 (seed 1003: ``bench_audio_hour.py --seed 1``), the first 16 s: stepping under a
radio at +1.8 dB, no stop. A fire the model vetoes at 12.84 s; the pieces after its first depart from the model to the
window's end, and the onset fit places a change at 13.69 s, 110 ms before the fitted stretch's end (spread 20 ms).
Without the hold a false stop is counted there (``found_late``, emitted at the window's end, 14.84 s). In the 0.48 s
after the window's end the lines are back within the model in a 0.24 s piece (z 1.3, under ``model_max_z``): with
the hold nothing is counted, nothing flagged.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache

from fan_sound import SR, Arm, render, tuning_scene
from hour_sound import Hour, stream
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent


@cache
def _heard(hold_s: float) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    h = Hour(Arm(3), rate=1100.0, dur=16.0, seed=1003)
    tu = tune(render(tuning_scene(Arm(3))), SR, 2.0)
    det = ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=replace(CLOCKED, model_hold_s=hold_s)))
    det.reset(0.0, step_rate_hz=h.rate)
    return [e for block in stream(h) for e in det.feed(block)] + det.finish(), det


def test_a_stop_found_departed_whose_lines_change_back_past_the_window_is_not_counted() -> None:
    off, det_off = _heard(0.0)
    assert [(round(e.onset_s, 3), e.onset_uncertain, e.found_late) for e in off] == [(13.693, False, True)]
    assert [(round(a, 2), round(b, 3), s) for a, b, s in det_off.log.inside] == [(12.84, 13.693, 0.02)]
    assert det_off.log.held == [] and round(off[0].detected_at_s, 2) == 14.84  # emitted at the window's end
    on, det_on = _heard(CLOCKED.model_hold_s)
    assert det_on.log.inside == [] and on == []  # the window stays vetoed: nothing counted, nothing flagged
    [(fire_s, z)] = det_on.log.held
    assert round(fire_s, 2) == 12.84 and math.isfinite(z) and z < CLOCKED.model_max_z  # read back within the model
