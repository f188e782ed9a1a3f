"""The two storage backends: what differs behind the seam, and what must not.

* the same schema on both (tables and columns; PostgreSQL's column types are doubles and 64-bit integers);
* a database that is not stickslip's is refused without a write, on both (a PostgreSQL schema with other
  tables and no marker; a marker of another owner; a newer schema version);
* a password in a PostgreSQL URL never reaches a message, a log record or a stored row;
* a writer killed inside its transaction leaves no partial rows and no lock behind, on both;
* the device lock: one holder at a time on both; on PostgreSQL a lock whose process died is free on any host;
* ``--db``, ``$STICKSLIP_DB`` and the config file's ``database`` take a URL as well as a file;
* a server that goes away mid-command, or never answers, is one line (exit 2);
* two rigs in two processes share one history.
"""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from stickslip import config, storage
from stickslip.measurements import Traverse
from stickslip.storage import ConstraintError, Store, StoreError, describe_database, resolve_database

ROW = Traverse("2026-11-20", 3, "+", 0.0, -math.pi / 2, 0.0, 0.0, 0.0, 0.0, 0.012, 12000)


def _admin(server, schema: str, sql: str) -> list[tuple[object, ...]]:
    return server.admin(sql, schema=schema)


def _schema_of(url: str) -> str:
    return url.rsplit("%3D", 1)[1]


# ---------------------------------------------------------------- where the database is


def test_a_url_is_a_server_and_anything_else_a_file(tmp_path, monkeypatch):
    url = "postgresql://rig@db.lab:5432/stickslip"
    assert resolve_database(url) == url and resolve_database("postgres://h/d") == "postgres://h/d"
    assert resolve_database(tmp_path / "a.db") == tmp_path / "a.db"
    assert resolve_database("C://data/s.db") == Path("C://data/s.db")  # a drive letter is no scheme
    monkeypatch.setenv("STICKSLIP_DB", url)
    assert resolve_database(None) == url
    with pytest.raises(StoreError, match=r"^\$STICKSLIP_DB: mysql:// is not a database") as e:
        monkeypatch.setenv("STICKSLIP_DB", "mysql://u:hunter2@h/d")
        resolve_database(None)
    assert "hunter2" not in str(e.value)
    # the config file takes the same schemes as the store
    assert config.DATABASE_SCHEMES == storage.POSTGRES_SCHEMES


_CLEAN = "postgresql://rig@db.lab:5432/stickslip?options=-csearch_path%3Dlab"


@settings(max_examples=200, deadline=None)
@given(password=st.text(st.characters(blacklist_categories=("Cs",)), min_size=1, max_size=24))
@example(password="opti")  # drawn once (hypothesis took it from the word 'options'): part of the URL masked
@example(password="word")  # part of the option's name "password"
@example(password="rig@")
def test_a_url_is_shown_the_same_whatever_its_password(password):
    """The shown form does not depend on the password: percent-encoded, written raw, or as an option.

    A password of 4 characters or more is masked wherever it shows (describe_database's last
    guard), so one whose characters are also part of the host, path or options masks them there.
    """
    encoded = _CLEAN.replace("rig@", f"rig:{quote(password, safe='')}@")
    forms = [f for f in (quote(password, safe=""), password) if len(f) >= 4]
    shown = describe_database(encoded)
    if not any(f in _CLEAN for f in forms):
        assert shown == _CLEAN
    else:
        assert not any(f in shown for f in forms), shown
    raw = _CLEAN.replace("rig@", f"rig:{password}@")  # not encoded: '/', '?', '@', ':' inside it
    if password not in _CLEAN:
        assert password not in describe_database(raw)
    as_option = f"{_CLEAN}&password={quote(password, safe='')}"
    if not any(f in f"{_CLEAN}&password=***" for f in forms):
        assert describe_database(as_option) == f"{_CLEAN}&password=***"
    else:
        assert not any(f in describe_database(as_option) for f in forms)


def test_without_psycopg_the_message_names_the_extra(monkeypatch, tmp_path):
    from typer.testing import CliRunner

    from stickslip.cli import app

    monkeypatch.setitem(sys.modules, "psycopg", None)  # import psycopg raises ImportError
    with pytest.raises(StoreError, match=r"needs psycopg.*pip install 'stickslip\[postgres\]'"):
        Store.open("postgresql://rig:hunter2@127.0.0.1/stickslip")
    r = CliRunner().invoke(app, ["history", "--db", "postgresql://rig:hunter2@127.0.0.1/stickslip"])
    assert r.exit_code == 2 and "stickslip[postgres]" in r.stderr and "hunter2" not in r.output
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.output


