"""A fan switching on before the stop, pauses with no stop, another instrument in bursts: an acoustic generator.

Issue 35 (item 6): on an independent battery one draw gave a false stop and then missed the
stop when a fan switched on shortly before it, and two false stops over pauses in the
stepping. These tests come from the tenth generator (``tests/support/fan_sound.py``: slip
pulses of finite length through a bank of resonators, a fan that spins up by the fan laws,
pauses), written before the detector was changed for them and never used to tune it.

Each arm is tuned on its own quiet 1000 Hz recording and heard as a traverse hears it (the
confirming detector, told the commanded rate). A fan switched on 0.3-1.0 s before the stop,
at -4 to +4 dB of the stepping's level: the first event must be the stop, its onset within
25 ms, or flagged (a traverse refuses it: never a wrong count). Two pauses of 0.2-0.8 s and
no stop: no event at all. Another arm of the generator stepping at 730 Hz in bursts of
0.3-0.8 s (gaps 0.4-1.2 s), as loud as the joint (RMS), in the tuning recording, the test
recording or both: the tuning may refuse (never a wrong count), else the first event is the
stop within 25 ms, or flagged. A test recording 12-20 dB louder than the tuning's: the stop
within 25 ms, heard within 50 ms (the battery's latency bound). A test stepping 20 % slower
or faster than the tuning, the commanded rate told: the stop within 25 ms. Draws that fail
today are strict xfails with what was measured; ``benchmarks/bench_audio_tenth.py`` runs the
same conditions on other draws.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from fan_sound import SR, Arm, Scene, render, tuning_scene
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent
from stickslip.audio.tuning import TuningError
from stickslip.audio.tuningfile import Tuning

STOP_S = 2.4
TOL_S = 0.025
ARMS = range(1, 9)
#: (arm, draw) -> what was measured (the detector as of this test's writing)
FAN_KNOWN = {
    (3, 1): "the stop flagged, its onset 201 ms late (the fan's spin-up 0.86 s before it, +0.7 dB; before the"
    " clocked check read the lines in step: a false stop 315 ms before the stop, counted); its window rejected 0.2 s"
    " after the stop: too little of it to look for the stop inside on the joint's clock (confirm.inside, 0.48 s)",
    (6, 0): "the stop flagged, not heard cleanly (fan 0.68 s before it, -1.3 dB): its fire at the stop hot in 21 % of"
    " the window and its lines not read in phase (line 5 held 16 % of its power in phase under the fan): not affirmed",
    (6, 1): "the stop flagged, heard 32 ms late: its stop-like run began at 2.395 s, the hot verdict held back by the"
    " fan (0.56 s before it, -1.0 dB; before the lines in phase affirmed a fire not hot: missed)",
}


@cache
def _tuning(arm: int) -> Tuning:
    return tune(render(tuning_scene(Arm(arm))), SR, 2.0)


def _events(tu: Tuning, y: np.ndarray, rate_hz: float = 1000.0) -> list[StopEvent]:
    det = ConfirmedStopDetector(detector_for(tu))
    det.reset(0.0, step_rate_hz=rate_hz)  # as a traverse tells it
    return det.feed(y) + det.finish()


def _fan_draw(arm: int, k: int, other: int = 0) -> Scene:
    """The fan's ``k``-th draw for ``arm`` (``other`` > 0: another battery, every seed moved by 1000 x other)."""
    rng = np.random.default_rng(arm + 1000 * other)
    draws = [(float(rng.uniform(0.3, 1.0)), float(rng.uniform(-4.0, 4.0))) for _ in range(2)]
    lead, fan_db = draws[k]
    return Scene(
        Arm(arm), stop_at=STOP_S, dur=3.4, fan_at=STOP_S - lead, fan_db=fan_db, seed=100 + 10 * arm + k + 1000 * other
    )


