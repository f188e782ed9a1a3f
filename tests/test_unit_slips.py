"""A quantity in the wrong unit is refused with the likely slip named: degrees for radians, mm or µm for m (units58)."""

from __future__ import annotations

import math
import pickle
import re
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from stickslip.calibration import calibrate
from stickslip.joints import JOINTS, MAX_STROKE, MAX_TURN
from stickslip.joints import MM3A_FILE as JOINTS_FILE
from stickslip.kinematics import Geometry, Pose
from stickslip.measurements import TableError, Traverse, check_traverses, parse_measurements, write_measurements
from stickslip.measurements.poses import parse_pose_table
from stickslip.measurements.rows import HEADER, unit_column_problem
from stickslip.measurements.steps import parse_step_sizes
from stickslip.measurements.table import parse_measurement_table
from stickslip.models import JointModel
from stickslip.rig import RigError, parse_rig
from stickslip.sim.arm import NOMINAL, SimulatedMM3A

_HEADER = "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n"


@pytest.mark.parametrize(
    ("joint", "q", "slip"),
    [
        (2, -90.0, "in degrees? -90 deg is -1.5708 rad"),  # said only "outside joint 2's range"
        (1, 45.0, "in degrees? 45 deg is 0.785398 rad"),
        (3, 5.0, "in mm or µm? 5 mm is 0.005 m, 5 µm is 5e-06 m"),
        (3, 5000.0, "in µm? 5000 µm is 0.005 m"),
    ],
)
def test_a_value_outside_the_stops_names_the_unit_it_fits_in(joint: int, q: float, slip: str) -> None:
    problem = JOINTS[joint].range_problem(f"q{joint}", q)
    assert problem is not None and problem.endswith(f"({slip}: angles are in radians)" if joint < 3 else
                                                    f"({slip}: lengths are in metres)")


@pytest.mark.parametrize(
    ("joint", "q"),
    [(2, -500.0), (2, 40.0), (3, -5.0), (3, -0.5), (2, 0.6), (3, 0.02), (3, -0.01)],  # the last three: near misses
)
def test_no_slip_is_named_where_no_other_unit_fits(joint: int, q: float) -> None:
    problem = JOINTS[joint].range_problem(f"q{joint}", q)
    assert problem is not None and "?" not in problem  # -500 deg and 40 deg are outside too; no negative length fits
    assert JOINTS[2].unit_slip(-math.pi / 2) is None  # inside: no slip


def test_a_table_in_degrees_is_refused_with_the_slip_named() -> None:
    text = _HEADER + "2026-11-22,3,+,0,-90,0,0,0,0,0.01,10000\n"
    with pytest.raises(TableError, match=r"q2 = -90 rad is outside joint 2's range .* \(in degrees\? -90 deg is "):
        parse_measurements(text, "t.csv")


GOOD = Traverse("2026-11-30", 2, "+", 0.0, -1.0, 0.0, 0.0, 0.0, -1.5, 0.3, 1000)
_DEG = "angles are in radians"
_MM = "lengths are in metres"


@pytest.mark.parametrize(
    ("changes", "named"),
    [
        ({"q2": -90.0, "joint": 3, "start": 0.0, "end": 0.01}, f"q2 = -90 is no arm's position of joint 2: beyond a "
         f"full turn (6.28319 rad) (in degrees? -90 deg is -1.5708 rad: {_DEG})"),  # fitted on main, silently
        ({"start": -210.0, "end": 30.0}, "start = -210 is no arm's position of joint 2"),  # gave 5.2e-5 rad
        ({"joint": 3, "start": 0.0, "end": 10.0}, f"end = 10 is no arm's position of joint 3: beyond a metre (1 m) "
         f"(in mm or µm? 10 mm is 0.01 m, 10 µm is 1e-05 m: {_MM})"),  # a 10 m traverse: gamma 1e-2 m
        ({"q3": 5000.0}, f"q3 = 5000 is no arm's position of joint 3: beyond a metre (1 m) (in µm? 5000 µm is "
         f"0.005 m: {_MM})"),
        ({"q1": 45.0}, "q1 = 45 is no arm's position of joint 1"),
    ],
)
def test_a_traverse_built_in_degrees_or_mm_is_refused_before_it_is_fitted(
    changes: dict[str, object], named: str, tmp_path: Path
) -> None:
    bad = replace(GOOD, **changes)
    with pytest.raises(TableError, match=re.escape(f"traverse 1: {named}")):
        check_traverses([GOOD, bad])
    with pytest.raises(TableError, match="no arm's position"):
        calibrate([GOOD, bad], method="lsq")
    with pytest.raises(TableError, match="no arm's position"):
        write_measurements(tmp_path / "t.csv", [GOOD, bad])


