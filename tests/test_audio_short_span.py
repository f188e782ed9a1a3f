"""A stop confirmed on a reference the stream's start cut short is flagged: the bar is the reference's own span.

The fifth generator's arm 2, damped (``tests/support/arrival_sound.py``), tuned on its own 1000 Hz recording, steps
at 900 Hz, told, with the hour's "speech over the radio" at +3 dB from the first sample, as
``benchmarks/bench_audio_lines_model.py`` renders it (its stop at 20 s). The speech changed 0.38 s into listening:
the levels held the window (0.98 stop-like, 0.98 hot), and the per-fire lines reading, against the 0.35 s of stepping
heard before the fire (the reference is ``SyncParams.span_s``, 0.48 s, where the stream allows), even affirmed it (a
2.30, in phase 1.90, at a line heard at 910 Hz). No span of stepping had been offered to the lines model. On main it
was counted, a silently wrong position 19.6 s before the stop: ``onset_short_ref`` flagged only under ``min_s``
(0.2 s) of reference. With ``onset_short_span`` a reference under its own span is flagged: no stepping whole to
place the stop by.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from arrival_sound import Arm, Scene, render, tuning_scene
from hour_sound import over_stepping
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR, STOP_S, RATE = 48_000, 20.0, 900.0
KIND, DB = "speech over the radio", 3.0


def _heard(span: bool) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    arm = Arm(2, "damped")
    tu = tune(render(tuning_scene(arm)), SR, 2.0)
    y = render(Scene(arm=arm, rate=RATE, stop_at=STOP_S, dur=STOP_S + 2.0, jitter=0.004, seed=9007))
    y = over_stepping(y, KIND, DB, np.random.default_rng(9007 + int(DB)), int(STOP_S * SR))[: int(1.2 * SR)]
    p = ConfirmParams(clocked=replace(CLOCKED, onset_short_span=span))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish(), det


def test_a_false_stop_on_a_reference_cut_short_is_flagged() -> None:
    before, det = _heard(False)
    assert [(round(e.onset_s, 3), round(e.detected_at_s, 3), e.onset_uncertain) for e in before] == [
        (0.382, 0.408, False)
    ]  # counted 19.6 s before the stop: silently wrong
    assert det.log.onset == []
    got = det.log.clocked[0][1]
    assert (round(got.a, 2), round(got.locked, 2), round(got.rate_hz)) == (2.30, 1.90, 910)  # "affirmed"
    after, det = _heard(True)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in after] == [(0.382, True)]  # flagged: no count
    why = "only 0.35 s of stepping heard before it: it may have begun there"
    assert det.log.onset == [(after[0].detected_at_s, why)]
    c = det.checks.clocked
    assert c is not None and c.ref is not None and c.ref.size < det.checks.span and not c.model_ready()
