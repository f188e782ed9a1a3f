"""A quantity in the wrong unit is refused with the likely slip named: degrees for radians, mm or µm for m (units58)."""

from __future__ import annotations

import math

import pytest

from stickslip.joints import JOINTS
from stickslip.measurements import TableError, parse_measurements

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
