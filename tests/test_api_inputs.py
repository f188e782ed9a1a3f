"""The Python API as a notebook calls it: a bad argument is refused early, by name, not used (audit54)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.calibration import Calibration
from stickslip.kinematics import Pose
from stickslip.measurements import TableError, Traverse, read_measurements, write_measurements
from stickslip.models import (
    JointModel,
    NonPhysicalError,
    PrismaticParams,
    RotaryParams,
    StepProfile,
    position_after_steps,
    steps_between,
)
from stickslip.motion.planning import Planner
from stickslip.sim.arm import NOMINAL

ROT = RotaryParams((52.0e-6, 47.0e-6), (-8.15e-6, -19.40e-6))
PRISM = PrismaticParams(972e-9, 0.27, 372e-9)


@pytest.mark.parametrize(
    ("joint", "direction", "params", "named"),
    [
        (3, "+", ROT, "joint 3"),  # gave 1.05e-5 "m" from rotary parameters in rad
        (2, "+", PRISM, "joint 2"),  # gave 8.9e-8 "rad" from the prismatic Eq. 3
        (7, "+", ROT, "joint = 7"),
        (2, "x", ROT, "direction = 'x'"),
        (2, 1, ROT, "direction = 1"),
        ("2", "+", ROT, "joint = '2'"),
    ],
)
def test_joint_model_refuses_a_joint_direction_or_params_that_do_not_fit(
    joint: object, direction: object, params: object, named: str
) -> None:
    with pytest.raises(ValueError, match=named):
        JointModel(joint, direction, params)  # type: ignore[arg-type]


def test_joint_model_accepts_the_paper_s_pairs() -> None:
    assert JointModel(3, "-", PRISM).gamma(0.0, -math.pi / 2, 0.0, 0.0, 0.0) == pytest.approx(972e-9 - 372e-9 * 0.0)
    assert JointModel(1, "+", ROT).joint == 1


GOOD = Traverse("2026-11-30", 2, "+", 0.0, -1.0, 0.0, 0.0, 0.0, -1.5, 0.3, 1000)


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [
        ("theta", 30.0, "theta = 30 rad"),  # degrees: written, then refused by read_measurements
        ("steps", 0, "steps"),
        ("steps", -3, "steps"),  # gamma was -0.67 rad
        ("direction", "x", "direction must be"),
        ("joint", 5, "joint must be"),
        ("start", math.nan, "start must be"),
        ("day", "", "day"),
    ],
)
def test_write_measurements_refuses_a_traverse_it_could_not_read_back(
    tmp_path: Path, field: str, value: object, named: str
) -> None:
    path = tmp_path / "m.csv"
    write_measurements(path, [GOOD])
    before = path.read_text()
    bad = replace(GOOD, **{field: value})
    with pytest.raises(TableError, match=f"traverse 1: .*{named}"):
        write_measurements(path, [GOOD, bad])
    assert path.read_text() == before  # the old file is kept
    assert read_measurements(path) == [GOOD]


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda: steps_between(math.nan, 1.0, 1e-5), "start"),  # was array(nan)
        (lambda: steps_between(0.0, math.inf, 1e-5), "end"),  # was array(inf)
        (lambda: steps_between(0.0, 1.0, math.nan), "A"),
        (lambda: steps_between(np.array([0.0, math.nan]), 1.0, 1e-5), "start"),  # was [1e5, nan]
        (lambda: steps_between(0.0, 1.0, 5e-5, math.nan), "alpha"),
        (lambda: position_after_steps(0.0, math.nan, 1, 1e-5), "n_steps"),  # was nan
        (lambda: position_after_steps(0.0, -10, 1, 1e-5), "n_steps"),  # was -1e-4: backwards
        (lambda: position_after_steps(math.inf, 10, 1, 1e-5), "start"),
        (lambda: StepProfile(1e-5).inverse(0.0, 3, 5), "sign"),  # was 1.5e-4: five times as far
        (lambda: StepProfile(1e-5).inverse(0.0, -3, 1), "n_steps"),
        (lambda: StepProfile(1e-5).steps(0.0, math.nan), "end"),
        (lambda: StepProfile(math.nan), "A"),
    ],
)
def test_step_integrals_refuse_a_non_finite_value_or_a_bad_count(call: Callable[[], object], named: str) -> None:
    with pytest.raises(ValueError, match=named):
        call()


_floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, 1e-5, -1e-5, 1.0]))


@settings(deadline=None)  # the first call imports scipy
@given(_floats, _floats, _floats, _floats, _floats, st.booleans())
def test_steps_between_is_a_finite_count_or_a_value_error(
    start: float, end: float, A: float, alpha: float, beta: float, arrays: bool
) -> None:
    """Found by this test: (0, 0, 4e-110, 0, 1) gave nan (a zero-length traverse at a near-stall), (0, 1, 4e-179,
    0, 1) nan (the log form within rounding of a stall), (0, 4e156, 2e-152) inf."""
    args = [np.asarray([x]) if arrays else x for x in (start, end, A, alpha, beta)]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy's quadrature may warn on a huge interval
            n = float(np.asarray(steps_between(*args)).ravel()[0])
    except ValueError:
        return
    assert math.isfinite(n)
    assert n >= 0.0


@pytest.mark.parametrize("knots", [(0.0, 12.0), (0.0, 0.0), (math.nan, 0.012), (0.0, math.inf)])
def test_rotary_params_refuse_knots_in_mm_equal_or_not_finite(knots: tuple[float, float]) -> None:
    # (0, 12): at q3 = 12 mm the model used the q3 = 0 values (0.1 % of the way); (0, 0): nan steps
    with pytest.raises(ValueError, match=r"knots = \("):
        RotaryParams((52.0e-6, 47.0e-6), (-8.15e-6, -19.40e-6), knots)


def test_rotary_params_interpolate_between_the_paper_s_knots() -> None:
    g0, d = ROT.at(0.006)
    assert float(g0) == pytest.approx(49.5e-6)
    assert float(d) == pytest.approx((-8.15e-6 - 19.40e-6) / 2)


@pytest.mark.parametrize(
    "params",
    [
        PrismaticParams(972.0, 0.27, 372.0),  # nm written as m: accepted, every plan a billionth of its steps
        PrismaticParams(0.972, 0.27, 0.372),  # mm written as m
        RotaryParams((52.0, 47.0), (-8.15, -19.40)),  # µrad written as rad
    ],
)
def test_check_physical_refuses_a_step_longer_than_the_joint_s_travel(params: PrismaticParams | RotaryParams) -> None:
    with pytest.raises(NonPhysicalError, match="a step longer than"):
        params.check_physical()


def test_check_physical_accepts_the_simulator_s_nominal_parameters() -> None:
    for params in NOMINAL.values():
        params.check_physical()


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [
        ("theta", -90.0, "traverse 1: theta = -90 rad"),  # a day in degrees was fitted, silently
        ("steps", 0, "traverse 1: steps"),  # was a ZeroDivisionError 8 frames deep
        ("end", math.nan, "traverse 1: end must be"),
    ],
)
def test_calibrate_refuses_a_traverse_that_could_not_be_a_table_row(field: str, value: object, named: str) -> None:
    from stickslip.calibration import calibrate
    from stickslip.calibration.groups import TraverseGroups

    rows = [GOOD, replace(GOOD, **{field: value})]
    with pytest.raises(TableError, match=named) as e:
        calibrate(rows, method="lsq")
    assert "written" not in str(e.value)
    with pytest.raises(TableError, match=named):
        TraverseGroups(rows)  # what calibrate_paper / calibrate_lsq / the families take


@pytest.fixture(scope="module")
def paper_calibration() -> Calibration:
    m = {(j, d): JointModel(j, d, p) for (j, d), p in NOMINAL.items()}
    return Calibration(m, {k: None for k in m}, {}, "2026-11-30", "paper")


@pytest.mark.parametrize(
    ("pose", "q", "named"),
    [
        ((0.0, -90.0, 0.0, 0.0, 0.0), None, r"q2 = -90 .*\(in degrees\?"),  # gave 4.47e-5 rad on main, silently
        ({"q2": -90.0}, None, r"q2 = -90 .*\(in degrees\?"),  # a Pose in degrees: refused as it is made (units58)
        ({"q2": -1.0, "theta": 30.0}, None, "theta = 30 rad"),
        ({"q2": math.nan}, None, "q2 must be a finite"),  # gave nan
        ({"q3": 5.0}, None, r"q3 = 5 .*\(in mm or µm\?"),  # mm as m: gave -6.7e-3 rad, a negative step
        ({}, -90.0, r"q2 = -90 .*\(in degrees\?"),
    ],
)
def test_calibration_gamma_refuses_a_pose_in_degrees_or_not_finite(
    paper_calibration: Calibration, pose: dict[str, float] | tuple[float, ...], q: float | None, named: str
) -> None:
    with pytest.raises(ValueError, match=named):
        paper_calibration.gamma(2, "+", Pose(**pose) if isinstance(pose, dict) else pose, q)


def test_calibration_gamma_takes_a_pose_as_five_numbers(paper_calibration: Calibration) -> None:
    want = paper_calibration.gamma(2, "+", Pose(q2=-1.0))
    assert paper_calibration.gamma(2, "+", (0.0, -1.0, 0.0, 0.0, 0.0)) == want  # was AttributeError: 'tuple' ... q1
    assert want == pytest.approx(float(JointModel(2, "+", NOMINAL[(2, "+")]).gamma(0.0, -1.0, 0.0, 0.0, 0.0)))


def test_calibration_predict_refuses_a_traverse_in_degrees(paper_calibration: Calibration) -> None:
    bad = replace(GOOD, theta=30.0)
    with pytest.raises(TableError, match="theta = 30 rad"):
        paper_calibration.predict(bad)  # gave 5.14e-5 rad on main (4.78e-5 at theta 0), silently
    with pytest.raises(TableError, match="traverse 1: theta = 30 rad"):
        paper_calibration.predict_many([GOOD, bad])


@pytest.mark.parametrize(("name", "value"), [("roll", 90.0), ("azimuth", -45.0), ("roll", 7.0)])
def test_view_refuses_an_angle_in_degrees(name: str, value: float) -> None:
    from stickslip.vision import View

    with pytest.raises(ValueError, match=f"view {name} = {value:g} rad is more than a full turn"):
        View(**{name: value})  # roll 90 was a roll of 90 rad (116.6 deg), silently


def test_view_keeps_an_angle_within_a_turn() -> None:
    from stickslip.vision import View

    assert View(roll=-2 * math.pi, azimuth=math.pi / 2).roll == pytest.approx(-2 * math.pi)


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda p: p.steps(-60.0, -50.0), "q_from = -60 rad is more than a full turn"),  # was 139624 steps
        (lambda p: p.exact_steps(-1.0, -50.0), "q_to = -50 rad"),
        (lambda p: p.position_after(-90.0, 100), "q_start = -90 rad"),
        (lambda p: p.steps(-1.0, math.nan), "q_to = nan must be a finite"),
    ],
)
def test_planner_refuses_a_position_in_degrees(
    paper_calibration: Calibration, call: Callable[[Planner], object], named: str
) -> None:
    with pytest.raises(ValueError, match=named):
        call(Planner(paper_calibration, 2, Pose(q2=-1.0)))


def test_planner_refuses_millimetres_for_joint_3(paper_calibration: Calibration) -> None:
    planner = Planner(paper_calibration, 3, Pose())
    with pytest.raises(ValueError, match="q_to = 5 m is more than a metre"):
        planner.steps(0.0, 5.0)
    assert planner.steps(0.0, 5e-6) == round(5e-6 / float(JointModel(3, "+", NOMINAL[(3, "+")]).gamma(0, -math.pi / 2,
                                                                                                        0, 0, 0)))


@pytest.mark.parametrize(
    ("kw", "error", "named"),
    [
        ({"by": "0.5deg"}, TypeError, "by = '0.5deg' must be a number in rad"),  # was 'could not convert string'
        ({"by": "0.01"}, TypeError, "by = '0.01' must be a number"),  # was taken as 0.01 rad
        ({"to": "-1.0"}, TypeError, "to = '-1.0' must be a number"),
        ({"by": math.nan}, ValueError, "by = nan must be a finite"),  # was 'the target nan deg is outside ...'
    ],
)
def test_move_refuses_a_displacement_that_is_not_a_number(
    tmp_path: Path, paper_calibration: Calibration, kw: dict[str, object], error: type[Exception], named: str
) -> None:
    from stickslip.procedures.move import MoveRequest, move
    from stickslip.storage import Store

    with Store.open(tmp_path / "s.db") as store, pytest.raises(error, match=named):
        move(store, MoveRequest(device="sim://", joint=2, **kw), paper_calibration)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kw", "named"),
    [
        ({"taper": 8.0}, "taper = 8.0 must be"),  # degrees: a cone of 8 rad, rendered silently
        ({"pixel_size_m": 0.5}, "pixel_size_m = 0.5 must be"),  # µm as m
        ({"dof_m": 4.0}, "dof_m = 4.0"),
        ({"tip_radius_m": math.nan}, "tip_radius_m = nan"),
    ],
)
def test_sim_camera_settings_take_the_url_s_bounds_in_python_too(kw: dict[str, object], named: str) -> None:
    from stickslip.sim.camera import SimCamSettings

    with pytest.raises(ValueError, match=named):
        SimCamSettings(**kw)  # type: ignore[arg-type]


def test_sim_camera_default_settings_are_within_the_bounds() -> None:
    from stickslip.sim.camera import SimCamSettings

    assert SimCamSettings().taper == pytest.approx(math.radians(8.0))
    assert SimCamSettings(look="sem", taper=math.radians(45.0)).look == "sem"


def test_planner_names_a_pose_of_three_numbers(paper_calibration: Calibration) -> None:
    with pytest.raises(ValueError, match=r"pose = \[0.0, -1.0, 0.0\]: a Pose or its five numbers"):
        Planner(paper_calibration, 2, [0.0, -1.0, 0.0])
    five = Planner(paper_calibration, 2, (0.0, -1.0, 0.0, 0.0, 0.0))
    assert five.pose == Pose(q2=-1.0)
    assert five.steps(-1.0, -0.9) == Planner(paper_calibration, 2, Pose(q2=-1.0)).steps(-1.0, -0.9)


@pytest.mark.parametrize(("kw", "named"), [({"q2": "a"}, "q2 = 'a' must be a number in rad"),
                                           ({"q3": "5mm"}, "q3 = '5mm' must be a number in m"),
                                           ({"theta": None, "psi": "0.1"}, "psi = '0.1' must be a number in rad")])
def test_simulator_set_pose_names_an_argument_that_is_not_a_number(kw: dict[str, object], named: str) -> None:
    from stickslip.sim.arm import open_url

    arm = open_url("sim://")
    with pytest.raises(TypeError, match=named):
        arm.set_pose(**kw)  # type: ignore[arg-type]
    arm.set_pose(q2=np.float64(-1.0))
    assert arm.position(2) == -1.0


@pytest.mark.parametrize("pixel", [0.5, 0.0, math.nan, -1e-6])
def test_projection_refuses_a_pixel_size_that_is_not_one(pixel: float) -> None:
    from stickslip.vision.view import TOP_VIEW, base_to_image, project

    with pytest.raises(ValueError, match="pixel_size_m = .* must be a pixel size"):
        base_to_image(TOP_VIEW, pixel)  # 0.5 (µm as m) gave 2 px per m; 0 gave inf with a warning
    with pytest.raises(ValueError, match="pixel_size_m"):
        project(np.zeros(3), TOP_VIEW, pixel, np.zeros(3), (0.0, 0.0))
    assert base_to_image(TOP_VIEW, 0.5e-6)[0, 0] == pytest.approx(2e6)


@pytest.mark.parametrize("path", ["lab.db", Path("lab.db")])
def test_a_store_made_from_a_path_says_to_open_it(path: str | Path, tmp_path: Path) -> None:
    from stickslip.storage import Store

    with pytest.raises(TypeError, match=r"open a database with Store\.open\('lab\.db'\)"):
        Store(path)  # type: ignore[arg-type]  # before: AttributeError: 'str' object has no attribute 'where'
    assert not (tmp_path / "lab.db").exists()
    with Store.open(tmp_path / "lab.db") as store:
        assert store.count_traverses() == 0
