"""The PostgreSQL backend: a database several rigs share, through psycopg (the ``postgres`` extra).

``--db postgresql://user@host:5432/dbname`` (docs/storage.md). The tables are those of
the SQLite file, made by the same migrations (:meth:`PostgresBackend.ddl` maps the
column types), in the connection's current schema (``public``, or the first schema
of a ``search_path`` given in the URL: ``?options=-csearch_path%3Dlab2``).

Safety
------
* Whose database: a marker table, ``stickslip_marker`` (owner ``stickslip``, the
  application id 0x5374536C, the schema version). A schema with other tables and no
  marker, or a marker of another owner, is refused before anything is written; an
  empty schema is stamped and migrated in one transaction.
* One writer at a time, as SQLite's ``BEGIN IMMEDIATE``: every write transaction
  first takes a transaction-level advisory lock (per schema), so read-then-write
  steps (a device's row, a session's, the device lock) cannot interleave; readers
  never wait (MVCC). A writer waits at most ``lock_timeout`` (30 s, as SQLite's busy
  timeout), a statement runs at most ``statement_timeout`` (10 min), a connection
  attempt at most ``connect_timeout`` (10 s) unless the URL says otherwise, and TCP
  keepalives (and, on Linux, ``tcp_user_timeout``) find a network or a host that went
  silent in about a minute. A server that goes away (stopped, restarted, its
  connection ended) is one :class:`~.schema.StoreError` at the next statement. What no
  timeout on this side can see is a server process that hangs while its host still
  answers TCP: ``statement_timeout`` is the server's own.
* A process killed mid-transaction: the server rolls the transaction back when the
  connection drops, and frees its locks; a device lock is also a session-level
  advisory lock, so a lock whose process died on any host is seen as free.
* Credentials: a password in the URL works but is never shown, logged or stored
  (messages name the database as :func:`~.schema.describe_database` shows it, and any
  server message is masked); libpq also reads ``$PGPASSWORD`` and ``~/.pgpass``
  (``%APPDATA%\\postgresql\\pgpass.conf`` on Windows), which keep it out of the URL.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from functools import lru_cache
from itertools import count
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, ClassVar

from ..devices.base import redact_text
from .backend import Cursor, Kind, qmarks_to_format
from .schema import (
    APPLICATION_ID,
    BUSY_TIMEOUT_MS,
    ConstraintError,
    NoDatabase,
    StoreError,
    _now,
    describe_database,
    schema_tables,
    url_secrets,
)

if TYPE_CHECKING:  # pragma: no cover
    import psycopg

__all__ = ["EXTRA", "MARKER", "OWNER", "PostgresBackend", "load_psycopg"]

EXTRA = "postgres"
"""The optional extra that brings psycopg: ``pip install 'stickslip[postgres]'``."""
MARKER = "stickslip_marker"
"""The table that says a PostgreSQL schema is stickslip's: one row (owner, application id, schema version)."""
OWNER = "stickslip"
"""The marker's owner tag."""
CONNECT_TIMEOUT_S = 10
"""Longest wait for a connection (s), unless the URL or ``$PGCONNECT_TIMEOUT`` gives one."""
STATEMENT_TIMEOUT_MS = 600_000
"""Longest a statement may run (ms): a backstop, far above any import or history."""
TCP_USER_TIMEOUT_MS = 60_000
"""Longest data sent may stay unacknowledged before the connection is given up (ms): a host that vanished."""

_MARKER_DDL = (
    f"CREATE TABLE {MARKER} ("
    " id INTEGER PRIMARY KEY CHECK (id = 1),"
    " owner TEXT NOT NULL,"
    " application_id BIGINT NOT NULL,"
    " version INTEGER NOT NULL,"
    " updated_at TEXT NOT NULL)"
)


def load_psycopg() -> ModuleType:
    """psycopg (3), or a :class:`~.schema.StoreError` naming the extra that brings it."""
    try:
        import psycopg
    except ImportError:
        raise StoreError(
            "a postgresql:// database needs psycopg, which is not installed: "
            f"pip install 'stickslip[{EXTRA}]' (docs/storage.md)"
        ) from None
    return psycopg


