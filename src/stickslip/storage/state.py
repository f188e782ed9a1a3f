"""Per-device state and the device lock."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from ..devices.base import command_url, redact_text, redact_url
from ..processes import process_gone
from ..records import loads_json
from .base import _Base
from .schema import StoreError, _now, device_filter, lock_name

if TYPE_CHECKING:  # pragma: no cover
    from .backend import Backend


class StateStore(_Base):
    """Small per-device state (positions, the move journal) and the one-process device lock."""

    # -- per-device state

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        """Store a small JSON value under ``key`` for ``device`` (replaces the old one).

        ``value_json`` is JSON text, or any JSON-serialisable object (it is dumped). A value
        :meth:`get_state` would refuse (a NaN or an infinity, a key twice) is refused here,
        ``ValueError``, and the old value kept: stored, it made the device's state unreadable.
        """
        if isinstance(value_json, str):
            try:
                json.loads(value_json)
                text = value_json
            except json.JSONDecodeError:
                text = json.dumps(value_json)
        else:
            text = json.dumps(value_json)
        text = redact_text(text)  # no secret is stored
        loads_json(text, f"the state {key!r} of {redact_url(device)}")  # read back as get_state reads it
        with self._write() as con:
            dev = self._device_id(con, device)
            con.execute(
                "INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, ?, ?, ?) "
                "ON CONFLICT (device_id, key) DO UPDATE SET value = excluded.value, "
                "updated_at = excluded.updated_at",
                (dev, key, text, _now()),
            )

    def get_state(self, device: str, key: str, default: Any = None) -> Any:
        """The decoded JSON value stored under ``key`` for ``device``, or ``default``.

        A stored value that is not JSON (or gives a key twice) raises :class:`StoreError`
        naming the database, the device and the key.
        """
        row = self._con.execute(
            "SELECT s.value FROM device_state s JOIN devices d ON d.id = s.device_id "
            "WHERE d.url = ? AND s.key = ?",
            (device_filter(device), key),
        ).fetchone()
        return default if row is None else self._json(row[0], device, key)

    def _json(self, text: object, device: str, key: str) -> Any:
        where = f"{self.path}: the stored {key!r} of {redact_url(device)}"
        if not isinstance(text, str):
            raise StoreError(f"{where} holds {type(text).__name__}, not JSON text")
        try:
            return loads_json(text, where)
        except ValueError as e:
            raise StoreError(str(e)) from None

    # -- one process drives a device at a time

    def acquire_lock(self, device: str, holder: dict[str, Any]) -> dict[str, Any] | None:
        """Take ``device``'s lock for ``holder`` (``{"pid", "host", "since"}``), atomically.

        Returns ``None`` when taken, else the current holder (the caller refuses, naming
        it). The lock is a row of the device's state, written in one write transaction.
        On PostgreSQL it is also a session-level advisory lock, which the server frees
        when the holder's connection ends: a lock left by a process that died, on any
        host, is taken over. On SQLite a lock whose holder is a process on this host
        that no longer exists (:func:`~stickslip.processes.process_gone`, POSIX only;
        elsewhere a lock is released only by its holder, or by ``where --unlock``) is taken over.

        One controller written two ways (``anc300://h``, ``anc300://h:7230``) is one device, stored under
        one name (:func:`~.schema.stored_device`) whose row holds its one lock (:func:`~.schema.lock_name`).
        """
        name = f"device {lock_name(device)}"  # one lock however the URL is written, the controller's default port too
        claimed: bool | None = None
        try:
            with self._write() as con:
                dev, current = self._lock_row(con, device)
                claimed = con.claim(name)
                if claimed is False:  # a live connection holds it (the server knows)
                    if isinstance(current, dict):
                        return dict(current)
                    return {"pid": "?", "host": "another connection to the shared database", "since": "?"}
                if claimed is None and isinstance(current, dict) and not process_gone(current):  # unknown: running
                    return dict(current)
                con.execute(
                    "INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, 'lock', ?, ?) "
                    "ON CONFLICT (device_id, key) DO UPDATE SET value = excluded.value, "
                    "updated_at = excluded.updated_at",
                    (dev, json.dumps(holder), _now()),
                )
        except BaseException:
            if claimed:  # the row was not written: nor is the lock held
                self._con.release(name)
            raise
        return None

    def _lock_row(self, con: Backend, device: str) -> tuple[int, Any]:
        """``device``'s id and its stored lock holder (decoded, or ``None``), read inside the write ``con``;
        :class:`StoreError` with the way out (``where --unlock``) for a row that cannot be read."""
        dev = self._device_id(con, device)
        row = con.execute("SELECT value FROM device_state WHERE device_id = ? AND key = 'lock'", (dev,)).fetchone()
        return dev, None if row is None else self._readable_lock(row[0], device)

    def _readable_lock(self, text: object, device: str) -> Any:
        """A stored lock row decoded; :class:`StoreError` with the way out for one that cannot be read."""
        try:
            return self._json(text, device, "lock")
        except StoreError as e:  # a hand edit, a bad sector: it names no holder, and --unlock releases it
            raise StoreError(f"{e}; if no stickslip process drives {redact_url(device)} now, release it with "
                             f"`stickslip where -d {command_url(device)} --unlock`") from None

    def release_lock(self, device: str, pid: int) -> None:
        """Release ``device``'s lock if process ``pid`` holds it."""
        try:
            with self._write() as con:
                dev, current = self._lock_row(con, device)
                if isinstance(current, dict) and current.get("pid") == pid:
                    con.execute("DELETE FROM device_state WHERE device_id = ? AND key = 'lock'", (dev,))
        finally:
            self._con.release(f"device {lock_name(device)}")
