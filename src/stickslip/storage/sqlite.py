"""The SQLite backend: a file, opened safely (whose it is, WAL, ``BEGIN IMMEDIATE``, a damaged file named)."""

from __future__ import annotations

import os
import sqlite3
import time
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NoReturn

from ..records import special_kind
from .backend import Cursor, Kind
from .schema import (
    APPLICATION_ID,
    BUSY_TIMEOUT_MS,
    MIGRATIONS,
    ConstraintError,
    NoDatabase,
    StoreError,
    schema_tables,
    tables_of,
)

__all__ = ["SQLiteBackend", "check_database_file"]


# ---------------------------------------------------------------- whose file is it?

_MAGIC = b"SQLite format 3\x00"


def _header(path: Path) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(100)
    except OSError as e:
        raise StoreError(f"cannot open the database {path}: {e.strerror or e}") from None


def _tables(path: Path) -> dict[str, tuple[str, ...]]:
    try:
        con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
        try:
            return tables_of(con)
        finally:
            con.close()
    except sqlite3.DatabaseError as e:
        raise StoreError(f"the database {path} is damaged or not a database ({e}); it was left untouched") from None


def _fingerprint(path: Path) -> tuple[int, int, bytes]:
    """The file's size, modification time (ns) and first 100 bytes: what changes while anything writes it."""
    try:
        st = os.stat(path)
    except OSError:
        return (-1, -1, b"")
    return (st.st_size, st.st_mtime_ns, _header(path))


def _settled(path: Path, before: tuple[int, int, bytes], wait_s: float = 0.05) -> bool:
    """Whether the file is as it was at ``before`` now and ``wait_s`` later: nothing is writing it."""
    if _fingerprint(path) != before:
        return False
    time.sleep(wait_s)
    return _fingerprint(path) == before


def _changing(path: Path) -> NoReturn:
    raise StoreError(f"the database {path} kept changing while stickslip looked at whose it is; try again")


def check_database_file(path: Path, looks: int = 50) -> str:
    """Whether stickslip may open ``path``: ``"new"``, ``"ours"`` or ``"legacy"``; else :class:`StoreError`.

    Decided before anything opens the file for writing, from its first 100 bytes and, for
    a file without an application id, a read-only look at its tables (``immutable``: no
    lock, no journal, nothing created beside it). The first 100 bytes are read again after
    the tables: a file another stickslip process is making (its id, schema version and
    tables in one transaction, reaching the file when the WAL is copied back) is looked at
    again, up to ``looks`` times, rather than judged from a header older than its tables, and
    so is one whose tables could not be read while it changed (or within 50 ms after: a WAL
    copied back page by page reads as damaged until it is done); a file that stayed the same
    is damaged:

    * nothing there, an empty file, or an SQLite file without tables: ``"new"``;
    * ``PRAGMA application_id`` is stickslip's (:data:`~.schema.APPLICATION_ID`): ``"ours"``, unless its
      schema version is newer than this stickslip's (refused, the file not even opened);
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
    head = _header(path)
    if not head.startswith(_MAGIC) or len(head) < 100:
        raise StoreError(
            f"{path} is not an SQLite database (it begins {head[:16]!r}); stickslip leaves it untouched: "
            "give --db another file"
        )
    user_version = int.from_bytes(head[60:64], "big", signed=True)
    app_id = int.from_bytes(head[68:72], "big", signed=True)
    if app_id == APPLICATION_ID:
        if user_version > len(MIGRATIONS):  # refused here, before opening it switches its journal mode to WAL
            raise StoreError(
                f"{path} has schema version {user_version}, newer than this stickslip understands "
                f"({len(MIGRATIONS)}): left untouched (upgrade stickslip)"
            )
        return "ours"
    if app_id != 0:
        raise StoreError(
            f"{path} is another application's SQLite file (application id {app_id & 0xFFFFFFFF:#010x}, "
            f"not stickslip's {APPLICATION_ID:#010x}); stickslip leaves it untouched: give --db another file"
        )
    before = _fingerprint(path)
    try:
        tables = _tables(path)
    except StoreError:  # damaged, or read while another stickslip writes it (a WAL copied back page by page)
        if not _settled(path, before):
            return check_database_file(path, looks - 1) if looks > 1 else _changing(path)
        raise
    again = _header(path)
    if again != head:  # written meanwhile (another stickslip making it: ours and its tables in one transaction)
        return check_database_file(path, looks - 1) if looks > 1 else _changing(path)
    if not tables and user_version == 0:
        return "new"
    if 1 <= user_version <= len(MIGRATIONS) and tables == schema_tables(user_version):
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


_UNREADABLE = (sqlite3.DatabaseError, UnicodeDecodeError)
"""What reading a file can raise: SQLite's errors, and bytes that are not UTF-8 where text is kept (a damaged
schema, whose text SQLite quotes in its error message, or a damaged text value)."""


def _damaged(e: sqlite3.DatabaseError | UnicodeDecodeError) -> bool:
    if isinstance(e, UnicodeDecodeError) or "Could not decode to UTF-8" in str(e):
        return True
    name = str(getattr(e, "sqlite_errorname", "") or "")
    text = str(e)
    return name.startswith(_DAMAGED) or "malformed" in text or "not a database" in text


class _Cursor(sqlite3.Cursor):
    """A cursor whose reads turn a damaged file (``database disk image is malformed``) into :class:`StoreError`."""

    def _problem(self, e: sqlite3.DatabaseError | UnicodeDecodeError) -> BaseException:
        con = self.connection
        return con._problem(e) if isinstance(con, _Connection) else e

    def fetchone(self) -> Any:
        try:
            return super().fetchone()
        except _UNREADABLE as e:
            raise self._problem(e) from None

    def fetchmany(self, size: int | None = None) -> list[Any]:
        try:
            return super().fetchmany(self.arraysize if size is None else size)
        except _UNREADABLE as e:
            raise self._problem(e) from None

    def fetchall(self) -> list[Any]:
        try:
            return super().fetchall()
        except _UNREADABLE as e:
            raise self._problem(e) from None

    def __next__(self) -> Any:
        try:
            return super().__next__()
        except _UNREADABLE as e:
            raise self._problem(e) from None


class _Connection(sqlite3.Connection):
    """The store's connection: a damaged file is one :class:`StoreError` naming it, wherever it is found."""

    path: Path = Path()

    def _problem(self, e: sqlite3.DatabaseError | UnicodeDecodeError) -> BaseException:
        if isinstance(e, sqlite3.IntegrityError):
            return ConstraintError(f"the database refused the value: {e}; nothing of this change was stored")
        if not _damaged(e):
            return e
        why = "text that is not UTF-8" if isinstance(e, UnicodeDecodeError) else str(e)
        return StoreError(
            f"the database {self.path} is damaged ({why}); nothing was changed: restore it from a backup, "
            f"or see what `sqlite3 {self.path} .recover` can save"
        )

    def cursor(self, factory: Any = None) -> Any:  # the same, with our cursor
        return super().cursor(factory or _Cursor)

    def execute(self, sql: str, parameters: Any = (), /) -> Any:
        cur = self.cursor()  # sqlite3's own execute makes a plain cursor, whose reads we could not watch
        try:
            return cur.execute(sql, parameters)
        except _UNREADABLE as e:
            raise self._problem(e) from None
        except OverflowError as e:  # an integer past 64 bits: as PostgreSQL's "out of range"
            raise ConstraintError(f"the database refused the value: {e}; nothing of this change was stored") from None

    def executemany(self, sql: str, parameters: Any, /) -> Any:
        cur = self.cursor()
        try:
            return cur.executemany(sql, parameters)
        except _UNREADABLE as e:
            raise self._problem(e) from None
        except OverflowError as e:
            raise ConstraintError(f"the database refused the value: {e}; nothing of this change was stored") from None


