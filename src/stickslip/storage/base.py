"""Opening the SQLite file safely: connection settings, transactions, migrations, devices and sessions."""

from __future__ import annotations

import os
import sqlite3
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

from ..devices.base import redact_url
from ..measurements import Traverse
from .schema import (
    BUSY_TIMEOUT_MS,
    MIGRATIONS,
    SCHEMA_VERSION,
    StoreError,
    _now,
    _split_sql,
    content_key,
    resolve_db_path,
)

if TYPE_CHECKING:  # pragma: no cover
    pass


def _connect(path: Path) -> sqlite3.Connection:
    con = sqlite3.connect(str(path), timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
    con.row_factory = sqlite3.Row
    con.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
    con.execute("PRAGMA foreign_keys = ON")
    # Switching to WAL needs an exclusive lock once per file; retry while another
    # process holds it (the busy handler is not always consulted for this pragma).
    deadline = time.monotonic() + BUSY_TIMEOUT_MS / 1000
    while True:
        try:
            mode = con.execute("PRAGMA journal_mode = WAL").fetchone()[0]
            break
        except sqlite3.OperationalError as e:
            if "locked" not in str(e) and "busy" not in str(e) or time.monotonic() > deadline:
                raise
            time.sleep(0.01)
    if str(mode).lower() != "wal":  # e.g. a file system without shared memory
        con.execute("PRAGMA journal_mode = DELETE")
    con.execute("PRAGMA synchronous = FULL")
    return con




class _Base:
    """The connection, transactions, migrations, devices and sessions (shared by every part of ``Store``)."""

    def __init__(self, con: sqlite3.Connection, path: Path):
        self._con = con
        self.path = path

    # -- opening / closing

    @classmethod
    def open(cls, path: str | os.PathLike[str] | None = None) -> Self:
        """Open (creating and migrating if needed) the database at ``path``.

        ``path`` defaults to ``$STICKSLIP_DB``, else the user's data directory (see
        :func:`default_db_path`). Raises :class:`StoreError` when the file is not a
        stickslip database or comes from a newer version.
        """
        p = resolve_db_path(path)
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise StoreError(f"cannot create the directory for the database {p}: {e}") from None
        try:
            con = _connect(p)
        except sqlite3.DatabaseError as e:
            raise StoreError(f"cannot open the database {p}: {e}") from None
        store = cls(con, p)
        try:
            store._migrate()
        except sqlite3.DatabaseError as e:
            con.close()
            raise StoreError(f"{p} is not a usable stickslip database: {e}") from None
        except StoreError as e:
            con.close()
            if "newer than" in str(e):
                raise
            raise StoreError(f"{p} is not a usable stickslip database: {e}") from None
        return store

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if self._con is not None:
            self._con.close()
            self._con = None  # type: ignore[assignment]  # a closed store has no connection; using it raises

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        """``PRAGMA user_version`` of the file."""
        return int(self._con.execute("PRAGMA user_version").fetchone()[0])

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """One write transaction, taken with ``BEGIN IMMEDIATE`` (waits on busy_timeout)."""
        con = self._con
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.DatabaseError as e:
            raise StoreError(self._write_problem(e)) from None
        try:
            yield con
            con.execute("COMMIT")
        except BaseException as e:
            if con.in_transaction:
                try:
                    con.execute("ROLLBACK")
                except sqlite3.DatabaseError:
                    pass  # SQLite rolls back itself when the file cannot be written
            if isinstance(e, sqlite3.DatabaseError) and not isinstance(e, sqlite3.IntegrityError):
                raise StoreError(self._write_problem(e)) from None
            raise

    def _write_problem(self, e: sqlite3.DatabaseError) -> str:
        text = str(e)
        hint = {
            "disk I/O error": "is the disk full, or the file too large for a quota?",
            "database or disk is full": "free some space",
            "attempt to write a readonly database": "the file or its folder is read-only",
            "database is locked": "another process kept it busy for 30 s",
        }.get(text, "")
        return (
            f"cannot write to the database {self.path}: {text}"
            + (f" ({hint})" if hint else "")
            + "; nothing of this change was stored"
        )

    def _migrate(self) -> None:
        version = self.schema_version
        if version > SCHEMA_VERSION:
            raise StoreError(
                f"{self.path} has schema version {version}, newer than this stickslip understands "
                f"({SCHEMA_VERSION}): upgrade stickslip"
            )
        if version == SCHEMA_VERSION:
            return
        with self._write() as con:
            version = int(
                con.execute("PRAGMA user_version").fetchone()[0]
            )  # another process may have won
            for k in range(version, SCHEMA_VERSION):
                for stmt in _split_sql(MIGRATIONS[k]):
                    con.execute(stmt)
                con.execute(f"PRAGMA user_version = {k + 1}")
            if version < 3:
                self._backfill_content(con)

    def _backfill_content(self, con: sqlite3.Connection) -> None:
        rows = con.execute(
            "SELECT t.*, s.day AS day, d.url AS url FROM traverses t JOIN sessions s ON s.id = t.session_id "
            "JOIN devices d ON d.id = s.device_id WHERE t.content IS NULL"
        ).fetchall()
        for r in rows:
            key = content_key(self._to_traverse(r), r["url"])
            con.execute("UPDATE traverses SET content = ? WHERE id = ?", (key, r["id"]))

    # -- devices and sessions

    def _device_id(self, con: sqlite3.Connection, url: str, model: str | None = None) -> int:
        url = redact_url(str(url).strip())  # a secret in a URL is never stored
        if not url:
            raise ValueError("device URL is empty (e.g. sim://)")
        row = con.execute("SELECT id, model FROM devices WHERE url = ?", (url,)).fetchone()
        if row is not None:
            if model and row["model"] != model:
                con.execute("UPDATE devices SET model = ? WHERE id = ?", (model, row["id"]))
            return int(row["id"])
        cur = con.execute(
            "INSERT INTO devices (url, model, created_at) VALUES (?, ?, ?)", (url, model, _now())
        )
        return _rowid(cur)

    def _session_id(self, con: sqlite3.Connection, device_id: int, day: str) -> int:
        row = con.execute(
            "SELECT id FROM sessions WHERE device_id = ? AND day = ?", (device_id, day)
        ).fetchone()
        if row is not None:
            return int(row["id"])
        cur = con.execute(
            "INSERT INTO sessions (device_id, day, created_at) VALUES (?, ?, ?)",
            (device_id, day, _now()),
        )
        return _rowid(cur)

    def add_device(self, url: str, model: str | None = None) -> int:
        """Register a device URL (and its model name); returns its id. Idempotent."""
        with self._write() as con:
            return self._device_id(con, url, model)

    def devices(self) -> list[dict[str, Any]]:
        """Every device: ``{"url", "model", "created_at"}``."""
        rows = self._con.execute(
            "SELECT url, model, created_at FROM devices ORDER BY id"
        ).fetchall()
        return [dict(r) for r in rows]

    # -- maintenance

    def _traverse_rows(
        self,
        device: str | None,
        day: str | None,
        joint: int | None,
        ids: Sequence[int] | None = None,
        include_excluded: bool = False,
    ) -> list[sqlite3.Row]:
        return self._traverse_cursor(device, day, joint, ids, include_excluded).fetchall()

    def _traverse_cursor(
        self,
        device: str | None,
        day: str | None,
        joint: int | None,
        ids: Sequence[int] | None = None,
        include_excluded: bool = False,
    ) -> sqlite3.Cursor:
        sql = (
            "SELECT t.*, s.day AS day, d.url AS device FROM traverses t "
            "JOIN sessions s ON s.id = t.session_id JOIN devices d ON d.id = s.device_id WHERE 1=1"
        )
        if not include_excluded:
            sql += " AND t.excluded IS NULL"
        args: list[Any] = []
        if device is not None:
            sql += " AND d.url = ?"
            args.append(redact_url(device))
        if day is not None:
            sql += " AND s.day = ?"
            args.append(day)
        if joint is not None:
            sql += " AND t.joint = ?"
            args.append(int(joint))
        if ids is not None:
            sql += f" AND t.id IN ({','.join('?' * len(ids))})"
            args += [int(i) for i in ids]
        sql += " ORDER BY t.id"
        return self._con.execute(sql, args)

    @staticmethod
    def _to_traverse(r: sqlite3.Row) -> Traverse:
        return Traverse(
            r["day"],
            int(r["joint"]),
            r["direction"],
            r["q1"],
            r["q2"],
            r["q3"],
            r["theta"],
            r["psi"],
            r["start"],
            r["end"],
            int(r["steps"]),
        )

    def integrity_check(self) -> str:
        """``PRAGMA integrity_check`` (``"ok"`` when the file is sound)."""
        return "; ".join(r[0] for r in self._con.execute("PRAGMA integrity_check"))

    def backup(self, path: str | os.PathLike[str]) -> Path:
        """Copy the whole database, consistently, into a new file ``path`` (SQLite's online backup).

        Safe while other processes use the database (a plain file copy can miss what the
        write-ahead log still holds). An existing ``path`` is refused (``FileExistsError``);
        the copy is written beside it and renamed into place, so a failed backup leaves nothing.
        """
        dest = Path(path).expanduser()
        if dest.exists():
            raise FileExistsError(f"{dest} exists: give a new file for the backup")
        tmp = dest.with_name(f".{dest.name}.part")
        try:
            out = sqlite3.connect(tmp)
            try:
                self._con.backup(out)
                out.commit()
            finally:
                out.close()
            os.replace(tmp, dest)
        except (OSError, sqlite3.Error):
            tmp.unlink(missing_ok=True)
            raise
        return dest





def _rowid(cur: sqlite3.Cursor) -> int:
    """The id of the row an INSERT just wrote."""
    if cur.lastrowid is None:  # pragma: no cover - sqlite3 sets it after every INSERT
        raise StoreError("the database did not report the id of the row it wrote")
    return int(cur.lastrowid)


def _require_traverses(con: sqlite3.Connection, ids: list[int], marks: str) -> None:
    """Raise ``ValueError`` naming the ids (of ``ids``) that are not stored traverses."""
    found = {int(r[0]) for r in con.execute(f"SELECT id FROM traverses WHERE id IN ({marks})", ids)}
    missing = [i for i in ids if i not in found]
    if missing:
        raise ValueError(f"no stored traverse with id {', '.join(map(str, missing))}")



