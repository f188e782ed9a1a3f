"""A confirmed stop is never counted at a wrong time without a flag (round 8b).

A traverse counts its steps to the confirmed event's ``onset_s``; an event flagged
``onset_uncertain`` is refused ("measure again"), which is safe. An onset early or late by
more than 25 ms *without* the flag is a silently wrong count. The cases here were found
on today's generators (the battery's drift and talk, the fourth generator's arms) and on a
fifth one written for it (``arrival_sound``: the stop arrives over a few steps as the joint
loads it, in a reverberant room, under a jittered clock whose rate wanders, with a burst of
interference around the stop). Each pinned case counted silently wrong before
:meth:`ConfirmedStopDetector._onset_doubt`; each is now flagged.
"""

from __future__ import annotations

from functools import cache

import arrival_sound as ar
import battery_sound as bs
import modal_sound as ms
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.detector import StopEvent, detector_for
from stickslip.audio.tuning import TuningError
from stickslip.audio.tuningfile import Tuning
from test_audio_rate_signature import tuned_alone

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

TOL_S = 0.025
SR = 48_000


def _first(tu: Tuning, y: np.ndarray) -> tuple[StopEvent | None, ConfirmedStopDetector]:
    det = ConfirmedStopDetector(detector_for(tu))
    events = det.feed(np.asarray(y, dtype=np.float32)) + det.finish()
    return (events[0] if events else None), det


def _silently_wrong(ev: StopEvent | None, stop_at: float) -> bool:
    return ev is not None and not ev.onset_uncertain and abs(ev.onset_s - stop_at) > TOL_S


@cache
def _battery_tuning(joint: str, seed: int) -> Tuning:
    x, sr = bs.render(bs.Scene(joint, 1000.0, 2.0, 3.0, seed=seed))
    return tune(x, sr, 2.0, seed=0)


@cache
def _modal_tuning(joint_seed: int, kind: str) -> Tuning:
    return tune(ms.render(ms.Scene(joint_seed, kind, stop_at=3.0, dur=4.5, seed=10)), SR, 3.0)


@cache
def _arrival_tuning(seed: int, kind: str) -> Tuning:
    return tune(ar.render(ar.tuning_scene(ar.Arm(seed, kind))), SR, 2.0)


# (joint, rate, drift, seed, why it is flagged, what round 7b's code did); the step clock drifts 10 % over 2 s, the stop
# at 1.4 s
DRIFT = [
    ("P", 834.6815007897175, -0.1, 969018, "a gap after the fire", "a false fire, a 93 ms gap, the stop: -127 ms"),
    ("Q", 981.7488086727872, -0.1, 826159, "a fire weaker than the stop", "a weak false fire into the stop: -97 ms"),
    ("P", 1135.5254606088138, -0.1, 341026, "a stop heard late", "stop-like from 0 s, hot 0.43 s later: +429 ms"),
    ("Q", 867.6947732806664, 0.1, 440314, "a stop heard late", "at full level from 0 s, hot at +83 ms: +59 ms"),
]


@pytest.mark.parametrize(("joint", "rate", "drift", "seed", "why", "before"), DRIFT, ids=[d[5][:40] for d in DRIFT])
def test_a_drifting_rate_into_the_stop_is_flagged_not_counted_wrong(
    joint: str, rate: float, drift: float, seed: int, why: str, before: str
) -> None:
    scene = bs.Scene(joint, 1000.0, 2.0, 3.0, seed=1 if joint == "P" else 2)
    y, _ = bs.render(bs.variant(scene, seed=seed, stop_at=1.4, dur=2.0, rate=rate, drift=drift))
    ev, det = _first(_battery_tuning(joint, 1 if joint == "P" else 2), y)
    assert ev is not None and ev.onset_uncertain, (before, ev)
    assert det.log.onset == [(ev.detected_at_s, why)]


def test_a_voice_over_arm_3s_louder_stop_that_held_it_back_is_flagged() -> None:
    """The stop at its level from 0 s, a syllable hiding its drops: hot only at +86 ms; before, +41 ms unflagged."""
    stop = 2.0 + 0.25 * (92 % 7)  # the modal table's "a voice from the first sample" room: seed 92
    x = ms.render(ms.Scene(3, "louder", stop_at=stop, seed=92, voice_db=0.0))
    ev, det = _first(_modal_tuning(3, "louder"), x)
    assert ev is not None and ev.onset_uncertain and ev.onset_s - stop > TOL_S  # the onset itself is unchanged
    assert [w for _, w in det.log.onset] == ["a stop heard late"]