def test_a_server_that_is_not_there_is_one_line_without_the_password(tmp_path):
    pytest.importorskip("psycopg")
    from typer.testing import CliRunner

    from stickslip.cli import app

    url = "postgresql://rig:hunter2-secret@127.0.0.1:1/stickslip?connect_timeout=2"
    r = CliRunner().invoke(app, ["history", "--db", url])
    assert r.exit_code == 2, r.output
    assert r.stderr.startswith("error: cannot connect to the database postgresql://rig@127.0.0.1:1/stickslip")
    assert "hunter2" not in r.output and r.stderr.count("\n") == 1


def _terminate_stickslips_connections(server) -> None:
    """What a server that is stopped or restarted does to its clients: end every stickslip connection."""
    server.admin(
        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
        "WHERE application_name = 'stickslip' AND pid <> pg_backend_pid()",
        dbname="postgres",
    )


@pytest.mark.parametrize("command", ["history", "export", "import"])
def test_a_server_that_goes_away_mid_command_is_one_line_exit_2(
    command, postgres_server, postgres_url, monkeypatch, tmp_path
):
    from typer.testing import CliRunner

    from stickslip.cli import app

    with Store.open(postgres_url) as st:
        st.add_traverse(ROW, device="sim://")
    opened = Store.open.__func__  # type: ignore[attr-defined]

    def open_then_lose_the_server(cls, *args, **kwargs):
        store = opened(cls, *args, **kwargs)
        _terminate_stickslips_connections(postgres_server)  # between opening and the command's work
        return store

    args = {
        "history": ["history"],
        "export": ["export", "-o", str(tmp_path / "out.csv")],
        "import": ["import", str(_table(tmp_path)), "-d", "sim://", "--allow-duplicates"],
    }[command]
    with monkeypatch.context() as m:
        m.setattr(Store, "open", classmethod(open_then_lose_the_server))
        r = CliRunner().invoke(app, [*args, "--db", postgres_url])
    assert r.exit_code == 2, r.output
    assert r.stderr.startswith(f"error: cannot read the database {describe_database(postgres_url)}: ")
    assert "(the server or the network went away)" in r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.output and r.stdout == ""
    assert not (tmp_path / "out.csv").exists()
    with Store.open(postgres_url) as st:  # the server is still there for the next connection; nothing half-done
        assert st.count_traverses() == 1


@pytest.mark.slow
def test_a_server_that_never_answers_is_one_line_after_the_connect_timeout(monkeypatch):
    """A host that accepts the connection and then says nothing (a hung server): no hang, one line."""
    pytest.importorskip("psycopg")
    import socket

    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.storage import postgres

    for k in [k for k in os.environ if k.startswith("PG")]:
        monkeypatch.delenv(k)
    monkeypatch.setattr(postgres, "CONNECT_TIMEOUT_S", 2)  # libpq's smallest; the default is 10 s
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(4)  # the kernel completes the handshake; nobody ever reads or answers
        port = silent.getsockname()[1]
        url = f"postgresql://rig:hunter2-secret@127.0.0.1:{port}/stickslip"
        r = CliRunner().invoke(app, ["history", "--db", url])
    assert r.exit_code == 2, r.output
    assert r.stderr.startswith(f"error: cannot connect to the database postgresql://rig@127.0.0.1:{port}/stickslip")
    assert "timeout" in r.stderr and "is the server running" in r.stderr
    assert "hunter2" not in r.output and r.stderr.count("\n") == 1


# ---------------------------------------------------------------- one schema on both engines


