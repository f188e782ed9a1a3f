"""The issue's acceptance on a second, independent physics arm (tests/support/lugre_arm.py: LuGre friction).

The arm was written after the selection method and the benchmark settings, and nothing
was tuned on it. Per day: the paper's 14 calibration traverses, 32 more at poses spread
over the load space (``calibration.design.spread_poses``, as ``stickslip suggest``-style
planning would give), 32 validation traverses at *random* poses, and 4 of the day's
traverses at random poses (one per joint and direction) to update yesterday's
calibration. Seeds fixed; the numbers asserted are the issue's.
"""

from __future__ import annotations

import numpy as np
import pytest
from lugre_arm import LugreArm
from physics_scenarios import max_errors, paper_poses, random_pose

from stickslip.calibration import calibrate
from stickslip.calibration.design import spread_poses
from stickslip.calibration.update import update_calibration

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("lugre_acceptance")]  # one worker computes `results` once

DAYS = ("2026-10-05", "2026-10-06", "2026-10-07")


def _day(seed: int, day: str, rng: np.random.Generator):
    arm = LugreArm(seed, day)
    p14 = [arm.traverse(j, d, p, day) for j in (3, 2) for p in paper_poses(j) for d in "+-"]
    s32 = [arm.traverse(j, d, p, day) for j in (3, 2)
           for p in spread_poses(j, 8, int(rng.integers(2**31)), existing=paper_poses(j)) for d in "+-"]
    val = [arm.traverse(j, d, p, day) for j in (3, 2) for p in [random_pose(rng, j) for _ in range(8)] for d in "+-"]
    new4 = [arm.traverse(j, d, random_pose(rng, j), day) for j in (3, 2) for d in "+-"]
    return p14, s32, val, new4


def run(seed: int = 7):
    rng = np.random.default_rng(seed)
    out = []
    prev = None
    for day in DAYS:
        p14, s32, val, new4 = _day(seed, day, rng)
        c14 = calibrate(p14, model="auto")
        c46 = calibrate(p14 + s32, model="auto")
        row = {
            "day": day,
            "constant": max_errors(np.array([c14.constant_step(t.joint, t.direction) for t in val]), val),
            "paper14": max_errors(c14.predict_many(val), val),
            "auto46": max_errors(c46.predict_many(val), val),
        }
        if prev is not None:
            upd, _ = update_calibration(prev, new4)
            row["prior+4"] = max_errors(upd.predict_many(val), val)
        out.append(row)
        prev = c46
    return out


@pytest.fixture(scope="session")
def results():
    return run()


def test_paper_calibration_beats_the_constant_step(results):
    for r in results:
        for j in (3, 2):
            assert r["paper14"][j] < r["constant"][j], r


def test_46_traverses_meet_the_issue_numbers(results):
    for r in results:
        assert r["auto46"][3] <= 0.075 and r["auto46"][2] <= 0.035, r


def test_prior_plus_four_meets_the_issue_numbers(results):
    for r in results[1:]:
        assert r["prior+4"][3] <= 0.10 and r["prior+4"][2] <= 0.05, r


if __name__ == "__main__":  # the table in docs/models.md
    for r in run():
        print(r["day"], {k: {j: round(100 * v, 1) for j, v in e.items()} for k, e in r.items() if k != "day"})
