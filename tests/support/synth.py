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


HISTORY_TRUTH = {
    (3, "+"): ("load2-normal", (1000e-9, 0.24, 330e-9, 60e-9, 40e-9, 15e-9)),
    (3, "-"): ("load2-normal", (920e-9, 0.22, -420e-9, -50e-9, 30e-9, -10e-9)),
    (2, "+"): ("torque2-radial", (48e-6, 54e-6, -8e-6, -20e-6, 1.2e-6, 0.8e-6, 0.5e-6)),
    (2, "-"): ("torque2-radial", (44e-6, 49e-6, 4e-6, 22e-6, 1.0e-6, -0.6e-6, 0.4e-6)),
}
"""A truth beyond the paper's form (families of docs/models.md §2) for long synthetic histories."""


def history_csv(n: int, seed: int = 0, session: int = 100, noise: float = 0.005) -> str:
    """A lab's history as a measurement table of ``n`` rows (CSV text), vectorised.

    Sessions of ``session`` traverses: the paper's 14 calibration traverses, the rest at
    random poses (joints 3 and 2, both directions), each on its own day; steps from
    :data:`HISTORY_TRUTH` with a relative noise ``noise`` and a day-to-day scale of 3 %.
    Values are written to 7 significant digits, as a logger would.
    """
    import datetime

    from stickslip.models.families import FamilyModel, FamilyParams

    rng = np.random.default_rng(seed)
    base = paper_table()
    rows = np.arange(n)
    k = rows % session
    day_index = rows // session
    is_paper = k < len(base)
    joint = np.where(is_paper, [base[i].joint for i in np.minimum(k, len(base) - 1)], np.where(k % 2, 3, 2))
    direction = np.where(is_paper, [base[i].direction for i in np.minimum(k, len(base) - 1)],
                         np.where((k // 2) % 2, "+", "-"))
    q1 = np.where(is_paper, 0.0, rng.uniform(-0.5, 0.5, n))
    q2 = np.where(is_paper, [base[i].q2 for i in np.minimum(k, len(base) - 1)],
                  rng.uniform(JOINTS[2].lower, JOINTS[2].upper, n))
    q3 = np.where(is_paper, [base[i].q3 for i in np.minimum(k, len(base) - 1)], rng.uniform(0.0, JOINTS[3].upper, n))
    theta = np.where(is_paper, [base[i].theta for i in np.minimum(k, len(base) - 1)],
                     rng.uniform(-math.pi / 2, math.pi / 2, n))
    psi = np.where(is_paper, [base[i].psi for i in np.minimum(k, len(base) - 1)],
                   rng.uniform(-math.pi / 3, math.pi / 3, n))
    q1 = np.where(joint == 1, 0.0, q1)
    q2 = np.where(joint == 2, 0.0, q2)
    q3 = np.where(joint == 3, 0.0, q3)
    start = np.empty(n)
    end = np.empty(n)
    gamma = np.empty(n)
    day_scale = 1.0 + 0.03 * rng.standard_normal(int(day_index.max()) + 1)
    for (j, d), (fam, vals) in HISTORY_TRUTH.items():
        sel = (joint == j) & (direction == d)
        lo, hi = full_range(j, d)
        start[sel], end[sel] = lo, hi
        m = FamilyModel(j, d, FamilyParams(fam, j, vals))
        gamma[sel] = m.average_gamma(lo, hi, q1[sel], q2[sel], q3[sel], theta[sel], psi[sel])
    gamma *= day_scale[day_index] * (1.0 + noise * rng.standard_normal(n))
    steps = np.maximum(1, np.round(np.abs(end - start) / gamma)).astype(np.int64)
    day0 = datetime.date(2024, 1, 1)
    days = [(day0 + datetime.timedelta(days=int(i))).isoformat() for i in range(int(day_index.max()) + 1)]
    lines = ["day,joint,direction,q1,q2,q3,theta,psi,start,end,steps"]
    lines += [
        f"{days[di]},{j},{d},{a:.7g},{b:.7g},{c:.7g},{t:.7g},{p:.7g},{s:.7g},{e:.7g},{st}"
        for di, j, d, a, b, c, t, p, s, e, st in zip(
            day_index.tolist(), joint.tolist(), direction.tolist(), q1.tolist(), q2.tolist(), q3.tolist(),
            theta.tolist(), psi.tolist(), start.tolist(), end.tolist(), steps.tolist(), strict=True
        )
    ]
    return "\n".join(lines) + "\n"
