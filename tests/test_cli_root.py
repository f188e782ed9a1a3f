"""Root options: --version, -v/-vv logging to stderr, --log-file."""

from __future__ import annotations

import subprocess
import sys

import pytest

from stickslip import __version__

MAIN = "import sys; from stickslip.cli import main; sys.argv[0] = 'stickslip'; main()"


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", MAIN, *args], capture_output=True, text=True, timeout=60)


def test_version():
    r = _cli("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"stickslip {__version__}"


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="the NanoControl peer runs on a POSIX pseudo-terminal")
def test_vv_shows_device_traffic_and_log_file_keeps_it(tmp_path):
    from nanocontrol_peer import NanoControlPeer

    log = tmp_path / "stickslip.log"
    with NanoControlPeer() as peer:
        quiet = _cli("where", "-d", peer.url, "--db", str(tmp_path / "s.db"))
        assert quiet.returncode == 0, quiet.stderr
        assert quiet.stderr == ""  # no logging without -v
        r = _cli("-vv", "--log-file", str(log), "where", "-d", peer.url, "--db", str(tmp_path / "s.db"))
        assert r.returncode == 0, r.stderr
    assert "DEBUG stickslip.devices.nanocontrol: -> version;" in r.stderr
    assert "-> version;" in log.read_text(encoding="utf-8")


@pytest.mark.slow
def test_an_unwritable_log_file_is_one_line(tmp_path):
    r = _cli("--log-file", str(tmp_path / "no" / "such" / "dir.log"), "--version")
    assert r.returncode == 0  # --version is eager: it answers before anything else
    r = _cli("--log-file", str(tmp_path / "no" / "such" / "dir.log"), "history", "--db", str(tmp_path / "s.db"))
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "log file" in lines[0], r.stderr


def test_the_command_line_loads_no_numpy_scipy_or_matplotlib_until_a_command_needs_them():
    """`stickslip --help` and shell completion import only the CLI shell (issue 14's start-up budget)."""
    import subprocess
    import sys

    code = "import sys, stickslip.cli; print(sorted(m for m in ('numpy', 'scipy', 'matplotlib') if m in sys.modules))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
