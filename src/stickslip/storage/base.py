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
from ..records import special_kind
from .schema import (
    APPLICATION_ID,
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


# ---------------------------------------------------------------- whose file is it?

_MAGIC = b"SQLite format 3\x00"


def _tables_of(con: sqlite3.Connection) -> dict[str, tuple[str, ...]]:
    """``{table: column names}`` of a database (its own tables, not SQLite's)."""
    sql = "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%'"
    names = [r[0] for r in con.execute(sql)]
    return {n: tuple(r[1] for r in con.execute(f'PRAGMA table_info("{n}")')) for n in names}


def _our_schema(version: int) -> dict[str, tuple[str, ...]]:
    """The tables and columns a stickslip database has at schema ``version`` (the migrations run in memory)."""
    con = sqlite3.connect(":memory:")
    try:
        for script in MIGRATIONS[:version]:
            for stmt in _split_sql(script):
                con.execute(stmt)
        return _tables_of(con)
    finally:
        con.close()


def check_database_file(path: Path) -> str:
    """Whether stickslip may open ``path``: ``"new"``, ``"ours"`` or ``"legacy"``; else :class:`StoreError`.

    Decided before anything opens the file for writing, from its first 100 bytes and, for
    a file without an application id, a read-only look at its tables (``immutable``: no
    lock, no journal, nothing created beside it):

    * nothing there, an empty file, or an SQLite file without tables: ``"new"``;
    * ``PRAGMA application_id`` is stickslip's (:data:`~.schema.APPLICATION_ID`): ``"ours"``;
    * no application id, and the tables and columns of a stickslip schema version
      (a database made before the id was set): ``"legacy"``, stamped when opened;
    * anything else is refused untouched, naming the file and why: a folder, FIFO or
      device; not an SQLite file; another application's id; another schema; a schema
      newer than this stickslip; a file too damaged to read its tables.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "new"
    except OSError as e:
        raise StoreError(f"cannot open the database {path}: {e.strerror or e}") from None
    kind = special_kind(st.st_mode)
    if kind is not None:
        raise StoreError(f"{path} is {kind}, not a database file: give --db the path of a file")
    if st.st_size == 0:
        return "new"
    try:
        with open(path, "rb") as f:
            head = f.read(100)
    except OSError as e:
        raise StoreError(f"cannot open the database {path}: {e.strerror or e}") from None
    if not head.startswith(_MAGIC) or len(head) < 100:
        raise StoreError(
            f"{path} is not an SQLite database (it begins {head[:16]!r}); stickslip leaves it untouched: "
            "give --db another file"
        )
    user_version = int.from_bytes(head[60:64], "big", signed=True)
    app_id = int.from_bytes(head[68:72], "big", signed=True)
    if app_id == APPLICATION_ID:
        return "ours"
    if app_id != 0:
        raise StoreError(
            f"{path} is another application's SQLite file (application id {app_id & 0xFFFFFFFF:#010x}, "
            f"not stickslip's {APPLICATION_ID:#010x}); stickslip leaves it untouched: give --db another file"
        )
    try:
        con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
        try:
            tables = _tables_of(con)
        finally:
            con.close()
    except sqlite3.DatabaseError as e:
        raise StoreError(f"the database {path} is damaged or not a database ({e}); it was left untouched") from None
    if not tables and user_version == 0:
        return "new"
    if 1 <= user_version <= len(MIGRATIONS) and tables == _our_schema(user_version):
        return "legacy"
    if user_version > len(MIGRATIONS):
        raise StoreError(
            f"{path} has schema version {user_version}, newer than this stickslip understands ({len(MIGRATIONS)}), "
            "or is another application's file: left untouched (upgrade stickslip, or give --db another file)"
        )
    shown = ", ".join(sorted(tables)[:5]) + (" ..." if len(tables) > 5 else "")
    raise StoreError(
        f"{path} is an SQLite database of another application (tables: {shown or 'none'}; schema version "
        f"{user_version}); stickslip leaves it untouched: give --db another file"
    )


# ---------------------------------------------------------------- a connection that names a damaged file

_DAMAGED = ("SQLITE_CORRUPT", "SQLITE_NOTADB")


def _damaged(e: sqlite3.DatabaseError) -> bool:
    name = str(getattr(e, "sqlite_errorname", "") or "")
    text = str(e)
    return name.startswith(_DAMAGED) or "malformed" in text or "not a database" in text


class _Cursor(sqlite3.Cursor):
    """A cursor whose reads turn a damaged file (``database disk image is malformed``) into :class:`StoreError`."""

    def _problem(self, e: sqlite3.DatabaseError) -> BaseException:
        con = self.connection
        return con._problem(e) if isinstance(con, _Connection) else e

    def fetchone(self) -> Any:
        try:
            return super().fetchone()
        except sqlite3.DatabaseError as e:
            raise self._problem(e) from None

    def fetchmany(self, size: int | None = None) -> list[Any]:
        try:
            return super().fetchmany(self.arraysize if size is None else size)
        except sqlite3.DatabaseError as e:
            raise self._problem(e) from None

    def fetchall(self) -> list[Any]:
        try:
            return super().fetchall()
        except sqlite3.DatabaseError as e:
            raise self._problem(e) from None

    def __next__(self) -> Any:
        try:
            return super().__next__()
        except sqlite3.DatabaseError as e:
            raise self._problem(e) from None


class _Connection(sqlite3.Connection):
    """The store's connection: a damaged file is one :class:`StoreError` naming it, wherever it is found."""

    path: Path = Path()

    def _problem(self, e: sqlite3.DatabaseError) -> BaseException:
        if not _damaged(e):
            return e
        return StoreError(
            f"the database {self.path} is damaged ({e}); nothing was changed: restore it from a backup, "
            f"or see what `sqlite3 {self.path} .recover` can save"
        )

    def cursor(self, factory: Any = None) -> Any:  # the same, with our cursor
        return super().cursor(factory or _Cursor)

    def execute(self, sql: str, parameters: Any = (), /) -> Any:
        cur = self.cursor()  # sqlite3's own execute makes a plain cursor, whose reads we could not watch
        try:
            return cur.execute(sql, parameters)
        except sqlite3.DatabaseError as e:
            raise self._problem(e) from None

    def executemany(self, sql: str, parameters: Any, /) -> Any:
        cur = self.cursor()
        try:
            return cur.executemany(sql, parameters)
        except sqlite3.DatabaseError as e:
            raise self._problem(e) from None


def _connect(path: Path) -> sqlite3.Connection:
    con = sqlite3.connect(
        str(path), timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None, factory=_Connection
    )
    con.path = path
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
        :func:`default_db_path`). Before anything writes to it, :func:`check_database_file`
        decides whose the file is: another application's SQLite file, a file that is not a
        database, a folder, FIFO or device is refused untouched (:class:`StoreError`
        naming it); a stickslip database made before the application id is stamped with
        it; a new one gets it. A damaged file, or one from a newer stickslip, is refused.
        """
        p = resolve_db_path(path)
        whose = check_database_file(p)
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
            store._migrate(stamp=whose != "ours")
        except sqlite3.DatabaseError as e:
            con.close()
            raise StoreError(f"{p} is not a usable stickslip database: {e}") from None
        except StoreError as e:
            con.close()
            if "newer than" in str(e) or "damaged" in str(e):
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

    def _migrate(self, stamp: bool = False) -> None:
        """Bring the file to :data:`SCHEMA_VERSION`; with ``stamp``, also set stickslip's application id."""
        version = self.schema_version
        if version > SCHEMA_VERSION:
            raise StoreError(
                f"{self.path} has schema version {version}, newer than this stickslip understands "
                f"({SCHEMA_VERSION}): upgrade stickslip"
            )
        if version == SCHEMA_VERSION and not stamp:
            return
        with self._write() as con:
            if stamp:
                con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
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
        where, args = self._traverse_filter(device, day, joint, ids, include_excluded)
        self._check_stored_types(where, args)
        return self._con.execute(sql + where + " ORDER BY t.id", args)

    @staticmethod
    def _traverse_filter(
        device: str | None,
        day: str | None,
        joint: int | None,
        ids: Sequence[int] | None,
        include_excluded: bool,
    ) -> tuple[str, list[Any]]:
        """The ``AND ...`` clauses (and their arguments) that pick the traverses asked for."""
        sql = ""
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
        return sql, args

    def _check_stored_types(self, where: str, args: list[Any]) -> None:
        """Refuse, naming the traverse and the column, a stored value of the wrong type or out of its range.

        SQLite keeps what it is given (text in a REAL column, 2.5 in an INTEGER one, a
        joint 7 past a CHECK turned off): one query over the traverses asked for finds
        the first such row, before any is read, so none is exported or fitted silently.
        """
        row = self._con.execute(
            "SELECT id, bad FROM (SELECT t.id AS id, " + _BAD_COLUMN + " AS bad FROM traverses t "
            "JOIN sessions s ON s.id = t.session_id JOIN devices d ON d.id = s.device_id WHERE 1=1" + where
            + ") WHERE bad IS NOT NULL ORDER BY id LIMIT 1",
            args,
        ).fetchone()
        if row is None:
            return
        tid, col = int(row[0]), str(row[1])
        if col == "day":
            value = self._con.execute(
                "SELECT s.day FROM traverses t JOIN sessions s ON s.id = t.session_id WHERE t.id = ?", (tid,)
            ).fetchone()[0]
        else:
            value = self._con.execute(f'SELECT "{col}" FROM traverses WHERE id = ?', (tid,)).fetchone()[0]
        raise StoreError(
            f"{self.path}: traverse {tid}: {col} holds {value!r} ({type(value).__name__}), {_SHOULD[col]}; "
            f"nothing was read (fix or delete it: stickslip delete -t {tid})"
        )

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





