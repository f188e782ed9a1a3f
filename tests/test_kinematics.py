"""Kinematics: the general gravity projection reproduces the paper's load terms (docs/design.md §2)."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from stickslip import kinematics as kin

angle = st.floats(-math.pi, math.pi, allow_nan=False)
q2s = st.floats(kin.JOINTS[2].lower, kin.JOINTS[2].upper)


def test_gravity_base_is_rotated_world_gravity():
    rng = np.random.default_rng(0)
    for theta, psi in rng.uniform(-math.pi, math.pi, (50, 2)):
        R = kin.rotation_base(theta, psi)
        np.testing.assert_allclose(kin.gravity_base(theta, psi), R.T @ np.array([0.0, 0.0, -1.0]), atol=1e-15)


@given(q2=q2s, theta=angle, psi=angle)
def test_prismatic_load_is_seed_term_at_q1_zero(q2, theta, psi):
    # Eq. (3): load along the arm = cos(zeta) cos(theta), zeta = psi - q2
    g = kin.gravity_base(theta, psi)
    z2 = kin.arm_axis(0.0, q2)
    explicit = -g @ z2
    seed = math.cos(psi - q2) * math.cos(theta)
    assert abs(float(kin.prismatic_load(0.0, q2, theta, psi)) - seed) < 1e-14
    assert abs(explicit - seed) < 1e-14


@given(q2=q2s, theta=angle, psi=angle)
def test_joint2_load_is_seed_term_at_q1_zero(q2, theta, psi):
    # Eq. (8): minus the gravity torque about z1 = sin(zeta) cos(theta)
    g = kin.gravity_base(theta, psi)
    torque = np.cross(kin.arm_axis(0.0, q2), g) @ kin.joint2_axis(0.0)
    seed = math.sin(psi - q2) * math.cos(theta)
    assert abs(-torque - seed) < 1e-14
    assert abs(float(kin.joint2_load(0.0, q2, theta, psi)) - seed) < 1e-14


@given(q1=angle, q2=q2s, theta=angle, psi=angle)
def test_general_projection_matches_vectors_for_any_q1(q1, q2, theta, psi):
    g = kin.gravity_base(theta, psi)
    z2 = kin.arm_axis(q1, q2)
    assert abs(float(kin.prismatic_load(q1, q2, theta, psi)) - (-g @ z2)) < 1e-14
    torque2 = np.cross(z2, g) @ kin.joint2_axis(q1)
    assert abs(float(kin.joint2_load(q1, q2, theta, psi)) + torque2) < 1e-14
    torque1 = np.cross(z2, g) @ np.array([0.0, 0.0, 1.0])  # mass on the arm, unit length
    assert abs(float(kin.joint1_load(q1, q2, theta, psi)) + torque1) < 1e-14


@given(q1=angle, q2=q2s, theta=angle, psi=angle)
def test_joint1_term_is_design_formula(q1, q2, theta, psi):
    # docs/design.md: torque about z0 ∝ -r (sin θ cos q1 + cos θ sin ψ sin q1), r = horizontal reach = -sin q2
    r = -math.sin(q2)
    expected = r * (math.sin(theta) * math.cos(q1) + math.cos(theta) * math.sin(psi) * math.sin(q1))
    assert abs(float(kin.joint1_load(q1, q2, theta, psi)) - expected) < 1e-14


def test_joint1_no_load_upright_and_largest_on_its_side():
    q1 = np.linspace(-2, 2, 9)
    np.testing.assert_allclose(kin.joint1_load(q1, -math.pi / 2, 0.0, 0.0), 0.0, atol=1e-15)
    np.testing.assert_allclose(kin.joint1_load(0.0, -math.pi / 2, -math.pi / 2, 0.0), -1.0, atol=1e-15)


@given(q1=angle, q2=q2s, q3=st.floats(0, 0.012), theta=angle, psi=angle)
def test_rotary_coefficients_reconstruct_load(q1, q2, q3, theta, psi):
    for joint, q in ((1, q1), (2, q2)):
        al, be = kin.rotary_load_coefficients(joint, q1, q2, q3, theta, psi)
        assert abs(al * math.cos(q) + be * math.sin(q) - float(kin.load_term(joint, q1, q2, q3, theta, psi))) < 1e-14


def test_ranges_from_the_paper():
    assert math.isclose(kin.JOINTS[2].span, 4 * math.pi / 3)
    assert math.isclose(kin.JOINTS[1].span, 4 * math.pi / 3)
    assert kin.JOINTS[2].lower == -7 * math.pi / 6 and kin.JOINTS[2].upper == math.pi / 6
    assert kin.JOINTS[3].span == 0.012
    assert math.isclose(float(kin.zeta(-math.pi / 2, 0.0)), math.pi / 2)


@pytest.mark.parametrize("joint", [True, False, 2.5, 3.7, float("nan"), float("inf"), None, "x", 4, 0])
def test_joint_spec_refuses_what_is_not_a_joint_number(joint):
    """True was joint 1 and 2.5 joint 2 (int() of them): StickSlipAxis(url, True, cal) moved joint 1."""
    with pytest.raises(ValueError, match="unknown joint"):
        kin.joint_spec(joint)


def test_joint_spec_takes_a_whole_number_however_written():
    assert [kin.joint_spec(j).number for j in (1, 2.0, "3", np.int64(3))] == [1, 2, 3, 3]