def _pause_draw(arm: int, other: int = 0) -> Scene:
    rng = np.random.default_rng(arm + 1000 * other)
    for _ in range(4):  # the fan draws come first from the same stream
        rng.uniform()
    p1 = (float(rng.uniform(1.0, 1.5)), float(rng.uniform(0.2, 0.8)))
    p2 = (float(rng.uniform(2.4, 2.8)), float(rng.uniform(0.2, 0.8)))
    return Scene(Arm(arm), stop_at=None, dur=4.0, pauses=(p1, p2), seed=200 + arm + 1000 * other)


def _louder_draw(arm: int, other: int = 0) -> tuple[Scene, float]:
    """A test recording 12-20 dB louder than the tuning's (the gain in dB), with the stop at ``STOP_S``."""
    gain_db = float(np.random.default_rng(700 + arm + 1000 * other).uniform(12.0, 20.0))
    return Scene(Arm(arm), stop_at=STOP_S, dur=3.4, seed=400 + arm + 1000 * other), gain_db


def test_generator_levels() -> None:
    """The generator as documented: stepping at -30 dBFS; the fan at its level relative to it at full speed."""
    y = render(Scene(Arm(1), stop_at=None, dur=2.0, snr_db=80.0))
    assert 20 * np.log10(np.sqrt(np.mean(y.astype(np.float64) ** 2))) == pytest.approx(-30.0, abs=0.05)
    quiet = render(Scene(Arm(1), stop_at=None, dur=3.0, snr_db=80.0, seed=3))
    fan = render(Scene(Arm(1), stop_at=None, dur=3.0, snr_db=80.0, seed=3, fan_at=0.5, fan_db=6.0, spin_s=0.1))
    added = (fan - quiet)[int(2.0 * SR) :].astype(np.float64)
    assert 20 * np.log10(np.sqrt(np.mean(added**2))) == pytest.approx(-24.0, abs=0.5)  # -30 + 6 dB, at full speed
    assert np.all((fan - quiet)[: int(0.5 * SR)] == 0.0)  # silent before it is switched on


#: (arm, where the bursts are) -> what was measured. Before the floor was capped at the joint's own level
#: (stickslip.audio.change.added) bursts in the test recording gave 6 events 1.7-1.9 s early and 2 flags
BURSTS_KNOWN = {
    (3, "test"): "the stop flagged (before the floor was capped at the joint's own level: 1884 ms early)",
}


def _bursts(arm: int, dur: float, seed: int) -> np.ndarray:
    """Another arm stepping at 730 Hz in bursts, its RMS over the recording (gaps included) the joint's."""
    rng = np.random.default_rng(seed)
    t, pauses = 0.0, []
    while t < dur:
        on, off = float(rng.uniform(0.3, 0.8)), float(rng.uniform(0.4, 1.2))
        pauses.append((t + on, off))
        t += on + off
    return render(Scene(Arm(arm + 50), rate=730.0, stop_at=None, dur=dur, pauses=tuple(pauses), snr_db=80.0, seed=seed))


def _known(a: int, k: int) -> list[pytest.MarkDecorator]:
    return [pytest.mark.xfail(strict=True, reason=FAN_KNOWN[(a, k)])] if (a, k) in FAN_KNOWN else []


@pytest.mark.slow
@pytest.mark.parametrize(("arm", "k"), [pytest.param(a, k, marks=_known(a, k)) for a in ARMS for k in (0, 1)])
def test_fan_switching_on_before_the_stop(arm: int, k: int) -> None:
    events = _events(_tuning(arm), render(_fan_draw(arm, k)))
    assert events, "the stop was missed"
    first = events[0]
    assert first.onset_uncertain is False, "the stop was flagged"
    assert abs(first.onset_s - STOP_S) <= TOL_S, f"the first event is {1e3 * (first.onset_s - STOP_S):+.0f} ms off"


