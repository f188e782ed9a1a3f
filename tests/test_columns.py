"""Every command's --help and its typical output fit 80 columns without breaking a word (issue 36, finding 8).

A word broken by wrapping (a URL, a path, ``30.16`` and ``µm`` torn apart is fine, ``sim://?seed=``
and ``3`` is not) is found by comparing the words of the 80-column output with those of the same
command printed 400 columns wide, from the same database. On a terminal, warnings and errors wrap
at its width (at spaces only, later lines indented); in a pipe they stay one line.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
import typer
from cli_script import SIM, true_calibration
from typer.testing import CliRunner

from stickslip.cli import _common, app

runner = CliRunner()
ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _commands() -> list[list[str]]:
    group: Any = typer.main.get_command(app)
    ctx = group.make_context("stickslip", ["--help"], resilient_parsing=True)
    out: list[list[str]] = [[]]
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        out.append([name])
        if hasattr(cmd, "list_commands"):
            out += [[name, sub] for sub in cmd.list_commands(ctx)]
    return out


@pytest.mark.parametrize("command", _commands(), ids=lambda c: " ".join(c) or "stickslip")
def test_help_fits_80_columns_and_names_what_each_option_takes(command, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    r = runner.invoke(app, [*command, "--help"])
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert max(len(ln) for ln in lines) <= 80, [ln for ln in lines if len(ln) > 80]
    assert "…" not in r.stdout  # nothing cut off ($STICKSLIP_ANC300_PASSWO…)
    assert "<float>" not in r.stdout and "FLOAT" not in r.stdout
    assert "<bool>" not in r.stdout  # a flag takes nothing: --version <bool> reads as if it took a value
    usage = r.stdout.split("\n\n")[0]  # the usage line names arguments as their rows do: POSES, [MEASUREMENTS]
    assert "{" not in usage and "[[" not in usage, usage
    monkeypatch.setenv("COLUMNS", "400")
    wide = runner.invoke(app, [*command, "--help"]).stdout
    words = {w for w in r.stdout.split() if any(not 0x2500 <= ord(c) <= 0x257F for c in w)}  # not the panels' lines
    assert words <= set(wide.split())  # no word broken


def test_lengths_angles_and_steps_are_typed_in_help(monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    move = runner.invoke(app, ["move", "--help"]).stdout
    for option in ("--q1 <angle>", "--q3 <length>", "--steps <steps>", "--burst <steps>", "--by <length|angle|steps>"):
        assert option in move, option
    traverse = runner.invoke(app, ["traverse", "--help"]).stdout
    assert "--q2 <angle>" in traverse and "--q3 <length>" in traverse and "-d, --device <url>" in traverse
    reach = runner.invoke(app, ["reach", "--help"]).stdout
    assert "--by <x,y,z>" in reach and "--segment <length>" in reach and "$STICKSLIP_ANC300_PASSWORD" in reach


SESSION = [
    ["where", "-d", SIM, "--set", "3=min", "--set", "2=-90deg", "--set", "1=0deg"],
    ["move", "-d", SIM, "-c", "cal.json", "-j", "3", "--by", "30um"],
    ["move", "-d", SIM, "-c", "cal.json", "-j", "2", "--by", "2deg"],
    ["observe", "-d", SIM, "-j", "3", "--at", "30.5um", "--sigma", "1um"],
    ["where", "-d", SIM],
    ["plan", "-c", "cal.json", "-j", "3", "--from", "2mm", "--to", "2.03mm", "--q2", "-60deg"],
    ["reach", "-d", SIM, "-c", "cal.json", "--by", "20um,-10um,5um"],
    ["move", "-d", SIM, "-c", "cal.json", "-j", "3", "--steps", "-15000"],
    ["where", "-d", SIM, "--offline"],
    ["move", "-d", SIM, "-c", "cal.json", "-j", "3", "--by", "1um"],
    ["history"],
    ["show", "1"],
    ["config", "show"],
    ["move", "-d", SIM, "-c", "other-day.json", "-j", "2", "--by", "1deg"],
]


def _session(folder: Path, width: int, monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, str]]:
    """Run :data:`SESSION` in ``folder`` with stdout ``width`` wide and stderr a terminal of that width."""
    monkeypatch.chdir(folder)
    monkeypatch.setenv("STICKSLIP_DB", "s.db")  # relative: a path as long as the test's folder would not fit
    monkeypatch.setattr(_common.console, "_width", width)
    monkeypatch.setattr(_common.err_console, "_width", width)
    monkeypatch.setattr(_common.err_console, "_force_terminal", True)
    out = []
    for argv in SESSION:
        r = runner.invoke(app, argv)
        out.append((ANSI.sub("", r.stdout), ANSI.sub("", r.stderr)))
    return out


@pytest.mark.slow  # the session twice, at 80 and at 400 columns
def test_typical_output_fits_80_columns_without_breaking_a_word(tmp_path, monkeypatch):
    import dataclasses

    from stickslip.calibration import Calibration
    from stickslip.storage import Store

    for name in ("narrow", "wide"):
        folder = tmp_path / name
        folder.mkdir()
        true_calibration(folder / "cal.json")
        cal = Calibration.load(folder / "cal.json")
        dataclasses.replace(cal, day="2026-11-01").save(folder / "other-day.json")  # old: a long warning
        with Store.open(folder / "s.db") as store:
            store.add_calibration(cal, "sim://?seed=4", [])
    narrow = _session(tmp_path / "narrow", 80, monkeypatch)
    wide = _session(tmp_path / "wide", 400, monkeypatch)
    for argv, (out80, err80), (out400, err400) in zip(SESSION, narrow, wide, strict=True):
        text = out80 + err80
        # longer than 80 only where one word alone is (a path of the test's own folder): never cut
        long = [ln for ln in text.splitlines() if len(ln) > 80 and len(ln.split()) > 1]
        assert not long, (argv, long)
        assert (out80 + err80).split() == (out400 + err400).split() or set(text.split()) <= set(
            (out400 + err400).split()
        ), argv  # the same words: nothing broken mid-word
        for line in text.splitlines():  # a ± always says what it is
            if "±" in line:
                assert "95 %" in line or "σ" in line or "s.e." in line, (argv, line)
    moved = narrow[1][0]
    assert "σ" in moved and "±" not in moved  # a standard deviation is named σ
    assert "(95 % prediction interval)" in narrow[5][0]
    assert any("warning:" in err and "\n  " in err for _, err in narrow)  # a long warning wrapped, indented


def test_a_long_error_is_one_line_in_a_pipe(tmp_path, monkeypatch):
    true_calibration(tmp_path / "cal.json")
    monkeypatch.setattr(_common.err_console, "_width", 80)
    argv = ["move", "-d", "mm3a:///dev/ttyNONE", "-j", "3", "--by", "1um", "-c", str(tmp_path / "cal.json")]
    r = runner.invoke(app, [*argv, "--trust-calibration"])  # refused: joint 3 was never referenced
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and len(lines[0]) > 80, r.stderr  # whole, for grep and logs
