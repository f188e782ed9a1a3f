"""A stop flagged out of step (``ClockedParams.model_in_step``) whose lines still depart from the stepping's lines
modelled past its window is a stop, not flagged (``ClockedParams.model_in_step_hold_z``; read as ``model_hold_s``).

The case: the product's simulator (seed 1, joint 3, stepping into its stop in the "-" direction at 1000 Hz, told),
judged with a tuning told 1100 Hz, so the stepping's lines model judges the fire. The simulator's stop rattles out of
step with the steps: the fire's lines held 0.61 of their power in phase where the stepping held 1.00, with +15 dB
out of phase, as music over the stepping would. But at an end stop the joint steps on into it: the 0.48 s after the
window still depart from the model by 17 spreads or more, where the development hour's music read 4.4 and less.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache

from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent
from stickslip.sim.arm import SimulatedMM3A

DAY = "2026-11-20"


@cache
def _recording() -> tuple[object, int, float, object]:
    sim = SimulatedMM3A(seed=1, day=DAY)
    samples, rate, stop_at = sim.labelled_recording(3, "+")
    tu = replace(tune(samples, rate, stop_at, 3), step_rate_hz=1100.0)
    x, rate, stop_at = SimulatedMM3A(seed=1, day=DAY).labelled_recording(3, "-", before_s=10.0, after_s=2.0)
    return x, rate, stop_at, tu


def _heard(hold_z: float, cut_s: float | None = None) -> tuple[list[StopEvent], ConfirmedStopDetector, float]:
    x, rate, stop_at, tu = _recording()
    clocked = replace(CLOCKED, model_in_step_hold_z=hold_z)
    det = ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=clocked))  # type: ignore[arg-type]
    det.reset(0.0, step_rate_hz=1000.0)
    y = x if cut_s is None else x[: int(round(cut_s * rate))]  # type: ignore[index]
    return det.feed(y) + det.finish(), det, stop_at  # type: ignore[arg-type,return-value]


def test_the_simulators_stop_out_of_step_is_counted_where_its_lines_stay_departed_past_the_window() -> None:
    (off, det_off, stop_at), (on, det, _) = _heard(0.0), _heard(CLOCKED.model_in_step_hold_z)
    assert len(off) == 1 and off[0].onset_uncertain and abs(off[0].onset_s - stop_at) < 0.005  # refused before
    assert [w.endswith("not in step") for _, w in det_off.log.onset] == [True]
    assert len(on) == 1 and not on[0].onset_uncertain and on[0].onset_s == off[0].onset_s  # the same onset, counted
    assert det.log.onset == [] and len(det.log.held) == 1
    assert det.log.held[0][1] >= 17.0  # the least z of the two pieces past the window (music: 4.4 and less)
    assert math.isclose(on[0].detected_at_s, off[0].confirmed_at_s + CLOCKED.model_hold_s, abs_tol=1e-3)


def test_the_stream_ended_before_the_hold_was_heard_flags_it_for_the_lines_out_of_step() -> None:
    full = _heard(CLOCKED.model_in_step_hold_z)[0]
    end = full[0].detected_at_s - CLOCKED.model_hold_s  # the window's end
    cut, det, _ = _heard(CLOCKED.model_in_step_hold_z, end + 0.1)  # 0.1 s into the hold: no 0.24 s piece heard
    assert [(e.onset_s, e.onset_uncertain) for e in cut] == [(full[0].onset_s, True)]
    assert [w.endswith("not in step") for _, w in det.log.onset] == [True] and math.isnan(det.log.held[0][1])
