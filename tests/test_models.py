"""Models: Eqs. 2, 3, 8 and the exact traverse integral, cross-checked three ways."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from synth import PAPER_PRISMATIC, PAPER_ROTARY

from stickslip import models as m
from stickslip.kinematics import JOINTS


def test_eq3_at_the_calibration_poses():
    # Section 3.3: gamma(-pi/2,0,0) = a; gamma(0,-pi/2,0) = a(1-b); gamma(0,0,0) = (1-b)(a-c)
    for p in PAPER_PRISMATIC.values():
        assert math.isclose(float(m.gamma_prismatic(-math.pi / 2, 0, 0, p.a, p.b, p.c)), p.a, rel_tol=1e-15)
        assert math.isclose(float(m.gamma_prismatic(0, -math.pi / 2, 0, p.a, p.b, p.c)), p.a * (1 - p.b), rel_tol=1e-15)
        assert math.isclose(float(m.gamma_prismatic(0, 0, 0, p.a, p.b, p.c)), (1 - p.b) * (p.a - p.c), rel_tol=1e-15)


def test_eta_eq2():
    np.testing.assert_allclose(m.eta([-math.pi / 2, 0, -math.pi, math.pi / 6], 0.27),
                               [1, 0.73, 0.73, 1 - 0.27 * math.cos(math.pi / 6)], atol=1e-15)


def test_downward_steps_bigger_than_upward():
    # Section 3.4: with the paper's signs, gravity helps '-' where sin(zeta) > 0 (arm outstretched)
    g_minus = m.JointModel(2, "-", PAPER_ROTARY["-"]).gamma(0, -math.pi / 2, 0.012, 0, 0)
    g_plus = m.JointModel(2, "+", PAPER_ROTARY["+"]).gamma(0, -math.pi / 2, 0.012, 0, 0)
    assert g_minus > PAPER_ROTARY["-"].gamma0[1] and g_plus < PAPER_ROTARY["+"].gamma0[1]


coef = st.tuples(st.floats(0.2, 3.0), st.floats(0.0, 0.98), st.floats(-10, 10))


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(c=coef, a=st.floats(-8, 8), span=st.floats(-7, 7))
def test_closed_form_equals_quadrature(c, a, span):
    A, frac, phase = c
    B = frac * A
    al, be = B * math.sin(phase), B * math.cos(phase)
    assume(abs(span) > 1e-6)
    exact = float(m.steps_between(a, a + span, A, al, be))
    quad = m.steps_between_quad(a, a + span, A, al, be)
    assert exact == pytest.approx(quad, rel=1e-11)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(A=st.floats(0.3, 2.0), ratio=st.floats(1.05, 4.0), phase=st.floats(-4, 4), a=st.floats(-6, 6),
       span=st.floats(0.01, 5))
def test_log_form_where_step_positive_only_along_the_way(A, ratio, phase, a, span):
    B = ratio * A
    al, be = B * math.sin(phase), B * math.cos(phase)
    lo, hi = a, a + span
    assume(A + float(m.sinusoid_range(lo, hi, al, be)[0]) > 0.05 * A)
    exact = float(m.steps_between(lo, hi, A, al, be))
    assert exact == pytest.approx(m.steps_between_quad(lo, hi, A, al, be), rel=1e-10)


def test_stall_is_refused():
    with pytest.raises(m.NonPhysicalError):
        m.steps_between(-3.0, 0.0, 1.0, 0.0, 2.0)  # 1 + 2 sin q <= 0 for q in [-5pi/6, -pi/6]


def test_discrete_simulation_agrees_with_integral():
    # the paper's step-by-step simulation (Fig. 8) vs the exact integral over joint 2's range
    for d_sign in ("+", "-"):
        model = m.JointModel(2, d_sign, PAPER_ROTARY[d_sign])
        A, al, be = (float(x) for x in model.rotary_coefficients(0, 0, 0.012, 0, 0))
        lo, hi = JOINTS[2].lower, JOINTS[2].upper
        start, end = (lo, hi) if d_sign == "+" else (hi, lo)
        exact = float(m.steps_between(start, end, A, al, be))
        n = m.simulate_traverse_steps(start, end, lambda q, A=A, al=al, be=be: A + al * math.cos(q) + be * math.sin(q))
        # Euler stepping overshoots the end by < 1 step; the discretisation error is O(d gamma/dq) ~ 1 step
        assert abs(n - exact) < 2.0, (n, exact)


@settings(max_examples=100, deadline=None)
@given(A=st.floats(20e-6, 100e-6), frac=st.floats(0, 0.9), phase=st.floats(-3, 3), start=st.floats(-3.6, 0.5),
       n=st.integers(1, 50_000), sign=st.sampled_from([1, -1]))
def test_dead_reckoning_inverts_the_integral(A, frac, phase, start, n, sign):
    B = frac * A
    al, be = B * math.sin(phase), B * math.cos(phase)
    q = m.position_after_steps(start, n, sign, A, al, be)
    assert (q - start) * sign > 0
    assert float(m.steps_between(start, q, A, al, be)) == pytest.approx(n, rel=1e-10, abs=1e-8)


def test_average_gamma_of_unloaded_rotary_is_gamma0():
    model = m.JointModel(2, "+", PAPER_ROTARY["+"])
    g = float(model.average_gamma(JOINTS[2].lower, JOINTS[2].upper, 0, 0, 0.006, -math.pi / 2, 0))
    assert g == pytest.approx(np.mean(PAPER_ROTARY["+"].gamma0), rel=1e-14)


def test_nonphysical_parameters():
    with pytest.raises(m.NonPhysicalError, match="outside"):
        m.PrismaticParams(900e-9, 1.0, 0).check_physical()
    with pytest.raises(m.NonPhysicalError, match="<= 0"):
        m.PrismaticParams(300e-9, 0.2, -400e-9).check_physical()
    with pytest.raises(m.NonPhysicalError, match="q3 = 12 mm"):
        m.RotaryParams((40e-6, 20e-6), (5e-6, 25e-6)).check_physical()
    m.PrismaticParams(972e-9, 0.27, 372e-9).check_physical()


def test_a_step_zero_to_rounding_is_a_stall_not_a_step():
    """audit38 item 5: gamma0 - |d| = 1e-20 rad passed a strict > 0 (counts of 1e15 followed): a relative margin."""
    g0 = 1e-5
    for d in (g0 - 1e-20, g0 * (1 - 1e-9), g0 * (1 - 0.9e-6)):  # smallest step 1e-15 .. 4.5e-7 of the largest
        with pytest.raises(m.NonPhysicalError, match="stall"):
            m.RotaryParams((g0, g0), (d, -d)).check_physical()
    m.RotaryParams((g0, g0), (g0 * (1 - 1e-5), g0 * (1 - 1e-5))).check_physical()  # 5e-6 of the largest: a step
    with pytest.raises(m.NonPhysicalError, match="stall"):
        m.PrismaticParams(972e-9, 0.27, 972e-9 * (1 - 1e-9)).check_physical()
    m.PrismaticParams(972e-9, 0.27, 972e-9 * (1 - 1e-5)).check_physical()


@settings(max_examples=200, deadline=None)
@given(al=st.floats(-2, 2), be=st.floats(-2, 2), lo=st.floats(-8, 8), span=st.floats(0, 8))
def test_sinusoid_range_equals_dense_sampling(al, be, lo, span):
    q = np.linspace(lo, lo + span, 20001)
    f = al * np.cos(q) + be * np.sin(q)
    mn, mx = m.sinusoid_range(lo, lo + span, al, be)
    # the sampled extremes bracket the exact ones from inside, to the grid's resolution
    assert f.min() >= mn - 1e-12 and f.max() <= mx + 1e-12
    assert f.min() - mn < 1e-6 * (abs(al) + abs(be) + 1) and mx - f.max() < 1e-6 * (abs(al) + abs(be) + 1)