def test_a_stage_s_and_a_full_turn_s_positions_are_still_taken() -> None:
    stage = Traverse("2026-11-30", 1, "+", 0.0, 0.02, 0.01, 0.0, 0.0, 0.0, 0.05, 1000)  # an xyz stage, m
    turn = replace(GOOD, q1=-2 * math.pi, start=-6.0, end=6.0)  # within a turn either way
    check_traverses([GOOD, stage, turn])  # no error


@pytest.mark.parametrize(
    ("fields", "named"),
    [
        ({"q2": -90.0}, f"pose: q2 = -90 is no arm's position of joint 2: beyond a full turn (6.28319 rad) "
         f"(in degrees? -90 deg is -1.5708 rad: {_DEG})"),  # was made, carried to a range check if any
        ({"q3": 5.0}, "pose: q3 = 5 is no arm's position of joint 3: beyond a metre (1 m) (in mm or µm?"),
        ({"theta": 30.0}, "pose: theta = 30 rad is outside [-pi, pi] (angles are in radians)"),
        ({"psi": math.inf}, "pose: psi must be a finite number in SI units, got inf"),
        ({"q1": math.nan, "q2": 1e9}, "pose: q1 must be a finite number in SI units, got nan; q2 = 1e+09 is no arm's"),
    ],
)
def test_a_pose_no_arm_takes_is_refused_as_it_is_made(fields: dict[str, float], named: str) -> None:
    with pytest.raises(ValueError, match=re.escape(named)):
        Pose(**fields)
    with pytest.raises(ValueError, match=re.escape(named)):
        Pose()._replace(**fields)  # the named tuple's _make and _replace are checked too
    with pytest.raises(ValueError, match=re.escape(named)):
        Pose._make({**Pose()._asdict(), **fields}.values())


def test_a_pose_any_arm_takes_is_made_as_before() -> None:
    p = Pose(0.05, 0.02, 0.01)  # a stage's metres
    assert p == (0.05, 0.02, 0.01, 0.0, 0.0) and p._replace(q3=0.0).q3 == 0.0
    assert pickle.loads(pickle.dumps(p)) == p and type(pickle.loads(pickle.dumps(p))) is Pose
    assert Pose(-MAX_TURN, MAX_TURN, -MAX_STROKE, math.pi, -math.pi) == (-MAX_TURN, MAX_TURN, -MAX_STROKE, math.pi,
                                                                          -math.pi)
    assert Pose() == (0.0, -math.pi / 2, 0.0, 0.0, 0.0) and Pose._fields == ("q1", "q2", "q3", "theta", "psi")


def test_the_simulator_s_tilt_says_its_unit() -> None:
    with pytest.raises(ValueError, match=re.escape("theta = 30 rad is outside [-pi, pi] (angles are in radians)")):
        SimulatedMM3A().set_pose(theta=30.0)


_MM3A_TEXT = (Path(JOINTS_FILE).read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    ("old", "new", "named"),
    [
        ('range = ["-120deg", "120deg"]', 'range = ["-400deg", "120deg"]',
         "reaches 400 deg: beyond a full turn either way, no joint's position (a unit slip?)"),
        ('range = ["0mm", "12mm"]', 'range = ["0mm", "2m"]', "reaches 2 m: beyond a metre either way"),
    ],
)
def test_a_rig_s_joint_beyond_a_turn_or_a_metre_is_refused(old: str, new: str, named: str) -> None:
    assert old in _MM3A_TEXT
    with pytest.raises(RigError, match=re.escape(named)):  # its kept positions would be no Pose (units58)
        parse_rig(_MM3A_TEXT.replace(old, new), "rig.toml")
    parse_rig(_MM3A_TEXT, "rig.toml")  # the shipped one reads


def test_plan_on_the_command_line_says_a_pose_no_arm_takes_in_one_line(tmp_path: Path) -> None:
    from synth import paper_table
    from typer.testing import CliRunner

    from stickslip.cli import app

    calibrate(paper_table()).save(tmp_path / "cal.json")
    r = CliRunner().invoke(app, ["plan", "-c", str(tmp_path / "cal.json"), "--joint", "3", "--from", "2mm", "--to",
                                 "2.03mm", "--q2", "-90rad"])
    assert r.exit_code == 2, r.output
    assert "error: pose: q2 = -90 is no arm's position of joint 2" in r.output and "Traceback" not in r.output


