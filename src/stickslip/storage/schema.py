"""The database's schema and its migrations, content keys of traverses, where the file lives."""

from __future__ import annotations

import datetime as _dt
import hashlib
import os
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from ..clock import now_utc, stale_message
from ..devices.base import redact_url
from ..measurements import Traverse

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
    ``%LOCALAPPDATA%\\stickslip\\stickslip.db`` on Windows (``platformdirs.user_data_path``).
    """
    import platformdirs  # the three platforms' conventions, as the config file's folder (config.py)

    return platformdirs.user_data_path("stickslip", appauthor=False) / "stickslip.db"


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



def _split_sql(script: str) -> list[str]:
    """Statements of a migration script (no semicolons inside our statements)."""
    return [s.strip() for s in script.split(";") if s.strip()]
