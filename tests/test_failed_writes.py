"""audit37: writes that fail for the reasons labs meet (a full disk, a read-only folder) never lose earlier data.

Each test says what failed before its fix. A full disk is simulated portably (a write raising ``ENOSPC``);
a read-only folder by the error the operating system gives, so nothing here needs POSIX permissions or root.
"""

from __future__ import annotations

import errno
import json
import os
import sqlite3
import sys
from pathlib import Path

import pytest
from full_disk import filling_fdopen
from synth import paper_table
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.storage import Store
from stickslip.storage import sqlite as sqlite_backend

runner = CliRunner()


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_error(r) -> str:
    """Exit 2 and one ``error:`` line (warnings allowed before it), no traceback; returns it."""
    assert r.exit_code == 2, (r.exit_code, r.output)
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines and lines[-1].startswith("error:"), r.stderr
    assert all(ln.startswith(("error:", "warning:")) for ln in lines), r.stderr
    return lines[-1]


def _store(tmp_path):
    db = tmp_path / "s.db"
    with Store.open(db) as st:
        st.add_traverses(paper_table(), device="sim://")
    return db


def test_a_backup_on_a_full_disk_names_the_backup_asked_for_not_its_part_file(tmp_path, monkeypatch):
    # said 'error: cannot write the backup /lab/.copy.db.2363-34fb405f.part: database or disk is full': a file
    # the user never named, and which was already removed
    db = _store(tmp_path)
    out = tmp_path / "copy.db"

    def full(self, target, *a, **k):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(sqlite_backend._Connection, "backup", full, raising=False)
    line = one_error(run("backup", out, "--db", db))
    assert line == f"error: cannot write the backup {out}: database or disk is full; nothing was written"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.db"]


def test_a_backup_into_a_read_only_folder_names_the_backup_asked_for(tmp_path, monkeypatch):
    # said 'error: /lab/.copy.db.2363-34fb405f.part: Read-only file system' (the rename into place failed)
    db = _store(tmp_path)
    out = tmp_path / "copy.db"

    def refuse(src, dst):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(src))

    from stickslip.storage import base

    monkeypatch.setattr(base.os, "replace", refuse)
    line = one_error(run("backup", out, "--db", db))
    assert line == f"error: cannot write the backup {out}: {os.strerror(errno.EROFS)}; nothing was written"
    assert ".part" not in line and sorted(p.name for p in tmp_path.iterdir()) == ["s.db"]
    with Store.open(db) as st:
        assert st.count_traverses() == len(paper_table()) and st.integrity_check() == "ok"


def disk_fills_after(monkeypatch, limit: int, code: int = errno.ENOSPC) -> dict:
    """Every file opened for writing through ``os.fdopen`` (the atomic writes) fails after ``limit`` bytes."""
    seen = {"n": 0, "failed": False}
    monkeypatch.setattr(os, "fdopen", filling_fdopen(limit, code, seen))
    return seen


def test_a_recording_on_a_full_disk_is_one_line_and_keeps_the_old_one(tmp_path, monkeypatch):
    # libsndfile wrote the WAV into the temporary file itself: each write or seek that failed inside its cffi
    # callbacks printed 'Exception ignored from cffi callback ... Traceback ... OSError: [Errno 28]' (8 of them
    # on a full tmpfs) before the error line; a disk that filled mid-file ended `stickslip record` with
    # soundfile's own AssertionError (a traceback, exit 1; seen on a 3 MB tmpfs with 336 kB free)
    import sys

    import numpy as np

    from stickslip.audio.sources import write_wav

    out = tmp_path / "j2.wav"
    write_wav(out, np.zeros(4800), 48000)
    before = out.read_bytes()
    ignored: list[object] = []
    monkeypatch.setattr(sys, "unraisablehook", ignored.append)
    seen = disk_fills_after(monkeypatch, 1000)
    try:
        write_wav(out, np.ones(48000), 48000)
    except OSError as e:
        text = str(e)
    else:
        raise AssertionError("the write should have failed")
    assert seen["failed"] and ignored == []
    assert text == f"cannot write {out}: {os.strerror(errno.ENOSPC)}; the old file is kept as it was"
    assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["j2.wav"]