@pytest.mark.parametrize(
    ("old", "new", "named"),
    [
        ("q2,", "q2_deg,", "q2_deg names a unit: the columns are SI and named without one (write q2 in rad)"),
        ("q3,", "q3 [mm],", "q3 [mm] names a unit: the columns are SI and named without one (write q3 in m)"),
        ("theta,psi", "theta (degrees),psi (degrees)", "theta (degrees), psi (degrees) name a unit: the columns are SI "
         "and named without one (write theta, psi in rad)"),
        ("start,end", "start_um,end_um", "(write start, end in rad or m, the joint's unit)"),
        ("q1,q2", "q1 [rad],q2 [deg]", "q1 [rad], q2 [deg] name a unit: the columns are SI and named without one "
         "(write q2 in rad; call it q1)"),
    ],
)
def test_a_column_named_with_its_unit_is_told_to_be_si(old: str, new: str, named: str) -> None:
    header = _HEADER.replace(old, new)
    for parse in (parse_measurements, parse_measurement_table):  # the row reader and the columnar one
        with pytest.raises(TableError, match=re.escape(named)):  # said only "missing q2; unexpected q2_deg"
            parse(header + "2026-11-22,3,+,0,-1.5,0,0,0,0,0.01,10000\n", "t.csv")


def test_a_pose_table_s_column_named_with_its_unit_is_told_to_be_si() -> None:
    with pytest.raises(TableError, match=re.escape("q2_deg names a unit: the columns are SI and named without one "
                                                   "(write q2 in rad)")):
        parse_pose_table("joint,direction,q1,q2_deg,q3,theta,psi\n3,+,0,-90,0,0,0\n", "p.csv")
    assert unit_column_problem(["q2", "q2_note", "x_deg", "sample_um"], HEADER) is None  # no column with a unit


@pytest.mark.parametrize(
    ("joint", "gamma", "slip"),
    [
        (3, "970", "in nm? 970 nm is 9.7e-07 m"),  # the unit `stickslip` shows steps of joint 3 in
        (3, "0.97", "in nm or µm? 0.97 nm is 9.7e-10 m, 0.97 µm is 9.7e-07 m"),
        (2, "40", "in µrad? 40 µrad is 4e-05 rad"),
    ],
)
def test_a_step_size_in_nm_or_urad_is_refused_with_the_slip_named(joint: int, gamma: str, slip: str) -> None:
    text = ("day,joint,direction,q1,q2,q3,theta,psi,gamma,sigma,steps,method\n"
            f"2026-11-22,{joint},+,0,-1.5,0.005,0,0,{gamma},1e-8,100,camera\n")
    with pytest.raises(TableError, match=re.escape(f"is not a step size of joint {joint} (") + ".*" + re.escape(slip)):
        parse_step_sizes(text, "s.csv")  # said only "(1e-10..0.0001 m; SI units)"


def test_a_bare_length_beyond_a_metre_in_a_rig_file_is_refused_as_mm_without_its_unit() -> None:
    thick = _MM3A_TEXT.replace('radius = "0.5mm"', 'radius = 2')  # 2 m: 2 mm meant (was taken)
    named = 'arm[1].radius: 2 has no unit, so it is 2 m: more than a metre; write its unit ("2mm" for millimetres'
    with pytest.raises(RigError, match=re.escape(named)):
        parse_rig(thick, "rig.toml")
    assert parse_rig(_MM3A_TEXT.replace('length = "21mm"', "length = 0.021"), "rig.toml")  # a bare metre's part


@pytest.mark.parametrize(("fields", "named"), [
    ({"length": 23.5}, "geometry length = 23.5 m must be in (0, 1] m (in mm? 23.5 mm is 0.0235 m: lengths are in "
     "metres)"),
    ({"offset": -3.0}, "geometry offset = -3 m must be within ±1 m (in mm? -3 mm is -0.003 m: lengths are in metres)"),
])
def test_a_geometry_in_mm_is_refused_with_the_slip_named(fields: dict[str, float], named: str) -> None:
    with pytest.raises(ValueError, match=re.escape(named)):  # a config file's bare 'length = 23.5' said only the range
        Geometry(**fields)
    with pytest.raises(ValueError, match=r"must be in \(0, 1\] m$"):
        Geometry(length=-0.02)  # not a slip: no hint


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda m: m.gamma(0.0, -90.0, 0.0, 0.0, 0.0), "JointModel.gamma: q2 = -90 is no arm's position of joint 2: "
         "beyond a full turn (6.28319 rad) (in degrees? -90 deg is -1.5708 rad"),  # gave 4.47e-5 rad, silently
        (lambda m: m.gamma(0.0, -1.5, 5.0, 0.0, 0.0), "JointModel.gamma: q3 = 5 is no arm's position of joint 3"),
        # (5 m: gave -6.7e-3 rad, a negative step)
        (lambda m: m.gamma(0.0, np.array([-1.5, -1.0, np.nan]), 0.0, 0.0, 0.0), "q2 must be a finite number"),
        (lambda m: m.average_gamma(-210.0, 30.0, 0.0, 0.0, 0.0, 0.0, 0.0), "JointModel.average_gamma: start = -210 "
         "is no arm's position of joint 2"),
        (lambda m: m.average_gamma(-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 5.0), "psi = 5 rad is outside [-pi, pi]"),
    ],
)
def test_a_joint_model_refuses_a_pose_no_arm_takes(call: Callable[[JointModel], object], named: str) -> None:
    model = JointModel(2, "+", NOMINAL[(2, "+")])
    with pytest.raises(ValueError, match=re.escape(named)):
        call(model)
    q2 = np.linspace(-3.6, 0.5, 5)
    assert np.all(model.gamma(0.0, q2, 0.0, 0.0, 0.0) > 0)  # an array of poses any arm takes: as before


