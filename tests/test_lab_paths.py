"""Paths as labs have them (audit43): spaces, accents, ``#``, ``%``, ``[``, a leading ``-``, links.

Each test failed before its fix; the commands were also run by hand on ``sim://`` with
``HOME``, ``STICKSLIP_DB`` and the working folder under a 253-character folder named
``-Zoë Müller's OneDrive - Lab #1 100% R&D [2026] ...`` (the report of audit43 lists them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from stickslip.cli import app


def invoke(args: list[str]) -> Any:
    return CliRunner().invoke(app, [str(a) for a in args])


def path_options() -> list[tuple[tuple[str, ...], str]]:
    """(command path, option) of every command's option that names a file (a ``Path``), and ``--db``."""

    def takes_path(p: Any) -> bool:
        descriptor = getattr(p, "type_descriptor", None)
        annotation = getattr(descriptor, "annotation", None)
        return annotation is Path or annotation == (Path | None) or p.opts[0] == "--db"

    found: list[tuple[tuple[str, ...], str]] = []

    def walk(cmd: Any, path: list[str]) -> None:
        for name in getattr(cmd, "commands", {}):
            walk(cmd.commands[name], [*path, name])
        for p in cmd.params:
            if path and p.opts[0].startswith("-") and not getattr(p, "is_flag", False) and takes_path(p):
                found.append((tuple(path), p.opts[0]))

    walk(typer.main.get_command(app), [])
    return sorted(found)


PATH_OPTIONS = path_options()


def test_the_path_options_are_found() -> None:
    assert (("show",), "--output") in PATH_OPTIONS and (("history",), "--db") in PATH_OPTIONS
    assert len(PATH_OPTIONS) >= 30, PATH_OPTIONS


@pytest.mark.parametrize("where", PATH_OPTIONS, ids=lambda w: " ".join([*w[0], w[1]]))
@pytest.mark.parametrize("value", ["--json", "-j", "--"])
def test_a_file_option_given_an_option_is_refused_not_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: tuple[tuple[str, ...], str], value: str
) -> None:
    """``show 2 -o --json`` wrote the calibration to a file named '--json' and printed no JSON."""
    monkeypatch.chdir(tmp_path)
    path, option = where
    r = invoke([*path, option, value])
    assert r.exit_code == 2, (r.exit_code, r.output)
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and f"{value!r} reads as an option, not a file" in errors[0], r.stderr
    assert str(tmp_path / value) in errors[0]  # how to name a file so called
    assert not (tmp_path / value).exists()


def test_a_log_file_given_an_option_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    r = invoke(["--log-file", "-v", "config", "path"])
    assert r.exit_code == 2 and "--log-file: '-v' reads as an option" in r.stderr, r.stderr
    assert not (tmp_path / "-v").exists()


