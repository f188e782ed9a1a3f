"""audit37: writes that fail for the reasons labs meet (a full disk, a read-only folder) never lose earlier data.

Each test says what failed before its fix. A full disk is simulated portably (a write raising ``ENOSPC``);
a read-only folder by the error the operating system gives, so nothing here needs POSIX permissions or root.
"""

from __future__ import annotations

import errno
import os
import sqlite3

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
