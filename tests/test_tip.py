"""The tip in task space: forward kinematics, Jacobian, inverse kinematics, limits, singularities.

Independent references: the tip is recomputed by composing rotations with scipy's
``Rotation`` (joint 2 turns about -y1, docs/design.md §2), not with the closed form;
the Jacobian is checked against central finite differences; the inverse is checked
by round trips over the whole joint space with hypothesis.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from stickslip import kinematics as kin
from stickslip.kinematics import (
    DEFAULT_GEOMETRY,
    Geometry,
    OutOfReach,
    SingularPose,
    distance_from_axis,
    inverse,
    jacobian,
    joint_rates,
    tip,
)

J1, J2, J3 = kin.JOINTS[1], kin.JOINTS[2], kin.JOINTS[3]


def tip_by_rotations(q, g: Geometry) -> np.ndarray:
    """p = R1 (offset x + R2 (length + q3) z): R1 about z0 by q1, R2 about -y1 by q2."""
    q1, q2, q3 = q
    r1 = Rotation.from_rotvec([0.0, 0.0, q1])
    r2 = Rotation.from_rotvec([0.0, -q2, 0.0])
    return r1.apply(np.array([g.offset, 0.0, 0.0]) + r2.apply([0.0, 0.0, g.length + q3]))


joint_q = st.tuples(st.floats(J1.lower, J1.upper), st.floats(J2.lower, J2.upper), st.floats(J3.lower, J3.upper))
geometries = st.builds(Geometry, st.floats(-5e-3, 5e-3), st.floats(5e-3, 60e-3))


def test_design_frames():
    """q2 = 0 points the arm up, q2 = -pi/2 holds it out along x0 (docs/design.md §2)."""
    g = Geometry(0.002, 0.021)
    np.testing.assert_allclose(tip([0.0, 0.0, 0.0], g), [0.002, 0.0, 0.021], atol=1e-15)
    np.testing.assert_allclose(tip([0.0, -math.pi / 2, 0.001], g), [0.024, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(tip([math.pi / 2, -math.pi / 2, 0.0], g), [0.0, 0.023, 0.0], atol=1e-15)
    # the arm axis of the frames module is the direction of joint 3's column
    q = np.array([0.3, -1.1, 0.004])
    np.testing.assert_allclose(jacobian(q, g)[:, 2], kin.arm_axis(q[0], q[1]), atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(joint_q, geometries)
def test_tip_matches_composed_rotations(q, g):
    np.testing.assert_allclose(tip(q, g), tip_by_rotations(q, g), atol=1e-15)


def test_tip_vectorised():
    qs = np.array([[0.1, -1.0, 0.0], [-0.5, -2.0, 0.01]])
    out = tip(qs)
    assert out.shape == (2, 3)
    np.testing.assert_allclose(out[1], tip(qs[1]), rtol=0, atol=0)
    assert jacobian(qs).shape == (2, 3, 3)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(joint_q, geometries)
def test_jacobian_against_finite_differences(q, g):
    q = np.array(q)
    h = np.array([1e-6, 1e-6, 1e-7])
    fd = np.empty((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = h[i]
        fd[:, i] = (tip_by_rotations(q + e, g) - tip_by_rotations(q - e, g)) / (2 * h[i])
    # central differences: error ~ h^2 |p'''| ~ 1e-12 * 0.07 m; rounding ~ 1e-17 / 1e-6
    np.testing.assert_allclose(jacobian(q, g), fd, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(joint_q, geometries)
def test_jacobian_columns_orthogonal_with_lengths_rho_r_1(q, g):
    J = jacobian(q, g)
    gram = J.T @ J
    rho = float(distance_from_axis(q, g))
    r = g.length + q[2]
    np.testing.assert_allclose(np.diag(gram), [rho**2, r**2, 1.0], rtol=1e-12, atol=1e-18)
    off = gram - np.diag(np.diag(gram))
    assert np.max(np.abs(off)) < 1e-15
    with np.errstate(divide="ignore", invalid="ignore"):  # LAPACK's det at rho = 0 exactly
        det = np.linalg.det(J)
    assert abs(det) == pytest.approx(rho * r, rel=1e-9, abs=1e-18)


@settings(max_examples=300, deadline=None)
@given(joint_q, geometries)
def test_inverse_round_trip(q, g):
    q = np.array(q)
    p = tip(q, g)
    rho = float(distance_from_axis(q, g))
    if rho < 2 * kin.MIN_REACH:
        with pytest.raises(SingularPose) if rho < kin.MIN_REACH else _nothing():
            inverse(p, g, near=q)
        return
    q_back = inverse(p, g, near=q)
    # the same tip, within 1e-12 m (the closed form loses nothing to iteration)
    np.testing.assert_allclose(tip(q_back, g), p, atol=1e-12)
    # and, started near q, the same branch: the same joints
    np.testing.assert_allclose(q_back, q, atol=1e-9)


@settings(max_examples=300, deadline=None)
@given(joint_q, joint_q, geometries)
def test_inverse_reaches_every_pose_in_range_whatever_it_starts_near(q, near, g):
    # the turn of joint 2 nearest `near` was the only one tried: from near q2 = -200 deg, a tip at q2 = +23 deg
    # (reachable) was refused as "joint 2 would be at -337 deg"; the turn inside the 240 deg range is now found
    q = np.array(q)
    if float(distance_from_axis(q, g)) < 2 * kin.MIN_REACH:
        return
    p = tip(q, g)
    q_back = inverse(p, g, near=np.array(near))
    np.testing.assert_allclose(tip(q_back, g), p, atol=1e-12)
    assert kin.limit_problem(q_back) is None


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_inverse_picks_a_branch_within_limits():
    g = DEFAULT_GEOMETRY
    # tip straight ahead at 25 mm, level: q1 = 0, q2 = -pi/2, q3 = 4 mm
    q = inverse([0.025, 0.0, 0.0], g)
    np.testing.assert_allclose(q, [0.0, -math.pi / 2, 0.004], atol=1e-12)
    # behind the base (q1 = pi is beyond joint 1's 120 deg): the other branch, q1 = 0, q2 = +pi/2,
    # is beyond joint 2's upper limit too, so reaching behind is out of reach with a named limit
    with pytest.raises(OutOfReach, match=r"joint [12] would be at .* beyond its (upper|lower) limit"):
        inverse([-0.025, 0.0, -0.001], g)


def test_inverse_out_of_reach_names_joint3():
    with pytest.raises(OutOfReach, match=r"joint 3 would be at 14000 µm, beyond its upper limit 12000 µm"):
        inverse([0.035, 0.0, 0.0], Geometry(0.0, 0.021))
    with pytest.raises(OutOfReach, match=r"joint 3 would be at -1000 µm, beyond its lower limit 0 µm"):
        inverse([0.020, 0.0, 0.0], Geometry(0.0, 0.021))


def test_inverse_refuses_the_axis():
    with pytest.raises(SingularPose, match="from joint 1's axis"):
        inverse([0.0, 0.0, 0.025])
    with pytest.raises(SingularPose):
        inverse([0.0004, 0.0003, 0.025])  # 0.5 mm from the axis
    q = inverse([0.0004, 0.0003, 0.025], min_reach=1e-4)  # allowed when asked
    np.testing.assert_allclose(tip(q), [0.0004, 0.0003, 0.025], atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(joint_q, st.tuples(*[st.floats(-1e-3, 1e-3)] * 3))
def test_joint_rates_invert_the_jacobian(q, v):
    q = np.array(q)
    if float(distance_from_axis(q)) < kin.MIN_REACH:
        with pytest.raises(SingularPose):
            joint_rates(q, v)
        return
    dq = joint_rates(q, v)
    np.testing.assert_allclose(jacobian(q) @ dq, v, atol=1e-15)
    np.testing.assert_allclose(dq, np.linalg.solve(jacobian(q), v), rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize(
    "text, expected",
    [("0mm,21mm", (0.0, 0.021)), ("1.5mm, 30mm", (0.0015, 0.03)), ("0,0.021", (0.0, 0.021))],
)
def test_geometry_parse(text, expected):
    g = Geometry.parse(text)
    assert (g.offset, g.length) == pytest.approx(expected)


@pytest.mark.parametrize("text", ["21mm", "0mm,0mm", "0mm,-5mm", "1,2,3", "0mm,21deg", "nan,0.02", "0,2m", ""])
def test_geometry_parse_refuses(text):
    with pytest.raises(ValueError):
        Geometry.parse(text)


def test_geometry_refuses_non_numbers():
    with pytest.raises(ValueError):
        Geometry(True, 0.02)  # type: ignore[arg-type]  # a bool is not a length
    with pytest.raises(ValueError):
        Geometry(0.0, float("inf"))