def test_knocks_just_before_arm_3s_spectral_stop_are_flagged() -> None:
    """A knock fires 0.14 s before the stop, a 117 ms gap follows, then the stop persists: before, -139 ms unflagged."""
    stop = 2.0 + 0.25 * (93 % 7)  # the modal table's "knocks" room: seed 93
    x = ms.render(ms.Scene(3, "spectral", stop_at=stop, seed=93, knocks=True))
    ev, det = _first(_modal_tuning(3, "spectral"), x)
    assert ev is not None and ev.onset_uncertain and ev.onset_s < stop - TOL_S
    assert [w for _, w in det.log.onset] == ["a gap after the fire"]


@pytest.mark.parametrize(("joint", "seed"), [("P", 1), ("Q", 2)])
def test_a_clean_stop_keeps_its_onset_unflagged(joint: str, seed: int) -> None:
    """What must not be lost: a stop in a quiet room is counted, at its onset, without a flag."""
    y, _ = bs.render(bs.Scene(joint, 1080.0, 2.0, 3.0, seed=40 + seed))
    ev, det = _first(_battery_tuning(joint, seed), y)
    assert ev is not None and not ev.onset_uncertain and abs(ev.onset_s - 2.0) <= TOL_S
    assert det.log.onset == []


@pytest.mark.parametrize(("joint", "seed"), [("P", 1), ("Q", 2)])
def test_a_recording_that_starts_at_the_stop_is_not_flagged(joint: str, seed: int) -> None:
    """Heard at once at the warm-up's end (no stop-likeness before it): the onset is the start, unflagged."""
    y, _ = bs.render(bs.Scene(joint, 1080.0, 0.0, 1.0, seed=50 + seed))
    ev, det = _first(_battery_tuning(joint, seed), y)
    assert ev is not None and not ev.onset_uncertain and abs(ev.onset_s) <= TOL_S
    assert det.log.onset == []


# the arms the fifth generator's tuning accepts, with a stop that is heard (the shifted stop, every mode 4-12 % up, was
# missed in 63 of 100 draws before round 9b's finer sub-bands, and is still often missed at other step rates:
# tests/test_audio_shifted.py; arm 4's stiff stop sits just
# over the threshold, and frames before it that flicker over the threshold set its crossing up to 40 ms early:
# docs/audio-log.md, "When did the stop begin?")
ARMS = [(s, k) for s in (1, 2, 3, 5, 6) for k in ("stiff", "damped")]


def _covered_scene(burst_s: float, burst_db: float, **kw: object) -> ar.Scene:
    """Arm 2's damped stop, heard on time; 50 ms later a hiss covers it (a jet of air, a fricative)."""
    base = {
        "arm": ar.Arm(2, "damped"), "rate": 894.9291534446011, "stop_at": 1.9927504461722312, "dur": 3.5,
        "arrive_steps": 4, "jitter": 0.023199629140428814, "wander": 0.0024900136293833607,
        "t60_s": 0.37886893638161345, "reverb_db": -13.90276512229496, "snr_db": 26.56773393848928,
        "burst": "hiss", "burst_from": 0.05, "burst_s": burst_s, "burst_db": burst_db, "seed": 849951,
    }  # fmt: skip
    return ar.Scene(**{**base, **kw})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("scene", "why", "before"),
    [
        (
            _covered_scene(0.3019118609697671, -7.616563592313124),
            "a stop covered before",
            "the stop again after the hiss: +359 ms",
        ),
        (
            _covered_scene(
                1.0,
                0.0,
                rate=800.0,
                stop_at=2.0,
                arrive_steps=1,
                jitter=0.015625,
                wander=0.0,
                t60_s=0.25,
                reverb_db=-6.0,
                snr_db=35.0,
                seed=1,
            ),
            "a template learned anew since a rejected fire",
            "rejected, the template learned over the stop and the hiss, the stop after it: +1043 ms",
        ),  # fmt: skip
    ],
    ids=["re-fired inside the window", "heard again after the window"],
)
def test_a_stop_covered_after_its_fire_is_flagged_when_heard_again(scene: ar.Scene, why: str, before: str) -> None:
    """The fire on the stop is dropped (the hiss breaks its persistence); the stop heard again later is flagged."""
    assert scene.stop_at is not None
    ev, det = _first(_arrival_tuning(scene.arm.seed, scene.arm.stop_kind), ar.render(scene))
    assert [round(e.onset_s - scene.stop_at, 2) for e in det.log.rejected] in ([0.01], [0.02])  # heard on time, dropped
    assert ev is not None and ev.onset_uncertain and ev.onset_s - scene.stop_at > TOL_S, before
    assert [w for _, w in det.log.onset] == [why]


