"""Calibration history and every measured traverse, kept in an embedded SQLite file.

The database lives in the user's data directory by default
(``$XDG_DATA_HOME/stickslip/stickslip.db``, else ``~/.local/share/stickslip/stickslip.db``;
``~/Library/Application Support/stickslip`` on macOS, ``%LOCALAPPDATA%\\stickslip`` on
Windows). The environment variable ``STICKSLIP_DB`` or an explicit path overrides it.

Safety
------
* WAL journal, ``synchronous=FULL``, ``busy_timeout`` and foreign keys on every
  connection; every write is one ``BEGIN IMMEDIATE ... COMMIT`` transaction, so a crash
  (or Ctrl-C, or ``kill -9``) loses at most the write in flight and never corrupts the
  file, and several processes may write at once without losing rows.
* :meth:`Store.add_traverse` commits each traverse on its own: a measurement session
  that dies keeps every traverse completed before it died.
* The schema is versioned with ``PRAGMA user_version``; :data:`MIGRATIONS` is the
  ordered list of SQL scripts that bring a file from version *k* to *k + 1*. Opening a
  file runs the missing ones in one transaction; a file from a newer stickslip is
  refused rather than guessed at.

Tables: ``devices`` (url, model), ``sessions`` (device, day), ``traverses`` (the
measurement-table row, when and how it was measured, where it came from),
``calibrations`` (the Calibration's JSON, day, method, created_at),
``calibration_traverses`` (which traverses a calibration used) and ``device_state``
(small per-device key/value JSON, e.g. dead-reckoned joint positions).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import sqlite3
import sys
import time
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .clock import now_utc, stale_message
from .devices.base import redact_url
from .measurements import Traverse

if TYPE_CHECKING:  # pragma: no cover
    from .calibration import Calibration

__all__ = [
    "ENV_VAR",
    "MIGRATIONS",
    "SCHEMA_VERSION",
    "Store",
    "StoreError",
    "default_db_path",
    "resolve_db_path",
    "warn_if_stale",
    "stale_message",
]

ENV_VAR = "STICKSLIP_DB"
DEFAULT_DEVICE = "sim://"
BUSY_TIMEOUT_MS = 30_000

MIGRATIONS: tuple[str, ...] = (
    # version 0 -> 1: the first schema
    """
    CREATE TABLE devices (
        id          INTEGER PRIMARY KEY,
        url         TEXT NOT NULL UNIQUE,
        model       TEXT,
        created_at  TEXT NOT NULL
    );
    CREATE TABLE sessions (
        id          INTEGER PRIMARY KEY,
        device_id   INTEGER NOT NULL REFERENCES devices(id),
        day         TEXT NOT NULL,
        created_at  TEXT NOT NULL,
        UNIQUE (device_id, day)
    );
    CREATE TABLE traverses (
        id          INTEGER PRIMARY KEY,
        session_id  INTEGER NOT NULL REFERENCES sessions(id),
        joint       INTEGER NOT NULL CHECK (joint IN (1, 2, 3)),
        direction   TEXT NOT NULL CHECK (direction IN ('+', '-')),
        q1          REAL NOT NULL,
        q2          REAL NOT NULL,
        q3          REAL NOT NULL,
        theta       REAL NOT NULL,
        psi         REAL NOT NULL,
        start       REAL NOT NULL,
        "end"       REAL NOT NULL,
        steps       INTEGER NOT NULL CHECK (steps > 0),
        measured_at TEXT NOT NULL,
        how         TEXT NOT NULL,
        source      TEXT
    );
    CREATE INDEX traverses_session ON traverses(session_id, joint);
    CREATE TABLE calibrations (
        id          INTEGER PRIMARY KEY,
        device_id   INTEGER NOT NULL REFERENCES devices(id),
        day         TEXT,
        method      TEXT,
        created_at  TEXT NOT NULL,
        json        TEXT NOT NULL
    );
    CREATE INDEX calibrations_device ON calibrations(device_id, id);
    CREATE TABLE calibration_traverses (
        calibration_id INTEGER NOT NULL REFERENCES calibrations(id) ON DELETE CASCADE,
        traverse_id    INTEGER NOT NULL REFERENCES traverses(id),
        PRIMARY KEY (calibration_id, traverse_id)
    );
    CREATE TABLE device_state (
        device_id   INTEGER NOT NULL REFERENCES devices(id),
        key         TEXT NOT NULL,
        value       TEXT NOT NULL,
        updated_at  TEXT NOT NULL,
        PRIMARY KEY (device_id, key)
    );
    """,
    # version 1 -> 2: a traverse can be excluded from analyses (the reason is kept; NULL = used)
    """
    ALTER TABLE traverses ADD COLUMN excluded TEXT
    """,
    # version 2 -> 3: a content key per traverse (device, day and the row's values), so that the
    # same measurement stored twice (a demo run twice, a table imported twice) is found
    """
    ALTER TABLE traverses ADD COLUMN content TEXT;
    CREATE INDEX traverses_content ON traverses(content)
    """,
)
SCHEMA_VERSION = len(MIGRATIONS)

_COLUMNS = ("joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps")


def content_key(t: Traverse, device: str) -> str:
    """A key equal for two traverses with the same device, day and row values (floats to 12 digits).

    Two real traverses can share it (a repeat that happened to take exactly as many steps);
    commands that refuse duplicates therefore offer ``--allow-duplicates``.
    """
    return _content_keys([t], device)[0]


def _content_keys(traverses: Iterable[Traverse], device: str) -> list[str]:
    """:func:`content_key` of many traverses of one device (the URL redacted once, not per row)."""
    url = redact_url(str(device).strip())
    fmt = "\x1f".join([url, "{}", "{}", "{}", *["{:.12g}"] * 7, "{}"]).format
    sha = hashlib.sha256
    return [
        "sha256:"
        + sha(
            fmt(
                str(t.day).strip(), int(t.joint), t.direction, float(t.q1), float(t.q2), float(t.q3),
                float(t.theta), float(t.psi), float(t.start), float(t.end), int(t.steps),
            ).encode()
        ).hexdigest()
        for t in traverses
    ]


class StoreError(OSError):
    """The database cannot be opened, read or written (the message says why and where).

    An ``OSError``: storage is the environment, and every command turns ``OSError`` into
    one ``error:`` line.
    """


# ---------------------------------------------------------------- where the file lives


def default_db_path() -> Path:
    """The per-user database file (not created here).

    ``$XDG_DATA_HOME/stickslip/stickslip.db`` (else ``~/.local/share/...``) on Linux and
    other Unix; ``~/Library/Application Support/stickslip/stickslip.db`` on macOS;
    ``%LOCALAPPDATA%\\stickslip\\stickslip.db`` on Windows.
    """
    home = Path.home()
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or home / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = home / "Library" / "Application Support"
    else:
        xdg = os.environ.get("XDG_DATA_HOME")
        base = Path(xdg) if xdg and os.path.isabs(xdg) else home / ".local" / "share"
    return base / "stickslip" / "stickslip.db"


def resolve_db_path(path: str | os.PathLike[str] | None = None) -> Path:
    """``path`` if given, else ``$STICKSLIP_DB`` if set, else :func:`default_db_path`."""
    if path is not None and str(path) != "":
        return Path(path).expanduser()
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env).expanduser()
    return default_db_path()


def _now() -> str:
    return now_utc().isoformat(timespec="microseconds")


def _iso(t: _dt.datetime | None) -> str:
    if t is None:
        return _now()
    if t.tzinfo is None:
        t = t.astimezone()  # naive = local time
    return t.astimezone(_dt.UTC).isoformat(timespec="microseconds")


# ---------------------------------------------------------------- staleness


def warn_if_stale(cal: Calibration, today: str | None = None, max_age_days: int = 0) -> str | None:
    """Warning text if ``cal`` is older than ``max_age_days`` (default: from an earlier day), else ``None``.

    Text: ``"calibration is from DAY, today is TODAY (N days old): recalibrate ..."``.
    Today and a calibration's age are defined once, in :mod:`stickslip.clock`.
    """
    return stale_message(getattr(cal, "day", None), today, max_age_days)


# ---------------------------------------------------------------- the store


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


class Store:
    """The SQLite store of devices, sessions, traverses, calibrations and device state.

    Open with :meth:`Store.open` (a context manager)::

        with Store.open() as store:               # default path, or $STICKSLIP_DB
            tid = store.add_traverse(t, device="sim://", how="simulated")
            cal = store.latest_calibration("sim://")

    Device URLs name a controller (``sim://``, ``serial:///dev/ttyUSB0`` ...); a device
    row is created the first time a URL is used.
    """

    def __init__(self, con: sqlite3.Connection, path: Path):
        self._con = con
        self.path = path

    # -- opening / closing

    @classmethod
    def open(cls, path: str | os.PathLike[str] | None = None) -> Store:
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

    def __enter__(self) -> Store:
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

    # -- traverses

    @staticmethod
    def _check(t: Traverse) -> None:
        if not isinstance(t, Traverse):
            raise TypeError(f"expected a Traverse, got {type(t).__name__}")
        if not str(t.day).strip():
            raise ValueError("traverse has an empty day (session label)")

    def _insert_traverse(
        self,
        con: sqlite3.Connection,
        t: Traverse,
        device_id: int,
        how: str,
        measured_at: str,
        source: str | None,
    ) -> int:
        sid = self._session_id(con, device_id, str(t.day))
        url = con.execute("SELECT url FROM devices WHERE id = ?", (device_id,)).fetchone()["url"]
        return self._insert_row(con, t, sid, how, measured_at, source, content_key(t, url))

    _INSERT = (
        "INSERT INTO traverses (session_id, joint, direction, q1, q2, q3, theta, psi, "
        '    start, "end", steps, '
        "measured_at, how, source, content) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)"
    )

    @staticmethod
    def _insert_row(
        con: sqlite3.Connection, t: Traverse, sid: int, how: str, measured_at: str, source: str | None, key: str
    ) -> int:
        cur = con.execute(Store._INSERT, Store._row_values(t, sid, how, measured_at, source, key))
        return _rowid(cur)

    @staticmethod
    def _row_values(
        t: Traverse, sid: int, how: str, measured_at: str, source: str | None, key: str
    ) -> tuple[object, ...]:
        return (
            sid,
            int(t.joint),
            t.direction,
            float(t.q1),
            float(t.q2),
            float(t.q3),
            float(t.theta),
            float(t.psi),
            float(t.start),
            float(t.end),
            int(t.steps),
            measured_at,
            how,
            source,
            key,
        )

    def duplicates(self, traverses: Iterable[Traverse], device: str = DEFAULT_DEVICE) -> list[int]:
        """Positions (0-based) of the given traverses whose content is already stored for ``device``."""
        keys = _content_keys(traverses, device)
        stored: set[str] = set()
        step = 500  # keys per query (SQLite allows 999 parameters in old builds)
        for i in range(0, len(keys), step):
            part = keys[i : i + step]
            rows = self._con.execute(
                f"SELECT DISTINCT content FROM traverses WHERE content IN ({','.join('?' * len(part))})", part
            )
            stored.update(r[0] for r in rows)
        return [k for k, key in enumerate(keys) if key in stored]

    def add_traverse(
        self,
        traverse: Traverse,
        device: str = DEFAULT_DEVICE,
        how: str = "measured",
        measured_at: _dt.datetime | None = None,
        source: str | None = None,
    ) -> int:
        """Record one traverse in its own transaction; returns its id.

        Parameters
        ----------
        traverse : Traverse
            The measurement-table row (SI units).
        device : str
            Device URL, e.g. ``"sim://"``.
        how : str
            How it was measured: ``"simulated"``, ``"audio"``, ``"imported"``, ``"measured"`` ...
        measured_at : datetime, optional
            When (default now); naive datetimes are local time, stored as UTC.
        source : str, optional
            Provenance (e.g. the file it was imported from).
        """
        self._check(traverse)
        with self._write() as con:
            dev = self._device_id(con, device)
            return self._insert_traverse(con, traverse, dev, how, _iso(measured_at), source)

    def add_traverses(
        self,
        traverses: Iterable[Traverse],
        device: str = DEFAULT_DEVICE,
        how: str = "measured",
        measured_at: _dt.datetime | None = None,
        source: str | None = None,
    ) -> list[int]:
        """Record many traverses in ONE transaction (all or nothing); returns their ids.

        Use it for imports; use :meth:`add_traverse` while measuring, so that each
        completed traverse is safe on its own.
        """
        ts = list(traverses)
        for t in ts:
            self._check(t)
        when = _iso(measured_at)
        with self._write() as con:
            dev = self._device_id(con, device)
            url = con.execute("SELECT url FROM devices WHERE id = ?", (dev,)).fetchone()["url"]
            sessions: dict[str, int] = {}  # one look-up per day, not per row
            values = []
            for t, key in zip(ts, _content_keys(ts, url), strict=True):
                day = str(t.day)
                sid = sessions.get(day)
                if sid is None:
                    sid = sessions[day] = self._session_id(con, dev, day)
                values.append(self._row_values(t, sid, how, when, source, key))
            # one executemany; in this write transaction the new rows are exactly those above the old largest id
            before = int(con.execute("SELECT COALESCE(MAX(id), 0) FROM traverses").fetchone()[0])
            con.executemany(self._INSERT, values)
            ids = [int(r[0]) for r in con.execute("SELECT id FROM traverses WHERE id > ? ORDER BY id", (before,))]
            if len(ids) != len(values):  # pragma: no cover - would mean another writer inside our transaction
                raise StoreError(f"{self.path}: stored {len(ids)} rows for {len(values)} traverses; nothing kept")
            return ids

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

    def iter_traverses(
        self, device: str | None = None, day: str | None = None, joint: int | None = None, chunk: int = 10_000
    ) -> Iterator[Traverse]:
        """Like :meth:`traverses`, read ``chunk`` rows at a time (exports of any size in bounded memory)."""
        cur = self._traverse_cursor(device, day, joint)
        while rows := cur.fetchmany(chunk):
            yield from map(self._to_traverse, rows)

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

    def traverses(
        self, device: str | None = None, day: str | None = None, joint: int | None = None
    ) -> list[Traverse]:
        """Stored traverses in the order they were recorded, optionally filtered."""
        return [self._to_traverse(r) for r in self._traverse_rows(device, day, joint)]

    def traverse_records(
        self, device: str | None = None, day: str | None = None, joint: int | None = None
    ) -> list[dict[str, Any]]:
        """Like :meth:`traverses`, as dicts with ``id, device, measured_at, how, source`` too."""
        out = []
        for r in self._traverse_rows(device, day, joint):
            d = {
                k: r[k] for k in ("id", "device", "day", *_COLUMNS, "measured_at", "how", "source")
            }
            out.append(d)
        return out

    def count_traverses(self, device: str | None = None) -> int:
        """Number of stored traverses (of one device, or all)."""
        if device is None:
            return int(self._con.execute("SELECT COUNT(*) FROM traverses").fetchone()[0])
        return int(
            self._con.execute(
                "SELECT COUNT(*) FROM traverses t JOIN sessions s ON s.id = t.session_id "
                "JOIN devices d ON d.id = s.device_id WHERE d.url = ?",
                (redact_url(device),),
            ).fetchone()[0]
        )

    def has_source(self, source: str) -> bool:
        """Whether traverses from ``source`` (e.g. a file's checksum) were stored already."""
        return (
            self._con.execute(
                "SELECT 1 FROM traverses WHERE source = ? LIMIT 1", (source,)
            ).fetchone()
            is not None
        )

    def days(self, device: str | None = None) -> list[str]:
        """Session labels that hold traverses or calibrations, sorted."""
        sql = "SELECT DISTINCT s.day FROM sessions s JOIN devices d ON d.id = s.device_id"
        args: tuple[Any, ...] = ()
        if device is not None:
            sql += " WHERE d.url = ?"
            args = (redact_url(device),)
        days = {r[0] for r in self._con.execute(sql, args)}
        csql = (
            "SELECT DISTINCT c.day FROM calibrations c JOIN devices d ON d.id = c.device_id "
            "WHERE c.day IS NOT NULL"
        )
        if device is not None:
            csql += " AND d.url = ?"
        days |= {r[0] for r in self._con.execute(csql, args)}
        return sorted(days)

    # -- calibrations

    def add_calibration(
        self,
        cal: Calibration,
        device: str = DEFAULT_DEVICE,
        traverse_ids: Sequence[int] | None = None,
    ) -> int:
        """Store a calibration (its JSON, day, method) and the traverses it used; returns its id.

        Raises ``ValueError`` naming the ids that do not exist.
        """
        doc = json.dumps(cal.to_dict(), sort_keys=True)
        day = getattr(cal, "day", None)
        method = getattr(cal, "method", None)
        ids = [int(i) for i in (traverse_ids or [])]
        with self._write() as con:
            dev = self._device_id(con, device)
            if day:
                self._session_id(con, dev, str(day))
            if ids:
                found = {
                    r[0]
                    for r in con.execute(
                        f"SELECT id FROM traverses WHERE id IN ({','.join('?' * len(ids))})", ids
                    )
                }
                missing = sorted(set(ids) - found)
                if missing:
                    raise ValueError(f"no stored traverse with id {', '.join(map(str, missing))}")
            cur = con.execute(
                "INSERT INTO calibrations (device_id, day, method, created_at, json) "
                "VALUES (?, ?, ?, ?, ?)",
                (dev, day, method, _now(), doc),
            )
            cid = _rowid(cur)
            con.executemany(
                "INSERT OR IGNORE INTO calibration_traverses VALUES (?, ?)", [(cid, i) for i in ids]
            )
            return cid

    def _load_cal(self, doc: str) -> Calibration:
        from .calibration import Calibration

        return Calibration.from_dict(json.loads(doc))

    def calibration(self, calibration_id: int) -> Calibration:
        """The stored calibration with this id (``KeyError`` if none)."""
        row = self._con.execute(
            "SELECT json FROM calibrations WHERE id = ?", (int(calibration_id),)
        ).fetchone()
        if row is None:
            raise KeyError(f"no calibration with id {calibration_id}")
        return self._load_cal(row[0])

    def latest_calibration(self, device: str | None = None) -> Calibration | None:
        """The most recently stored calibration (of ``device``, or of any), or ``None``."""
        sql = "SELECT c.json FROM calibrations c JOIN devices d ON d.id = c.device_id"
        args: tuple[Any, ...] = ()
        if device is not None:
            sql += " WHERE d.url = ?"
            args = (redact_url(device),)
        row = self._con.execute(sql + " ORDER BY c.id DESC LIMIT 1", args).fetchone()
        return None if row is None else self._load_cal(row[0])

    def calibration_traverses(self, calibration_id: int) -> list[Traverse]:
        """The traverses a stored calibration was made from."""
        ids = [
            r[0]
            for r in self._con.execute(
                "SELECT traverse_id FROM calibration_traverses WHERE calibration_id = ? "
                "ORDER BY traverse_id",
                (int(calibration_id),),
            )
        ]
        if not ids:
            return []
        return [self._to_traverse(r) for r in self._traverse_rows(None, None, None, ids)]

    def calibrations(self, device: str | None = None) -> list[dict[str, Any]]:
        """Stored calibrations, oldest first.

        Each: ``{"id", "device", "day", "method", "created_at", "traverses"}``.
        """
        sql = (
            "SELECT c.id, d.url AS device, c.day, c.method, c.created_at, "
            "(SELECT COUNT(*) FROM calibration_traverses ct WHERE ct.calibration_id = c.id) "
            "AS traverses "
            "FROM calibrations c JOIN devices d ON d.id = c.device_id"
        )
        args: tuple[Any, ...] = ()
        if device is not None:
            sql += " WHERE d.url = ?"
            args = (redact_url(device),)
        return [dict(r) for r in self._con.execute(sql + " ORDER BY c.id", args)]

    # -- history

    def history(self, device: str | None = None) -> list[dict[str, Any]]:
        """One entry per device and session day, in day order.

        Each: ``device``, ``day``, ``traverses`` (count), ``by_joint`` (``{"3+": n, ...}``),
        ``first_measured_at``, ``last_measured_at`` (UTC ISO, or None),
        ``calibrations`` (list of ``{"id", "method", "created_at"}`` made for that day).
        """
        sql = (
            "SELECT d.url AS device, s.day AS day, t.joint AS joint, t.direction AS direction, "
            "COUNT(t.id) AS n, SUM(t.excluded IS NOT NULL) AS x, "
            "MIN(t.measured_at) AS first, MAX(t.measured_at) AS last "
            "FROM sessions s JOIN devices d ON d.id = s.device_id "
            "LEFT JOIN traverses t ON t.session_id = s.id"
        )
        args: tuple[Any, ...] = ()
        if device is not None:
            sql += " WHERE d.url = ?"
            args = (redact_url(device),)
        sql += " GROUP BY d.url, s.day, t.joint, t.direction"
        entries: dict[tuple[str, str], dict[str, Any]] = {}
        for r in self._con.execute(sql, args):
            e = entries.setdefault(
                (r["device"], r["day"]),
                {
                    "device": r["device"],
                    "day": r["day"],
                    "traverses": 0,
                    "excluded": 0,
                    "by_joint": {},
                    "first_measured_at": None,
                    "last_measured_at": None,
                    "calibrations": [],
                },
            )
            if r["joint"] is None:
                continue
            used = int(r["n"]) - int(r["x"] or 0)
            e["traverses"] += used
            e["excluded"] += int(r["x"] or 0)
            e["by_joint"][f"{r['joint']}{r['direction']}"] = used
            if e["first_measured_at"] is None or r["first"] < e["first_measured_at"]:
                e["first_measured_at"] = r["first"]
            if e["last_measured_at"] is None or r["last"] > e["last_measured_at"]:
                e["last_measured_at"] = r["last"]
        for c in self.calibrations(device):
            key = (c["device"], c["day"])
            if key in entries:
                entries[key]["calibrations"].append(
                    {"id": c["id"], "method": c["method"], "created_at": c["created_at"]}
                )
        return sorted(entries.values(), key=lambda e: (e["device"], e["day"]))

    # -- per-device state

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        """Store a small JSON value under ``key`` for ``device`` (replaces the old one).

        ``value_json`` is JSON text, or any JSON-serialisable object (it is dumped).
        """
        if isinstance(value_json, str):
            try:
                json.loads(value_json)
                text = value_json
            except json.JSONDecodeError:
                text = json.dumps(value_json)
        else:
            text = json.dumps(value_json)
        with self._write() as con:
            dev = self._device_id(con, device)
            con.execute(
                "INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, ?, ?, ?) "
                "ON CONFLICT (device_id, key) DO UPDATE SET value = excluded.value, "
                "updated_at = excluded.updated_at",
                (dev, key, text, _now()),
            )

    def get_state(self, device: str, key: str, default: Any = None) -> Any:
        """The decoded JSON value stored under ``key`` for ``device``, or ``default``."""
        row = self._con.execute(
            "SELECT s.value FROM device_state s JOIN devices d ON d.id = s.device_id "
            "WHERE d.url = ? AND s.key = ?",
            (redact_url(device), key),
        ).fetchone()
        return default if row is None else json.loads(row[0])

    # -- deleting

    def traverse_ids(self, device: str | None = None, day: str | None = None) -> list[int]:
        """Ids of the stored traverses (of one device and/or session day)."""
        return [int(r["id"]) for r in self._traverse_rows(device, day, None, include_excluded=True)]

    def set_excluded(self, ids: Sequence[int], reason: str | None) -> int:
        """Exclude traverses from analyses (``reason``, kept) or include them again (``None``).

        Excluded traverses stay stored (``export``/``history`` count them apart) but are not
        returned by :meth:`traverses`. Raises ``ValueError`` naming unknown ids (nothing changes).
        """
        ids = sorted({int(i) for i in ids})
        if reason is not None and not reason.strip():
            raise ValueError("give a reason for excluding (e.g. 'cable snagged')")
        marks = ",".join("?" * len(ids))
        with self._write() as con:
            _require_traverses(con, ids, marks)
            return int(con.execute(f"UPDATE traverses SET excluded = ? WHERE id IN ({marks})", [reason, *ids]).rowcount)

    def delete_traverses(self, ids: Sequence[int]) -> dict[str, int]:
        """Delete traverses by id in one transaction; ``{"traverses": n, "calibration_links": m}``.

        Calibrations made from them keep their stored parameters (their JSON is complete);
        only the links to the deleted rows go. Sessions left empty are removed. Raises
        ``ValueError`` naming ids that do not exist (and deletes nothing).
        """
        ids = sorted({int(i) for i in ids})
        if not ids:
            return {"traverses": 0, "calibration_links": 0}
        marks = ",".join("?" * len(ids))
        with self._write() as con:
            _require_traverses(con, ids, marks)
            links = con.execute(f"DELETE FROM calibration_traverses WHERE traverse_id IN ({marks})", ids).rowcount
            n = con.execute(f"DELETE FROM traverses WHERE id IN ({marks})", ids).rowcount
            con.execute(
                "DELETE FROM sessions WHERE id NOT IN (SELECT session_id FROM traverses) "
                "AND NOT EXISTS (SELECT 1 FROM calibrations c WHERE c.device_id = sessions.device_id "
                "AND c.day = sessions.day)"
            )
        return {"traverses": int(n), "calibration_links": int(links)}

    # -- one process drives a device at a time

    def acquire_lock(self, device: str, holder: dict[str, Any]) -> dict[str, Any] | None:
        """Take ``device``'s lock for ``holder`` (``{"pid", "host", "since"}``), atomically.

        Returns ``None`` when taken, else the current holder (the caller refuses, naming
        it). A lock whose holder is a process on this host that no longer exists (POSIX
        only; elsewhere a lock is released only by its holder) is taken over.
        """
        with self._write() as con:
            dev = self._device_id(con, device)
            row = con.execute(
                "SELECT value FROM device_state WHERE device_id = ? AND key = 'lock'", (dev,)
            ).fetchone()
            if row is not None:
                current = json.loads(row[0])
                if isinstance(current, dict) and _alive(current):
                    return dict(current)
            con.execute(
                "INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, 'lock', ?, ?) "
                "ON CONFLICT (device_id, key) DO UPDATE SET value = excluded.value, "
                "updated_at = excluded.updated_at",
                (dev, json.dumps(holder), _now()),
            )
        return None

    def release_lock(self, device: str, pid: int) -> None:
        """Release ``device``'s lock if process ``pid`` holds it."""
        with self._write() as con:
            dev = self._device_id(con, device)
            row = con.execute(
                "SELECT value FROM device_state WHERE device_id = ? AND key = 'lock'", (dev,)
            ).fetchone()
            if row is not None and json.loads(row[0]).get("pid") == pid:
                con.execute("DELETE FROM device_state WHERE device_id = ? AND key = 'lock'", (dev,))

    # -- maintenance

    def integrity_check(self) -> str:
        """``PRAGMA integrity_check`` (``"ok"`` when the file is sound)."""
        return "; ".join(r[0] for r in self._con.execute("PRAGMA integrity_check"))



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


def _alive(holder: dict[str, Any]) -> bool:
    """Whether a lock holder may still be running (unknown counts as running)."""
    import socket

    pid = holder.get("pid")
    if not isinstance(pid, int) or holder.get("host") != socket.gethostname() or os.name != "posix":
        return True
    try:
        os.kill(pid, 0)  # POSIX: signal 0 only checks that the process exists
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _split_sql(script: str) -> list[str]:
    """Statements of a migration script (no semicolons inside our statements)."""
    return [s.strip() for s in script.split(";") if s.strip()]
