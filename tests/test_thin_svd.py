"""The identifiability check with a thin SVD gives the same verdicts and messages as with the full one."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.calibration import lsq
from stickslip.calibration.result import CalibrationError
from stickslip.models import PrismaticParams, RotaryParams


def _full_svd_verdict(j, d, names, jac):
    """The check as it was: ``full_matrices=True`` (an n x n U)."""
    original = np.linalg.svd

    def full(a, full_matrices=True, **kw):
        return original(a, full_matrices=True, **kw)

    np.linalg.svd = full
    try:
        return _verdict(j, d, names, jac)
    finally:
        np.linalg.svd = original


def _verdict(j, d, names, jac):
    try:
        lsq._identifiability(j, d, names, jac)
    except CalibrationError as e:
        return str(e)
    return None


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(1, 40),
    rotary=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
    defect=st.sampled_from(["none", "zero column", "equal columns", "scaled column", "low rank"]),
)
def test_thin_svd_gives_the_same_verdicts(n, rotary, seed, defect):
    rng = np.random.default_rng(seed)
    names = RotaryParams((0, 0), (0, 0)).names() if rotary else PrismaticParams(0, 0, 0).names()
    p = len(names)
    jac = rng.standard_normal((n, p))
    if defect == "zero column":
        jac[:, rng.integers(p)] = 0.0
    elif defect == "equal columns":
        jac[:, 1] = jac[:, 0]
    elif defect == "scaled column":
        jac[:, 2] = -3.5 * jac[:, 0]
    elif defect == "low rank":
        jac = rng.standard_normal((n, 1)) @ rng.standard_normal((1, p))
    j, d = (2, "+") if rotary else (3, "-")
    assert _verdict(j, d, names, jac) == _full_svd_verdict(j, d, names, jac)


def test_a_tall_rank_deficient_jacobian_is_refused_without_an_n_by_n_matrix():
    """100 000 rows: the full U would be 80 GB; the thin check answers and names the free parameter."""
    rng = np.random.default_rng(0)
    jac = rng.standard_normal((100_000, 3))
    jac[:, 1] = 0.0
    with pytest.raises(CalibrationError, match=r"cannot determine b-"):
        lsq._identifiability(3, "-", PrismaticParams(0, 0, 0).names(), jac)
