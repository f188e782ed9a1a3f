"""The store on both backends (the ``db`` fixture: an SQLite file, a PostgreSQL schema): round trips, schema
versioning, concurrent writers, crash safety. Tests of the SQLite file's own mechanics (its header, PRAGMAs) take
``tmp_path`` alone."""

from __future__ import annotations

import datetime as dt
import json
import math
import multiprocessing as mp
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import pytest

from stickslip import storage
from stickslip.measurements import Traverse, measurements_to_csv
from stickslip.storage import SCHEMA_VERSION, ConstraintError, Store, StoreError, stale_message, warn_if_stale


def _t(day="2026-11-20", joint=3, direction="+", steps=12000, q2=-math.pi / 2, theta=0.0):
    start, end = (0.0, 0.012) if direction == "+" else (0.012, 0.0)
    return Traverse(day, joint, direction, 0.0, q2, 0.0, theta, 0.0, start, end, steps)


def test_round_trip_keeps_every_field_exactly(db):
    rows = [
        _t(steps=12001, q2=-1.2345678901234567),
        _t(direction="-", steps=13313, theta=-0.5),
        Traverse(
            "day2",
            2,
            "-",
            0.1,
            0.0,
            0.012,
            -math.pi / 2,
            0.25,
            math.pi / 6,
            -7 * math.pi / 6,
            104729,
        ),
    ]
    with Store.open(db) as st:
        ids = [st.add_traverse(t, device="sim://", how="simulated") for t in rows]
        assert ids == sorted(ids) and len(set(ids)) == 3
        assert st.traverses() == rows  # floats survive bit for bit (SQLite's REAL and PostgreSQL's float8: doubles)
        assert list(st.iter_traverses(chunk=2)) == rows  # read 2 at a time (PostgreSQL: a cursor on the server)
        assert st.traverses(day="day2") == [rows[2]]
        assert st.traverses(joint=3) == rows[:2]
        assert st.traverses(device="other://") == []
        assert st.days() == ["2026-11-20", "day2"]
        rec = st.traverse_records(day="day2")[0]
        assert rec["how"] == "simulated" and rec["device"] == "sim://"


def test_measured_at_is_stored_as_utc(db):
    when = dt.datetime(2026, 11, 20, 9, 30, tzinfo=dt.timezone(dt.timedelta(hours=2)))
    with Store.open(db) as st:
        st.add_traverse(_t(), measured_at=when)
        assert st.traverse_records()[0]["measured_at"] == "2026-11-20T07:30:00.000000+00:00"


def test_add_traverses_is_all_or_nothing(db, monkeypatch):
    bad = Traverse("", 3, "+", 0, 0, 0, 0, 0, 0, 0.012, 10)
    with Store.open(db) as st:
        with pytest.raises(ValueError, match="empty day"):
            st.add_traverses([_t(), bad])
        assert st.count_traverses() == 0
        with pytest.raises(ValueError, match="steps must be a whole number"):  # the store's own check comes first
            st.add_traverses([_t(), Traverse("d", 3, "+", 0, 0, 0, 0, 0, 0, 0.012, 0)])
        # the database's own CHECK constraints hold too, and roll the batch back (one error type on both backends)
        monkeypatch.setattr(type(st), "_check", staticmethod(lambda t: t))
        with pytest.raises(ConstraintError, match="steps"):
            st.add_traverses([_t(), Traverse("d", 3, "+", 0, 0, 0, 0, 0, 0, 0.012, 0)])
        monkeypatch.undo()
        assert st.count_traverses() == 0 and st.days() == []  # nor the session it made on the way
        ids = st.add_traverses([_t(), _t(direction="-")], device="sim://", how="imported", source="abc")
        assert len(ids) == 2 and st.has_source("abc") and not st.has_source("xyz")


def test_history_counts_per_day_and_direction(db):
    with Store.open(db) as st:
        for _ in range(3):
            st.add_traverse(_t("2026-11-20"))
        st.add_traverse(_t("2026-11-20", direction="-"))
        st.add_traverse(_t("2026-11-21", joint=2, direction="-", steps=5), device="serial:///dev/ttyUSB0")
        h = st.history()
        assert [(e["device"], e["day"], e["traverses"]) for e in h] == [
            ("serial:///dev/ttyUSB0", "2026-11-21", 1),
            ("sim://", "2026-11-20", 4),
        ]
        assert h[1]["by_joint"] == {"3+": 3, "3-": 1}
        assert st.history(device="sim://") == h[1:]
        assert st.days(device="sim://") == ["2026-11-20"]


