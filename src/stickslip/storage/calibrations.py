"""Calibrations in the database, and the history view."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from ..devices.base import redact_text, redact_url
from ..measurements import Traverse
from ..records import dumps_json, loads_json
from .base import _Base
from .schema import DEFAULT_DEVICE, StoreError, _now, device_filter

if TYPE_CHECKING:  # pragma: no cover
    from ..calibration import Calibration


class CalibrationStore(_Base):
    """Calibrations (with the traverses they used) and the history of a device."""

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
        # a URL or note in it: no secret stored; in the calibration's own order, so that `show N -o` writes
        # the bytes `calibrate -o` wrote (sorted, an update's prior and a family selection came back reordered)
        doc = redact_text(dumps_json(cal.to_dict(), f"calibration of {redact_url(device)}"))
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
            cid = con.insert(
                "INSERT INTO calibrations (device_id, day, method, created_at, json) VALUES (?, ?, ?, ?, ?)",
                (dev, day, method, _now(), doc),
            )
            con.executemany(
                "INSERT INTO calibration_traverses (calibration_id, traverse_id) VALUES (?, ?) ON CONFLICT DO NOTHING",
                [(cid, i) for i in sorted(set(ids))],
            )
            return cid

    def _load_cal(self, doc: object, cid: object = "?") -> Calibration:
        from ..calibration import Calibration

        where = f"{self.path}: stored calibration #{cid}"
        try:
            if not isinstance(doc, str):
                raise ValueError(f"{where} holds {type(doc).__name__}, not JSON text")
            return Calibration.from_dict(loads_json(doc, where))
        except ValueError as e:
            raise StoreError(str(e) if str(e).startswith(where) else f"{where}: {e}") from None

    def calibration(self, calibration_id: int) -> Calibration:
        """The stored calibration with this id (``KeyError`` if none)."""
        row = self._con.execute(
            "SELECT json FROM calibrations WHERE id = ?", (int(calibration_id),)
        ).fetchone()
        if row is None:
            raise KeyError(f"no calibration with id {calibration_id}")
        return self._load_cal(row[0], calibration_id)

    def latest_calibration(self, device: str | None = None) -> Calibration | None:
        """The most recently stored calibration (of ``device``, or of any), or ``None``."""
        sql = "SELECT c.json, c.id FROM calibrations c JOIN devices d ON d.id = c.device_id"
        args: tuple[Any, ...] = ()
        if device is not None:
            sql += " WHERE d.url = ?"
            args = (device_filter(device),)
        row = self._con.execute(sql + " ORDER BY c.id DESC LIMIT 1", args).fetchone()
        return None if row is None else self._load_cal(row[0], row[1])

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
            args = (device_filter(device),)
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
            "COUNT(t.id) AS n, COUNT(t.excluded) AS x, "
            "MIN(t.measured_at) AS first, MAX(t.measured_at) AS last "
            "FROM sessions s JOIN devices d ON d.id = s.device_id "
            "LEFT JOIN traverses t ON t.session_id = s.id"
        )
        args: tuple[Any, ...] = ()
        if device is not None:
            sql += " WHERE d.url = ?"
            args = (device_filter(device),)
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

