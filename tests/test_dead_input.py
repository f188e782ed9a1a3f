"""A dead audio input (silence, a constant, clipping) never becomes a traverse.

The detector is the real one, tuned on a recording of the simulator; the dead inputs are
written here, not rendered by the simulator: zeros, a DC offset, a pinned full-scale
signal, and a live room that goes silent (the cable pulled) mid-traverse.
"""

from __future__ import annotations

import numpy as np
import pytest
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.detector import detector_for
from stickslip.audio.sources.guard import NoSignalError, SignalGuard, block_problem
from stickslip.procedures.traverse import TraverseError, measure_traverse
from stickslip.sim.arm import SimulatedMM3A

DAY = "2026-11-22"
RATE = 48_000


@pytest.fixture(scope="module")
def tuning():
    sim = SimulatedMM3A(seed=5, day=DAY)
    samples, rate, stop_at = sim.labelled_recording(3, "+", before_s=2.0, after_s=1.0)
    return tune(samples, rate, stop_at, joint=3)


def _dead(kind: str, n: int = 1024):
    rng = np.random.default_rng(1)
    while True:
        if kind == "silence":
            yield np.zeros(n, dtype=np.float32)
        elif kind == "constant":
            yield np.full(n, 0.37, dtype=np.float32)
        elif kind == "clipped":
            yield np.sign(rng.standard_normal(n)).astype(np.float32)
        else:
            raise AssertionError(kind)


@pytest.mark.parametrize("kind,problem", [("silence", "silence"), ("constant", "a constant"), ("clipped", "clipping")])
def test_block_problem_names_the_fault(kind, problem):
    assert block_problem(next(_dead(kind))) == problem


def test_live_room_noise_is_alive():
    rng = np.random.default_rng(0)
    assert block_problem(1e-4 * rng.standard_normal(1024)) is None  # -80 dBFS room noise
    assert block_problem(0.5 * rng.standard_normal(1024)) is None  # loud, a few samples clip


def test_guard_trips_only_after_hold_without_a_break():
    g = SignalGuard(RATE, hold_s=0.2)
    dead = np.zeros(2400)  # 50 ms
    alive = 1e-3 * np.random.default_rng(2).standard_normal(2400)
    assert [g.check(dead) for _ in range(3)] == [False, False, False]  # 150 ms
    assert g.check(alive) is True and g.dead_s == 0.0  # a break resets the count
    for _ in range(3):
        g.check(dead)
    with pytest.raises(NoSignalError, match=r"no signal from the audio input: silence for 0.20 s"):
        g.check(dead)


@pytest.mark.parametrize("kind", ["silence", "constant", "clipped"])
def test_a_traverse_on_a_dead_input_records_nothing(tuning, kind):
    sim = SimulatedMM3A(seed=5, day=DAY)
    with pytest.raises(TraverseError, match="no signal from the audio input") as e:
        measure_traverse(
            sim,
            3,
            "+",
            detector=detector_for(tuning),
            audio_blocks=_dead(kind),
            pose=sim.pose,
            day=DAY,
            burst_steps=1000,
        )
    assert "nothing was recorded" in str(e.value) and "\n" not in str(e.value)


def test_a_microphone_unplugged_mid_traverse_stops_it(tuning):
    """Live room sound from the simulator, then the cable is pulled: zeros from 1 s on."""
    sim = SimulatedMM3A(seed=5, day=DAY)
    mic = sim.microphone(block=1024)
    fed = {"s": 0.0}

    def blocks():
        while True:
            for b in mic():
                fed["s"] += len(b) / RATE
                yield b if fed["s"] < 1.0 else np.zeros_like(b)

    with pytest.raises(TraverseError, match="no signal from the audio input: silence"):
        measure_traverse(
            sim,
            3,
            "+",
            detector=detector_for(tuning),
            audio_blocks=blocks(),
            pose=sim.pose,
            day=DAY,
            burst_steps=1000,
        )


def test_a_live_room_without_the_joints_steps_stops_the_traverse(tuning):
    """The microphone hears a room (noise and a 50 Hz hum) but not the joint: no stepping at the commanded rate."""
    rng = np.random.default_rng(3)

    def room():
        t0 = 0
        while True:
            t = (t0 + np.arange(1024)) / RATE
            t0 += 1024
            yield (1e-3 * rng.standard_normal(1024) + 3e-3 * np.sin(2 * np.pi * 50 * t)).astype(np.float32)

    sim = SimulatedMM3A(seed=5, day=DAY)
    with pytest.raises(TraverseError, match=r"no stepping sound at \d+ Hz in the audio input") as e:
        measure_traverse(
            sim,
            3,
            "+",
            detector=detector_for(tuning),
            audio_blocks=room(),
            pose=sim.pose,
            day=DAY,
            burst_steps=1000,
        )
    assert "nothing was recorded" in str(e.value) and "\n" not in str(e.value)


def test_step_line_is_strong_for_stepping_and_weak_for_noise():
    from stickslip.audio.sources.guard import step_line_db
    from stickslip.sim.sound import render_traverse_recording

    x, sr = render_traverse_recording(2, 1000.0, 1e9, 0.5, seed=9, babble=True)
    assert step_line_db(x[: sr // 4], sr, 1000.0) > 20.0
    assert step_line_db(x[: sr // 4], sr, 1370.0) < 10.0  # the wrong rate
    assert step_line_db(np.random.default_rng(0).standard_normal(sr // 4), sr, 1000.0) < 8.0
    assert step_line_db(x[:100], sr, 1000.0) == float("inf")  # too short to judge