def _record(tmp_path, folder, *extra):
    return run("record", folder / "r.wav", "--joint", "2", "--device", "sim://?seed=3", "--db", tmp_path / "s.db",
               *extra)


def test_a_recording_whose_label_or_tuning_cannot_be_written_says_which_and_what_was_kept(tmp_path, monkeypatch):
    # record said 'cannot write r.wav: No space left on device' when r.wav had been written and its label r.json
    # had not (the old label, of another recording, stayed beside the new WAV, unmentioned); a tuning that could not
    # be written lost '; the old file is kept as it was'
    sizes = tmp_path / "sizes"
    sizes.mkdir()
    assert _record(tmp_path, sizes, "--tune", sizes / "t.json").exit_code == 0
    wav, label = (sizes / "r.wav").stat().st_size, (sizes / "r.json").stat().st_size
    for name, limit in (("r.json", wav + 5), ("t.json", wav + label + 5)):
        d = tmp_path / name
        d.mkdir()
        for old in ("r.wav", "r.json", "t.json"):
            (d / old).write_text(f"the old {old}\n")
        monkeypatch.undo()
        seen = disk_fills_after(monkeypatch, limit)
        line = one_error(_record(tmp_path, d, "--tune", d / "t.json"))
        assert seen["failed"]
        kept = f"cannot write {d / name}: {os.strerror(errno.ENOSPC)}; the old file is kept as it was"
        assert line.startswith(f"error: {kept}"), line
        assert (d / name).read_text() == f"the old {name}\n"
        if name == "r.json":
            assert line.endswith(f"; the recording {d / 'r.wav'} was written (its stop is at 2.016 s)"), line
        assert (d / "r.wav").stat().st_size == wav  # the new recording
        assert sorted(p.name for p in d.iterdir()) == ["r.json", "r.wav", "t.json"]  # no temporary file left


def test_config_init_on_a_full_disk_says_the_old_file_is_kept(tmp_path, monkeypatch):
    # said 'cannot write .../config.toml: No space left on device' (whether the old file was kept, not said)
    cfg = tmp_path / "config.toml"
    cfg.write_text("# mine\n")
    monkeypatch.setenv("STICKSLIP_CONFIG", str(cfg))
    disk_fills_after(monkeypatch, 10)
    line = one_error(run("config", "init", "--force"))
    assert line == f"error: cannot write {cfg}: {os.strerror(errno.ENOSPC)}; the old file is kept as it was"
    assert cfg.read_text() == "# mine\n" and sorted(p.name for p in tmp_path.iterdir()) == ["config.toml"]


def test_a_store_from_a_newer_stickslip_is_refused_without_a_byte_changed(tmp_path):
    # refused, but only after opening it had switched its journal from DELETE to WAL (header bytes 18-19 from 1 to 2,
    # the change counter bumped, -wal and -shm made beside it): a newer stickslip keeping its file in rollback mode
    # (a network share, where WAL's shared memory does not work) found it in WAL mode
    from stickslip.storage.schema import SCHEMA_VERSION

    db = _store(tmp_path)
    con = sqlite3.connect(db)
    con.execute("PRAGMA journal_mode = DELETE")
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.commit()
    con.close()
    before = db.read_bytes()
    commands = (["history"], ["where", "--offline"], ["where", "--offline", "--set", "3=1mm"],
                ["backup", tmp_path / "b.db"])
    for cmd in commands:
        line = one_error(run(*cmd, "--db", db))
        assert f"schema version {SCHEMA_VERSION + 1}, newer than this stickslip understands" in line, line
        assert db.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["s.db"], cmd


