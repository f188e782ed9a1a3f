"""The configuration file on the command line: every level of precedence, for every setting it gives.

Order (docs/config.md): command-line option > environment variable (``$STICKSLIP_DB``,
``$STICKSLIP_MAX_AGE_DAYS``; there is none for the others) > the file > built-in default.
Each level is checked by what a command *does* (which database gets the positions,
which calibration plans the steps, which geometry places the tip, whether a stale
calibration warns), not only by what ``config show`` says; and ``config show`` is checked
to say the same.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.calibration import Calibration
from stickslip.cli import app
from stickslip.config import ENV_CONFIG, template
from stickslip.sim.arm import SimulatedMM3A

runner = CliRunner()
DAY = "2026-11-22"  # the pinned today (conftest)


def run(*args: object):
    return runner.invoke(app, [str(a) for a in args])


def ok(*args: object):
    r = run(*args)
    assert r.exit_code == 0, (args, r.output, r.stderr)
    return r


def one_error(r) -> str:
    assert r.exit_code == 2, (r.exit_code, r.output)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "Traceback" not in r.output
    return lines[0]


def calibration(seed: int, day: str = DAY) -> Calibration:
    """The true models of the simulated arm ``seed`` as a calibration (exact by construction)."""
    models = SimulatedMM3A(seed=seed, day=DAY).true_models()
    full = {"+": lambda s: (s.lower, s.upper), "-": lambda s: (s.upper, s.lower)}
    constant = {(j, d): float(m.average_gamma(*full[d](kin.JOINTS[j]), *kin.Pose())) for (j, d), m in models.items()}
    return Calibration(models=models, stderr=dict.fromkeys(models), constant_steps=constant, day=day, method="paper")


@pytest.fixture()
def cfg(tmp_path, monkeypatch):
    """A config file in its own folder (named by $STICKSLIP_CONFIG) and a working folder elsewhere."""
    folder = tmp_path / "cfg"
    folder.mkdir()
    path = folder / "config.toml"
    monkeypatch.setenv(ENV_CONFIG, str(path))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)

    def write(text: str) -> Path:
        path.write_text(text, encoding="utf-8")
        return path

    return write


def settings(*args: object) -> dict:
    return json.loads(ok("config", "show", "--json", *args).stdout)["settings"]


# ---------------------------------------------------------------- database: option > $STICKSLIP_DB > file > default


def _has_q3(db: Path, q3: float) -> bool:
    w = json.loads(ok("where", "--db", db, "--offline", "--json").stdout)
    return math.isclose(w["joints"][2]["q"], q3, abs_tol=1e-12)


def test_database_every_level(cfg, tmp_path, monkeypatch):
    cfg('database = "from-file.db"\n')  # relative: from the config's folder, not the working folder
    file_db, env_db, opt_db = tmp_path / "cfg" / "from-file.db", tmp_path / "env.db", tmp_path / "opt.db"

    monkeypatch.delenv("STICKSLIP_DB")
    ok("where", "--offline", "--set", "3=1mm")
    assert _has_q3(file_db, 1e-3) and not (tmp_path / "work" / "from-file.db").exists()
    assert settings()["database"] == {"value": str(file_db), "source": "file", "where": str(tmp_path / "cfg" /
                                      "config.toml"), "exists": True}

    monkeypatch.setenv("STICKSLIP_DB", str(env_db))
    ok("where", "--offline", "--set", "3=2mm")
    assert _has_q3(env_db, 2e-3) and _has_q3(file_db, 1e-3)
    assert settings()["database"]["source"] == "env" and settings()["database"]["where"] == "$STICKSLIP_DB"

    ok("where", "--offline", "--set", "3=3mm", "--db", opt_db)
    assert _has_q3(opt_db, 3e-3) and _has_q3(env_db, 2e-3) and _has_q3(file_db, 1e-3)
    s = settings("--db", opt_db)["database"]
    assert (s["value"], s["source"], s["where"]) == (str(opt_db), "option", "--db")

    cfg("")  # nothing in the file, no variable: the data folder
    monkeypatch.delenv("STICKSLIP_DB")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    s = settings()["database"]
    assert s["source"] == "default"
    if sys.platform.startswith("linux"):
        assert s["value"] == str(tmp_path / "data" / "stickslip" / "stickslip.db")


def test_demo_and_history_use_the_files_database(cfg, tmp_path, monkeypatch):
    monkeypatch.delenv("STICKSLIP_DB")
    cfg(f"database = {json.dumps(str(tmp_path / 'lab.db'))}\n")
    r = run("history", "--json")
    assert "no database at " + str(tmp_path / "lab.db") in one_error(r)  # read-only commands name the file's db


# ---------------------------------------------------------------- device: option > file > default


def test_device_every_level(cfg):
    assert json.loads(ok("where", "--offline", "--json").stdout)["device"] == "sim://"
    assert settings()["device"] == {"value": "sim://", "source": "default", "where": ""}

    cfg('device = "sim://?seed=7"\n')
    assert json.loads(ok("where", "--offline", "--json").stdout)["device"] == "sim://?seed=7"
    assert settings()["device"]["source"] == "file"

    out = json.loads(ok("where", "--offline", "--json", "-d", "sim://?seed=3").stdout)
    assert out["device"] == "sim://?seed=3"
    shown = settings("-d", "sim://?seed=3")["device"]
    assert shown == {"value": "sim://?seed=3", "source": "option", "where": "--device"}


def test_a_move_drives_the_files_device_and_keeps_its_positions_under_it(cfg, tmp_path):
    path = tmp_path / "cal.json"
    calibration(7).save(path)
    cfg(f'device = "sim://?seed=7"\ncalibration = {json.dumps(str(path))}\n')
    out = json.loads(ok("move", "-j", "3", "--by", "30um", "--json").stdout)
    assert out["device"] == "sim://?seed=7" and out["steps"] > 0
    # it really moved: the simulated arm ends within about a step (~1 um) of the planned 30 um
    assert out["q_end_predicted"] == pytest.approx(30e-6, abs=1e-6)
    assert abs(out["sim_true_end"] - out["q_end_predicted"]) < 1e-6
    kept = json.loads(ok("where", "--offline", "--json", "-d", "sim://?seed=7").stdout)["joints"][2]["q"]
    assert kept == pytest.approx(out["q_end_predicted"], abs=1e-12)
    assert json.loads(ok("where", "--offline", "--json", "-d", "sim://").stdout)["joints"][2]["q"] == 0.0
    # the arm the file chose is named on stderr (the text output would not say which arm moved)
    text = ok("move", "-j", "3", "--by", "1um")
    assert f"device sim://?seed=7 (from {tmp_path / 'cfg' / 'config.toml'})" in text.stderr
    assert "device sim://" not in ok("move", "-j", "3", "--by", "1um", "-d", "sim://?seed=7").stderr


# ---------------------------------------------------------------- calibration: option > file > none


def _plan_steps(*args: object) -> int:
    return json.loads(ok("plan", "-j", "3", "--from", "2mm", "--to", "2.5mm", "--json", *args).stdout)["steps"]


def test_calibration_every_level(cfg, tmp_path):
    a, b = tmp_path / "cfg" / "a.json", tmp_path / "b.json"
    calibration(4).save(a)
    calibration(11).save(b)
    by_a, by_b = _plan_steps("-c", a), _plan_steps("-c", b)
    assert by_a != by_b  # two arms, two step sizes: the test can tell which calibration planned

    msg = one_error(run("plan", "-j", "3", "--from", "2mm", "--to", "2.5mm"))
    assert "no calibration: give --calibration CAL.json, or set calibration in the config file" in msg
    assert settings()["calibration"] == {"value": None, "source": "default", "where": "", "exists": None}

    cfg('calibration = "a.json"\n')  # relative to the config's folder
    assert _plan_steps() == by_a
    assert settings()["calibration"]["source"] == "file" and settings()["calibration"]["exists"] is True
    assert _plan_steps("-c", b) == by_b  # the option wins
    assert settings("-c", b)["calibration"]["source"] == "option"

    shown = json.loads(ok("show", "--json").stdout)  # `show` without its argument shows the file's calibration
    assert shown == json.loads(ok("show", a, "--json").stdout)
    # `suggest` too: the file's calibration designs the same poses as naming it
    suggested = json.loads(ok("suggest", "-j", "3", "--n", "1", "--json").stdout)
    assert suggested == json.loads(ok("suggest", "-j", "3", "--n", "1", "--json", "-c", a).stdout)
    assert suggested != json.loads(ok("suggest", "-j", "3", "--n", "1", "--json", "-c", b).stdout)


def test_a_calibration_the_file_names_but_that_is_gone_names_the_config(cfg, tmp_path):
    path = cfg('calibration = "gone.json"\n')
    msg = one_error(run("predict", tmp_path / "poses.csv"))
    gone = tmp_path / "cfg" / "gone.json"
    assert msg == f"error: {path}: calibration: {gone} does not exist (give --calibration, or fix the config file)"


# ---------------------------------------------------------------- max_age_days: option > env > file > 0


def test_max_age_every_level(cfg, tmp_path, monkeypatch):
    path = tmp_path / "old.json"
    calibration(4, day="2026-11-19").save(path)  # 3 days before the pinned today
    move = ("move", "-j", "3", "--by", "10um", "-c", path, "--json")

    def warns(*extra: object) -> bool:
        return "calibration is from 2026-11-19" in ok(*move, *extra).stderr

    assert warns() and settings()["max_age_days"] == {"value": 0, "source": "default", "where": ""}
    cfg("max_age_days = 3\n")
    assert not warns() and settings()["max_age_days"]["source"] == "file"
    monkeypatch.setenv("STICKSLIP_MAX_AGE_DAYS", "2")
    assert warns() and settings()["max_age_days"] == {"value": 2, "source": "env", "where": "$STICKSLIP_MAX_AGE_DAYS"}
    assert not warns("--max-age", "5")
    assert settings("--max-age", "5")["max_age_days"] == {"value": 5, "source": "option", "where": "--max-age"}
    # predict reads the same setting: 3 days old is fresh with the file's 3 (the variable unset)
    monkeypatch.delenv("STICKSLIP_MAX_AGE_DAYS")
    poses = tmp_path / "poses.csv"
    poses.write_text("joint,direction,q1,q2,q3,theta,psi\n3,+,0,-1.5707963,0,0,0\n", encoding="utf-8")
    assert "calibration is from" not in ok("predict", poses, "-c", path).stderr
    cfg("max_age_days = 2\n")
    assert "calibration is from 2026-11-19" in ok("predict", poses, "-c", path).stderr


# ---------------------------------------------------------------- geometry: option > file > default


def _start_tip(*args: object) -> list[float]:
    r = ok("reach", "--by", "0,5um,0", "--dry-run", "--json", *args)
    return json.loads(r.stdout)["start"]["tip"]


def test_geometry_every_level(cfg, tmp_path):
    path = tmp_path / "cal.json"
    calibration(4).save(path)
    # the kept pose is outstretched (q1 = 0, q2 = -90deg, q3 = 0): the tip is at x = offset + length (design.md §9)
    assert _start_tip("-c", path) == pytest.approx([kin.DEFAULT_GEOMETRY.length, 0, 0], abs=1e-12)
    assert settings()["geometry"]["source"] == "default"
    cfg(f'calibration = {json.dumps(str(path))}\n[geometry]\noffset = "2mm"\nlength = "30mm"\n')
    assert _start_tip() == pytest.approx([0.032, 0, 0], abs=1e-12)
    assert settings()["geometry"] == {
        "value": {"offset": pytest.approx(0.002), "length": pytest.approx(0.03)},
        "source": "file",
        "where": str(tmp_path / "cfg" / "config.toml"),
    }
    assert _start_tip("--geometry", "0,25mm") == pytest.approx([0.025, 0, 0], abs=1e-12)
    assert settings("--geometry", "0,25mm")["geometry"]["source"] == "option"
    cfg(f'calibration = {json.dumps(str(path))}\n[geometry]\nlength = "24mm"\n')  # only one: offset stays 0
    assert _start_tip() == pytest.approx([0.024, 0, 0], abs=1e-12)


def test_a_geometry_the_arm_cannot_have_is_refused_naming_the_file(cfg, tmp_path):
    path = cfg('[geometry]\nlength = "2m"\n')
    msg = one_error(run("config", "show"))
    assert msg.startswith(f"error: {path}: [geometry]: geometry length = 2 m must be in (0, 1] m")


# ---------------------------------------------------------------- the file's faults: one line, never a secret


@pytest.mark.parametrize(
    "args",
    [
        ("config", "show"),
        ("where", "--offline"),
        ("move", "-j", "3", "--by", "1um", "-c", "x.json"),
        ("reach", "--by", "1um,0,0", "-c", "x.json", "--dry-run"),
    ],
)
def test_a_password_in_the_files_device_stops_the_command_and_is_never_printed(cfg, args):
    path = cfg('device = "anc300://admin:hunter2@10.0.0.2:7230"\n')
    r = run(*args)
    msg = one_error(r)
    assert msg.startswith(f"error: {path}:1: device: a password in the device URL is refused")
    assert "hunter2" not in r.output and "hunter2" not in r.stderr


def test_a_password_with_a_slash_in_the_files_device_is_refused_as_a_password_not_quoted_as_a_port(cfg):
    """urllib reads `pa` of `pa/ss` as the port, and its message quoted it; the file's password is refused first."""
    path = cfg('device = "anc300://admin:pa/ss@10.0.0.2:7230"\n')
    r = run("where")
    assert one_error(r).startswith(f"error: {path}:1: device: a password in the device URL is refused")
    assert "pa/ss" not in r.output + r.stderr and "'pa'" not in r.output + r.stderr