def test_device_state_round_trip(db):
    with Store.open(db) as st:
        assert st.get_state("sim://", "position") is None
        st.set_state("sim://", "position", {"q1": 0.0, "q2": -1.5707963267948966, "q3": 0.006})
        st.set_state("sim://", "position", '{"q1": 0.1, "q2": -1.0, "q3": 0.001}')  # JSON text works too
        assert st.get_state("sim://", "position") == {"q1": 0.1, "q2": -1.0, "q3": 0.001}
        assert st.get_state("other://", "position", default=7) == 7


def test_schema_is_versioned_and_newer_files_are_refused(tmp_path):
    p = tmp_path / "s.db"
    with Store.open(p) as st:
        assert st.schema_version == SCHEMA_VERSION == len(storage.MIGRATIONS)
        assert st.integrity_check() == "ok"
    con = sqlite3.connect(p)
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.commit()
    con.close()
    with pytest.raises(StoreError, match="newer than this stickslip"):
        Store.open(p)


def test_not_a_database_is_a_clear_error(tmp_path):
    p = tmp_path / "junk.db"
    p.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(StoreError, match="junk.db"):
        Store.open(p)


def test_path_resolution(tmp_path, monkeypatch):
    monkeypatch.setenv("STICKSLIP_DB", str(tmp_path / "env.db"))
    assert storage.resolve_db_path() == tmp_path / "env.db"
    assert storage.resolve_db_path(tmp_path / "x.db") == tmp_path / "x.db"
    monkeypatch.delenv("STICKSLIP_DB")
    if sys.platform.startswith("linux"):
        monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
        assert storage.resolve_db_path() == tmp_path / "xdg" / "stickslip" / "stickslip.db"
        monkeypatch.delenv("XDG_DATA_HOME")
        monkeypatch.setenv("HOME", str(tmp_path))
        assert storage.default_db_path() == tmp_path / ".local" / "share" / "stickslip" / "stickslip.db"


def test_stale_warning():
    msg = stale_message("2026-11-20", today="2026-11-21")
    assert msg == (
        "calibration is from 2026-11-20, today is 2026-11-21 (1 day old): recalibrate "
        "(the paper found day-to-day changes significant)"
    )
    assert "(3 days old)" in stale_message("2026-11-18", today="2026-11-21")
    assert stale_message("2026-11-18", today="2026-11-21", max_age_days=3) is None
    assert stale_message("2026-11-17", today="2026-11-21", max_age_days=3) is not None
    assert stale_message("2026-11-21", today="2026-11-21") is None
    assert stale_message("2026-11-22", today="2026-11-21") is None  # later is not stale
    assert stale_message("day1", today="day2") is not None  # unordered labels: differ -> warn
    assert stale_message(None, today="day2") is None

    class Cal:
        day = "2020-01-01"

    assert "today is 2026-11-22 " in warn_if_stale(Cal())  # default today: the pinned one (conftest)


# ---------------------------------------------------------------- concurrency and crashes


def _writer(path: str, who: int, n: int) -> None:  # path: a file or a URL (its password in $PGPASSWORD)
    with Store.open(path) as st:
        for k in range(n):
            st.add_traverse(_t(day=f"w{who}", steps=1000 * (who + 1) + k), device=f"sim://?seed={who + 1}")


@pytest.mark.slow
def test_concurrent_writers_lose_no_rows(db):
    """4 processes x 25 traverses each, all opening a fresh database at once: 100 rows, none lost."""
    path = str(db)
    n_proc, n_rows = 4, 25
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(path, w, n_rows)) for w in range(n_proc)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
        assert p.exitcode == 0
    with Store.open(path) as st:
        assert st.count_traverses() == n_proc * n_rows
        for w in range(n_proc):
            got = sorted(t.steps for t in st.traverses(device=f"sim://?seed={w + 1}"))
            assert got == [1000 * (w + 1) + k for k in range(n_rows)]
        assert st.integrity_check() == "ok"
        assert len(st.devices()) == n_proc and len(st.days()) == n_proc  # each made once, though all raced to