def test_a_store_that_cannot_be_opened_on_a_full_disk_or_in_a_read_only_folder_says_why(tmp_path, monkeypatch):
    # on a full disk every command, reading ones too, said only 'cannot open the database s.db: disk I/O error'; in a
    # read-only folder (a share mounted read-only) 'unable to open database file' of a file that is there and readable
    # (SQLite makes s.db-shm beside it to read a WAL database). The words are SQLite's, as it says them on Linux
    # (a 6 MB tmpfs filled; a read-only bind mount)
    db = _store(tmp_path)

    def failing(text):
        def connect(path):
            raise sqlite3.OperationalError(text)
        return connect

    monkeypatch.setattr(sqlite_backend, "_connect", failing("disk I/O error"))
    line = one_error(run("history", "--db", db))
    assert line == f"error: cannot open the database {db}: disk I/O error (is the disk full? even reading needs room " \
                   "for s.db-shm beside it)"
    monkeypatch.setattr(sqlite_backend, "_connect", failing("unable to open database file"))
    assert one_error(run("history", "--db", db)).endswith("unable to open database file")  # a writable folder
    monkeypatch.setattr(sqlite_backend.os, "access", lambda path, mode: False)
    line = one_error(run("where", "--offline", "--db", db))
    assert line == (f"error: cannot open the database {db}: unable to open database file (its folder {tmp_path} is "
                    "read-only: SQLite needs to make s.db-shm beside it, even to read; copy the file into a folder you "
                    "can write, and give --db the copy)")


def test_a_move_cut_short_by_a_full_disk_says_where_each_joint_is_kept(tmp_path, monkeypatch):
    # said only 'cannot write to the database ...: database or disk is full (free some space); nothing of this change
    # was stored', though bursts had been sent (97 um of joint 3 here): the kept state was honest (uncertain over the
    # burst whose confirmation was lost) but the line read as if the joint had not moved; and with the disk still
    # full, releasing the device lock failed too and its error replaced the first
    from stickslip.measurements import measurements_to_csv

    table = tmp_path / "t.csv"
    table.write_text(measurements_to_csv(paper_table()))
    cal = tmp_path / "cal.json"
    assert run("calibrate", table, "-o", cal).exit_code == 0
    real = sqlite_backend._Connection.execute
    # the commits: the lock, the pose, the controller's identity kept at its first opening (devices.identity), then
    # the first burst's intent (5) and its confirmation (6)
    for first, kept in ((5, "joint 3 uncertain, 2000 µm to 2097.2 µm"), (6, "joint 3 2097.2 µm (dead-reckoned)")):
        db = tmp_path / f"s{first}.db"
        assert run("where", "--offline", "--db", db, "--set", "3=2mm").exit_code == 0
        commits = {"n": 0}

        def execute(self, sql, params=(), /, first=first, commits=commits):
            if sql == "COMMIT":  # the disk fills before this write transaction and stays full
                commits["n"] += 1
                if commits["n"] >= first:
                    raise sqlite3.OperationalError("database or disk is full")
            return real(self, sql, params)

        monkeypatch.setattr(sqlite_backend._Connection, "execute", execute)
        line = one_error(run("move", "--db", db, "-c", cal, "-j", "3", "--by", "300um", "--burst", "100"))
        monkeypatch.undo()
        assert line.startswith(f"error: cannot write to the database {db}: database or disk is full"), line
        assert line.endswith(f"the move of joint 3 stopped at that write; as kept now: joint 1 0 deg (default); "
                             f"joint 2 -90 deg (default); {kept}"), line
        j3 = json.loads(run("where", "--offline", "--db", db, "--json").stdout)["joints"][2]  # what the line says
        want = ("uncertain", False) if first == 5 else ("dead-reckoned", True)
        assert (j3["source"], j3["uncertain"] is None) == want
        assert round(1e6 * (j3["uncertain"] or [j3["q"]])[-1], 1) == 2097.2