_REAL_COLUMNS = ("q1", "q2", "q3", "theta", "psi", "start", "end")
_SHOULD = {
    "joint": "not a joint (1, 2 or 3)",
    "direction": "not a direction ('+' or '-')",
    "steps": "not a positive whole number of steps",
    "day": "not a session label (non-blank text)",
    **dict.fromkeys(_REAL_COLUMNS, "not a finite number (SI units)"),
}
_BAD_COLUMN = (
    "CASE"
    " WHEN typeof(t.joint) != 'integer' OR t.joint NOT IN (1, 2, 3) THEN 'joint'"
    " WHEN typeof(t.direction) != 'text' OR t.direction NOT IN ('+', '-') THEN 'direction'"
    + "".join(
        f" WHEN typeof(t.\"{c}\") NOT IN ('real', 'integer') OR abs(t.\"{c}\") > 1.7976931348623157e308 THEN '{c}'"
        for c in _REAL_COLUMNS
    )
    + " WHEN typeof(t.steps) != 'integer' OR t.steps <= 0 THEN 'steps'"
    " WHEN typeof(s.day) != 'text' OR trim(s.day) = '' THEN 'day'"
    " END"
)
"""SQL: the first column of a stored traverse ``t`` (with its session ``s``) whose value cannot be what it says."""


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



