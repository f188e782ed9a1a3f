"""The traverse procedure: step counting, latency correction, fallbacks, round trip.

Reference values come from the simulator itself: the steps that truly moved the joint
are the steps issued before its first at-stop step (``SimulatedMM3A.stop_times``), and
the true parameters are ``SimulatedMM3A.true_parameters()``.
"""

from __future__ import annotations

import math

import pytest

from stickslip import kinematics as kin
from stickslip.calibration import calibrate
from stickslip.measurements import measurements_to_csv, parse_measurements
from stickslip.procedures.traverse import TraverseError, _count_before, measure_traverse
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.oracle import OracleStopDetector

DAY = "2026-11-22"


def _true_steps(sim: SimulatedMM3A, result, joint: int) -> int:
    """Steps issued before the true stop (the ones that moved the joint)."""
    t0 = result.bursts[0][0]
    t_stop = min(t for t in sim.stop_times(joint) if t >= t0)
    return _count_before(t_stop, list(result.bursts), result.frequency_hz)


def _oracle_traverse(sim, joint, direction, delay_s=0.06, **kw):
    return measure_traverse(
        sim,
        joint,
        direction,
        detector=OracleStopDetector(sim, joint, delay_s=delay_s),
        audio_blocks=sim.microphone(block=512, silent=True),
        pose=sim.pose,
        day=DAY,
        **kw,
    )


@pytest.mark.parametrize("direction", ["+", "-"])
def test_latency_correction_with_a_known_delay(direction):
    """A 60 ms detector delay at 1 kHz is ~60 extra steps uncorrected; the onset removes them."""
    sim = SimulatedMM3A(seed=3, day=DAY)
    res = {}
    true = {}
    for mode in ("none", "fixed", "onset"):
        res[mode] = _oracle_traverse(sim, 3, direction, latency=mode)
        true[mode] = _true_steps(sim, res[mode], 3)
    err = {m: res[m].steps - true[m] for m in res}
    # uncorrected: delay (60 steps) plus up to one 512-sample block (10.7 steps)
    assert 59 <= err["none"] <= 72
    assert res["none"].latency_steps_corrected == 0
    # fixed: detected_at - 60 ms leaves only the block quantisation
    assert 0 <= err["fixed"] <= 12
    # onset: exact
    assert abs(err["onset"]) <= 1
    assert res["onset"].latency_steps_corrected >= 59


def test_audio_latency_correction_on_the_simulated_microphone():
    """With the tuned audio switch the raw detection time overcounts; the onset fixes it."""
    from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

    from stickslip.audio.detector import detector_for

    sim = SimulatedMM3A(seed=5, day=DAY)
    samples, rate, stop_at = sim.labelled_recording(3, "+", before_s=2.0, after_s=1.0)
    detector = detector_for(tune(samples, rate, stop_at, joint=3))
    mic = sim.microphone()
    for direction in ("-", "+"):
        r = measure_traverse(
            sim,
            3,
            direction,
            detector=detector,
            audio_blocks=mic,
            pose=sim.pose,
            day=DAY,
            burst_steps=1000,
            listen_after_steps=10_000,
        )
        true = _true_steps(sim, r, 3)
        uncorrected = r.steps + r.latency_steps_corrected
        assert uncorrected - true >= 8  # the detector's delay is visible (~15-20 steps) ...
        assert abs(r.steps - true) <= 4  # ... and gone with the onset estimate
        assert r.traverse.joint == 3 and r.traverse.direction == direction


@pytest.mark.slow
def test_prismatic_round_trip_recovers_the_true_parameters():
    """Simulated arm -> 6 audio-timed traverses (Eqs. 4-6 poses) -> calibrate -> truth.

    Tolerances: a within 0.5 %, b within 0.005, c within 2 % (per-step noise 3 % over
    >12 000 steps gives ~0.03 % on each count; the ripple ~1e-5).
    """
    from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

    from stickslip.audio.detector import detector_for

    sim = SimulatedMM3A(seed=8, day=DAY)
    samples, rate, stop_at = sim.labelled_recording(3, "+")
    detector = detector_for(tune(samples, rate, stop_at, joint=3))
    mic = sim.microphone()
    rows = []
    for q2, theta, psi in ((-math.pi / 2, 0.0, 0.0), (0.0, -math.pi / 2, 0.0), (0.0, 0.0, 0.0)):
        sim.set_pose(q2=q2, theta=theta, psi=psi)
        for direction in ("+", "-"):
            r = measure_traverse(
                sim,
                3,
                direction,
                detector=detector,
                audio_blocks=mic,
                pose=sim.pose,
                day=DAY,
                burst_steps=1000,
                listen_after_steps=8000,
            )
            rows.append(r.traverse)
    cal = calibrate(rows, method="paper")
    truth = {
        (p.direction, p.name): p.value for p in sim.true_parameters() if p.joint == 3
    }
    for p in cal.parameters():
        true = truth[(p.direction, p.name)]
        if p.name == "b":
            assert p.value == pytest.approx(true, abs=0.005)
        elif p.name == "a":
            assert p.value == pytest.approx(true, rel=0.005)
        else:
            assert p.value == pytest.approx(true, rel=0.02)


