"""The seam between the store and a database engine: what SQLite and PostgreSQL each do their own way.

The store (:mod:`.base`, :mod:`.traverses`, :mod:`.calibrations`, :mod:`.state`) writes
its queries once, in the SQL both engines share, with ``?`` placeholders, and runs the
same migrations (:data:`.schema.MIGRATIONS`) on both. What differs lives behind
:class:`Backend`, one class per engine (:mod:`.sqlite`, :mod:`.postgres`):

========================  ==============================  ====================================
                          SQLite (a file)                 PostgreSQL (a server)
========================  ==============================  ====================================
placeholders              ``?``                           ``%s`` (translated, :func:`qmarks_to_format`)
the id of a new row       ``cursor.lastrowid``            ``INSERT ... RETURNING id``
many rows at once         ``executemany``                 ``COPY`` with ids drawn from the sequence
column types (DDL)        as written                      ``BIGINT`` / identity key / ``DOUBLE PRECISION`` / ``BYTEA``
one writer at a time      ``BEGIN IMMEDIATE``             a transaction-level advisory lock
waiting for it            ``busy_timeout``                ``lock_timeout`` (and ``statement_timeout``)
whose database it is      ``PRAGMA application_id``       a marker table: owner, id, schema version
schema version            ``PRAGMA user_version``         the marker table's ``version``
a lock that dies with     none: the holder's pid is       a session-level advisory lock, freed by
its process               probed on the same host         the server when the connection ends
a stored value's type     ``typeof()`` (SQLite keeps      the column's type (enforced)
                          what it is given)
========================  ==============================  ====================================

Every driver error leaves a backend as one of three things: :class:`~.schema.StoreError`
(an ``OSError``: the database cannot be reached, read or written; the message names it
and never a password), :class:`~.schema.ConstraintError` (a ``ValueError``: a value the
schema refuses) or, for a programming error, the driver's own.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from contextlib import AbstractContextManager
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal, Protocol

__all__ = ["Backend", "Cursor", "Kind", "qmarks_to_format"]

Kind = Literal["integer", "real", "text"]
"""The kinds of value a column holds, for :meth:`Backend.not_a`."""


class Cursor(Protocol):
    """The rows of one query: each row is read by position (``r[0]``) and by column name (``r["day"]``)."""

    @property
    def rowcount(self) -> int: ...

    def fetchone(self) -> Any: ...

    def fetchall(self) -> list[Any]: ...

    def fetchmany(self, size: int = ...) -> list[Any]: ...

    def __iter__(self) -> Iterator[Any]: ...


class Backend(Protocol):
    """One open database of one engine: the only place the store's SQL meets a driver."""

    dialect: str
    """``"sqlite"`` or ``"postgresql"``."""

    where: Path | str
    """The database as messages name it: the file, or the URL without its password."""

    def execute(self, sql: str, args: Sequence[Any] = ()) -> Cursor:
        """Run one statement (``?`` placeholders) and return its rows."""
        ...

    def executemany(self, sql: str, rows: Iterable[Sequence[Any]]) -> None:
        """Run one statement once per row of arguments."""
        ...

    def insert(self, sql: str, args: Sequence[Any]) -> int:
        """Run one ``INSERT`` into a table with an ``id`` key; return the new row's id."""
        ...

    def insert_many(self, table: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[int]:
        """Insert ``rows`` into ``table`` (inside :meth:`write`); return their new ids, in the order given."""
        ...

    def stream(self, sql: str, args: Sequence[Any], chunk: int) -> Iterator[Any]:
        """The rows of a query, ``chunk`` at a time: memory bounded by ``chunk``, whatever the result's size."""
        ...

    def write(self) -> AbstractContextManager[None]:
        """One write transaction: every writer of the database waits for the one before (all or nothing)."""
        ...

    def schema_version(self) -> int:
        """The schema version the database is at (0: nothing of stickslip's there yet)."""
        ...

    def owned(self) -> bool:
        """Whether the database already carries stickslip's mark (else :meth:`claim_ownership` sets it)."""
        ...

    def claim_ownership(self) -> None:
        """Inside :meth:`write`, before the first migration: check once more that the database is ours, and mark it."""
        ...

    def set_schema_version(self, version: int) -> None:
        """Inside :meth:`write`: record that the migrations up to ``version`` ran."""
        ...

    def ddl(self, statement: str) -> str:
        """A migration's statement (written for SQLite) in this engine's column types."""
        ...

    def not_a(self, column: str, kind: Kind) -> str:
        """SQL true where ``column`` holds a value not of ``kind`` (``"0 = 1"`` where the engine enforces types)."""
        ...

    def claim(self, name: str) -> bool | None:
        """Take the lock ``name``, held until :meth:`release` or until this connection ends, whichever first.

        ``True`` when taken; ``False`` when another connection (or this one) holds it;
        ``None`` when the engine has no such lock (SQLite: the caller judges a holder by
        its process id instead).
        """
        ...

    def release(self, name: str) -> None:
        """Give back a lock taken with :meth:`claim` (nothing if it is not held here)."""
        ...

    def integrity_check(self) -> str:
        """``"ok"`` when the database is sound, else what is wrong."""
        ...

    def snapshot(self) -> AbstractContextManager[None]:
        """Reads that all see the database as it was at the first of them (no write inside)."""
        ...

    def copy_as_read(self, dest: Path) -> None:
        """Copy the database file, as another reader sees it now, into the new SQLite file ``dest``.

        Inside a write transaction that has written nothing yet, the copy is the database
        before it (an upgrade's copy, :mod:`.upgrade`). SQLite only: a server has no file.
        """
        ...

    def online_copy(self, dest: Path) -> bool:
        """Copy the database into the new SQLite file ``dest`` by the engine's own means.

        ``True`` when done; ``False`` when the engine has none (the store then copies the
        rows, :meth:`Store.backup`).
        """
        ...

    def close(self) -> None:
        """Close the connection (idempotent)."""
        ...


@lru_cache(maxsize=512)
def qmarks_to_format(sql: str) -> str:
    """``sql`` with each ``?`` placeholder as ``%s`` and each ``%`` as ``%%`` (the ``format`` paramstyle).

    Quoted text (``'...'``, ``"..."``) is left as it is: a ``?`` inside a string or a
    quoted name is not a placeholder.

    >>> qmarks_to_format("SELECT id FROM t WHERE a = ? AND b LIKE 'x%?' AND \\"c?\\" = ?")
    'SELECT id FROM t WHERE a = %s AND b LIKE \\'x%%?\\' AND "c?" = %s'
    """
    out: list[str] = []
    quote = ""
    for c in sql:
        if quote:
            out.append("%%" if c == "%" else c)
            if c == quote:
                quote = ""
        elif c in "'\"":
            quote = c
            out.append(c)
        elif c == "?":
            out.append("%s")
        elif c == "%":
            out.append("%%")
        else:
            out.append(c)
    return "".join(out)
