"""Synthetic measurement tables for the tests: the paper's poses, a known truth, optional noise."""

from __future__ import annotations

import math

import numpy as np
from pinned import PINNED_TODAY

from stickslip.calibration import PRISMATIC_PAPER_POSES, ROTARY_PAPER_POSES
from stickslip.kinematics import JOINTS
from stickslip.measurements import Traverse
from stickslip.models import JointModel, PrismaticParams, RotaryParams

# The paper's published prismatic values (Fig. 4b caption), SI.
PAPER_PRISMATIC = {"+": PrismaticParams(972e-9, 0.27, 372e-9), "-": PrismaticParams(899e-9, 0.25, -436e-9)}
# Rotary: d from the paper's Fig. 10 (q3 = 0 and 12 mm); gamma0 typical of its Fig. 6.
PAPER_ROTARY = {
    "+": RotaryParams((45e-6, 52e-6), (-8.15e-6, -19.40e-6)),
    "-": RotaryParams((41e-6, 47e-6), (3.83e-6, 23.94e-6)),
}


def full_range(joint: int, direction: str) -> tuple[float, float]:
    spec = JOINTS[joint]
    return (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)


def traverse_from_model(
    model: JointModel,
    pose: dict[str, float],
    day: str = PINNED_TODAY,
    rng: np.random.Generator | None = None,
    noise: float = 0.0,
    start_end: tuple[float, float] | None = None,
) -> Traverse:
    """A traverse whose step count is what ``model`` predicts (rounded), times (1 + noise * N(0,1))."""
    j, d = model.joint, model.direction
    start, end = start_end or full_range(j, d)
    p = {"q1": 0.0, "q2": -math.pi / 2, "q3": 0.0, "theta": 0.0, "psi": 0.0, **pose}
    g = float(model.average_gamma(start, end, p["q1"], p["q2"], p["q3"], p["theta"], p["psi"]))
    if noise and rng is not None:
        g *= 1.0 + noise * rng.standard_normal()
    steps = max(1, round(abs(end - start) / g))
    return Traverse(day, j, d, p["q1"], p["q2"], p["q3"], p["theta"], p["psi"], start, end, steps)


def paper_table(
    prismatic: dict[str, PrismaticParams] = PAPER_PRISMATIC,
    rotary: dict[str, RotaryParams] = PAPER_ROTARY,
    day: str = PINNED_TODAY,
    rng: np.random.Generator | None = None,
    noise: float = 0.0,
) -> list[Traverse]:
    """The paper's 14 calibration traverses (6 prismatic, 8 of joint 2) generated from a truth."""
    rows = []
    for d, p in prismatic.items():
        m = JointModel(3, d, p)
        for q2, th, ps in PRISMATIC_PAPER_POSES.values():
            rows.append(traverse_from_model(m, {"q2": q2, "theta": th, "psi": ps}, day, rng, noise))
    for d, r in rotary.items():
        m = JointModel(2, d, r)
        for q3, th, ps in ROTARY_PAPER_POSES:
            rows.append(traverse_from_model(m, {"q2": 0.0, "q3": q3, "theta": th, "psi": ps}, day, rng, noise))
    return rows


def random_poses(rng: np.random.Generator, joint: int, n: int) -> list[dict[str, float]]:
    """Random poses (fixed joints and tilt) within range."""
    out = []
    for _ in range(n):
        out.append(
            {
                "q1": 0.0,
                "q2": rng.uniform(JOINTS[2].lower, JOINTS[2].upper) if joint != 2 else 0.0,
                "q3": rng.uniform(0, JOINTS[3].upper) if joint != 3 else 0.0,
                "theta": rng.uniform(-math.pi / 2, 0.0),
                "psi": rng.uniform(-math.pi / 3, math.pi / 3),
            }
        )
    return out
