"""Traverses with their provenance: read out whole (excluded ones too) and stored again as they were.

What ``export --json`` and ``import`` of a history file use, so that a moved history is the
same record: how each traverse was measured, when, from what, and why it is excluded.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator

from ..measurements.history_file import Provenance
from ..measurements.rows import Traverse
from .schema import DEFAULT_DEVICE, _content_keys, _now
from .traverses import TraverseStore, _note

__all__ = ["ProvenanceStore"]


class ProvenanceStore(TraverseStore):
    """Traverses and their provenance, for moving a history between stores."""

    def iter_provenance(
        self, device: str | None = None, day: str | None = None, joint: int | None = None, chunk: int = 10_000
    ) -> Iterator[tuple[Traverse, Provenance]]:
        """Every stored traverse asked for, excluded ones too, in the order recorded, with its provenance."""
        sql, args = self._traverse_query(device, day, joint, include_excluded=True)
        for r in self._con.stream(sql, args, chunk):
            yield self._to_traverse(r), Provenance(str(r["how"]), str(r["measured_at"]), r["source"], r["excluded"])

    def add_with_provenance(
        self, rows: Iterable[tuple[Traverse, Provenance]], device: str = DEFAULT_DEVICE
    ) -> list[int]:
        """Store traverses each with its own provenance, in ONE transaction (all or nothing); returns their ids.

        A provenance whose ``measured_at`` is None gets the time of this call (an import's
        time); ``how``, ``source`` and the exclusion's reason go through the one redaction,
        as every text kept with a row does.
        """
        now = _now()
        it = iter(rows)
        with self._write() as con:
            dev = self._device_id(con, device)
            url = con.execute("SELECT url FROM devices WHERE id = ?", (dev,)).fetchone()["url"]
            sessions: dict[str, int] = {}
            ids: list[int] = []
            while batch := list(itertools.islice(it, 10_000)):
                checked = [self._check(t) for t, _ in batch]
                values = []
                for t, (_, p), key in zip(checked, batch, _content_keys(checked, url), strict=True):
                    sid = sessions.get(str(t.day))
                    if sid is None:
                        sid = sessions[str(t.day)] = self._session_id(con, dev, str(t.day))
                    how, source = _note(p.how) or "imported", _note(p.source)
                    row = self._row_values(t, sid, how, p.measured_at or now, source, key)
                    values.append((*row, _note(p.excluded)))
                ids += con.insert_many("traverses", (*self._FIELDS, "excluded"), values)
            return ids
