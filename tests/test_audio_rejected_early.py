"""A stop the levels rejected before the stepping's lines model is ready, read against the spans heard before it.

The sixth generator's beam 5 (``tests/support/beam_sound.py``), tuned on its own 1000 Hz recording, steps at 900 Hz,
told, into its stop at 2 s, as ``benchmarks/bench_audio_rates.py --commanded`` renders it. At 10 % off the tuning's
rate the stop's fire at 2.04 s is stop-like over only 0.38 of its window: the levels reject it. Off the tuning's rate
``model_rejected`` would read such a window against the stepping's lines modelled, but the model is not ready before
about 5 s of listening (a span is modelled ``model_lag_s`` after it ended), and the stop was missed. With
``ClockedParams.model_rejected_early`` the window is read against the four spans of stepping offered before the
fire's onset (:func:`~stickslip.audio.confirm.inside.early_model`): its lines departed 13.9 spreads, and the stop is
emitted flagged (a traverse refuses it, never counts it).
"""

from __future__ import annotations

import math

import numpy as np
from beam_sound import Beam, Scene, render, tuning_scene
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedParams
from stickslip.audio.confirm.inside import departed_throughout, early_model
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR, STOP_S, RATE, BEAM = 48_000, 2.0, 900.0, 5


def _heard(early: bool) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    tu = tune(render(tuning_scene(Beam(BEAM))), SR, 2.0, seed=0)
    y = render(Scene(beam=Beam(BEAM), rate=RATE, seed=int(RATE)))
    p = ConfirmParams(clocked=ClockedParams(model_rejected_early=early))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish(), det


def test_a_rejected_stop_before_the_model_is_ready_is_flagged() -> None:
    before, det0 = _heard(False)
    assert before == []  # missed: the levels rejected the stop's fire, no model to read its window
    assert [round(e.detected_at_s, 3) for e in det0.log.rejected] == [2.043]
    c0 = det0.checks.clocked
    assert c0 is not None and c0.model is not None and not c0.model_ready()

    after, det = _heard(True)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in after] == [(2.013, True)]  # flagged: no count
    assert abs(after[0].onset_s - STOP_S) < 0.025
    assert len(det.log.onset) == 1 and "heard before it in every span (z 13.9)" in det.log.onset[0][1]


def test_the_early_model_counts_the_spans_before_the_fire() -> None:
    """Four spans of 0.48 s ended before the onset (2.013 s), all stepping accepted: ``model_min_spans`` (4) counted.
    Spans that ended later (the stop's own) are not taken; with three before it, no reading."""
    _, det = _heard(True)
    c = det.checks.clocked
    assert c is not None and not c.model_ready()
    at = int(round(2.013 * SR))
    m = early_model(c, at)
    assert m is not None and round(m.weight, 2) == 3.95  # (four spans, forgotten over 60 s: weight under 4)
    assert early_model(c, int(round(1.9 * SR))) is None  # three spans ended by 1.9 s
    w = np.asarray(render(Scene(beam=Beam(BEAM), rate=RATE, seed=int(RATE))), dtype=np.float64)
    z = departed_throughout(w[int(2.05 * SR) : int(2.6 * SR)], c, m)
    assert z > 2 * c.p.model_max_z
    assert math.isnan(departed_throughout(w[int(2.05 * SR) : int(2.6 * SR)], c))  # the model itself: not ready
