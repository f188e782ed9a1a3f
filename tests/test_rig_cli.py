"""A rig from the user's side: two arms (an MM3A on the NanoControl console emulator, a SmarAct xyz stack on the
MCS2 emulator), an objective (cylinder) and a sample plane (half-space), driven from the command line, its
history in PostgreSQL."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

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
q3 = "0.1mm"
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


STACK_RIG = """\
name = "two arms"
arm_distance = "1mm"
database = "{db}"

[[arm]]
name = "probe"
controller = "{nano}"
calibration = "cal.json"
mount = {{ origin = ["-30mm", "0mm", "0mm"] }}

[[arm]]
name = "stack"
kind = "xyz"
controller = "{smaract}?hz=20000"  # the driver waits out each burst: 20 kHz keeps the test short
calibration = "stack.json"
tool = ["0mm", "0mm", "-5mm"]
mount = {{ origin = ["-7mm", "6mm", "2mm"] }}

  [[arm.joint]]
  range = ["-10mm", "10mm"]
  step = "50nm"

  [[arm.joint]]
  range = ["-10mm", "10mm"]

  [[arm.joint]]
  range = ["-10mm", "10mm"]

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
point = ["0mm", "0mm", "-12mm"]
normal = [0, 0, -1]
margin = "100um"

[[position]]
name = "park"
arm = "probe"
q2 = "-120deg"
q3 = "0mm"
order = [3, 2]

[[position]]
name = "retract"
arm = "stack"
q2 = "3mm"
q3 = "-2mm"
order = [3, 2]
"""

STACK_STEP = 1e-6  # m: the stack's calibrated constant step, both directions


def _stack_cal(path):
    """The stack's calibration: a constant step per stage and direction (what it is planned with)."""
    steps = {(j, d): STACK_STEP for j in (1, 2, 3) for d in "+-"}
    calibration.Calibration(models={}, stderr={}, constant_steps=steps, day=DAY, method="constant",
                            kinds=dict.fromkeys((1, 2, 3), "prismatic")).save(path)