_KILL_SCRIPT = textwrap.dedent("""
    import sys
    from stickslip.measurements import Traverse
    from stickslip.storage import Store
    with Store.open(sys.argv[1]) as st:
        k = 0
        while True:
            k += 1
            st.add_traverse(Traverse("2026-11-20", 3, "+", 0.0, -1.5, 0.0, 0.0, 0.0, 0.0, 0.012, k))
            print(k, flush=True)
""")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_kill_minus_9_mid_session_keeps_every_completed_traverse(db):
    path = db
    proc = subprocess.Popen([sys.executable, "-c", _KILL_SCRIPT, str(path)], stdout=subprocess.PIPE, text=True)
    done = 0
    for line in proc.stdout:  # noqa: B007  (read until enough rows are committed)
        done = int(line)
        if done >= 40:
            break
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(10)
    proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    with Store.open(path) as st:
        assert st.integrity_check() == "ok"
        steps = [t.steps for t in st.traverses()]
    # every traverse reported as committed is there, in order, with nothing half-written
    assert steps[:done] == list(range(1, done + 1))
    assert steps == list(range(1, len(steps) + 1))


# ---------------------------------------------------------------- calibrations


def _calibration(day="2026-11-20"):
    from stickslip.calibration import calibrate

    rows = []
    for q2, th, n_plus, n_minus in (
        (-math.pi / 2, 0.0, 12346, 13348),
        (0.0, -math.pi / 2, 16900, 17790),
        (0.0, 0.0, 25010, 11100),
        (-1.0, -0.5, 13000, 14000),
    ):
        rows.append(Traverse(day, 3, "+", 0.0, q2, 0.0, th, 0.0, 0.0, 0.012, n_plus))
        rows.append(Traverse(day, 3, "-", 0.0, q2, 0.0, th, 0.0, 0.012, 0.0, n_minus))
    return calibrate(rows, method="lsq"), rows


def test_calibrations_round_trip_with_their_traverses(db):
    cal, rows = _calibration()
    with Store.open(db) as st:
        assert st.latest_calibration() is None
        ids = st.add_traverses(rows, device="sim://")
        cid = st.add_calibration(cal, "sim://", ids)
        back = st.latest_calibration("sim://")
        assert back.to_dict() == cal.to_dict()
        assert st.calibration(cid).parameters() == cal.parameters()
        assert st.calibration_traverses(cid) == rows
        assert st.latest_calibration("other://") is None
        with pytest.raises(ValueError, match="no stored traverse with id 999"):
            st.add_calibration(cal, "sim://", [999])
        h = st.history("sim://")
        assert h[0]["calibrations"][0]["method"] == "lsq" and h[0]["traverses"] == 8


# ---------------------------------------------------------------- command line