#: (arm, draw, other draw) -> (what the first event is now, what was measured before the lines read in phase with the
#: steps affirmed a fire the levels held but not hot, and were read from each stop's onset)
FAN_OTHER = {
    (6, 0, 1): ("right", "the stop missed: its fire stop-like throughout, hot in 14 % of the window (fan +0.8 dB)"),
    (6, 1, 3): ("right", "the stop missed: its fire stop-like throughout, hot in 23 % of the window (fan -1.3 dB)"),
    (3, 0, 2): ("flagged", "a false stop 137 ms early, counted: the fan's spin-up fired, the stop in its window"),
    (3, 1, 3): ("flagged", "a false stop 172 ms early, counted: the fan's spin-up fired, the stop in its window"),
}


@pytest.mark.slow
@pytest.mark.parametrize(("arm", "k", "other"), sorted(FAN_OTHER))
def test_fan_on_other_draws_the_stop_affirmed_in_phase_or_an_early_fire_doubted(arm: int, k: int, other: int) -> None:
    """The draws of ``bench_audio_tenth.py`` the lines in phase with the steps changed. Arm 6: the fan masks the stop's
    drops (the window stop-like throughout, not hot), the lines in phase vanish as the stop's do: the stop, right.
    Arm 3: the fan's spin-up fires before the stop and the stop comes in its window, so the window reads as a stop;
    the lines read in phase from the fire's onset are stepping: flagged, not counted."""
    expected, before = FAN_OTHER[(arm, k, other)]
    events = _events(_tuning(arm), render(_fan_draw(arm, k, other)))
    assert events, before
    first = events[0]
    err_ms = 1e3 * (first.onset_s - STOP_S)
    if expected == "flagged":
        assert first.onset_uncertain, f"{err_ms:+.0f} ms, counted ({before})"
    else:
        assert not first.onset_uncertain and abs(err_ms) <= 1e3 * TOL_S, f"{err_ms:+.0f} ms ({before})"


@pytest.mark.slow
@pytest.mark.parametrize("arm", ARMS)
def test_pauses_without_a_stop(arm: int) -> None:
    assert _events(_tuning(arm), render(_pause_draw(arm))) == []


#: (arm, other draw) -> what was measured before the detector waited for the stepping to come back after a pause
PAUSES_OTHER = {
    (3, 1): "a false stop at 2.079 s: restarted at 1.9 s in the 0.63 s pause, stepping back at 2.010 s",
    (3, 3): "a false stop at 1.780 s: restarted at 1.6 s in the 0.63 s pause, stepping back at 1.709 s",
}


@pytest.mark.slow
@pytest.mark.parametrize(("arm", "other"), sorted(PAUSES_OTHER))
def test_pauses_on_other_draws_restart_where_the_stepping_comes_back(arm: int, other: int) -> None:
    """The draws of ``bench_audio_tenth.py`` that failed: no event, and each restart where the stepping came back.

    A pause is judged 0.5 s after its fire; a pause that lasted longer is waited out, and the detector restarts
    within a piece (10 ms) of the first step after it; one that ended sooner restarts where it was judged.
    """
    scene = _pause_draw(arm, other)
    det = ConfirmedStopDetector(detector_for(_tuning(arm)))
    det.reset(0.0, step_rate_hz=1000.0)
    assert det.feed(render(scene)) + det.finish() == [], PAUSES_OTHER[(arm, other)]
    assert len(det.log.restarts) == len(scene.pauses) == 2
    for (judged, restarted), (start, length) in zip(det.log.restarts, scene.pauses, strict=True):
        back = start + length
        assert start < judged < start + 0.6
        if back <= judged:
            assert restarted == judged
        else:
            assert -0.010 <= restarted - back <= 0.030, (judged, restarted, back)


def _known_bursts(a: int, where: str) -> list[pytest.MarkDecorator]:
    why = BURSTS_KNOWN.get((a, where))
    return [pytest.mark.xfail(strict=True, reason=why)] if why else []


