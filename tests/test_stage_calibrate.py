"""A stage's calibration (``stickslip calibrate TABLE --rig RIG --arm NAME``): each joint and direction's mean step.

The numbers are checked against hand arithmetic (the weighted mean and its standard error of two traverses),
against an independent generator (tests/support/stage_walk.py: a walk of scattered steps, counted; not the
project's simulator), and against the MCS2 emulator's step counter after a ``move`` planned with the result.
"""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from stage_walk import StageTruth, table
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.calibration import Calibration, CalibrationError
from stickslip.calibration.stage import calibrate_stage, mean_step
from stickslip.cli import app
from stickslip.joints import JointSpec
from stickslip.measurements import Traverse
from stickslip.motion.planning import Planner
from stickslip.sim.smaract_emulator import MCS2Emulator

runner = CliRunner()
DAY = "2026-11-22"
STAGE = {j: JointSpec(j, "prismatic", -0.01, 0.01, "m", step_model="constant") for j in (1, 2, 3)}
# the walk's true mean steps, m: every joint and direction its own
TRUE = {(1, "+"): 1.00e-6, (1, "-"): 0.92e-6, (2, "+"): 0.45e-6, (2, "-"): 0.50e-6,
        (3, "+"): 1.30e-6, (3, "-"): 1.21e-6}

RIG = """\
[[arm]]
name = "stack"
kind = "xyz"
controller = "{smaract}?hz=20000"
calibration = "stack.json"

  [[arm.joint]]
  range = ["-10mm", "10mm"]

  [[arm.joint]]
  range = ["-10mm", "10mm"]

  [[arm.joint]]
  range = ["-10mm", "10mm"]

[[arm]]
name = "probe"
controller = "sim://?seed=2"  # not the stack's sim:// (a rig refuses two arms on one controller's channels)
mount = {{ origin = ["-40mm", "0mm", "0mm"] }}
"""


def _t(joint, direction, start, end, steps):
    return Traverse(DAY, joint, direction, 0.0, 0.0, 0.0, 0.0, 0.0, start, end, steps)


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_the_mean_step_is_the_length_weighted_mean_of_the_traverses():
    # 10 mm in 10 000 steps (1 µm) and 5 mm in 4 000 steps (1.25 µm): weights 10 and 5 (mm)
    m = mean_step([_t(1, "+", -0.005, 0.005, 10_000), _t(1, "+", 0.0, 0.005, 4_000)])
    assert m.value == pytest.approx((10 * 1e-6 + 5 * 1.25e-6) / 15, rel=1e-12)  # 1.08333 µm
    # se^2 = n/(n-1) * sum(w^2 (g - mean)^2) / sum(w)^2, by hand: deviations -1/12 and +1/6 µm
    se = math.sqrt(2 * ((10 * 1e-6 / 12) ** 2 + (5 * 1e-6 / 6) ** 2)) / 15
    assert m.stderr == pytest.approx(se, rel=1e-12) and (m.count, m.length) == (2, pytest.approx(0.015))
    one = mean_step([_t(2, "-", 0.004, -0.004, 16_000)])
    assert (one.value, one.stderr, one.count) == (pytest.approx(0.5e-6, rel=1e-12), None, 1)


@settings(max_examples=60)
@given(st.lists(st.tuples(st.floats(1e-4, 0.02), st.integers(100, 50_000)), min_size=2, max_size=12))
def test_the_mean_step_lies_among_the_traverses_and_a_doubled_table_keeps_it(rows):
    traverses = [_t(3, "+", -0.01, length - 0.01, n) for length, n in rows]
    m = mean_step(traverses)
    gammas = [t.gamma for t in traverses]
    assert min(gammas) * (1 - 1e-12) <= m.value <= max(gammas) * (1 + 1e-12)
    # the same traverses twice: the same mean; se^2 goes from n/(n-1) S/W^2 to 2n/(2n-1) 2S/(2W)^2
    twice = mean_step(traverses * 2)
    n = len(traverses)
    assert twice.value == pytest.approx(m.value, rel=1e-12) and twice.count == 2 * n
    assert twice.stderr == pytest.approx(m.stderr * math.sqrt((n - 1) / (2 * n - 1)), rel=1e-9, abs=1e-30)