def test_cli_import_history_export_round_trip(tmp_path, db):
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import read_measurements, write_measurements

    runner = CliRunner()
    meas, out = tmp_path / "m.csv", tmp_path / "out.csv"
    rows = [_t("2026-11-20"), _t("2026-11-20", direction="-", steps=13000), _t("2026-11-21", steps=12500)]
    write_measurements(meas, rows)
    r = runner.invoke(app, ["import", str(meas), "--db", str(db), "--device", "sim://", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["imported"] == 3
    r = runner.invoke(app, ["import", str(meas), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2 and "imported before" in r.output  # same file twice: refused
    r = runner.invoke(app, ["history", "--db", str(db), "--json"])
    assert [(e["day"], e["traverses"]) for e in json.loads(r.stdout)] == [("2026-11-20", 2), ("2026-11-21", 1)]
    r = runner.invoke(app, ["export", "--db", str(db), "--day", "2026-11-20", "-o", str(out)])
    assert r.exit_code == 0 and read_measurements(out) == rows[:2]
    r = runner.invoke(app, ["export", "--db", str(db), "--day", "2020-01-01", "-o", str(out)])
    assert r.exit_code == 2 and "stored days: 2026-11-20, 2026-11-21" in r.output
    # an option that picks no other arm names the same device: the filter finds its rows (it found none before)
    r = runner.invoke(app, ["export", "--db", str(db), "-d", "sim://?realtime=1", "-o", str(tmp_path / "r.csv")])
    assert r.exit_code == 0 and read_measurements(tmp_path / "r.csv") == rows, r.output
    # a simulator's seed is another simulated arm: none stored; the database is not empty, nothing written
    r = runner.invoke(app, ["export", "--db", str(db), "-d", "sim://?seed=3", "-o", str(tmp_path / "n.csv")])
    assert r.exit_code == 2 and not (tmp_path / "n.csv").exists()
    assert r.stderr.strip() == ("error: no traverses match device sim://?seed=3 (the devices with traverses: "
                                "sim://; a device is its URL without options, but a simulator's seed picks "
                                "another arm)"), r.stderr
    r = runner.invoke(app, ["export", "--db", str(db), "-d", "sim://", "-j", "2", "-o", str(tmp_path / "n.csv")])
    assert r.stderr.strip() == "error: no traverses match device sim://, joint 2 (stored days: 2026-11-20, 2026-11-21)"


def test_cli_import_reports_every_bad_row_and_stores_nothing(tmp_path, db):
    from typer.testing import CliRunner

    from stickslip.cli import app

    bad = tmp_path / "bad.csv"
    bad.write_text(
        "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n"
        "d1,3,+,0,0,0,0,0,0,0.012,12000\n"
        "d1,3,+,0,0,0,0,0,0,0.012,-5\n"
        "d1,7,+,0,0,0,0,0,0,0.012,12000\n"
    )
    r = CliRunner().invoke(app, ["import", str(bad), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2
    assert "bad.csv:3: steps must be a positive integer" in r.output and "bad.csv:4: unknown joint" in r.output
    with Store.open(db) as st:
        assert st.count_traverses() == 0


def _columns(st, table):
    """The columns of ``table``, by each engine's own catalogue."""
    if st.backend == "sqlite":
        return [r[1] for r in st._con.execute(f"PRAGMA table_info({table})")]
    sql = "SELECT column_name FROM information_schema.columns WHERE table_schema = current_schema() AND table_name = ?"
    return [r[0] for r in st._con.execute(sql, (table,))]


def _version_on_disk(db):
    """The schema version the database says, read without the store (which would migrate it)."""
    if not isinstance(db, str):
        con = sqlite3.connect(db)
        try:
            return con.execute("PRAGMA user_version").fetchone()[0]
        finally:
            con.close()
    import psycopg

    with psycopg.connect(db) as con:
        return con.execute("SELECT version FROM stickslip_marker").fetchone()[0]


def test_opening_an_older_file_runs_the_missing_migrations_and_keeps_the_data(db, monkeypatch):
    p = db
    with Store.open(p) as st:
        st.add_traverse(_t(steps=4242))
        assert st.upgraded_from is None  # made new: nothing upgraded
    future = (*storage.MIGRATIONS, "ALTER TABLE traverses ADD COLUMN note TEXT; CREATE TABLE extra (x INTEGER)")
    # the store's, the SQLite file check's (which refuses a newer file before opening it), and the reference
    # integrity_check compares to
    for module in (storage.base, storage.sqlite, storage.schema):
        monkeypatch.setattr(module, "MIGRATIONS", future)
    monkeypatch.setattr(storage.base, "SCHEMA_VERSION", len(future))
    with Store.open(p) as st:
        assert st.upgraded_from == len(future) - 1  # said once, by the command that upgraded it (the CLI: a line)
        assert st.schema_version == len(future)
        assert [t.steps for t in st.traverses()] == [4242]
        assert "note" in _columns(st, "traverses") and _columns(st, "extra") == ["x"]
        assert st.integrity_check() == "ok"
    with Store.open(p) as st:
        assert st.upgraded_from is None
    # a migration that fails leaves the file at its old version, untouched
    broken = (*future, "CREATE TABLE extra (x INTEGER)")  # 'extra' exists already
    monkeypatch.setattr(storage.base, "MIGRATIONS", broken)
    monkeypatch.setattr(storage.sqlite, "MIGRATIONS", broken)
    monkeypatch.setattr(storage.base, "SCHEMA_VERSION", len(broken))
    with pytest.raises(StoreError, match="not a usable stickslip database"):
        Store.open(p)
    assert _version_on_disk(p) == len(future)
    if not isinstance(p, str):  # the copy made before the failed upgrade is gone with it; the earlier one is kept
        assert sorted(x.name for x in p.parent.iterdir() if ".v" in x.name) == [f"s.v{len(future) - 1}.db"]


def test_cli_reading_commands_refuse_a_missing_database(tmp_path, db):
    from typer.testing import CliRunner

    from stickslip.cli import app

    missing = tmp_path / "nope.db" if not isinstance(db, str) else db  # a file not there; an empty schema
    for args in (["history"], ["export", "-o", str(tmp_path / "x.csv")], ["anova"], ["fit"]):
        r = CliRunner().invoke(app, [*args, "--db", str(missing)])
        assert r.exit_code == 2 and "no database at" in r.output, args
    if isinstance(db, str):  # nothing was created in the schema
        import psycopg

        with psycopg.connect(db) as con:
            assert con.execute("SELECT count(*) FROM pg_tables WHERE schemaname = current_schema()").fetchone() == (0,)
    else:
        assert not missing.exists()


def test_cli_fit_record_from_the_database_links_the_traverses(db):
    from typer.testing import CliRunner

    from stickslip.cli import app

    cal, rows = _calibration("2026-11-21")
    with Store.open(db) as st:
        st.add_traverses(rows, device="mm3a:///dev/ttyUSB0")
    r = CliRunner().invoke(app, ["fit", "--db", str(db), "--record", "--json"])
    assert r.exit_code == 0, r.output
    cid = json.loads(r.stdout)["stored_id"]
    with Store.open(db) as st:
        assert st.calibrations()[0]["device"] == "mm3a:///dev/ttyUSB0"
        assert st.calibration_traverses(cid) == rows
        assert st.latest_calibration("mm3a:///dev/ttyUSB0").day == "2026-11-21"


def test_cli_fit_record_of_a_table_needs_its_device(db, tmp_path):
    """`fit TABLE --record` without -d filed the calibration under sim:// (a guess, as `import`'s default was)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    _cal, rows = _calibration("2026-11-21")
    table = tmp_path / "t.csv"
    table.write_text(measurements_to_csv(rows))
    r = CliRunner().invoke(app, ["fit", str(table), "--db", str(db), "--record", "--json"])
    assert r.exit_code == 2 and "fit TABLE --record needs --device" in " ".join(r.stderr.split()), r.output
    with Store.open(db) as st:
        assert not st.calibrations()  # nothing stored
    r = CliRunner().invoke(app, ["fit", str(table), "--db", str(db), "--record", "-d", "mm3a://COM4", "--json"])
    assert r.exit_code == 0, r.output
    with Store.open(db) as st:
        assert [c["device"] for c in st.calibrations()] == ["mm3a://com4"]  # the device's one name


# ---------------------------------------------------------------- duplicates


def test_import_refuses_rows_already_stored_unless_allowed(tmp_path, db):
    from synth import paper_table
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import measurements_to_csv

    runner = CliRunner()
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    rows = paper_table()
    a.write_text(measurements_to_csv(rows))
    b.write_text(measurements_to_csv(rows[:3]) + "\n")  # other bytes, the same three measurements
    assert runner.invoke(app, ["import", str(a), "-d", "sim://", "--db", str(db)]).exit_code == 0
    r = runner.invoke(app, ["import", str(b), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2 and "3 of 3 rows are already stored for sim:// (same day, pose" in r.stderr
    assert "rows 2, 3, 4" in r.stderr
    with Store.open(db) as st:
        assert st.count_traverses() == 14
    r = runner.invoke(app, ["import", str(b), "-d", "sim://", "--db", str(db), "--allow-duplicates"])
    assert r.exit_code == 0, r.output
    with Store.open(db) as st:
        assert st.count_traverses() == 17
        assert st.duplicates(rows[:2], "sim://") == [0, 1]
        assert st.duplicates(rows[:2], "sim://?seed=9") == []  # another device: not a duplicate


def test_a_schema_2_database_gets_content_keys_on_migration(tmp_path):
    import sqlite3

    from synth import paper_table

    from stickslip.storage import MIGRATIONS, content_key
    from stickslip.storage.schema import _split_sql

    path = tmp_path / "old.db"
    con = sqlite3.connect(path)
    for script in MIGRATIONS[:2]:
        for stmt in _split_sql(script):
            con.execute(stmt)
    con.execute("PRAGMA user_version = 2")
    con.execute("INSERT INTO devices (id, url, created_at) VALUES (1, 'sim://', 'x')")
    con.execute("INSERT INTO sessions (id, device_id, day, created_at) VALUES (1, 1, '2026-11-22', 'x')")
    t = paper_table()[0]
    con.execute(
        'INSERT INTO traverses (session_id, joint, direction, q1, q2, q3, theta, psi, start, "end", steps, '
        "measured_at, how) VALUES (1, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, 'x', 'old')",
        (t.joint, t.direction, t.q1, t.q2, t.q3, t.theta, t.psi, t.start, t.end, t.steps),
    )
    con.commit()
    con.close()
    with Store.open(path) as st:
        assert st.schema_version == SCHEMA_VERSION == 5
        assert st.duplicates([t], "sim://") == [0]
        key = st._con.execute("SELECT content FROM traverses").fetchone()[0]
        assert key == content_key(t, "sim://")
        assert st.integrity_check() == "ok"


def test_a_database_carries_stickslips_application_id_and_one_made_before_it_is_stamped(tmp_path):
    """PRAGMA application_id says a file is ours; one of ours without it (older releases) is known by its tables."""
    from stickslip.storage import APPLICATION_ID

    p = tmp_path / "s.db"
    with Store.open(p) as st:
        st.add_traverse(_t(steps=4242))

    def app_id() -> int:
        con = sqlite3.connect(p)
        try:
            return int(con.execute("PRAGMA application_id").fetchone()[0])
        finally:
            con.close()

    assert app_id() == APPLICATION_ID == 0x5374536C
    con = sqlite3.connect(p)
    con.execute("PRAGMA application_id = 0")  # as every database made before the id was set
    con.commit()
    con.close()
    with Store.open(p) as st:
        assert [t.steps for t in st.traverses()] == [4242] and st.integrity_check() == "ok"
    assert app_id() == APPLICATION_ID
    # one more table than a stickslip schema has: another application's file, refused untouched
    con = sqlite3.connect(p)
    con.execute("PRAGMA application_id = 0")
    con.execute("CREATE TABLE photos (x)")
    con.commit()
    con.close()
    before = p.read_bytes()
    with pytest.raises(StoreError, match="another application"):
        Store.open(p)
    assert p.read_bytes() == before


def test_a_file_another_process_is_making_is_looked_at_again_not_refused(tmp_path, monkeypatch):
    """Another stickslip process makes the file (id, version and tables in one transaction) while this one looks:
    the header read before its tables still says version 0, the tables are stickslip's. Looked at again, it is ours;
    a file that changes at every look is refused in one line."""
    from stickslip.storage import sqlite as backend

    p = tmp_path / "s.db"
    with Store.open(p):
        pass
    stamp = (backend.APPLICATION_ID, SCHEMA_VERSION)

    def set_header(app_id: int, version: int) -> None:
        con = sqlite3.connect(p)
        con.execute(f"PRAGMA application_id = {app_id}")
        con.execute(f"PRAGMA user_version = {version}")
        con.commit()
        con.close()

    set_header(0, 0)  # the moment before the other process's transaction reached the file
    real_tables = backend._tables

    def tables_then_stamped(path):  # ... which it does between this process's two reads of the header
        tables = real_tables(path)
        set_header(*stamp)
        return tables

    monkeypatch.setattr(backend, "_tables", tables_then_stamped)
    assert backend.check_database_file(p) == "ours"

    looks = iter(range(100, 200))

    def tables_then_changed(path):  # a file rewritten at every look (its schema version: 100, 101, ...)
        tables = real_tables(path)
        set_header(0, next(looks))
        return tables

    set_header(0, 0)
    monkeypatch.setattr(backend, "_tables", tables_then_changed)
    with pytest.raises(StoreError, match="kept changing"):
        backend.check_database_file(p, looks=3)


def test_tables_unreadable_while_another_process_writes_the_file_are_looked_at_again(tmp_path, monkeypatch):
    """A WAL copied back page by page reads as damaged until it is done: a file that changed is looked at again;
    one that stayed the same is damaged (seen once: a Bluesky example's axes opening one new file at once)."""
    from stickslip.storage import sqlite as backend

    p = tmp_path / "new.db"
    con = sqlite3.connect(p)
    con.execute("CREATE TABLE t (x)")  # an SQLite file without stickslip's id: its tables are read
    con.commit()
    con.close()
    real_tables = backend._tables
    calls = []

    def damaged_while_written(path):
        calls.append(path)
        if len(calls) == 1:  # the other process's pages land while this process reads them
            with open(path, "ab") as f:
                f.write(b"\0" * 4096)
            raise StoreError(f"the database {path} is damaged or not a database (malformed)")
        return real_tables(path)

    monkeypatch.setattr(backend, "_tables", damaged_while_written)
    with pytest.raises(StoreError, match="another application"):  # judged on the second look, from its tables
        backend.check_database_file(p)
    assert len(calls) == 2

    def damaged(path):
        calls.append(path)
        raise StoreError(f"the database {path} is damaged or not a database (malformed)")

    calls.clear()
    monkeypatch.setattr(backend, "_tables", damaged)
    with pytest.raises(StoreError, match="damaged"):  # nothing wrote it: damaged, after one look
        backend.check_database_file(p)
    assert len(calls) == 1


def test_cli_empty_db_option_is_refused_not_taken_for_the_default(tmp_path, monkeypatch):
    """``--db ""`` (an unset shell variable) must not record into $STICKSLIP_DB's database."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    env_db = tmp_path / "env.db"
    monkeypatch.setenv("STICKSLIP_DB", str(env_db))
    meas = tmp_path / "m.csv"
    meas.write_text("joint,direction,steps\n1,+,1000\n", encoding="utf-8")
    for value in ("", "  "):
        for args in (["history"], ["import", str(meas), "-d", "sim://"]):
            r = CliRunner().invoke(app, [*args, "--db", value])
            assert r.exit_code == 2, (args, r.output)
            assert "--db is empty" in r.output and "Traceback" not in r.output, r.output
    assert not env_db.exists()


def test_the_command_that_upgrades_an_older_database_says_so_once(tmp_path, monkeypatch):
    # an older store was upgraded in place without a word: an older stickslip sharing the file then refused it as
    # newer, and nobody had been told why (audit37's question)
    from typer.testing import CliRunner

    from stickslip.cli import app

    p = tmp_path / "old.db"
    with Store.open(p) as st:
        st.add_traverse(_t(steps=4242))
    future = (*storage.MIGRATIONS, "CREATE TABLE extra (x INTEGER)")
    for module in (storage.base, storage.sqlite, storage.schema):
        monkeypatch.setattr(module, "MIGRATIONS", future)
    monkeypatch.setattr(storage.base, "SCHEMA_VERSION", len(future))
    runner = CliRunner()
    first = runner.invoke(app, ["history", "--db", str(p)])
    again = runner.invoke(app, ["history", "--db", str(p)])
    assert first.exit_code == 0 and again.exit_code == 0, first.output
    said = " ".join(first.stderr.split())
    copy = p.with_name(f"old.v{len(future) - 1}.db")  # the file as it was, kept before the upgrade (audit37)
    assert said.count("note:") == 1 and "warning:" not in said and (
        f"note: upgraded the database {p} from schema version {len(future) - 1} to {len(future)} (docs/storage.md); "
        f"the file as it was is kept as {copy}, which an older stickslip still reads") in said, said
    assert "upgraded" not in again.stderr
    con = sqlite3.connect(copy)
    assert con.execute("PRAGMA user_version").fetchone()[0] == len(future) - 1
    assert con.execute("SELECT steps FROM traverses").fetchall() == [(4242,)]
    con.close()
    assert sorted(x.name for x in tmp_path.iterdir() if "part" in x.name) == []
