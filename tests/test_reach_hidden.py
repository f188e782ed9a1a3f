"""The issue's check, on a hidden arm: calibrate from its traverses, plan with `reach --dry-run --json`,
execute the plans step by step with the arm's *true* steps.

The hidden arm (tests/support/hidden_arm.py) is not the project's model: other parameters, a
load term the paper's equations lack, a ripple along each joint's travel and 3 %
lognormal noise per step; its frames and loads are computed independently. It is
calibrated the way a user would: full-range traverses (counted step by step between
the end stops) at the paper's poses, then ``stickslip.calibration.calibrate``.

Criteria (the issue): for random moves of 20–300 µm at several poses the executed tip
ends within 5 % of the move's length of the target and never strays more than 5 % of
the length from the straight line; the plan's own predicted end is within half a step
of every joint (the rounding bound); the constant-step plan is far worse.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hidden_arm import RANGES, HiddenArm, distance_from_segment, execute
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.calibration import calibrate
from stickslip.cli import app
from stickslip.measurements import Traverse
from stickslip.motion.reach import plan_reach

P = math.pi
DAY = "2026-11-22"
# the paper's poses for joints 3 and 2 (Eqs. 4-6, Fig. 7); joint 1 with the roles of theta = 0
# and theta = -pi/2 interchanged (the paper's Section 4), arm outstretched
CAL_POSES = [
    (3, (0, -P / 2, 0, 0, 0)),
    (3, (0, 0, 0, -P / 2, 0)),
    (3, (0, 0, 0, 0, 0)),
    (2, (0, 0, 0, 0, 0)),
    (2, (0, 0, 0.012, 0, 0)),
    (2, (0, 0, 0.012, -P / 2, 0)),
    (2, (0, 0, 0, -P / 2, 0)),
    (1, (0, -P / 2, 0, 0, 0)),
    (1, (0, -P / 2, 0.012, 0, 0)),
    (1, (0, -P / 2, 0.012, -P / 2, 0)),
    (1, (0, -P / 2, 0, -P / 2, 0)),
]


@pytest.fixture(scope="module")
def hidden(tmp_path_factory):
    arm = HiddenArm(seed=11)
    rows = []
    for j, (q1, q2, q3, th, ps) in CAL_POSES:
        for sign in (1, -1):
            n = arm.traverse_steps(j, sign, [q1, q2, q3], th, ps)
            lo, hi = RANGES[j]
            a, b = (lo, hi) if sign > 0 else (hi, lo)
            rows.append(Traverse(DAY, j, "+" if sign > 0 else "-", q1, q2, q3, th, ps, a, b, n))
    cal = calibrate(rows)
    path = tmp_path_factory.mktemp("hidden") / "cal.json"
    cal.save(path)
    return arm, cal, path


def _moves(seed: int, n: int):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        pose = kin.Pose(
            rng.uniform(-1.0, 1.0),
            rng.uniform(-P + 0.3, -0.3),
            rng.uniform(0.001, 0.011),
            rng.uniform(-P / 2, 0.0),
            rng.uniform(-P / 6, P / 6),
        )
        length = rng.uniform(20e-6, 300e-6)
        v = rng.normal(size=3)
        yield pose, v * length / np.linalg.norm(v)


def _score(arm, plan_json, pose):
    g = kin.DEFAULT_GEOMETRY
    tips = execute(arm, plan_json, g.offset, g.length, pose.theta, pose.psi)
    start, target = plan_json["start"]["tip"], plan_json["target"]
    length = math.dist(start, target)
    end = float(np.linalg.norm(tips[-1] - target)) / length
    dev = float(distance_from_segment(tips, start, target).max()) / length
    return end, dev


@pytest.mark.slow
def test_hidden_arm_reach_within_5_percent_and_constant_far_worse(hidden):
    arm, cal, _ = hidden
    model, const = [], []
    for pose, by in _moves(seed=2026, n=24):
        plan = plan_reach(cal, pose, by=by)
        # the plan's own end: within half a step of each joint (J's columns are orthogonal)
        J = kin.jacobian(plan.q_end)
        end_pose = kin.Pose(*plan.q_end, pose.theta, pose.psi)
        half = 0.5 * math.sqrt(
            sum((np.linalg.norm(J[:, j - 1]) * max(cal.gamma(j, d, end_pose) for d in "+-")) ** 2 for j in (1, 2, 3))
        )
        assert plan.end_error <= half < 1.5e-6
        model.append(_score(arm, plan.as_dict(), pose))
        const.append(_score(arm, plan_reach(cal, pose, by=by, step_model="constant").as_dict(), pose))
    model_a, const_a = np.array(model), np.array(const)
    assert model_a[:, 0].max() < 0.05, model_a  # end within 5 % of the length
    assert model_a[:, 1].max() < 0.05, model_a  # never more than 5 % from the line
    # the constant step: several times worse at the end, typically beyond the 5 % the model meets
    assert np.median(const_a[:, 0]) > 4 * np.median(model_a[:, 0])
    assert np.median(const_a[:, 0]) > 0.05
    assert const_a[:, 0].max() > 0.2


@pytest.mark.slow
def test_hidden_arm_through_the_cli_dry_run(hidden, tmp_path):
    """The plans the checker reads: `reach --dry-run --json`, executed with the true steps."""
    arm, _, cal_path = hidden
    runner = CliRunner()
    for pose, by in _moves(seed=7, n=4):
        args = ["reach", "-c", str(cal_path), "--db", str(tmp_path / "s.db"), "--dry-run", "--json"]
        args += [f"--q1={pose.q1!r}rad", f"--q2={pose.q2!r}rad", f"--q3={pose.q3!r}m"]  # every value with its unit
        args += [f"--theta={pose.theta!r}rad", f"--psi={pose.psi!r}rad"]
        args += ["--by=" + ",".join(f"{float(v)!r}m" for v in by)]
        r = runner.invoke(app, args)
        assert r.exit_code == 0, r.output
        out = json.loads(r.stdout)
        end, dev = _score(arm, out, pose)
        assert end < 0.05 and dev < 0.05