def _draw(rng: np.random.Generator) -> tuple[tuple[int, str], ar.Scene]:
    """One scene of the domain: any arm, a rate within the tuning's 1000 Hz +-5 % (beyond it traverse and listen warn),
    arrival over 1-11 steps, a jittered clock, a reverberant room, no burst."""
    arm = ARMS[int(rng.integers(len(ARMS)))]
    s = ar.Scene(
        arm=ar.Arm(*arm), rate=float(rng.uniform(950, 1050)), stop_at=float(rng.uniform(1.5, 2.5)), dur=3.5,
        arrive_steps=int(rng.integers(1, 12)), jitter=float(rng.uniform(0.002, 0.03)), wander=0.0,
        t60_s=float(rng.uniform(0.05, 0.3)), reverb_db=float(rng.uniform(-18, -9)), snr_db=float(rng.uniform(25, 40)),
        burst="none", seed=int(rng.integers(1, 10**6)),
    )  # fmt: skip
    return arm, s


def test_no_unflagged_onset_error_beyond_25_ms_on_40_draws_of_the_fifth_generator() -> None:
    """40 fixed draws of the domain (:func:`_draw`): right, flagged, heard at once or missed; none silently wrong.

    Measured (session 25): 33 right, 6 flagged or heard at once, 1 missed, none silently wrong. This was a hypothesis
    property over fresh draws; fresh draws found two silent errors (a 19 % slower rate, outside the warning, and the
    strongest reverberation of the domain), pinned below, so the test became this fixed sample, which it must keep.
    Round 9a (the climb to the onset judged): the property over fresh draws is back below, over the room and rates.
    """
    rng = np.random.default_rng(2026)
    outcomes = {"right": 0, "flagged": 0, "missed": 0}
    for _ in range(40):
        arm, s = _draw(rng)
        assert s.stop_at is not None
        ev, det = _first(_arrival_tuning(*arm), ar.render(s))
        assert not _silently_wrong(ev, s.stop_at), (arm, s, ev, getattr(det, "onset_log", None))
        key = "missed" if ev is None else "flagged" if ev.onset_uncertain or ev.onset_s < 0.02 else "right"
        outcomes[key] += 1
    assert outcomes["right"] >= 30, outcomes  # measured 33: the check is not met by flagging everything


def _strongest_room() -> ar.Scene:
    return ar.Scene(
        arm=ar.Arm(2, "damped"), rate=950.0, stop_at=2.375, dur=3.5, arrive_steps=1, jitter=0.025390625,
        wander=0.0, t60_s=0.28125, reverb_db=-9.0, snr_db=25.0, burst="none", seed=438,
    )  # fmt: skip


def _far_rate() -> ar.Scene:
    return ar.Scene(
        arm=ar.Arm(1, "stiff"), rate=813.0, stop_at=2.0, dur=3.5, arrive_steps=1, jitter=0.015625,
        wander=0.0, t60_s=0.25, reverb_db=-9.0, snr_db=25.0, burst="none", seed=1,
    )  # fmt: skip


def test_the_strongest_reverberation_of_the_domain_is_heard_on_time() -> None:
    """Arm 2's damped stop at 950 Hz in the domain's strongest room (-9 dB, T60 0.28 s).

    Its stop-likeness climbs in 8 ms to the threshold, hot at +28 ms, then wavers under it while
    the room's tail fills what the stop empties, and the hold begins again: the fire at +70 ms took
    its onset from the second crossing, +37 ms, unflagged (a fresh hypothesis draw, session 25).
    Round 9a takes the onset back to the first hot frame the climb held from: +14 ms. Pinned on the tuned signature
    alone: with round 11a's second fit (950 Hz, 5 % off) the fire is on time without being taken back
    (``tests/test_audio_rate_signature.py``).
    """
    ev, det = _first(tuned_alone(_arrival_tuning(2, "damped")), ar.render(_strongest_room()))
    assert ev is not None and not ev.onset_uncertain and abs(ev.onset_s - 2.375) <= TOL_S, ev
    assert [round(1e3 * (fired - taken)) for _, fired, taken in det.log.retime] == [22]
    assert det.log.onset == []


def test_a_rate_far_from_the_tuning_s_is_never_silently_wrong() -> None:
    """19 % slower than the tuning (arm 1's stiff stop at 813 Hz; a traverse warns beyond 5 %).

    The stepping's stop-likeness sits near the threshold (0.7 of it), the stop crosses it at
    +8 ms but shows its drops only at +45 ms, and the onset, +42 ms, was unflagged (a fresh
    hypothesis draw, session 25). Round 9a: flagged, a stepping near the threshold whose climb
    crossed it more than 25 ms before the onset.
    """
    ev, det = _first(_arrival_tuning(1, "stiff"), ar.render(_far_rate()))
    assert ev is not None and not _silently_wrong(ev, 2.0), ev
    assert ev.onset_uncertain and [w for _, w in det.log.onset] == ["a stepping near the threshold"]


