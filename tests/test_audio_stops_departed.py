"""A stop inside the window of a fire the stepping's lines modelled vetoed is found there (issue 35 item 6).

The tenth generator's arm 1 (``tests/support/fan_sound.py``) steps at 1200 Hz, told (the tuning's
rate: 1000 Hz), into its stop at 12 s under the hour's speech over the radio at +3 dB to the stepping
(``tests/support/hour_sound.py``), as ``benchmarks/bench_audio_stops_noise.py`` renders it. With
``ClockedParams.lines_model`` the fast path's fire at 11.46 s is vetoed: the first 0.48 s piece of its
window sits within ``model_max_z`` of the stepping modelled. The stop comes in the second piece, and
the pieces from it to the window's end depart from the model. Without ``model_inside`` the stop had no
event at all: the window was dropped, and the stop's own fire, 16 ms after the window's end, was
rejected by persistence at the stream's end (0.52 s of its window heard); since ``model_rejected`` that window, its
lines departed from the model in every span, gives a flagged event (the fire's onset, 13.45 s). With ``model_inside``,
the stop is found inside the window, where the fit on the model's lines places the change within ``model_max_spread_s``
(:func:`stickslip.audio.confirm.inside.stop_departed`); here within 20 ms. It is emitted 0.48 s after the window's
end, once its lines were read still departed there (``model_hold_s``). Asked to place it within
10 ms, the fit cannot, and the window is dropped as before.
"""

from __future__ import annotations

from fan_sound import SR, Arm, render, tuning_scene
from noise_bench import recording
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedParams
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

STOP_S, RATE, ARM, KIND = 12.0, 1200.0, 1, "speech over the radio"


def _heard(max_spread_s: float, rejected: bool = True) -> tuple[list[StopEvent], list[tuple[float, float, float]]]:
    tu = tune(render(tuning_scene(Arm(ARM))), SR, 2.0)
    y = recording(ARM, RATE, KIND, 3.0)
    p = ConfirmParams(clocked=ClockedParams(model_max_spread_s=max_spread_s, model_rejected=rejected))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(y) + det.finish(), det.log.inside


def test_a_stop_in_the_window_of_a_fire_the_model_vetoed_is_found_there() -> None:
    dropped, none = _heard(0.01, rejected=False)
    assert none == [] and dropped == []  # the stop missed so (as without model_inside)
    flagged, none = _heard(0.01)  # its own fire's window, rejected at the stream's end, departed in every span
    assert none == [] and [(round(e.onset_s, 3), e.onset_uncertain, e.detected_at_s) for e in flagged] == [
        (13.453, True, 14.0)
    ]  # (model_rejected: heard, flagged: a traverse refuses it)
    events, inside = _heard(ClockedParams().model_max_spread_s)
    assert len(inside) == 1 and abs(inside[0][0] - 11.461) < 0.01 and 0.01 < inside[0][2] <= 0.025  # its window
    at = [e for e in events if e.onset_s >= STOP_S - 0.025]
    assert at and at[0].found_late and abs(at[0].onset_s - STOP_S) < 0.025  # within the bench's tolerance
    held = 13.461 + ClockedParams().model_hold_s  # the window's end, and its lines read still departed past it
    assert at[0].detected_at_s == at[0].confirmed_at_s and abs(at[0].detected_at_s - held) < 0.01
    assert all(e.onset_s >= STOP_S - 0.025 for e in events)  # and no false stop before it