@pytest.mark.slow  # seconds: in make test, out of the fast tier
def test_a_report_cut_short_by_a_full_disk_leaves_the_earlier_report_whole(tmp_path, monkeypatch):
    # each figure was written atomically, but one after the other: a disk that filled after the first left the new
    # fig4_prismatic.png beside the old index.html and the old other figures (a page describing one calibration
    # showing another's figure), and the old fig4 lost
    from stickslip.calibration import calibrate
    from stickslip.records import WriteError
    from stickslip.report import build_report

    rows = paper_table()
    cal = calibrate(rows)
    out = tmp_path / "report"
    first = build_report(cal, rows, out, dpi=30, seed_simulation="exact")
    names = sorted(p.name for p in out.iterdir())
    assert len(names) == len(first.figures) + 1 >= 5
    size = first.figures[0].stat().st_size
    for name in names:
        (out / name).write_bytes(b"the earlier report's " + name.encode())
    for limit in (size - 1, size + 1, 10**9):  # within the first figure, just after it, never
        seen = disk_fills_after(monkeypatch, limit)
        if limit < 10**9:
            try:
                build_report(cal, rows, out, dpi=30, seed_simulation="exact")
            except WriteError as e:
                assert "; the old file is kept as it was" in str(e)
            else:
                raise AssertionError("the write should have failed")
            assert seen["failed"]
            assert {n: (out / n).read_bytes() for n in names} == {n: b"the earlier report's " + n.encode()
                                                                 for n in names}, limit
        else:
            build_report(cal, rows, out, dpi=30, seed_simulation="exact")
            assert not seen["failed"] and b"<html" in (out / "index.html").read_bytes()[:200].lower()
        assert sorted(p.name for p in out.iterdir()) == names  # no temporary file left
        monkeypatch.undo()


def test_demo_results_cut_short_by_a_full_disk_leave_the_earlier_run_whole(tmp_path, monkeypatch):
    # measurements.csv, calibration.json and summary.json were written one after the other: a disk that filled after
    # the first left this run's measurements beside an earlier run's calibration and summary
    from stickslip.procedures.demo import run_demo
    from stickslip.records import WriteError

    out = tmp_path / "results"
    first = run_demo(seed=6, day="2026-11-22", out=out, switch="oracle", validation=False, repeats=0)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["calibration.json", "measurements.csv", "summary.json"]
    size = Path(first.files["measurements"]).stat().st_size
    for name in names:
        (out / name).write_text(f"an earlier run's {name}\n")
    disk_fills_after(monkeypatch, size + 1)
    try:
        run_demo(seed=7, day="2026-11-23", out=out, switch="oracle", validation=False, repeats=0)
    except WriteError as e:
        assert str(e).startswith(f"cannot write {out / 'calibration.json'}: "), str(e)
    else:
        raise AssertionError("the write should have failed")
    assert {n: (out / n).read_text() for n in names} == {n: f"an earlier run's {n}\n" for n in names}
    assert sorted(p.name for p in out.iterdir()) == names


def test_a_database_whose_folder_cannot_be_made_is_one_plain_line(tmp_path, monkeypatch):
    # said "cannot create the directory for the database /share/new/s.db: [Errno 30] Read-only file system:
    # '/share/new'" (Python's repr of the error; seen with STICKSLIP_DB in a folder to make on a read-only mount)
    db = tmp_path / "new" / "s.db"

    def refuse(self, *a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))

    monkeypatch.setattr(Path, "mkdir", refuse)
    line = one_error(run("where", "--offline", "--set", "3=1mm", "--db", db))
    assert line == f"error: cannot create the folder {db.parent} for the database {db}: {os.strerror(errno.EROFS)}"


@pytest.mark.skipif(sys.platform == "win32", reason="Windows limits the whole path to 260 characters unless long "
                    "paths are enabled: a 250-character name in a temporary folder is over it")
@pytest.mark.parametrize("stem", ["a" * 246, "µ" * 123])  # 250 and 250 bytes with '.csv' / '.db', under 255
def test_a_file_name_near_the_limit_is_written(tmp_path, stem):
    # its temporary file (.NAME.xxxxxxxx.tmp, 14 bytes more; a backup's .NAME.PID-xxxxxxxx.part, 23 more) was over
    # the file system's 255: 'cannot write .../aaa...a.csv: File name too long; nothing was written' for a name
    # `touch` makes
    from stickslip.records import atomic_write_text

    out = tmp_path / f"{stem}.csv"
    assert len(out.name.encode()) == 250
    atomic_write_text(out, "x\n")
    assert out.read_text() == "x\n" and [p.name for p in tmp_path.iterdir()] == [out.name]
    db = _store(tmp_path)
    copy = tmp_path / f"{stem}.db"
    r = run("backup", copy, "--db", db)
    assert r.exit_code == 0, r.output
    with Store.open(copy) as st:
        assert st.count_traverses() == len(paper_table())


