"""A Cartesian arm (a rig file's ``xyz`` arm): its joints, kinematics and planning come from the arm, not the MM3A.

Every number here is an identity of the stage's linear kinematics (tip = A^T q + tool) or of a constant step
(steps = distance / step), computed by hand; none is read back from the code under test.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from stickslip import kinematics as kin
from stickslip.calibration import Calibration
from stickslip.devices.positions import DeviceState
from stickslip.joints import JOINTS, NOMINAL_STEP, JointSpec
from stickslip.motion.planning import Planner
from stickslip.motion.reach import plan_reach
from stickslip.motion.tracking import scaled_calibration
from stickslip.procedures.jog import JogController
from stickslip.procedures.move import steps_to_stop, target_of
from stickslip.rig import RigError, mm3a_rig, parse_rig
from stickslip.sim.arm import SimulatedMM3A
from stickslip.units import format_position, format_spread

STEP = 0.5e-6  # m: a stage's constant step in both directions
# the stages turned: stage 1 moves along the base frame's y, stage 2 along -x, stage 3 along z
AXES = ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
TOOL = (0.0, 0.0, -0.005)

XYZ = """\
database = "{database}"

[[arm]]
name = "stack"
kind = "xyz"
controller = "sim://"
tool = ["0mm", "0mm", "-5mm"]
axes = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]
home = ["0mm", "1mm", "-2mm"]

  [[arm.joint]]
  range = ["-6mm", "6mm"]
  step = "0.2um"

  [[arm.joint]]
  range = ["-6mm", "6mm"]

  [[arm.joint]]
  range = ["-6mm", "6mm"]
