"""CLI: calibrate, predict, validate, plan, show — and their one-line errors (exit 2, no traceback)."""

import csv
import io
import json
import math

import numpy as np
import pytest
from synth import paper_table
from typer.testing import CliRunner

from stickslip.calibration import Calibration, calibrate
from stickslip.cli import app
from stickslip.kinematics import Pose
from stickslip.measurements import measurements_to_csv
from stickslip.motion.planning import plan_move

runner = CliRunner()


@pytest.fixture()
def files(tmp_path):
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    return tmp_path, meas


def _cal(tmp, meas):
    out = tmp / "cal.json"
    r = runner.invoke(app, ["calibrate", str(meas), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return out


def _bad(result, *words):
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and "Traceback" not in result.stderr
    assert result.stderr.startswith("error: ")
    for w in words:
        assert w in result.stderr, result.stderr


def test_calibrate_json_and_file(files):
    tmp, meas = files
    r = runner.invoke(app, ["calibrate", str(meas), "--json", "-o", str(tmp / "c.json")])
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    a_plus = next(p for p in data["parameters"] if p["joint"] == 3 and p["name"] == "a" and p["direction"] == "+")
    assert a_plus["value"] == pytest.approx(972e-9, rel=1e-4) and a_plus["unit"] == "m"
    assert Calibration.load(tmp / "c.json").parameters() == Calibration.from_dict(data).parameters()


def test_calibrate_table_output_has_units(files):
    tmp, meas = files
    r = runner.invoke(app, ["calibrate", str(meas)])
    assert r.exit_code == 0 and "nm" in r.stdout and "µrad" in r.stdout and "971.9" in r.stdout


def test_predict_adds_gamma_pred(files):
    tmp, meas = files
    cal_path = _cal(tmp, meas)
    poses = tmp / "poses.csv"
    poses.write_text(
        "joint,direction,q1,q2,q3,theta,psi,start,end,label\n"
        "3,+,0,-1.5707963267948966,0,0,0,,,unloaded\n"
        f"2,-,0,0,0,0,0,{math.pi / 6},{-7 * math.pi / 6},full range\n"
    )
    r = runner.invoke(app, ["predict", "-c", str(cal_path), str(poses)])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert rows[0]["label"] == "unloaded"
    cal = calibrate(paper_table())
    assert float(rows[0]["gamma_pred"]) == pytest.approx(cal.gamma(3, "+", Pose()), rel=1e-12)
    full = next(t for t in paper_table() if t.joint == 2 and t.direction == "-" and t.q3 == 0 and t.theta == 0)
    assert float(rows[1]["gamma_pred"]) == pytest.approx(full.gamma, rel=1e-4)
    r = runner.invoke(app, ["predict", "-c", str(cal_path), str(poses), "--json"])
    recs = json.loads(r.stdout)
    assert recs[1]["label"] == "full range" and recs[1]["joint"] == 2 and isinstance(recs[1]["gamma_pred"], float)


def test_plan_json_matches_library(files):
    tmp, meas = files
    cal_path = _cal(tmp, meas)
    r = runner.invoke(app, ["plan", "-c", str(cal_path), "--joint", "2", "--from", "10deg", "--to", "-100deg",
                            "--q3", "6mm", "--theta", "-0.3rad", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    lib = plan_move(Calibration.load(cal_path), 2, math.radians(10), math.radians(-100), Pose(q3=0.006, theta=-0.3))
    assert out["steps"] == lib.steps and isinstance(out["steps"], int)
    assert out["end_predicted"] == pytest.approx(lib.q_end_predicted, abs=1e-15)
    r = runner.invoke(app, ["plan", "-c", str(cal_path), "--joint", "3", "--from", "2mm", "--to", "2.03mm"])
    assert r.exit_code == 0 and "steps in direction +" in r.stdout and "µm" in r.stdout


def test_plan_interval_of_an_older_calibration_adds_a_days_change_as_move_does(files, monkeypatch):
    # move's dead reckoning starts a calibration from another day with a day's change of step scale (15 %,
    # DRIFT_PRIOR); plan gave the same move the calibration's model error alone, 100x narrower (issue: audit31)
    tmp, meas = files
    cal_path = _cal(tmp, meas)  # the pinned day, 2026-11-22
    args = ["plan", "-c", str(cal_path), "--joint", "3", "--from", "2mm", "--to", "4mm", "--json"]
    today = json.loads(runner.invoke(app, args).stdout)
    monkeypatch.setenv("STICKSLIP_TODAY", "2026-11-23")
    r = runner.invoke(app, args)
    later = json.loads(r.stdout)
    assert today["pi95_day_drift"] == 0.0 and later["pi95_day_drift"] == 0.15
    distance = abs(today["end_predicted"] - today["from"])
    sd_today = today["pi95"] / (1.96 * distance)
    assert later["pi95"] == pytest.approx(1.96 * distance * math.hypot(sd_today, 0.15), rel=1e-9)
    assert later["pi95"] > 1.9 * today["pi95"]  # 7.5 % assumed model error: the interval doubles
    r = runner.invoke(app, args[:-1])
    assert "with a day's change of step, 15%: the calibration is from another day" in " ".join(r.stdout.split())


def test_predict_interval_of_an_older_calibration_adds_a_days_change_as_plan_does(files, monkeypatch):
    # plan and move add a day's change of step scale (15 %, DRIFT_PRIOR) to a calibration from another day;
    # predict --interval gave the same pose the calibration's model error alone, 2x narrower (lead, stop 62)
    tmp, meas = files
    cal_path = _cal(tmp, meas)  # the pinned day, 2026-11-22
    poses = tmp / "poses.csv"
    poses.write_text("joint,direction,q1,q2,q3,theta,psi\n3,+,0,-1.0,0.002,0,0\n2,-,0,-0.5,0,0,0.1\n")
    args = ["predict", "-c", str(cal_path), str(poses), "--interval", "--json"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0 and r.stderr == "", r.output
    today = json.loads(r.stdout)
    monkeypatch.setenv("STICKSLIP_TODAY", "2026-11-23")
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    later = json.loads(r.stdout)
    assert "gamma_pi95 includes a day's change of step, 15%: the calibration is from 2026-11-22" in " ".join(
        r.stderr.split())
    for a, b in zip(today, later, strict=True):
        assert b["gamma_pred"] == a["gamma_pred"]
        sd = a["gamma_pi95"] / (1.96 * a["gamma_pred"])
        assert b["gamma_pi95"] == pytest.approx(1.96 * a["gamma_pred"] * math.hypot(sd, 0.15), rel=1e-12)
        assert b["gamma_pi95"] > 1.9 * a["gamma_pi95"]  # 7.5 % assumed model error: the interval doubles
    plain = runner.invoke(app, args[:-2])  # without --interval: the stale calibration's warning only
    assert plain.exit_code == 0 and "1 day old" in plain.stderr and "gamma_pi95" not in plain.stderr


def test_validate(files):
    tmp, meas = files
    cal_path = _cal(tmp, meas)
    r = runner.invoke(app, ["validate", "-c", str(cal_path), str(meas), "--json"])
    rows = json.loads(r.stdout)
    assert {row["joint"] for row in rows} == {2, 3}
    for row in rows:
        assert row["model_max_rel_error"] < 1e-3 < row["constant_max_rel_error"]


def test_show(files):
    tmp, meas = files
    r = runner.invoke(app, ["show", str(_cal(tmp, meas))])
    assert r.exit_code == 0 and "gamma0" in r.stdout and "constant-step comparator" in r.stdout


def test_a_parameter_given_twice_is_refused(files):
    """A hand-edited calibration that gives one parameter twice was read with the last value, silently (audit25:
    a second joint 2+ gamma0 at q3 = 0 of 1e-3 rad made predict answer 0.001 rad); now one line, exit 2."""
    tmp, meas = files
    data = json.loads(_cal(tmp, meas).read_text())
    first = next(p for p in data["parameters"] if p["joint"] == 2 and p["name"] == "gamma0")
    i = data["parameters"].index(first)
    twice = tmp / "twice.json"
    twice.write_text(json.dumps({**data, "parameters": [*data["parameters"], {**first, "value": 1e-3}]}))
    n = len(data["parameters"])
    for cmd in (["show", str(twice)], ["predict", str(meas), "-c", str(twice)]):
        _bad(runner.invoke(app, cmd), f"parameters[{n}] gives joint 2{first['direction']} gamma0 at q3 = "
             f"{first['q3']:g} m again (parameters[{i}] gives it too): keep one")
    const = data["constant_steps"][0]
    twice.write_text(json.dumps({**data, "constant_steps": [*data["constant_steps"], const]}))
    k = len(data["constant_steps"])
    _bad(runner.invoke(app, ["show", str(twice)]),
         f"constant_steps[{k}] gives joint {const['joint']}{const['direction']}'s constant step again")


def test_bad_inputs_give_one_line_reasons(files):
    tmp, meas = files
    bad = tmp / "bad.csv"
    bad.write_text("day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\nd,3,+,0,0,0,0,0,0,0.01,-4\n")
    _bad(runner.invoke(app, ["calibrate", str(bad)]), f"{bad}:2: steps must be a positive integer")
    _bad(runner.invoke(app, ["calibrate", str(tmp / "missing.csv")]), "no such file")
    cal_path = _cal(tmp, meas)
    _bad(runner.invoke(app, ["plan", "-c", str(cal_path), "--joint", "3", "--from", "2mm", "--to", "20mm"]),
         "outside joint 3's range")
    _bad(runner.invoke(app, ["plan", "-c", str(cal_path), "--joint", "3", "--from", "2parsec", "--to", "2mm"]),
         "unknown length unit")
    _bad(runner.invoke(app, ["plan", "-c", str(cal_path), "--joint", "7", "--from", "0", "--to", "1"]), "unknown joint")
    _bad(runner.invoke(app, ["plan", "-c", str(tmp / "nope.json"), "--joint", "3", "--from", "0", "--to", "1mm"]),
         "no such calibration file")
    only_3 = tmp / "only3.csv"
    only_3.write_text(measurements_to_csv([t for t in paper_table() if t.joint == 3]))
    _bad(runner.invoke(app, ["calibrate", str(only_3), "--method", "magic"]), "unknown calibration method")


def test_nonphysical_table_is_refused(files):
    tmp, _ = files
    rows = [t for t in paper_table() if t.joint == 3]
    # make the (0, -pi/2, 0) traverse faster than the unloaded one: b < 0
    rows = [
        t if not (t.q2 == 0 and t.theta != 0) else t.__class__(**{**t.as_row(), "steps": t.steps // 2}) for t in rows
    ]
    p = tmp / "np.csv"
    p.write_text(measurements_to_csv(rows))
    _bad(runner.invoke(app, ["calibrate", str(p)]), "non-physical")


@pytest.mark.slow
@pytest.mark.parametrize("cmd", ["calibrate", "predict", "validate", "plan", "show", "demo", "tune", "listen",
                                 "anova", "fit", "report", "history", "export", "import", "move", "where", "traverse"])
def test_every_command_has_help(cmd):
    r = runner.invoke(app, [cmd, "--help"])
    assert r.exit_code == 0, r.output
    assert "Usage" in r.stdout and len(r.stdout) > 300


def test_top_level_help_lists_commands():
    r = runner.invoke(app, ["--help"])
    for cmd in ("calibrate", "predict", "plan", "demo"):
        assert cmd in r.stdout
    for panel in ("Measure", "Calibrate and predict", "Drive a manipulator", "Keep and study"):
        assert panel in r.stdout
    assert "─ Other ─" not in r.stdout  # every command sits in a workflow panel
    np.testing.assert_equal(r.exit_code, 0)


def test_python_dash_m_runs_the_same_command_line(tmp_path):
    """``python -m stickslip`` (no scripts folder on the PATH): the same commands, exit codes and help."""
    import subprocess
    import sys

    ok = subprocess.run([sys.executable, "-m", "stickslip", "--version"], capture_output=True, text=True, cwd=tmp_path)
    assert ok.returncode == 0 and ok.stdout.startswith("stickslip ")
    bad = subprocess.run([sys.executable, "-m", "stickslip", "where", "--bogus"], capture_output=True, text=True,
                         cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines()[-1].startswith("error:")
    assert "python -m stickslip where --help" in bad.stderr


def test_plan_help_says_a_position_takes_its_unit() -> None:
    """--from/--to once read 'rad / m, or with units' while a bare number (0 excepted) is refused."""
    r = CliRunner().invoke(app, ["plan", "--help"], terminal_width=200)
    assert r.exit_code == 0
    text = " ".join(r.output.split())
    assert "rad / m" not in text and "a bare number other than 0 is refused" in text
    r = CliRunner().invoke(app, ["plan", "-j", "3", "--from", "0.002", "--to", "2.03mm"])
    assert r.exit_code == 2 and "--from: 0.002 has no unit" in r.output


@pytest.mark.parametrize("json_out", [False, True])
def test_predict_for_a_joint_the_calibration_lacks_says_why_and_prints_nothing(files, json_out: bool) -> None:
    """The reason was lost ('error: poses.csv: row 2:' and nothing after it: min() of (row, '') and (row, why)
    took the empty one), and the CSV's header was already on standard output."""
    tmp, meas = files
    cal_path = _cal(tmp, meas)
    poses = tmp / "poses.csv"
    poses.write_text("joint,direction,q1,q2,q3,theta,psi\n3,+,0,0,0,0,0\n1,+,0,0,0,0,0\n")
    args = ["predict", "-c", str(cal_path), str(poses), "--interval", *(["--json"] if json_out else [])]
    r = runner.invoke(app, args)
    _bad(r, f"{poses}: row 2: ", "joint 1")
    assert r.stderr.count("\n") == 1 and r.stdout == ""


def test_a_hand_edited_calibration_whose_step_would_be_negative_is_refused_where_it_is_read(files):
    # calibrate refuses a - |c| <= 0 (the step <= 0 at full axial load), a loaded file was not checked: a hand edit
    # c = 2 um > a dead-reckoned +100 steps as 7.5 um backwards while its plan was refused (audit38's question)
    tmp, meas = files
    data = json.loads(_cal(tmp, meas).read_text())
    params = [dict(p) for p in data["parameters"]]
    a = next(p for p in params if p["joint"] == 3 and p["direction"] == "+" and p["name"] == "a")["value"]
    c = next(p for p in params if p["joint"] == 3 and p["direction"] == "+" and p["name"] == "c")
    c["value"] = 1.5 * a
    bad = tmp / "negative.json"
    bad.write_text(json.dumps({**data, "parameters": params}))
    for cmd in (["show", str(bad)], ["predict", str(meas), "-c", str(bad)],
                ["plan", "-c", str(bad), "--joint", "3", "--from", "0", "--to", "2mm"]):
        _bad(runner.invoke(app, cmd), str(bad), "joint 3+: non-physical calibration refused: a - |c|")
    c["value"] = 0.5 * a  # still physical: read as before
    bad.write_text(json.dumps({**data, "parameters": params}))
    assert runner.invoke(app, ["show", str(bad)]).exit_code == 0


def test_a_parameter_in_another_unit_is_refused(files):
    """A hand-edited calibration labelling a value in another unit was read in SI regardless (joint 2+ gamma0
    labelled 'um' was shown and used as rad: a factor 1e6 silently); now one line naming both units, exit 2."""
    tmp, meas = files
    data = json.loads(_cal(tmp, meas).read_text())
    i = next(k for k, p in enumerate(data["parameters"]) if p["joint"] == 2 and p["name"] == "gamma0")
    j = next(k for k, p in enumerate(data["parameters"]) if p["joint"] == 3 and p["name"] == "a")
    bad = tmp / "unit.json"
    for k, unit, right in ((i, "um", "rad"), (j, "nm", "m")):
        params = [dict(p) for p in data["parameters"]]
        params[k]["unit"] = unit
        bad.write_text(json.dumps({**data, "parameters": params}))
        p = params[k]
        for cmd in (["show", str(bad)], ["predict", str(meas), "-c", str(bad)]):
            _bad(runner.invoke(app, cmd), f"joint {p['joint']}{p['direction']} {p['name']}: unit '{unit}', "
                 f"but the value is read in '{right}'")
    fam = tmp / "fam.json"
    r = runner.invoke(app, ["calibrate", str(meas), "--model", "constant", "-o", str(fam)])
    assert r.exit_code == 0, r.output
    data = json.loads(fam.read_text())
    entry = next(e for e in data["families"] if e["family"] == "constant")
    entry["parameters"][0]["unit"] = "mm"
    bad.write_text(json.dumps(data))
    name = entry["parameters"][0]["name"]
    _bad(runner.invoke(app, ["show", str(bad)]), f"{name}: unit 'mm', but the value is read in")
    del entry["parameters"][0]["unit"]  # no unit: read in SI, as files written by hand
    bad.write_text(json.dumps(data))
    assert runner.invoke(app, ["show", str(bad)]).exit_code == 0