def test_stop_before_listening_starts_is_measured_again():
    """listen_after_steps beyond the stop: the stop sounds at once, so the traverse is redone."""
    sim = SimulatedMM3A(seed=1, day=DAY, step_noise=0.0)
    r = _oracle_traverse(sim, 3, "+", listen_after_steps=20_000, latency="onset")
    assert r.retried and r.listen_after_steps == 0
    assert abs(r.steps - _true_steps(sim, r, 3)) <= 1
    model = sim.true_models()[(3, "+")]
    exact = kin.Q3_MAX / float(model.average_gamma(0.0, kin.Q3_MAX, *sim.pose))
    assert r.steps == pytest.approx(exact, abs=2)


def test_traverse_row_is_a_valid_measurement_row():
    sim = SimulatedMM3A(seed=2, day=DAY)
    sim.set_pose(q3=0.004, theta=-0.3)
    r = _oracle_traverse(sim, 2, "-")
    t = r.traverse
    assert (t.start, t.end) == (kin.JOINTS[2].upper, kin.JOINTS[2].lower)
    assert (t.q3, t.theta, t.day) == (0.004, -0.3, DAY)
    assert parse_measurements(measurements_to_csv([t])) == [t]
    assert r.gamma == pytest.approx(kin.ROTARY_SPAN / r.steps)
    assert r.commanded_steps == r.steps + r.steps_after_stop
    assert not r.retried
    assert "joint 2 -" in r.report() and "µrad" in r.report()


def test_overdrive_predrive_and_progress_callback():
    sim = SimulatedMM3A(seed=6, day=DAY)
    sim.set_pose(q3=0.006)
    seen = []
    r = _oracle_traverse(
        sim, 3, "+", predrive="overdrive", progress=lambda n, t: seen.append((n, t))
    )
    assert r.predrive_steps > 12_000 / 0.3  # more than the range can take at the smallest step
    assert abs(r.steps - _true_steps(sim, r, 3)) <= 1
    assert seen and seen[-1][0] == r.commanded_steps
    assert all(b[0] <= a[0] for a, b in zip(seen[1:], seen[:-1], strict=False))


def test_iterator_audio_source():
    """A source that yields blocks as recorded (like a live microphone) works too."""
    sim = SimulatedMM3A(seed=2, day=DAY)
    mic = sim.microphone(block=400, silent=True)

    def blocks():
        while True:
            yield from mic()

    r = measure_traverse(
        sim,
        3,
        "+",
        detector=OracleStopDetector(sim, 3, delay_s=0.03),
        audio_blocks=blocks(),
        pose=sim.pose,
        day=DAY,
    )
    assert abs(r.steps - _true_steps(sim, r, 3)) <= 1


def test_no_stop_heard_raises():
    sim = SimulatedMM3A(seed=0, day=DAY)
    deaf = OracleStopDetector(sim, 1)  # listens for joint 1 while joint 3 moves
    with pytest.raises(TraverseError, match="no stop heard after 5000 steps"):
        measure_traverse(
            sim,
            3,
            "+",
            detector=deaf,
            audio_blocks=sim.microphone(silent=True),
            pose=sim.pose,
            day=DAY,
            predrive="none",
            max_steps=5000,
        )


def test_bad_arguments():
    sim = SimulatedMM3A()
    det = OracleStopDetector(sim, 3)
    mic = sim.microphone(silent=True)
    for kw, msg in (
        ({"latency": "late"}, "latency must be one of"),
        ({"predrive": "x"}, "predrive"),
        ({"burst_steps": 0}, "burst_steps"),
        ({"listen_after_steps": -1}, "listen_after"),
    ):
        with pytest.raises(ValueError, match=msg):
            measure_traverse(
                sim, 3, "+", detector=det, audio_blocks=mic, pose=sim.pose, day=DAY, **kw
            )
    with pytest.raises(ValueError, match="direction"):
        measure_traverse(sim, 3, "up", detector=det, audio_blocks=mic, pose=sim.pose, day=DAY)


def test_a_traverse_tells_the_detector_the_rate_it_commands():
    """Every reset of the detector carries the controller's step rate (Hz): the detector hears the clock near it."""

    class Spy(OracleStopDetector):
        rates: list[float | None] = []

        def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
            self.rates.append(step_rate_hz)
            super().reset(t0_s, step_rate_hz)

    sim = SimulatedMM3A(seed=3, day=DAY)
    spy = Spy(sim, 3, delay_s=0.06)
    res = measure_traverse(
        sim, 3, "+", detector=spy, audio_blocks=sim.microphone(block=512, silent=True), pose=sim.pose, day=DAY
    )
    # the first reset is the confirming wrapper's own, when it is made; every reset the traverse makes tells the rate
    assert spy.rates[0] is None and len(spy.rates) >= 2
    assert set(spy.rates[1:]) == {res.frequency_hz} and res.frequency_hz == sim.frequency(3) > 0
