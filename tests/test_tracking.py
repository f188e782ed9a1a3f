"""The Kalman filter over position and step scale (stickslip.tracking), on the physics arm."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physics_scenarios import paper14
from stickslip import kinematics as kin
from stickslip.calibration import calibrate
from stickslip.planning import dead_reckon
from stickslip.sim import physics as ph
from stickslip.tracking import PositionTracker


def test_sparse_feedback_learns_the_scale_and_beats_dead_reckoning():
    # yesterday's calibration; today the arm's steps differ. Moves of 300 steps, a microscope
    # reading (sd 1 µm) every fifth move: the filter learns the scale, dead reckoning drifts
    day0, day1 = "2026-07-01", "2026-07-02"
    cal = calibrate(paper14(ph.PhysicsMM3A(seed=61, day=day0), day0))
    arm = ph.PhysicsMM3A(seed=61, day=day1, warmup=0.0)
    pose = kin.Pose(0.0, -math.pi / 2, 0.0, 0.0, 0.0)
    arm.set_pose(q2=pose.q2, q3=0.001)
    tr = PositionTracker(cal, 3, pose, q0=0.001, q0_sd=0.0)
    dr = 0.001
    rng = np.random.default_rng(0)
    errs_kf, errs_dr = [], []
    for k in range(30):
        n = 300
        arm.step(3, n)
        tr.step(n)
        dr = dead_reckon(cal, 3, dr, n, pose)
        if k % 5 == 4:
            tr.observe(arm.position(3) + 1e-6 * rng.standard_normal(), 1e-6)
        errs_kf.append(abs(tr.position - arm.position(3)))
        errs_dr.append(abs(dr - arm.position(3)))
        assert abs(tr.position - arm.position(3)) < 4 * tr.sd + 1e-6  # the stated uncertainty is honest
    true_scale = (arm.position(3) - 0.001) / (dr - 0.001)
    assert tr.scale == pytest.approx(true_scale, rel=0.03)
    assert np.mean(errs_kf[10:]) < 0.3 * np.mean(errs_dr[10:])


def test_end_stop_pins_the_position():
    cal = calibrate(paper14(ph.PhysicsMM3A(seed=62, day="d"), "d"))
    tr = PositionTracker(cal, 3, kin.Pose(0.0, -math.pi / 2, 0.0, 0.0, 0.0), q0=0.005, q0_sd=1e-4)
    tr.step(1000)
    assert tr.sd > 1e-4
    tr.observe(kin.Q3_MAX, 0.0)
    assert tr.position == kin.Q3_MAX and tr.sd == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError):
        tr.observe(float("nan"), 1e-6)
