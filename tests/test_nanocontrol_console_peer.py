"""The issue's check: `stickslip move` against an independent console (tests/support/console_peer.py).

With no dialect option the CLI must detect the console, make exactly the steps
`stickslip plan` gives (counted by the peer from the wall-clock timing of go and stop at
the channel's frequency, power-on 700 Hz), on the joint's channel only, with no fine
steps and no channel left driving; `where` must report plan's end. An `e` answer to
`go` and silence after `go` each end in one line naming the port, with a stop sent.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from synth import paper_table

from stickslip.measurements import measurements_to_csv

pytestmark = [
    pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX-only"),
    pytest.mark.xdist_group("nanocontrol_console_peer"),  # one worker starts the console once
]
if sys.platform != "win32":
    from console_peer import ConsolePeer

MAIN = "import sys; from stickslip.cli import main; sys.argv[0] = 'stickslip'; main()"


def _cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", MAIN, *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def cal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("cal")
    meas = tmp / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    out = tmp / "cal.json"
    r = _cli("calibrate", str(meas), "-o", str(out))
    assert r.returncode == 0, r.stderr
    return out


def _plan(cal: Path, frm: str, to: str) -> dict[str, Any]:
    r = _cli("plan", "-c", str(cal), "--joint", "3", "--from", frm, "--to", to, "--q2", "-90deg", "--json")
    assert r.returncode == 0, r.stderr
    plan: dict[str, Any] = json.loads(r.stdout)
    return plan


@pytest.mark.slow
def test_move_without_dialect_option_makes_exactly_the_planned_steps(cal: Path, tmp_path: Path) -> None:
    db = str(tmp_path / "s.db")
    plan = _plan(cal, "2mm", "3mm")
    with ConsolePeer() as peer:
        assert _cli("where", "-d", peer.url, "--offline", "--set", "3=2mm", "--db", db).returncode == 0
        r = _cli("move", "-d", peer.url, "-c", str(cal), "--joint", "3", "--by", "1mm", "--q2", "-90deg",
                 "--trust-calibration",  # the calibration records no device
                 "--db", db)
        assert r.returncode == 0, r.stderr
        assert r.stderr == ""
        w = _cli("where", "-d", peer.url, "--db", db, "--json")
        assert w.returncode == 0, w.stderr
        driving_at_end = peer.driving
    assert plan["steps"] > 1000  # two bursts at the default --burst 1000
    assert peer.steps == {"A": 0, "B": 0, "C": plan["steps"], "D": 0}, peer.commands()
    assert peer.fine == dict.fromkeys("ABCD", 0)
    assert not driving_at_end
    assert peer.violations == []
    assert peer.frequency_set_before_go is True  # never timed with the power-on 700 Hz
    assert peer.active == 3  # the user's profile is active again
    gos = [c for c in peer.commands() if c.startswith("go ")]
    assert 2 <= len(gos) <= 4 and all(c.split()[1:3] == ["0", "0"] and c.split()[4] == "0" for c in gos)
    where = json.loads(w.stdout)
    q3 = where["joints"][2]
    assert q3["source"] == "dead-reckoned"
    assert q3["q"] == pytest.approx(plan["end_predicted"], abs=1e-12)
    assert where["info"]["dialect"] == "console"
    assert where["info"]["version"] == "NanoControl peer console 9.9"
    assert where["info"]["active_profile"] == 3


@pytest.mark.slow
@pytest.mark.parametrize("fault, words", [
    ("error", "refused 'go 0 0 "),
    ("silent", "did not answer 'go 0 0 "),
])
def test_a_fault_at_go_is_one_line_naming_the_port_with_a_stop_sent(
    cal: Path, tmp_path: Path, fault: str, words: str
) -> None:
    db = str(tmp_path / "s.db")
    with ConsolePeer(fault=fault) as peer:
        url = peer.url + "?timeout=0.5"
        assert _cli("where", "-d", url, "--offline", "--set", "3=2mm", "--db", db).returncode == 0
        t0 = time.monotonic()
        r = _cli("move", "-d", url, "-c", str(cal), "--joint", "3", "--by", "30um", "--q2", "-90deg",
                 "--db", db, "--trust-calibration")  # the calibration records no device
        elapsed = time.monotonic() - t0
        w = _cli("where", "-d", url, "--offline", "--db", db, "--json")
        driving_at_end = peer.driving
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert peer.port in lines[0] and words in lines[0], lines[0]
    cmds = peer.commands()
    first_go = next(i for i, c in enumerate(cmds) if c.startswith("go "))
    assert cmds[first_go + 1] == "stopnack" and "stop" in cmds[first_go + 2 :], cmds
    assert not driving_at_end
    # a few CLI start-ups (~1-2 s each on a loaded machine) + timeout 0.5 s + the stop's 0.25 s
    assert elapsed < 15
    q3 = json.loads(w.stdout)["joints"][2]
    if fault == "error":  # refused and acknowledged stop: at most the refused go's steps
        assert q3["source"] == "uncertain" and q3["uncertain"][0] == pytest.approx(2e-3, abs=1e-12)
    else:  # the stop was never acknowledged: up to the end stop
        assert q3["source"] == "uncertain" and q3["uncertain"][0] == pytest.approx(2e-3, abs=1e-12)
        assert q3["uncertain"][1] > 2.03e-3
