"""The camera against the simulated arm: finding the tip by moving a joint, and step sizes measured by camera."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.devices.base import DeviceInfo
from stickslip.procedures.camera import acquire_tip, calibrate_camera
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.camera import SimCamera, SimCamSettings
from stickslip.vision.acquire import AcquireError, find_moving_tip
from stickslip.vision.jacobian import joint_observation


class Recording:
    """A controller that records the true position of the joint before and after every burst."""

    def __init__(self, sim: SimulatedMM3A):
        self.sim = sim
        self.bursts: list[tuple[int, int, float, float]] = []

    @property
    def info(self) -> DeviceInfo:
        return self.sim.info

    def step(self, joint: int, n: int) -> None:
        q0 = self.sim.position(joint)
        self.sim.step(joint, n)
        self.bursts.append((joint, n, q0, self.sim.position(joint)))

    def position(self, joint: int) -> float:
        return self.sim.position(joint)

    def set_frequency(self, joint: int, hz: float) -> None:
        self.sim.set_frequency(joint, hz)

    def frequency(self, joint: int) -> float:
        return self.sim.frequency(joint)

    def stop(self, joint: int | None = None) -> None:
        self.sim.stop(joint)

    def settings(self) -> dict[str, object]:
        return self.sim.settings()

    def close(self) -> None:
        self.sim.close()

    @property
    def pose(self):  # the camera reads the base tilt from it
        return self.sim.pose


def _realized(bursts, joint: int, sign: int, first: int, count: int) -> float:
    """The mean true step of ``count`` bursts of ``joint`` in direction ``sign`` from the ``first``-th such burst."""
    mine = [b for b in bursts if b[0] == joint and np.sign(b[1]) == sign][first : first + count]
    return sum(abs(b[3] - b[2]) for b in mine) / sum(abs(b[1]) for b in mine)


@pytest.mark.parametrize("joint", [1, 3])
def test_acquire_finds_the_tip_of_a_needle_in_bright_field(joint):
    sim = SimulatedMM3A(seed=2)
    cam = SimCamera(sim, SimCamSettings(look="optical", seed=2, photons=120))
    x, y = acquire_tip(sim, cam, joint, 20)
    truth, _ = cam.true_tip()
    assert math.hypot(x - truth[0], y - truth[1]) <= 2.0


def test_nothing_moved_is_said():
    rng = np.random.default_rng(1)
    frames = [rng.normal(0.5, 0.01, (64, 64)) for _ in range(4)]
    with pytest.raises(AcquireError, match="nothing moved"):
        find_moving_tip(frames[:2], frames[2:])
    with pytest.raises(AcquireError, match="differ in size"):
        find_moving_tip([frames[0]], [np.zeros((32, 32))])


@pytest.mark.slow
def test_camera_calibration_recovers_the_true_step_within_1_percent():
    """Joint 3 at the outstretched pose, 0.5 µm a pixel, at most 200 steps each way: the realized mean step."""
    sim = SimulatedMM3A(seed=7)
    dev = Recording(sim)
    cam = SimCamera(dev, SimCamSettings(look="optical", seed=7, photons=200))  # type: ignore[arg-type]
    truth, _ = cam.true_tip()
    res = calibrate_camera(dev, cam, sim.pose, joints=(3, 2), tip=(float(truth[0]), float(truth[1])),
                           day="2026-11-22")
    j3, j2 = res.joints
    assert j3.refused is None and "optical axis" in (j2.refused or "")
    plus, minus = j3.step_sizes
    n_plus = len(j3.fits[0].steps) - 1
    g_plus = _realized(dev.bursts, 3, 1, 0, n_plus)
    g_minus = _realized(dev.bursts, 3, -1, 0, len(j3.fits[1].steps) - 1)
    assert plus.steps <= 200 and abs(plus.gamma / g_plus - 1) < 0.01 and abs(minus.gamma / g_minus - 1) < 0.01
    assert 0.002 < plus.sigma / plus.gamma < 0.02  # the fit's uncertainty is stated, and sensible
    rows = res.rows
    assert [(r.joint, r.direction, r.method) for r in rows] == [(3, "+", "camera"), (3, "-", "camera")]
    assert rows[0].gamma == plus.gamma and rows[0].q2 == sim.pose.q2 and rows[0].day == "2026-11-22"
    # the seam: a later fix of the tip gives joint 3's position, to its sigma
    assert res.calibration is not None
    sim.step(3, 30)
    fix, _ = cam.true_tip()
    obs = joint_observation(res.calibration, 3, float(fix[0]), float(fix[1]), 0.2)
    assert obs.sigma == pytest.approx(0.2 * 0.5e-6) and abs(obs.q - sim.position(3)) < 3 * obs.sigma


@pytest.mark.slow
def test_a_joint_at_its_end_stop_is_refused_as_not_linear():
    sim = SimulatedMM3A(seed=8)
    sim.set_pose(q3=0.012 - 40e-6)  # 40 µm from the outer stop
    cam = SimCamera(sim, SimCamSettings(look="optical", seed=8, photons=200), centre_base="tip")
    truth, _ = cam.true_tip()
    res = calibrate_camera(sim, cam, sim.pose, joints=(3,), tip=(float(truth[0]), float(truth[1])), max_steps=150)
    (j3,) = res.joints
    assert j3.refused is not None and "not linear in the steps" in j3.refused and not res.rows
