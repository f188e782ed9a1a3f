"""Calibration history and every measured traverse, kept in an SQLite file or a shared PostgreSQL database.

The database lives in the user's data directory by default
(``$XDG_DATA_HOME/stickslip/stickslip.db``, else ``~/.local/share/stickslip/stickslip.db``;
``~/Library/Application Support/stickslip`` on macOS, ``%LOCALAPPDATA%\\stickslip`` on
Windows). The environment variable ``STICKSLIP_DB`` or an explicit path overrides it. A
``postgresql://user@host/dbname`` URL in their place keeps the same tables, through the
same :class:`Store`, in a PostgreSQL server several rigs share (the ``postgres`` extra;
:mod:`.postgres`, docs/storage.md). What differs between the two engines is behind one
typed seam, :class:`.backend.Backend`; the SQLite specifics below have their PostgreSQL
counterparts there.

Safety
------
* WAL journal, ``synchronous=FULL``, ``busy_timeout`` and foreign keys on every
  connection; every write is one ``BEGIN IMMEDIATE ... COMMIT`` transaction, so a crash
  (or Ctrl-C, or ``kill -9``) loses at most the write in flight and never corrupts the
  file, and several processes may write at once without losing rows.
* :meth:`Store.add_traverse` commits each traverse on its own: a measurement session
  that dies keeps every traverse completed before it died.
* The file is stickslip's: ``PRAGMA application_id`` is :data:`APPLICATION_ID`. Another
  application's SQLite file, a file that is not a database, a folder, FIFO or device is
  refused before anything is written (a database made before the id existed is known by
  its tables and stamped); a damaged file is one :class:`StoreError` naming it, never a
  ``sqlite3.DatabaseError``.
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

from ..clock import stale_message
from .calibrations import CalibrationStore
from .provenance import ProvenanceStore
from .schema import (
    APPLICATION_ID,
    BUSY_TIMEOUT_MS,
    DEFAULT_DEVICE,
    ENV_VAR,
    MIGRATIONS,
    POSTGRES_SCHEMES,
    SCHEMA_VERSION,
    ConstraintError,
    NoDatabase,
    StoreError,
    content_key,
    default_db_path,
    describe_database,
    resolve_database,
    resolve_db_path,
    warn_if_stale,
)
from .state import StateStore

__all__ = [
    "APPLICATION_ID",
    "BUSY_TIMEOUT_MS",
    "DEFAULT_DEVICE",
    "ENV_VAR",
    "MIGRATIONS",
    "POSTGRES_SCHEMES",
    "SCHEMA_VERSION",
    "ConstraintError",
    "NoDatabase",
    "Store",
    "StoreError",
    "content_key",
    "default_db_path",
    "describe_database",
    "resolve_database",
    "resolve_db_path",
    "warn_if_stale",
    "stale_message",
]


class Store(ProvenanceStore, CalibrationStore, StateStore):
    """The store of devices, sessions, traverses, calibrations and device state (SQLite or PostgreSQL).

    Open with :meth:`Store.open` (a context manager)::

        with Store.open() as store:               # default path, or $STICKSLIP_DB
            tid = store.add_traverse(t, device="sim://", how="simulated")
            cal = store.latest_calibration("sim://")

        with Store.open("postgresql://rig1@labdb/stickslip") as store:   # the lab's shared history
            ...

    Device URLs name a controller (``sim://``, ``mm3a:///dev/ttyUSB0`` ...); a device is
    stored under its key (:func:`.schema.stored_device`: ``mm3a:///COM3`` and
    ``mm3a://com3?timeout=5`` are ``mm3a://com3``), on every write and in every filter, and
    its row is created the first time it is used.
    """