def test_a_stage_file_is_labelled_by_its_joints_kinds_and_plans_the_same_after_a_round_trip(tmp_path):
    joints = {**STAGE, 2: JointSpec(2, "rotary", -1.0, 1.0, "rad", step_model="constant")}  # a rotation stage
    rows = [_t(j, d, *((-0.5e-2, 0.5e-2) if d == "+" else (0.5e-2, -0.5e-2)), n)
            for j in (1, 2, 3) for d in "+-" for n in (10_000, 10_200)]
    cal = calibrate_stage(rows, joints, arm="stack")
    cal.save(tmp_path / "stack.json")
    doc = json.loads((tmp_path / "stack.json").read_text(encoding="utf-8"))
    units = {(c["joint"], c["direction"]): c["unit"] for c in doc["constant_steps"]}
    assert units == {(1, "+"): "m", (1, "-"): "m", (2, "+"): "rad", (2, "-"): "rad", (3, "+"): "m", (3, "-"): "m"}
    assert {c["traverses"] for c in doc["constant_steps"]} == {2} and doc["method"] == "stage-mean"
    back = Calibration.load(tmp_path / "stack.json")
    assert back.kinds == {1: "prismatic"} and back.kind(2) == "rotary" and back.unit(1) == "m"
    assert back.constant_stderr == cal.constant_stderr and back.constant_traverses == cal.constant_traverses
    for j, q_to in ((1, 0.004), (2, -0.3), (3, 0.007)):  # 10 mm / 10 100 steps on average: 4 mm is 4040 steps
        before = Planner(cal, joints[j], kin.Pose()).steps(0.0, q_to)
        assert Planner(back, joints[j], kin.Pose()).steps(0.0, q_to) == before
        assert before == round(q_to / (0.01 * (1 / 10_000 + 1 / 10_200) / 2))
    # the MM3A's file keeps rad for its rotary joints; a stage's steps labelled rad are refused, not used as metres
    as_rad = dict(doc, constant_steps=[dict(c, unit="rad") for c in doc["constant_steps"]])
    with pytest.raises(ValueError, match=r"joint 1 are in rad \(a rotary joint's\), and this joint is prismatic"):
        Planner(Calibration.from_dict(as_rad), STAGE[1], kin.Pose())
    bad = dict(doc, constant_steps=[dict(c, unit="um") for c in doc["constant_steps"]])
    with pytest.raises(ValueError, match="unit must be 'm' or 'rad', got 'um'"):
        Calibration.from_dict(bad)


def test_a_stage_without_a_traverse_each_way_or_with_a_joint_it_lacks_is_refused_by_name():
    rows = [_t(j, "+", -0.005, 0.005, 10_000) for j in (1, 2, 3)] + [_t(1, "-", 0.005, -0.005, 10_000)]
    with pytest.raises(CalibrationError, match=r"no traverse of joint 2-, 3- for arm 'stack'"):
        calibrate_stage(rows, STAGE, arm="stack")
    with pytest.raises(CalibrationError, match="moves joint 3, which arm 'two' does not have"):
        calibrate_stage(rows, {j: STAGE[j] for j in (1, 2)}, arm="two")
    with pytest.raises(CalibrationError, match="arm 'probe' is an MM3A"):
        calibrate_stage(rows, kin.JOINTS, arm="probe")


