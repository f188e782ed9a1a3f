"""Model families (stickslip.models.families), their fitting and the cross-validated selection."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from physics_scenarios import max_errors, paper14, random_pose, spread, well_spread
from synth import paper_table

from stickslip import kinematics as kin
from stickslip.calibration import Calibration, calibrate
from stickslip.measurements import Traverse
from stickslip.models import JointModel, NonPhysicalError, PrismaticParams, RotaryParams
from stickslip.models.families import FAMILIES, FamilyModel, FamilyParams, family_spec
from stickslip.motion.planning import Planner
from stickslip.sim import physics as ph


def test_paper_family_is_the_papers_equations():
    # (F1) with only a, b, c is Eq. 3; (F3) with gamma0, d linear in q3 is Eq. 8 (exact closed form vs quadrature)
    pm = JointModel(3, "+", PrismaticParams(972e-9, 0.27, 372e-9))
    fm = FamilyModel(3, "+", FamilyParams("paper", 3, (972e-9, 0.27, 372e-9)))
    rng = np.random.default_rng(0)
    q2, th = rng.uniform(-2, 0.5, 50), rng.uniform(-1.5, 1.5, 50)
    ps, q1 = rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50)
    np.testing.assert_allclose(fm.gamma(q1, q2, 0.0, th, ps), pm.gamma(q1, q2, 0.0, th, ps), rtol=1e-14)
    rp = RotaryParams((52e-6, 47e-6), (-8.15e-6, -19.4e-6))
    pr = JointModel(2, "+", rp)
    fr = FamilyModel(2, "+", FamilyParams("paper", 2, (52e-6, 47e-6, -8.15e-6, -19.4e-6)))
    q3 = rng.uniform(0, kin.Q3_MAX, 50)
    lo, hi = kin.JOINTS[2].lower, kin.JOINTS[2].upper
    a = fr.average_gamma(lo, hi, q1, 0.0, q3, th, ps)
    b = pr.average_gamma(lo, hi, q1, 0.0, q3, th, ps)
    np.testing.assert_allclose(a, b, rtol=1e-11)


def test_tabulated_profile_plans_like_the_closed_form():
    cal = calibrate(paper_table())
    fam = Calibration({k: FamilyModel(k[0], k[1], FamilyParams("paper", k[0], tuple(m.params.as_vector())))
                       for k, m in cal.models.items() if k[0] == 2}, {}, {}, "d", "families")
    pose = kin.Pose(0.0, 0.0, 0.004, 0.0, 0.0)
    exact = Planner(cal, 2, pose)
    tab = Planner(fam, 2, pose)
    assert tab.exact_steps(-1.0, 0.3) == pytest.approx(exact.exact_steps(-1.0, 0.3), rel=1e-7)
    end = tab.position_after(-1.0, 5000)
    assert end == pytest.approx(exact.position_after(-1.0, 5000), abs=1e-9)
    assert tab.exact_steps(-1.0, end) == pytest.approx(5000, rel=1e-9)


@settings(max_examples=60, deadline=None)
@given(a=st.floats(-0.2, 1.2), n=st.integers(-20000, 20000))
@pytest.mark.slow
def test_tabulated_profile_steps_and_dead_reckoning_invert_each_other_beyond_the_table(a, n):
    # the table ends 5 % of the travel past each stop; dead reckoning went on past it at the edge's step but the
    # step count stopped there (np.interp clips): 5405 steps out from the lower stop counted back as 5404.68
    cal = calibrate(paper_table())
    fam = Calibration({k: FamilyModel(k[0], k[1], FamilyParams("paper", k[0], tuple(m.params.as_vector())))
                       for k, m in cal.models.items() if k[0] == 2}, {}, {}, "d", "families")
    tab = Planner(fam, 2, kin.Pose(0.0, 0.0, 0.0, 0.0, 0.0))
    spec = kin.JOINTS[2]
    q0 = spec.lower + a * spec.span
    end = tab.position_after(q0, n)
    assert tab.exact_steps(q0, end) == pytest.approx(abs(n), rel=1e-9, abs=1e-6)
    assert (end - q0) * n >= 0.0


def test_paper_poses_still_give_the_paper_calibration():
    a = calibrate(paper_table(), model="auto")
    b = calibrate(paper_table())
    assert a.method == b.method == "paper"
    for k in b.models:
        np.testing.assert_array_equal(a.models[k].params.as_vector(), b.models[k].params.as_vector())


def _second_arm_traverses(rng, n_poses, truth):
    """A closed-form arm whose prismatic step is quadratic in the load (family load2), 0.5 % noise."""
    out = []
    spec = family_spec(3, "load2")
    for _ in range(n_poses):
        p = random_pose(rng, 3)
        for d, vals in truth.items():
            fm = FamilyModel(3, d, FamilyParams(spec.name, 3, vals))
            g = float(fm.gamma(p.q1, p.q2, 0.0, p.theta, p.psi)) * (1 + 0.005 * rng.standard_normal())
            start, end = (0.0, kin.Q3_MAX) if d == "+" else (kin.Q3_MAX, 0.0)
            out.append(Traverse("d", 3, d, p.q1, p.q2, 0.0, p.theta, p.psi, start, end, max(1, round(kin.Q3_MAX / g))))
    return out


@pytest.mark.slow
def test_selection_finds_a_nonlinear_load_on_a_second_arm():
    # independent of the physics arm: the closed form with a strong L^2 term; the paper's form cannot fit it
    truth = {"+": (950e-9, 0.25, 300e-9, 250e-9), "-": (900e-9, 0.22, -400e-9, 200e-9)}
    rng = np.random.default_rng(7)
    ts = _second_arm_traverses(rng, 14, truth)
    cal = calibrate(ts, model="auto")
    chosen = cal.selection[(3, "+")]["chosen"]
    assert "load2" in str(chosen) or "full" in str(chosen) or "ratio" in str(chosen)
    weights = cal.selection[(3, "+")]["weights"]
    # the families with the true L^2 term (load2 and those containing it) take the weight; forms without it none
    with_l2 = [k for k in weights if any(n == "e" for n, _ in family_spec(3, k.partition("+")[0]).names)]
    assert sum(weights[k] for k in with_l2) > 0.95, weights
    assert not any(k.startswith("paper") or k == "constant" for k in weights)
    val = _second_arm_traverses(rng, 20, truth)
    err = np.abs(cal.predict_many(val) / np.array([t.gamma for t in val]) - 1)
    # the average hedges between families 14 poses cannot tell apart (load2, load2-normal, load-mount, ...):
    # its largest error stays near load2's alone (2.6 %), far below the paper's form's (13 %)
    assert np.max(err) < 0.04
    paper = calibrate(ts, model="paper", method="lsq")
    perr = np.abs(paper.predict_many(val) / np.array([t.gamma for t in val]) - 1)
    assert np.max(perr) > 2 * np.max(err)
    scores = {s["family"]: s for s in cal.selection[(3, "+")]["scores"]}
    assert scores["paper"]["cv_rms"] > scores["load2"]["cv_rms"]


@pytest.mark.slow
def test_averaged_members_are_labelled_like_the_selection(tmp_path):
    # a family and its +shared variant are two members with the same family name: the file keeps each member's
    # label (the selection's), so members and weights can be matched; a file without labels still loads
    truth = {"+": (950e-9, 0.25, 300e-9, 250e-9), "-": (900e-9, 0.22, -400e-9, 200e-9)}
    ts = _second_arm_traverses(np.random.default_rng(7), 14, truth)
    cal = calibrate(ts, model="auto")
    for key, m in cal.models.items():
        assert isinstance(m, FamilyModel) and len(m.members) > 1  # averaged, so the test means something
        weights = cal.selection[key]["weights"]
        assert len(m.member_labels) == len(m.members) == len(weights)
        for lab, (w, p) in zip(m.member_labels, m.members, strict=True):
            assert lab in (p.family, p.family + "+shared") and weights[lab] == pytest.approx(w, abs=1e-12)
    path = tmp_path / "cal.json"
    cal.save(path)
    back = Calibration.load(path)
    for key, m in cal.models.items():
        assert back.models[key].member_labels == m.member_labels
    data = json.loads(path.read_text())
    for fam in data["families"]:
        for mem in fam["members"]:
            del mem["label"]
    path.write_text(json.dumps(data))
    old = Calibration.load(path)
    assert all(m.member_labels == () for m in old.models.values())
    np.testing.assert_allclose(old.predict_many(ts), cal.predict_many(ts), rtol=1e-12)
    data["families"][0]["members"][1]["parameters"][0]["value"] *= 2  # not the heaviest member: the step changes
    path.write_text(json.dumps(data))
    assert not np.allclose(Calibration.load(path).predict_many(ts), cal.predict_many(ts), rtol=1e-6)
    top = data["families"][0]["parameters"][0]
    top["value"] *= 2  # the shown parameters no longer those of the heaviest member: a damaged file
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="not those of the member with the largest weight"):
        Calibration.load(path)
    top["value"] /= 2
    data["families"][0]["members"][0]["label"] = "paper+shared"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="label 'paper\\+shared' is not"):
        Calibration.load(path)


@pytest.mark.slow
def test_family_calibration_round_trips_through_json(tmp_path):
    arm = ph.PhysicsMM3A(seed=41, day="2026-04-01")
    rng = np.random.default_rng(41)
    ts = paper14(arm, "2026-04-01") + spread(arm, "2026-04-01", rng, 5)
    cal = calibrate(ts, model="auto")
    path = tmp_path / "cal.json"
    cal.save(path)
    data = json.loads(path.read_text())
    assert data["version"] == 2 and data["families"]
    back = Calibration.load(path)
    np.testing.assert_allclose(back.predict_many(ts), cal.predict_many(ts), rtol=1e-12)
    assert back.sigma_model == pytest.approx(cal.sigma_model)
    for k in cal.covariance:
        np.testing.assert_allclose(back.covariance[k], cal.covariance[k], rtol=1e-12)
    # a paper calibration is still written as version 1
    p1 = tmp_path / "p.json"
    calibrate(paper_table()).save(p1)
    assert json.loads(p1.read_text())["version"] == 1


def test_bad_family_file_is_refused(tmp_path):
    arm = ph.PhysicsMM3A(seed=42, day="x")
    ts = paper14(arm, "x") + spread(arm, "x", np.random.default_rng(2), 4)
    data = calibrate(ts, model="auto").to_dict()
    data["families"][0]["parameters"][0]["value"] = float("nan")
    with pytest.raises(ValueError, match="finite"):
        Calibration.from_dict(json.loads(json.dumps(data).replace("NaN", "null")))
    data["families"][0]["family"] = "nonsense"
    with pytest.raises(ValueError):
        Calibration.from_dict(data)


@pytest.mark.slow
def test_calibrate_never_stops_and_meets_the_issue_numbers():
    # the issue's acceptance on days and a seed not used while developing: 46 traverses (the 32 spread
    # over the load space) -> <= 7.5 % / 3.5 % at random validation poses
    rng = np.random.default_rng(21)
    for day in ("2026-05-11", "2026-05-12", "2026-05-13"):
        arm = ph.PhysicsMM3A(seed=21, day=day)
        p14 = paper14(arm, day)
        s32 = well_spread(arm, day, rng)
        val = spread(arm, day, rng, 8)
        c14 = calibrate(p14, model="auto")
        c46 = calibrate(p14 + s32, model="auto")
        const = np.array([c14.constant_step(t.joint, t.direction) for t in val])
        e14, e46, ec = max_errors(c14.predict_many(val), val), max_errors(c46.predict_many(val), val), max_errors(
            const, val
        )
        assert e14[3] < ec[3] and e14[2] < ec[2]
        assert e46[3] <= 0.075 and e46[2] <= 0.035, (day, e46)
        assert set(c46.selection) == {(2, "+"), (2, "-"), (3, "+"), (3, "-")}


def test_every_family_is_documented():
    text = (__import__("pathlib").Path(__file__).resolve().parents[1] / "docs" / "models.md").read_text()
    for key, spec in FAMILIES.items():
        assert f"`{spec.name}`" in text, key


def test_joint_one_with_few_traverses_falls_back():
    arm = ph.PhysicsMM3A(seed=3, day="x")
    ts = paper14(arm, "x") + spread(arm, "x", np.random.default_rng(3), 3)
    ts.append(ph.traverse(arm, 1, "+", kin.Pose(0.0, -math.pi / 2, 0.0, -math.pi / 2, 0.0), "x"))
    cal = calibrate(ts, model="auto")
    assert cal.models[(1, "+")].params.family == "constant"


@pytest.mark.slow
def test_cli_calibrate_and_fit_with_families(tmp_path):
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import write_measurements

    arm = ph.PhysicsMM3A(seed=43, day="2026-04-02")
    ts = paper14(arm, "2026-04-02") + spread(arm, "2026-04-02", np.random.default_rng(43), 6)
    meas = tmp_path / "m.csv"
    write_measurements(meas, ts)
    runner = CliRunner()
    r = runner.invoke(app, ["calibrate", str(meas), "-o", str(tmp_path / "c.json")])
    assert r.exit_code == 0, r.output
    flat = " ".join(r.output.split())  # rich wraps the title and caption at 80 columns
    assert "cross-validation on held-out poses" in flat and "weight" in flat and "◀" in flat
    assert "expected RMS error at new poses of the workspace: 2+" in flat
    r = runner.invoke(app, ["show", str(tmp_path / "c.json")])  # the saved file tells the same mix
    assert r.exit_code == 0, r.output
    flat = " ".join(r.output.split())
    assert "cross-validation on held-out poses" in flat and "weight" in flat and "◀" in flat
    r = runner.invoke(app, ["fit", str(meas), "--model", "auto", "--json"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["calibrate", str(meas), "--model", "nonsense"])
    assert r.exit_code == 2 and "no model family 'nonsense'" in r.stderr
    r = runner.invoke(app, ["plan", "-c", str(tmp_path / "c.json"), "--joint", "2", "--from", "-30deg",
                            "--to", "-60deg", "--q3", "6mm", "--json"])
    assert r.exit_code == 0, r.output
    assert "pi95" in r.output


def test_sinusoidal_form_of_a_family_is_exact_where_it_exists():
    # the paper family's (A, alpha, beta) equal Eq. 8's; the radial and normal terms are sinusoids too
    rp = RotaryParams((52e-6, 47e-6), (-8.15e-6, -19.4e-6))
    pr = JointModel(2, "+", rp)
    fr = FamilyModel(2, "+", FamilyParams("paper", 2, (52e-6, 47e-6, -8.15e-6, -19.4e-6)))
    args = (np.array([0.1, -0.3]), 0.0, np.array([0.004, 0.011]), np.array([-0.3, 0.7]), 0.2)
    for a, b in zip(fr.rotary_coefficients(*args), pr.rotary_coefficients(*args), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-18)
    rad = FamilyModel(2, "+", FamilyParams("radial", 2, (52e-6, 47e-6, -8.15e-6, -19.4e-6, 3e-6)))
    A, al, be = rad.rotary_coefficients(0.2, 0.0, 0.005, -0.4, 0.3)
    q = np.linspace(-3.0, 0.4, 7)
    np.testing.assert_allclose(A + al * np.cos(q) + be * np.sin(q), rad.gamma(0.2, q, 0.005, -0.4, 0.3), rtol=1e-12)


def _family_doc() -> dict:
    arm = ph.PhysicsMM3A(seed=44, day="f")
    ts = paper14(arm, "f") + spread(arm, "f", np.random.default_rng(44), 4)
    return calibrate(ts, model="auto").to_dict()


_DOC = None


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(150))
def test_mangled_family_files_give_one_reason(seed):
    # fuzz: replace one field anywhere in the families / uncertainty entries with a hostile value;
    # loading either works or raises ValueError, never anything else
    global _DOC
    if _DOC is None:
        _DOC = _family_doc()
    doc = json.loads(json.dumps(_DOC))
    rng = np.random.default_rng(seed)
    hostile = [None, "x", -1, 0, 1e308, -1e308, [], {}, True, [1, 2], {"a": 1}, "NaN"]
    paths = []

    def walk(node, path):
        if isinstance(node, dict):
            for k, v in node.items():
                paths.append((*path, k))
                walk(v, (*path, k))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                paths.append((*path, i))
                walk(v, (*path, i))

    for key in ("families", "uncertainty", "selection"):
        walk(doc[key], (key,))
    path = paths[int(rng.integers(len(paths)))]
    target = doc
    for k in path[:-1]:
        target = target[k]
    target[path[-1]] = hostile[int(rng.integers(len(hostile)))]
    try:
        cal = Calibration.from_dict(doc)
    except ValueError:
        return
    try:  # a number that is valid alone can still make the step reach zero: refused where used, with the reason
        cal.predict_many([t for t in paper_table() if (t.joint, t.direction) in cal.models][:4])
    except NonPhysicalError as e:
        assert "stall" in str(e)


def test_averaging_weights_identities():
    # pseudo-BMA+ (docs/models.md §3): equal errors -> equal weights; a family whose left-out errors are
    # 10x smaller on every pose takes (nearly) all the weight; weights sum to 1, are deterministic, and a
    # family that is better on only some poses keeps part of the weight (the Bayesian bootstrap's hedge)
    from stickslip.calibration.selection import MIN_WEIGHT, averaging_weights

    rng = np.random.default_rng(3)
    ids = np.repeat(np.arange(10), 2)
    e = 0.02 * rng.standard_normal(20)
    w = averaging_weights({"a": e, "b": e.copy()}, ids)
    assert w["a"] == pytest.approx(0.5, abs=1e-12) and w["b"] == pytest.approx(0.5, abs=1e-12)
    w = averaging_weights({"good": 0.1 * e, "bad": e}, ids)
    assert w == {"good": 1.0}  # the other falls under MIN_WEIGHT and is dropped
    mixed = e.copy()
    mixed[:6] *= 0.2  # better on 3 of 10 poses, the same elsewhere
    w2 = averaging_weights({"x": mixed, "y": e}, ids)
    assert sum(w2.values()) == pytest.approx(1.0, abs=1e-12) and min(w2.values()) >= MIN_WEIGHT
    assert w2["x"] > w2["y"]
    assert averaging_weights({"x": mixed, "y": e}, ids) == w2


def test_averaged_model_predicts_the_weighted_step():
    # an averaged FamilyModel's step is sum w_k gamma_k; its traverse average is the harmonic mean of that
    # sum along the travel (rotary), not the weighted traverse averages
    a = FamilyParams("paper", 2, (52e-6, 47e-6, -8e-6, -19e-6))
    b = FamilyParams("radial", 2, (50e-6, 49e-6, -6e-6, -21e-6, 3e-6))
    m = FamilyModel(2, "+", a, members=((0.7, a), (0.3, b)))
    ma, mb = FamilyModel(2, "+", a), FamilyModel(2, "+", b)
    args = (0.1, np.linspace(-3.0, 0.4, 5), 0.004, -0.3, 0.2)
    np.testing.assert_allclose(m.gamma(*args), 0.7 * ma.gamma(*args) + 0.3 * mb.gamma(*args), rtol=1e-14)
    lo, hi = kin.JOINTS[2].lower, kin.JOINTS[2].upper
    q = np.linspace(lo, hi, 200001)
    g = m.gamma(0.1, q, 0.004, -0.3, 0.2)
    inv = 1.0 / g
    exact = (hi - lo) / float(np.sum(0.5 * (inv[1:] + inv[:-1]) * np.diff(q)))
    assert float(m.average_gamma(lo, hi, 0.1, 0.0, 0.004, -0.3, 0.2)) == pytest.approx(exact, rel=1e-8)
    scaled = m.map_params(lambda p: p.scaled(1.1))
    np.testing.assert_allclose(scaled.gamma(*args), 1.1 * m.gamma(*args), rtol=1e-14)
