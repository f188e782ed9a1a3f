"""The benchmark's counting arithmetic (tests/support/arm_days.py; benchmarks/bench_models.py).

The coverage cells print a 95 % Wilson interval, and the "days above the paper's procedure"
print how many days the draw of the validation poses alone gives (the share of the subsets of
the day's poses on which one model's largest error is above the other's, in closed form).
Both are checked here against independent computations: scipy's Wilson interval and its
closed form at ``k = 0``, and the enumeration of every subset.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest
from arm_days import make_day, share_above, wilson_interval
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binomtest

Z = 1.959963984540054


@pytest.mark.parametrize(("k", "n"), [(137, 144), (1, 8), (144, 144), (0, 1152), (1100, 1152), (5, 9)])
def test_wilson_is_scipys(k: int, n: int) -> None:
    ci = binomtest(k, n).proportion_ci(0.95, method="wilson")
    assert wilson_interval(k, n) == pytest.approx((ci.low, ci.high), abs=1e-12)


@pytest.mark.parametrize("n", [1, 16, 144, 1152])
def test_wilson_with_nothing_inside_is_zero_to_z2_over_n_plus_z2(n: int) -> None:
    # k = 0: centre and half-width are both z^2 / 2 / (n + z^2)
    lo, hi = wilson_interval(0, n)
    assert lo == pytest.approx(0.0, abs=1e-15)
    assert hi == pytest.approx(Z * Z / (n + Z * Z), rel=1e-13)
    lo, hi = wilson_interval(n, n)  # and its mirror
    assert (lo, hi) == pytest.approx((n / (n + Z * Z), 1.0), rel=1e-13)


@pytest.mark.parametrize(("k", "n"), [(-1, 5), (6, 5), (0, 0)])
def test_wilson_refuses_what_is_not_a_proportion(k: int, n: int) -> None:
    with pytest.raises(ValueError, match="0 <= k <= n"):
        wilson_interval(k, n)


def _enumerated(a: np.ndarray, b: np.ndarray, m: int) -> float:
    sets = np.array(list(combinations(range(a.size), m)))
    return float(np.mean(a[sets].max(axis=1) > b[sets].max(axis=1)))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 11), m=st.integers(1, 11), seed=st.integers(0, 2**32 - 1))
def test_share_above_is_the_share_of_all_subsets(n: int, m: int, seed: int) -> None:
    m = min(m, n)
    rng = np.random.default_rng(seed)
    a, b = rng.exponential(size=n), rng.exponential(size=n)
    assert share_above(a, b, m) == pytest.approx(_enumerated(a, b, m), abs=1e-12)


def test_share_above_at_the_ends() -> None:
    a = np.array([0.01, 0.07, 0.03, 0.025])
    b = np.array([0.02, 0.05, 0.04, 0.01])
    assert share_above(a, b, 4) == 1.0  # all poses: the comparison itself (0.07 > 0.05)
    assert share_above(b, a, 4) == 0.0
    assert share_above(a, b, 1) == pytest.approx(0.5)  # one pose: the share of poses with a > b
    # m = 2: a is above in the 3 pairs with 0.07's pose, and in the first and last poses' pair
    # (0.025 against 0.02); b in the pairs with its 0.04 and without 0.07: 4 of 6
    assert share_above(a, b, 2) == pytest.approx(4 / 6)


def test_share_above_refuses_more_poses_than_it_has() -> None:
    with pytest.raises(ValueError, match="m = 5 poses of 4"):
        share_above(np.ones(4), np.ones(4), 5)


def test_more_validation_poses_leave_the_day_as_it_was() -> None:
    day = "2026-09-02"
    base = make_day("dahl", 7, day, np.random.default_rng(7), validation_poses=2, repeat_first=True)
    more = make_day("dahl", 7, day, np.random.default_rng(7), validation_poses=2, repeat_first=True,
                    more_validation=3)
    for name in ("paper14", "spread32", "repeat", "validation", "new4", "more_new"):
        assert getattr(more, name) == getattr(base, name), name
    assert base.more_validation == []
    assert [(t.joint, t.direction) for t in more.more_validation] == [(3, "+"), (3, "-")] * 3 + [(2, "+"), (2, "-")] * 3
    # new poses: none of them is one of the day's first validation poses
    first = {(t.q1, t.q2, t.q3, t.theta, t.psi) for t in base.validation}
    assert not first & {(t.q1, t.q2, t.q3, t.theta, t.psi) for t in more.more_validation}


def test_check_poses_leave_the_day_as_it_was() -> None:
    day = "2026-09-02"
    base = make_day("lugre", 7, day, np.random.default_rng(7), validation_poses=2, repeat_first=True)
    checked = make_day("lugre", 7, day, np.random.default_rng(7), validation_poses=2, repeat_first=True,
                       check_per_joint=2)
    for name in ("paper14", "spread32", "repeat", "validation", "new4", "more_new", "more_validation"):
        assert getattr(checked, name) == getattr(base, name), name
    assert base.check == []
    assert [(t.joint, t.direction) for t in checked.check] == [(3, "+"), (3, "-")] * 2 + [(2, "+"), (2, "-")] * 2
    calibrated = {(t.q1, t.q2, t.q3, t.theta, t.psi) for t in base.calibration + base.validation}
    assert not calibrated & {(t.q1, t.q2, t.q3, t.theta, t.psi) for t in checked.check}
