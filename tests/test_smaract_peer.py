"""`stickslip where` and `stickslip move` against independent SmarAct controllers (tests/support/smaract_peer.py).

The peer was written from docs/devices/smaract.md alone and counts each channel's steps
from the wall-clock timing of its bursts. A good move must make exactly the steps
`stickslip plan` gives, on the joint's channel only and in the channel map's sense, with
nothing on stderr and no command outside the documented forms; `where` must then report
plan's end. Each fault must end in one line naming the port (exit 2), with the joint kept
uncertain over the failed burst only (or not at all if the controller refused it).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest
from smaract_peer import SmarActPeer
from synth import paper_table
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.measurements import measurements_to_csv

runner = CliRunner()


def _cli(*args: str) -> Any:
    return runner.invoke(app, list(args))


@pytest.fixture(scope="module")
def cal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("cal")
    meas = tmp / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    out = tmp / "cal.json"
    r = _cli("calibrate", str(meas), "-o", str(out))
    assert r.exit_code == 0, r.output
    return out


def _plan(cal: Path, frm: str, to: str) -> dict[str, Any]:
    r = _cli("plan", "-c", str(cal), "--joint", "3", "--from", frm, "--to", to, "--q2", "-90deg", "--json")
    assert r.exit_code == 0, r.output
    plan: dict[str, Any] = json.loads(r.stdout)
    return plan


@pytest.mark.parametrize("kind", ["mcs", "mcs2"])
def test_a_move_makes_exactly_the_planned_steps_on_the_mapped_channel(cal: Path, tmp_path: Path, kind: str) -> None:
    db = str(tmp_path / "s.db")
    plan = _plan(cal, "2mm", "2.3mm")
    with SmarActPeer(kind) as peer:
        url = peer.url + "?channels=1,0,-3&hz=5000"  # joint 3 on channel 3, reversed
        assert _cli("where", "-d", url, "--offline", "--set", "3=2mm", "--db", db).exit_code == 0
        r = _cli("move", "-d", url, "-c", str(cal), "--joint", "3", "--by", "300um", "--q2", "-90deg",
                 "--trust-calibration",  # the calibration records no device
                 "--burst", "100", "--db", db)
        assert r.exit_code == 0, r.output
        assert r.stderr == ""
        w = _cli("where", "-d", url, "--db", db, "--json")
        assert w.exit_code == 0, w.output
        stepping = peer.stepping()
    assert plan["steps"] > 200  # three bursts or more
    assert peer.steps == {0: 0, 1: 0, 2: 0, 3: -plan["steps"]}, peer.log
    assert peer.violations == []
    assert stepping == []
    where = json.loads(w.stdout)
    q3 = where["joints"][2]
    assert q3["source"] == "dead-reckoned"
    assert q3["q"] == pytest.approx(plan["end_predicted"], abs=1e-12)
    assert where["info"]["channels"] == {"1": "1", "2": "0", "3": "-3"}
    assert where["info"]["frequency_hz"]["ch3"] == 5000.0
    model = "SmarAct MCS (system id 77)" if kind == "mcs" else "SmarAct MCS2 (serial PEER-0042)"
    assert where["answers"] == model


@pytest.mark.parametrize("kind", ["mcs", "mcs2"])
@pytest.mark.parametrize("fault, words, uncertain", [
    ("refuse", "refused", False),
    ("mute", "did not answer", True),
    ("endless", "still stepping", True),
])
def test_each_fault_is_one_line_naming_the_port_and_bounds_the_position(
    cal: Path, tmp_path: Path, kind: str, fault: str, words: str, uncertain: bool
) -> None:
    db = str(tmp_path / "s.db")
    with SmarActPeer(kind, fault=fault) as peer:
        url = peer.url + "?timeout=0.3&hz=5000"
        assert _cli("where", "-d", url, "--offline", "--set", "3=2mm", "--db", db).exit_code == 0
        r = _cli("move", "-d", url, "-c", str(cal), "--joint", "3", "--by", "30um", "--q2", "-90deg",
                 "--db", db, "--trust-calibration")  # the calibration records no device
        w = _cli("where", "-d", url, "--offline", "--db", db, "--json")
        log = list(peer.log)
        violations = list(peer.violations)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert peer.name in lines[0] and words in lines[0], lines[0]
    assert violations == []
    stop = ":S2" if kind == "mcs" else ":STOP2"
    assert (stop in log) == uncertain  # a refused burst needs no stop: nothing moves
    q3 = json.loads(w.stdout)["joints"][2]
    if uncertain:  # between nothing and the whole (only) burst of about 30 steps
        assert q3["source"] == "uncertain"
        lo, hi = q3["uncertain"]
        assert lo == pytest.approx(2e-3, abs=1e-12) and 2.02e-3 < hi < 2.05e-3
    else:
        assert q3["source"] == "set" and q3["q"] == pytest.approx(2e-3, abs=1e-12)


@pytest.mark.parametrize("kind", ["mcs", "mcs2"])
def test_a_channel_another_program_drives_leaves_the_joint_uncertain_not_where_it_was_kept(
    cal: Path, tmp_path: Path, kind: str
) -> None:
    """SmarAct's own software (or its hand control) is stepping the joint's channel when a move begins: the
    controller says so (MCS: status 1 to :GS; MCS2: state bit 0x0001) and the burst is not sent (on the MCS a
    :MST would have taken the channel over, the other program's steps so far unknown). The joint is then
    wherever that program takes it, either way, so it must not stay kept, referenced, where it was; it is kept
    uncertain over its whole range (audit57; the lead: not only up to the stop of our burst's direction, since
    the other program's is not known)."""
    db = str(tmp_path / "s.db")
    with SmarActPeer(kind) as peer:
        url = peer.url + "?timeout=0.3&hz=5000"
        assert _cli("where", "-d", url, "--offline", "--set", "3=2mm", "--db", db).exit_code == 0
        peer._begin(2, 90000, 1000.0, time.monotonic())  # the vendor's program: 90 s of steps on channel 2
        r = _cli("move", "-d", url, "-c", str(cal), "--joint", "3", "--by", "30um", "--q2", "-90deg",
                 "--db", db, "--trust-calibration")
        w = _cli("where", "-d", url, "--offline", "--db", db, "--json")
        moves = [line for line in peer.log if line.startswith((":MOVE", ":MST"))]
    assert r.exit_code == 2, r.output
    assert "channel 2 is already moving" in r.stderr and "another program may be driving it" in r.stderr, r.stderr
    assert moves == []  # nothing of ours was sent
    q3 = json.loads(w.stdout)["joints"][2]
    assert q3["source"] == "uncertain", q3  # before: "set" at 2 mm, as if nothing moved it
    assert q3["uncertain"] == pytest.approx([0.0, 12e-3], abs=1e-12)  # was [2 mm, 12 mm]: only up from 2 mm