@pytest.mark.slow
def test_two_arms_from_the_command_line_with_a_postgresql_history(tmp_path, postgres_url):
    """The issue's "Done when": an MM3A on the NanoControl emulator and a SmarAct xyz stack on the MCS2
    emulator, an objective and a sample plane; both arms driven from the CLI, every colliding move refused
    naming the obstacle, named positions reached in their order, the history in a PostgreSQL server."""
    from stickslip.storage import Store

    _cal(tmp_path / "cal.json")
    _stack_cal(tmp_path / "stack.json")
    with NanoControlEmulator() as nano, MCS2Emulator() as smaract:
        rig = tmp_path / "rig.toml"
        rig.write_text(STACK_RIG.format(nano=nano.url, smaract=smaract.url, db=postgres_url), encoding="utf-8")
        common = ("--rig", rig, "--from-unreferenced", "--trust-calibration")  # no --db: the rig file's

        r = run("rig", "check", rig, "-o", tmp_path / "rig.png")
        assert r.exit_code == 0, r.output
        for words in ("2 arm(s), 2 volume(s), 2 named position(s)", "arm 'probe' (mm3a)", "arm 'stack' (xyz)",
                      "volume 'objective': cylinder, margin 200 µm", "position 'park' of 'probe': q3 0.000 mm, "
                      "then q2 -120.00 deg", "no problem found"):
            assert words in r.output
        assert (tmp_path / "rig.png").stat().st_size > 10_000

        # each arm moves from the CLI: the probe's joint 3 out by 1 mm, the stack's y stage to -4 mm (µm shown)
        r = run("move", *common, "--arm", "probe", "--joint", 3, "--by", "1mm", "--json")
        assert r.exit_code == 0, r.output
        assert json.loads(r.stdout)["q_end_predicted"] == pytest.approx(0.001, abs=2e-6)
        r = run("move", *common, "--arm", "stack", "--joint", 2, "--to", "-4mm")
        assert r.exit_code == 0, r.output
        assert "joint 2: 0 µm -> -4000 µm, -4000 steps" in r.output  # 4 mm / 1 µm, no angle anywhere
        assert smaract.steps[1] == -4000  # the MCS2's channel 1 drove the stack's joint 2
        r = run("move", *common, "--arm", "stack", "--joint", 1, "--by", "30deg")
        assert r.exit_code == 2 and "joint 1 takes a length" in r.output, r.output

        # where: every arm, a stage's joints in µm
        r = run("where", "--rig", rig, "--json")
        assert r.exit_code == 0, r.output
        arms = json.loads(r.stdout)["arms"]
        assert [a["arm"] for a in arms] == ["probe", "stack"]
        assert arms[1]["q"] == pytest.approx([0.0, -0.004, 0.0], abs=1e-12) and arms[1]["units"] == ["m"] * 3
        r = run("where", "--rig", rig, "--arm", "stack", "--offline")
        assert r.exit_code == 0 and "-4000 µm" in r.output and "deg" not in r.output.split("tilt")[0], r.output

        # colliding moves are refused, nothing sent: the probe up into the objective, the stack's holder into
        # it and its tip into the sample plane; a straight line of the stack into the objective
        before = dict(smaract.steps)
        r = run("move", *common, "--arm", "probe", "--joint", 2, "--to", "-60deg")
        assert r.exit_code == 2 and "objective" in r.output and "rig frame" in r.output, r.output
        r = run("move", *common, "--arm", "stack", "--joint", 3, "--to", "6mm")
        assert r.exit_code == 2 and "'objective'" in r.output and "Traceback" not in r.output, r.output
        r = run("move", *common, "--arm", "stack", "--joint", 3, "--to", "-10mm")
        assert r.exit_code == 2 and "'sample'" in r.output, r.output
        r = run("reach", *common, "--arm", "stack", "--by", "0,0,6mm")
        assert r.exit_code == 2 and "'objective'" in r.output, r.output
        assert dict(smaract.steps) == before
        # a short straight line of the stack is driven: its tip moves by the line, to within half a step
        r = run("reach", *common, "--arm", "stack", "--by", "0,1mm,-1mm", "--json")
        assert r.exit_code == 0, r.output
        plan = json.loads(r.stdout)
        moved = [e - s for e, s in zip(plan["end"]["tip"], plan["start"]["tip"], strict=True)]
        assert moved == pytest.approx([0.0, 0.001, -0.001], abs=STACK_STEP / 2)
        assert plan["end"]["q"] == pytest.approx([0.0, -0.003, -0.001], abs=STACK_STEP / 2)
        # the same tip in the rig frame: the mount's origin (-7, 6, 2) mm added, the tool 5 mm below the holder
        assert plan["arm"] == "stack" and plan["rig_frame"]["end"] == pytest.approx([-0.007, 0.003, -0.004], abs=1e-6)

        # the named positions: joint 3 first, then joint 2, for each arm
        for arm, name in (("probe", "park"), ("stack", "retract")):
            r = run("rig", "go", name, "--rig", rig, "--arm", arm, "--from-unreferenced", "--trust-calibration")
            assert r.exit_code == 0, r.output
            lines = [ln for ln in r.output.splitlines() if "joint" in ln]
            assert "joint 3" in lines[0] and "joint 2" in lines[1], r.output
        r = run("where", "--rig", rig, "--json")
        probe, stack = json.loads(r.stdout)["arms"]
        assert probe["q"][1] == pytest.approx(-2 * math.pi / 3, abs=1e-4)
        assert 0.0 <= probe["q"][2] <= 0.5e-6  # within half a step of the lower stop, never past it
        assert stack["q"] == pytest.approx([0.0, 0.003, -0.002], abs=STACK_STEP / 2)
        r = run("move", *common, "--arm", "probe", "--joint", 3, "--by", "0.5mm", "--json")  # from the stop
        assert r.exit_code == 0, r.output
        assert json.loads(r.stdout)["q_from"] == probe["q"][2]

    # the history is in the PostgreSQL database the rig file names, none in $STICKSLIP_DB's file
    assert not Path(os.environ["STICKSLIP_DB"]).exists()
    with Store.open(postgres_url) as st:
        kept = {a: st.get_state(a, "positions") for a in (arms[0]["device"], arms[1]["device"])}
    assert all(kept.values())