@pytest.mark.slow
@pytest.mark.parametrize(
    ("arm", "where"),
    [pytest.param(a, w, marks=_known_bursts(a, w)) for a in ARMS for w in ("training", "test", "both")],
)
def test_another_instrument_in_bursts(arm: int, where: str) -> None:
    x = render(tuning_scene(Arm(arm)))
    if where in ("training", "both"):
        x = (x + _bursts(arm, 3.2, 500 + arm)).astype(np.float32)
    y = render(Scene(Arm(arm), stop_at=STOP_S, dur=3.4, seed=300 + arm))
    if where in ("test", "both"):
        y = (y + _bursts(arm, 3.4, 600 + arm)).astype(np.float32)
    try:
        tu = tune(x, SR, 2.0)
    except TuningError:
        return  # refused: the tuning names the stepping that sounds like the stop; never a wrong count
    events = _events(tu, y)
    assert events, "the stop was missed"
    assert events[0].onset_uncertain is False, "the stop was flagged"
    err_ms = 1e3 * (events[0].onset_s - STOP_S)
    assert abs(err_ms) <= 1e3 * TOL_S, f"the first event is {err_ms:+.0f} ms off"


#: (arm, where) -> what was measured where the tuning told the commanded rate does not count the stop right
TOLD_KNOWN = {
    (3, "both"): "flagged: a burst in the test began 0.1 s before the stop and fired; the joint's lines changed later",
}


@pytest.mark.slow
@pytest.mark.parametrize(("arm", "where"), [(a, w) for a in ARMS for w in ("training", "both")])
def test_another_instrument_in_the_training_left_out_where_the_rate_is_told(arm: int, where: str) -> None:
    """Told the commanded rate (as a traverse's recording tells it), the tuning keeps the joint's clock and leaves out
    the pieces the other instrument's holds (``stickslip.audio.tuning.clocks``); it may still refuse (too little
    left). Not refused: the first event is the stop within 25 ms, or flagged where listed; never a wrong count.
    Untold, every one of these tunings with a second clock heard is refused (``test_another_instrument_in_bursts``)."""
    x = (render(tuning_scene(Arm(arm))) + _bursts(arm, 3.2, 500 + arm)).astype(np.float32)
    y = render(Scene(Arm(arm), stop_at=STOP_S, dur=3.4, seed=300 + arm))
    if where == "both":
        y = (y + _bursts(arm, 3.4, 600 + arm)).astype(np.float32)
    try:
        tu = tune(x, SR, 2.0, step_rate_hz=1000.0)
    except TuningError:
        return  # refused (too little left, or the tuning's own checks): never a wrong count
    events = _events(tu, y)
    assert events, "the stop was missed"
    err_ms = 1e3 * (events[0].onset_s - STOP_S)
    if (arm, where) in TOLD_KNOWN:
        assert events[0].onset_uncertain, f"{err_ms:+.0f} ms, counted ({TOLD_KNOWN[(arm, where)]})"
        return
    assert events[0].onset_uncertain is False, "the stop was flagged"
    assert abs(err_ms) <= 1e3 * TOL_S, f"the first event is {err_ms:+.0f} ms off"


#: (arm, other draw) -> what was measured before a stop inside a rejected window was looked for on the joint's clock
BURSTS_OTHER = {
    (1, 1): "flagged: the stop heard at the un-latching of a window rejected since 1.06 s",
    (3, 1): "missed: the stop inside a window rejected at its end (1.26-3.26 s), no fire after it",
    (3, 3): "missed: the stop inside a window rejected at its end (1.15-3.15 s), no fire after it",
}


