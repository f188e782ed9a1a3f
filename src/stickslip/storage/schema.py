"""The database's schema and its migrations, content keys of traverses, where the database lives."""

from __future__ import annotations

import datetime as _dt
import hashlib
import os
import re
import sqlite3
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from ..clock import now_utc, stale_message
from ..devices.base import controller_of, device_key, redact_url, url_scheme
from ..measurements import Traverse
from ..records import FILE_URL_DATABASE, is_file_url

if TYPE_CHECKING:  # pragma: no cover
    from ..calibration import Calibration


ENV_VAR = "STICKSLIP_DB"
APPLICATION_ID = 0x5374536C
"""``PRAGMA application_id`` of every stickslip database (``"StSl"``): a file without it is not written to
unless its tables are a stickslip schema (a database made before the id was set, stamped when opened)."""
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
    # version 3 -> 4: every device is stored under its key (device_key), however its URL was written; the
    # rows of older spellings are renamed and merged by storage.upgrade.key_devices, their content keys recomputed.
    # The index makes a traverse's calibration links quick to find (delete, and that merge).
    """
    CREATE INDEX calibration_traverses_traverse ON calibration_traverses(traverse_id)
    """,
    # version 4 -> 5: every device is stored under its controller's name (stored_device: the default port written
    # out, no / after the host), as its lock was taken: anc300://h, anc300://h:7230 and anc300://h/ kept three
    # positions of one arm. No table changes; the devices are renamed and merged as at 4 (storage.upgrade), their
    # kept positions merged by storage.spellings (a joint they kept apart becomes uncertain).
    "",
)
SCHEMA_VERSION = len(MIGRATIONS)

_COLUMNS = ("joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps")


def stored_device(url: str) -> str:
    """The name a device's rows are stored under, and its lock taken under: its controller
    (:func:`~stickslip.devices.base.controller_of`: its key with the scheme's default port written out and no
    ``/`` after the host).

    One name however the URL is written: ``mm3a:///COM3``, ``mm3a://COM3?timeout=5`` and ``mm3a://com3`` are
    ``mm3a://com3``; ``anc300://H``, ``anc300://h:7230/`` and ``anc300://h?password=x`` are
    ``anc300://h:7230``; options and secrets are dropped, except a simulator's ``seed`` (another simulated
    arm). A rig arm sharing its controller keeps its ``#arm=NAME``. Raises ``ValueError`` (without a secret)
    for an empty URL, one with no scheme (which :func:`device_key` would read as ``sim://``) or a malformed one.

    >>> stored_device("anc300://h?password=x"), stored_device("sim://?seed=3&realtime=1")
    ('anc300://h:7230', 'sim://?seed=3')
    >>> stored_device("mm3a:///COM3#arm=left"), stored_device("anc300://H:7230/#arm=left")
    ('mm3a://com3#arm=left', 'anc300://h:7230#arm=left')
    """
    text = str(url).strip()
    if not text:
        raise ValueError("device URL is empty (e.g. sim://)")
    arm = _ARM.search(text)
    base = text[: arm.start()] if arm else text
    url_scheme(base)
    # rstrip: 'anc300://h ?password=x' has the key 'anc300://h ' (a host ending in a space), whose own stored name
    # is 'anc300://h:7230': the name of a name must be itself, or the upgrade's rename collides (UNIQUE devices.url)
    return controller_of(device_key(base).rstrip()) + (arm.group(0) if arm else "")


_ARM = re.compile(r"#arm=[A-Za-z0-9][A-Za-z0-9 _.\-]{0,39}$")
"""A rig arm's part of a state key (``rig.model.Rig.state_key``): an arm name as rig files allow it."""


def device_filter(url: str) -> str:
    """What a ``--device`` filter matches: :func:`stored_device`, or for a URL it refuses the URL redacted (an
    older release's name kept as written; nothing else matches it). Never raises."""
    try:
        return stored_device(url)
    except ValueError:
        return redact_url(str(url).strip())


def lock_name(url: str) -> str:
    """The name of the lock a device URL takes: its stored name (:func:`device_filter`: the controller's, and a rig
    arm's ``#arm=NAME``), so that two processes never drive one controller at once, however each wrote its URL.
    Never raises.

    >>> lock_name("anc300://h"), lock_name("anc300://H:7230/?password=x"), lock_name("mm3a:///COM3#arm=left")
    ('anc300://h:7230', 'anc300://h:7230', 'mm3a://com3#arm=left')
    """
    return device_filter(url)


