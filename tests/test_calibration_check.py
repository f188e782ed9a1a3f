"""Check traverses scale a calibration's intervals (stickslip.calibration.check; docs/models.md §4).

One Dahl arm day (tests/support/arm_days.py): ``auto`` on the paper's 14, the 32 spread and the 4
repeats; the check traverses are the day's random validation traverses, not fitted. The scale is
recomputed here from the standardized errors (``predict_many`` and ``relative_sd``) and the
formula, and every interval, ``sigma_model`` and prediction compared with the calibration's own.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from arm_days import make_day
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.calibration import Calibration, calibrate
from stickslip.calibration.check import CHECK, CheckParams, apply_check, check_scales
from stickslip.calibration.design import check_poses, spread_poses, workspace_poses
from stickslip.calibration.intervals import relative_sd
from stickslip.measurements import Traverse

DAY = make_day("dahl", 7, "2026-09-02", np.random.default_rng(7), validation_poses=3, repeat_first=True)


@pytest.fixture(scope="module")
def day() -> tuple[Calibration, list[Traverse]]:
    return calibrate(DAY.calibration, model="auto"), DAY.validation


def _z2(cal: Calibration, ts: list[Traverse]) -> np.ndarray:
    out = []
    for t in ts:
        sd = relative_sd(cal, t.joint, t.direction, t.q1, t.q2, t.q3, t.theta, t.psi).item()
        out.append((cal.predict_many([t])[0] / t.gamma - 1.0) ** 2 / sd**2)
    return np.array(out)


def test_the_scale_is_the_pooled_mean_square(day: tuple[Calibration, list[Traverse]]) -> None:
    cal, val = day
    checked = apply_check(cal, val)
    for j in (3, 2):
        ts = [t for t in val if t.joint == j]
        z2 = _z2(cal, ts)
        s = math.sqrt((CHECK.prior_traverses + z2.sum()) / (CHECK.prior_traverses + len(ts)))
        assert check_scales(cal, val)[j].scale == pytest.approx(s, rel=1e-12)
        for d in "+-":
            before, after = cal.predictive[(j, d)], checked.predictive[(j, d)]
            assert after.floor == pytest.approx(s * before.floor, rel=1e-12)
            assert after.slope == pytest.approx(s * before.slope, rel=1e-12)
            poses = np.array([list(p) for p in workspace_poses(j, 20, 5)]).T
            assert relative_sd(checked, j, d, *poses) == pytest.approx(s * relative_sd(cal, j, d, *poses), rel=1e-12)
            assert checked.sigma_model[(j, d)] == pytest.approx(s * cal.sigma_model[(j, d)], rel=1e-12)
            assert checked.selection[(j, d)]["check"]["traverses"] == len(ts)  # type: ignore[index]
        assert sum(f"joint {j}: {len(ts)} check traverse(s)" in n for n in checked.provenance.notes) == 1
    np.testing.assert_array_equal(checked.predict_many(val), cal.predict_many(val))  # the fit's predictions
    assert cal.predictive != checked.predictive  # the original is left as it was


def test_without_prior_the_scale_is_the_rms_of_z(day: tuple[Calibration, list[Traverse]]) -> None:
    cal, val = day
    got = check_scales(cal, val, CheckParams(prior_traverses=0.0))
    for j in (3, 2):
        z2 = _z2(cal, [t for t in val if t.joint == j])
        assert got[j].scale == pytest.approx(math.sqrt(z2.mean()), rel=1e-12)
        assert got[j].rms_z == pytest.approx(math.sqrt(z2.mean()), rel=1e-12)


def test_wild_check_traverses_widen(day: tuple[Calibration, list[Traverse]]) -> None:
    cal, val = day
    slow = [dataclasses.replace(t, steps=2 * t.steps) for t in val if t.joint == 3]  # steps half as long
    c = check_scales(cal, slow)[3]
    assert c.rms_error == pytest.approx(1.0, abs=0.1)  # predicted about twice the measured step
    assert c.scale > 5.0
    assert set(check_scales(cal, slow)) == {3}


def test_repeats_at_one_pose_count_once(day: tuple[Calibration, list[Traverse]]) -> None:
    """Three traverses at one pose and direction share its model error: one term, their z^2 averaged."""
    cal, val = day
    ts = [t for t in val if t.joint == 3]
    again = [dataclasses.replace(ts[0], steps=ts[0].steps + k) for k in (3, -5)]  # the pose traversed twice more
    z2 = _z2(cal, ts)
    z2_rep = _z2(cal, [ts[0], *again])
    c = check_scales(cal, ts + again)[3]
    nu = CHECK.prior_traverses
    want = math.sqrt((nu + z2[1:].sum() + z2_rep.mean()) / (nu + len(ts)))
    assert (c.traverses, c.poses) == (len(ts) + 2, len(ts))
    assert c.scale == pytest.approx(want, rel=1e-12)
    assert c.scale != pytest.approx(math.sqrt((nu + z2.sum() + z2_rep[1:].sum()) / (nu + len(ts) + 2)), rel=1e-6)
    notes = apply_check(cal, ts + again).provenance.notes
    assert any(f"joint 3: {len(ts) + 2} check traverse(s) at new poses ({len(ts)} counted" in n for n in notes)


@settings(max_examples=30, deadline=None)
@given(nu=st.floats(0.0, 100.0), keep=st.lists(st.booleans(), min_size=12, max_size=12))
def test_the_scale_lies_between_one_and_the_checks(day: tuple[Calibration, list[Traverse]], nu: float,
                                                   keep: list[bool]) -> None:
    cal, val = day
    ts = [t for t, k in zip(val, keep, strict=True) if k]
    for j, c in check_scales(cal, ts, CheckParams(prior_traverses=nu)).items():
        lo, hi = sorted((1.0, c.rms_z))
        assert lo - 1e-12 <= c.scale <= hi + 1e-12, j


def test_nothing_to_check(day: tuple[Calibration, list[Traverse]]) -> None:
    cal, val = day
    assert apply_check(cal, []) is cal
    paper = calibrate(DAY.paper14)  # the paper's procedure: no error model
    checked = apply_check(paper, val)
    assert checked.predictive == paper.predictive == {}
    assert checked.sigma_model == paper.sigma_model
    assert any("no error model" in n for n in checked.provenance.notes)
    stray = dataclasses.replace(val[0], joint=1, q1=0.0)  # a joint the calibration does not have
    notes = apply_check(cal, [stray]).provenance.notes
    assert "joint 1: check traverses not used: the calibration has no joint 1" in notes


def test_calibrate_takes_the_check(day: tuple[Calibration, list[Traverse]]) -> None:
    cal, val = day
    via = calibrate(DAY.calibration, model="auto", check=val)
    direct = apply_check(cal, val)
    assert via.predictive.keys() == direct.predictive.keys()
    for k in via.predictive:
        assert via.predictive[k].floor == pytest.approx(direct.predictive[k].floor, rel=1e-12)
    np.testing.assert_array_equal(via.predict_many(val), cal.predict_many(val))


def test_a_check_that_checks_nothing_is_refused(tmp_path: Path) -> None:
    """Asked for and used nowhere (the paper's method has no intervals; a joint the table lacks), a check must
    not pass for one: the calibration is refused with the reason, and nothing is written."""
    from typer.testing import CliRunner

    from stickslip.calibration import CalibrationError
    from stickslip.cli import app
    from stickslip.measurements import write_measurements

    with pytest.raises(CalibrationError, match=rf"none of the {len(DAY.validation)} check traverse\(s\) can check this "
                       r"calibration: they are of 2\+, 2-, 3\+, 3-; the joints and directions with intervals to "
                       r"scale are none"):
        calibrate(DAY.paper14, method="paper", check=DAY.validation)
    stray = [dataclasses.replace(t, joint=1, q1=0.0) for t in DAY.validation[:2]]
    meas, chk, out = tmp_path / "m.csv", tmp_path / "check.csv", tmp_path / "c.json"
    write_measurements(meas, DAY.calibration)
    write_measurements(chk, stray)
    r = CliRunner().invoke(app, ["calibrate", str(meas), "--check", str(chk), "-o", str(out)])
    assert r.exit_code == 2, r.output
    assert "none of the 2 check traverse(s) can check this calibration: they are of 1" in " ".join(r.stderr.split())
    assert not out.exists()


def test_check_poses_are_their_own_stream() -> None:
    a, b = check_poses(3, 4, 11), check_poses(3, 4, 11)
    assert a == b and len(a) == 4 and check_poses(2, 0, 11) == []
    assert not set(a) & set(workspace_poses(3, 2000, 11))  # not spread_poses' candidates
    assert not set(a) & set(spread_poses(3, 8, 11))
    assert all(p.q3 == 0.0 for p in a)  # the moving joint's own column


def test_calibrate_command_takes_a_check_table(day: tuple[Calibration, list[Traverse]], tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import write_measurements

    cal, val = day
    meas, chk = tmp_path / "m.csv", tmp_path / "check.csv"
    write_measurements(meas, DAY.calibration)
    write_measurements(chk, val)
    runner = CliRunner()
    r = runner.invoke(app, ["calibrate", str(meas), "--check", str(chk), "-o", str(tmp_path / "c.json")])
    assert r.exit_code == 0, r.output
    assert "check traverse(s) at new poses" in " ".join(r.output.split())
    saved = Calibration.load(tmp_path / "c.json")
    want = apply_check(cal, val)
    for k, p in want.predictive.items():
        assert saved.predictive[k].floor == pytest.approx(p.floor, rel=1e-9)
        assert saved.selection[k]["check"]["scale"] == pytest.approx(  # type: ignore[index]
            want.selection[k]["check"]["scale"], rel=1e-9)  # type: ignore[index]
    r = runner.invoke(app, ["calibrate", str(meas), "--check", str(chk), "--prior", str(tmp_path / "c.json")])
    assert r.exit_code == 2 and "not with --prior" in r.stderr


def test_suggest_check_writes_the_check_poses_in_both_directions(
    day: tuple[Calibration, list[Traverse]], tmp_path: Path
) -> None:
    from typer.testing import CliRunner

    from stickslip.cli import app

    cal, _ = day
    cal.save(tmp_path / "c.json")
    out = tmp_path / "poses.csv"
    runner = CliRunner()
    r = runner.invoke(app, ["suggest", "-c", str(tmp_path / "c.json"), "--check", "2", "--seed", "5", "-o", str(out)])
    assert r.exit_code == 0, r.output
    rows = [line.split(",") for line in out.read_text(encoding="utf-8").splitlines()[1:]]
    want = [(j, d, p) for j in cal.joints for p in check_poses(j, 2, 5) for d in "+-"]
    assert [(int(r[0]), r[1], tuple(float(v) for v in r[2:])) for r in rows] == [(j, d, tuple(p)) for j, d, p in want]
    r = runner.invoke(app, ["suggest", "-c", str(tmp_path / "c.json"), "--check", "1", "-j", "3", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.output) == [{"joint": 3, **check_poses(3, 1, 0)[0]._asdict()}]  # random: no sd to claim
    r = runner.invoke(app, ["suggest", "-c", str(tmp_path / "c.json"), "--check", "21"])
    assert r.exit_code == 2 and "--check 21 is outside 1..20" in r.stderr
    r = runner.invoke(app, ["suggest", "-c", str(tmp_path / "c.json"), "--seed", "3"])
    assert r.exit_code == 2 and "give --check N too" in r.stderr


def test_a_check_traverse_at_a_fitted_pose_is_refused() -> None:
    # the fit's own pose shows its residual there, not its error between poses: it would narrow the intervals
    from stickslip.calibration import CalibrationError

    again = dataclasses.replace(DAY.calibration[5], steps=DAY.calibration[5].steps + 7)  # a repeat, other count
    with pytest.raises(CalibrationError, match=r"check traverse 2 \(joint \d, [+-]\) is at a pose the calibration"):
        calibrate(DAY.calibration, model="auto", check=[DAY.validation[0], again])
    # one pose as the fit's groups key it (POSE_DECIMALS): here 1 µrad off is the same pose, 1 mrad a new one
    near = dataclasses.replace(again, psi=again.psi + 1e-6)
    with pytest.raises(CalibrationError, match=r"check traverse 2 .* is at a pose the calibration"):
        calibrate(DAY.calibration, model="auto", check=[DAY.validation[0], near])
    moved = dataclasses.replace(again, psi=again.psi + 1e-3)
    assert calibrate(DAY.calibration, model="auto", check=[DAY.validation[0], moved]).selection


def test_a_check_traverse_of_another_day_is_refused() -> None:
    # another session's traverse measures the step's drift between sessions too, not only the fit's error
    from stickslip.calibration import CalibrationError

    later = dataclasses.replace(DAY.validation[2], day="2026-09-03")
    with pytest.raises(CalibrationError, match=r"check traverse 3 \(joint \d, [+-]\) is of day '2026-09-03', the "
                                               r"calibration of day '2026-09-02'"):
        calibrate(DAY.calibration, model="auto", check=[DAY.validation[0], DAY.validation[1], later])
    # the calibration's day given: the check is of that session
    assert calibrate(DAY.calibration, model="auto", day="2026-09-03", check=[later]).day == "2026-09-03"
