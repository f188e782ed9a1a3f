"""A window cut short by a refire, read against the stepping's lines modelled as a rejected one is
(``ClockedParams.model_refired``; ``inside.held_refired``; issue 35 item 6, "no stop missed").

Persistence never judges a window cut short where the fast path fired again inside it, and under music that fires
every half second a stop can lie in nothing but such windows (the tenth generator's arm 3, 950 Hz, music +3 dB,
``bench_audio_stops_noise.py``: read only at the stream's end). The reading is checked here on another generator
than the one it was measured on: the fifth (``tests/support/arrival_sound.py``, its damped arm, the clock jittered
0.4 % a step), tuned at 1000 Hz, stepping at 1100 Hz told into its stop at 20 s under the hour's music at -3 dB.
The detector hears the stepping to 19.9 s (its lines model ready); a window from there across the stop, as a refire
would cut it (0.6 s: one span), departs from the model (14 spreads) and still does past it: held, and emitted
flagged (its onset the cut fire's, not known). Windows of the stepping under the music before the stop read within
the model (under 1 spread): not held. Off (``model_refired`` False): not read.
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from functools import cache

import numpy as np
from arrival_sound import Arm, Scene, render, tuning_scene
from hour_sound import over_stepping
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.confirm.chain import Fire
from stickslip.audio.confirm.inside import held_refired
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent

SR = 48_000
RATE, STOP_S, SEED, HEARD_S = 1100.0, 20.0, 11006, 19.9
ARM = Arm(2, "damped")


@cache
def _recording() -> np.ndarray:
    y = render(Scene(arm=ARM, rate=RATE, stop_at=STOP_S, dur=STOP_S + 1.0, jitter=0.004, seed=SEED))
    y = y.astype(np.float64)
    return over_stepping(y, "music", -3, np.random.default_rng(SEED - 3), int(STOP_S * SR))  # re the stepping's RMS


@cache
def _heard() -> ConfirmedStopDetector:
    """The confirming detector, told the rate, having heard the stepping to :data:`HEARD_S`."""
    tu = tune(np.asarray(render(tuning_scene(ARM)), dtype=np.float32), SR, 2.0)
    det = ConfirmedStopDetector(detector_for(tu))
    det.reset(0.0, step_rate_hz=RATE)
    assert det.feed(np.asarray(_recording()[: int(HEARD_S * SR)], dtype=np.float32)) == []
    return det


def _cut(lo_s: float, hi_s: float, det: ConfirmedStopDetector, refired: bool = True) -> object:
    """The window ``lo_s`` .. ``hi_s`` (s) read as one cut short there by a refire: the hold, or None."""
    c = det.checks.clocked
    assert c is not None
    if not refired:
        c = copy.copy(c)
        c.p = replace(c.p, model_refired=False)
    ev = StopEvent(lo_s, lo_s - 0.02, -20.0)
    fire = Fire(ev, int(lo_s * SR) // int(det.tuning.hop), int((hi_s - lo_s) * SR) // int(det.tuning.hop))
    w = _recording()[int(lo_s * SR) : int(hi_s * SR)]
    return held_refired(w, fire, (int(hi_s * SR), 0.0, float(SR)), c, det.checks.pause)


def test_a_window_cut_short_across_the_stop_is_held_and_emitted_flagged() -> None:
    det = _heard()
    c = det.checks.clocked
    assert c is not None and c.model_ready()
    h = _cut(HEARD_S, 20.5, det)
    assert h is not None and h.flagged is not None and h.flagged.startswith("cut short by a fire inside it")
    z = float(h.flagged.split("(z ")[1].split(")")[0])
    assert z >= c.p.model_max_z
    assert h.until - h.end == int(round(c.p.model_hold_s * SR))
    past = _recording()[h.end : h.until]  # the lines past the window: the joint stepping on into its stop
    e, z_past = h.judged(past, 0.0, c)
    assert e is not None and z_past >= c.p.model_max_z
    assert e.onset_uncertain and e.found_late  # a traverse refuses it: its onset (the cut fire's) is not known
    assert e.onset_s == HEARD_S - 0.02 and math.isclose(e.detected_at_s, 20.98)
    assert _cut(HEARD_S, 20.5, det, refired=False) is None  # off: not read


def test_windows_of_the_stepping_under_music_are_not_held() -> None:
    det = _heard()
    for lo, hi in ((17.0, 18.6), (18.0, 19.0), (19.3, 19.9)):
        assert _cut(lo, hi, det) is None
    assert _cut(19.5, 19.9, det) is None  # under one span: not read
