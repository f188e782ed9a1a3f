"""The machinery of issue 33: closed-form Jacobians, folds matched to new poses, the fallback rule,
the error model of the intervals, a calibration's cost (groups made once, one-step refits, a sample
for the choice on a long table)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.stats import wasserstein_distance
from synth import history_csv, paper_table

from stickslip import kinematics as kin
from stickslip.calibration import Calibration, calibrate
from stickslip.calibration import groups as groups_mod
from stickslip.calibration import selection as sel_mod
from stickslip.calibration.family_fit import FamilyProblem, JointFit
from stickslip.calibration.folds import cv_folds, wasserstein
from stickslip.calibration.groups import group_traverses, load_coordinates_of
from stickslip.calibration.intervals import relative_sd
from stickslip.measurements import parse_measurements
from stickslip.models import families as F
from stickslip.motion.tracking import joint_sigma_model

VALUES = {"a": 1e-6, "b": 0.2, "b2": 0.05, "c": 2e-7, "e": 5e-8, "f": 3e-8, "h": -2e-8, "k": 0.1, "m": 1e-7,
          "gamma0": 50e-6, "d": -8e-6, "t2": 1e-6}


@pytest.mark.parametrize("joint", [3, 2, 1])
def test_fit_basis_averages_and_closed_form_jacobian(joint):
    # the fit's averages equal the 48-node rule of traverse_features (rotary loads are sinusoids of the
    # joint's angle: three evaluations give them exactly), and d avg / d x equals central differences
    rng = np.random.default_rng(joint)
    n = 40
    q1, q2, q3 = rng.uniform(-0.5, 0.5, n), rng.uniform(-3.6, 0.5, n), rng.uniform(0, kin.Q3_MAX, n)
    th, ps = rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n)
    spec = kin.JOINTS[joint]
    st, en = np.full(n, spec.lower), np.full(n, spec.upper)
    st[::3] = spec.lower + 0.3 * spec.span  # partial traverses too
    basis = F.fit_basis(joint, st, en, q1, q2, q3, th, ps)
    feats = F.traverse_features(joint, st, en, q1, q2, q3, th, ps)
    for fam in F.families_for(joint):
        x = np.array([VALUES[name] for name, _ in fam.names]) * (1 + 0.1 * rng.standard_normal(fam.n_params))
        avg, jac = F.average_and_jacobian(fam, x, basis)
        np.testing.assert_allclose(avg, F.average_from_features(fam, x, feats), rtol=1e-13)
        for i in range(fam.n_params):
            h = 1e-5 * abs(x[i])
            e = np.zeros_like(x)
            e[i] = h
            fd = (F.average_and_jacobian(fam, x + e, basis)[0] - F.average_and_jacobian(fam, x - e, basis)[0]) / (2 * h)
            np.testing.assert_allclose(jac[:, i], fd, rtol=2e-4, atol=1e-9 * np.max(np.abs(fd)), err_msg=fam.name)


def test_wasserstein_is_the_area_between_the_distribution_functions():
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = rng.normal(size=int(rng.integers(2, 40)))
        b = rng.normal(1.0, 2.0, size=int(rng.integers(2, 60)))
        assert wasserstein(a, b) == pytest.approx(wasserstein_distance(a, b), rel=1e-12)


def test_folds_leave_one_out_where_poses_are_spread_and_regions_where_they_bunch():
    rng = np.random.default_rng(1)
    workspace = rng.uniform(-1, 1, (1000, 2))
    grid = np.array([[x, y] for x in np.linspace(-0.9, 0.9, 4) for y in np.linspace(-0.9, 0.9, 4)])
    spread = cv_folds(grid, workspace)
    assert spread.clusters == len(grid) and spread.n_folds == len(grid)  # new poses are as far as neighbours
    bunched = np.concatenate([rng.normal([-0.8, -0.8], 0.02, (8, 2)), rng.normal([0.8, 0.8], 0.02, (8, 2))])
    regions = cv_folds(bunched, workspace)
    # a new pose is a region away from these poses: most are held out with their bunch, not alone
    assert regions.n_folds <= 4
    dist = np.linalg.norm(bunched[:, None] - bunched[None], axis=-1)
    np.fill_diagonal(dist, np.inf)
    to_new = np.min(np.linalg.norm(workspace[:, None] - bunched[None], axis=-1), axis=1)
    assert regions.mismatch < wasserstein(dist.min(axis=1), to_new)  # closer to new poses than leaving one out


def _table(n: int, seed: int = 0):
    return parse_measurements(history_csv(n, seed), "history.csv")


def test_groups_are_made_once_per_calibration(monkeypatch):
    made = {"groups": 0, "joints": 0}
    init, joint_data = groups_mod.TraverseGroups.__init__, groups_mod._joint_data

    def counted_init(self, ts):
        made["groups"] += 1
        init(self, ts)

    def counted_joint(joint, by_dir):
        made["joints"] += 1
        return joint_data(joint, by_dir)

    monkeypatch.setattr(groups_mod.TraverseGroups, "__init__", counted_init)
    monkeypatch.setattr(groups_mod, "_joint_data", counted_joint)
    ts = _table(300)
    calibrate(ts, model="auto")
    # the paper's procedure gets the paper poses' groups (one more grouping of those), the families the rest
    assert made["joints"] == 2
    assert made["groups"] <= 2


def test_one_step_refit_lands_near_the_refit():
    # above EXACT_REFIT_ROWS a fold's refit is one Gauss-Newton step from the fit on all traverses
    data = group_traverses(_table(1200)).joint_data(3)
    spec = F.family_spec(3, "load2-normal")
    prob = FamilyProblem(spec, data)
    fit = prob.fit()
    rows = np.concatenate([data.pose[d] % 7 == 0 for d in data.dirs])  # a seventh of the poses held out
    x1, ok = prob.one_step(fit, rows)
    train = {d: data.pose[d] % 7 != 0 for d in data.dirs}
    x2 = prob.solve(fit.x, train, 50)[0]
    assert ok
    for d in data.dirs:
        test = ~train[d]
        a, b = prob.average(x1, d, test), prob.average(x2, d, test)
        np.testing.assert_allclose(a, b, rtol=2e-4)


@pytest.mark.slow
def test_a_long_table_is_chosen_on_a_sample_and_fitted_to_all(monkeypatch):
    ts = _table(3400)
    sampled = calibrate(ts, model="auto")
    sel = sampled.selection[(3, "+")]
    assert "refitted to all" in str(sel["reason"])
    monkeypatch.setattr(sel_mod, "SELECTION_ROWS", 10**9)
    whole = calibrate(ts, model="auto")
    val = _table(200, seed=9)
    a, b = sampled.predict_many(val), whole.predict_many(val)
    assert np.max(np.abs(a / b - 1)) < 0.005  # the same model within a fraction of the 3 % day-to-day scatter


def test_error_model_floor_and_slope():
    from scipy.stats import t as student

    r = np.array([0.01, -0.02, 0.015, -0.005])
    e = np.array([0.03, -0.04, 0.05, 0.02, -0.03])
    d = np.array([1.0, 0.8, 1.2, 0.9, 1.1])
    floor, slope = sel_mod.error_model(e, d, r)
    t = student.ppf(0.975, len(e) - 1) / 1.959963984540054
    assert floor == pytest.approx(t * math.sqrt(np.mean(r**2)), rel=1e-12)
    # the error between poses grows with the square of the distance (an interpolation error)
    assert slope == pytest.approx(t * math.sqrt((np.mean(e**2) - np.mean(r**2)) / np.mean(d**4)), rel=1e-12)
    assert sel_mod.error_model(0.001 * e, d, r)[1] == 0.0  # held-out errors below the residuals: no growth


def _fake_fit(label: str, n: int = 6, residual: float = 0.01) -> JointFit:
    spec = F.family_spec(3, label.partition("+")[0])
    z = np.zeros(spec.n_params)
    return JointFit(spec, 3, (), {"+": z}, {"+": None}, {"+": np.full(n, residual)}, True, z, 1e-4)


def _evidence(cv_errors, residuals=(0.01, 0.01)):
    from types import SimpleNamespace

    ev = sel_mod._Evidence.__new__(sel_mod._Evidence)
    ev.data = SimpleNamespace(joint=3, n_poses=6, dirs=("+",), n_rows=lambda: 6, coords=np.eye(6, 4))
    ev.n_folds, ev.ids, ev.row_dist, ev._ws_d4 = 6, np.arange(6), np.ones(6), None
    ev.fits = {"paper": _fake_fit("paper", residual=residuals[0]), "load2": _fake_fit("load2", residual=residuals[1])}
    ev.scores = [sel_mod.CVScore(lab, 3, "ok", 0.0, 0.0, 0.0) for lab in ev.fits]
    ev.cv_errors = cv_errors
    return ev


def test_the_average_falls_back_to_the_papers_form_when_it_is_expected_to_err_more():
    paper = np.array([0.02, -0.01, 0.015, -0.02, 0.01, 0.012])
    good_in_most = np.array([0.001, -0.001, 0.002, -0.001, 0.001, 0.09])  # one fold badly wrong
    out = sel_mod._decide(_evidence({"paper": paper, "load2": good_in_most}), True)
    assert out.fallback and out.fit.spec.name == "paper" and "paper's form" in out.reason
    # the same families where the other is better everywhere: no fallback
    out = sel_mod._decide(_evidence({"paper": paper, "load2": 0.3 * paper}), True)
    assert not out.fallback and out.fit.spec.name == "load2"


def test_the_fallback_compares_the_errors_expected_at_new_poses():
    from scipy.stats import t as student

    from stickslip.calibration.folds import workspace_coordinates

    paper = np.array([0.02, -0.01, 0.015, -0.02, 0.01, 0.012])
    one_bad_fold = np.array([0.001, -0.001, 0.002, -0.001, 0.001, 0.03])  # its largest above the paper's
    ev = _evidence({"paper": paper, "load2": one_bad_fold}, residuals=(0.02, 0.005))
    out = sel_mod._decide(ev, True)
    # one held-out pose's error is not the error at new poses: the family that fits 4x closer stays
    assert not out.fallback and out.fit.spec.name == "load2"
    # each expected error: floor^2 + slope^2 mean(d^4) over the workspace poses' distances to the calibrated
    # ones, Student's t for 6 held-out traverses (what the intervals' error model gives there)
    t2 = (student.ppf(0.975, 5) / 1.959963984540054) ** 2
    d4 = np.mean(groups_mod.nearest(workspace_coordinates(3), np.eye(6, 4))[0] ** 4)

    def expected(e, r):
        return math.sqrt(t2 * (r**2 + max(0.0, np.mean(e**2) - r**2) * d4))

    assert out.compared[1] == pytest.approx(expected(paper, 0.02), rel=1e-12)
    # the average's: its honest held-out errors (each fold's weights without it) and its residuals
    w = {lab: wt for lab, (wt, _) in out.mixture.items()}
    assert 0 < w["paper"] < 1
    r_mix = w["paper"] * 0.02 + w["load2"] * 0.005
    assert out.compared[0] == pytest.approx(expected(out.cv_errors, r_mix), rel=1e-12)


def test_intervals_grow_away_from_the_calibrated_poses_and_the_filter_uses_them(tmp_path):
    cal = calibrate(_table(300), model="auto")
    pred = cal.predictive[(3, "+")]
    p0 = pred.poses[0]
    at = float(relative_sd(cal, 3, "+", *p0))
    assert at == pytest.approx(pred.floor, rel=1e-9)
    far = np.array([0.0, 0.3, 0.0, 1.2, 0.9])  # tilted beyond the table's poses
    coords = load_coordinates_of(3, pred.poses)
    d = float(np.min(np.linalg.norm(coords - load_coordinates_of(3, far[None])[0], axis=1)))
    assert pred.exponent == 2.0
    assert float(relative_sd(cal, 3, "+", *far)) == pytest.approx(math.hypot(pred.floor, pred.slope * d**2), rel=1e-9)
    assert d > 0.1 and float(relative_sd(cal, 3, "+", *far)) > at
    pose = kin.Pose(*far)
    assert joint_sigma_model(cal, 3, pose) == pytest.approx(
        max(float(relative_sd(cal, 3, s, *far)) for s in "+-"), rel=1e-12)
    path = tmp_path / "cal.json"
    cal.save(path)
    back = Calibration.load(path)
    for key, p in cal.predictive.items():
        q = back.predictive[key]
        assert (q.floor, q.slope, q.exponent) == (p.floor, p.slope, p.exponent)
        np.testing.assert_array_equal(q.poses, p.poses)
    # a file written before the exponent was kept: its intervals grow linearly, as they were made
    doc = json.loads(path.read_text(encoding="utf-8"))
    for rec in doc["uncertainty"]:
        rec.pop("exponent", None)
    path.write_text(json.dumps(doc), encoding="utf-8")
    old = Calibration.load(path)
    assert old.predictive[(3, "+")].exponent == 1.0
    assert float(relative_sd(old, 3, "+", *far)) == pytest.approx(math.hypot(pred.floor, pred.slope * d), rel=1e-9)
    doc["uncertainty"][0]["exponent"] = 3
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ValueError, match=r"uncertainty\[0\]\.exponent must be 1 or 2"):
        Calibration.load(path)


def test_the_papers_procedure_is_untouched():
    # the paper's 14 traverses still give the paper's vectors exactly (the truth of synth.paper_table)
    from synth import PAPER_PRISMATIC

    cal = calibrate(paper_table(), model="auto")
    assert cal.method == "paper" and not cal.predictive
    for d, p in PAPER_PRISMATIC.items():
        got = cal.models[(3, d)].params
        assert got.a == pytest.approx(p.a, rel=1e-3) and got.c == pytest.approx(p.c, rel=2e-3)
