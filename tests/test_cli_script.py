"""The device commands' outputs and stored rows are those recorded (tests/data/cli_script.json).

tests/support/cli_script.py runs a scripted session of move, where, observe, reach, jog and
listen on sim://, the legacy NanoControl emulator and the console emulator, recording each
command's exit code, stdout, stderr and the device rows it left in the database. Moving the
workflows out of the CLI (issue 35 item 3) must leave all of it as it was; a change that is
meant to change an output updates the recording in the same commit and says why.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from cli_script import DAY, record

RECORDED = Path(__file__).parent / "data" / "cli_script.json"
needs_pty = pytest.mark.skipif(not hasattr(os, "openpty"), reason="the emulators serve pseudo-terminals (POSIX)")


@pytest.mark.parametrize(
    "part",
    [
        "sim",
        pytest.param("emulator", marks=[needs_pty, pytest.mark.slow]),  # timeouts and a fault injected: seconds
        pytest.param("console", marks=needs_pty),
        pytest.param("listen", marks=pytest.mark.slow),  # renders and tunes three recordings
    ],
)
def test_the_scripted_session_prints_and_stores_what_was_recorded(part, tmp_path, monkeypatch):
    monkeypatch.setenv("STICKSLIP_TODAY", DAY)
    monkeypatch.setenv("COLUMNS", "80")
    expected = json.loads(RECORDED.read_text(encoding="utf-8"))[part]
    got = record(tmp_path, (part,))[part]
    assert [r["args"] for r in got] == [r["args"] for r in expected]
    for g, e in zip(got, expected, strict=True):
        assert g == e, " ".join(e["args"])
