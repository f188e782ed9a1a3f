"""A stop confirmed before the stepping's lines model could be ready, no reading of the lines judging it, is flagged.

The twelfth generator's joint 3 (``tests/support/crystal_sound.py``: a divided crystal's step clock in bursts,
music placed on and beside the lines, 0 to +6 dB) steps at 1100 Hz, told (the tuning's rate: 1000 Hz). Music
fires the fast path 0.57 s into the recording and persistence confirms it. The per-fire vetoes give no verdict:
the step clock near the told rate is heard at 1109.8 Hz (music on the lines pulls it), where the stop's predicted
signature moves the locked sub-bands 1.8 dB (``min_pred_moved_db`` 3). The model (``lines_model``) holds none of
the 4 spans it needs, and ``model_unjudged`` is asked only once it could be ready (4.4 s). Without
``ClockedParams.model_unjudged_early`` it was a stop counted 11.4 s early, unflagged.
"""

from __future__ import annotations

import math

import crystal_sound as cs
import numpy as np
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedParams, OnClock
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

RATE = 1100.0


def _heard(early: bool) -> tuple[list[StopEvent], list[tuple[float, str]]]:
    tu = tune(cs.render(cs.tuning_session(cs.Joint(3))), cs.SR, 2.0)
    s = cs.Session(
        cs.Joint(3), cs.Clock(rate=RATE), dur=14, stop_at=12, seed=2, kinds=("music",), span_s=(30, 40), music_db=(0, 6)
    )
    x = np.asarray(cs.render(s)[: int(1.2 * cs.SR)], dtype=np.float32)  # the first 1.2 s: the false stop
    det = ConfirmedStopDetector(
        detector_for(tu), params=ConfirmParams(clocked=ClockedParams(model_unjudged_early=early))
    )
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(x) + det.finish(), det.log.onset


def test_a_stop_no_reading_judged_before_the_model_could_be_ready_is_flagged() -> None:
    before, why_before = _heard(False)
    after, why = _heard(ClockedParams().model_unjudged_early)
    assert [round(e.onset_s, 3) for e in before] == [0.574] == [round(e.onset_s, 3) for e in after]
    assert not before[0].onset_uncertain and not why_before  # counted: 11.4 s before the stop at 12 s
    assert after[0].onset_uncertain and after[0].detected_at_s == before[0].detected_at_s
    assert len(why) == 1 and "neither the stepping's lines modelled nor the lines in phase" in why[0][1]


def test_the_early_rule_asks_only_where_nothing_read_the_lines() -> None:
    from stickslip.audio.confirm.clocked import ClockedCheck

    tu = tune(cs.render(cs.tuning_session(cs.Joint(3))), cs.SR, 2.0)
    c = ClockedCheck(tu, ClockedParams())
    c.reset(RATE)
    at = int(0.6 * cs.SR)
    assert c.models_lines() and not c.model_ready()
    assert c.unjudged(at, None)  # nothing read it, too early for the model: the levels alone
    assert not c.unjudged(0, None)  # the start of listening: the warm-up judged the stop began there
    read = OnClock(math.nan, RATE, 1, moved_db=6.4)  # a per-fire veto read it and let it through
    assert not c.unjudged(at, read)
    c.reset(1000.0)  # at the tuning's rate: not asked
    assert not c.unjudged(at, None)
    off = ClockedCheck(tu, ClockedParams(model_unjudged_early=False))
    off.reset(RATE)
    assert not off.unjudged(at, None)
