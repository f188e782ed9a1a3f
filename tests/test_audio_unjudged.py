"""Off the tuning's rate (the rate told), a stop the stepping's lines model could have judged and did not is flagged
unless the lines affirm it (``ClockedParams.model_unjudged``; ``ClockedCheck.unjudged``).

The case: the fifth generator's arm 2 (damped; ``tests/support/arrival_sound.py``, its clock jittered 1 % a step),
tuned at 1000 Hz, stepping at 950 Hz told under the hour's music at -3 dB (``bench_audio_lines_model.py``'s
``arrival-1%`` run; its first 9 s, before the stop at 20 s). The music keeps the lines' in-phase share under
``model_min_share``: the model is never ready, the per-fire vetoes pass two fires (4.995 s: no reading; 7.027 s:
lines moved 1.27 dB, a 0.02), and the levels alone counted both as stops. With the switch on they are flagged: a
traverse refuses them.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache

import numpy as np
from arrival_sound import Arm, Scene, render, tuning_scene
from hour_sound import over_stepping
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED, OnClock
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR = 48_000
RATE = 950.0


@cache
def _heard(unjudged: bool) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    arm = Arm(2, "damped")
    tu = tune(np.asarray(render(tuning_scene(arm)), dtype=np.float32), SR, 2.0)
    y = render(Scene(arm=arm, rate=RATE, stop_at=20.0, dur=22.0, jitter=0.01, seed=9506)).astype(np.float64)
    y = over_stepping(y, "music", -3, np.random.default_rng(9506 - 3), 20 * SR)  # (as the bench)
    params = ConfirmParams(clocked=replace(CLOCKED, model_unjudged=unjudged))
    det = ConfirmedStopDetector(detector_for(tu), params=params)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(np.asarray(y[: 9 * SR], dtype=np.float32)) + det.finish(), det


def test_fires_off_the_rate_the_model_could_not_judge_are_flagged_not_counted() -> None:
    (off, _), (on, det) = _heard(False), _heard(True)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in off] == [(4.995, False), (7.027, False)]
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in on] == [(4.995, True), (7.027, True)]
    assert [w.startswith("off the tuning's rate") for _, w in det.log.onset] == [True, True]
    c = det.checks.clocked
    assert c is not None and not c.model_ready()


def test_the_rule_waits_for_the_model_to_have_heard_enough_and_yields_to_its_reading_or_an_affirmation() -> None:
    c = _heard(True)[1].checks.clocked
    assert c is not None
    n = math.ceil(CLOCKED.model_min_spans)
    span = round(0.48 * SR)  # the spans offered: every span_s of the stream from its start
    assert c.offered == [span * (k + 1) for k in range(n)]
    ready_at = c.offered[-1] + round(CLOCKED.model_lag_s * SR)  # the model could have been ready from here on
    low = OnClock(0.1, RATE, 1, locked=0.1)  # read by a per-fire veto, not affirmed
    assert not c.unjudged(ready_at - 1, low) and c.unjudged(ready_at, low) and c.unjudged(ready_at, None)
    assert c.unjudged(ready_at - 1, None)  # before it, a stop nothing read at all (``model_unjudged_early``)
    c.p = replace(c.p, model_unjudged_early=False)
    assert not c.unjudged(ready_at - 1, None) and c.unjudged(ready_at, None)
    c.p = CLOCKED
    read = OnClock(math.nan, RATE, 0, still_z=5.0)  # the model read the fire: it judged
    affirmed = OnClock(0.6, RATE, 1, locked=0.6)  # both readings at min_affirm, against its own stepping
    assert not c.unjudged(ready_at, read) and not c.unjudged(ready_at, affirmed)
    assert c.unjudged(ready_at, replace(affirmed, kept_s=12.0))  # affirmed against stepping from long before
    assert c.unjudged(ready_at, replace(affirmed, locked=0.4))