def test_rig_options_are_checked(tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG.format(nano="sim://", smaract="sim://?seed=2"), encoding="utf-8")
    # one line as written, not a KeyError's repr in double quotes ('error: "rig.toml: no arm named ..."')
    line = f"error: {rig}: no arm named 'nobody' (the arms: probe, gripper)"
    for cmd in (["move", "--joint", 3, "--by", "1mm", "-c", tmp_path / "x.json"], ["where"], ["rig", "go", "park"],
                ["reach", "--by", "0,0,1um", "-c", tmp_path / "x.json"]):
        r = run(*cmd, "--rig", rig, "--arm", "nobody")
        assert r.exit_code == 2 and r.stderr.strip() == line, (cmd, r.stderr)
    r = run("move", "--rig", rig, "-d", "sim://", "--joint", 3, "--by", "1mm")
    assert r.exit_code == 2 and "not both" in r.output
    r = run("move", "--arm", "probe", "--joint", 3, "--by", "1mm")
    assert r.exit_code == 2 and "--rig" in r.output
    bad = tmp_path / "bad.toml"
    bad.write_text(RIG.format(nano="sim://", smaract="sim://?seed=2").replace('radius = "3mm"', 'radius = "3kg"'))
    r = run("rig", "check", bad)
    assert r.exit_code == 2 and f"{bad}:" in r.output and "radius" in r.output


def test_two_arms_on_one_controllers_channels_are_refused(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(RIG.format(nano="sim://", smaract="sim://"), encoding="utf-8")
    r = run("rig", "check", bad)
    assert r.exit_code == 2 and "arm 'probe' drives channel 1 of this controller (sim://) already" in r.output, r.output


TWO_ON_ONE = """\
arm_distance = "0.5mm"
{arms}
"""
STAGE = """
[[arm]]
name = "{name}"
kind = "xyz"
controller = "{url}"
calibration = "stack.json"
mount = {{ origin = ["{x}", "0mm", "0mm"] }}
{joints}
"""


def test_two_arms_on_one_controller_keep_their_own_positions(tmp_path):
    """Two stacks on one MCS2 (channels 0-2 and 3-5): one lock (the controller's), positions kept per arm."""
    _stack_cal(tmp_path / "stack.json")
    joints = "".join(f'\n  [[arm.joint]]\n  channel = {c}\n  range = ["-5mm", "5mm"]\n' for c in (1, 2, 3))
    with MCS2Emulator() as emu:
        arms = [STAGE.format(name="left", url=f"{emu.url}?channels=0,1,2&hz=20000", x="-20mm", joints=joints),
                STAGE.format(name="right", url=f"{emu.url}?channels=3,4,5&hz=20000", x="20mm", joints=joints)]
        rig = tmp_path / "rig.toml"
        rig.write_text(TWO_ON_ONE.format(arms="".join(arms)), encoding="utf-8")
        common = ("--rig", rig, "--db", tmp_path / "s.db", "--from-unreferenced", "--trust-calibration")
        for arm, by in (("left", "100um"), ("right", "-30um")):
            r = run("move", *common, "--arm", arm, "--joint", 1, "--by", by, "--json")
            assert r.exit_code == 0, r.output
            assert json.loads(r.stdout)["device"] == f"{emu.url}#arm={arm}"
        assert emu.steps[0] == 100 and emu.steps[3] == -30  # 1 µm steps, each arm on its own channels
        _cal(tmp_path / "mm3a.json")  # an MM3A's calibration given to a stage: refused, nothing sent
        r = run("move", *common, "--arm", "left", "-c", tmp_path / "mm3a.json", "--joint", 3, "--by", "10um")
        assert r.exit_code == 2 and "models joint 3 as an MM3A's" in r.output and "Traceback" not in r.output
        assert emu.steps[2] == 0
        r = run("where", "--rig", rig, "--db", tmp_path / "s.db", "--json")
        left, right = json.loads(r.stdout)["arms"]
        assert left["q"] == pytest.approx([1e-4, 0.0, 0.0], abs=1e-12)
        assert right["q"] == pytest.approx([-3e-5, 0.0, 0.0], abs=1e-12)
        # the controller's one lock: held for one arm, the other waits its turn (refused, naming the holder)
        from stickslip.storage import Store

        with Store.open(tmp_path / "s.db") as st:
            assert st.acquire_lock(emu.url, {"pid": 1, "host": "elsewhere", "since": "then"}) is None
        r = run("move", *common, "--arm", "right", "--joint", 2, "--by", "10um")
        assert r.exit_code == 2 and "being driven by another stickslip process (pid 1 on elsewhere" in r.output


def test_rig_check_draws_a_png_where_it_says_or_refuses(tmp_path):
    """-o rig wrote rig.png but said 'drawn: rig'; -o FOLDER wrote FOLDER.png; -o /dev/full wrote /dev/full.png
    (as root); -o x.jpg a JPEG though --help says PNG. Now -o must name a .png file; it is written whole or not
    at all (atomic_write), and the earlier drawing is kept when the new one cannot be written."""
    rig = tmp_path / "rig.toml"
    rig.write_text("[[arm]]\nname = 'a'\ncontroller = 'sim://'\n", encoding="utf-8")
    folder = tmp_path / "pics"
    folder.mkdir()
    for out, words in ((tmp_path / "rig", "name it .png"), (tmp_path / "rig.jpg", "name it .png"),
                       (folder, "name it .png"), (tmp_path / "pics.png" / "x.png", "x.png")):
        r = run("rig", "check", rig, "-o", out)
        assert r.exit_code == 2, (out, r.output)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error:") and words in lines[0], (out, r.stderr)
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(("rig.", "pics.", ".rig"))
                and p.name != "rig.toml"] and not any(folder.iterdir())
    png = tmp_path / "R.PNG"
    r = run("rig", "check", rig, "-o", png)
    assert r.exit_code == 0 and f"drawn: {png}" in " ".join(r.stdout.split()), r.output  # lines wrap
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