def content_key(t: Traverse, device: str) -> str:
    """A key equal for two traverses with the same device, day and row values (floats to 12 digits).

    Two real traverses can share it (a repeat that happened to take exactly as many steps);
    commands that refuse duplicates therefore offer ``--allow-duplicates``. ``-0.0`` is
    ``0.0`` here: SQLite stores a negative zero as 0, so a row exported from a file and
    imported again must have the key it was stored with.
    """
    return _content_keys([t], device)[0]


def _content_keys(traverses: Iterable[Traverse], device: str, signed_zeros: bool = False) -> list[str]:
    """:func:`content_key` of many traverses of one device (the URL redacted once, not per row).

    ``signed_zeros``: the key as stored before zeros were unsigned (``-0`` for a ``-0.0``),
    for finding rows stored then.
    """
    url = device_filter(device)  # the device's stored name: a row's key whichever way its URL was written
    fmt = "\x1f".join([url, "{}", "{}", "{}", *["{:.12g}"] * 7, "{}"]).format
    sha = hashlib.sha256
    zero = -0.0 if signed_zeros else 0.0  # x + 0.0 is x, except -0.0 + 0.0 = 0.0; x + -0.0 is x for every x
    return [
        "sha256:"
        + sha(
            fmt(
                str(t.day).strip(), int(t.joint), t.direction, float(t.q1) + zero, float(t.q2) + zero,
                float(t.q3) + zero, float(t.theta) + zero, float(t.psi) + zero, float(t.start) + zero,
                float(t.end) + zero, int(t.steps),
            ).encode()
        ).hexdigest()
        for t in traverses
    ]


class StoreError(OSError):
    """The database cannot be opened, read or written (the message says why and where).

    An ``OSError``: storage is the environment, and every command turns ``OSError`` into
    one ``error:`` line.
    """


class NoDatabase(StoreError):
    """Opened only to read (``create=False``), and there is no stickslip database there yet."""


class ConstraintError(ValueError):
    """A value the database's constraints refuse (a CHECK, a unique key, a number out of range).

    Raised by either backend in place of its driver's integrity error; the write it was
    part of was rolled back, so nothing of it was stored.
    """


# ---------------------------------------------------------------- where the file lives


def default_db_path() -> Path:
    """The per-user database file (not created here).

    ``$XDG_DATA_HOME/stickslip/stickslip.db`` (else ``~/.local/share/...``) on Linux and
    other Unix; ``~/Library/Application Support/stickslip/stickslip.db`` on macOS;
    ``%LOCALAPPDATA%\\stickslip\\stickslip.db`` on Windows (``platformdirs.user_data_path``).
    """
    import platformdirs  # the three platforms' conventions, as the config file's folder (config.py)

    return platformdirs.user_data_path("stickslip", appauthor=False) / "stickslip.db"


def resolve_db_path(path: str | os.PathLike[str] | None = None) -> Path:
    """``path``, else ``$STICKSLIP_DB``, else :func:`default_db_path`: a file only (see :func:`resolve_database`)."""
    target = resolve_database(path)
    if isinstance(target, str):
        raise StoreError(f"{describe_database(target)} is a database server, not a file")
    return target


POSTGRES_SCHEMES = ("postgresql", "postgres")
"""URL schemes of a PostgreSQL database (libpq's two spellings): ``postgresql://user@host:5432/dbname``."""


def database_scheme(spec: str) -> str | None:
    """The URL scheme ``spec`` begins with (``"postgresql"``), else ``None`` for a file path.

    A one-letter scheme is a Windows drive (``C:\\data``, ``C://data``), not a URL.
    """
    head, sep, _ = str(spec).strip().partition("://")
    if not sep or len(head) < 2 or not head[0].isalpha():
        return None
    if not all(c.isalnum() or c in "+-." for c in head):
        return None
    return head.lower()


