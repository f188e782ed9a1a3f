"""A hidden arm for task-space tests: physics that is *not* the project's model, and its own executor.

Written from a different view than ``stickslip.models`` / ``stickslip.sim``:

* frames by composing rotations (scipy ``Rotation``), gravity by rotating the world's
  ``-z`` into the base frame, loads by cross products of the arm axis with gravity;
* other parameters than the simulator's, a load term the paper's models do not have
  (quadratic for the rotary joints, cubic for the prismatic one), a ripple along each
  joint's travel, and lognormal per-step noise;
* traverses counted step by step between the end stops, as a limit switch would;
* plans executed one step at a time, the tip recomputed after every step.

Nothing here imports the planner or the model functions; only the calibration is made
with the project's ``calibrate`` (that is what a user would do with these traverses).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

RANGES = {1: (-2 * math.pi / 3, 2 * math.pi / 3), 2: (-7 * math.pi / 6, math.pi / 6), 3: (0.0, 0.012)}


def gravity_in_base(theta: float, psi: float) -> np.ndarray:
    """World gravity (0, 0, -1) seen in a base turned by theta about x, then psi about the new y."""
    base = Rotation.from_euler("XY", [theta, psi])  # intrinsic: x, then the new y
    return np.asarray(base.inv().apply([0.0, 0.0, -1.0]), dtype=float)


def arm_rotation(q1: float, q2: float) -> Rotation:
    return Rotation.from_rotvec([0.0, 0.0, q1]) * Rotation.from_rotvec([0.0, -q2, 0.0])


def tip_of(q: Sequence[float], offset: float, length: float) -> np.ndarray:
    q1, q2, q3 = q
    return np.asarray(
        Rotation.from_rotvec([0.0, 0.0, q1]).apply(
            np.array([offset, 0.0, 0.0]) + Rotation.from_rotvec([0.0, -q2, 0.0]).apply([0.0, 0.0, length + q3])
        ),
        dtype=float,
    )


def loads(q: Sequence[float], theta: float, psi: float) -> dict[int, float]:
    """Dimensionless loads: gravity along the arm (joint 3, against +), minus the torques about z1 and z0."""
    g = gravity_in_base(theta, psi)
    z2 = arm_rotation(q[0], q[1]).apply([0.0, 0.0, 1.0])
    z1 = Rotation.from_rotvec([0.0, 0.0, q[0]]).apply([0.0, -1.0, 0.0])
    torque = np.cross(z2, g)
    return {3: float(-g @ z2), 2: float(-torque @ z1), 1: float(-torque @ np.array([0.0, 0.0, 1.0]))}


@dataclass
class HiddenArm:
    """True mean steps of a hidden MM3A-like arm (m or rad), with per-step noise."""

    seed: int = 0
    noise: float = 0.03
    # prismatic: a, b, c, cubic (m, 1, m, m) per direction
    prismatic: dict[str, tuple[float, float, float, float]] = field(
        default_factory=lambda: {"+": (1050e-9, 0.22, 300e-9, 40e-9), "-": (830e-9, 0.30, -480e-9, -40e-9)}
    )
    # rotary: gamma0 at q3 = 0 and 12 mm, d at q3 = 0 and 12 mm, quadratic (rad)
    rotary: dict[tuple[int, str], tuple[float, float, float, float, float]] = field(
        default_factory=lambda: {
            (2, "+"): (55e-6, 44e-6, -10e-6, -22e-6, 1.0e-6),
            (2, "-"): (48e-6, 45e-6, 5e-6, 26e-6, 1.0e-6),
            (1, "+"): (45e-6, 40e-6, -6e-6, -12e-6, 0.8e-6),
            (1, "-"): (50e-6, 46e-6, 4e-6, 10e-6, 0.8e-6),
        }
    )
    ripple: float = 0.006

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    def mean_step(self, joint: int, sign: int, q: Sequence[float], theta: float, psi: float) -> float:
        d = "+" if sign > 0 else "-"
        load = loads(q, theta, psi)[joint]
        lo, hi = RANGES[joint]
        wiggle = 1.0 + self.ripple * math.sin(2 * math.pi * 3 * (q[joint - 1] - lo) / (hi - lo) + joint)
        if joint == 3:
            a, b, c, e = self.prismatic[d]
            return (1.0 - b * abs(math.cos(q[1]))) * (a - c * load - e * load**3) * wiggle
        g0a, g0b, da, db, quad = self.rotary[(joint, d)]
        w = q[2] / 0.012
        return (g0a + (g0b - g0a) * w + (da + (db - da) * w) * load + quad * load**2) * wiggle

    def one_step(self, joint: int, sign: int, q: list[float], theta: float, psi: float) -> None:
        """Move ``q`` (in place) by one noisy step, stopping at the end stop."""
        s = self.mean_step(joint, sign, q, theta, psi)
        s *= math.exp(self.noise * self.rng.standard_normal() - 0.5 * self.noise**2)
        lo, hi = RANGES[joint]
        q[joint - 1] = min(max(q[joint - 1] + sign * s, lo), hi)

    def traverse_steps(self, joint: int, sign: int, q: Sequence[float], theta: float, psi: float) -> int:
        """Steps from one end stop to the other (the count a limit switch would give).

        The other joints and the tilt stay put, so the mean step is tabulated along the
        joint's travel (601 points) and the steps are drawn in chunks, each step's size
        taken at its own position (two fixed-point passes; the step changes by < 1e-3
        over a chunk).
        """
        lo, hi = RANGES[joint]
        grid = np.linspace(lo, hi, 601)
        qq = list(q)
        table = []
        for x in grid:
            qq[joint - 1] = x
            table.append(self.mean_step(joint, sign, qq, theta, psi))
        table_a = np.array(table)
        pos = lo if sign > 0 else hi
        end = hi if sign > 0 else lo
        n = 0
        while True:
            eps = np.exp(self.noise * self.rng.standard_normal(512) - 0.5 * self.noise**2)
            p = np.full(512, pos)
            for _ in range(2):
                sizes = np.interp(p, grid, table_a) * eps
                p = pos + sign * np.concatenate(([0.0], np.cumsum(sizes)[:-1]))
            ends = p + sign * np.interp(p, grid, table_a) * eps
            hit = np.nonzero(sign * (ends - end) >= 0)[0]
            if hit.size:
                return n + int(hit[0]) + 1
            n += 512
            pos = float(ends[-1])


def execute(
    arm: HiddenArm, plan_json: dict[str, Any], offset: float, length: float, theta: float, psi: float
) -> np.ndarray:
    """Apply a ``reach --json`` plan step by step; returns the tip after every step, ``(n, 3)`` m."""
    q = list(plan_json["start"]["q"])
    tips = [tip_of(q, offset, length)]
    for seg in plan_json["segments"]:
        for j, n in zip((1, 2, 3), seg["steps"], strict=True):
            sign = 1 if n > 0 else -1
            for _ in range(abs(n)):
                arm.one_step(j, sign, q, theta, psi)
                tips.append(tip_of(q, offset, length))
    return np.array(tips)


def distance_from_segment(points: np.ndarray, a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    a0 = np.asarray(a, dtype=float)
    d = np.asarray(b, dtype=float) - a0
    t = np.clip((points - a0) @ d / (d @ d), 0.0, 1.0)
    return np.asarray(np.linalg.norm(points - (a0 + t[:, None] * d), axis=1), dtype=float)
