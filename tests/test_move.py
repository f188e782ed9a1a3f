"""`stickslip move` / `stickslip where`: planned steps sent in bursts, positions kept per device.

Reference values: stickslip.motion.planning.plan_move / dead_reckon for the same calibration
and pose (what `stickslip plan` prints); the calibration here is the simulator's own
true model, so on sim:// the true end must match the planned end within the per-step
noise (3 % per step, independent: ~3 %/sqrt(N) over N steps) and the ripple (0.4 %).
"""

from __future__ import annotations

import json
import math
import os
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.cli import app
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.emulators import NanoControlEmulator

planning = pytest.importorskip("stickslip.motion.planning")
calibration = pytest.importorskip("stickslip.calibration")

runner = CliRunner()
DAY = "2026-11-22"


@pytest.fixture()
def cal_path(tmp_path):
    """A calibration holding the true models of sim://?seed=4&day=DAY (exact by construction)."""
    sim = SimulatedMM3A(seed=4, day=DAY)
    models = sim.true_models()
    cal = calibration.Calibration(
        models=models,
        stderr=dict.fromkeys(models),
        constant_steps={
            k: float(m.average_gamma(*_full(k[0], k[1]), *kin.Pose())) for k, m in models.items()
        },
        day=DAY,
        method="paper",
    )
    path = tmp_path / "cal.json"
    cal.save(path)
    return path


def _full(joint, direction):
    spec = kin.JOINTS[joint]
    return (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def where_json(db, device):
    r = run("where", "--device", device, "--db", db, "--json", "--offline")
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def test_where_defaults_and_set(tmp_path):
    db = tmp_path / "s.db"
    w = where_json(db, "sim://")
    assert [j["source"] for j in w["joints"]] == ["default"] * 3
    assert w["joints"][1]["q"] == pytest.approx(-math.pi / 2)
    r = run(
        "where",
        "--db",
        db,
        "--set",
        "3=max",
        "--set",
        "2=min",
        "--set",
        "1=-30deg",
        "--theta",
        "-45deg",
    )
    assert r.exit_code == 0, r.output
    w = where_json(db, "sim://")
    assert [j["q"] for j in w["joints"]] == pytest.approx(
        [-math.pi / 6, -7 * math.pi / 6, kin.Q3_MAX]
    )
    assert [j["source"] for j in w["joints"]] == ["set"] * 3
    assert w["theta"] == pytest.approx(-math.pi / 4)
    # another device keeps its own positions; query options do not make a new device
    assert where_json(db, "mm3a:///dev/ttyX")["joints"][2]["source"] == "default"
    run("where", "--db", db, "-d", "mm3a:///dev/ttyX?timeout=5", "--set", "3=1mm")
    w = where_json(db, "mm3a:///dev/ttyX")
    assert w["joints"][2]["q"] == pytest.approx(1e-3)
    assert w["device"] == "mm3a:///dev/ttyX"
    assert where_json(db, "anc300://10.0.0.2:7230?password=pw")["device"] == "anc300://10.0.0.2:7230"


@pytest.mark.parametrize(
    "bad, msg",
    [
        ("3=20mm", "outside joint 3's range"),
        ("4=0", "JOINT=VALUE"),
        ("3=5deg", "takes a length"),
        ("x", "JOINT=VALUE"),
    ],
)
def test_where_set_rejects_bad_values(tmp_path, bad, msg):
    r = run("where", "--db", tmp_path / "s.db", "--set", bad)
    assert r.exit_code == 2
    assert msg in r.output


def test_move_on_sim_sends_the_planned_steps_and_keeps_the_position(tmp_path, cal_path):
    db = tmp_path / "s.db"
    dev = f"sim://?seed=4&day={DAY}"
    cal = calibration.Calibration.load(cal_path)
    r = run(
        "move",
        "-d",
        dev,
        "-c",
        cal_path,
        "--db",
        db,
        "--joint",
        3,
        "--by",
        "30um",
        "--burst",
        10,
        "--json",
    )
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    plan = planning.plan_move(cal, 3, 0.0, 30e-6, kin.Pose())
    assert out["steps"] == plan.steps and out["direction"] == "+"
    assert sum(out["bursts"]) == plan.steps and max(out["bursts"]) <= 10
    assert out["q_end_predicted"] == pytest.approx(plan.q_end_predicted, abs=1e-15)
    # true end of the simulated arm vs the plan: per-step noise + ripple
    assert out["sim_true_end"] == pytest.approx(30e-6, rel=0.03)
    w = where_json(db, dev)
    assert w["joints"][2]["q"] == pytest.approx(plan.q_end_predicted, abs=1e-15)
    assert w["joints"][2]["source"] == "dead-reckoned"
    # a second move continues from there
    r = run("move", "-d", dev, "-c", cal_path, "--db", db, "--joint", 3, "--by", "-10um", "--json")
    out2 = json.loads(r.stdout)
    assert out2["q_from"] == pytest.approx(plan.q_end_predicted)
    assert out2["direction"] == "-"
    plan2 = planning.plan_move(
        cal, 3, plan.q_end_predicted, plan.q_end_predicted - 10e-6, kin.Pose()
    )
    assert out2["steps"] == plan2.steps


def test_rotary_move_in_a_recorded_pose_matches_the_plan(tmp_path, cal_path):
    db = tmp_path / "s.db"
    cal = calibration.Calibration.load(cal_path)
    r = run(
        "move", "-c", cal_path, "--db", db, "--joint", 2, "--to", "-60deg",
        "--q3", "6mm", "--theta", "-30deg", "--json",
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    pose = kin.Pose(0.0, -math.pi / 2, 6e-3, -math.pi / 6, 0.0)
    plan = planning.plan_move(cal, 2, -math.pi / 2, math.radians(-60), pose)
    assert out["steps"] == plan.steps and out["direction"] == "+"
    w = where_json(db, "sim://")
    assert w["joints"][1]["q"] == pytest.approx(plan.q_end_predicted, abs=1e-12)
    assert w["joints"][2] == {**w["joints"][2], "q": pytest.approx(6e-3), "source": "set"}
    assert w["theta"] == pytest.approx(-math.pi / 6)


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--joint", 3, "--by", "20mm"], "outside joint 3's range"),
        (["--joint", 3, "--by", "1um", "--to", "2um"], "exactly one of --by, --to and --steps"),
        (["--joint", 3], "exactly one of --by, --to and --steps"),
        (["--joint", 3, "--by", "30"], "30 has no unit: did you mean 30um?"),
        (["--joint", 2, "--by", "1"], "1 has no unit: did you mean 1deg?"),
        (["--joint", 2, "--by", "3um"], "takes an angle"),
        (["--joint", 3, "--by", "3um", "--q2", "40deg"], "outside joint 2's range"),
    ],
)
def test_move_rejects_bad_input(tmp_path, cal_path, args, msg):
    r = run("move", "-c", cal_path, "--db", tmp_path / "s.db", *args)
    assert r.exit_code == 2, r.output
    assert msg in r.output


