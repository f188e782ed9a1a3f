"""A lines-model veto resting on one locked sub-band only flags the stop (issue 35 item 6, "no stop missed").

The tenth generator's arm 3 (``tests/support/fan_sound.py``) steps at 1050 Hz, told (the tuning's rate: 1000 Hz),
into its stop at 12 s under the hour's speech over a radio at +3 dB to the stepping (``tests/support/hour_sound.py``),
as ``benchmarks/bench_audio_stops_noise.py`` renders it. The radio is on the lines from the first sample: of the
model's five sub-bands only one holds ``min_locked`` of its lines' power in phase (0.56). The stop's own fire at
13.06 s persists (stop-like throughout the 0.94 s heard before the stream ends), and the model reads its window 2.64
spreads off that one line, within ``model_max_z`` (3): before ``ClockedParams.model_min_bands`` it was vetoed and the
stop missed. One line's level is no RMS over the stop's signature (speech on it scatters a stop's pieces 0.6-7.3
spreads), so such a model cannot veto: the stop is emitted, flagged (a traverse refuses it, never counts it).

The model is built here where the clock was first heard, not at the told rate (``told_held_tol`` 0): with the clock
held at the told rate (the default) the radio no longer pulls it, the model locks all five sub-bands and the stop is
heard without this rule (flagged at the same onset); the rule stays for a clock the detector cannot hold (a rough
one, or before a clean span was heard).
"""

from __future__ import annotations

import math
from dataclasses import replace

from fan_sound import SR, Arm, render, tuning_scene
from noise_bench import recording
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedParams, model_thin
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

STOP_S, RATE, ARM = 12.0, 1050.0, 3


def _heard(min_bands: int) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    tu = tune(render(tuning_scene(Arm(ARM))), SR, 2.0)
    y = recording(ARM, RATE, "speech over the radio", 3.0)
    p = ConfirmParams(clocked=ClockedParams(model_min_bands=min_bands, told_held_tol=0.0))
    det = ConfirmedStopDetector(detector_for(tu), params=p)
    det.reset(0.0, step_rate_hz=RATE)
    return det.feed(y) + det.finish(), det


def test_a_one_line_model_veto_flags_the_stop_instead() -> None:
    before, det0 = _heard(0)  # every veto stands: the stop's own fire vetoed, nothing heard
    assert before == []
    fires = {round(t, 2): on for t, on in det0.log.clocked}
    assert list(fires) == [0.71, 13.06]  # the first: before the model was ready (the lines' move read)
    on = fires[13.06]
    assert math.isnan(on.a) and round(on.still_z, 2) == 2.64  # no comb verdict; the model within model_max_z
    assert [round(e.onset_s, 2) for e in det0.log.rejected][-2:] == [11.02, 13.04]  # the stop lay in the first's

    after, det = _heard(ClockedParams().model_min_bands)
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in after] == [(13.044, True)]  # flagged: no count
    assert after[0].onset_s >= STOP_S  # after the stop, not before it: a traverse refuses at the stop
    # (here the chain flagged it first: no 0.15 s gap since the rejected window that held the stop, 11.05-13.05 s)


def test_the_rule_asks_the_model_s_locked_sub_bands() -> None:
    """The same fire: the model held one locked sub-band of five; a veto needs ``model_min_bands`` (2)."""
    _, det = _heard(ClockedParams().model_min_bands)
    c = det.checks.clocked
    assert c is not None and c.model is not None
    assert len(c.model.bands) == 5 and c.model.locked_bands() == [0]
    assert round(float(c.model.locked[0]), 2) == 0.56
    on = det.log.clocked[-1][1]  # the stop's own fire, 13.06 s
    assert model_thin(c, on) and c.verdict(on)  # not vetoed: flagged by onset_doubt
    why = det.checks.onset_doubt(int(round(13.044 * SR)))  # the doubt a fire the chain had not flagged gets
    assert why is not None and "on 1 locked sub-band(s)" in why and "(z 2.64)" in why
    c.p = replace(c.p, model_min_bands=1)  # one locked sub-band is enough: the veto stands
    assert not model_thin(c, on) and not c.verdict(on)