def test_the_same_tables_and_columns_on_both_and_doubles_on_postgresql(postgres_url, postgres_server, tmp_path):
    with Store.open(tmp_path / "s.db") as a, Store.open(postgres_url) as b:
        assert a.schema_version == b.schema_version == storage.SCHEMA_VERSION
        assert a.integrity_check() == b.integrity_check() == "ok"
        assert (a.backend, b.backend) == ("sqlite", "postgresql")
    schema = _schema_of(postgres_url)
    types = dict(
        _admin(
            postgres_server,
            schema,
            "SELECT column_name, data_type FROM information_schema.columns "
            f"WHERE table_schema = '{schema}' AND table_name = 'traverses'",
        )
    )
    assert types["q2"] == types["theta"] == "double precision"  # not REAL's 4 bytes
    assert types["id"] == types["steps"] == "bigint" and types["day" if "day" in types else "how"] == "text"
    marker = _admin(postgres_server, schema, "SELECT owner, application_id, version FROM stickslip_marker")
    assert marker == [("stickslip", storage.APPLICATION_ID, storage.SCHEMA_VERSION)]
    # a column gone is what integrity_check reports
    _admin(postgres_server, schema, "ALTER TABLE traverses DROP COLUMN content")
    with Store.open(postgres_url) as b:
        assert "table traverses: columns" in b.integrity_check()


def test_a_value_postgresql_keeps_but_no_traverse_has_is_named_before_any_row_is_read(postgres_url, postgres_server):
    with Store.open(postgres_url) as st:
        tid = st.add_traverse(ROW)
    _admin(postgres_server, _schema_of(postgres_url), f"UPDATE traverses SET q2 = 'NaN' WHERE id = {tid}")
    with Store.open(postgres_url) as st, pytest.raises(StoreError, match=rf"traverse {tid}: q2 holds nan"):
        st.traverses()


def test_a_value_out_of_range_is_a_constraint_error_on_both(db, monkeypatch):
    with Store.open(db) as st:
        with pytest.raises(ValueError, match="steps must be a whole number"):  # the store's own check first
            st.add_traverse(Traverse("d", 3, "+", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.012, 2**63))
        monkeypatch.setattr(type(st), "_check", staticmethod(lambda t: t))  # the database's own limit holds too
        with pytest.raises(ConstraintError):
            st.add_traverse(Traverse("d", 3, "+", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.012, 2**63))  # past 64 bits
        assert st.count_traverses() == 0 and st.days() == []


# ---------------------------------------------------------------- whose database it is


def test_a_postgresql_schema_of_another_application_is_refused_untouched(postgres_url, postgres_server):
    from typer.testing import CliRunner

    from stickslip.cli import app

    schema = _schema_of(postgres_url)
    _admin(postgres_server, schema, "CREATE TABLE photos (id int); INSERT INTO photos VALUES (1)")
    snapshot = "SELECT relname, relkind FROM pg_class c JOIN pg_namespace n ON n.oid = c.relnamespace " \
        f"WHERE n.nspname = '{schema}' ORDER BY relname"
    before = _admin(postgres_server, schema, snapshot)
    with pytest.raises(StoreError, match=r"another application's tables \(schema t\S+: photos\).*untouched"):
        Store.open(postgres_url)
    for cmd in (["history"], ["import", "x.csv", "-d", "sim://"], ["where", "--offline", "-d", "sim://"]):
        r = CliRunner().invoke(app, [*cmd, "--db", postgres_url])
        assert r.exit_code == 2, (cmd, r.output)
    assert _admin(postgres_server, schema, snapshot) == before  # not a table, index or sequence more
    assert _admin(postgres_server, schema, "SELECT * FROM photos") == [(1,)]


def test_a_marker_of_another_owner_or_a_newer_version_is_refused(postgres_url, postgres_server):
    schema = _schema_of(postgres_url)
    with Store.open(postgres_url) as st:
        st.add_traverse(ROW)
    _admin(postgres_server, schema, f"UPDATE stickslip_marker SET version = {storage.SCHEMA_VERSION + 1}")
    with pytest.raises(StoreError, match="newer than this stickslip understands"):
        Store.open(postgres_url)
    _admin(postgres_server, schema, f"UPDATE stickslip_marker SET version = {storage.SCHEMA_VERSION}, owner = 'x'")
    with pytest.raises(StoreError, match="names another owner"):
        Store.open(postgres_url)
    assert _admin(postgres_server, schema, "SELECT count(*) FROM traverses") == [(1,)]


def test_a_search_path_without_a_schema_is_one_line(postgres_url):
    url = postgres_url.rsplit("%3D", 1)[0] + "%3Dnot_there"
    with pytest.raises(StoreError, match="no schema to keep the tables in"):
        Store.open(url)


# ---------------------------------------------------------------- secrets


