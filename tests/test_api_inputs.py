"""The Python API as a notebook calls it: a bad argument is refused early, by name, not used (audit54)."""

from __future__ import annotations

import math

import pytest

from stickslip.models import JointModel, PrismaticParams, RotaryParams

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
