"""A fire the levels rejected whose lines departed from the stepping's modelled in every span is a stop, flagged
(``ClockedParams.model_rejected``; ``inside.departed_throughout``; issue 35 item 6, "no stop missed").

The case, from a generator the rule was not developed on: the fifth generator's arm 2 (damped;
``tests/support/arrival_sound.py``, its clock jittered 1 % a step), tuned at 1000 Hz, stepping at 1100 Hz told into
its stop at 20 s under the hour's music at -3 dB (``bench_audio_lines_model.py``'s ``arrival-1%`` run). The music
masks the stop's drops: its fire at 20.30 s (onset 20.275 s) came within 2 s of a rejected one, and what was heard of
its 2 s window (to the stream's end at 22 s) was not stop-like enough; nothing was read on the lines, and the stop had
no event at all (a traverse steps on into it). The stepping's lines modelled (ready since the first seconds) read the
window 11 spreads off in every span: with the rule the stop is emitted, flagged (its onset is the fire's, not known),
at the stream's end (no lines heard past the window to hold it by).
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
from stickslip.audio.confirm.clocked import CLOCKED, ClockedCheck
from stickslip.audio.confirm.inside import departed_throughout
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR = 48_000
RATE, STOP_S, SEED = 1100.0, 20.0, 11006  # (the bench's seed for this rate and noise)


@cache
def _recording() -> np.ndarray:
    y = render(Scene(arm=Arm(2, "damped"), rate=RATE, stop_at=STOP_S, dur=STOP_S + 2.0, jitter=0.01, seed=SEED))
    y = y.astype(np.float64)
    music = over_stepping(y, "music", -3, np.random.default_rng(SEED - 3), int(STOP_S * SR))  # (as the bench)
    return np.asarray(music, dtype=np.float32)


@cache
def _heard(rejected: bool, block: int = 0) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    tu = tune(np.asarray(render(tuning_scene(Arm(2, "damped"))), dtype=np.float32), SR, 2.0)
    p = ConfirmParams(clocked=replace(CLOCKED, model_rejected=rejected))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    y = _recording()
    n = block or y.size
    events = [e for i in range(0, y.size, n) for e in det.feed(y[i : i + n])]
    return events + det.finish(), det


def test_a_stop_the_levels_rejected_is_heard_flagged_where_its_lines_departed_in_every_span() -> None:
    off, _ = _heard(False)
    assert off == []  # missed: the window was rejected and nothing else heard it
    on, det = _heard(True)
    assert len(on) == 1
    e = on[0]
    assert e.onset_uncertain and e.found_late  # a traverse refuses it: its onset (the fire's) is not known
    assert abs(e.onset_s - 20.275) < 0.002 and e.onset_s > STOP_S  # the fire's onset, 0.28 s after the stop
    assert e.detected_at_s == 22.0  # the stream's end: no lines past the window to hold it by
    assert [w.startswith("the levels did not hold it") for _, w in det.log.onset] == [True]
    assert len(det.log.held) == 1 and math.isnan(det.log.held[0][1])  # (held, nothing read past the window)
    blocks, _ = _heard(True, 65_536)
    assert blocks == on  # the same in 65 536-sample blocks


def test_the_lines_depart_in_every_span_at_the_stop_and_not_over_the_stepping_before() -> None:
    c = _heard(True)[1].checks.clocked
    assert c is not None and c.model_ready()
    y = _recording().astype(np.float64)
    stop = departed_throughout(y[int(20.3 * SR) : int(22.0 * SR)], c)  # the rejected window, as heard
    stepping = departed_throughout(y[int(17.5 * SR) : int(19.5 * SR)], c)
    assert stop >= CLOCKED.model_max_z > stepping
    assert math.isnan(departed_throughout(y[: int(0.4 * SR)], c))  # under one span: not read
    fresh = ClockedCheck(c.tuning)
    fresh.reset(RATE)
    assert math.isnan(departed_throughout(y[int(20.3 * SR) : int(22.0 * SR)], fresh))  # no model: not read