def test_a_sample_rate_in_khz_is_refused_with_the_slip_named(tmp_path: Path) -> None:
    from stickslip.audio.sources.files import AudioSourceError
    from stickslip.audio.sources.vibration import read_vibration
    from stickslip.audio.tuningfile import TUNING_FILE

    (tmp_path / "v.csv").write_text("x\n0.1\n0.2\n", encoding="utf-8")
    with pytest.raises(AudioSourceError, match=re.escape("sample rate 48 Hz is outside 1000-1000000 Hz (in kHz? "
                                                         "48 kHz is 48000 Hz: rates are in Hz)")):
        read_vibration(tmp_path / "v.csv", sample_rate=48.0)  # `stickslip tune --sample-rate 48`: said the range
    assert TUNING_FILE.rate_problem(44.1) == ("sample rate 44.1 Hz is outside 2000-192000 Hz (in kHz? 44.1 kHz is "
                                              "44100 Hz: rates are in Hz)")
    assert TUNING_FILE.rate_problem(500.0) == "sample rate 500 Hz is outside 2000-192000 Hz"  # 500 kHz is no rate


def test_a_move_target_given_as_a_number_in_degrees_names_the_slip() -> None:
    """The control room's HTTP API and Python take SI numbers: {"to": -60} meant as degrees was refused as 'the
    target -3437.75 deg is outside ...; positions are in deg', which read as if -60 had been taken as degrees
    (units58). Now it names the slip; a relative move (by) or a near miss gets no guess."""
    from stickslip.devices.positions import DeviceState
    from stickslip.procedures.move import TargetOutOfRange, target_of

    state = DeviceState("sim://", {1: 0.0, 2: -math.pi / 2, 3: 0.0}, dict.fromkeys((1, 2, 3), "set"))
    with pytest.raises(TargetOutOfRange) as e:
        target_of(state, 2, to=-60.0)
    assert "positions are in deg (in degrees? -60 deg is -1.0472 rad: angles are in radians)" in str(e.value)
    with pytest.raises(TargetOutOfRange) as e:
        target_of(state, 2, by=-60.0)
    assert str(e.value).endswith("positions are in deg"), str(e.value)
    with pytest.raises(TargetOutOfRange) as e:
        target_of(state, 3, to=0.0121)  # 12.1 mm: a near miss, not a unit
    assert str(e.value).endswith("positions are in µm"), str(e.value)


def test_a_kept_position_or_tilt_set_from_python_in_degrees_names_the_slip() -> None:
    """DeviceState.set_position / set_tilt (the Python API, `where --set` after parsing, a server's JSON) said only
    'outside the range' for q2 = -90 meant as degrees (units58)."""
    from stickslip.devices.positions import DeviceState

    state = DeviceState("sim://", {1: 0.0, 2: -math.pi / 2, 3: 0.0}, dict.fromkeys((1, 2, 3), "set"))
    with pytest.raises(ValueError, match=re.escape("(in degrees? -90 deg is -1.5708 rad: angles are in radians)")):
        state.set_position(2, -90.0)
    with pytest.raises(ValueError, match=re.escape("theta = 45 rad is outside [-pi, pi] (angles are in radians)")):
        state.set_tilt(theta=45.0)
    with pytest.raises(ValueError, match="outside joint 3's range") as e:
        state.set_position(3, 0.0121)  # a near miss: no guess
    assert "in mm" not in str(e.value) and state.positions[2] == -math.pi / 2 and state.theta == 0.0


