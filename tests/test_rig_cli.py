"""A rig from the user's side: two arms (an MM3A on the NanoControl console emulator, a SmarAct MCS2 on its
emulator), an objective (cylinder) and a sample plane (half-space), driven from the command line."""

from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.cli import app
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.emulators import NanoControlEmulator
from stickslip.sim.smaract_emulator import MCS2Emulator

calibration = pytest.importorskip("stickslip.calibration")
runner = CliRunner()
DAY = "2026-11-22"

RIG = """\
name = "two arms"
arm_distance = "1mm"

[[arm]]
name = "probe"
controller = "{nano}"
calibration = "cal.json"
mount = {{ origin = ["-30mm", "0mm", "0mm"] }}

[[arm]]
name = "gripper"
controller = "{smaract}"
calibration = "cal.json"
mount = {{ origin = ["30mm", "0mm", "0mm"], rotation = ["0deg", "0deg", "180deg"] }}

[[volume]]
name = "objective"
shape = "cylinder"
base = ["-7mm", "0mm", "6mm"]
axis = [0, 0, 1]
radius = "3mm"
height = "20mm"
margin = "200um"

[[volume]]
name = "sample"
shape = "half-space"
point = ["0mm", "0mm", "-15mm"]
normal = [0, 0, -1]
margin = "100um"

[[position]]
name = "park"
arm = "probe"
q2 = "-120deg"
q3 = "0mm"
order = [3, 2]
"""


def _cal(path):
    sim = SimulatedMM3A(seed=0, day=DAY)
    models = sim.true_models()

    def full(joint, direction):
        spec = kin.JOINTS[joint]
        return (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)

    cal = calibration.Calibration(
        models=models, stderr=dict.fromkeys(models),
        constant_steps={k: float(m.average_gamma(*full(k[0], k[1]), *kin.Pose())) for k, m in models.items()},
        day=DAY, method="paper",
    )
    cal.save(path)


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.mark.slow
def test_two_arms_from_the_command_line(tmp_path):
    _cal(tmp_path / "cal.json")
    db = tmp_path / "s.db"
    with NanoControlEmulator() as nano, MCS2Emulator() as smaract:
        rig = tmp_path / "rig.toml"
        rig.write_text(RIG.format(nano=nano.url, smaract=smaract.url), encoding="utf-8")
        common = ("--rig", rig, "--db", db, "--from-unreferenced", "--trust-calibration")

        r = run("rig", "check", rig, "-o", tmp_path / "rig.png")
        assert r.exit_code == 0, r.output
        for words in ("2 arm(s), 2 volume(s), 1 named position(s)", "arm 'probe' (mm3a)", "arm 'gripper'",
                      "volume 'objective': cylinder, margin 200 µm", "position 'park' of 'probe': q3 0.000 mm, "
                      "then q2 -120.00 deg", "no problem found"):
            assert words in r.output
        assert (tmp_path / "rig.png").stat().st_size > 10_000

        # each arm moves from the CLI: joint 3 out by 1 mm
        for arm in ("probe", "gripper"):
            r = run("move", *common, "--arm", arm, "--joint", 3, "--by", "1mm", "--json")
            assert r.exit_code == 0, r.output
            out = json.loads(r.stdout)
            assert out["arm"] == arm and out["q_end_predicted"] == pytest.approx(0.001, abs=2e-6)
        assert smaract.steps[2] > 0  # the MCS2's channel 2 drove the gripper's joint 3
        r = run("where", "--rig", rig, "--db", db, "--json")
        assert r.exit_code == 0, r.output
        arms = json.loads(r.stdout)["arms"]
        assert [a["arm"] for a in arms] == ["probe", "gripper"]
        assert [a["q"][2] for a in arms] == pytest.approx([0.001, 0.001], abs=2e-6)

        # a colliding move is refused, nothing sent: the probe's tip (at x = -8 mm) up into the objective
        before = dict(nano.steps) if hasattr(nano, "steps") else None
        r = run("move", *common, "--arm", "probe", "--joint", 2, "--to", "-60deg")
        assert r.exit_code == 2, r.output
        assert "objective" in r.output and "rig frame" in r.output and "Traceback" not in r.output
        if before is not None:
            assert dict(nano.steps) == before
        # into the sample plane
        r = run("move", *common, "--arm", "gripper", "--joint", 2, "--to", "-160deg")
        assert r.exit_code == 2 and "sample" in r.output, r.output

        # a straight tip line up into the objective is refused; a short one is driven
        r = run("reach", *common, "--arm", "probe", "--by", "0,0,8mm")
        assert r.exit_code == 2 and "objective" in r.output, r.output
        r = run("reach", *common, "--arm", "probe", "--by", "0,0,1mm", "--segment", "100um", "--json")
        assert r.exit_code == 0, r.output
        plan = json.loads(r.stdout)
        assert plan["end"]["tip"][2] - plan["start"]["tip"][2] == pytest.approx(0.001, abs=2e-6)

        # the named position: joint 3 retracted first, then joint 2
        r = run("rig", "go", "park", "--rig", rig, "--db", db, "--from-unreferenced", "--trust-calibration")
        assert r.exit_code == 0, r.output
        lines = [ln for ln in r.output.splitlines() if "joint" in ln]
        assert "joint 3" in lines[0] and "joint 2" in lines[1], r.output
        r = run("where", "--rig", rig, "--db", db, "--json")
        probe = json.loads(r.stdout)["arms"][0]
        assert probe["q"][1] == pytest.approx(-2 * math.pi / 3, abs=1e-4)
        assert 0.0 <= probe["q"][2] <= 0.5e-6  # within half a step of the stop, never past it
        r = run("move", *common, "--arm", "probe", "--joint", 3, "--by", "0.5mm", "--json")
        assert r.exit_code == 0, r.output
        assert json.loads(r.stdout)["q_from"] == probe["q"][2]


def test_rig_options_are_checked(tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG.format(nano="sim://", smaract="sim://?seed=2"), encoding="utf-8")
    r = run("move", "--rig", rig, "--arm", "nobody", "--joint", 3, "--by", "1mm", "-c", tmp_path / "x.json")
    assert r.exit_code == 2 and "no arm named 'nobody'" in r.output
    r = run("move", "--rig", rig, "-d", "sim://", "--joint", 3, "--by", "1mm")
    assert r.exit_code == 2 and "not both" in r.output
    r = run("move", "--arm", "probe", "--joint", 3, "--by", "1mm")
    assert r.exit_code == 2 and "--rig" in r.output
    bad = tmp_path / "bad.toml"
    bad.write_text(RIG.format(nano="sim://", smaract="sim://?seed=2").replace('radius = "3mm"', 'radius = "3kg"'))
    r = run("rig", "check", bad)
    assert r.exit_code == 2 and f"{bad}:" in r.output and "radius" in r.output


def test_two_arms_on_one_controller_are_refused(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(RIG.format(nano="sim://", smaract="sim://"), encoding="utf-8")
    r = run("rig", "check", bad)
    assert r.exit_code == 2 and "arm 'probe' is on this controller already" in r.output
