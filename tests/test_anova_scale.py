"""The linear-time ANOVA pieces against the libraries and the plain scan they replace.

* pose grouping through the grid against the greedy scan over all groups (the rule as
  written), on poses clustered at and around the tolerances;
* the closed-form type-II two-way table against statsmodels' ``ols`` + ``anova_lm``;
* the one-way F test against :func:`scipy.stats.f_oneway`.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from stickslip.analysis import ANGLE_TOL, LENGTH_TOL, _group_poses_scan, _two_way, group_poses, one_way
from stickslip.measurements import Traverse


def _traverse(rng: np.random.Generator, centres: np.ndarray, jitter: float) -> Traverse:
    c = centres[rng.integers(len(centres))]
    joint = int(c[0])
    q1, q2, q3, th, ps = (float(v) for v in c[1:6])
    # offsets at, inside and just beyond the tolerance, so that matches hinge on it
    off = rng.choice([0.0, 0.5, 0.999, 1.0, 1.001, 1.5, 2.0], size=7) * rng.choice([-1, 1], size=7) * jitter
    lo, hi = (0.0, 0.012) if joint == 3 else (-1.0, 0.5)
    start, end = lo + off[5] * (LENGTH_TOL if joint == 3 else ANGLE_TOL), hi + off[6] * (
        LENGTH_TOL if joint == 3 else ANGLE_TOL
    )
    return Traverse(
        "d", joint, "+", q1 + off[0] * ANGLE_TOL, q2 + off[1] * ANGLE_TOL, q3 + off[2] * LENGTH_TOL,
        th + off[3] * ANGLE_TOL, ps + off[4] * ANGLE_TOL, start, end, 100,
    )


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 120), k=st.integers(1, 6), jitter=st.sampled_from([0.0, 1.0]))
def test_grid_grouping_equals_the_greedy_scan(seed, n, k, jitter):
    rng = np.random.default_rng(seed)
    centres = np.column_stack(
        [rng.integers(2, 4, k), np.zeros(k), rng.uniform(-2, 0, k).round(3), rng.uniform(0, 0.01, k).round(5),
         rng.uniform(-1, 0, k).round(3), np.zeros(k)]
    )
    ts = [_traverse(rng, centres, jitter) for _ in range(n)]
    fast = group_poses(ts)
    slow = _group_poses_scan(ts, ANGLE_TOL, LENGTH_TOL)
    assert [[id(t) for t in g.traverses] for g in fast] == [[id(t) for t in g.traverses] for g in slow]
    assert [(g.pose, g.interval) for g in fast] == [(g.pose, g.interval) for g in slow]


@pytest.mark.parametrize("tols", [(0.0, 0.0), (math.inf, math.inf), (-1.0, 1e-5)])
def test_odd_tolerances_fall_back_to_the_scan(tols):
    rng = np.random.default_rng(0)
    centres = np.array([[3, 0, -1.0, 0, 0, 0], [2, 0, 0, 0.006, -0.5, 0]])
    ts = [_traverse(rng, centres, 1.0) for _ in range(40)]
    fast = group_poses(ts, *tols)
    slow = _group_poses_scan(ts, *tols)
    assert [[id(t) for t in g.traverses] for g in fast] == [[id(t) for t in g.traverses] for g in slow]


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), days=st.integers(2, 6), extra=st.integers(1, 12))
def test_closed_form_two_way_equals_statsmodels(seed, days, extra):
    pd = pytest.importorskip("pandas")
    smf = pytest.importorskip("statsmodels.formula.api")
    from statsmodels.stats.anova import anova_lm

    rng = np.random.default_rng(seed)
    day = [f"d{i}" for i in range(days) for _ in (0, 1)]  # every cell filled once
    plus = [j == 0 for _ in range(days) for j in (0, 1)]
    for _ in range(extra):  # then unbalanced repeats
        day.append(f"d{rng.integers(days)}")
        plus.append(bool(rng.integers(2)))
    y = 900 + 20 * rng.standard_normal(len(day)) + np.array([5.0 * int(d[1:]) for d in day]) + 30 * np.array(plus)
    ours = _two_way(y, day, np.array(plus))
    df = pd.DataFrame({"gamma": y, "day": day, "direction": ["pos" if p else "neg" for p in plus]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = anova_lm(smf.ols("gamma ~ C(day) * C(direction)", data=df).fit(), typ=2)
    names = {"day": "C(day)", "direction": "C(direction)", "day:direction": "C(day):C(direction)"}
    for term, F, p, dfn, dfd in ours:
        row = table.loc[names[term]]
        assert dfn == round(row["df"]) and dfd == round(table.loc["Residual", "df"])
        assert F == pytest.approx(max(0.0, row["F"]), rel=1e-7, abs=1e-9)
        assert p == pytest.approx(min(1.0, row["PR(>F)"]), rel=1e-6, abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), sizes=st.lists(st.integers(1, 8), min_size=2, max_size=6))
def test_one_way_equals_scipy(seed, sizes):
    if sum(sizes) <= len(sizes):
        return
    rng = np.random.default_rng(seed)
    samples = [1e-6 * (40 + rng.standard_normal(k)) for k in sizes]
    F, p, dfb, dfw = one_way(samples)
    ref = stats.f_oneway(*samples)
    assert (dfb, dfw) == (len(sizes) - 1, sum(sizes) - len(sizes))
    assert F == pytest.approx(float(ref.statistic), rel=1e-9)
    assert p == pytest.approx(float(ref.pvalue), rel=1e-8, abs=1e-15)