def test_a_password_on_the_command_line_is_redacted_by_config_show(cfg):
    r = ok("config", "show", "-d", "anc300://u:hunter2@h?password=hunter2")
    assert "hunter2" not in r.stdout and "anc300://u:***@h?password=***" in r.stdout
    s = settings("-d", "anc300://u:hunter2@h?password=hunter2")
    assert s["device"]["value"] == "anc300://u:***@h?password=***"


def test_the_files_faults_are_one_line_naming_file_and_line(cfg):
    path = cfg('# lab\ndevise = "sim://"\n')
    assert one_error(run("where", "--offline")) == (
        f"error: {path}:2: unknown key 'devise' (did you mean 'device'? known: calibration, database, device, "
        "geometry, max_age_days)"
    )
    cfg("[geometry\n")
    assert one_error(run("config", "show")).startswith(f"error: {path}:1:")


def test_a_broken_file_stops_only_the_commands_that_read_it(cfg, tmp_path, monkeypatch):
    """`calibrate` takes nothing from the file, so a broken file does not stop it; `where` does, and stops."""
    path = cfg("this is not toml\n")
    assert str(path) in one_error(run("where", "--offline"))
    ok("where", "--offline", "-d", "sim://")  # the device given, the database from $STICKSLIP_DB: not read
    monkeypatch.delenv("STICKSLIP_DB")
    assert str(path) in one_error(run("where", "--offline", "-d", "sim://"))  # now it reads the file for --db
    assert str(path) not in one_error(run("calibrate", tmp_path / "missing.csv"))  # fails for its own reason
    ok("where", "--offline", "-d", "sim://", "--db", tmp_path / "s.db")  # every setting given: the file is not read