def test_a_password_in_the_url_is_never_shown_logged_or_stored(
    postgres_server, postgres_url, caplog, monkeypatch, tmp_path
):
    from typer.testing import CliRunner

    from stickslip.cli import app

    monkeypatch.delenv("PGPASSWORD")
    secret = postgres_server.password
    forms = {secret, quote(secret, safe="")}
    url = postgres_server.url(_schema_of(postgres_url), with_password=True)
    wrong = url.replace(quote(secret, safe=""), quote(secret[::-1], safe=""))
    caplog.set_level(logging.DEBUG)
    seen: list[str] = []
    with Store.open(url) as st:
        seen += [str(st.path)]
        st.add_traverse(ROW, device=f"sim://?password={secret}", how=f"by {url}", source=url)
    with pytest.raises(StoreError, match="password authentication failed") as e:
        Store.open(wrong)
    seen += [str(e.value), e.value.args[0]]
    runner = CliRunner()
    out = tmp_path / "out.csv"
    for args in (["history", "--json"], ["export", "-o", str(out)], ["config", "show", "--json"], ["config", "show"]):
        r = runner.invoke(app, [*args, "--db", url])
        assert r.exit_code == 0, r.output
        seen += [r.output]
    r = runner.invoke(app, ["history", "--db", wrong])
    assert r.exit_code == 2 and "PGPASSWORD" in r.stderr  # the hint says where a password belongs
    seen += [r.output, caplog.text, out.read_text()]
    dump = _admin(
        postgres_server,
        _schema_of(postgres_url),
        "SELECT string_agg(t::text, ' ') FROM (SELECT * FROM traverses) t "
        "UNION ALL SELECT string_agg(d::text, ' ') FROM devices d UNION ALL SELECT string_agg(m::text, ' ') "
        "FROM stickslip_marker m",
    )
    seen += [str(dump)]
    # the device is stored under its key: no option, so not even the password's place (it was sim://?password=***)
    assert "sim://" in str(dump) and "?password" not in str(dump) and "by postgresql://rig:***@127.0.0.1" in str(dump)
    for text in seen:
        for form in forms:
            assert form not in text


# ---------------------------------------------------------------- crashes and locks

_KILLED_WRITER = textwrap.dedent("""
    import sys, time
    from stickslip.measurements import Traverse
    from stickslip.storage import Store
    st = Store.open(sys.argv[1])
    st.add_traverse(Traverse("2026-11-20", 3, "+", 0.0, -1.5, 0.0, 0.0, 0.0, 0.0, 0.012, 1))  # committed
    assert st.acquire_lock("sim://", {"pid": int(sys.argv[2]), "host": sys.argv[3], "since": "now"}) is None
    rows = [Traverse("2026-11-20", 3, "+", 0.0, -1.5, 0.0, 0.0, 0.0, 0.0, 0.012, k) for k in range(2, 1002)]
    with st._write() as con:  # a transaction left open: 1000 rows written, not committed
        sid = st._session_id(con, st._device_id(con, "sim://"), "2026-11-20")
        for t in rows:
            st._insert_row(con, t, sid, "measured", "x", None, "k")
        print("inside", flush=True)
        time.sleep(600)
""")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_a_writer_killed_inside_its_transaction_leaves_no_partial_rows_and_no_lock(db):
    import socket

    proc = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(db), "0", socket.gethostname()],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "inside"
        with Store.open(db) as st:  # while it holds the write transaction, readers still read
            assert [t.steps for t in st.traverses()] == [1]
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        proc.stdout.close()
    me = {"pid": os.getpid(), "host": socket.gethostname(), "since": "now"}
    with Store.open(db) as st:
        assert [t.steps for t in st.traverses()] == [1]  # none of the 1000
        st.add_traverse(ROW)  # the write lock is free (else: "kept it busy for 30 s")
        assert st.count_traverses() == 2 and st.integrity_check() == "ok"
        # the device lock of the dead process (pid 0 here stands for "no such process") is taken over
        if st.backend == "sqlite":
            st.set_state("sim://", "lock", {"pid": 2**22 + 12345, "host": socket.gethostname(), "since": "x"})
        assert st.acquire_lock("sim://", me) is None
        st.release_lock("sim://", me["pid"])


