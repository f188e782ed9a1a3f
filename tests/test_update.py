"""Bringing a calibration up to date with a few traverses (stickslip.calibration.update)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from physics_scenarios import max_errors, paper14, random_pose, spread, well_spread
from synth import PAPER_PRISMATIC, paper_table, random_poses, traverse_from_model
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.calibration import Calibration, CalibrationError, Conditions, calibrate
from stickslip.calibration.design import workspace_poses
from stickslip.calibration.update import (
    LOAD_PRIOR,
    WORKSPACE_POSES,
    _load_gradients,
    model_sigma,
    prediction_sd,
    update_calibration,
)
from stickslip.cli import app
from stickslip.measurements import Traverse, measurements_to_csv
from stickslip.models import JointModel, PrismaticParams
from stickslip.sim import physics as ph


def _scaled_table(factor: float) -> list[Traverse]:
    """The paper table measured on an arm whose steps are all ``factor`` times larger (fewer steps)."""
    return [t.__class__(**{**t.as_row(), "steps": round(t.steps / factor)}) for t in paper_table()]


def test_posterior_is_the_normal_normal_formula():
    prior = calibrate(paper_table())
    prior.sigma_model[(3, "+")] = 0.02
    new = [t for t in _scaled_table(1.10) if t.joint == 3 and t.direction == "+"][:1]
    cal, ups = update_calibration(prior, new, drift=0.15)
    r = math.log(new[0].gamma / prior.predict(new[0]))
    precision = 1 / 0.15**2 + 1 / 0.02**2
    (u,) = ups
    assert math.log(u.scale) == pytest.approx(r / 0.02**2 / precision, rel=1e-12)
    assert u.scale_sd == pytest.approx(1 / math.sqrt(precision), rel=1e-12)
    # the new traverse carries no load, so the load sensitivity keeps its prior variance; averaged over the
    # workspace's loads it widens sigma_model beyond the scale's posterior
    g2 = float(np.mean(_load_gradients(prior.models[(3, "+")], workspace_poses(3, WORKSPACE_POSES)) ** 2))
    assert g2 > 0.05  # RMS load gradient 0.24: a 10 % load change moves the step 2.4 % (RMS) over the workspace
    assert cal.sigma_model[(3, "+")] == pytest.approx(math.sqrt(0.02**2 + u.scale_sd**2 + LOAD_PRIOR**2 * g2), rel=1e-9)
    # only the measured direction changed; the other keeps its model and widens its uncertainty
    np.testing.assert_array_equal(cal.models[(3, "-")].params.as_vector(), prior.models[(3, "-")].params.as_vector())
    assert cal.sigma_model[(3, "-")] == pytest.approx(math.hypot(model_sigma(prior, 3, "-")[0], 0.15))
    # the scaled model predicts the new traverse within the posterior's pull towards 1
    assert cal.predict(new[0]) / new[0].gamma == pytest.approx(1.0, abs=0.01)


def test_many_traverses_recover_the_scale():
    prior = calibrate(paper_table())
    cal, ups = update_calibration(prior, _scaled_table(0.9), drift=0.15)
    for u in ups:
        assert u.scale == pytest.approx(0.9, rel=0.01)
    b = cal.models[(3, "+")].params
    assert b.b == prior.models[(3, "+")].params.b  # shape (b) is kept


def test_prior_without_the_joint_is_refused():
    prior = calibrate([t for t in paper_table() if t.joint == 3])
    with pytest.raises(CalibrationError, match="no model for joint 2"):
        update_calibration(prior, [t for t in paper_table() if t.joint == 2][:1])


def test_a_stage_calibration_as_prior_is_refused_by_what_it_is():
    # a stage's file holds mean steps, no models: the message said "(it has: )"
    prior = Calibration({}, {}, {(3, "+"): 1e-6, (3, "-"): 1e-6}, "2026-11-22", "stage-mean")
    with pytest.raises(CalibrationError, match=r"the prior calibration \(stage-mean\) has no step-size model"):
        update_calibration(prior, [t for t in paper_table() if t.joint == 3][:1])


def test_prediction_interval_grows_for_short_moves():
    cal = calibrate(paper_table())
    long, assumed = prediction_sd(cal, 3, "+", 10_000)
    short, _ = prediction_sd(cal, 3, "+", 4)
    assert assumed and short > long
    assert short == pytest.approx(math.hypot(0.075, 0.03 / 2), rel=1e-12)
    assert long == pytest.approx(math.hypot(0.075, 0.03 / 100), rel=1e-12)


@pytest.mark.slow
def test_prior_plus_four_on_the_physics_arm():
    # yesterday's 46-traverse calibration (32 poses spread over the load space) with 4 of today's traverses
    # (one per joint and direction) at random poses, on a seed and days not used while developing: the
    # issue's <= 10 % / <= 5 % (measured 9.0 % / 3.2 % and 3.9 % / 3.1 %; yesterday's as is: 17.5 % / 9.6 %
    # and 17.6 % / 12.0 %; with the maximin design for joint 3: 9.7 % and 7.6 % prismatic), and the update
    # must beat yesterday's calibration used as it is
    rng = np.random.default_rng(23)
    arm = ph.PhysicsMM3A(seed=23, day="2026-06-01")
    prior = calibrate(paper14(arm, "2026-06-01") + well_spread(arm, "2026-06-01", rng), model="auto")
    for day in ("2026-06-02", "2026-06-03"):
        arm = ph.PhysicsMM3A(seed=23, day=day)
        val = spread(arm, day, rng, 8)
        new4 = [ph.traverse(arm, j, d, random_pose(rng, j), day) for j in (3, 2) for d in "+-"]
        cal, _ = update_calibration(prior, new4)
        e = max_errors(cal.predict_many(val), val)
        assert e[3] <= 0.10 and e[2] <= 0.05, (day, e)
        old = max_errors(prior.predict_many(val), val)
        assert e[3] + e[2] < old[3] + old[2]


def test_cli_prior_round_trip(tmp_path):
    runner = CliRunner()
    prior = tmp_path / "old.json"
    calibrate(paper_table()).save(prior)
    new = tmp_path / "new.csv"
    new.write_text(measurements_to_csv([t for t in _scaled_table(1.05) if t.q2 == -math.pi / 2 or t.joint == 2][:4]))
    out = tmp_path / "today.json"
    r = runner.invoke(app, ["calibrate", str(new), "--prior", str(prior), "-o", str(out)])
    assert r.exit_code == 0, r.output
    cal = Calibration.load(out)
    assert cal.method.endswith("+ update") and cal.provenance.extra["updates"]
    r = runner.invoke(app, ["calibrate", str(new), "--prior", str(tmp_path / "missing.json")])
    assert r.exit_code == 2 and "no such calibration file" in r.stderr


def test_suggest_after_the_papers_procedure_starts_from_its_traverses():
    # the paper's procedure keeps no covariance: the design starts from the information of its own
    # traverses (3 prismatic, 4 rotary poses for as many parameters), not from nothing (a ridge of
    # 1e-6 said the workspace's sd was about 1000x the step: 99391 % on the demo's calibration)
    from stickslip.calibration import design

    arm = ph.PhysicsMM3A(seed=52, day="x")
    cal = calibrate(paper14(arm, "x"))
    assert cal.method.startswith("paper") and not cal.covariance
    for joint, n_params in ((3, 3), (2, 4)):
        poses = design._paper_poses(joint)
        sig, _ = model_sigma(cal, joint, "+")
        g = design._gradients(design._as_family(cal.models[(joint, "+")]), "+", poses)
        assert g.shape == (n_params, n_params) and np.linalg.matrix_rank(g) == n_params
        # exactly determined: the fit passes through each traverse, whose prediction keeps its sd (leverage 1)
        m = g.T @ g / sig**2
        np.testing.assert_allclose(np.einsum("ip,pq,iq->i", g, np.linalg.inv(m), g), sig**2, rtol=1e-6)
        (first,) = design.suggest_poses(cal, joint, 1)
        assert 0.5 * sig < first.rms_sd_before < 10 * sig and first.rms_sd_after < first.rms_sd_before


@pytest.mark.slow
def test_suggest_picks_informative_poses(tmp_path):
    # greedy I-optimal design: the suggested pose is the candidate that most reduces the workspace's
    # prediction variance, so it beats every other candidate, e.g. the paper's unloaded pose
    from stickslip.calibration import design

    arm = ph.PhysicsMM3A(seed=51, day="x")
    cal = calibrate(paper14(arm, "x") + spread(arm, "x", np.random.default_rng(51), 4), model="auto")
    (first,) = design.suggest_poses(cal, 3, 1)
    assert first.rms_sd_after < first.rms_sd_before
    orig = design.workspace_poses
    try:  # offer only the suggested pose and the unloaded pose (q2 = -90°, level): it must pick the first
        design.workspace_poses = lambda j, n, seed=0: (  # type: ignore[assignment]
            [first.pose, kin.Pose(0.0, -math.pi / 2, 0.0, 0.0, 0.0)] if seed == 1 else orig(j, n, seed)
        )
        (again,) = design.suggest_poses(cal, 3, 1, candidates=2)
    finally:
        design.workspace_poses = orig
    assert again.pose == first.pose
    path = tmp_path / "cal.json"
    cal.save(path)
    out = tmp_path / "next.csv"
    r = CliRunner().invoke(app, ["suggest", "-c", str(path), "--n", "2", "-o", str(out), "--json"])
    assert r.exit_code == 0, r.output
    lines = out.read_text().splitlines()
    assert lines[0] == "joint,direction,q1,q2,q3,theta,psi" and len(lines) == 1 + 2 * 2 * 2
    r = CliRunner().invoke(app, ["suggest", "-c", str(path), "--n", "0"])
    assert r.exit_code == 2 and "outside 1..20" in r.stderr


def test_an_update_at_a_pose_without_load_keeps_the_load_sensitivity_uncertain():
    # a prior that fitted its day exactly (sigma_model 0.1 %, as a family fit on the simulator keeps), and a
    # next day whose friction made every load term 8 % stronger (within LOAD_PRIOR's 10 %), updated with one
    # traverse each way at the paper's first pose, where the step does not depend on the load: the load
    # sensitivity stays at its prior, so away from that pose the update knows the step no better than that.
    # The constant sigma_model was the scale's posterior alone (0.14 %): 8 of 16 traverses at random poses
    # (errors 0.1-6.3 %) fell outside their 95 % intervals; with the load sensitivity's variance averaged over
    # the workspace it is 2.4 % (+) and 3.4 % (-), and none does
    prior = calibrate(paper_table())
    for d in "+-":
        prior.sigma_model[(3, d)] = 0.001
    today = {d: JointModel(3, d, PrismaticParams(p.a, p.b, p.c * 1.08)) for d, p in PAPER_PRISMATIC.items()}
    new = [traverse_from_model(today[d], {}) for d in "+-"]  # q2 = -90 deg, no tilt: no load along the joint
    cal, _ = update_calibration(prior, new)
    rng = np.random.default_rng(5)
    val = [traverse_from_model(today[d], p) for p in random_poses(rng, 3, 8) for d in "+-"]
    err = np.abs(np.log(np.array([t.gamma for t in val]) / cal.predict_many(val)))
    sd = np.array([cal.sigma_model[(3, t.direction)] for t in val])
    assert np.count_nonzero(err > 1.96 * sd) == 0, (err, sd)


def test_cli_prior_of_another_arm_or_a_later_day_is_warned_about(tmp_path):
    # the update keeps the prior's shape: another arm's (or a later session's) is named, one line each
    runner = CliRunner()
    prior, later = tmp_path / "arm7.json", tmp_path / "later.json"
    cal = calibrate(paper_table(day="2026-11-22"))
    dataclasses.replace(cal, conditions=Conditions("sim://?seed=7", 1000.0)).save(prior)
    dataclasses.replace(cal, day="2026-11-25").save(later)
    new = tmp_path / "new.csv"
    new.write_text(measurements_to_csv([t for t in paper_table(day="2026-11-23") if t.q2 == -math.pi / 2]))
    r = runner.invoke(app, ["calibrate", str(new), "--prior", str(prior), "--device", "sim://?seed=3"])
    assert r.exit_code == 0, r.output
    assert ("warning: the prior calibration was made under other conditions (made on sim://?seed=7, this is "
            "sim://?seed=3)") in " ".join(r.stderr.split())
    r = runner.invoke(app, ["calibrate", str(new), "--prior", str(prior), "--device", "sim://?seed=7",
                            "--frequency", "1000"])
    assert r.exit_code == 0 and "warning" not in r.stderr, r.stderr
    r = runner.invoke(app, ["calibrate", str(new), "--prior", str(later)])
    assert r.exit_code == 0, r.output
    assert ("warning: the prior calibration is of 2026-11-25, 2 days after these traverses' 2026-11-23"
            in " ".join(r.stderr.split()))


def test_cli_a_table_of_several_sessions_is_warned_about(tmp_path):
    # the fit pools the days (the day-to-day change becomes model error) and dates the result by the latest
    runner = CliRunner()
    table = tmp_path / "two-days.csv"
    table.write_text(measurements_to_csv(paper_table(day="2026-11-22") + paper_table(day="2026-11-23")))
    r = runner.invoke(app, ["calibrate", str(table)])
    assert r.exit_code == 0, r.output
    assert ("warning: the table holds traverses of 2 sessions (2026-11-22, 2026-11-23), fitted as one and dated "
            "2026-11-23") in " ".join(r.stderr.split())
    one = tmp_path / "one-day.csv"
    one.write_text(measurements_to_csv(paper_table(day="2026-11-23")))
    r = runner.invoke(app, ["calibrate", str(one)])
    assert r.exit_code == 0 and "warning" not in r.stderr, r.stderr