def test_a_read_only_output_file_is_refused_not_replaced(tmp_path, monkeypatch):
    # a calibration made read-only (chmod a-w) to keep it was replaced by 'calibrate -o cal.json': the atomic write
    # renames a new file over it, which POSIX allows whenever the folder is writable (a plain open(..., 'w') is
    # refused; Windows refuses the rename: the same command differed by platform). os.access reports the file
    # read-only for this user (root may write anything, as with a plain write)
    from stickslip.measurements import measurements_to_csv

    table = tmp_path / "t.csv"
    table.write_text(measurements_to_csv(paper_table()))
    cal = tmp_path / "cal.json"
    cal.write_text("kept\n")
    real = os.access
    def access(path, mode, **k):
        return False if Path(path) == cal and mode & os.W_OK else real(path, mode, **k)

    monkeypatch.setattr(os, "access", access)
    line = one_error(run("calibrate", table, "-o", cal))
    assert line == f"error: cannot write {cal}: the file is read-only; the old file is kept as it was"
    assert cal.read_text() == "kept\n" and sorted(p.name for p in tmp_path.iterdir()) == ["cal.json", "t.csv"]


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="POSIX permission bits; root ignores them")
def test_a_chmod_read_only_output_file_is_kept(tmp_path):
    from stickslip.records import WriteError, atomic_write_text

    out = tmp_path / "cal.json"
    out.write_text("kept\n")
    out.chmod(0o444)
    with pytest.raises(WriteError, match="the file is read-only"):
        atomic_write_text(out, "new\n")
    assert out.read_text() == "kept\n"


def test_a_server_token_that_could_not_be_written_leaves_no_empty_file(tmp_path, monkeypatch):
    # on a full disk `stickslip serve` created the token file (O_EXCL) and failed writing it: the empty file stayed,
    # and once space was freed every later serve waited 1 s and refused it ('does not hold a token (it is empty)
    # (delete it: a new one is made)') until it was deleted by hand
    from stickslip.server.security import load_or_create_token

    p = tmp_path / "token"
    disk_fills_after(monkeypatch, 0)
    try:
        load_or_create_token(p)
    except OSError as e:
        assert e.errno == errno.ENOSPC
    else:
        raise AssertionError("the write should have failed")
    assert not p.exists()
    monkeypatch.undo()
    token, new = load_or_create_token(p)
    assert new and len(token) >= 32 and p.read_text() == token + "\n"


def test_a_log_file_on_a_full_disk_is_one_warning_not_a_traceback_per_line(tmp_path, capsys):
    # logging's FileHandler printed '--- Logging error ---', a traceback and 'Message: ...' on stderr for every record
    # it could not write (-vv with a real controller: every message to and from it), while the command went on
    import logging

    from stickslip.cli import _logging

    log = tmp_path / "run.log"
    _logging(0, log)
    try:
        handler = next(h for h in logging.getLogger("stickslip").handlers if getattr(h, "_stickslip_cli", False))

        class Full:
            def write(self, text):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

            def flush(self):
                pass

        handler.stream.close()
        handler.stream = Full()
        for i in range(3):
            logging.getLogger("stickslip.devices.transport").debug("sent %d", i)
        err = capsys.readouterr().err
    finally:
        _logging(0, None)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines == [f"warning: cannot write the log file {log}: {os.strerror(errno.ENOSPC)}; nothing more is logged "
                     "to it"], err