WALL = """\
[[arm]]
name = "a"
controller = "sim://"
calibration = "cal.json"

[[volume]]
name = "wall"
shape = "half-space"
point = ["21.5mm", "0mm", "0mm"]
normal = [1, 0, 0]
"""


def test_an_uncertain_joint_is_checked_where_it_may_be_not_where_it_was_last(tmp_path):
    """Raw steps leave joint 3 uncertain (0 to 12 mm); --from-unreferenced plans from its last value, 0. The
    envelope took it as there with no σ, and a move of 100 µm toward a wall 500 µm beyond the tip was accepted
    though the tip may be 11.5 mm past the wall; now the farthest it may be is one σ of the margin."""
    _cal(tmp_path / "cal.json")
    rig = tmp_path / "rig.toml"
    rig.write_text(WALL, encoding="utf-8")
    db = tmp_path / "s.db"
    r = run("move", "-d", "sim://", "--db", db, "--joint", 3, "--steps", 2000)
    assert r.exit_code == 0 and "uncertain" in r.output, r.output
    r = run("move", "--rig", rig, "--db", db, "--joint", 3, "--by", "100um", "--from-unreferenced",
            "--trust-calibration")
    assert r.exit_code == 2 and "starts within the margin of 'wall'" in r.output, r.output
    assert "36000.00 µm kept (36000.00 µm of it the position's σ)" in r.output  # 3 σ of 12 mm
    # referenced, the same move is clear (the wall 500 µm away, the σ of 101 steps a few µm)
    r = run("where", "-d", "sim://", "--db", db, "--set", "3=min")
    assert r.exit_code == 0, r.output
    r = run("move", "--rig", rig, "--db", db, "--joint", 3, "--by", "100um", "--trust-calibration")
    assert r.exit_code == 0, r.output


