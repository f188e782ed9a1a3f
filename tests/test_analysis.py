"""ANOVA of step sizes (the paper's Section 3.1) and fit residuals.

Reference values: a one-way ANOVA worked by hand; for the two-way table, type-II sums
of squares computed independently from nested least-squares fits (numpy.linalg.lstsq);
p-values from the F distribution's survival function.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from analysis_tables import TRUE_PRISMATIC, TRUE_ROTARY, simulated_table  # tests/support
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import stats
from typer.testing import CliRunner

from stickslip.analysis import anova, group_poses, one_way, residual_summary
from stickslip.calibration import Calibration, calibrate
from stickslip.cli import app
from stickslip.measurements import Traverse, measurements_to_csv, write_measurements
from stickslip.storage import Store

runner = CliRunner()

L3 = 0.012  # prismatic stroke, m


def _row(day, direction, steps, q2=-math.pi / 2, theta=0.0, psi=0.0, joint=3, q1=0.0, q3=0.0):
    if joint == 3:
        lo, hi = 0.0, L3
    else:
        lo, hi = -7 * math.pi / 6, math.pi / 6
    start, end = (lo, hi) if direction == "+" else (hi, lo)
    return Traverse(day, joint, direction, q1, q2, q3, theta, psi, start, end, int(steps))


def test_one_way_matches_a_hand_computation():
    # groups (1,2,3), (2,3,4), (6,7,8): means 2, 3, 7, grand mean 4;
    # SSB = 3 (4 + 1 + 9) = 42 on 2 df, SSW = 3 * 2 = 6 on 6 df -> F = 21 / 1 = 21.
    # For F(2, d2) the survival function is (1 + 2F/d2)^(-d2/2) = 8^-3 = 1/512.
    F, p, dfb, dfw = one_way([[1, 2, 3], [2, 3, 4], [6, 7, 8]])
    assert (dfb, dfw) == (2, 6)
    assert F == pytest.approx(21.0, rel=1e-12)
    assert p == pytest.approx(1 / 512, rel=1e-9)


def test_one_way_degenerate_cases():
    assert one_way([[1, 1], [2, 2]])[:2] == (math.inf, 0.0)
    F, p, *_ = one_way([[1, 1], [1, 1]])
    assert math.isnan(F) and math.isnan(p)
    with pytest.raises(ValueError, match="n > groups"):
        one_way([[1], [2]])


def _table(seed=0, days=("d1", "d2", "d3"), reps=3, drift=0.02, noise=0.01):
    """Two poses of joint 3, both directions, three days; day effect ``drift`` (relative)."""
    rng = np.random.default_rng(seed)
    rows = []
    for di, day in enumerate(days):
        f = 1 + drift * di
        for q2 in (-math.pi / 2, 0.0):
            for d, g in (("+", 972e-9), ("-", 899e-9)):
                for _ in range(reps):
                    gamma = g * f * (1 + noise * rng.standard_normal())
                    rows.append(_row(day, d, round(L3 / gamma), q2=q2))
    return rows


def test_day_and_direction_tests_equal_scipy_on_hand_filtered_groups():
    rows = _table(seed=1)
    res = anova(rows, two_way=False)
    day = [t for t in res.tests if t.test == "day"]
    dirs = [t for t in res.tests if t.test == "direction"]
    assert len(day) == 2 * 2  # 2 poses x 2 directions
    assert len(dirs) == 2 * 3  # 2 poses x 3 days
    for t in day:
        ts = [r for r in rows if r.direction == t.direction and abs(r.q2 - t.pose["q2"]) < 1e-12]
        ref = stats.f_oneway(*[[r.gamma for r in ts if r.day == d] for d in ("d1", "d2", "d3")])
        assert t.F == pytest.approx(ref.statistic, rel=1e-9)
        assert abs(t.p - ref.pvalue) < 1e-12
        assert (t.df_num, t.df_den, t.n) == (2, 6, 9)
    for t in dirs:
        ts = [r for r in rows if r.day == t.day and abs(r.q2 - t.pose["q2"]) < 1e-12]
        plus = [r.gamma for r in ts if r.direction == "+"]
        minus = [r.gamma for r in ts if r.direction == "-"]
        tt = stats.ttest_ind(plus, minus)  # pooled t test: F = t^2, same p
        assert t.F == pytest.approx(tt.statistic**2, rel=1e-9)
        assert abs(t.p - tt.pvalue) < 1e-12


def _rss(X, y):
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    return float(r @ r)


def test_two_way_equals_type2_sums_of_squares_from_nested_fits():
    rows = [r for r in _table(seed=2, drift=0.01, noise=0.02) if r.q2 == 0.0]
    rows = rows[:-1]  # unbalanced on purpose: type II differs from type I here
    res = anova(rows)
    tw = {t.term: t for t in res.tests if t.test == "two-way"}
    assert set(tw) == {"day", "direction", "day:direction"}
    y = np.array([r.gamma for r in rows]) * 1e9
    days = sorted({r.day for r in rows})
    one = np.ones_like(y)
    D = np.column_stack([[r.day == d for r in rows] for d in days[1:]]).astype(float)
    P = np.array([[r.direction == "+"] for r in rows], dtype=float)
    DP = D * P
    rss_full = _rss(np.column_stack([one, D, P, DP]), y)
    rss_add = _rss(np.column_stack([one, D, P]), y)
    rss_d = _rss(np.column_stack([one, D]), y)
    rss_p = _rss(np.column_stack([one, P]), y)
    df_res = len(y) - (1 + D.shape[1] + 1 + DP.shape[1])
    mse = rss_full / df_res
    ref = {
        "day": ((rss_p - rss_add) / D.shape[1] / mse, D.shape[1]),
        "direction": ((rss_d - rss_add) / 1 / mse, 1),
        "day:direction": ((rss_add - rss_full) / DP.shape[1] / mse, DP.shape[1]),
    }
    for term, (F, dfn) in ref.items():
        t = tw[term]
        assert (t.df_num, t.df_den) == (dfn, df_res)
        assert t.F == pytest.approx(F, rel=1e-7)
        assert abs(t.p - stats.f.sf(F, dfn, df_res)) < 1e-9


def test_pose_grouping_tolerance_moving_column_and_reversed_interval():
    a = _row("d1", "+", 12000, q2=-math.pi / 2)
    b = _row("d1", "-", 12100, q2=-math.pi / 2 + 2e-4)  # within 1e-3 rad; start/end swapped
    c = Traverse("d1", 3, "+", 0.0, -math.pi / 2, 0.005, 0.0, 0.0, 0.0, L3, 12050)  # q3 column ignored
    d = _row("d1", "+", 12000, q2=-math.pi / 2 + 5e-3)  # a different pose
    e = Traverse("d1", 3, "+", 0.0, -math.pi / 2, 0.0, 0.0, 0.0, 0.0, 0.006, 6000)  # other interval
    groups = group_poses([a, b, c, d, e])
    assert [len(g.traverses) for g in groups] == [3, 1, 1]


def test_single_day_and_unrepeated_poses_are_skipped_with_reasons():
    rows = [_row("d1", "+", 12000), _row("d1", "+", 12010), _row("d2", "+", 12100)]
    res = anova(rows)
    assert [t.test for t in res.tests] == ["day"]
    rows = [_row("d1", "+", 12000), _row("d2", "+", 12100)]
    res = anova(rows)
    assert res.tests == [] and "one traverse per day" in res.skipped[0]
    assert "no testable groups" in res.report()


def test_strong_drift_is_significant_and_the_null_holds_its_size():
    # a 5 % day-to-day change with 1 % noise and 3 repeats: always significant
    res = anova(_table(seed=3, drift=0.05, noise=0.01), two_way=False)
    assert all(t.significant() for t in res.tests if t.test == "day")
    # no day effect: the fraction of p < 0.05 must be near 5 % (binomial, 400 tests)
    ps = [
        t.p
        for s in range(100)
        for t in anova(_table(seed=100 + s, drift=0.0, noise=0.01), two_way=False).tests
        if t.test == "day"
    ]
    assert len(ps) == 400
    rate = np.mean(np.array(ps) < 0.05)
    assert 0.02 <= rate <= 0.09, rate


def test_rows_are_json_ready_with_the_documented_keys(tmp_path):
    res = anova(_table(seed=4))
    rows = json.loads(json.dumps(res.rows()))
    kinds = {r["test"] for r in rows}
    assert kinds == {"day", "direction", "two-way"}
    for r in rows:
        assert set(r["pose"]) == {"q1", "q2", "q3", "theta", "psi"}
        assert isinstance(r["F"], float) and 0.0 <= r["p"] <= 1.0
        if r["test"] == "day":
            assert r["direction"] in "+-" and "day" not in r
        if r["test"] == "direction":
            assert r["day"] in {"d1", "d2", "d3"} and "direction" not in r
    assert measurements_to_csv(_table(seed=4)).startswith("day,joint")


# ---------------------------------------------------------------- regression fit: coverage and residuals

def _truth_vector(joint, d):
    return (TRUE_PRISMATIC[d] if joint == 3 else TRUE_ROTARY[d]).as_vector()


@pytest.mark.slow
def test_fit_recovers_known_parameters_within_their_standard_errors():
    """Coverage over 60 seeds x 14 parameters: |fit - truth| <= 2 SE in >= 90 % (expected ~94 %
    for a t distribution with n - p = 17-18 degrees of freedom), and <= 1 SE near 68 %."""
    within1 = within2 = total = 0
    rms = []
    for seed in range(60):
        rows = simulated_table(seed)
        cal = calibrate(rows, method="lsq")
        for (j, d), m in cal.models.items():
            se = cal.stderr[(j, d)]
            assert se is not None and np.all(np.isfinite(se)) and np.all(se > 0)
            z = np.abs(m.params.as_vector() - _truth_vector(j, d)) / se
            within1 += int(np.sum(z <= 1))
            within2 += int(np.sum(z <= 2))
            total += z.size
        rms += [r.rms_rel for r in residual_summary(cal, rows).rows_]
    assert total == 60 * 14
    cover1, cover2 = within1 / total, within2 / total
    print(f"coverage: |err| <= 1 SE {cover1:.1%}, <= 2 SE {cover2:.1%} of {total} parameters")
    assert cover2 >= 0.90
    assert 0.60 <= cover1 <= 0.76
    # the residuals measure the noise put in (2 %), slightly less by the fitted degrees of freedom
    assert 0.017 <= np.mean(rms) <= 0.021


def test_residual_summary_is_exact_on_noise_free_rows_and_counts_per_direction():
    rows = simulated_table(0, noise=0.0)
    truth = calibrate(simulated_table(1, noise=0.0), method="lsq")
    res = residual_summary(truth, rows)
    assert [(r.joint, r.direction, r.n) for r in res.rows_] == [(2, "+", 20), (2, "-", 20), (3, "+", 21), (3, "-", 21)]
    # only the rounding of the step count remains: |rel| <= 0.5 / steps
    for r in res.rows_:
        ts = [t for t in rows if (t.joint, t.direction) == (r.joint, r.direction)]
        assert r.max_rel <= 0.5 / min(t.steps for t in ts) * 1.01
    text = res.report()
    assert "nm" in text and "µrad" in text


# ---------------------------------------------------------------- command line


def test_cli_anova_json_equals_scipy(tmp_path):
    rows = _table(seed=5)
    p = tmp_path / "meas.csv"
    write_measurements(p, rows)
    r = runner.invoke(app, ["anova", str(p), "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    day = [o for o in out if o["test"] == "day"]
    assert len(day) == 4
    for o in day:
        ts = [t for t in rows if t.direction == o["direction"] and abs(t.q2 - o["pose"]["q2"]) < 1e-9]
        ref = stats.f_oneway(*[[t.gamma for t in ts if t.day == d] for d in sorted({t.day for t in ts})])
        assert abs(o["p"] - ref.pvalue) < 1e-6 and o["F"] == pytest.approx(ref.statistic, rel=1e-9)
    r = runner.invoke(app, ["anova", str(p)])
    assert r.exit_code == 0 and "SIGNIFICANT" in r.stdout and "F" in r.stdout


def test_cli_anova_reads_the_database_and_rejects_bad_input(tmp_path):
    db = tmp_path / "s.db"
    with Store.open(db) as st:
        st.add_traverses(_table(seed=6), device="sim://")
    r = runner.invoke(app, ["anova", "--db", str(db), "--device", "sim://", "--json"])
    assert r.exit_code == 0 and len(json.loads(r.stdout)) > 0
    r = runner.invoke(app, ["anova", "--db", str(db), "--device", "nope://"])
    assert r.exit_code == 2 and "no traverses" in r.output
    bad = tmp_path / "bad.csv"
    bad.write_text("day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\nd1,4,+,0,0,0,0,0,0,0.012,10\n")
    r = runner.invoke(app, ["anova", str(bad)])
    assert r.exit_code == 2 and "bad.csv:2: unknown joint" in r.output
    r = runner.invoke(app, ["anova", str(bad), "--alpha", "2"])
    assert r.exit_code == 2


def test_cli_fit_writes_a_calibration_with_standard_errors(tmp_path):
    p, out = tmp_path / "meas.csv", tmp_path / "cal.json"
    write_measurements(p, simulated_table(7))
    r = runner.invoke(app, ["fit", str(p), "-o", str(out), "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["calibration"]["method"] == "lsq"
    assert {(x["joint"], x["direction"]) for x in doc["residuals"]} == {(2, "+"), (2, "-"), (3, "+"), (3, "-")}
    cal = Calibration.load(out)
    a = next(x for x in cal.parameters() if x.name == "a" and x.direction == "+")
    assert a.stderr is not None and abs(a.value - 972e-9) < 3 * a.stderr
    r = runner.invoke(app, ["fit", str(p)])
    assert r.exit_code == 0 and "± " in r.stdout and "RMS" in r.stdout
    # a table that cannot determine the parameters: one pose only
    one = tmp_path / "one.csv"
    write_measurements(one, [t for t in simulated_table(7) if t.joint == 3 and t.q2 == 0.0 and t.theta == 0.0])
    r = runner.invoke(app, ["fit", str(one)])
    assert r.exit_code == 2 and "cannot determine" in r.output


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.lists(
        st.lists(st.floats(min_value=-1e3, max_value=1e3, allow_nan=False), min_size=1, max_size=6),
        min_size=2,
        max_size=5,
    ),
    st.floats(min_value=1e-9, max_value=1e6),
    st.floats(min_value=-1e3, max_value=1e3),
)
def test_one_way_equals_scipy_and_is_invariant_under_affine_changes_of_unit(groups, scale, shift):
    n = sum(len(g) for g in groups)
    assume(n > len(groups))
    flat = np.concatenate([np.asarray(g) for g in groups])
    assume(np.ptp(flat) > 1e-6 * max(1.0, np.max(np.abs(flat))))
    within = sum(float(np.sum((np.asarray(g) - np.mean(g)) ** 2)) for g in groups)
    assume(within > 1e-9 * max(1.0, float(np.sum(flat**2))))  # away from the degenerate case
    F, p, dfb, dfw = one_way(groups)
    ref = stats.f_oneway(*groups)
    assert (dfb, dfw) == (len(groups) - 1, n - len(groups))
    if np.isfinite(ref.pvalue):
        assert F == pytest.approx(ref.statistic, rel=1e-6, abs=1e-9)
        assert abs(p - ref.pvalue) < 1e-6
    else:  # equal group means: scipy returns F ~ -1e-33 and p = NaN; the answer is F = 0, p = 1
        assert abs(F) < 1e-9 and p == pytest.approx(1.0)
    # gamma in nm or in m, with an offset: the same test (where float64 keeps the spread beside the offset:
    # an offset 1e7 times the spread leaves about 9 digits of it, as the 1e-5 tolerance below needs)
    assume(scale * np.ptp(flat) > 1e-7 * max(1.0, abs(shift)))
    F2, p2, *_ = one_way([[scale * x + shift for x in g] for g in groups])
    assert F2 == pytest.approx(F, rel=1e-5, abs=1e-9)
    assert abs(p2 - p) < 1e-6
