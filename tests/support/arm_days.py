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

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from dahl_arm import DahlArm
from lugre_arm import LugreArm
from physics_scenarios import paper_poses, random_pose

from stickslip import kinematics as kin
from stickslip.calibration.design import check_poses, spread_poses
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
    more_validation: list[Traverse] = field(default_factory=list)
    """``make_day(..., more_validation=n)``: ``n`` more random validation poses per joint (both directions),
    measured last (drawn from their own generator: the other tables are those of ``n = 0``)."""
    check: list[Traverse] = field(default_factory=list)
    """``make_day(..., check_per_joint=n)``: check traverses at ``n`` random poses per joint (both directions;
    :func:`stickslip.calibration.design.check_poses`), not fitted (``calibrate(..., check=...)``). Measured
    after every other traverse of the day, so that those are the same whatever ``n`` (no arm here changes
    within a day after its first traverse: docs/models-log.md, fifteenth round's control)."""

    @property
    def calibration46(self) -> list[Traverse]:
        """The paper's 14 and the 32 spread traverses (without the repeats)."""
        return self.paper14 + self.spread32

    @property
    def calibration(self) -> list[Traverse]:
        """The whole calibration in the order measured: the 46 and the repeats."""
        return self.paper14 + self.spread32 + self.repeat


def make_day(arm_name: str, seed: int, day: str, rng: np.random.Generator, validation_poses: int = 8,
             repeat_first: bool = False, new_per_direction: int = 1, more_validation: int = 0,
             check_per_joint: int = 0) -> Day:
    """The day's tables (``validation_poses`` random poses per joint, both directions), measured in this order
    on one arm (a joint that warms up is warm by the validation). ``repeat_first``: each joint's first paper
    pose is traversed again in both directions after the 46 (the random poses drawn are the same).
    ``new_per_direction``: new traverses per joint and direction for the update (:attr:`Day.more_new`).
    ``more_validation``: random validation poses per joint measured after all of them
    (:attr:`Day.more_validation`). ``check_per_joint``: check poses per joint measured last (:attr:`Day.check`)."""
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
    val_rng = np.random.default_rng((seed, int(day.replace("-", "")), 13))
    more_val = [arm.traverse(j, d, p, day) for j in (3, 2)
                for p in [random_pose(val_rng, j) for _ in range(more_validation)] for d in "+-"]
    check_seed = int(np.random.default_rng((seed, int(day.replace("-", "")), 17)).integers(2**31))
    check = [arm.traverse(j, d, p, day) for j in (3, 2) for p in check_poses(j, check_per_joint, check_seed)
             for d in "+-"]
    return Day(arm_name, seed, day, p14, s32, val, new4, rep, more, more_val, check)


def relative_errors(pred: np.ndarray, ts: list[Traverse]) -> np.ndarray:
    """``pred / measured - 1`` per traverse."""
    out: np.ndarray = np.asarray(pred, dtype=float) / np.array([t.gamma for t in ts]) - 1.0
    return out


def wilson_interval(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval of a proportion ``k / n`` (default 95 %: ``z`` the normal quantile 0.975).

    ``(c - h, c + h)`` with ``c = (k + z^2/2) / (n + z^2)`` and
    ``h = z sqrt(k (n - k) / n + z^2 / 4) / (n + z^2)``. Raises ``ValueError`` unless ``0 <= k <= n``, ``n > 0``.
    """
    if not (n > 0 and 0 <= k <= n):
        raise ValueError(f"k = {k}, n = {n}: a proportion needs 0 <= k <= n and n > 0")
    c = (k + z * z / 2) / (n + z * z)
    h = z * math.sqrt(k * (n - k) / n + z * z / 4) / (n + z * z)
    return c - h, c + h


def share_above(a: np.ndarray, b: np.ndarray, m: int) -> float:
    """The share of the ``m``-subsets of the poses on which ``max a > max b`` over the subset (exact).

    ``a[i]``, ``b[i]``: two models' errors at pose ``i`` (no ties between poses). On a subset the larger
    maximum belongs to the pose with the largest ``max(a[i], b[i])``; the pose of rank ``r`` (0 the largest)
    among ``n`` is the subset's top in ``C(n - 1 - r, m - 1) / C(n, m)`` of the subsets, so the share is the
    sum of those over the poses with ``a > b``. ``m = n``: 1 or 0, the comparison itself.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = a.size
    if a.shape != b.shape or a.ndim != 1 or not 1 <= m <= n:
        raise ValueError(f"m = {m} poses of {n} (shapes {a.shape}, {b.shape}): need 1 <= m <= n, equal 1-D shapes")
    order = np.argsort(-np.maximum(a, b), kind="stable")
    top = np.array([math.comb(n - 1 - r, m - 1) for r in range(n)], dtype=float) / math.comb(n, m)
    return float(np.sum(top[(a > b)[order]]))