def test_a_stage_calibrated_from_the_command_line_recovers_the_walks_steps_and_lands_its_moves(tmp_path):
    """The independent walk's steps come back within 3 standard errors; a move planned with them on the MCS2
    emulator sends the step count the true step gives, so the stage lands within half a step of the target."""
    (tmp_path / "walk.csv").write_text(table(StageTruth(TRUE), per_direction=8, seed=1), encoding="utf-8")
    with MCS2Emulator() as emu:
        rig = tmp_path / "rig.toml"
        rig.write_text(RIG.format(smaract=emu.url), encoding="utf-8")
        r = run("calibrate", tmp_path / "walk.csv", "--rig", rig, "--arm", "stack", "-o", tmp_path / "stack.json")
        assert r.exit_code == 0, r.output
        assert "mean step" in r.output and "nm" in r.output and "µrad" not in r.output
        cal = Calibration.load(tmp_path / "stack.json")
        for key, true in TRUE.items():
            assert cal.constant_traverses[key] == 8
            assert abs(cal.constant_steps[key] - true) <= 3 * cal.constant_stderr[key], key
            assert cal.constant_stderr[key] < 2e-3 * true  # and the bound says something: within 0.2 %
        doc = json.loads((tmp_path / "stack.json").read_text(encoding="utf-8"))
        assert {c["unit"] for c in doc["constant_steps"]} == {"m"}
        assert doc["conditions"]["device"].startswith("smaract-mcs2://127.0.0.1:")  # the arm's controller

        # whole numbers of true steps as targets: the calibration's error must stay under half a step
        for joint, by, true in ((2, -100e-6, TRUE[(2, "-")]), (3, 260e-6, TRUE[(3, "+")])):
            before = emu.steps[joint - 1]
            r = run("move", "--rig", rig, "--arm", "stack", "--joint", joint, "--by", f"{by * 1e6:g}um",
                    "--from-unreferenced", "--json")
            assert r.exit_code == 0, r.output
            sent = emu.steps[joint - 1] - before  # channel joint - 1 drives the stage, sign +
            assert sent == round(by / true) == (-200 if joint == 2 else 200)
            assert abs(sent * true - by) <= true / 2  # where the true mean step takes it


def test_the_command_line_refuses_what_a_stage_calibration_cannot_use(tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG.format(smaract="sim://"), encoding="utf-8")
    walk = table(StageTruth(TRUE), per_direction=2, seed=3).splitlines()
    cases = {
        "joint4.csv": ([*walk, f"{DAY},4,+,0,0,0,0,0,0.0,0.001,1000"], ["joint4.csv:14: unknown joint '4'"]),
        "oneway.csv": ([ln for ln in walk if ",3,-," not in ln], ["no traverse of joint 3- for arm 'stack'"]),
        "beyond.csv": ([*walk, f"{DAY},3,-,0,0,0,0,0,0.0,-0.011,1000"],
                       ["beyond.csv:14: end = -0.011 m is outside joint 3's range"]),
    }
    for name, (lines, words) in cases.items():
        (tmp_path / name).write_text("\n".join(lines) + "\n", encoding="utf-8")
        r = run("calibrate", tmp_path / name, "--rig", rig, "--arm", "stack", "-o", tmp_path / "out.json")
        assert r.exit_code == 2 and "Traceback" not in r.output, r.output
        assert all(w in r.output for w in words), r.output
    assert not (tmp_path / "out.json").exists()
    (tmp_path / "walk.csv").write_text("\n".join(walk) + "\n", encoding="utf-8")
    r = run("calibrate", tmp_path / "walk.csv", "--rig", rig, "--arm", "probe")
    assert r.exit_code == 2 and "arm 'probe' is an MM3A" in r.output and "without --rig" in r.output, r.output
    r = run("calibrate", tmp_path / "walk.csv", "--rig", rig, "--method", "lsq")
    assert r.exit_code == 2 and "from its traverses alone" in r.output, r.output
    r = run("calibrate", tmp_path / "walk.csv", "--arm", "stack")
    assert r.exit_code == 2 and "give --rig FILE too" in r.output, r.output
    r = run("calibrate", tmp_path / "walk.csv", "--rig", rig, "--arm", "stack", "--db", tmp_path / "x.db")
    assert r.exit_code == 2 and "leave out --db" in r.output and not (tmp_path / "x.db").exists(), r.output
