"""The image Jacobian, step sizes from it, and the joint observation (the closed loop's seam): exact identities."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip import kinematics as kin
from stickslip.vision.jacobian import (
    MIN_VISIBILITY,
    CameraCalibration,
    JacobianError,
    fit_image_jacobian,
    joint_observation,
    step_size,
    visibility,
)
from stickslip.vision.view import TOP_VIEW, View, project

OUT = kin.Pose()  # outstretched: q2 = -90 deg, level base


def test_a_straight_motion_gives_its_slope_exactly():
    n = [0, 20, 40, 60, 80]
    J = np.array([1.25, -0.5])
    pts = [(100 + J[0] * k, 50 + J[1] * k) for k in n]
    fit = fit_image_jacobian(3, "+", n, pts, 0.1)
    np.testing.assert_allclose(fit.jacobian, J, rtol=1e-12)
    assert np.max(fit.residuals) < 1e-9 and fit.travel_px == pytest.approx(80 * math.hypot(*J))


def test_a_motion_that_stops_is_not_linear_in_the_steps():
    n = [0, 25, 50, 75, 100, 125]
    x = [0, 25, 50, 60, 60, 60]  # an end stop after 60 px
    with pytest.raises(JacobianError, match="not linear in the steps.*end stop"):
        fit_image_jacobian(3, "+", n, [(v, 0.0) for v in x], 0.2)


@pytest.mark.parametrize(
    "n, pts, words",
    [([0, 10], [(0, 0), (1, 0)], "at least 3"), ([0, 10, 10], [(0, 0)] * 3, "must increase"),
     ([0, 10, 20], [(0, 0), (0.1, 0), (0.2, 0)], "within the tracking noise")],
)
def test_too_little_to_fit_is_refused(n, pts, words):
    with pytest.raises(JacobianError, match=words):
        fit_image_jacobian(1, "-", n, pts, 0.3)


def test_step_size_from_the_top_is_pixel_size_times_pixels_per_step():
    """Joint 3 at the outstretched pose moves the tip along x, in the image plane: gamma = s |J| / 1."""
    fit = fit_image_jacobian(3, "+", [0, 50, 100], [(0, 0), (97.2, 0), (194.4, 0)], 0.1)
    s = step_size(fit, OUT, 0.5e-6, TOP_VIEW)
    assert s.gamma == pytest.approx(0.5e-6 * 1.944, rel=1e-12) and s.visibility == pytest.approx(1.0)
    # joint 1 turns the tip about z at radius length: gamma = s |J| / length
    fit1 = fit_image_jacobian(1, "+", [0, 50, 100], [(0, 0), (0, -105), (0, -210)], 0.1)
    assert step_size(fit1, OUT, 0.5e-6, TOP_VIEW).gamma == pytest.approx(0.5e-6 * 2.1 / kin.DEFAULT_GEOMETRY.length)


def test_a_joint_along_the_optical_axis_is_refused_and_a_tilted_view_shortens_by_cos():
    assert visibility(2, OUT, TOP_VIEW) == pytest.approx(0.0, abs=1e-12)  # joint 2 moves the tip up
    fit = fit_image_jacobian(2, "+", [0, 10, 20], [(0, 0), (10, 0), (20, 0)], 0.1)
    with pytest.raises(JacobianError, match="along the camera's optical axis"):
        step_size(fit, OUT, 1e-6, TOP_VIEW)
    tilt = math.radians(30)
    view = View(tilt=tilt)  # the optical axis leans towards +x: joint 3 (along x) is seen shortened by cos 30
    assert visibility(3, OUT, view) == pytest.approx(math.cos(tilt), rel=1e-12)
    assert visibility(2, OUT, view) == pytest.approx(math.sin(tilt), rel=1e-12)
    fit3 = fit_image_jacobian(3, "+", [0, 10, 20], [(0, 0), (17.32, 0), (34.64, 0)], 0.1)
    assert step_size(fit3, OUT, 1e-6, view).gamma == pytest.approx(1.732e-6 / math.cos(tilt), rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    tilt=st.floats(0.0, 1.2), azimuth=st.floats(-3.0, 3.0), roll=st.floats(-3.0, 3.0),
    q1=st.floats(-0.5, 0.5), q2=st.floats(-2.5, -0.6), q3=st.floats(0.0, 0.01), joint=st.sampled_from([1, 2, 3]),
)
def test_step_size_inverts_the_projection_of_a_true_step(tilt, azimuth, roll, q1, q2, q3, joint):
    """Project n true steps through the camera (view.project), fit, recover gamma: the identity of design.md §10."""
    view, pose, s = View(tilt, azimuth, roll), kin.Pose(q1, q2, q3), 0.4e-6
    m = visibility(joint, pose, view)
    if m < MIN_VISIBILITY:
        return
    gamma = 1e-6 if joint == 3 else 50e-6
    q = np.array([q1, q2, q3])
    n = [0, 10, 20, 30]
    pts = []
    for k in n:
        qq = q.copy()
        qq[joint - 1] += gamma * k
        u, _ = project(kin.tip(qq), view, s, kin.tip(q), (0.0, 0.0))
        pts.append((float(u[0]), float(u[1])))
    fit = fit_image_jacobian(joint, "+", n, pts, 1e-3)
    got = step_size(fit, pose._replace(**{f"q{joint}": float(q[joint - 1] + gamma * 15)}), s, view)
    assert got.gamma == pytest.approx(gamma, rel=2e-4)  # the tip's path bends a little over 30 steps


def test_joint_observation_round_trip_and_refusals():
    """A fix on joint 3's line gives q3 back with sigma_px / |g|; off the line or far beyond the range, refused."""
    fit_p = fit_image_jacobian(3, "+", [0, 50, 100], [(300, 256), (400, 256), (500, 256)], 0.1)
    fit_m = fit_image_jacobian(3, "-", [0, 50, 100], [(500, 256), (405, 256), (310, 256)], 0.1)
    cal = CameraCalibration.from_fits([fit_p, fit_m], OUT, (300.0, 256.0), 0.5e-6, TOP_VIEW)
    assert cal.px_per_unit[3] == pytest.approx((2e6, 0.0))  # 1 / (0.5 µm per px) along x
    obs = joint_observation(cal, 3, 340.0, 256.2, 0.3)
    assert obs.q == pytest.approx(20e-6) and obs.sigma == pytest.approx(0.15e-6)
    assert obs.off_line_px == pytest.approx(0.2)
    with pytest.raises(JacobianError, match="off joint 3's line"):
        joint_observation(cal, 3, 340.0, 270.0, 0.3)
    with pytest.raises(JacobianError, match="beyond twice its range"):
        joint_observation(cal, 3, 300.0 + 2.1 * cal.range_px, 256.0, 0.3)
    with pytest.raises(JacobianError, match="joint 1 was not calibrated"):
        joint_observation(cal, 1, 340.0, 256.0, 0.3)
