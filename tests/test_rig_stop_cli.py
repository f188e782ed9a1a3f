"""`stickslip rig stop`: the rig's STOP pressed from a terminal ends every arm's motion before its next burst."""

from __future__ import annotations

from pathlib import Path

from server_support import RIG
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.procedures import rigstop
from stickslip.rig import load_rig
from stickslip.storage import Store

runner = CliRunner()


def test_a_terminal_presses_the_rigs_stop_that_every_arm_reads(tmp_path: Path) -> None:
    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", "30mm"), encoding="utf-8")
    rig, db = load_rig(path), tmp_path / "rig.db"
    with Store.open(db) as store:
        watches = {arm.name: rigstop.RigStopWatch(rig, arm.name) for arm in rig.arms}
        for w in watches.values():
            w.begin(store)  # two motions under way
    r = runner.invoke(app, ["rig", "stop", "--rig", str(path), "--db", str(db)])
    assert r.exit_code == 0, r.output
    assert f"rig {rig.name!r}: STOP pressed (press 1)" in " ".join(r.stdout.split())
    with Store.open(db) as store:
        for w in watches.values():  # no arm of the rig pressed it: every one stops, told where it was pressed
            why = w.stopped(store)
            assert why is not None and "stopped by the rig's STOP (pressed from a terminal at " in why, why
            assert w.stopped(store) is None  # said once per press
        assert rigstop.pressed(store, rig)["count"] == 1 and rigstop.pressed(store, rig)["arm"] is None
    r = runner.invoke(app, ["rig", "stop", "--rig", str(tmp_path / "nope.toml"), "--db", str(db)])
    assert r.exit_code == 2 and r.stderr.count("error:") == 1  # a rig file that is not there: one line