def test_move_missing_calibration_is_a_clean_error(tmp_path):
    r = run(
        "move", "-c", tmp_path / "nope.json", "--db", tmp_path / "s.db", "--joint", 3, "--by", "1um"
    )
    assert r.exit_code == 2 and "nope.json" in r.output


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")
def test_move_over_the_emulated_nanocontrol(tmp_path, cal_path):
    """The issue's check: only well-formed commands, step counts adding up to the plan."""
    db = tmp_path / "s.db"
    cal = calibration.Calibration.load(cal_path)
    with NanoControlEmulator() as emu:
        url = emu.url
        r = run("where", "-d", url, "--db", db, "--set", "3=min", "--q2", "-90deg")
        assert r.exit_code == 0, r.output
        r = run("move", "-d", url, "-c", cal_path, "--db", db, "--joint", 3, "--by", "0.5mm",
                "--burst", 100, "--json", "--trust-calibration")  # fmt: skip
        assert r.exit_code == 0, r.output
        r2 = run(
            "move", "-d", url, "-c", cal_path, "--db", db, "--joint", 2, "--by", "-5deg", "--json",
            "--trust-calibration",
        )
        assert r2.exit_code == 0, r2.output
        sent = list(emu.received)
    out, out2 = json.loads(r.stdout), json.loads(r2.stdout)
    pat = re.compile(r"^(version|coarse [ABC] [+-][1-9]\d*)$")
    assert all(pat.match(m) for m in sent), sent
    c = [int(m.split()[2]) for m in sent if m.startswith("coarse C")]
    b = [int(m.split()[2]) for m in sent if m.startswith("coarse B")]
    plan = planning.plan_move(cal, 3, 0.0, 0.5e-3, kin.Pose())
    assert sum(c) == plan.steps == out["steps"] and max(map(abs, c)) <= 100
    pose2 = kin.Pose(0.0, -math.pi / 2, plan.q_end_predicted, 0.0, 0.0)
    plan2 = planning.plan_move(cal, 2, -math.pi / 2, -math.pi / 2 - math.radians(5), pose2)
    assert -sum(b) == plan2.steps == out2["steps"]
    w = where_json(db, url)
    assert [w["joints"][1]["q"], w["joints"][2]["q"]] == pytest.approx(
        [plan2.q_end_predicted, plan.q_end_predicted], abs=1e-12
    )


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")
def test_device_failing_mid_move_keeps_the_dead_reckoned_position(tmp_path, cal_path):
    db = tmp_path / "s.db"
    cal = calibration.Calibration.load(cal_path)
    with NanoControlEmulator() as emu:
        emu.inject("silent", after=3)
        r = run("move", "-d", emu.url + "?timeout=0.2", "-c", cal_path, "--db", db, "--joint", 3,
                "--by", "100um", "--burst", 10, "--trust-calibration", "--from-unreferenced")  # fmt: skip
        url = emu.url
    assert r.exit_code == 2
    assert "did not answer" in r.output and "; 30 of" in r.output
    assert "steps confirmed (the burst under way may have moved" in r.output
    w = where_json(db, url)
    expected = planning.dead_reckon(cal, 3, 0.0, 30, kin.Pose())
    assert w["joints"][2]["q"] == pytest.approx(float(np.asarray(expected)), abs=1e-15)