def _paper_calibration(tmp_path) -> Path:
    from stickslip.measurements import measurements_to_csv

    table = tmp_path / "t.csv"
    table.write_text(measurements_to_csv(paper_table()))
    cal = tmp_path / "cal.json"
    assert run("calibrate", table, "-o", cal).exit_code == 0
    return cal


def test_camera_calibrate_refuses_a_jacobian_calibration_without_a_measured_joint_before_moving(tmp_path):
    # the paper's calibration has joints 2 and 3: measuring joint 1 too, the run drove every joint and ended in
    # "KeyError: 'joint 1 is not in this calibration'" (a traceback, exit 1) after writing steps.csv and not j.json
    cal = _paper_calibration(tmp_path)
    db = tmp_path / "s.db"
    before = run("where", "--offline", "--db", db, "--json").stdout
    r = run("camera", "calibrate", "-d", "sim://", "--camera", "simcam://?pixel=0.5um", "--db", db,
            "-o", tmp_path / "steps.csv", "--jacobian", tmp_path / "j.json", "-c", cal)
    line = one_error(r)
    assert line == ("error: --calibration models joint(s) 2, 3, not joint(s) 1 of --joints: --jacobian scales each "
                    "measured joint by its steps (calibrate them, or measure --joints without them); nothing was moved")
    assert run("where", "--offline", "--db", db, "--json").stdout == before
    assert not (tmp_path / "steps.csv").exists() and not (tmp_path / "j.json").exists()


