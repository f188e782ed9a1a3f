"""The vectorised exact inversion for d agrees with the scalar one, row by row, and refuses alike."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.calibration import calibrate_paper
from stickslip.calibration.inversion import invert_d_exact, invert_d_exact_many
from stickslip.calibration.result import CalibrationError
from stickslip.kinematics import JOINTS

LO, HI = JOINTS[2].lower, JOINTS[2].upper


@settings(max_examples=40, deadline=None)
@given(
    g0=st.floats(20e-6, 100e-6),
    deltas=st.lists(st.floats(-9e-6, 9e-6), min_size=1, max_size=12),
    beta=st.sampled_from([-1.0, -0.7, 0.5]),
    alpha=st.sampled_from([0.0, 0.3]),
    down=st.booleans(),
)
def test_many_equals_one_at_a_time(g0, deltas, beta, alpha, down):
    start, end = (HI, LO) if down else (LO, HI)
    gam = g0 + np.array(deltas)
    want = []
    for g in gam:
        try:
            want.append(invert_d_exact(float(g), g0, start, end, alpha, beta))
        except CalibrationError:
            want.append(None)
    if any(w is None for w in want):
        first = next(i for i, w in enumerate(want) if w is None)
        with pytest.raises(CalibrationError) as e:
            invert_d_exact_many(gam, g0, start, end, alpha, beta)
        with pytest.raises(CalibrationError) as e1:
            invert_d_exact(float(gam[first]), g0, start, end, alpha, beta)
        assert str(e.value) == str(e1.value)
        return
    got = invert_d_exact_many(gam, g0, start, end, alpha, beta)
    # both solve to ~1e-17 rad; d near 0 (no load effect) differs only at that level
    np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-15)


def test_a_long_log_calibrates_like_its_distinct_rows():
    """Repeating every traverse 500 times changes nothing but the cost (rows of one pose are solved together)."""
    from synth import paper_table

    rng = np.random.default_rng(5)
    base = paper_table(rng=rng, noise=0.01)
    once = calibrate_paper(base)
    many = calibrate_paper(base * 500)
    for key, m in once.models.items():
        np.testing.assert_allclose(many.models[key].params.as_vector(), m.params.as_vector(), rtol=1e-11)
    assert math.isfinite(many.models[(2, "+")].params.d[0])