# ---------------------------------------------------------------- rows read by position and by name


class _Row:
    """One row: ``r[0]`` and ``r["day"]``, ``dict(r)``, ``len``, iteration (as :class:`sqlite3.Row`)."""

    __slots__ = ("_values",)
    _index: ClassVar[dict[str, int]] = {}
    _names: ClassVar[tuple[str, ...]] = ()

    def __init__(self, values: Sequence[Any]) -> None:
        self._values = tuple(values)

    def __getitem__(self, key: int | str) -> Any:
        if isinstance(key, str):
            return self._values[self._index[key]]
        return self._values[key]

    def __len__(self) -> int:
        return len(self._values)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._values)

    def keys(self) -> list[str]:
        return list(self._names)

    def __repr__(self) -> str:
        return f"Row({dict(zip(self._names, self._values, strict=True))!r})"


@lru_cache(maxsize=256)
def _row_class(names: tuple[str, ...]) -> type[_Row]:
    return type("Row", (_Row,), {"__slots__": (), "_names": names, "_index": {n: i for i, n in enumerate(names)}})


def _rows(cursor: Any) -> Callable[[Sequence[Any]], Any]:
    """psycopg row factory: rows as :class:`_Row`."""
    desc = cursor.description
    if desc is None:
        return tuple
    return _row_class(tuple(c.name for c in desc))


# ---------------------------------------------------------------- the column types of the migrations

_DDL_TYPES = (
    (re.compile(r"\bINTEGER PRIMARY KEY\b"), "BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY"),
    (re.compile(r"\bINTEGER\b"), "BIGINT"),
    (re.compile(r"\bREAL\b"), "DOUBLE PRECISION"),
    (re.compile(r"\bBLOB\b"), "BYTEA"),
)


def _key(*parts: str) -> int:
    """A signed 64-bit advisory-lock key for ``parts`` (sha256: the same on every host and Python)."""
    return int.from_bytes(hashlib.sha256("\x1f".join(parts).encode()).digest()[:8], "big", signed=True)


