"""A quantity in the wrong unit is refused with the likely slip named: degrees for radians, mm or µm for m (units58)."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import pytest

from stickslip.calibration import calibrate
from stickslip.joints import JOINTS
from stickslip.measurements import TableError, Traverse, check_traverses, parse_measurements, write_measurements

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


@pytest.mark.parametrize(("joint", "q"), [(2, -500.0), (2, 40.0), (3, -5.0), (3, -0.5)])
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
