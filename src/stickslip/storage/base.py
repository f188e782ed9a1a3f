"""Opening a database (a file or a server) safely: the backend, transactions, migrations, devices and sessions."""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from itertools import islice
from pathlib import Path
from typing import Any, Self

from .backend import Backend
from .schema import (
    MIGRATIONS,
    SCHEMA_VERSION,
    StoreError,
    _now,
    _split_sql,
    content_key,
    device_filter,
    resolve_database,
    schema_tables,
    stored_device,
)
from .sqlite import SQLiteBackend, check_database_file
from .upgrade import (
    KEYED_AT,
    _part_file,
    _remove_part,
    copy_before_upgrade,
    key_devices,
    redact_texts,
    row_traverse,
    secret_names,
)

__all__ = ["check_database_file", "open_backend"]


def open_backend(target: Path | str, create: bool = True) -> Backend:
    """The backend for ``target``: an SQLite file (``Path``), or a PostgreSQL URL (``str``, psycopg imported here)."""
    if isinstance(target, str):
        from .postgres import PostgresBackend  # psycopg only when a postgresql:// URL is given

        return PostgresBackend.open(target, create)
    return SQLiteBackend.open(target, create)


class _Base:
    """The backend, transactions, migrations, devices and sessions (shared by every part of ``Store``)."""

    def __init__(self, db: Backend):
        if isinstance(db, (str, os.PathLike)):  # a notebook's first try: Store("lab.db")
            raise TypeError(f"Store({str(db)!r}) takes an open backend; open a database with Store.open({str(db)!r})")
        self._con: Backend = db
        self.path: Path | str = db.where
        self.upgraded_from: int | None = None
        """The schema version this process upgraded the database from when it opened it (``None``: not upgraded)."""
        self.upgrade_copy: Path | None = None
        """Where the file was copied before this process upgraded it (``None``: not upgraded, or not a file)."""
        self.upgrade_notes: list[str] = []
        """What the upgrade changed that a user should know (two spellings of a device merged), one line each."""

    # -- opening / closing

    @classmethod
    def open(cls, path: str | os.PathLike[str] | None = None, create: bool = True) -> Self:
        """Open (creating and migrating if needed) the database at ``path``: a file, or a PostgreSQL URL.

        ``path`` defaults to ``$STICKSLIP_DB``, else the user's data directory (see
        :func:`default_db_path`); a ``postgresql://user@host/dbname`` URL opens a shared
        database on a server (the ``postgres`` extra; docs/storage.md). Before anything
        writes to it, the backend decides whose it is: another application's SQLite file,
        a file that is not a database, a folder, FIFO or device (:func:`check_database_file`),
        or a PostgreSQL schema holding other tables and no stickslip marker, is refused
        untouched (:class:`StoreError` naming it, never a password); a stickslip file made
        before the application id is stamped with it; a new one gets it. A damaged file,
        or a database from a newer stickslip, is refused. With ``create=False`` a database
        that is not there yet is :class:`~.schema.NoDatabase` (nothing is created).
        """
        db = open_backend(resolve_database(path), create)
        store = cls(db)
        try:
            store._migrate()
        except StoreError as e:
            db.close()
            if any(said in str(e) for said in _SAID_WHOLE):
                raise
            raise StoreError(f"{db.where} is not a usable stickslip database: {e}") from None
        except BaseException:
            db.close()
            raise
        return store

    def close(self) -> None:
        """Close the connection (idempotent)."""
        self._con.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def backend(self) -> str:
        """``"sqlite"`` or ``"postgresql"``."""
        return self._con.dialect

    @property
    def schema_version(self) -> int:
        """The schema version of the database (SQLite: ``PRAGMA user_version``; PostgreSQL: the marker's)."""
        return self._con.schema_version()

    @contextmanager
    def _write(self) -> Iterator[Backend]:
        """One write transaction: every writer waits for the one before (SQLite: ``BEGIN IMMEDIATE``)."""
        with self._con.write():
            yield self._con

    def _migrate(self) -> None:
        """Bring the database to :data:`SCHEMA_VERSION`, marking it stickslip's first if it is not yet."""
        db = self._con
        version = db.schema_version()
        if version > SCHEMA_VERSION:
            raise StoreError(
                f"{self.path} has schema version {version}, newer than this stickslip understands "
                f"({SCHEMA_VERSION}): upgrade stickslip"
            )
        if version == SCHEMA_VERSION and db.owned():
            return
        try:
            version = self._migrate_from(version)
        except StoreError as e:
            raise _cannot_migrate(e, self.path, version) from None
        if 1 <= version < SCHEMA_VERSION:  # a stickslip database of an older release, not a new one
            self.upgraded_from = version

    def _migrate_from(self, version: int) -> int:
        """The migrations from ``version``; returns the version they started from (another process may have
        upgraded the database between the first look and the write lock: then none ran, and nothing is said)."""
        try:
            return self._upgrade(version)
        except BaseException:
            if self.upgrade_copy is not None:  # the file is left as it was: its copy says nothing new
                _remove_part(self.upgrade_copy)
                self.upgrade_copy = None
            raise

    def _upgrade(self, version: int) -> int:
        with self._write() as con:
            con.claim_ownership()  # first: on a server it is what makes two processes opening a new database wait
            version = con.schema_version()  # another process may have won
            if 1 <= version < SCHEMA_VERSION and isinstance(self.path, Path):  # the copy reads only what is committed
                self.upgrade_copy = copy_before_upgrade(con, self.path, version, SCHEMA_VERSION)
            if version > SCHEMA_VERSION:
                raise StoreError(
                    f"{self.path} has schema version {version}, newer than this stickslip understands "
                    f"({SCHEMA_VERSION}): upgrade stickslip"
                )
            for k in range(version, SCHEMA_VERSION):
                for stmt in _split_sql(MIGRATIONS[k]):
                    con.execute(con.ddl(stmt))
                con.set_schema_version(k + 1)
            if version < 3:
                self._backfill_content(con)
            if 1 <= version < KEYED_AT:
                secrets, texts = secret_names(con), redact_texts(con)
                self.upgrade_notes = key_devices(con)
                if (secrets or texts) and self.upgrade_copy is not None:  # the copy is the file as it was
                    self.upgrade_notes.append(_copy_secrets_note(secrets, texts, self.upgrade_copy))
        return version

    def _backfill_content(self, con: Backend) -> None:
        rows = con.execute(
            "SELECT t.*, s.day AS day, d.url AS url FROM traverses t JOIN sessions s ON s.id = t.session_id "
            "JOIN devices d ON d.id = s.device_id WHERE t.content IS NULL"
        ).fetchall()
        for r in rows:
            key = content_key(self._to_traverse(r), r["url"])
            con.execute("UPDATE traverses SET content = ? WHERE id = ?", (key, r["id"]))

    # -- devices and sessions

    def _device_id(self, con: Backend, url: str, model: str | None = None) -> int:
        url = stored_device(url)  # one name however the URL is written; a secret in a URL is never stored
        row = con.execute("SELECT id, model FROM devices WHERE url = ?", (url,)).fetchone()
        if row is not None:
            if model and row["model"] != model:
                con.execute("UPDATE devices SET model = ? WHERE id = ?", (model, row["id"]))
            return int(row["id"])
        return con.insert("INSERT INTO devices (url, model, created_at) VALUES (?, ?, ?)", (url, model, _now()))

    def _session_id(self, con: Backend, device_id: int, day: str) -> int:
        row = con.execute(
            "SELECT id FROM sessions WHERE device_id = ? AND day = ?", (device_id, day)
        ).fetchone()
        if row is not None:
            return int(row["id"])
        return con.insert(
            "INSERT INTO sessions (device_id, day, created_at) VALUES (?, ?, ?)", (device_id, day, _now())
        )

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
    ) -> list[Any]:
        sql, args = self._traverse_query(device, day, joint, ids, include_excluded)
        return self._con.execute(sql, args).fetchall()

    def _traverse_query(
        self,
        device: str | None,
        day: str | None,
        joint: int | None,
        ids: Sequence[int] | None = None,
        include_excluded: bool = False,
    ) -> tuple[str, list[Any]]:
        """The query (and its arguments) of the traverses asked for, after checking their stored types."""
        sql = (
            "SELECT t.*, s.day AS day, d.url AS device FROM traverses t "
            "JOIN sessions s ON s.id = t.session_id JOIN devices d ON d.id = s.device_id WHERE 1=1"
        )
        where, args = self._traverse_filter(device, day, joint, ids, include_excluded)
        self._check_stored_types(where, args)
        return sql + where + " ORDER BY t.id", args

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
            args.append(device_filter(device))
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
        joint 7 past a CHECK turned off); PostgreSQL keeps a NaN or an infinity in a
        DOUBLE PRECISION column: one query over the traverses asked for finds the first
        such row, before any is read, so none is exported or fitted silently.
        """
        row = self._con.execute(
            "SELECT id, bad FROM (SELECT t.id AS id, " + _bad_column(self._con) + " AS bad FROM traverses t "
            "JOIN sessions s ON s.id = t.session_id JOIN devices d ON d.id = s.device_id WHERE 1=1" + where
            + ") AS checked WHERE bad IS NOT NULL ORDER BY id LIMIT 1",
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

    _to_traverse = staticmethod(row_traverse)

    def integrity_check(self) -> str:
        """``"ok"`` when the database is sound (SQLite: ``PRAGMA integrity_check``; PostgreSQL: every table there)."""
        return self._con.integrity_check()

    def backup(self, path: str | os.PathLike[str]) -> Path:
        """Copy the whole database, consistently, into a new SQLite file ``path``.

        Safe while other processes use the database. An SQLite file is copied by SQLite's
        online backup (a plain file copy can miss what the write-ahead log still holds); a
        PostgreSQL database row by row, every table read in one snapshot (``REPEATABLE
        READ``), into a new file made by the same migrations, the ids kept: the copy is
        what every command reads with ``--db``, e.g. a shared history taken home. An
        existing ``path`` is refused (``FileExistsError``); the copy is written beside it
        and renamed into place, so a failed backup leaves nothing.
        """
        dest = Path(path).expanduser()
        if dest.exists():
            raise FileExistsError(f"{dest} exists: give a new file for the backup")
        if not dest.parent.is_dir():  # else SQLite's 'unable to open database file', naming the .part file
            raise FileNotFoundError(f"cannot write the backup {dest}: its folder {dest.parent} does not exist; "
                                    "nothing was written")
        tmp = _part_file(dest)
        try:
            if not self._con.online_copy(tmp):
                self._copy_rows_into(tmp)
            os.replace(tmp, dest)
        except (OSError, StoreError) as e:  # a full disk, a read-only folder: said of the file asked for
            _remove_part(tmp)
            raise StoreError(_backup_problem(e, tmp, dest)) from None
        except BaseException:
            _remove_part(tmp)
            raise
        return dest

    def _copy_rows_into(self, path: Path) -> None:
        """Every row of every table, read in one snapshot, into a new SQLite database at ``path``."""
        tables = schema_tables(self.schema_version)
        order = [t for t in _COPY_ORDER if t in tables] + [t for t in tables if t not in _COPY_ORDER]
        with type(self).open(path) as copy, self._con.snapshot(), copy._write() as out:
            for table in order:
                names = ", ".join(f'"{c}"' for c in tables[table])
                marks = ", ".join("?" * len(tables[table]))
                rows = self._con.stream(f"SELECT {names} FROM {table}", (), 5000)
                while chunk := list(islice(rows, 5000)):
                    out.executemany(f"INSERT INTO {table} ({names}) VALUES ({marks})", [tuple(r) for r in chunk])


_SAID_WHOLE = ("newer than", "damaged", "untouched", "cannot make the database", "cannot upgrade the database")
"""An error opening a database that says all there is (else it is prefixed "not a usable stickslip database")."""
_MIGRATION_BLOCKED = ("disk I/O error", "database or disk is full", "readonly database", "database is locked")
"""SQLite's words for a write the disk or the file refused (storage.sqlite.SQLiteBackend._write_problem's hints)."""


def _cannot_migrate(e: StoreError, path: Path | str, version: int) -> StoreError:
    """A migration the file or disk refused (full, read-only, busy), said as such: not "not a usable database".

    Every command, reading ones too, upgrades an older stickslip's database when it opens it; one that cannot
    be written then was called "not a usable stickslip database", which it is. Other errors are ``e``.
    """
    text = str(e)
    if text.startswith("cannot upgrade the database") or not any(why in text for why in _MIGRATION_BLOCKED):
        return e
    reason = text.removeprefix(f"cannot write to the database {path}: ").removesuffix(
        "; nothing of this change was stored")
    if version == 0:
        return StoreError(f"cannot make the database {path}: {reason}; nothing was written")
    return StoreError(
        f"cannot upgrade the database {path} from schema version {version} (an older stickslip's) to "
        f"{SCHEMA_VERSION}, which every command does before it reads: {reason}; it is left as it was"
    )


def _backup_problem(e: OSError | StoreError, tmp: Path, dest: Path) -> str:
    """One line naming the backup asked for, never its temporary ``.part`` file (which is gone by then)."""
    if isinstance(e, StoreError):
        text = str(e).replace(str(tmp), str(dest))
        return text if "nothing" in text else f"{text}; nothing was written"
    return f"cannot write the backup {dest}: {e.strerror or e}; nothing was written"


_COPY_ORDER = ("devices", "sessions", "traverses", "calibrations", "calibration_traverses", "device_state")
"""Tables in the order their foreign keys allow them to be filled (any later table after these)."""


_REAL_COLUMNS = ("q1", "q2", "q3", "theta", "psi", "start", "end")
_SHOULD = {
    "joint": "not a joint (1, 2 or 3)",
    "direction": "not a direction ('+' or '-')",
    "steps": "not a positive whole number of steps",
    "day": "not a session label (non-blank text)",
    **dict.fromkeys(_REAL_COLUMNS, "not a finite number (SI units)"),
}


def _bad_column(db: Backend) -> str:
    """SQL: the first column of a stored traverse ``t`` (with its session ``s``) whose value cannot be what it says."""
    quoted = {c: f't."{c}"' for c in _REAL_COLUMNS}
    reals = "".join(
        f" WHEN {db.not_a(q, 'real')} OR abs({q}) > 1.7976931348623157e308 THEN '{c}'" for c, q in quoted.items()
    )
    return (
        "CASE"
        f" WHEN {db.not_a('t.joint', 'integer')} OR t.joint NOT IN (1, 2, 3) THEN 'joint'"
        f" WHEN {db.not_a('t.direction', 'text')} OR t.direction NOT IN ('+', '-') THEN 'direction'"
        + reals
        + f" WHEN {db.not_a('t.steps', 'integer')} OR t.steps <= 0 THEN 'steps'"
        f" WHEN {db.not_a('s.day', 'text')} OR trim(s.day) = '' THEN 'day'"
        " END"
    )


def _require_traverses(con: Backend, ids: list[int], marks: str) -> None:
    """Raise ``ValueError`` naming the ids (of ``ids``) that are not stored traverses."""
    found = {int(r[0]) for r in con.execute(f"SELECT id FROM traverses WHERE id IN ({marks})", ids)}
    missing = [i for i in ids if i not in found]
    if missing:
        raise ValueError(f"no stored traverse with id {', '.join(map(str, missing))}")


def _copy_secrets_note(names: int, texts: int, copy: Path) -> str:
    """The note that an upgrade's copy still holds the passwords the old store kept (``names`` device names,
    ``texts`` traverses' how, source or reason), which the upgraded store no longer does."""
    parts = [f"{names} device name(s)"] if names else []
    parts += [f"{texts} traverse(s)' how, source or reason"] if texts else []
    what = " and ".join(parts)
    since = "2026-11-28" if texts else "2026-11-24"
    return (f"{what} of the old store held a password as written (stores made before {since}); the upgraded store "
            f"holds none, but its copy {copy} still does: delete the copy once you no longer need it, or keep it "
            "where only you can read it")
