"""The limit switch on a fourth, independent generator (``modal_sound``): arms drawn at random.

Each ``joint_seed`` is another arm (seven modes with their own Q, a rough step clock); the
detector is tuned on one clean recording of it and must then find the stop once, with its
onset within 25 ms and latency under 50 ms, and nothing else, on recordings with other
seeds and the room's sounds. Written and run after the detector was developed; the
conditions that fail are strict xfails with the measured reason. The detector is told the
rate each recording steps at, as a traverse tells it (``detect(..., step_rate_hz=)``):
untold, the stops of arms 2 and 5 (louder) stepping 15 % faster fire 96 and 173 ms late.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from modal_sound import Scene, render
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.detector import detect
from stickslip.audio.tuningfile import Tuning

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

ROOMS: dict[str, dict[str, object]] = {
    "quiet room": {},
    "second instrument from 0.7 s": {"instrument": True},
    "a voice from the first sample": {"voice_db": 0.0},
    "knocks": {"knocks": True},
    "a door slam": {"door": True},
    "fan and hum": {"fan": True},
    "noisy (10 dB SNR)": {"snr_db": 10.0},
    "steps 15 % faster": {"rate": 1150.0},
}
#: measured on the detector as merged (python tests/test_audio_modal.py lists them); onset / detected re the stop
VOICE = (
    "a syllable over the stop fills the sub-bands the stop empties (arm 2: the bands above 4 kHz 4-5 spreads up "
    "at the stop); the stop is heard when it ends"
)
ARM3 = (
    "arm 3's spectral stop lowers nothing worth checking (its drops add up to 0.84 spreads over the whole template "
    "and at most 0.74 in any sub-range, against the 2 the detector asks for), so every candidate relies on the "
    "stop's rises alone: the self-check's sound shaped like the rise fires each of the 7 and tune says so; of the "
    "7, none passes the voice, the knocks and the door slam together (round 6, measured); anything adding sound "
    "where the stop does fires it"
)
KNOWN = {
    (2, "duller", "a voice from the first sample"): VOICE + ": onset +61 ms",
    (3, "duller", "a voice from the first sample"): VOICE + ": onset +70 ms",
    (3, "spectral", "a voice from the first sample"): ARM3 + ": a false alarm 1.66 s before the stop",
    (3, "spectral", "knocks"): ARM3 + ": a broadband knock (stop-likeness 1.84) 1.34 s before the stop",
    (3, "spectral", "a door slam"): ARM3 + ": the slam's thump 1.53 s before the stop",
    (3, "louder", "second instrument from 0.7 s"): "onset +384 ms: the instrument adds 1-3 spreads to sub-band 10, "
    "where the stop's largest drop is (-2.4 spreads): too little to be set aside as added sound, enough to hide the "
    "drop; the candidates that check drops are all later (+1.2 to +2.1 s), those that do not fire on knocks",
    (3, "louder", "a voice from the first sample"): VOICE + ": onset +62 ms",
    (5, "duller", "a voice from the first sample"): VOICE + ": onset +31 ms",
    (5, "louder", "a voice from the first sample"): VOICE + ": onset +62 ms",
}


@cache
def _tuning(joint_seed: int, kind: str) -> Tuning:
    return tune(render(Scene(joint_seed, kind, stop_at=3.0, dur=4.5, seed=10)), 48_000, 3.0)


CASES = [
    pytest.param(
        js, kind, room, id=f"arm {js}, {kind} stop, {room}",
        marks=[pytest.mark.xfail(strict=True, reason=KNOWN[(js, kind, room)])] if (js, kind, room) in KNOWN else [],
    )
    for js in (2, 3, 5)
    for kind in ("quieter", "duller", "spectral", "louder")
    for room in ROOMS
]


@pytest.mark.parametrize(("joint_seed", "kind", "room"), CASES)
def test_one_stop_found_on_time_and_nothing_else(joint_seed: int, kind: str, room: str) -> None:
    seed = 90 + list(ROOMS).index(room)
    stop = 2.0 + 0.25 * (seed % 7)
    scene = Scene(joint_seed, kind, stop_at=stop, seed=seed, **ROOMS[room])  # type: ignore[arg-type]
    events = detect(render(scene).astype(np.float32), _tuning(joint_seed, kind), step_rate_hz=scene.rate)
    got = [(round(e.onset_s, 3), round(e.detected_at_s, 3)) for e in events]
    assert len(events) == 1, f"stop at {stop:.3f} s; events (onset, detected) {got}"
    assert abs(events[0].onset_s - stop) <= 0.025, got
    assert 0.0 <= events[0].detected_at_s - stop <= 0.050, got


if __name__ == "__main__":  # the table of every condition: python tests/test_audio_modal.py
    for js in (2, 3, 5):
        for kind in ("quieter", "duller", "spectral", "louder"):
            for room in ROOMS:
                try:
                    test_one_stop_found_on_time_and_nothing_else(js, kind, room)
                    verdict = "pass"
                except AssertionError as e:
                    verdict = ("xfail " if (js, kind, room) in KNOWN else "FAIL ") + str(e).splitlines()[0][:90]
                print(f"arm {js} {kind:9s} {room:30s} {verdict}")