def test_help_texts():
    for cmd in ("move", "where"):
        r = run(cmd, "--help")
        assert r.exit_code == 0 and "Example" in r.output


def test_move_over_the_emulated_anc300(tmp_path, cal_path):
    pytest.importorskip("pymeasure")
    from stickslip.sim.emulators import ANC300Emulator

    db = tmp_path / "s.db"
    cal = calibration.Calibration.load(cal_path)
    with ANC300Emulator() as emu:
        url = emu.url + "&delay=0.002"
        r = run("move", "-d", url, "-c", cal_path, "--db", db, "--joint", 3, "--by", "40um",
                "--burst", 20, "--json", "--trust-calibration", "--from-unreferenced")  # fmt: skip
        assert r.exit_code == 0, r.output
        sent = list(emu.received)
        assert emu.continuous_moves == 0
    plan = planning.plan_move(cal, 3, 0.0, 40e-6, kin.Pose())
    ups = [int(m.split()[2]) for m in sent if m.startswith("stepu 3 ")]
    assert sum(ups) == plan.steps == json.loads(r.stdout)["steps"] and max(ups) <= 20
    assert not any(m.startswith("stepd") for m in sent)
    # the password is not kept with the positions
    w = where_json(db, url)
    assert "password" not in w["device"]
    assert w["joints"][2]["q"] == pytest.approx(plan.q_end_predicted, abs=1e-15)


def test_a_move_to_the_lower_stop_ends_at_the_stop_and_the_next_move_runs(tmp_path, cal_path):
    """Whole steps may overshoot a target by half a step; at an end stop the kept end is the stop.

    Before, the predicted end (-0.33 µm) was kept as the position, refused as outside the
    range after the last burst: the move failed and left joint 3 uncertain.
    """
    db = tmp_path / "s.db"
    dev = f"sim://?seed=4&day={DAY}"
    cal = calibration.Calibration.load(cal_path)
    # a start from which the nearest whole number of steps lands below the stop
    starts = [q for q in np.linspace(1.0e-3, 1.2e-3, 41)
              if planning.Planner(cal, 3, kin.Pose(q3=q)).plan(q, 0.0).q_end_predicted < -0.05e-6]
    assert starts
    start = float(starts[0])
    assert run("where", "-d", dev, "--db", db, "--set", f"3={start * 1e6!r}um").exit_code == 0
    r = run("move", "-d", dev, "-c", cal_path, "--db", db, "--joint", 3, "--to", "min", "--json")
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    raw = planning.Planner(cal, 3, kin.Pose(q3=start)).plan(start, 0.0)
    assert out["steps_signed"] == raw.signed_steps and out["q_end_predicted"] == 0.0
    w = where_json(db, dev)["joints"][2]
    assert w["q"] == 0.0 and w["source"] == "dead-reckoned"
    r = run("move", "-d", dev, "-c", cal_path, "--db", db, "--joint", 3, "--by", "0.5mm", "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["q_from"] == 0.0


def test_within_stops_holds_a_position_at_the_stops():
    from stickslip.procedures.move import within_stops

    spec = kin.JOINTS[3]
    assert within_stops(3, -3.3e-7) == spec.lower and within_stops(3, spec.upper + 1e-7) == spec.upper
    assert within_stops(3, 1e-3) == 1e-3