@pytest.mark.slow  # seconds: in make test, out of the fast tier
def test_camera_calibrate_writes_its_step_sizes_and_jacobian_together(tmp_path, monkeypatch):
    # steps.csv was written, then j.json: a disk that filled between them left this run's step sizes beside an
    # earlier run's Jacobian
    cal = _paper_calibration(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    args = ["camera", "calibrate", "-d", "sim://", "--camera", "simcam://?pixel=0.5um", "--db", tmp_path / "s.db",
            "-o", out / "steps.csv", "--jacobian", out / "j.json", "-c", cal, "--joints", "3,2"]
    assert run(*args).exit_code == 0
    size = (out / "steps.csv").stat().st_size
    for name in ("steps.csv", "j.json"):
        (out / name).write_text(f"an earlier run's {name}\n")
    disk_fills_after(monkeypatch, size + 1)
    line = one_error(run(*args))
    assert line == f"error: cannot write {out / 'j.json'}: {os.strerror(errno.ENOSPC)}; the old file is kept as it was"
    assert {p.name: p.read_text() for p in out.iterdir()} == {n: f"an earlier run's {n}\n"
                                                            for n in ("steps.csv", "j.json")}


def test_an_older_store_that_cannot_be_upgraded_says_so_not_that_it_is_unusable(tmp_path, monkeypatch):
    # every command, reading ones too, upgrades an older stickslip's database when it opens it: on a full disk (or a
    # read-only file) that said 'X is not a usable stickslip database: cannot write to the database X: database or
    # disk is full ...', of a sound database; a new one could not be made either, called the same
    from stickslip.storage.schema import MIGRATIONS, SCHEMA_VERSION

    old = tmp_path / "old.db"
    con = sqlite3.connect(old)
    con.executescript(MIGRATIONS[0])
    con.execute("PRAGMA user_version = 1")
    con.execute("INSERT INTO devices (url, model, created_at) VALUES ('sim://', NULL, 'x')")
    con.commit()
    con.execute("PRAGMA journal_mode = WAL")  # as every stickslip left its files
    con.close()
    before = old.read_bytes()
    real = sqlite_backend._Connection.execute

    def full(self, sql, params=(), /):
        if sql == "COMMIT":
            raise sqlite3.OperationalError("database or disk is full")
        return real(self, sql, params)

    monkeypatch.setattr(sqlite_backend._Connection, "execute", full)
    line = one_error(run("history", "--db", old))
    assert line == (f"error: cannot upgrade the database {old} from schema version 1 (an older stickslip's) to "
                    f"{SCHEMA_VERSION}, which every command does before it reads: database or disk is full (free some "
                    "space); it is left as it was")
    assert old.read_bytes() == before
    new = tmp_path / "new.db"
    line = one_error(run("where", "--offline", "--set", "3=1mm", "--db", new))
    assert line == f"error: cannot make the database {new}: database or disk is full (free some space); nothing was " \
                   "written"


def test_a_traverse_the_database_refuses_keeps_its_row(tmp_path, monkeypatch):
    # the traverse was measured (minutes of a rig's time), then storing it failed on a full disk: the one line said
    # 'cannot write to the database ...; nothing of this change was stored' and the row was gone, not even appended
    # to the --append table it was asked into
    from types import SimpleNamespace

    from stickslip.audio.detector import Tuning
    from stickslip.kinematics import Pose
    from stickslip.measurements import read_measurements
    from stickslip.procedures import session
    from stickslip.storage import StoreError

    row = paper_table()[0]
    monkeypatch.setattr(session, "_measure", lambda *a, **k: SimpleNamespace(traverse=row))
    db, table = tmp_path / "s.db", tmp_path / "day.csv"
    request = session.TraverseRequest("sim://", row.joint, row.direction, Pose(0.0, -1.5707963, 0.0, 0.0, 0.0),
                                      row.day, Tuning(band_hz=(5600, 7100), threshold_db=-40.0), append=table)
    with Store.open(db) as st:
        real = sqlite_backend._Connection.execute
        row_written = {"yes": False}

        def full(self, sql, params=(), /):
            if "INSERT INTO traverses" in sql:  # the lock and the journal were written; the disk fills with the row
                row_written["yes"] = True
            if sql == "COMMIT" and row_written["yes"]:
                raise sqlite3.OperationalError("database or disk is full")
            return real(self, sql, params)

        monkeypatch.setattr(sqlite_backend._Connection, "execute", full)
        try:
            session.traverse(st, request, progress=False)
        except StoreError as e:
            text = str(e)
        else:
            raise AssertionError("storing the row should have failed")
        monkeypatch.undo()
        assert st.count_traverses() == 0
    line = text.split("its row: ")[-1]
    assert text.startswith(f"cannot write to the database {db}: database or disk is full"), text
    assert f"the traverse was measured but not stored, joint {row.joint} is kept uncertain" in text
    assert f"stickslip where -d {request.device} --set {row.joint}=min at the lower, =max at the upper" in text
    assert f"it is appended to {table}; " in text and line.split(",")[:3] == [row.day, str(row.joint), row.direction]
    assert read_measurements(table) == [row]


def test_a_reach_cut_short_by_a_full_disk_says_where_each_joint_is_kept(tmp_path, monkeypatch):
    # as a move's (above): 'nothing of this change was stored' after the first burst of joint 3 had been sent
    from server_support import true_calibration

    url = "sim://?seed=4&day=2026-11-22"
    cal = tmp_path / "cal.json"
    true_calibration(url).save(cal)
    real = sqlite_backend._Connection.execute
    commits = {"n": 0}

    def execute(self, sql, params=(), /):
        if sql == "COMMIT":  # the lock, the pose, the identity kept, the first burst's intent; the disk fills before
            commits["n"] += 1  # its confirmation
            if commits["n"] >= 6:
                raise sqlite3.OperationalError("database or disk is full")
        return real(self, sql, params)

    monkeypatch.setattr(sqlite_backend._Connection, "execute", execute)
    db = tmp_path / "s.db"
    line = one_error(run("reach", "-c", cal, "--db", db, "--by", "20um,-10um,5um", "-d", url, "--burst", "20"))
    monkeypatch.undo()
    assert line.endswith("; nothing of this change was stored; the straight tip move stopped at that write; as kept "
                         "now: joint 1 0 deg (default); joint 2 -90 deg (default); joint 3 uncertain, 0 µm to "
                         "0.973038 µm"), line
    j3 = json.loads(run("where", "--offline", "--db", db, "-d", url, "--json").stdout)["joints"][2]
    assert j3["source"] == "uncertain" and j3["uncertain"][0] == 0.0 and round(j3["uncertain"][1] * 1e6, 6) == 0.973038