@pytest.mark.slow
@pytest.mark.parametrize(("arm", "other"), sorted(BURSTS_OTHER))
def test_bursts_in_the_test_on_other_draws_the_stop_found_inside_a_rejected_window(arm: int, other: int) -> None:
    """The draws of ``bench_audio_tenth.py`` with bursts in the test recording that the joint's clock read in phase
    changed: the levels learnt the other instrument from the first sample (the joint alone then reads stop-like, its
    stop does not), a fire on a burst's end was rejected after its 2 s window, and the stop began inside it. Read in
    phase at the commanded rate the window shows the stepping, then the stop: found there, its onset within 25 ms."""
    y = render(Scene(Arm(arm), stop_at=STOP_S, dur=3.4, seed=300 + arm + 1000 * other))
    events = _events(_tuning(arm), (y + _bursts(arm, 3.4, 600 + arm + 1000 * other)).astype(np.float32))
    assert events, BURSTS_OTHER[(arm, other)]
    err_ms = 1e3 * (events[0].onset_s - STOP_S)
    assert events[0].found_late and not events[0].onset_uncertain, BURSTS_OTHER[(arm, other)]
    assert abs(err_ms) <= 1e3 * TOL_S, f"{err_ms:+.0f} ms ({BURSTS_OTHER[(arm, other)]})"


#: arm -> what was measured when the test was written (before any change for it)
LOUDER_KNOWN: dict[int, str] = {}


def _known_louder(a: int) -> list[pytest.MarkDecorator]:
    return [pytest.mark.xfail(strict=True, reason=LOUDER_KNOWN[a])] if a in LOUDER_KNOWN else []


@pytest.mark.slow
@pytest.mark.parametrize("arm", [pytest.param(a, marks=_known_louder(a)) for a in (1, 3, 5, 7)])
def test_a_test_recorded_12_to_20_db_louder_than_the_tuning(arm: int) -> None:
    """Half the arms (CI's time): all eight, on four draws each, in ``benchmarks/bench_audio_tenth.py``."""
    scene, gain_db = _louder_draw(arm)
    y = (render(scene) * np.float32(10 ** (gain_db / 20))).astype(np.float32)
    events = _events(_tuning(arm), y)
    assert events, f"the stop was missed ({gain_db:.1f} dB louder)"
    first = events[0]
    assert first.onset_uncertain is False, f"the stop was flagged ({gain_db:.1f} dB louder)"
    err_ms = 1e3 * (first.onset_s - STOP_S)
    assert abs(err_ms) <= 1e3 * TOL_S, f"the first event is {err_ms:+.0f} ms off ({gain_db:.1f} dB louder)"
    assert first.detected_at_s - STOP_S <= 0.050, f"heard {1e3 * (first.detected_at_s - STOP_S):.0f} ms after the stop"


#: arm -> what was measured when the test was written (the detector told the commanded rate)
RATE_KNOWN: dict[int, str] = {}


def _rate_draw(arm: int, other: int = 0) -> Scene:
    """A test recording stepping 20 % slower (odd arms) or faster (even arms) than the 1000 Hz tuning."""
    return Scene(Arm(arm), rate=800.0 if arm % 2 else 1200.0, stop_at=STOP_S, dur=3.4, seed=800 + arm + 1000 * other)


def _known_rate(a: int) -> list[pytest.MarkDecorator]:
    return [pytest.mark.xfail(strict=True, reason=RATE_KNOWN[a])] if a in RATE_KNOWN else []


@pytest.mark.slow
@pytest.mark.parametrize("arm", [pytest.param(a, marks=_known_rate(a)) for a in (2, 4, 5, 7)])
def test_stepping_20_percent_off_the_tuning_with_the_commanded_rate_told(arm: int) -> None:
    """Two arms slower, two faster (CI's time; all eight pass, told and untold: docs/audio-log.md)."""
    scene = _rate_draw(arm)
    events = _events(_tuning(arm), render(scene), scene.rate)
    assert events, f"the stop was missed at {scene.rate:.0f} Hz"
    first = events[0]
    assert first.onset_uncertain is False, f"the stop was flagged at {scene.rate:.0f} Hz"
    err_ms = 1e3 * (first.onset_s - STOP_S)
    assert abs(err_ms) <= 1e3 * TOL_S, f"the first event is {err_ms:+.0f} ms off at {scene.rate:.0f} Hz"
