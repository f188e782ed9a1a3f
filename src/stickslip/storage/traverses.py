"""Traverses in the database."""

from __future__ import annotations

import datetime as _dt
import itertools
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from ..devices.base import redact_text
from ..measurements import Traverse, traverse_problems
from .backend import Backend
from .base import _Base, _require_traverses
from .schema import _COLUMNS, DEFAULT_DEVICE, _content_keys, _iso, content_key, device_filter

if TYPE_CHECKING:  # pragma: no cover
    pass


class TraverseStore(_Base):
    """Traverses: add (with duplicate detection), read, count, exclude and delete."""

    # -- traverses

    @staticmethod
    def _check(t: Traverse) -> Traverse:
        """``t`` with its session label stripped, if it could be a table's row; else ``ValueError`` saying why.

        What is stored is exported as a table that ``import`` reads again (the arm's joint
        ranges aside: the store does not know the arm).
        """
        if not isinstance(t, Traverse):
            raise TypeError(f"expected a Traverse, got {type(t).__name__}")
        if not str(t.day).strip():
            raise ValueError("traverse has an empty day (session label)")
        problems = traverse_problems(t)
        if problems:
            raise ValueError(f"traverse {t.day!r} joint {t.joint} {t.direction}: {'; '.join(problems)}; nothing stored")
        day = str(t.day).strip()
        return t if day == t.day else replace(t, day=day)

    def _insert_traverse(
        self,
        con: Backend,
        t: Traverse,
        device_id: int,
        how: str,
        measured_at: str,
        source: str | None,
    ) -> int:
        sid = self._session_id(con, device_id, str(t.day))
        url = con.execute("SELECT url FROM devices WHERE id = ?", (device_id,)).fetchone()["url"]
        return self._insert_row(con, t, sid, how, measured_at, source, content_key(t, url))

    _FIELDS = (
        "session_id", "joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps",
        "measured_at", "how", "source", "content",
    )
    _INSERT = (
        "INSERT INTO traverses (" + ", ".join(f'"{c}"' for c in _FIELDS) + ") "
        "VALUES (" + ", ".join("?" * len(_FIELDS)) + ")"
    )

    @staticmethod
    def _insert_row(
        con: Backend, t: Traverse, sid: int, how: str, measured_at: str, source: str | None, key: str
    ) -> int:
        return con.insert(TraverseStore._INSERT, TraverseStore._row_values(t, sid, how, measured_at, source, key))

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
        given = traverses if isinstance(traverses, Sequence) else list(traverses)
        keys = _content_keys(given, device)
        # a row with a -0.0 stored before zeros were unsigned in the key has its signed key
        signed = _content_keys(given, device, signed_zeros=True)
        asked = sorted({*keys, *signed})
        stored: set[str] = set()
        step = 500  # keys per query (SQLite allows 999 parameters in old builds)
        for i in range(0, len(asked), step):
            part = asked[i : i + step]
            rows = self._con.execute(
                f"SELECT DISTINCT content FROM traverses WHERE content IN ({','.join('?' * len(part))})", part
            )
            stored.update(r[0] for r in rows)
        return [k for k, (key, old) in enumerate(zip(keys, signed, strict=True)) if key in stored or old in stored]

    def device_holding(self, traverses: Iterable[Traverse]) -> tuple[str, list[int]] | None:
        """The one device whose stored traverses include every one of ``traverses`` (by content), and their ids.

        How a calibration made from a table learns which arm its traverses came from: the
        rows were stored when they were measured (``stickslip traverse``, ``demo``, ``import
        --device``). ``None`` when no device, or more than one, holds them all.
        """
        rows = list(traverses)
        if not rows:
            return None
        urls = [str(r[0]) for r in self._con.execute("SELECT url FROM devices ORDER BY id")]
        holders = [url for url in urls if len(self.duplicates(rows, url)) == len(rows)]
        if len(holders) != 1:
            return None
        keys = sorted({*_content_keys(rows, holders[0]), *_content_keys(rows, holders[0], signed_zeros=True)})
        ids: list[int] = []
        for i in range(0, len(keys), 500):
            part = keys[i : i + 500]
            ids += [int(r[0]) for r in self._con.execute(
                f"SELECT MIN(id) FROM traverses WHERE content IN ({','.join('?' * len(part))}) GROUP BY content", part
            )]
        return holders[0], sorted(ids)

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
        traverse = self._check(traverse)
        how, source = redact_text(str(how)), _note(source)
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
        completed traverse is safe on its own. ``traverses`` is consumed in batches (an
        iterator of a million rows is never held as a list); an exception while it is read
        rolls the whole transaction back.
        """
        when = _iso(measured_at)
        it = iter(traverses)
        how, source = redact_text(str(how)), _note(source)
        with self._write() as con:
            dev = self._device_id(con, device)
            url = con.execute("SELECT url FROM devices WHERE id = ?", (dev,)).fetchone()["url"]
            sessions: dict[str, int] = {}  # one look-up per day, not per row
            ids: list[int] = []
            while batch := list(itertools.islice(it, 10_000)):
                batch = [self._check(t) for t in batch]
                values = []
                for t, key in zip(batch, _content_keys(batch, url), strict=True):
                    day = str(t.day)
                    sid = sessions.get(day)
                    if sid is None:
                        sid = sessions[day] = self._session_id(con, dev, day)
                    values.append(self._row_values(t, sid, how, when, source, key))
                ids += con.insert_many("traverses", self._FIELDS, values)  # executemany (SQLite), COPY (PostgreSQL)
            return ids

    def iter_traverses(
        self, device: str | None = None, day: str | None = None, joint: int | None = None, chunk: int = 10_000
    ) -> Iterator[Traverse]:
        """Like :meth:`traverses`, read ``chunk`` rows at a time (exports of any size in bounded memory)."""
        sql, args = self._traverse_query(device, day, joint)
        yield from map(self._to_traverse, self._con.stream(sql, args, chunk))

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
                (device_filter(device),),
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
            args = (device_filter(device),)
        days = {r[0] for r in self._con.execute(sql, args)}
        csql = (
            "SELECT DISTINCT c.day FROM calibrations c JOIN devices d ON d.id = c.device_id "
            "WHERE c.day IS NOT NULL"
        )
        if device is not None:
            csql += " AND d.url = ?"
        days |= {r[0] for r in self._con.execute(csql, args)}
        return sorted(days)

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
        reason = _note(reason)
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


def _note(text: str | None) -> str | None:
    """Free text kept with a row (how, source, a reason), through the one redaction: no secret is stored."""
    return None if text is None else redact_text(str(text))