# ---------------------------------------------------------------- config path / init


def test_config_path_prints_only_the_path(cfg, tmp_path):
    p = tmp_path / "cfg" / "config.toml"
    assert ok("config", "path").stdout == f"{p}\n"
    assert json.loads(ok("config", "path", "--json").stdout) == {
        "path": str(p), "exists": False, "source": "env", "where": "$STICKSLIP_CONFIG"}


def test_config_init_writes_the_template_and_refuses_to_overwrite(cfg, tmp_path, monkeypatch):
    p = tmp_path / "cfg" / "deeper" / "config.toml"
    monkeypatch.setenv(ENV_CONFIG, str(p))
    assert str(p) in ok("config", "init").stdout
    assert p.read_text(encoding="utf-8") == template()
    p.write_text('device = "sim://?seed=3"\n', encoding="utf-8")
    msg = one_error(run("config", "init"))
    assert msg == f"error: {p} exists: keep it, or overwrite it with --force"
    assert p.read_text(encoding="utf-8") == 'device = "sim://?seed=3"\n'
    ok("config", "init", "--force")
    assert p.read_text(encoding="utf-8") == template()
    shown = json.loads(ok("config", "show", "--json").stdout)
    assert shown["config"] == {"path": str(p), "found": True, "sets": {}}
    assert {s["source"] for s in shown["settings"].values()} <= {"default", "env"}