def resolve_database(spec: str | os.PathLike[str] | None = None) -> Path | str:
    """Where the database is: a file (``Path``) or a PostgreSQL URL (``str``), as :meth:`Store.open` takes it.

    ``spec`` if given, else ``$STICKSLIP_DB`` if set, else :func:`default_db_path`. A
    ``postgresql://`` (or ``postgres://``) URL is returned as given, password and all
    (libpq needs it; :func:`describe_database` is the form to show). Any other
    ``scheme://`` is refused (:class:`StoreError` naming the scheme, not the rest): a
    URL is never taken for a file name.
    """
    if spec is None or str(spec) == "":
        env = os.environ.get(ENV_VAR)
        if not env:
            return default_db_path()
        spec, where = env, f"${ENV_VAR}"
    else:
        where = "the database"
    if isinstance(spec, os.PathLike):
        return Path(spec).expanduser()
    scheme = database_scheme(spec)
    if scheme is None and is_file_url(spec):  # SQLite's own URI form, RFC 8089's file:/path
        raise StoreError(f"{where}: {FILE_URL_DATABASE} (docs/storage.md)")
    if scheme is None:
        return Path(spec).expanduser()
    if scheme in POSTGRES_SCHEMES:
        return spec.strip()
    raise StoreError(
        f"{where}: {scheme}:// is not a database stickslip can use: give a file path (SQLite) or "
        "a postgresql://user@host/dbname URL (docs/storage.md)"
    )


def describe_database(target: Path | str) -> str:
    """``target`` as it may be shown: a file's path, or the URL without its password.

    The URL is cut apart without trusting it to be well formed: everything between
    ``://`` and the last ``@`` is the user information, of which only the user name is
    kept (so a password holding ``/``, ``?``, ``@`` or ``:`` that was not
    percent-encoded is dropped whole, never shown in part); a query option whose name
    holds ``pass``, ``secret``, ``token`` or ``pw`` (``password``, ``sslpassword``)
    shows ``***``. Last, the password (4 characters or more, as written and decoded) shows
    ``***`` wherever it still appears, even where the same characters are part of the host,
    path or options (a password ``opti`` shows ``?***ons=``): never the secret. Never raises.
    """
    if isinstance(target, Path):
        return str(target)
    text = str(target).strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        return redact_url(text)
    userinfo, at, after = rest.rpartition("@")
    shown = f"{scheme}://" + (userinfo.partition(":")[0] + "@" if at else "")
    main, q, query = after.partition("?")
    shown += main
    if q:
        opts = []
        for opt in query.split("&"):
            key, eq, _ = opt.partition("=")
            hidden = bool(eq) and any(w in key.lower() for w in ("pass", "secret", "token", "pw"))
            opts.append(f"{key}=***" if hidden else opt)
        shown += "?" + "&".join(opts)
    for pw in url_secrets(text):
        if len(pw) >= 4:  # belt and braces: a password that got into another part anyway
            shown = shown.replace(pw, "***")
    return redact_url(shown)


def url_secrets(url: str) -> list[str]:
    """Every form a URL's password may take in a message: as written, and percent-decoded."""
    from urllib.parse import unquote

    out: list[str] = []
    rest = str(url).partition("://")[2]
    userinfo, at, after = rest.rpartition("@")
    if at and ":" in userinfo:
        pw = userinfo.partition(":")[2]
        out += [pw, unquote(pw)]
    for opt in after.partition("?")[2].split("&"):
        key, eq, value = opt.partition("=")
        if eq and any(w in key.lower() for w in ("pass", "secret", "token", "pw")):
            out += [value, unquote(value)]
    return [s for s in out if s]


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



def _split_sql(script: str) -> list[str]:
    """Statements of a migration script (no semicolons inside our statements)."""
    return [s.strip() for s in script.split(";") if s.strip()]


def tables_of(con: sqlite3.Connection) -> dict[str, tuple[str, ...]]:
    """``{table: column names}`` of an SQLite database (its own tables, not SQLite's)."""
    sql = "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%'"
    names = [r[0] for r in con.execute(sql)]
    return {n: tuple(r[1] for r in con.execute(f'PRAGMA table_info("{n}")')) for n in names}


def schema_tables(version: int) -> dict[str, tuple[str, ...]]:
    """The tables and columns a stickslip database has at schema ``version``, on either backend.

    The migrations run in an SQLite database in memory: they are the reference the
    SQLite file's legacy check and the PostgreSQL backend's integrity check compare to.
    """
    con = sqlite3.connect(":memory:")
    try:
        for script in MIGRATIONS[:version]:
            for stmt in _split_sql(script):
                con.execute(stmt)
        return tables_of(con)
    finally:
        con.close()