_HOLDER = textwrap.dedent("""
    import sys, time
    from stickslip.storage import Store
    st = Store.open(sys.argv[1])
    print(st.acquire_lock("sim://", {"pid": 424242, "host": "rig-2.lab", "since": "09:00"}), flush=True)
    time.sleep(600)
""")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_a_lock_held_on_another_host_is_refused_and_on_postgresql_freed_when_its_process_dies(db):
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, str(db)], stdout=subprocess.PIPE, text=True)
    me = {"pid": os.getpid(), "host": "rig-1.lab", "since": "10:00"}
    try:
        assert proc.stdout.readline().strip() == "None"  # it took the lock
        with Store.open(db) as st:
            assert st.acquire_lock("sim://", me) == {"pid": 424242, "host": "rig-2.lab", "since": "09:00"}
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        proc.stdout.close()
    with Store.open(db) as st:
        got = st.acquire_lock("sim://", me)
        if st.backend == "postgresql":  # the server freed the dead connection's advisory lock
            assert got is None
            with Store.open(db) as other:  # and it is held again, now by us
                assert other.acquire_lock("sim://", {"pid": 1, "host": "h", "since": "s"}) == me
            st.release_lock("sim://", me["pid"])
            with Store.open(db) as other:
                assert other.acquire_lock("sim://", {"pid": 1, "host": "h", "since": "s"}) is None
        else:  # SQLite cannot see a process on another host: still refused, until `where --unlock`
            assert got == {"pid": 424242, "host": "rig-2.lab", "since": "09:00"}
            st.set_state("sim://", "lock", "null")
            assert st.acquire_lock("sim://", me) is None


_ALIAS_HOLDER = textwrap.dedent("""
    import sys, time
    from stickslip.storage import Store
    st = Store.open(sys.argv[1])
    print(st.acquire_lock("anc300://h", {"pid": 424242, "host": "rig-2.lab", "since": "09:00"}), flush=True)
    time.sleep(600)
""")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_one_controller_written_two_ways_takes_one_lock(db):
    """anc300://h and anc300://h:7230 are one controller (its default port); each took its own lock, so two
    processes drove the controller at once (audit57). Now (schema 5) they are one device, stored under one name
    whose row holds the one lock: the second is refused; another controller, or another arm's channel, is not."""
    proc = subprocess.Popen([sys.executable, "-c", _ALIAS_HOLDER, str(db)], stdout=subprocess.PIPE, text=True)
    me = {"pid": os.getpid(), "host": "rig-1.lab", "since": "10:00"}
    try:
        assert proc.stdout.readline().strip() == "None"  # it took the lock
        with Store.open(db) as st:
            for spelling in ("anc300://h:7230", "anc300://H:7230/", "anc300://h/?password=x"):
                assert st.acquire_lock(spelling, me) == {"pid": 424242, "host": "rig-2.lab", "since": "09:00"}, spelling
            assert st.acquire_lock("anc300://h:7231", me) is None  # another controller
            st.release_lock("anc300://h:7231", me["pid"])
            assert st.acquire_lock("anc300://h:7230#arm=probe", me) is None  # a rig arm's lock is its own
            st.release_lock("anc300://h:7230#arm=probe", me["pid"])
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        proc.stdout.close()


def test_a_move_refused_through_another_spelling_names_the_one_device_for_unlock(tmp_path):
    from stickslip.procedures.move import DeviceBusy, device_lock

    with Store.open(tmp_path / "s.db") as st:
        assert st.acquire_lock("anc300://h", {"pid": 424242, "host": "rig-2.lab", "since": "09:00"}) is None
        with pytest.raises(DeviceBusy) as e, device_lock(st, "anc300://h:7230"):
            pass
    assert str(e.value) == (
        "anc300://h:7230 is being driven by another stickslip process (pid 424242 on rig-2.lab since 09:00); wait for "
        "it to finish, or if that process is gone, release the lock with `stickslip where -d anc300://h:7230 "
        "--unlock`")
    with Store.open(tmp_path / "s.db") as st:  # the lock is the one device's, whichever way --unlock writes it
        assert [d["url"] for d in st.devices()] == ["anc300://h:7230"]


def test_one_store_cannot_hold_a_device_twice(db):
    me = {"pid": os.getpid(), "host": "h", "since": "s"}
    with Store.open(db) as st:
        assert st.acquire_lock("sim://?seed=1", me) is None
        assert st.acquire_lock("sim://?seed=1", {**me, "pid": 7}) == me
        assert st.acquire_lock("sim://?realtime=1&seed=1", {**me, "pid": 7}) == me  # the same arm written otherwise
        assert st.acquire_lock("sim://?seed=2", {**me, "pid": 7}) is None  # another device: its own lock
        st.release_lock("sim://?seed=1", me["pid"])
        assert st.acquire_lock("sim://?seed=1", {**me, "pid": 7}) is None