def _connect(path: Path) -> _Connection:
    con = sqlite3.connect(str(path), timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None, factory=_Connection)
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


def _open_hint(path: Path, e: sqlite3.DatabaseError) -> str:
    """Why SQLite could not open an existing file, where its words do not say: a full disk, a read-only folder.

    Even a reading command needs the write-ahead log's ``-shm`` file beside the database (SQLite makes it and
    writes into it to read): on a full disk opening says only "disk I/O error", in a read-only folder (a share
    mounted read-only) "unable to open database file".
    """
    text, shm = str(e), f"{path.name}-shm"
    if text == "disk I/O error":
        return f" (is the disk full? even reading needs room for {shm} beside it)"
    if text == "unable to open database file" and path.exists() and not os.access(path.parent, os.W_OK):
        return (f" (its folder {path.parent} is read-only: SQLite needs to make {shm} beside it, even to read; "
                "copy the file into a folder you can write, and give --db the copy)")
    return ""


# ---------------------------------------------------------------- the backend


class SQLiteBackend:
    """A stickslip database in an SQLite file (:class:`~.backend.Backend`)."""

    dialect = "sqlite"

    def __init__(self, con: _Connection, path: Path) -> None:
        self._con: _Connection | None = con
        self.where: Path | str = path
        self.path = path

    @classmethod
    def open(cls, path: Path, create: bool = True) -> SQLiteBackend:
        """Open ``path`` after :func:`check_database_file` said whose it is (nothing written before).

        With ``create=False`` a file that is not there (or empty) is :class:`~.schema.NoDatabase`.
        """
        whose = check_database_file(path)
        if whose == "new" and not create:
            raise NoDatabase(f"no database at {path}")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            why = e.strerror or e
            raise StoreError(f"cannot create the folder {path.parent} for the database {path}: {why}") from None
        try:
            con = _connect(path)
        except sqlite3.DatabaseError as e:
            raise StoreError(f"cannot open the database {path}: {e}{_open_hint(path, e)}") from None
        return cls(con, path)

    @property
    def con(self) -> _Connection:
        if self._con is None:
            raise StoreError(f"the database {self.path} was closed")
        return self._con

    # -- statements

    def execute(self, sql: str, args: Sequence[Any] = ()) -> Cursor:
        cur: Cursor = self.con.execute(sql, args)
        return cur

    def executemany(self, sql: str, rows: Iterable[Sequence[Any]]) -> None:
        self.con.executemany(sql, rows)

    def insert(self, sql: str, args: Sequence[Any]) -> int:
        cur = self.con.execute(sql, args)
        if cur.lastrowid is None:  # pragma: no cover - sqlite3 sets it after every INSERT
            raise StoreError("the database did not report the id of the row it wrote")
        return int(cur.lastrowid)

    def insert_many(self, table: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[int]:
        # one executemany; in this write transaction (BEGIN IMMEDIATE: no other writer) the new rows
        # are exactly those above the old largest id
        con = self.con
        before = int(con.execute(f"SELECT COALESCE(MAX(id), 0) FROM {table}").fetchone()[0])
        names = ", ".join(f'"{c}"' for c in columns)
        con.executemany(f"INSERT INTO {table} ({names}) VALUES ({', '.join('?' * len(columns))})", rows)
        return [int(r[0]) for r in con.execute(f"SELECT id FROM {table} WHERE id > ? ORDER BY id", (before,))]

    def stream(self, sql: str, args: Sequence[Any], chunk: int) -> Iterator[Any]:
        cur = self.con.execute(sql, args)
        while rows := cur.fetchmany(chunk):
            yield from rows

    @contextmanager
    def write(self) -> Iterator[None]:
        """One write transaction, taken with ``BEGIN IMMEDIATE`` (waits on busy_timeout)."""
        con = self.con
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.DatabaseError as e:
            raise StoreError(self._write_problem(e)) from None
        try:
            yield
            con.execute("COMMIT")
        except BaseException as e:
            if con.in_transaction:
                try:
                    con.execute("ROLLBACK")
                except sqlite3.DatabaseError:
                    pass  # SQLite rolls back itself when the file cannot be written
            if isinstance(e, sqlite3.DatabaseError):
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

    # -- schema

    def schema_version(self) -> int:
        return int(self.con.execute("PRAGMA user_version").fetchone()[0])

    def owned(self) -> bool:
        # through the connection, not the file's header: a new file's first transactions may
        # still be in the WAL, where check_database_file (which reads only the header) cannot see them
        return int(self.con.execute("PRAGMA application_id").fetchone()[0]) == APPLICATION_ID

    def claim_ownership(self) -> None:
        """Under ``BEGIN IMMEDIATE``: look again (with what the WAL holds), then stamp the application id."""
        con = self.con
        app_id = int(con.execute("PRAGMA application_id").fetchone()[0])
        if app_id == APPLICATION_ID:
            return
        version = self.schema_version()
        tables = tables_of(con)
        if app_id != 0 or tables and not (1 <= version <= len(MIGRATIONS) and tables == schema_tables(version)):
            raise StoreError(
                f"{self.path} is an SQLite database of another application; stickslip leaves it untouched: "
                "give --db another file"
            )
        con.execute(f"PRAGMA application_id = {APPLICATION_ID}")

    def set_schema_version(self, version: int) -> None:
        self.con.execute(f"PRAGMA user_version = {int(version)}")

    def ddl(self, statement: str) -> str:
        return statement  # the migrations are written in SQLite's types

    def not_a(self, column: str, kind: Kind) -> str:
        # SQLite keeps what it is given: text in a REAL column, 2.5 in an INTEGER one
        allowed = {"integer": "'integer'", "real": "'real', 'integer'", "text": "'text'"}[kind]
        return f"typeof({column}) NOT IN ({allowed})"

    # -- locks that end with their holder: SQLite has none (the store probes the holder's pid)

    def claim(self, name: str) -> bool | None:
        return None

    def release(self, name: str) -> None:
        return None

    def integrity_check(self) -> str:
        """``PRAGMA integrity_check`` (``"ok"`` when the file is sound)."""
        return "; ".join(r[0] for r in self.con.execute("PRAGMA integrity_check"))

    # -- copies

    @contextmanager
    def snapshot(self) -> Iterator[None]:
        """Reads in one deferred transaction: in WAL mode they all see the database as it was at the first."""
        con = self.con
        con.execute("BEGIN")
        try:
            yield
        finally:
            if con.in_transaction:
                con.execute("COMMIT")

    def copy_as_read(self, dest: Path) -> None:
        """SQLite's online backup through a connection of its own (the store's may be in a write transaction)."""
        try:
            src = sqlite3.connect(f"{Path(self.path).resolve().as_uri()}?mode=ro", uri=True)
            try:
                out = sqlite3.connect(dest)
                try:
                    src.backup(out)
                    out.commit()
                finally:
                    out.close()
            finally:
                src.close()
        except sqlite3.Error as e:
            raise StoreError(f"cannot write {dest}: {e}") from None

    def online_copy(self, dest: Path) -> bool:
        """SQLite's online backup into the new file ``dest`` (page by page, consistent, pragmas and all)."""
        try:
            out = sqlite3.connect(dest)
            try:
                self.con.backup(out)
                out.commit()
            finally:
                out.close()
        except sqlite3.Error as e:
            raise StoreError(f"cannot write the backup {dest}: {e}") from None
        return True

    def close(self) -> None:
        if self._con is not None:
            self._con.close()
            self._con = None