def test_names_that_begin_with_a_dash_but_are_files_are_taken(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """'-o.csv', '--help.csv' (a dot) and a name with its folder are names, not options."""
    monkeypatch.chdir(tmp_path)
    for name in ("-o.csv", "--help.csv", str(tmp_path / "--json")):
        r = invoke(["suggest", "--n", "2", "--seed", "1", "-c", "none.json", "-o", name])
        assert "reads as an option" not in r.stderr, r.stderr


def test_a_result_line_keeps_a_path_with_spaces_whole(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """'config show' and 'saved to' broke a path at its spaces, indenting the rest: no line could be copied back."""
    folder = tmp_path / "Zoë Müller's OneDrive - Lab #1 100% R&D [2026]" / "Messungen 2026 Sehr langer Ordnername"
    folder.mkdir(parents=True)
    db = folder / "stickslip ü.db"
    monkeypatch.setenv("STICKSLIP_DB", str(db))
    r = CliRunner().invoke(app, ["config", "show"], env={"COLUMNS": "60"})
    assert r.exit_code == 0, r.output
    assert any(ln.strip().startswith(f"{db} (not there)") or ln.strip() == str(db) for ln in r.stdout.splitlines())
    from synth import paper_table  # tests/support

    from stickslip.measurements import measurements_to_csv

    meas, out = folder / "meas ä.csv", folder / "cal é [1].json"
    meas.write_text(measurements_to_csv(paper_table()))
    r = CliRunner().invoke(app, ["calibrate", str(meas), "-o", str(out)], env={"COLUMNS": "60"})
    assert r.exit_code == 0, r.output
    assert str(out) in [ln.strip() for ln in r.stdout.splitlines()], r.stdout  # on a line of its own, whole


@pytest.mark.parametrize("url", ["file:lab.db", "FILE:lab.db", "file:{tmp}/lab.db", "file:lab.db?mode=ro"])
def test_a_file_url_as_the_database_is_refused_not_made_a_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, url: str
) -> None:
    """--db file:lab.db made a file named 'file:lab.db' (on Windows: the stream 'lab.db' of a file named 'file')."""
    from synth import paper_table  # tests/support

    from stickslip.measurements import measurements_to_csv

    monkeypatch.chdir(tmp_path)
    (tmp_path / "meas.csv").write_text(measurements_to_csv(paper_table()))
    r = invoke(["import", "meas.csv", "-d", "sim://", "--db", url.format(tmp=tmp_path)])
    assert r.exit_code == 2 and "a file: URL is not read" in r.stderr, r.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["meas.csv"]


def test_written_files_are_named_whole_too(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """export's 'wrote N traverses to PATH' (rich's own wrapping) broke the path at its spaces too."""
    from synth import paper_table  # tests/support

    from stickslip.measurements import measurements_to_csv

    folder = tmp_path / "Zoë Müller's OneDrive - Lab #1 100% R&D [2026]" / "Messungen 2026 Sehr langer Ordnername"
    folder.mkdir(parents=True)
    meas, out = folder / "meas ä.csv", folder / "export é [1].csv"
    meas.write_text(measurements_to_csv(paper_table()))
    assert invoke(["import", str(meas), "-d", "sim://"]).exit_code == 0
    r = CliRunner().invoke(app, ["export", "-o", str(out)], env={"COLUMNS": "60"})
    assert r.exit_code == 0, r.output
    assert str(out) in [ln.strip() for ln in r.stdout.splitlines()], r.stdout


def test_a_file_url_as_the_config_or_rig_files_database_is_refused(tmp_path: Path) -> None:
    """database = "file:lab.db" in the config or a rig file was a file named 'file:lab.db' beside it."""
    from stickslip.config import ConfigError, load_config
    from stickslip.rig.load import RigError, load_rig

    cfg = tmp_path / "config.toml"
    cfg.write_text('database = "file:lab.db"\n')
    with pytest.raises(ConfigError, match=r"config.toml:1: database: a file: URL is not read"):
        load_config(cfg)
    rig = tmp_path / "lab.toml"
    rig.write_text('database = "File:/data/lab.db"\n[[arm]]\nname = "probe"\ncontroller = "sim://"\n')
    with pytest.raises(RigError, match=r"lab.toml:1: database: a file: URL is not read"):
        load_rig(rig)


def _arguments() -> list[tuple[tuple[str, ...], str]]:
    """(command path, argument name) of every positional argument (tables, recordings, frames, rig files)."""
    found: list[tuple[tuple[str, ...], str]] = []

    def walk(cmd: Any, path: list[str]) -> None:
        for name in getattr(cmd, "commands", {}):
            walk(cmd.commands[name], [*path, name])
        for p in cmd.params:
            if path and not p.opts[0].startswith("-"):
                found.append((tuple(path), str(p.name)))

    walk(typer.main.get_command(app), [])
    return sorted(found)


_TOO_LONG = "ü" * 140  # 280 bytes: more than a file name may have (255 on ext4, NTFS, APFS)
_RUNS = ("serve", "jog")  # they would run on (a server, a terminal loop), not a path's concern


@pytest.mark.parametrize(
    "args",
    [[*p, o, _TOO_LONG + tail] for p, o in PATH_OPTIONS if p[0] not in _RUNS for tail in (".csv", "/x.csv")]
    + [[*p, _TOO_LONG + tail] for p, _ in _arguments() if p[0] not in _RUNS for tail in (".csv", "/x.csv")],
    ids=lambda a: " ".join(a[:-1]) + (" NAME/x" if "/" in a[-1] else " NAME"),
)
def test_a_name_too_long_for_the_file_system_is_one_line_never_a_traceback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, args: list[str]
) -> None:
    """calibrate, fit, anova, report (a table), demo -o and config show --db/--calibration raised OSError
    'File name too long' with a traceback: Path.exists and is_dir raise it on Python 3.11."""
    monkeypatch.chdir(tmp_path)
    r = invoke(args)
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert "Traceback" not in r.output


def test_a_file_options_leading_tilde_is_the_home_folder_whatever_the_shell(tmp_path, monkeypatch):
    # PowerShell and cmd pass ~ to a program as it stands: `-o ~/cal.json` wrote a folder named '~' in the working
    # folder (or failed 'no such folder'); --db expanded it, the other file options did not (audit43's question)
    from synth import paper_table
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import measurements_to_csv

    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("USERPROFILE", str(home))  # Path.expanduser on Windows
    monkeypatch.chdir(tmp_path)
    (tmp_path / "meas.csv").write_text(measurements_to_csv(paper_table()))
    r = CliRunner().invoke(app, ["calibrate", "meas.csv", "-o", "~/cal.json"])
    assert r.exit_code == 0, r.output
    assert (home / "cal.json").is_file() and not (tmp_path / "~").exists()
    r = CliRunner().invoke(app, ["predict", "meas.csv", "-c", "~/cal.json", "-o", "~/predicted.csv"])
    assert r.exit_code == 0 and (home / "predicted.csv").is_file(), r.output


FOLDER_OPTIONS = {(("demo",), "--output"), (("report",), "-o")}
"""The path options that name a folder (metavar FOLDER): a trailing / is theirs."""


@pytest.mark.parametrize("where", sorted(set(PATH_OPTIONS) - FOLDER_OPTIONS), ids=lambda w: " ".join([*w[0], w[1]]))
def test_a_file_option_ending_with_a_slash_names_a_folder_and_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: tuple[tuple[str, ...], str]
) -> None:
    """``show 2 -o neu/`` and ``export -o exp/`` wrote a *file* named neu / exp: pathlib dropped the slash (audit43)."""
    monkeypatch.chdir(tmp_path)
    path, option = where
    r = invoke([*path, option, "neu/"])
    assert r.exit_code == 2, (r.exit_code, r.output)
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "'neu/' ends with '/', so it names a folder" in errors[0], r.stderr
    assert not (tmp_path / "neu").exists()


def test_a_folder_option_takes_a_slash_and_a_log_file_refuses_one(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    from stickslip.cli._common import path_text

    monkeypatch.chdir(tmp_path)
    walked = {(tuple(p), o) for p, o in PATH_OPTIONS}
    assert FOLDER_OPTIONS <= walked
    cmds = typer.main.get_command(app).commands  # type: ignore[attr-defined]
    for (name,), option in FOLDER_OPTIONS:
        (param,) = [p for p in cmds[name].params if option in p.opts]
        assert param.metavar == "FOLDER"
    assert path_text(folder=True)("day1/") == Path("day1")
    r = invoke(["--log-file", "lg/", "config", "path"])
    assert r.exit_code == 2 and "'--log-file': 'lg/' ends with '/'" in r.stderr, r.stderr
    assert not (tmp_path / "lg").exists()
    r = invoke(["show", "1", "-o", "neu"])  # without the slash: a file, as before (no calibration #1 here)
    assert "names a folder" not in r.stderr
