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

A true stop found so (``tests/test_audio_stops_departed.py``'s case: the tenth generator's arm 1 at 1200 Hz told, into
its stop at 12 s under speech over the radio at +3 dB) is emitted at the hold's end, 13.94 s, in whatever blocks the
stream comes; where the stream ends within the hold, on what was heard of it: one 0.24 s piece still departed, the
stop; not one piece heard, the stop flagged (a traverse refuses it; never counted unread).
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache

import numpy as np
from fan_sound import SR, Arm
from hour_heard import heard_by, joint_tuning
from hour_sound import Hour
from noise_bench import recording

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent
from stickslip.audio.tuningfile import Tuning


@cache
def _heard(hold_s: float) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    h = Hour(Arm(3), rate=1100.0, dur=16.0, seed=1003)
    # (the lines read at 1100 Hz itself, ``told_held_tol``, the fire at 12.84 s is not found departed: turned off)
    return heard_by(h, joint_tuning(3), ConfirmParams(clocked=replace(CLOCKED, model_hold_s=hold_s, told_held_tol=0.0)))


def test_a_stop_found_departed_whose_lines_change_back_past_the_window_is_not_counted() -> None:
    off, det_off = _heard(0.0)
    assert [(round(e.onset_s, 3), e.onset_uncertain, e.found_late) for e in off] == [(13.693, False, True)]
    assert [(round(a, 2), round(b, 3), s) for a, b, s in det_off.log.inside] == [(12.84, 13.693, 0.02)]
    assert det_off.log.held == [] and round(off[0].detected_at_s, 2) == 14.84  # emitted at the window's end
    on, det_on = _heard(CLOCKED.model_hold_s)
    assert det_on.log.inside == [] and on == []  # the window stays vetoed: nothing counted, nothing flagged
    [(fire_s, z)] = det_on.log.held
    assert round(fire_s, 2) == 12.84 and math.isfinite(z) and z < CLOCKED.model_max_z  # read back within the model


@cache
def _stop() -> tuple[Tuning, np.ndarray]:
    """The true stop's tuning and recording (as ``bench_audio_stops_noise.py`` renders arm 1, 1200 Hz, +3 dB)."""
    arm, rate, kind = 1, 1200.0, "speech over the radio"
    tu = joint_tuning(arm)
    return tu, recording(arm, rate, kind, 3.0)


def _stop_heard(until_s: float, block: int | None = None) -> tuple[list[tuple[float, float, bool]], list[float]]:
    tu, y = _stop()
    x = y[: int(round(until_s * SR))]
    det = ConfirmedStopDetector(detector_for(tu))
    det.reset(0.0, step_rate_hz=1200.0)
    n = block or x.size
    got = [e for i in range(0, x.size, n) for e in det.feed(x[i : i + n])] + det.finish()
    assert all(e.found_late for e in got)
    heard = [(round(e.onset_s, 3), round(e.detected_at_s, 3), e.onset_uncertain) for e in got]
    return heard, [z for _, z in det.log.held]


def test_a_true_stop_found_departed_is_emitted_at_its_holds_end_or_flagged_where_the_stream_ends_in_it() -> None:
    whole, z = _stop_heard(14.0)
    assert whole == [(12.006, 13.941, False)] and len(z) == 1 and z[0] >= CLOCKED.model_max_z  # 11.46 s + 2 s + 0.48
    assert _stop_heard(14.0, 4801) == (whole, z)  # whatever the blocks
    one, z1 = _stop_heard(13.75)  # the stream ends 0.29 s into the hold: one piece read, still departed
    assert one == [(12.006, 13.75, False)] and z1[0] >= CLOCKED.model_max_z
    none, z0 = _stop_heard(13.56)  # 0.1 s into it: not one piece heard
    assert none == [(12.006, 13.56, True)] and math.isnan(z0[0])
