"""The silent errors left by rounds 9a and 9b, each pinned (round 10a, docs/audio-log.md "Round 10a").

* **A false "listening began at the stop"** (``TemplateState._started_at_stop``): in the
  fifth generator's strongest rooms (reverberation -10 to -9 dB, T60 0.22-0.3 s) at
  1004-1048 Hz, and on arm 6's shifted stop at 1038 Hz, the first 0.18 s of *stepping*
  fitted the stop's signature on the sub-band levels (``b`` 0.95-2.1, the stop explaining
  79-86 % of what a gain change leaves), 1.6-2.4 s before the real stop: the detector
  fired at once. The continuum between the step clock's lines said no (``b`` -0.1 to 0.02,
  or a continuum signature that is a gain change only). Now the levels need the
  continuum's agreement where the tuning holds it.
* **Arm 8's shifted stop 37 ms late** (round 9b's scan, run on code without round 9a's
  climb check): round 9a's retiming takes its onset back to -6 ms. Pinned here so it stays.
"""

from __future__ import annotations

import arrival_sound as ar
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import test_audio_onset as on
import test_audio_shifted as sh
from stickslip.audio.detector import StopEvent, detector_for
from stickslip.audio.tuningfile import Tuning
from test_audio_rate_signature import tuned_alone

TOL_S = 0.025
SR = 48_000


def _heard_at_once(tu: Tuning, x: np.ndarray) -> list[StopEvent]:
    """The events of the first 0.6 s whose onset is the start of listening (the raw detector, no confirmation)."""
    det = detector_for(tu)
    return [e for e in det.feed(np.asarray(x[: int(0.6 * SR)], dtype=np.float32)) if e.onset_s < 0.02]


def _strong_room(seed: int, rate: float, t60_s: float, reverb_db: float) -> tuple[tuple[int, str], ar.Scene]:
    arm, s = on._draw(np.random.default_rng(seed))
    return arm, ar.Scene(**{**s.__dict__, "rate": rate, "t60_s": t60_s, "reverb_db": reverb_db})


# (draw seed, rate Hz, T60 s, reverberation dB, the arm): stepping 1.6-2.4 s before the stop, heard "at once" before
STRONG_ROOMS = [
    (3947455562, 1010.5837371303755, 0.2396441813794542, -9.231483001103745, (1, "stiff")),
    (1467997160, 1003.6595036195483, 0.23945723714450617, -9.743132532772897, (6, "damped")),
    (3857886077, 1048.2483871989868, 0.2620503618529803, -9.850951976629288, (6, "damped")),
    (2773352146, 1013.8566667435995, 0.22523191722893335, -9.833794834407028, (1, "stiff")),
    (2926755867, 1013.0362360911859, 0.24466551604284645, -9.486532176728975, (1, "stiff")),
]


@pytest.mark.slow
def test_stepping_in_the_strongest_room_is_not_taken_for_a_stop_at_the_start() -> None:
    """Five draws of the onset property's domain in its strongest room (a throwaway scan found 6 in 150): each fired
    at once on stepping; now none does, and the confirmed first event is on time or missed (the stop then falls in
    the template learned in the room; a traverse times out, which is safe), never silently wrong."""
    outcomes = []
    for seed, rate, t60, rv, want_arm in STRONG_ROOMS:
        arm, s = _strong_room(seed, rate, t60, rv)
        assert arm == want_arm and s.stop_at is not None and s.stop_at > 1.5
        tu = on._arrival_tuning(*arm)
        x = ar.render(s)
        assert _heard_at_once(tu, x) == [], (arm, rate)
        ev, det = on._first(tu, x)
        assert not on._silently_wrong(ev, s.stop_at), (arm, rate, ev, det.log.onset)
        outcomes.append(None if ev is None else round(1e3 * (ev.onset_s - s.stop_at)))
    assert [o is not None for o in outcomes] == [False, True, True, False, False], outcomes  # measured: 0 and 1 ms


def test_arm_6s_shifted_stop_is_not_heard_at_the_start_of_stepping_at_1038_hz() -> None:
    """Round 9b's scan: arm 6's shifted stop, draw 5 (1038 Hz, 3.8 % over the tuning): "-2122 ms, confirmed, unflagged".
    It was the start rule: 3.8 % faster stepping moves the click train's lines up as the stop moves the modes up, and
    the levels fitted the stop (b 0.95); the continuum did not (b -0.09). Now: not heard at all (a traverse times
    out)."""
    s = sh._arrival_draws(6)[5]
    assert s.stop_at is not None and round(s.rate) == 1038
    tu = sh._arrival_tuning(6)
    x = ar.render(s)
    assert _heard_at_once(tu, x) == []
    ev, det = on._first(tu, x)
    assert not on._silently_wrong(ev, s.stop_at), (ev, det.log.onset)