def test_move_and_where_in_a_rig_take_the_pose_and_the_references_they_are_given(tmp_path):
    """With --rig, move dropped --q1 ... --psi and --max-age unsaid (planned from the kept pose, not the one given),
    and where without --arm dropped --set: it listed the arms and exited 0, the joint not referenced."""
    _cal(tmp_path / "cal.json")
    rig = tmp_path / "rig.toml"
    rig.write_text(WALL.replace('"21.5mm"', '"40mm"'), encoding="utf-8")
    db = tmp_path / "s.db"
    r = run("move", "--rig", rig, "--db", db, "--joint", 3, "--by", "10um", "--q2", "-80deg", "--q3", "2mm",
            "--from-unreferenced", "--trust-calibration", "--max-age", 36500, "--json")
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["q_from"] == pytest.approx(2e-3) and out["q_end_predicted"] == pytest.approx(2.01e-3, abs=0.5e-6)
    assert "days old" not in r.output  # --max-age taken (the calibration is of DAY)
    r = run("where", "--rig", rig, "--db", db, "--json")
    q = json.loads(r.stdout)["arms"][0]["q"]
    assert q[1] == pytest.approx(math.radians(-80)) and q[2] == pytest.approx(2.01e-3, abs=0.5e-6)
    r = run("where", "--rig", rig, "--db", db, "--set", "3=min", "--offline", "--json")  # one arm: that arm
    assert r.exit_code == 0 and json.loads(r.stdout)["joints"][2]["q"] == 0.0, r.output
    two = tmp_path / "two.toml"
    two.write_text(WALL + WALL.replace('"a"', '"b"').replace('"sim://"', '"sim://?seed=2"').split("[[volume]]")[0],
                   encoding="utf-8")
    r = run("where", "--rig", two, "--db", db, "--set", "3=min")
    assert r.exit_code == 2 and "give --arm NAME (the rig's arms: a, b)" in r.output, r.output


def test_another_controller_under_two_arms_sharing_it_leaves_both_arms_uncertain(tmp_path):
    """A swap found at one arm's move on a shared controller (two stacks on one MCS2: another MCS2 now answers at its
    address) leaves the other arm's positions uncertain too: they were kept for the same controller, and this arm's
    envelope is checked against them. Before, only the moving arm's were; the other's kept pose, another
    controller's arm's, stayed 'dead-reckoned' for the envelope until that arm moved itself."""
    from stickslip.devices.identity import SWAPPED
    from stickslip.devices.positions import load_state
    from stickslip.rig import load_rig
    from stickslip.storage import Store

    _stack_cal(tmp_path / "stack.json")
    joints = "".join(f'\n  [[arm.joint]]\n  channel = {c}\n  range = ["-5mm", "5mm"]\n' for c in (1, 2, 3))
    with MCS2Emulator() as emu:
        arms = [STAGE.format(name="left", url=f"{emu.url}?channels=0,1,2&hz=20000", x="-20mm", joints=joints),
                STAGE.format(name="right", url=f"{emu.url}?channels=3,4,5&hz=20000", x="20mm", joints=joints)]
        rig = tmp_path / "rig.toml"
        rig.write_text(TWO_ON_ONE.format(arms="".join(arms)), encoding="utf-8")
        common = ("--rig", rig, "--db", tmp_path / "s.db", "--from-unreferenced", "--trust-calibration")
        for name, by in (("left", "100um"), ("right", "-30um")):
            assert run("move", *common, "--arm", name, "--joint", 1, "--by", by).exit_code == 0
        emu.serial_number = "MCS2-00009999"  # another MCS2 answers at the address now
        r = run("move", *common, "--arm", "left", "--joint", 1, "--by", "10um")
        line = " ".join(r.output.split())
        assert r.exit_code == 2 and "another controller answers at" in line, r.output
        assert f"every joint of {emu.url}#arm=left and of {emu.url}#arm=right is now uncertain" in line, line
        assert emu.steps[0] == 100 and emu.steps[3] == -30  # nothing sent
        model = load_rig(rig)
        with Store.open(tmp_path / "s.db") as store:
            for name in ("left", "right"):
                st = load_state(store, model.state_key(name), model.arm(name).joint_specs())
                assert set(st.uncertain) == {1, 2, 3} and set(st.why.values()) == {SWAPPED}, name
                assert st.uncertain[1] == (-5e-3, 5e-3)
                assert not st.claim  # the move's claim, held when the swap was found, taken back
