"""A stop the stepping's lines model "found" inside a vetoed fire's window, whose onset fit split its stretch at the
stretch's very end, is not counted (``ClockedParams.model_edge_s``;
:func:`stickslip.audio.confirm.inside.stop_departed`).

The case: the hour's generator (``tests/support/hour_sound.py``), development joint 3 stepping at 1050 Hz (told, off
its tuning's 1000 Hz), its draw 4 (seed 4003: ``bench_audio_hour.py --seed 4``), the first 14.5 s: stepping under
music at -0.8 dB, no stop. The fast path fires at 12.24 s; the model vetoes it (its first 0.48 s piece sits within
``model_max_z`` of the stepping), and the pieces after depart from the model to the window's end. The onset fit over
the last piece within and the first departed (0.96 s, 48 frames of 20 ms) puts its best split at 0.930 s, 30 ms from
the stretch's end, with no spread at all: a boundary optimum (the change lies at or past the end), not an onset.
Without the rule that is counted, a false stop at 13.647 s (``found_late``); with it the window stays vetoed and
nothing is counted (the sound there is heard again at the window's end, and flagged). The hold past the window
(``model_hold_s``, ``tests/test_audio_departed_hold.py``) drops it too; the "before" turns both off.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache

from fan_sound import Arm
from hour_heard import heard_by, joint_tuning
from hour_sound import Hour

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.events import StopEvent


@cache
def _heard(edge_s: float, hold_s: float = CLOCKED.model_hold_s) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    clocked = replace(CLOCKED, model_edge_s=edge_s, model_hold_s=hold_s)
    return heard_by(Hour(Arm(3), rate=1050.0, dur=14.5, seed=4003), joint_tuning(3), ConfirmParams(clocked=clocked))


def test_a_split_at_the_fitted_stretchs_end_is_not_counted_as_a_stop_found_inside() -> None:
    off, det_off = _heard(0.0, 0.0)  # (the hold past the window drops it too: off for the "before")
    assert [(round(e.onset_s, 3), e.onset_uncertain, e.found_late) for e in off] == [(13.647, False, True)]
    assert [(round(a, 2), round(b, 3), s) for a, b, s in det_off.log.inside] == [(12.24, 13.647, 0.0)]
    on, det_on = _heard(CLOCKED.model_edge_s)
    assert det_on.log.inside == []  # the window stays vetoed
    assert [e for e in on if not e.onset_uncertain] == []  # nothing counted
    assert all(e.onset_s > 13.647 + 0.5 for e in on)  # what is heard after it is the window's end, flagged