class PostgresBackend:
    """A stickslip database in a PostgreSQL schema (:class:`~.backend.Backend`)."""

    dialect = "postgresql"
    _cursors = count(1)

    def __init__(self, con: psycopg.Connection[Any], where: str, secrets: Sequence[str]) -> None:
        self._psycopg = load_psycopg()
        self._con: psycopg.Connection[Any] | None = con
        self.where: Path | str = where
        self.path = where
        self._secrets = sorted({s for s in secrets if s}, key=len, reverse=True)
        self._writing = False
        self._held: set[str] = set()
        self._schema = ""
        self._marked = False

    # -- opening

    @classmethod
    def open(cls, url: str, create: bool = True) -> PostgresBackend:
        """Connect to ``url`` and decide, before anything is written, whether the schema is ours (or empty)."""
        pg = load_psycopg()
        where = describe_database(url)
        secrets = url_secrets(url)
        try:
            params = pg.conninfo.conninfo_to_dict(url)
        except pg.Error as e:
            text = _mask(_first_line(e), secrets)
            raise StoreError(f"{where} is not a PostgreSQL URL libpq can read: {text}") from None
        secrets += [str(params.get("password") or "")]
        extra: dict[str, Any] = {}
        if "connect_timeout" not in params and not os.environ.get("PGCONNECT_TIMEOUT"):
            extra["connect_timeout"] = CONNECT_TIMEOUT_S
        if "application_name" not in params and not os.environ.get("PGAPPNAME"):
            extra["application_name"] = "stickslip"
        if "keepalives_idle" not in params:  # a network that goes silent is found in about a minute
            extra.update(keepalives=1, keepalives_idle=30, keepalives_interval=10, keepalives_count=3)
        if "tcp_user_timeout" not in params:  # ... also while a request is unanswered (Linux; ignored elsewhere)
            extra["tcp_user_timeout"] = TCP_USER_TIMEOUT_MS
        try:
            con = pg.connect(url, autocommit=True, row_factory=_rows, **extra)
        except pg.Error as e:
            text = _mask(_first_line(e), secrets)
            raise StoreError(f"cannot connect to the database {where}: {text}{_connect_hint(text)}") from None
        backend = cls(con, where, secrets)
        try:
            backend._settle()
            whose = backend._whose()
        except BaseException:
            backend.close()
            raise
        if whose == "new" and not create:
            backend.close()
            raise NoDatabase(f"no stickslip database at {where}")
        return backend

    def _settle(self) -> None:
        """The session's timeouts, and the schema it works in."""
        self._run(
            f"SET lock_timeout = {BUSY_TIMEOUT_MS}; SET statement_timeout = {STATEMENT_TIMEOUT_MS}; "
            f"SET idle_in_transaction_session_timeout = {STATEMENT_TIMEOUT_MS}"
        )
        schema = self._run("SELECT current_schema()").fetchone()[0]
        if schema is None:
            raise StoreError(
                f"{self.where}: no schema to keep the tables in: the search_path names none that exists "
                "(create it, or fix the URL's options=-csearch_path=...)"
            )
        self._schema = str(schema)
        self._write_key = _key("stickslip write", self._schema)

    def _whose(self) -> str:
        """``"new"`` (an empty schema) or ``"ours"`` (the marker); anything else refused untouched."""
        names = sorted(
            str(r[0])
            for r in self._run(
                "SELECT c.relname FROM pg_class c JOIN pg_namespace n ON n.oid = c.relnamespace "
                "WHERE n.nspname = current_schema() AND c.relkind IN ('r', 'p', 'v', 'm', 'f')"
            )
        )
        if MARKER in names:
            try:
                rows = self._run(f"SELECT owner, application_id, version FROM {MARKER}").fetchall()
            except StoreError as e:
                raise StoreError(f"{self.where}: the table {MARKER} is not stickslip's ({e}); left untouched") from None
            if len(rows) != 1 or rows[0][0] != OWNER or rows[0][1] != APPLICATION_ID:
                raise StoreError(
                    f"{self.where}: the table {MARKER} names another owner (not stickslip's mark); "
                    "stickslip leaves the database untouched: give --db another database or schema"
                )
            self._marked = True
            return "ours"
        if not names:
            return "new"
        shown = ", ".join(names[:5]) + (" ..." if len(names) > 5 else "")
        raise StoreError(
            f"{self.where} holds another application's tables (schema {self._schema}: {shown}) and no "
            f"stickslip marker; stickslip leaves it untouched: give --db an empty database, or another "
            "schema (?options=-csearch_path%3DNAME, docs/storage.md)"
        )

    @property
    def con(self) -> psycopg.Connection[Any]:
        if self._con is None:
            raise StoreError(f"the database {self.where} was closed")
        return self._con

    # -- statements

    def _run(self, sql: str, args: Sequence[Any] = ()) -> Any:
        """Execute ``sql`` (format paramstyle); a driver error outside a write is one :class:`StoreError`."""
        try:
            return self.con.execute(sql, args if args else None)
        except self._psycopg.Error as e:
            if self._writing:
                raise
            raise self._problem(e, "read") from None

    def execute(self, sql: str, args: Sequence[Any] = ()) -> Cursor:
        cur: Cursor = self._run(qmarks_to_format(sql) if args else sql, args)
        return cur

    def executemany(self, sql: str, rows: Iterable[Sequence[Any]]) -> None:
        try:
            with self.con.cursor() as cur:
                cur.executemany(qmarks_to_format(sql), rows)  # psycopg pipelines these: one round trip
        except self._psycopg.Error as e:
            if self._writing:
                raise
            raise self._problem(e, "write") from None

    def insert(self, sql: str, args: Sequence[Any]) -> int:
        return int(self.execute(sql + " RETURNING id", args).fetchone()[0])

    def insert_many(self, table: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[int]:
        """COPY ``rows`` in, with ids drawn from the table's sequence first (so each row's id is known)."""
        if not rows:
            return []
        seq = self._run("SELECT pg_get_serial_sequence(%s, 'id')", (table,)).fetchone()[0]
        ids = [
            int(r[0])
            for r in self._run("SELECT nextval(%s::regclass) FROM generate_series(1, %s) ORDER BY 1", (seq, len(rows)))
        ]
        names = ", ".join(f'"{c}"' for c in ("id", *columns))
        try:
            with self.con.cursor() as cur, cur.copy(f"COPY {table} ({names}) FROM STDIN") as copy:
                for i, row in zip(ids, rows, strict=True):
                    copy.write_row((i, *row))
        except self._psycopg.Error as e:
            if self._writing:
                raise
            raise self._problem(e, "write") from None  # pragma: no cover - always called inside write()
        return ids

    def stream(self, sql: str, args: Sequence[Any], chunk: int) -> Iterator[Any]:
        # a cursor WITH HOLD: the server keeps the result, the client holds `chunk` rows, no transaction stays open
        name = f"stickslip_{next(self._cursors)}"
        try:
            cur = self.con.cursor(name=name, withhold=True)
            cur.itersize = chunk
            cur.execute(qmarks_to_format(sql) if args else sql, args if args else None)
        except self._psycopg.Error as e:
            raise self._problem(e, "read") from None
        try:
            while True:
                try:
                    rows = cur.fetchmany(chunk)
                except self._psycopg.Error as e:
                    raise self._problem(e, "read") from None
                if not rows:
                    break
                yield from rows
        finally:
            try:
                cur.close()
            except self._psycopg.Error:
                pass  # the connection is gone: so is the cursor

    @contextmanager
    def write(self) -> Iterator[None]:
        """One write transaction, after every other writer's (an advisory lock; waits up to lock_timeout)."""
        pg = self._psycopg
        if self._writing:
            raise RuntimeError("write transactions do not nest")
        try:
            with self.con.transaction():
                self._writing = True
                self.con.execute("SELECT pg_advisory_xact_lock(%s)", (self._write_key,))
                yield
        except pg.Error as e:
            raise self._problem(e, "write") from None
        finally:
            self._writing = False

    # -- what went wrong, without a password

    def _problem(self, e: Exception, action: str) -> Exception:
        return _problem_of(self, e, action)

    def _mask(self, text: str) -> str:
        return _mask(text, self._secrets)

    # -- schema

    def schema_version(self) -> int:
        if not self._marked:
            return 0
        return int(self._run(f"SELECT version FROM {MARKER}").fetchone()[0])

    def owned(self) -> bool:
        return self._marked

    def claim_ownership(self) -> None:
        """Under the write lock: look again (another process may have stamped it, or another application filled it)."""
        self._marked = False
        if self._whose() == "new":
            self.con.execute(_MARKER_DDL)
            self.con.execute(
                f"INSERT INTO {MARKER} (id, owner, application_id, version, updated_at) VALUES (1, %s, %s, 0, %s)",
                (OWNER, APPLICATION_ID, _now()),
            )
            self._marked = True

    def set_schema_version(self, version: int) -> None:
        self.con.execute(f"UPDATE {MARKER} SET version = %s, updated_at = %s", (int(version), _now()))

    def ddl(self, statement: str) -> str:
        for pattern, replacement in _DDL_TYPES:
            statement = pattern.sub(replacement, statement)
        return statement

    def not_a(self, column: str, kind: Kind) -> str:
        return "0 = 1"  # the column's type is enforced by the server

    # -- locks that end with their holder's connection

    def claim(self, name: str) -> bool | None:
        if name in self._held:
            return False  # held by this very store (another holder in this process)
        key = _key("stickslip lock", self._schema, name)
        taken = bool(self._run("SELECT pg_try_advisory_lock(%s)", (key,)).fetchone()[0])
        if taken:
            self._held.add(name)
        return taken

    def release(self, name: str) -> None:
        if name in self._held:
            self._held.discard(name)
            self._run("SELECT pg_advisory_unlock(%s)", (_key("stickslip lock", self._schema, name),))

    def integrity_check(self) -> str:
        """``"ok"`` when the marker is stickslip's and every table and column of the schema version is there."""
        version = self.schema_version()
        want = schema_tables(version)
        have: dict[str, list[str]] = {}
        for r in self._run(
            "SELECT table_name, column_name FROM information_schema.columns WHERE table_schema = current_schema() "
            "ORDER BY table_name, ordinal_position"
        ):
            have.setdefault(str(r[0]), []).append(str(r[1]))
        problems = [
            f"table {t}: " + ("missing" if t not in have else f"columns {list(have[t])}, expected {list(cols)}")
            for t, cols in want.items()
            if tuple(have.get(t, ())) != cols
        ]
        return "; ".join(problems) or "ok"

    # -- copies

    @contextmanager
    def snapshot(self) -> Iterator[None]:
        """Reads in one ``REPEATABLE READ, READ ONLY`` transaction: every table as it was at the first read."""
        if self._writing:
            raise RuntimeError("a snapshot inside a write transaction")
        self._run("BEGIN ISOLATION LEVEL REPEATABLE READ, READ ONLY")
        try:
            yield
        finally:
            try:
                self.con.execute("COMMIT")
            except self._psycopg.Error:
                pass  # the connection is gone, and with it the transaction (nothing was written)

    def copy_as_read(self, dest: Path) -> None:
        """A server's database is no file to copy (its administrator's ``pg_dump`` keeps one)."""
        raise StoreError(f"{self.where} is on a server: no file to copy into {dest}")

    def online_copy(self, dest: Path) -> bool:
        """None on a server: the store copies the rows (``False``)."""
        return False

    def close(self) -> None:
        if self._con is not None:
            try:
                self._con.close()
            finally:
                self._con = None
                self._held.clear()


def _problem_of(self: PostgresBackend, e: Exception, action: str) -> Exception:
    """A driver error as one StoreError (or ConstraintError) naming the database, never a password."""
    pg = self._psycopg
    text = self._mask(_first_line(e))
    nothing = "; nothing of this change was stored" if action == "write" else ""
    if isinstance(e, pg.IntegrityError | pg.DataError):
        return ConstraintError(f"the database refused the value: {text}{nothing}")
    if isinstance(e, pg.errors.LockNotAvailable):
        hint = f"another process kept it busy for {BUSY_TIMEOUT_MS // 1000} s"
    elif isinstance(e, pg.errors.QueryCanceled):
        hint = f"it took longer than the statement timeout ({STATEMENT_TIMEOUT_MS // 1000} s)"
    elif isinstance(e, pg.errors.InsufficientPrivilege):
        hint = "the role needs the privileges named in docs/storage.md"
    elif isinstance(e, pg.OperationalError):
        hint = "the server or the network went away"
    else:
        hint = ""
    verb = "write to" if action == "write" else "read"
    return StoreError(f"cannot {verb} the database {self.where}: {text}" + (f" ({hint})" if hint else "") + nothing)


def _first_line(e: BaseException) -> str:
    diag = getattr(e, "diag", None)
    primary = getattr(diag, "message_primary", None) if diag is not None else None
    text = str(primary or e).strip()
    return text.splitlines()[0] if text else type(e).__name__


def _mask(text: str, secrets: Sequence[str]) -> str:
    for s in sorted({s for s in secrets if s}, key=len, reverse=True):
        text = text.replace(s, "***")
    return redact_text(text)


def _connect_hint(text: str) -> str:
    low = text.lower()
    if "password" in low or "authentication" in low:
        return (
            " (give the password in $PGPASSWORD or ~/.pgpass, not in the URL: docs/storage.md)"
        )
    if "does not exist" in low:
        return " (create it first: createdb, docs/storage.md)"
    if "timeout" in low or "refused" in low or "could not translate" in low:
        return " (is the server running, and the host and port right?)"
    return ""
