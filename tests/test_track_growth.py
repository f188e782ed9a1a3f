"""A reach's segments and a jog's ticks grow the joints' Kalman tracks as a move does (the σ the envelope uses)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.devices.positions import DeviceState
from stickslip.motion.reach import plan_reach
from stickslip.motion.tracking import JointTrack, calibration_id
from stickslip.procedures.jog import run_jog
from stickslip.procedures.move import sigma_growth
from stickslip.procedures.reach import drive_reach, joint_path
from stickslip.sim.arm import SimulatedMM3A
from test_jog import OUT, ctl
from test_reach import CAL

SD0 = (2e-4, 2e-4, 2e-7)  # rad, rad, m: each joint's σ before


def _state() -> DeviceState:
    state = DeviceState("sim://", {1: OUT.q1, 2: OUT.q2, 3: OUT.q3}, dict.fromkeys((1, 2, 3), "set"))
    for j, sd in zip((1, 2, 3), SD0, strict=True):
        v = 0.03**2  # the step scales known to 3 %
        state.track[j] = JointTrack(np.zeros(2), np.diag([sd**2, v, v]), calibration_id(CAL), None).to_json()
    return state


def _sd(state: DeviceState, j: int) -> float:
    return JointTrack.from_json(state.track[j]).sd


def test_a_reach_grows_the_tracks_as_the_envelope_predicts():
    state = _state()
    plan = plan_reach(CAL, state.pose, by=(0.0, 200e-6, -100e-6), segment=50e-6)
    predicted = sigma_growth(state, CAL).after(joint_path(plan))  # the envelope's σ at the path's end
    sim = SimulatedMM3A(seed=4, day="2026-11-22", pose=OUT)
    saved: list[DeviceState] = []
    out = drive_reach(sim, state, plan, CAL, saved.append)
    assert out.error is None and saved
    for j in (1, 2, 3):
        assert out.sent[j - 1] != 0
        after = _sd(state, j)
        assert after > SD0[j - 1]  # it grew: 3 % of the distance moved, and the per-step scatter
        assert after == pytest.approx(math.sqrt(predicted.P[j - 1][0][0]), rel=0.02)


def test_a_jog_grows_the_track_of_the_joint_it_moves():
    state = _state()
    sim = SimulatedMM3A(seed=4, day="2026-11-22", pose=OUT)
    c = ctl(speed_index=6, hold=0.0)
    clock = iter(np.arange(0.0, 100.0, 0.05))
    script = [["w"]] + [[]] * 20 + [["space"]] + [[]] * 3 + [["q"]]
    run_jog(sim, state, c, lambda t: script.pop(0), lambda s: None, lambda s: None, lambda: float(next(clock)))
    assert c.sent[0] > 0 and c.sent[1:] == [0, 0]  # joint 1 only
    moved = abs(c.q[0] - OUT.q1)
    # at least the scale's 3 % of the distance moved, added in quadrature
    assert _sd(state, 1) >= math.hypot(SD0[0], 0.03 * moved) * 0.999
    assert (_sd(state, 2), _sd(state, 3)) == pytest.approx(SD0[1:], rel=1e-12)