@pytest.mark.slow
def test_arm_8s_shifted_stop_that_was_37_ms_late_is_taken_back_on_time() -> None:
    """Round 9b's scan, arm 8's draw 10 (1034 Hz, 8 steps of arrival): fired with its onset +37 ms, unflagged, on code
    without round 9a's climb check; the climb (5 ms) held from an earlier hot frame, so the onset is taken back. On the
    tuned signature alone: round 11a's second fit hears it on time without taking it back."""
    s = sh._arrival_draws(8)[10]
    assert s.stop_at is not None
    ev, det = on._first(tuned_alone(sh._arrival_tuning(8)), ar.render(s))
    assert ev is not None and not ev.onset_uncertain and abs(ev.onset_s - s.stop_at) <= TOL_S, ev
    ((_, fired, taken),) = det.log.retime
    assert fired - s.stop_at > TOL_S  # the crossing that fired was 37 ms late
    assert round(1e3 * (fired - taken)) == 43


def test_a_recording_that_starts_at_the_stop_is_still_heard_at_once() -> None:
    """What must not be lost: where the continuum agrees (b 0.65, under the 0.7 it needs alone) the levels' verdict
    stands (arm 1's stiff stop at 1014 Hz, b 1.66 on the levels); and where the continuum shows the stop by itself
    (arm 2's stiff stop at 1048 Hz, b 1.04) it is heard at once as before."""
    _, s = on._draw(np.random.default_rng(994985987))
    s = ar.Scene(**{**s.__dict__, "rate": 1014.3452429561087, "t60_s": 0.20924515273954553,
                    "reverb_db": -15.076794175792227, "stop_at": 0.0, "dur": 0.8})  # fmt: skip
    assert s.arm == ar.Arm(1, "stiff")
    assert len(_heard_at_once(on._arrival_tuning(1, "stiff"), ar.render(s))) == 1
    _, s = on._draw(np.random.default_rng(0))
    s = ar.Scene(**{**s.__dict__, "arm": ar.Arm(2, "stiff"), "rate": 1048.0, "stop_at": 0.0, "dur": 0.8})
    assert len(_heard_at_once(on._arrival_tuning(2, "stiff"), ar.render(s))) == 1


@pytest.mark.slow
@settings(max_examples=12, deadline=None)
@example(seed=3947455562, t60_s=0.2396441813794542, reverb_db=-9.231483001103745, rate=1010.5837371303755)
@given(
    seed=st.integers(0, 2**32 - 1),
    t60_s=st.floats(0.2, 0.3),
    reverb_db=st.floats(-10.0, -9.0),
    rate=st.floats(950.0, 1050.0),
)
def test_stepping_in_a_strong_room_never_fires_at_once(seed: int, t60_s: float, reverb_db: float, rate: float) -> None:
    """Any arm of the onset property (:data:`test_audio_onset.ARMS`) stepping in the domain's strongest rooms, at rates
    within the warning, its stop 1.5-2.5 s later: nothing at the start of listening (a throwaway scan before: 6 of 150
    fired). The whole recording is rendered (its level and noise are set over all of it), the first 0.6 s heard."""
    arm, s = _strong_room(seed, rate, t60_s, reverb_db)
    assert s.stop_at is not None and s.stop_at >= 1.5
    assert _heard_at_once(on._arrival_tuning(*arm), ar.render(s)) == [], (arm, s)


@pytest.mark.xfail(
    strict=True,
    reason="measured (round 10a, a throwaway scan of 1000 draws at 800-1200 Hz): arm 2's damped stop at 1004 Hz in "
    "the strongest room (T60 0.26 s, -9.5 dB) crosses +25.3 ms late after a climb of 13 ms, under the 20 ms slow-rise "
    "limit (OnsetParams.slow_s): the room's tail delays the crossing; unflagged, 0.3 ms beyond the tolerance",
)
def test_arm_2s_damped_stop_in_the_strongest_room_at_1004_hz_is_never_silently_wrong() -> None:
    arm, s = on._draw(np.random.default_rng(1764737161))
    s = ar.Scene(**{**s.__dict__, "t60_s": 0.25845635152551505, "reverb_db": -9.544863829396984,
                    "rate": 1003.64385139928})  # fmt: skip
    assert arm == (2, "damped") and s.stop_at is not None
    ev, det = on._first(on._arrival_tuning(*arm), ar.render(s))
    assert ev is not None and not on._silently_wrong(ev, s.stop_at), (ev, det.log.rise)
