"""The issue's scenario on the physics arm: the paper's 14 traverses, well-spread poses and
validation traverses at random poses (tests and benchmarks share it)."""

from __future__ import annotations

import math

import numpy as np

from stickslip import kinematics as kin
from stickslip.calibration.paper import PRISMATIC_PAPER_POSES, ROTARY_PAPER_POSES
from stickslip.measurements import Traverse
from stickslip.sim import physics as ph


def paper14(arm: ph.PhysicsMM3A, day: str) -> list[Traverse]:
    out = []
    for q2, th, ps in PRISMATIC_PAPER_POSES.values():
        for d in "+-":
            out.append(ph.traverse(arm, 3, d, kin.Pose(0.0, q2, 0.0, th, ps), day))
    for q3, th, ps in ROTARY_PAPER_POSES:
        for d in "+-":
            out.append(ph.traverse(arm, 2, d, kin.Pose(0.0, 0.0, q3, th, ps), day))
    return out


def random_pose(rng: np.random.Generator, joint: int) -> kin.Pose:
    q1 = rng.uniform(-0.5, 0.5)
    q2 = rng.uniform(kin.JOINTS[2].lower, kin.JOINTS[2].upper)
    q3 = rng.uniform(0.0, kin.Q3_MAX)
    th = rng.uniform(-math.pi / 2, math.pi / 2)
    ps = rng.uniform(-math.pi / 3, math.pi / 3)
    return kin.Pose(q1, q2, q3, th, ps)


def spread(arm: ph.PhysicsMM3A, day: str, rng: np.random.Generator, per_joint: int = 8) -> list[Traverse]:
    """``per_joint`` random poses for joints 3 and 2, both directions each."""
    out = []
    for j in (3, 2):
        for _ in range(per_joint):
            p = random_pose(rng, j)
            for d in "+-":
                out.append(ph.traverse(arm, j, d, p, day))
    return out


def max_errors(pred: np.ndarray, ts: list[Traverse]) -> dict[int, float]:
    """Largest |relative error| per joint."""
    meas = np.array([t.gamma for t in ts])
    e = np.abs(pred / meas - 1.0)
    return {j: float(np.max(e[[t.joint == j for t in ts]])) for j in sorted({t.joint for t in ts})}


def paper_poses(joint: int) -> list[kin.Pose]:
    """The paper's calibration poses of ``joint`` (3 or 2) as poses."""
    if joint == 3:
        return [kin.Pose(0.0, q2, 0.0, th, ps) for q2, th, ps in PRISMATIC_PAPER_POSES.values()]
    return [kin.Pose(0.0, 0.0, q3, th, ps) for q3, th, ps in ROTARY_PAPER_POSES]


def well_spread(arm: ph.PhysicsMM3A, day: str, rng: np.random.Generator, per_joint: int = 8) -> list[Traverse]:
    """``per_joint`` poses for joints 3 and 2 spread over the load space around the paper's poses
    (:func:`stickslip.calibration.design.spread_poses`, seeded from ``rng``), both directions each."""
    from stickslip.calibration.design import spread_poses

    out = []
    for j in (3, 2):
        for p in spread_poses(j, per_joint, int(rng.integers(2**31)), existing=paper_poses(j)):
            for d in "+-":
                out.append(ph.traverse(arm, j, d, p, day))
    return out
