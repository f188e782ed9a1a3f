"""The envelope against paths that graze its surfaces, keep-outs of no thickness, and σ that is no σ.

Checked against the independent geometry of tests/support/rig_geometry (dense sampling):
an accepted path never comes within a volume's margin; a σ that is NaN, infinite,
negative or absurdly large is refused naming it (a NaN σ read as none, an infinite one
let a path through a wall: both accepted before).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import rig_geometry as geo
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.rig import Box, EnvelopeViolation, HalfSpace, Rig, check_path, safe_fraction
from stickslip.rig.envelope import SIGMA_MAX, TOLERANCE, SigmaGrowth
from test_envelope import mm3a

GRAZE = settings(max_examples=25, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])


def _lowest(arm, path, poses: int = 400, points: int = 2) -> float:
    """The lowest z any point of the arm reaches along ``path`` (dense sampling; a straight link's lowest point is an
    end), m."""
    u = np.linspace(0.0, 1.0, points)[:, None]
    low = math.inf
    for k in range(len(path) - 1):
        for t in np.linspace(0.0, 1.0, poses):
            q = path[k] + t * (path[k + 1] - path[k])
            for a, b in geo.links(arm, q):
                low = min(low, float(np.min((a + u * (b - a))[:, 2])))
    return low


@pytest.mark.slow
@GRAZE
@given(q2=st.floats(-2.5, -0.6), dq=st.floats(-0.3, 0.3), joint=st.sampled_from([1, 2, 3]),
       gap=st.sampled_from([-1e-6, -2e-7, 0.0, 2e-7, 1e-6, 1e-5]), margin=st.sampled_from([0.0, 1e-4]),
       tilt=st.sampled_from([0.0, 1e-4, 1e-2]))
def test_a_path_grazing_a_surface_is_accepted_only_if_it_keeps_the_margin(q2, dq, joint, gap, margin, tilt):
    arm = mm3a()
    start = np.array([0.0, q2, 0.004])
    end = start.copy()
    end[joint - 1] += dq if joint != 3 else dq / 50
    end[2] = min(max(end[2], 0.0), 0.012)
    path = np.array([start, end])
    floor = _lowest(arm, path) - margin - gap  # the margin's edge `gap` below the arm's lowest point
    normal = np.array([math.sin(tilt), 0.0, -math.cos(tilt)])
    rig = Rig("r", "r", (arm,), (HalfSpace("floor", (0.0, 0.0, floor), tuple(normal), margin),))
    try:
        check_path(rig, None, path)
    except EnvelopeViolation as e:
        r = e.refusal
        if r.point is not None:  # the named point is no farther than the margin (and the cut's tolerance)
            assert float(geo.point_distance(np.array([r.point]), rig.volumes[0])[0]) <= margin + TOLERANCE + 1e-9
        assert tilt > 0 or gap < TOLERANCE, (gap, r.message)  # a level floor clear by more than tol is not refused
        return
    clearance, _ = geo.dense_clearance(rig, arm, path, poses_per_segment=400, points_per_link=2)
    at_start, _ = geo.dense_clearance(rig, arm, path[:1].repeat(2, axis=0), poses_per_segment=1, points_per_link=2)
    # a path may start within the margin (never within the volume) and take the arm out: its clearance never falls
    assert clearance >= min(at_start, 0.0) - 1e-9, (clearance, at_start)


@settings(max_examples=15, deadline=None, database=None)
@given(t=st.floats(0.2, 0.8), q2=st.floats(-2.8, -0.3), q3=st.floats(0.0, 0.012))
def test_a_keep_out_of_no_thickness_across_the_path_is_refused(t, q2, q3):
    arm = mm3a()
    a, b = np.array([-1.0, q2, q3]), np.array([1.0, q2, q3])
    mid = a + t * (b - a)
    tangent = np.array([-math.sin(mid[0]), math.cos(mid[0]), 0.0])
    radial = np.array([math.cos(mid[0]), math.sin(mid[0]), 0.0])
    rot = np.column_stack((tangent, radial, np.cross(tangent, radial)))
    sheet = Box("sheet", tuple(0.9 * arm.tip(mid)), (0.0, 0.0002, 0.0002), 0.0, tuple(rot.ravel()))
    rig = Rig("r", "r", (arm,), (sheet,))
    with pytest.raises(EnvelopeViolation, match="'sheet'") as e:
        check_path(rig, None, [a, b])
    assert abs(e.value.refusal.fraction - t) < 0.05
    assert safe_fraction(rig, None, [a, b])[0] <= e.value.refusal.fraction


BAD_SIGMA = [(0.0, math.nan, 0.0), (0.0, math.inf, 0.0), (0.0, -2e-3, 0.0), (math.nan,) * 3, (0.0, 1e200, 0.0),
             (0.0, 2 * SIGMA_MAX, 0.0), (1e-3, 1e-3)]


@pytest.mark.parametrize("q_sd", BAD_SIGMA)
def test_a_sigma_that_is_no_sigma_is_refused_not_read_as_none(q_sd):
    arm = mm3a()
    q = np.array([0.0, -math.pi / 2, 0.0])
    wall = HalfSpace("wall", tuple(arm.tip(q) + [0.0, 0.0, -1e-4]), (0.0, 0.0, -1.0))  # 100 µm below the tip
    rig = Rig("r", "r", (arm,), (wall,), n_sigma=3.0)
    through = [q, q + [0.1, -0.2, 0.0]]  # the tip 4 mm down: through the wall (an infinite σ let it pass)
    for call in (check_path, safe_fraction):
        with pytest.raises(ValueError, match="position σ must be three numbers") as e:
            call(rig, None, through, q_sd=q_sd)
        assert not isinstance(e.value, EnvelopeViolation)
    with pytest.raises(EnvelopeViolation):
        check_path(rig, None, through)  # and without σ it is refused by the wall itself


@pytest.mark.parametrize("field", ["P", "step", "step_noise", "sigma_model"])
def test_a_sigma_model_with_a_nan_or_infinity_is_refused_naming_the_field(field):
    z = (0.0, 0.0, 0.0)
    values = {"P": ((z, z, z), ((math.nan, 0.0, 0.0), z, z), (z, z, z)), "step": (1e-6, math.inf, 1e-6),
              "step_noise": math.nan, "sigma_model": (0.0, math.inf, 0.0)}
    kwargs = {"P": ((z, z, z),) * 3, "step": (1e-6,) * 3, field: values[field]}
    with pytest.raises(ValueError, match=f"σ model's {field} must be finite"):
        SigmaGrowth(**kwargs)
