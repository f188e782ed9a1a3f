"""The simulated MM3A: truth, physics, end stops, clock, microphone, URL.

Reference values: the exact traverse integral of :mod:`stickslip.models`
(``steps_between``, cross-checked there against quadrature) and a plain Python
step-by-step loop (the paper's Fig. 8 simulation) on the simulator's own mean-step
function. The ripple has whole periods over the range, so a full-range traverse
matches Eq. 3/8 to second order (``RIPPLE**2 / 2`` = 8e-6 relative); we allow 1e-4.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip import kinematics as kin
from stickslip.devices import Controller, DeviceError, open_device
from stickslip.sim.arm import (
    FREQUENCY_RANGE,
    NOMINAL,
    RIPPLE,
    SimulatedMM3A,
    open_url,
)
from stickslip.sim.oracle import OracleStopDetector

DAY = "2026-11-22"


def _full_traverse(sim: SimulatedMM3A, joint: int, sign: int) -> int:
    """Steps that moved the joint over a full range (starting on the opposite stop)."""
    spec = kin.JOINTS[joint]
    sim.set_pose(**{f"q{joint}": spec.lower if sign > 0 else spec.upper})
    total = 0
    while True:
        sim.step(joint, sign * 50_000)
        b = sim._bursts[-1]
        total += b.k_stop
        if b.k_stop < b.n:
            return total


POSES = [
    (3, {"q2": -math.pi / 2, "theta": 0.0, "psi": 0.0}),
    (3, {"q2": 0.0, "theta": 0.0, "psi": 0.0}),
    (3, {"q2": -math.pi / 4, "theta": -math.pi / 4, "psi": 0.3}),
    (2, {"q3": 0.0, "theta": 0.0, "psi": 0.0}),
    (2, {"q3": kin.Q3_MAX, "theta": 0.0, "psi": 0.0}),
    (2, {"q3": 0.006, "theta": -math.pi / 4, "psi": 0.0}),
    (1, {"q2": -math.pi / 2, "q3": 0.0, "theta": -math.pi / 2, "psi": 0.0}),
]


@pytest.mark.parametrize("joint,pose", POSES)
@pytest.mark.parametrize("sign", [1, -1])
def test_noiseless_full_traverse_matches_exact_model_count(joint, pose, sign):
    """Without noise, a full traverse takes the exact Eq. 3/8 count (the truth's definition)."""
    sim = SimulatedMM3A(seed=4, day=DAY, step_noise=0.0)
    sim.set_pose(**pose)
    n = _full_traverse(sim, joint, sign)
    spec = kin.JOINTS[joint]
    model = sim.true_models()[(joint, "+" if sign > 0 else "-")]
    q1, q2, q3, theta, psi = sim.pose
    start, end = (spec.lower, spec.upper) if sign > 0 else (spec.upper, spec.lower)
    exact = spec.span / float(model.average_gamma(start, end, q1, q2, q3, theta, psi))
    assert n == pytest.approx(exact, rel=1e-4, abs=2)


@pytest.mark.slow
@pytest.mark.parametrize("joint,pose", [POSES[0], POSES[3], POSES[5], POSES[6]])
@pytest.mark.parametrize("sign", [1, -1])
def test_vectorised_burst_equals_step_by_step_loop(joint, pose, sign):
    """A burst (chunked fixed-point iteration) equals the step-by-step loop (Fig. 8), noise and all.

    Every step is the true mean step at the joint's current position times its own
    noise factor; the loop below draws the same noise factors.
    """
    sim = SimulatedMM3A(seed=2, day=DAY, step_noise=0.03)
    spec = kin.JOINTS[joint]
    q0 = spec.lower + 0.5 * spec.span
    sim.set_pose(**pose, **{f"q{joint}": q0})
    rng = copy.deepcopy(sim._rng)
    n = 4000
    sim.step(joint, sign * n)
    sigma = math.sqrt(math.log1p(0.03**2))
    eps = np.exp(sigma * rng.standard_normal(n) - 0.5 * sigma**2)
    q = q0
    for k in range(n):
        q += sign * float(sim.true_mean_step(joint, sign, q)) * eps[k]
    assert sim.position(joint) == pytest.approx(q, rel=1e-10, abs=1e-9 * spec.span)
    assert abs(sim.position(joint) - q0) > 0.03 * spec.span  # it really went somewhere


def test_noisy_count_scatters_like_the_noise():
    """Per-step lognormal noise of 3 %: the count of ~12 000 steps scatters by ~0.03*sqrt(N)."""
    counts = []
    for seed in range(6):
        sim = SimulatedMM3A(seed=seed, day="fixed-day", drift=0.0, step_noise=0.03)
        counts.append(_full_traverse(sim, 3, +1))
    model_sim = SimulatedMM3A(seed=0, day="fixed-day", drift=0.0, step_noise=0.0)
    exact = _full_traverse(model_sim, 3, +1)
    counts = np.array(counts)
    sigma = 0.03 * math.sqrt(exact)  # ~3.3 steps
    assert np.all(np.abs(counts - exact) < 5 * sigma)
    assert counts.std() > 0.2 * sigma  # the noise is really there
    assert len(set(counts.tolist())) > 1


def test_truth_drifts_with_the_day_and_is_reproducible():
    a = SimulatedMM3A(seed=1, day=DAY).true_parameters()
    b = SimulatedMM3A(seed=1, day=DAY).true_parameters()
    c = SimulatedMM3A(seed=1, day="2026-11-23").true_parameters()
    assert a == b
    va, vc = np.array([p.value for p in a]), np.array([p.value for p in c])
    rel = np.abs(vc / va - 1)
    assert rel.max() > 0.005  # it drifts ...
    assert rel.max() < 0.25  # ... by a few %, 2.5 sigma at most each
    # drift=0 gives the nominal values (the paper's prismatic a, b, c; Fig. 10's d)
    nominal = SimulatedMM3A(seed=1, day=DAY, drift=0.0).true_models()
    for key, params in NOMINAL.items():
        assert nominal[key].params == params


def test_true_parameters_records():
    recs = [p.to_dict() for p in SimulatedMM3A(seed=0, day=DAY).true_parameters()]
    assert len(recs) == 6 + 16
    names = {(r["joint"], r["direction"], r["name"], r["q3"]) for r in recs}
    assert (3, "+", "a", None) in names and (2, "-", "d", kin.Q3_MAX) in names
    for r in recs:
        assert r["unit"] == {"a": "m", "b": "1", "c": "m", "gamma0": "rad", "d": "rad"}[r["name"]]
        assert r["stderr"] is None
    a_plus = next(r for r in recs if r["joint"] == 3 and r["direction"] == "+" and r["name"] == "a")
    assert a_plus["value"] == pytest.approx(972e-9, rel=0.1)


def test_end_stops_are_hard_and_heard():
    sim = SimulatedMM3A(seed=0, day=DAY)
    sim.set_pose(q3=kin.Q3_MAX - 5e-6)  # ~5 steps from the upper stop
    sim.step(3, 100)
    assert sim.position(3) == kin.Q3_MAX
    assert sim.at_stop(3) == "upper"
    b = sim._bursts[-1]
    assert 2 <= b.k_stop <= 10  # a few moving steps, then at the stop
    times, joints, at_stop = sim.step_events(0.0, sim.clock_s)
    assert times.size == 100 and np.all(joints == 3)
    assert at_stop.sum() == 100 - b.k_stop
    assert sim.stop_times(3) == [pytest.approx(b.k_stop / 1000.0)]
    sim.step(3, 100)  # further into the stop: does not move, same stop run continues
    assert sim.position(3) == kin.Q3_MAX
    assert len(sim.stop_runs(3)) == 1
    sim.step(3, -10)  # back out: moves again
    assert sim.position(3) < kin.Q3_MAX
    assert sim.at_stop(3) is None


def test_clock_and_frequency():
    sim = SimulatedMM3A()
    assert sim.frequency(2) == 1000.0
    sim.set_frequency(2, 500)
    sim.step(2, -250)
    assert sim.clock_s == pytest.approx(0.5)
    sim.wait(1.5)
    assert sim.clock_s == pytest.approx(2.0)
    lo, hi = FREQUENCY_RANGE
    for bad in (0.0, hi + 1, -5, float("nan")):
        with pytest.raises(ValueError, match=r"1\.\.5000 Hz"):
            sim.set_frequency(1, bad)
    assert sim.frequency(2) == 500.0  # unchanged, not clipped
    with pytest.raises(ValueError, match="joints are 1, 2"):
        sim.step(4, 10)
    with pytest.raises(ValueError, match="integer"):
        sim.step(1, 2.5)
    sim.close()
    with pytest.raises(DeviceError):
        sim.step(1, 1)


def test_set_pose_validates_ranges():
    sim = SimulatedMM3A()
    with pytest.raises(ValueError, match=r"q2 = .* outside joint 2's range"):
        sim.set_pose(q2=1.0)
    with pytest.raises(ValueError, match=r"q3 = .* outside"):
        sim.set_pose(q3=0.02)
    with pytest.raises(ValueError, match=r"theta .* outside \[-pi, pi\]"):
        sim.set_pose(theta=4.0)
    sim.set_pose(q2=0.0, theta=-math.pi / 2)
    assert sim.pose == kin.Pose(0.0, 0.0, 0.0, -math.pi / 2, 0.0)


@settings(max_examples=40, deadline=None)
@given(
    joint=st.sampled_from([1, 2, 3]),
    moves=st.lists(st.integers(-30_000, 30_000), min_size=1, max_size=6),
    seed=st.integers(0, 50),
)
def test_positions_stay_within_the_stops_and_move_the_right_way(joint, moves, seed):
    sim = SimulatedMM3A(seed=seed, day=DAY, pose=kin.Pose(q3=0.006))
    spec = kin.JOINTS[joint]
    t = 0.0
    for n in moves:
        before = sim.position(joint)
        sim.step(joint, n)
        after = sim.position(joint)
        assert spec.lower <= after <= spec.upper
        assert (after - before) * n >= 0  # never moves against the command
        t += abs(n) / 1000.0
        assert sim.clock_s == pytest.approx(t)
    assert sim.steps_simulated == sum(abs(n) for n in moves)


def test_microphone_gives_complete_blocks_up_to_the_clock():
    sim = SimulatedMM3A(seed=0, day=DAY, sample_rate=8000)
    mic = sim.microphone(block=256, silent=True)
    sim.step(3, 100)  # 0.1 s = 800 samples -> 3 complete blocks
    blocks = mic()
    assert [b.size for b in blocks] == [256] * 3
    assert mic() == []
    sim.step(3, 100)  # 1600 samples in all -> 6 blocks, 3 new
    assert len(mic()) == 3
    assert mic.t_s == pytest.approx(6 * 256 / 8000)
    mic.skip_to(1.0)
    assert mic.t_s == pytest.approx(1.0)


def test_microphone_renders_the_steps_in_order():
    """Blocks rendered one by one equal one long rendering of the same span."""
    sim = SimulatedMM3A(seed=3, day=DAY)
    sim.set_pose(q3=kin.Q3_MAX - 100e-6)
    mic = sim.microphone(block=1024)
    t0 = sim.clock_s
    sim.step(3, 300)
    blocks = np.concatenate(mic())
    other = sim.microphone()
    other._next = int(round(t0 * sim.sample_rate))
    whole = other.read_until(t0 + blocks.size / sim.sample_rate)
    assert whole.size == blocks.size
    np.testing.assert_allclose(blocks, whole, atol=1e-5)
    assert np.sqrt(np.mean(blocks.astype(float) ** 2)) > 0  # not silent


def test_labelled_recording_stop_time():
    sim = SimulatedMM3A(seed=1, day=DAY)
    samples, rate, stop_at = sim.labelled_recording(2, "-", before_s=1.0, after_s=0.5)
    assert rate == 48_000
    assert samples.size == pytest.approx(1.5 * rate, abs=2)
    assert 0.8 < stop_at < 1.2  # placed about 1 s before the stop (ripple, noise)
    assert sim.at_stop(2) == "lower"


def test_oracle_detector_fires_once_after_its_delay():
    sim = SimulatedMM3A(seed=0, day=DAY, sample_rate=8000)
    sim.set_pose(q3=kin.Q3_MAX - 50e-6)
    det = OracleStopDetector(sim, 3, delay_s=0.02, t0_s=0.0)
    sim.step(3, 200)
    true_stop = sim.stop_times(3)[0]
    events = []
    mic = sim.microphone(block=80, silent=True)
    mic.skip_to(0.0)
    mic._next = 0  # listen from the start of the stream
    for b in mic():
        events += det.feed(b)
    assert len(events) == 1
    e = events[0]
    assert e.onset_s == pytest.approx(true_stop)
    assert true_stop + 0.02 <= e.detected_at_s < true_stop + 0.02 + 80 / 8000 + 1e-9


def test_ripple_is_small_and_smooth():
    sim = SimulatedMM3A(seed=0, day=DAY, step_noise=0.0)
    spec = kin.JOINTS[2]
    q = np.linspace(spec.lower, spec.upper, 2001)
    model = sim.true_models()[(2, "+")]
    p = sim.pose
    plain = model.gamma(p.q1, q, p.q3, p.theta, p.psi)
    ratio = sim.true_mean_step(2, "+", q) / plain
    assert np.max(np.abs(ratio - 1)) == pytest.approx(RIPPLE, rel=0.01)
    assert 0 < RIPPLE < 0.01


def test_open_url_and_registry():
    sim = open_device("sim://?seed=3&day=2026-11-22&noise=0.01")
    assert isinstance(sim, SimulatedMM3A) and isinstance(sim, Controller)
    assert (sim.seed, sim.day_label, sim.step_noise) == (3, DAY, 0.01)
    assert sim.info.url.startswith("sim://")
    assert open_url("sim://").seed == 0
    with pytest.raises(ValueError, match=r"unknown sim:// option 'sed'.*known: .*seed"):
        open_url("sim://?sed=3")
    with pytest.raises(ValueError, match="not a valid int"):
        open_url("sim://?seed=three")
    with pytest.raises(ValueError, match=r"seed = -1 must be an integer in \[0, 2\*\*63\)"):
        open_url("sim://?seed=-1")
    with pytest.raises(ValueError, match=r"noise.*outside \[0, 0.5\]"):
        SimulatedMM3A(step_noise=0.9)
    assert sim.settings()["frequency_hz"] == {1: 1000.0, 2: 1000.0, 3: 1000.0}
    with pytest.raises(DeviceError, match=r"unknown device URL scheme 'foo'.*sim://"):
        open_device("foo://x")
    with pytest.raises(ValueError, match=r"gives the option 'seed' twice"):  # which seed would it be?
        open_device("sim://?seed=1&noise=0.01&seed=2")


@pytest.mark.slow
def test_long_sessions_forget_what_every_microphone_has_heard():
    """Burst records are dropped once all live microphones have rendered past them."""
    sim = SimulatedMM3A(seed=0, day=DAY, sample_rate=8000)
    sim.set_pose(q3=0.006)
    mic = sim.microphone(block=400, silent=True)
    for k in range(5000):
        sim.step(3, 10 if k % 2 == 0 else -10)
        if k % 100 == 0:
            mic()
    assert len(sim._bursts) < 5000  # pruned ...
    times, _, _ = sim.step_events(mic.t_s, sim.clock_s)
    assert times.size == pytest.approx((sim.clock_s - mic.t_s) * 1000, abs=2)  # ... not what is unheard
    lagging = sim.microphone(silent=True)  # a new microphone keeps everything from now on
    for _ in range(5000):
        sim.step(3, 1)
        sim.step(3, -1)
    assert lagging.t_s == 50.0 and len(sim._bursts) >= 10_000
    assert sim.stop_runs(3) == []
