"""Traverses with their provenance: read out whole (excluded ones too) and stored again as they were.

What ``export --json`` and ``import`` of a history file use, so that a moved history is the
same record: how each traverse was measured, when, from what, and why it is excluded.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator

from ..measurements.history_file import Provenance
from ..measurements.rows import Traverse
from .schema import DEFAULT_DEVICE, _content_keys, _now, stored_device
from .traverses import TraverseStore, _note

__all__ = ["ProvenanceStore"]


class ProvenanceStore(TraverseStore):
    """Traverses and their provenance, for moving a history between stores."""

    @staticmethod
    def device_name(url: str) -> str:
        """The name ``url``'s rows are stored under (:func:`~.schema.stored_device`); ``ValueError`` (without a
        secret) for a URL that names no device."""
        return stored_device(url)

    def iter_provenance(
        self, device: str | None = None, day: str | None = None, joint: int | None = None, chunk: int = 10_000
    ) -> Iterator[tuple[Traverse, Provenance]]:
        """Every stored traverse asked for, excluded ones too, in the order recorded, with its provenance (its
        device's stored name included)."""
        sql, args = self._traverse_query(device, day, joint, include_excluded=True)
        for r in self._con.stream(sql, args, chunk):
            yield self._to_traverse(r), Provenance(
                str(r["how"]), str(r["measured_at"]), r["source"], r["excluded"], str(r["device"])
            )

    def add_with_provenance(
        self, rows: Iterable[tuple[Traverse, Provenance]], device: str | None = None
    ) -> list[int]:
        """Store traverses each with its own provenance, in ONE transaction (all or nothing); returns their ids.

        Each row goes to the device its provenance names (``Provenance.device``, stored by its
        name: :func:`~.schema.stored_device`), or to ``device`` (default ``sim://``) when it
        names none; a row naming another device than a ``device`` given is ``ValueError``
        (nothing stored: not silently put under either). A provenance
        whose ``measured_at`` is None gets the time of this call (an import's time); ``how``,
        ``source`` and the exclusion's reason go through the one redaction, as every text kept
        with a row does.
        """
        now = _now()
        it = iter(rows)
        with self._write() as con:
            devices: dict[str | None, tuple[int, str]] = {}  # a row's device as given: its id and stored name
            sessions: dict[tuple[int, str], int] = {}
            ids: list[int] = []
            while batch := list(itertools.islice(it, 10_000)):
                checked = [self._check(t) for t, _ in batch]
                for given in {p.device for _, p in batch} - devices.keys():
                    if given is not None and device is not None and stored_device(given) != stored_device(device):
                        raise ValueError(f"a row names the device {stored_device(given)}, not {stored_device(device)} "
                                         "(give device=None to store each row under the device it names)")
                    dev = self._device_id(con, (device or DEFAULT_DEVICE) if given is None else given)
                    url = con.execute("SELECT url FROM devices WHERE id = ?", (dev,)).fetchone()["url"]
                    devices[given] = (dev, str(url))
                values = []
                for t, (_, p), key in zip(checked, batch, self._keys(checked, batch, devices), strict=True):
                    dev = devices[p.device][0]
                    sid = sessions.get((dev, str(t.day)))
                    if sid is None:
                        sid = sessions[dev, str(t.day)] = self._session_id(con, dev, str(t.day))
                    how, source = _note(p.how) or "imported", _note(p.source)
                    row = self._row_values(t, sid, how, p.measured_at or now, source, key)
                    values.append((*row, _note(p.excluded)))
                ids += con.insert_many("traverses", (*self._FIELDS, "excluded"), values)
            return ids

    @staticmethod
    def _keys(
        checked: list[Traverse], batch: list[tuple[Traverse, Provenance]], devices: dict[str | None, tuple[int, str]]
    ) -> list[str]:
        """The content keys of a batch whose rows may be of several devices (each keyed under its own)."""
        keys = [""] * len(checked)
        for given, (_, url) in devices.items():
            at = [k for k, (_, p) in enumerate(batch) if p.device == given]
            for k, key in zip(at, _content_keys([checked[k] for k in at], url), strict=True):
                keys[k] = key
        return keys
