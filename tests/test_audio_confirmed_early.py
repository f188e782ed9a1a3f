"""A stop confirmed before the lines model is ready, read past its window: flagged where its lines came back.

The tenth generator's arm 3 (``tests/support/fan_sound.py``) steps at 1100 Hz, told (the tuning's rate: 1000 Hz),
under the hour's speech over a radio at +3 dB to the stepping (``tests/support/hour_sound.py``), as
``benchmarks/bench_audio_stops_noise.py`` renders it (the stop at 12 s). At 3.949 s the speech fires the fast path;
every per-fire reading says "stop" (read at 1099.61 Hz: comb 0.87, locked 0.97, moved 4.6 dB) and the stepping's
lines modelled are not ready (only one span of the stepping alone accepted by then): without
``ClockedParams.model_confirmed_early`` a false stop is counted. Held ``model_hold_s`` past its window and read
against every span offered before its onset (five, the speech on them too), its lines read back within
``model_max_z`` (0.80 spreads): speech changes the lines and changes back; the joint stepping on into an end stop
keeps them changed. Flagged, never dropped. The true stop nearest that bar on the rates bench told (the eighth
generator's arm 6, stiff stop, 1025 Hz) reads 5.03 past its window and stays counted right.
"""

from __future__ import annotations

import numpy as np
from arrival_sound import Arm as ArrivalArm
from arrival_sound import Scene as ArrivalScene
from arrival_sound import render as arrival_render
from arrival_sound import tuning_scene as arrival_tuning
from fan_sound import SR, Arm, Scene, render, tuning_scene
from hour_sound import over_stepping
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedParams
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent
from stickslip.audio.tuningfile import Tuning

RATE, ARM = 1100.0, 3


def _heard(tu: Tuning, y: np.ndarray, rate: float, on: bool) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    p = ConfirmParams(clocked=ClockedParams(model_confirmed_early=on))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=rate)
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish(), det


def _speech() -> tuple[Tuning, np.ndarray]:
    """The noise bench's run, its first 5.5 s (the stop at 12 s is not heard)."""
    tu = tune(render(tuning_scene(Arm(ARM))), SR, 2.0)
    y = render(Scene(Arm(ARM), rate=RATE, stop_at=12.0, dur=14.0, seed=int(RATE) + ARM + 77))
    y = over_stepping(y, "speech over the radio", 3.0, np.random.default_rng(ARM * 100 + int(RATE) + 3), 12 * SR)
    return tu, y[: int(5.5 * SR)]


def test_speech_confirmed_before_the_model_is_ready_is_flagged() -> None:
    tu, y = _speech()
    off, _ = _heard(tu, y, RATE, False)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in off] == [(0.983, True), (3.949, False)]  # counted
    on, det = _heard(tu, y, RATE, True)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in on] == [(0.983, True), (3.949, True)]
    assert round(on[1].confirmed_at_s - off[1].confirmed_at_s, 2) == 0.48  # held model_hold_s past the window
    held = {round(t, 2): z for t, z in det.log.held}
    assert list(held) == [3.97] and round(held[3.97], 2) == 0.80  # back within model_max_z (3)
    assert any("came back to the stepping's" in why for _, why in det.log.onset)


def test_a_true_stop_heard_early_stays_departed_and_counted() -> None:
    a = ArrivalArm(6, "stiff")
    tu = tune(arrival_render(arrival_tuning(a)), SR, 2.0)
    y = arrival_render(ArrivalScene(arm=a, rate=1025.0, seed=1025))
    on, det = _heard(tu, y, 1025.0, True)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in on][:1] == [(2.001, False)]  # right (the stop: 2 s)
    assert [round(z, 2) for _, z in det.log.held] == [5.03]  # still departed past the window: counted
