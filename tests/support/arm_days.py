"""The issue's day on three independent arms (issue 33): tests and benchmarks share it.

Per day: the paper's 14 calibration traverses, 32 more at poses spread over the load space
(8 poses per joint, both directions; ``calibration.design.spread_poses``) and validation
traverses at *random* poses of the workspace. The arms:

* ``physics``: the library's physics arm (``stickslip.sim.physics``: Coulomb friction with
  stiction and Stribeck, piezo lag, mass-spring mount, backlash, warm-up);
* ``lugre``: ``lugre_arm.py`` (LuGre bristles, first-order piezo lag, ``sin^2`` slack);
* ``dahl``: ``dahl_arm.py`` (Dahl friction, Hertzian contact compliance, static anisotropic
  mount), written for issue 33 before the fitting changed and never tuned to.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from dahl_arm import DahlArm
from lugre_arm import LugreArm
from physics_scenarios import paper_poses, random_pose

from stickslip import kinematics as kin
from stickslip.calibration.design import spread_poses
from stickslip.measurements import Traverse
from stickslip.sim import physics as ph


class Arm(Protocol):
    def traverse(self, joint: int, direction: str, pose: kin.Pose, day: str) -> Traverse: ...


class _Physics:
    def __init__(self, seed: int, day: str) -> None:
        self.arm = ph.PhysicsMM3A(seed=seed, day=day)

    def traverse(self, joint: int, direction: str, pose: kin.Pose, day: str) -> Traverse:
        return ph.traverse(self.arm, joint, direction, pose, day)


ARMS: dict[str, Callable[[int, str], Arm]] = {"physics": _Physics, "lugre": LugreArm, "dahl": DahlArm}
"""Arm name -> factory ``(seed, day) -> arm``."""


@dataclass(frozen=True)
class Day:
    """One day's traverses of one arm."""

    arm: str
    seed: int
    day: str
    paper14: list[Traverse]
    spread32: list[Traverse]
    validation: list[Traverse]
    new4: list[Traverse]
    """One traverse per joint and direction at random poses, measured last (to update yesterday's calibration)."""
    repeat: list[Traverse] = field(default_factory=list)
    """Each joint's first paper pose traversed again (both directions) at the end of the calibration, before
    the validation (``make_day(..., repeat_first=True)``): the drift within the session."""
    more_new: list[Traverse] = field(default_factory=list)
    """``make_day(..., new_per_direction=n)``: ``n - 1`` more traverses per joint and direction at random poses,
    measured after :attr:`new4` (drawn from their own generator: the other tables are those of ``n = 1``)."""

    @property
    def calibration46(self) -> list[Traverse]:
        """The paper's 14 and the 32 spread traverses (without the repeats)."""
        return self.paper14 + self.spread32

    @property
    def calibration(self) -> list[Traverse]:
        """The whole calibration in the order measured: the 46 and the repeats."""
        return self.paper14 + self.spread32 + self.repeat


def make_day(arm_name: str, seed: int, day: str, rng: np.random.Generator, validation_poses: int = 8,
             repeat_first: bool = False, new_per_direction: int = 1) -> Day:
    """The day's tables (``validation_poses`` random poses per joint, both directions), measured in this order
    on one arm (a joint that warms up is warm by the validation). ``repeat_first``: each joint's first paper
    pose is traversed again in both directions after the 46 (the random poses drawn are the same).
    ``new_per_direction``: new traverses per joint and direction for the update (:attr:`Day.more_new`)."""
    arm = ARMS[arm_name](seed, day)
    p14 = [arm.traverse(j, d, p, day) for j in (3, 2) for p in paper_poses(j) for d in "+-"]
    s32 = [arm.traverse(j, d, p, day) for j in (3, 2)
           for p in spread_poses(j, 8, int(rng.integers(2**31)), existing=paper_poses(j)) for d in "+-"]
    rep = [arm.traverse(j, d, paper_poses(j)[0], day) for j in (3, 2) for d in "+-"] if repeat_first else []
    val = [arm.traverse(j, d, p, day) for j in (3, 2)
           for p in [random_pose(rng, j) for _ in range(validation_poses)] for d in "+-"]
    new4 = [arm.traverse(j, d, random_pose(rng, j), day) for j in (3, 2) for d in "+-"]
    more_rng = np.random.default_rng((seed, int(day.replace("-", "")), 11))
    more = [arm.traverse(j, d, random_pose(more_rng, j), day)
            for _ in range(new_per_direction - 1) for j in (3, 2) for d in "+-"]
    return Day(arm_name, seed, day, p14, s32, val, new4, rep, more)


def relative_errors(pred: np.ndarray, ts: list[Traverse]) -> np.ndarray:
    """``pred / measured - 1`` per traverse."""
    out: np.ndarray = np.asarray(pred, dtype=float) / np.array([t.gamma for t in ts]) - 1.0
    return out