def test_config_init_where_a_file_stands_for_the_folder_is_one_line(cfg, tmp_path, monkeypatch):
    (tmp_path / "afile").write_text("x", encoding="utf-8")
    monkeypatch.setenv(ENV_CONFIG, str(tmp_path / "afile" / "sub" / "config.toml"))
    msg = one_error(run("config", "init"))
    target = tmp_path / "afile" / "sub"
    assert msg.startswith(f"error: cannot write {target / 'config.toml'}: cannot create the folder {target} (")


@pytest.mark.skipif(sys.platform == "win32", reason="a read-only folder is a POSIX permission here")
def test_config_init_into_a_folder_it_cannot_write_is_one_line(cfg, tmp_path, monkeypatch):
    import os

    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        monkeypatch.setenv(ENV_CONFIG, str(folder / "config.toml"))
        assert "cannot write" in one_error(run("config", "init"))
    finally:
        folder.chmod(0o700)


def test_config_show_says_where_the_file_is_and_that_it_is_missing(cfg, tmp_path):
    out = " ".join(ok("config", "show").stdout.split())  # a long path is put on a line of its own, never broken
    assert f"config file: {tmp_path / 'cfg' / 'config.toml'} (not there" in out
    for name in ("device", "calibration", "database", "max_age_days", "geometry"):
        assert name in out


def test_config_path_and_help_load_no_numpy(tmp_path):
    code = (
        "import sys; from stickslip.cli import main; sys.argv = ['stickslip', 'config', 'path']\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('numpy', 'scipy', 'matplotlib') if m in sys.modules))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == "[]"