"""


def _cal(plus=STEP, minus=STEP):
    steps = {(j, d): (plus if d == "+" else minus) for j in (1, 2, 3) for d in "+-"}
    return Calibration(models={}, stderr={}, constant_steps=steps, day="2026-11-22", method="constant",
                       kinds=dict.fromkeys((1, 2, 3), "prismatic"))


def _rig(database="stack.db"):
    return parse_rig(XYZ.format(database=database), "/lab/rig.toml")


def test_a_stage_arm_gives_its_own_joints():
    arm = _rig().arm("stack")
    js = arm.joint_specs()
    assert [js[j].kind for j in (1, 2, 3)] == ["prismatic"] * 3
    assert all(js[j].step_model == "constant" and js[j].unit == "m" for j in (1, 2, 3))
    assert (js[1].lower, js[1].upper) == (-0.006, 0.006)
    assert js[1].small_step == pytest.approx(0.2e-6, rel=1e-12)  # the file's step
    assert js[2].small_step == NOMINAL_STEP["prismatic"]  # none given: the kind's
    assert [js[j].home for j in (1, 2, 3)] == pytest.approx([0.0, 0.001, -0.002])
    # the MM3A's joints are untouched: rotary 1 and 2 planned with the paper's models
    assert [JOINTS[j].step_model for j in (1, 2, 3)] == ["paper"] * 3 and JOINTS[1].rotary
    # an unreferenced stage is at its home; positions in µm for every joint, never degrees
    state = DeviceState.default("sim://", js)
    assert [state.positions[j] for j in (1, 2, 3)] == pytest.approx([0.0, 0.001, -0.002])
    assert format_position(0.001, js[1]) == "1000 µm" and format_spread(2e-6, js[2]) == "2 µm"
    assert format_position(0.001, 1) == "0.0572958 deg"  # joint 1 of the MM3A, as before
    # how many steps surely reach a stop: 1.2 x 12 mm over the file's 0.2 µm, rounded up to a thousand
    assert steps_to_stop(1, None, js[1]) == 72_000
    assert steps_to_stop(2, None, js[2]) == math.ceil(1.2 * 0.012 / 0.8e-6 / 1000) * 1000


def test_a_stage_target_is_checked_against_its_own_range():
    js = _rig().arm("stack").joint_specs()
    state = DeviceState.default("sim://", js)
    assert target_of(state, 1, to=-0.005) == (0.0, -0.005)  # -5 mm: an MM3A's joint 3 would refuse it
    with pytest.raises(ValueError, match=r"outside joint 1's range \[-6000 µm, 6000 µm\]"):
        target_of(state, 1, to=0.007)
    with pytest.raises(ValueError, match="q3 = -7000 µm is outside joint 3's range"):
        state.set_position(3, -0.007)


def test_a_stage_is_planned_with_its_constant_step_and_the_tracked_scale():
    js = _rig().arm("stack").joint_specs()
    planner = Planner(_cal(plus=0.5e-6, minus=0.4e-6), js[3], kin.Pose(0.0, 0.0, -0.004))
    assert planner.steps(-0.004, -0.003) == 2000  # 1 mm / 0.5 µm
    assert planner.steps(-0.003, -0.004) == -2500  # 1 mm / 0.4 µm
    assert planner.position_after(0.001, -2500) == pytest.approx(0.0, abs=1e-15)
    assert planner.plan(0.0, 30e-6).spec is js[3]
    scaled = scaled_calibration(_cal(), 3, {"+": 1.25, "-": 1.0})  # the tracked step scale multiplies it
    assert Planner(scaled, js[3], kin.Pose()).steps(0.0, 0.001) == 1600
    with pytest.raises(KeyError, match="no constant step"):
        Planner(Calibration({}, {}, {}, "2026-11-22", "constant", kinds={1: "prismatic"}), js[1], kin.Pose())
    # an MM3A's calibration (joint 1 in rad) is never taken for a stage's steps (m): refused, not misread
    mm3a = SimulatedMM3A(seed=0).true_models()
    consts = {k: 40e-6 for k in mm3a}
    with pytest.raises(ValueError, match="models joint 1 as an MM3A's"):
        Planner(Calibration(mm3a, dict.fromkeys(mm3a), consts, "2026-11-22", "paper"), js[1], kin.Pose())


@given(st.lists(st.floats(-0.005, 0.005), min_size=3, max_size=3))
def test_the_stage_inverse_undoes_its_tip(q):
    stage = kin.Stage(AXES, TOOL)
    tip = stage.tip(q)
    assert tip == pytest.approx([q[1] * -1.0, q[0], q[2] - 0.005], abs=1e-15)  # A^T q + tool, by hand
    assert stage.inverse(tip) == pytest.approx(q, abs=1e-15)
    assert stage.joint_rates([1e-6, 0.0, 0.0]) == pytest.approx([0.0, -1e-6, 0.0])


def test_a_straight_line_of_a_stage_is_a_straight_line_of_its_joints():
    js = {j: JointSpec(j, "prismatic", -0.006, 0.006, "m", step_model="constant") for j in (1, 2, 3)}
    stage = kin.Stage(AXES, TOOL)
    plan = plan_reach(_cal(), kin.Pose(0.0, 0.0, 0.0), by=(30e-6, 40e-6, 0.0), segment=10e-6, stage=stage, joints=js)
    # tip +x is stage 2 backwards, tip +y is stage 1 forwards: 40 µm and 30 µm of 0.5 µm steps
    assert plan.total_steps == (80, 60, 0)
    assert sum(s.steps[1] for s in plan.segments) == -60
    assert plan.q_end == pytest.approx((40e-6, -30e-6, 0.0), abs=1e-15)
    assert plan.tip_end == pytest.approx((30e-6, 40e-6, -0.005), abs=1e-15)
    for s in plan.segments:  # every segment's end on the line, within one step of each joint
        assert plan.deviation(s.tip) <= STEP * math.sqrt(2) + 1e-15
    with pytest.raises(kin.OutOfReach, match="joint 3 would be at 6010 µm, beyond its upper limit 6000 µm"):
        plan_reach(_cal(), kin.Pose(0.0, 0.0, 0.0), by=(0.0, 0.0, 0.007), stage=stage, joints=js)


def test_the_jog_law_on_a_stage_needs_no_jacobian():
    js = {j: JointSpec(j, "prismatic", -0.006, 0.006, "m", step_model="constant") for j in (1, 2, 3)}
    ctl = JogController(_cal(), [0.0, 0.0, 0.0], joints=js, stage=kin.Stage(AXES, TOOL), speed_index=3, hold=0)
    ctl.press("right", 0.0)  # +x of the base frame: stage 2 backwards
    rates, scale = ctl.rates((3e-6, 0.0, 0.0))
    assert rates == pytest.approx((0.0, -6.0, 0.0)) and scale == 1.0  # 3 µm/s over 0.5 µm
    assert ctl.tick(1.0, 1.0) == (0, -6, 0)
    ctl.sent_steps(2, -6)
    status = ctl.status()
    assert status.q == pytest.approx((0.0, -3e-6, 0.0), abs=1e-15)
    assert status.tip == pytest.approx((3e-6, 0.0, -0.005), abs=1e-15)
    assert status.kinds == ("prismatic",) * 3 and status.to_limits[1] == pytest.approx(0.006 - 3e-6)


def test_the_rig_file_names_its_database():
    rig = _rig("history/stack.db")
    assert rig.database is not None and rig.database.replace("\\", "/") == "/lab/history/stack.db"
    url = "postgresql://rig@db.lab:5432/stickslip"
    assert _rig(url).database == url
    assert parse_rig(XYZ.replace('database = "{database}"\n', ""), "r.toml").database is None
    for bad, why in (("postgresql://rig:secret@db.lab/stickslip", "no password in the rig file"),
                     ("postgresql://rig@db.lab/s?password=secret", "no password in the rig file"),
                     ("mysql://rig@db.lab/s", "mysql:// is not a database")):
        with pytest.raises(RigError, match=why) as e:
            _rig(bad)
        assert "secret" not in str(e.value) and str(e.value).startswith("/lab/rig.toml:1: database:")
    with pytest.raises(RigError, match=r"r.toml:13: arm\[1\].joint\[1\].step: '-1um' must be greater than 0"):
        parse_rig(XYZ.format(database="s.db").replace('step = "0.2um"', 'step = "-1um"'), "r.toml")
    assert mm3a_rig().database is None  # the shipped MM3A's file names none


def test_the_simulated_mm3a_does_not_stand_for_a_stage(tmp_path):
    """On sim:// a stage is dead-reckoned like a real controller's: no true end, never referenced until set."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    _cal().save(tmp_path / "stack.json")
    rig = tmp_path / "lab.toml"
    rig.write_text(XYZ.format(database="hist.db").replace('controller = "sim://"', 'controller = "sim://?realtime=0"\n'
                                                         'calibration = "stack.json"'), encoding="utf-8")
    runner = CliRunner()
    r = runner.invoke(app, ["move", "--rig", str(rig), "--joint", "1", "--by", "250um"])
    assert r.exit_code == 2 and "joint 1 was never referenced: its position 0 µm is assumed" in r.output, r.output
    r = runner.invoke(app, ["move", "--rig", str(rig), "--joint", "1", "--by", "250um", "--from-unreferenced"])
    assert r.exit_code == 0, r.output
    assert "+500 steps" in r.output and "assumed end 250 µm" in r.output and "simulator" not in r.output
    assert (tmp_path / "hist.db").is_file()  # the rig file's database (relative to the file)