def test_a_stored_traverse_a_fit_now_refuses_is_named_by_its_id(tmp_path: Path) -> None:
    """A store written before traverses were checked (units58) may hold q3 = 5 (mm as m) or a tilt of 4 rad.
    fit, report and export refused it as 'traverse 1', its place in a list from 0: the stored id 2, and
    `stickslip delete -t 1` removed another row. They now name the stored id and how to go on; excluded, the
    rest is exported (anova, which fits nothing, still runs)."""
    import sqlite3

    from synth import paper_table
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.storage import Store

    db = tmp_path / "lab.db"
    with Store.open(db) as st:
        st.add_traverses(paper_table()[:4], device="sim://")
    con = sqlite3.connect(db)
    con.execute("UPDATE traverses SET q3 = 5.0 WHERE id = 2")
    con.execute("UPDATE traverses SET theta = 4.0 WHERE id = 3")
    con.commit()
    con.close()
    runner = CliRunner()
    for args in (["fit"], ["report"], ["export", "-o", str(tmp_path / "m.csv")]):
        r = runner.invoke(app, [*args, "--db", str(db)])
        said = " ".join(r.output.split())
        assert r.exit_code == 2, (args, said)
        assert "stored traverse 2 (sim://, 2026-11-22): q3 = 5 is no arm's position of joint 3" in said, said
        assert "stored traverse 3 (sim://, 2026-11-22): theta = 4 rad is outside [-pi, pi]" in said, said
        assert "traverse 1:" not in said and "stickslip exclude -t ID" in said
    assert runner.invoke(app, ["anova", "--db", str(db)]).exit_code == 0
    assert runner.invoke(app, ["exclude", "-t", "2", "-t", "3", "-r", "mm", "--db", str(db)]).exit_code == 0
    r = runner.invoke(app, ["export", "-o", str(tmp_path / "m.csv"), "--db", str(db)])
    assert r.exit_code == 0 and len(parse_measurements((tmp_path / "m.csv").read_text())) == 2, r.output


@pytest.mark.parametrize("field", ["q1", "q2", "q3", "theta", "psi"])
def test_a_pose_of_an_int_too_large_for_a_float_is_refused_not_an_overflow(field: str) -> None:
    """Pose(q2=10**400) (a notebook's int, a JSON integer) raised OverflowError from float(), not the ValueError a
    Pose promises; the message does not write the 401 digits out."""
    with pytest.raises(ValueError, match=f"{field} must be a finite number in SI units, got 1000") as e:
        Pose(**{field: 10**400})
    assert not isinstance(e.value, OverflowError) and len(str(e.value)) < 120


def test_a_traverse_of_an_int_too_large_for_a_float_is_refused_not_an_overflow() -> None:
    """check_traverses raised OverflowError (math.isfinite of 10**400) where it lists problems."""
    t = Traverse("2026-11-22", 3, "+", 0.0, -1.0, 0.001, 0.0, 0.0, 0.0, 10**400, 10)
    with pytest.raises(TableError, match="end must be a finite number"):
        check_traverses([t])


_MOVING_OWN_Q = (
    "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n"
    "2026-11-22,3,+,0,-1,5,0,0,0,0.001,10\n"  # joint 3's own q3 in mm: ignored by the fit, refused by the store
    "2026-11-22,2,+,0,-90,0.001,0,0,-0.5,0.2,10\n"  # joint 2's own q2 in degrees
)


@pytest.mark.parametrize("reader", ["rows", "columns", "import"])
def test_a_moving_joint_s_own_coordinate_no_arm_takes_is_refused_by_the_reader_naming_its_line(
    tmp_path: Path, reader: str
) -> None:
    """The readers skipped the moving joint's own q (ignored) while the store refuses it as no arm's position:
    such a table read, then import failed with 'traverse '2026-11-22' joint 3 +: q3 = 5 ...' (no file, no line, the
    second row unsaid) and fit with 'traverse 0: ...'. Now the reader names each line."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    path = tmp_path / "m.csv"
    path.write_text(_MOVING_OWN_Q)
    if reader == "import":
        r = CliRunner().invoke(app, ["import", str(path), "-d", "sim://", "--db", str(tmp_path / "s.db")])
        said = " ".join(r.stderr.split())
    else:
        with pytest.raises(TableError) as e:
            (parse_measurements if reader == "rows" else parse_measurement_table)(_MOVING_OWN_Q, str(path))
        said = " ".join(str(e.value).split())
    assert f"{path}:2: q3 = 5 is no arm's position of joint 3: beyond a metre" in said, said
    assert f"{path}:3: q2 = -90 is no arm's position of joint 2: beyond a full turn" in said, said