# ---------------------------------------------------------------- the command line and the config file


def test_the_config_files_database_may_be_a_url_but_never_with_a_password(tmp_path, postgres_url, monkeypatch):
    from typer.testing import CliRunner

    from stickslip.cli import app

    cfg = tmp_path / "cfg" / "config.toml"
    cfg.parent.mkdir()
    monkeypatch.setenv("STICKSLIP_CONFIG", str(cfg))
    monkeypatch.delenv("STICKSLIP_DB")
    cfg.write_text(f"database = {json.dumps(postgres_url)}\n")
    runner = CliRunner()
    r = runner.invoke(app, ["import", str(_table(tmp_path)), "-d", "sim://", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["db"] == describe_database(postgres_url)
    r = runner.invoke(app, ["config", "show", "--json"])
    row = json.loads(r.stdout)["settings"]["database"]
    assert row == {"value": postgres_url, "source": "file", "where": str(cfg), "exists": None}
    r = runner.invoke(app, ["history", "--json"])
    assert [e["traverses"] for e in json.loads(r.stdout)] == [1]
    for bad, reason in (
        ("postgresql://rig:hunter2@db.lab/stickslip", "a password in the database URL is refused"),
        ("postgresql://rig@db.lab/stickslip?password=hunter2", "a password in the database URL is refused"),
        ("mysql://rig@db.lab/stickslip", "mysql:// is not a database stickslip can use"),
    ):
        cfg.write_text(f"\ndatabase = {json.dumps(bad)}\n")
        r = runner.invoke(app, ["history"])
        assert r.exit_code == 2 and f"{cfg}:2: database: {reason}" in r.stderr, r.output
        assert "hunter2" not in r.output


def _table(tmp_path: Path) -> Path:
    from stickslip.measurements import write_measurements

    path = tmp_path / "m.csv"
    write_measurements(path, [ROW])
    return path


def test_every_command_that_takes_db_keeps_a_url_as_text():
    """A ``Path`` would fold ``postgresql://`` to ``postgresql:/``: each ``--db`` is read as text (db_option)."""
    import inspect

    import click
    import typer

    from stickslip.cli import app

    root = typer.main.get_command(app)
    ctx = click.Context(root)

    def commands(c: click.Command, path: tuple[str, ...] = ()):
        if isinstance(c, click.Group) or hasattr(c, "list_commands"):
            for name in c.list_commands(ctx):  # type: ignore[attr-defined]
                yield from commands(c.get_command(ctx, name), (*path, name))  # type: ignore[attr-defined]
        else:
            yield " ".join(path), c

    seen = {}
    for name, c in commands(root):
        if any("--db" in (p.opts or []) for p in c.params):
            seen[name] = str(inspect.signature(c.callback).parameters["db"].annotation)
    assert {"history", "import", "export", "fit", "move", "where", "jog", "reach", "demo", "config show"} <= set(seen)
    assert set(seen.values()) == {"str | None"}, seen


def test_calibrate_finds_the_device_and_keeps_the_calibration_and_show_reads_it_back_on_both(db, tmp_path):
    """calibrate TABLE learns the arm from the database holding the table's rows, keeps the calibration there;
    show N reads it back: the same commands on a file and on a server."""
    from synth import paper_table
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import write_measurements

    runner = CliRunner()
    meas = tmp_path / "m.csv"
    write_measurements(meas, paper_table())
    assert runner.invoke(app, ["import", str(meas), "-d", "mm3a:///dev/ttyUSB0", "--db", str(db)]).exit_code == 0
    r = runner.invoke(app, ["calibrate", str(meas), "-o", str(tmp_path / "cal.json"), "--db", str(db)])
    assert r.exit_code == 0 and "kept in the database as calibration #1" in r.stdout, r.output
    r = runner.invoke(app, ["show", "1", "--db", str(db), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["conditions"]["device"] == "mm3a:///dev/ttyUSB0"
    with Store.open(db) as st:
        assert st.calibration_traverses(1) == paper_table()


def test_a_bluesky_device_link_keeps_its_positions_in_a_postgresql_database(postgres_url):
    pytest.importorskip("ophyd_async")
    from stickslip.bluesky import DeviceLink

    link = DeviceLink("sim://?seed=7", db=postgres_url)
    assert link.db == postgres_url  # not folded into a path
    assert link.load().device == "sim://?seed=7"
    with link.store() as st:
        assert st.backend == "postgresql"


# ---------------------------------------------------------------- several rigs, one history

@pytest.mark.slow  # a second Python process importing the command line (seconds on a loaded machine)
def test_two_rigs_in_two_processes_share_one_postgresql_history(postgres_server, postgres_url, tmp_path):
    """The issue's "Done when", for storage: two rigs (two processes, two device URLs) record their
    traverses, calibrations and positions side by side in one PostgreSQL database; `history` shows both."""
    import pgserver
    import shared_rig
    from synth import paper_table
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import write_measurements

    rigs = {"sim://?seed=4": 0.001, "sim://?seed=5": 0.002}  # two arms, each with its own table
    args = {}
    for k, (device, noise) in enumerate(rigs.items()):
        table = tmp_path / f"rig{k}.csv"
        write_measurements(table, paper_table(rng=np.random.default_rng(k), noise=noise))
        args[device] = (postgres_url, device, str(table), str(tmp_path / f"cal{k}.json"))
    first, second = rigs
    # the second rig's password comes from a password file, as on a rig PC (~/.pgpass); the first's from $PGPASSWORD
    env = {k: v for k, v in os.environ.items() if k != "PGPASSWORD"}
    env["PGPASSFILE"] = str(pgserver.write_pgpass(postgres_server, tmp_path / "pgpass"))
    other = subprocess.Popen(  # the second rig in its own process, while the first runs in this one
        [sys.executable, shared_rig.__file__, *args[second]],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        results = {first: shared_rig.run_rig(*args[first])}
    finally:
        out, err = other.communicate(timeout=300)
    assert other.returncode == 0, err
    results[second] = json.loads(out)
    n = len(paper_table())
    for device, res in results.items():
        assert res["import"]["imported"] == n
        assert res["where"]["device"] == device
        q3 = res["where"]["joints"][2]
        assert q3["source"] == "dead-reckoned" and q3["q"] == pytest.approx(res["move"]["q_end_predicted"], abs=1e-15)
    runner = CliRunner()
    r = runner.invoke(app, ["history", "--db", postgres_url, "--json"])
    assert r.exit_code == 0, r.output
    entries = {e["device"]: e for e in json.loads(r.stdout)}
    assert set(entries) == set(rigs)
    for device, res in results.items():
        e = entries[device]
        assert e["traverses"] == n and sum(e["by_joint"].values()) == n
        assert [c["id"] for c in e["calibrations"]] == [res["fit"]["stored_id"]]
    r = runner.invoke(app, ["history", "--db", postgres_url])
    assert r.exit_code == 0 and r.stdout.count("sim://?seed=") == 2  # the table: one row per rig (folded)
    with Store.open(postgres_url) as st:  # each rig's calibration was fitted from its own rows only
        for device, res in results.items():
            assert st.calibration_traverses(res["fit"]["stored_id"]) == st.traverses(device=device)


def test_backup_copies_either_backend_into_an_sqlite_file_every_command_reads(db, tmp_path):
    """`stickslip backup`: the same rows, ids and links in the copy, from a file or from a shared database."""
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.devices.positions import DeviceState, save_state

    cal, rows = _calibration_and_rows()
    with Store.open(db) as st:
        ids = st.add_traverses(rows, device="sim://?seed=4")
        st.add_traverse(ROW, device="sim://?seed=5")
        cid = st.add_calibration(cal, "sim://?seed=4", ids)
        save_state(st, DeviceState.default("sim://?seed=5"))
        st.set_excluded(ids[:1], "a bad run")
        used = st.calibration_traverses(cid)
        want = (st.history(), st.traverse_records(), st.calibrations(), st.get_state("sim://?seed=5", "positions"))
    out = tmp_path / "copy.db"
    r = CliRunner().invoke(app, ["backup", str(out), "--db", str(db)])
    assert r.exit_code == 0, r.output
    assert f"copied {len(rows) + 1} traverse(s)" in r.stdout and out.is_file()
    assert not list(tmp_path.glob(".copy.db.*"))
    with Store.open(out) as copy:
        assert copy.backend == "sqlite" and copy.integrity_check() == "ok"
        assert copy.schema_version == storage.SCHEMA_VERSION
        state = copy.get_state("sim://?seed=5", "positions")
        assert (copy.history(), copy.traverse_records(), copy.calibrations(), state) == want
        assert copy.calibration_traverses(cid) == used == rows[1:]  # the excluded one is left out, as in the source
        assert copy.latest_calibration("sim://?seed=4").to_dict() == cal.to_dict()
    r = CliRunner().invoke(app, ["backup", str(out), "--db", str(db)])  # never over an existing file
    assert r.exit_code == 2 and "exists" in r.stderr and r.stderr.count("\n") == 1
    missing = tmp_path / "no such folder" / "copy.db"  # said 'cannot write the backup .../.copy.db.part: unable
    r = CliRunner().invoke(app, ["backup", str(missing), "--db", str(db)])  # to open database file'
    assert r.exit_code == 2 and not missing.parent.exists()
    assert r.stderr.strip() == (f"error: cannot write the backup {missing}: its folder {missing.parent} does not "
                                "exist; nothing was written"), r.stderr


@pytest.mark.parametrize("left", ["half", "whole"])
def test_a_backup_killed_before_its_rename_does_not_fail_the_next(db, tmp_path, left):
    """A backup killed (SIGKILL, a power cut) mid-copy leaves half a file, after the copy and before the rename a
    whole one, under the temporary name. The next backup to that name failed on it ('file is not a database';
    from PostgreSQL 'UNIQUE constraint failed: devices.id', leaving -wal and -shm files); now it writes its own
    copy and never touches the leftover (which may be another backup's, running now)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    with Store.open(db) as st:
        st.add_traverse(ROW, device="sim://?seed=5")
    out = tmp_path / "copy.db"
    leftover = tmp_path / ".copy.db.part"  # the name every backup to copy.db used
    if left == "whole":
        assert CliRunner().invoke(app, ["backup", str(out), "--db", str(db)]).exit_code == 0
        out.rename(leftover)
    else:
        leftover.write_bytes(b"SQLite format 3\x00" + bytes(84))  # the header, then nothing: half a copy
    before = leftover.read_bytes()
    r = CliRunner().invoke(app, ["backup", str(out), "--db", str(db)])
    assert r.exit_code == 0, r.output
    assert "copied 1 traverse(s)" in r.stdout
    with Store.open(out) as copy:
        assert copy.integrity_check() == "ok" and len(copy.traverses()) == 1
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".copy")) == [".copy.db.part"]
    assert leftover.read_bytes() == before


def _calibration_and_rows():
    from stickslip.calibration import calibrate

    rows = []
    for q2, th, n_plus, n_minus in (
        (-math.pi / 2, 0.0, 12346, 13348),
        (0.0, -math.pi / 2, 16900, 17790),
        (0.0, 0.0, 25010, 11100),
        (-1.0, -0.5, 13000, 14000),
    ):
        rows.append(Traverse("2026-11-20", 3, "+", 0.0, q2, 0.0, th, 0.0, 0.0, 0.012, n_plus))
        rows.append(Traverse("2026-11-20", 3, "-", 0.0, q2, 0.0, th, 0.0, 0.012, 0.0, n_minus))
    return calibrate(rows, method="lsq"), rows


def test_the_control_room_keeps_its_positions_in_a_postgresql_database(postgres_url, tmp_path):
    """`stickslip serve --db postgresql://...`: the room's move is kept where every rig of the lab sees it."""
    pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")
    from fastapi.testclient import TestClient
    from server_support import true_calibration

    from stickslip.devices.positions import load_state
    from stickslip.server.app import create_app
    from stickslip.server.room import ControlRoom, RoomOptions
    from stickslip.server.security import Access

    url = "sim://?realtime=1&speed=50"
    cal = tmp_path / "true-cal.json"
    true_calibration(url).save(cal)
    room = ControlRoom(RoomOptions(device=url, db=postgres_url, calibration=cal))
    try:
        with TestClient(create_app(room, Access(None, True)), base_url="http://127.0.0.1:8765") as client:
            r = client.post("/api/move", json={"joint": 3, "by": "100um"})
            assert r.status_code in (200, 202), r.text
            m = client.get(f"/api/motions/{r.json()['id']}", params={"wait": 20}).json()
            assert m["status"] == "done" and m["error"] is None, m
    finally:
        room.close()
    with Store.open(postgres_url) as st:
        assert load_state(st, "sim://").positions[3] == pytest.approx(m["result"]["q_end_predicted"], abs=1e-15)