@settings(max_examples=8, deadline=None)
@example(seed=52023, t60_s=0.25, reverb_db=-10.0, rate=1090.65625)  # arm 2 damped, 11 steps: +47 ms, slow (31 ms)
@example(seed=1467997160, t60_s=0.23945723714450617, reverb_db=-9.743132532772897, rate=1003.6595036195483)  # at once
@example(seed=3857886077, t60_s=0.2620503618529803, reverb_db=-9.850951976629288, rate=1048.2483871989868)  # at once
@given(
    seed=st.integers(0, 2**32 - 1),
    t60_s=st.floats(0.05, 0.3),
    reverb_db=st.floats(-18.0, -9.0),
    rate=st.floats(950.0, 1050.0),
)
def test_no_room_and_rate_of_the_domain_counts_silently_wrong(
    seed: int, t60_s: float, reverb_db: float, rate: float
) -> None:
    """Fresh draws of the fifth generator (any arm, arrival, clock) over the room's whole range, the strongest
    reverberation included, at rates within the warning (5 %): on time, flagged, heard at once or missed; never
    silently wrong. Beyond the warning it is not so: 4 of 1000 throwaway draws at 800-1200 Hz (docs/audio.md).
    Heard at once (round 9a's seeds 3 and 8): arm 6's damped stop at 1049 Hz in the strongest room was judged to be
    there from the start (``template._started_at_stop``), 1.9 s before it; this property let it pass as "heard at
    once" until round 10a, which made the levels' verdict on the start need the continuum's agreement: a stop heard
    at once here (1.5-2.5 s before the stop) is a false stop and fails (``tests/test_audio_silent.py``).
    """
    arm, s = _draw(np.random.default_rng(seed))
    s = ar.Scene(**{**s.__dict__, "t60_s": t60_s, "reverb_db": reverb_db, "rate": rate})
    assert s.stop_at is not None
    ev, det = _first(_arrival_tuning(*arm), ar.render(s))
    assert not _silently_wrong(ev, s.stop_at), (arm, s, ev, det.log.onset, det.log.rise)


def whole_and_in_blocks(tu: Tuning, x: np.ndarray, block: int) -> tuple[ConfirmedStopDetector, ConfirmedStopDetector]:
    """The confirming detector fed ``x`` whole and in ``block``-sample blocks; asserts the same events; both."""
    ref = ConfirmedStopDetector(detector_for(tu))
    want = ref.feed(x) + ref.finish()
    det = ConfirmedStopDetector(detector_for(tu))
    got = [e for i in range(0, x.size, block) for e in det.feed(x[i : i + block])] + det.finish()
    assert [(e.onset_s, e.detected_at_s, e.onset_uncertain) for e in got] == [
        (e.onset_s, e.detected_at_s, e.onset_uncertain) for e in want
    ]
    return ref, det


@pytest.mark.parametrize("block", [128, 777, 4096, 65536])
def test_the_onset_check_does_not_depend_on_the_block_size(block: int) -> None:
    """Four pinned cases (one taken back), in blocks of 128 to 65536 samples: the same events, doubts, onsets. On the
    tuned signature alone (round 11a's second fit hears the taken-back one on time; its own block-size test is in
    ``tests/test_audio_rate_signature.py``)."""
    y, _ = bs.render(bs.variant(bs.Scene("Q", 1000.0, 2.0, 3.0, seed=2), seed=826159, stop_at=1.4, dur=2.0,
                                rate=981.7488086727872, drift=-0.1))  # fmt: skip
    scene = _covered_scene(0.3019118609697671, -7.616563592313124)
    for tu, x in (
        (_battery_tuning("Q", 2), y),
        (_arrival_tuning(2, "damped"), ar.render(scene)),
        (_arrival_tuning(2, "damped"), ar.render(_strongest_room())),  # taken back
        (_arrival_tuning(1, "stiff"), ar.render(_far_rate())),
    ):
        ref, det = whole_and_in_blocks(tuned_alone(tu), x, block)
        assert det.log.onset == ref.log.onset and det.log.rise == ref.log.rise and det.log.retime == ref.log.retime
        assert len(det.log.onset) + len(det.log.retime) == 1


def test_tune_on_a_stop_heard_before_its_label_gives_a_tuning_not_a_traceback() -> None:
    """The fifth generator's arm 1, shifted stop: heard 23 ms before the label, so its median latency was negative,
    and the tuning it built refused its own latency_measured_s (ValueError out of tune)."""
    try:
        tu = tune(ar.render(ar.tuning_scene(ar.Arm(1, "shifted"))), SR, 2.0)
    except TuningError:  # a clear refusal would be an honest answer too
        return
    assert tu.latency_measured_s is not None and 0.0 <= tu.latency_measured_s <= 1.0
