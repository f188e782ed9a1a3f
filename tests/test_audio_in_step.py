"""A fire the stepping's lines model read and let through, whose lines were not in step with the steps, is flagged
(``ClockedParams.model_in_step``; ``SteppingLines.in_step``, asked by ``WindowChecks.onset_doubt``).

The case: the hour's generator (``tests/support/hour_sound.py``), development joint 3 stepping at 1100 Hz (10 % off
its tuning's rate, told), 26 s of stepping and music in spans of 4-12 s (draw 227), no stop. Music at 24.08 s fires
the fast path; the model, ready since the first seconds, reads the window 3.2 spreads off the stepping (a stop
departs so) and lets it through: counted, a false stop. Its lines held 0.58 of their power in phase over the
window's first 0.48 s where the stepping modelled held 0.98, and their power out of phase rose 15 dB: at an end stop
the joint steps on and its lines stay in step (true stops 0.88-1.00). With the rule the event is flagged: a traverse
refuses it.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache

from fan_sound import Arm
from hour_heard import heard_by, joint_tuning
from hour_sound import Hour

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.events import StopEvent


@cache
def _heard(in_step: float, added_db: float = CLOCKED.model_added_db) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    h = Hour(Arm(3), rate=1100.0, dur=26.0, seed=227, span_s=(4.0, 12.0), kinds=("nothing", "music"))
    # (the lines read at 1100 Hz itself, ``told_held_tol``, the model vetoes the fire: turned off to pin this rule)
    clocked = replace(CLOCKED, model_in_step=in_step, model_added_db=added_db, told_held_tol=0.0)
    return heard_by(h, joint_tuning(3), ConfirmParams(clocked=clocked))


def test_a_fire_the_model_let_through_with_its_lines_out_of_step_is_flagged_not_counted() -> None:
    (off, _), (on, det) = _heard(0.0), _heard(CLOCKED.model_in_step)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in off] == [(24.079, False)]  # counted without the rule
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in on] == [(24.079, True)]
    assert [w for _, w in det.log.onset] == [
        "lines 0.58 in phase at the fire, the stepping's 0.98, power out of phase +15.0 dB: not in step"
    ]
    got = [g for t, g in det.log.clocked if math.isfinite(g.in_step)]
    assert len(got) == 1 and got[0].still_z >= CLOCKED.model_max_z  # read by the model, and let through
    assert got[0].in_step < CLOCKED.model_in_step * got[0].model_share


def test_a_share_lowered_without_power_added_out_of_phase_is_not_flagged() -> None:
    """The same fire, asked for 16 dB out of phase where the music added 15.0: counted, as a stop lowering its
    lines into the room's noise would be (its share falls, nothing is added)."""
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in _heard(CLOCKED.model_in_step, 16.0)[0]] == [
        (24.079, False)
    ]


def test_the_share_is_read_only_where_the_model_let_the_fire_through() -> None:
    det = _heard(CLOCKED.model_in_step)[1]
    for _, g in det.log.clocked:
        assert math.isfinite(g.in_step) == (g.still_z >= CLOCKED.model_max_z)
        assert math.isfinite(g.in_step) == math.isfinite(g.model_share)
