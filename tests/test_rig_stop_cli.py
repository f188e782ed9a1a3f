"""`stickslip rig stop`: the rig's STOP pressed from a terminal ends every arm's motion before its next burst."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
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


class _Stale:
    """A store whose reads of the rig's STOP give what it held before (a press that read the count just before
    another press wrote it: two presses at once)."""

    def __init__(self, inner: Store, held: object) -> None:
        self.inner, self.held = inner, held

    def get_state(self, device: str, key: str, default: object = None) -> object:
        return self.held

    def set_state(self, device: str, key: str, value_json: object) -> None:
        self.inner.set_state(device, key, value_json)


def test_two_presses_at_once_both_stop_a_motion_begun_between_them(tmp_path: Path) -> None:
    # the arm 'other' presses; a motion of 'probe' begins; a terminal's press, which read the count before the
    # first was written, writes the same count 1: before audit55 the watch compared counts only and the second
    # press was lost (the probe moved on)
    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", "30mm"), encoding="utf-8")
    rig = load_rig(path)
    with Store.open(tmp_path / "rig.db") as store:
        before = store.get_state(rigstop._device(rig), "stop")
        assert rigstop.press(store, rig, "other") == 1
        watch = rigstop.RigStopWatch(rig, "probe")
        watch.begin(store)
        assert watch.stopped(store) is None
        assert rigstop.press(_Stale(store, before), rig, None) == 1  # type: ignore[arg-type]
        why = watch.stopped(store)
        assert why is not None and "pressed from a terminal" in why, why
        assert watch.stopped(store) is None  # said once


def test_a_corrupted_stop_record_is_not_read_as_a_count(tmp_path: Path) -> None:
    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", "30mm"), encoding="utf-8")
    rig = load_rig(path)
    with Store.open(tmp_path / "rig.db") as store:
        for bad in ({"count": True}, {"count": -3}, {"count": "7"}, {"count": 2.0}, [1], "x", {"count": 2, "arm": 5}):
            store.set_state(rigstop._device(rig), "stop", bad)
            assert rigstop.pressed(store, rig) == {"count": 0, "arm": None, "at": None}, bad
            assert rigstop.press(store, rig, "probe") == 1  # counted again from 0
        watch = rigstop.RigStopWatch(rig, "other")
        watch.begin(store)
        store.set_state(rigstop._device(rig), "stop", {"count": "9"})  # corrupted while a motion runs: it stops
        why = watch.stopped(store)
        assert why is not None and "removed or is unreadable" in why and "None" not in why, why


@pytest.mark.parametrize("names", [("Bench", "bench"), ("COM3", "com3"), ("a/b", "a%2Fb"), ("bänk 1", "BÄNK 1")])
def test_rigs_whose_names_differ_only_by_case_have_stops_of_their_own(tmp_path: Path, names: tuple[str, str]) -> None:
    # the STOP was kept under rig://NAME, whose host the store's key lowercases: rig 'Bench's STOP stopped rig
    # 'bench' (and 'COM3' read as a serial port)
    rigs = []
    for k, name in enumerate(names):
        path = tmp_path / f"rig{k}.toml"
        path.write_text(RIG.replace("{lid}", "30mm").replace('name = "bench"', f"name = {name!r}"), encoding="utf-8")
        rigs.append(load_rig(path))
    assert [r.name for r in rigs] == list(names)
    with Store.open(tmp_path / "rig.db") as store:
        watch = rigstop.RigStopWatch(rigs[1], "probe")
        watch.begin(store)
        assert rigstop.press(store, rigs[0], None) == 1
        assert watch.stopped(store) is None and rigstop.pressed(store, rigs[1])["count"] == 0
        assert rigstop.press(store, rigs[1], None) == 1
        assert watch.stopped(store) is not None


def test_where_names_a_claim_a_killed_move_left_and_what_clears_it(tmp_path: Path) -> None:
    # a move killed (SIGKILL) between two bursts leaves its claim and nothing uncertain: the other arms are refused
    # ("a move of it claims its joint 3 ..."), but before audit55 `where` showed the arm as known and still
    from stickslip.devices.positions import load_state, save_state

    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", "30mm"), encoding="utf-8")
    rig, db = load_rig(path), tmp_path / "rig.db"
    with Store.open(db) as store:
        state = load_state(store, rig.state_key("other"), rig.arm("other").joint_specs())
        state.claim[3] = (0.0, 0.009)
        save_state(store, state)
    r = runner.invoke(app, ["where", "--rig", str(path), "--db", str(db)])
    out = " ".join(r.stdout.split())
    assert r.exit_code == 0, r.output
    assert "arm 'other'" in out and "claimed by a move: joint 3 0 µm to 9000 µm" in out, out
    assert "where --rig" in out and "--arm other --set 3=" in out, out
    r = runner.invoke(app, ["where", "--rig", str(path), "--db", str(db), "--json"])
    arms = {a["arm"]: a for a in json.loads(r.stdout)["arms"]}
    assert arms["other"]["claim"] == {"3": [0.0, 0.009]} and arms["probe"]["claim"] == {}
    r = runner.invoke(app, ["where", "--rig", str(path), "--db", str(db), "--arm", "other", "--offline"])
    assert "claimed by a move: joint 3 0 µm to 9000 µm" in " ".join(r.stdout.split()), r.output
    r = runner.invoke(app, ["where", "--rig", str(path), "--db", str(db), "--arm", "other", "--offline", "--set",
                            "3=0"])
    assert r.exit_code == 0, r.output
    with Store.open(db) as store:
        assert load_state(store, rig.state_key("other"), rig.arm("other").joint_specs()).claim == {}
