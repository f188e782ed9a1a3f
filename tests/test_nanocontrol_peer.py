"""`stickslip move` against an independent NanoControl on a pseudo-terminal (tests/support/nanocontrol_peer.py).

Good moves send exactly the planned steps with nothing on stderr; each injected fault ends
within the configured timeout plus the burst's own duration with one line naming the port,
and a stop is sent. CR LF answers are accepted without complaint.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from synth import paper_table

from stickslip.measurements import measurements_to_csv

pytestmark = [
    pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX-only"),
    pytest.mark.xdist_group("nanocontrol_peer"),  # one worker makes the calibration once
]
if sys.platform != "win32":
    from nanocontrol_peer import NanoControlPeer

MAIN = "import sys; from stickslip.cli import main; sys.argv[0] = 'stickslip'; main()"


def _cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", MAIN, *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def cal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The paper's calibration, made once by the CLI for the module's moves (none writes it)."""
    tmp = tmp_path_factory.mktemp("cal")
    meas = tmp / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    out = tmp / "cal.json"
    r = _cli("calibrate", str(meas), "-o", str(out))
    assert r.returncode == 0, r.stderr
    return out


def _planned(cal: Path, frm: str, to: str) -> int:
    """What ``stickslip plan`` says the move takes (in this process: only the move runs as its own)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    r = CliRunner().invoke(app, ["plan", "-c", str(cal), "--joint", "3", "--from", frm, "--to", to, "--q2", "-90deg",
                                 "--json"])
    assert r.exit_code == 0, r.output
    return int(json.loads(r.stdout)["steps"])


@pytest.mark.slow
def test_a_good_move_sends_exactly_the_planned_steps_and_nothing_on_stderr(cal: Path, tmp_path: Path) -> None:
    db = str(tmp_path / "s.db")
    with NanoControlPeer() as peer:
        assert _cli("where", "-d", peer.url, "--offline", "--set", "3=2mm", "--db", db).returncode == 0
        r = _cli("move", "-d", peer.url, "-c", str(cal), "--joint", "3", "--by", "300um", "--q2", "-90deg",
                 "--trust-calibration",  # the calibration records no device
                 "--burst", "100", "--db", db)
        assert r.returncode == 0, r.stderr
        assert r.stderr == ""
        planned = _planned(cal, "2mm", "2.3mm")
        assert planned > 100  # several bursts
        assert peer.steps == {"A": 0, "B": 0, "C": planned, "D": 0}
        assert all(c.startswith(("version", "coarse C +")) for c in peer.log), peer.log


@pytest.mark.slow
@pytest.mark.parametrize("fault,words", [
    ("error", "refused 'coarse C +"),
    ("silent", "did not answer 'coarse C +"),
    ("garbage", "garbage reply"),
])
def test_each_fault_is_one_line_naming_the_port_with_a_stop_sent(
    cal: Path, tmp_path: Path, fault: str, words: str
) -> None:
    db = str(tmp_path / "s.db")
    with NanoControlPeer(fault=fault) as peer:
        assert _cli("where", "-d", peer.url, "--offline", "--set", "3=2mm", "--db", db).returncode == 0
        t0 = time.monotonic()
        r = _cli("move", "-d", peer.url, "-c", str(cal), "--joint", "3", "--by", "30um", "--q2", "-90deg",
                 "--db", db, "--trust-calibration")  # the calibration records no device
        elapsed = time.monotonic() - t0
        assert r.returncode == 2, r.stderr
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
        assert peer.port in lines[0] and words in lines[0], lines[0]
        assert "stop" in peer.log, peer.log
        # timeout 0.5 s + 1.5 x the burst (~35 steps at the assumed 1 kHz) + start-up of the CLI
        assert elapsed < 10
