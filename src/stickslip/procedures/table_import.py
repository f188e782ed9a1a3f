"""Storing a measurement table in the database, a chunk at a time (``stickslip import``).

A table of any length is read twice as it streams
(:func:`stickslip.measurements.stream_measurement_table`), never held whole: first every
row is checked and compared with what the database holds (a row identical to a stored
traverse of the same device is refused unless duplicates are allowed), then the rows are
stored in one transaction, so that on any bad row nothing is stored. The file is
recognised by the SHA-256 of its bytes (read a block at a time), so importing the same file
twice is refused unless forced.

A history file (``stickslip export --json``: :mod:`stickslip.measurements.history_file`)
is imported the same way, each row with its own provenance (how, source, measured_at, its
exclusion) and its own device (a history of several devices goes back to each): the moved
history is the same record. It is told from a table by its first character, ``{``.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from ..devices.base import redact_url
from ..measurements import TableError, Traverse, stream_measurement_table
from ..measurements.history_file import Provenance, is_history_file, read_history
from ..records import regular_file

__all__ = ["ImportStore", "ImportRefused", "ImportResult", "file_digest", "import_table"]


class ImportStore(Protocol):
    """What :func:`import_table` needs of a store (``stickslip.storage.Store`` is one)."""

    def has_source(self, source: str) -> bool: ...

    def duplicates(self, traverses: Iterable[Traverse], device: str = ...) -> list[int]: ...

    def add_traverses(
        self, traverses: Iterable[Traverse], *, device: str = ..., how: str = ..., source: str | None = ...
    ) -> list[int]: ...

    def add_with_provenance(
        self, rows: Iterable[tuple[Traverse, Provenance]], device: str | None = ...
    ) -> list[int]: ...

    def device_name(self, url: str) -> str: ...


class ImportRefused(ValueError):
    """The import would store something twice; the message says what and how to go on."""


@dataclass(frozen=True)
class ImportResult:
    """What an import stored: the new traverse ids and the session days among them."""

    ids: list[int]
    days: list[str] = field(default_factory=list)


def file_digest(path: str | Path, block: int = 1 << 20) -> str:
    """``"sha256:<hex>"`` of a file's bytes, read ``block`` bytes at a time."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(block):
            h.update(chunk)
    return "sha256:" + h.hexdigest()


def _rows(path: str | Path, history: bool, device: str | None) -> Iterator[tuple[str | None, Sequence[Traverse]]]:
    """The file's traverses in batches of one device each: ``(the device a history row names, or device, rows)``."""
    if history:
        for batch in read_history(path):
            start = 0
            for k in range(1, len(batch) + 1):
                if k == len(batch) or batch[k][1].device != batch[start][1].device:
                    yield batch[start][1].device or device, [t for t, _ in batch[start:k]]
                    start = k
        return
    for part in stream_measurement_table(path):
        yield device, part.traverses()


def _named(store: ImportStore, given: str | None, device: str | None) -> tuple[str | None, str | None]:
    """The stored name of the device rows are imported for, or why they cannot be: none named (``given`` None: a
    table or a version-1 history file, and no ``device``), a name that is no device, or another than ``device``
    (told with --device)."""
    if given is None:
        return None, ("no device named (a history file of version 1, or a row that leaves it out): give it with "
                      "--device URL")
    try:
        name = store.device_name(given)
    except ValueError as e:  # said with the name as written (redacted): '#arm=x' was 'device device URL '' ...'
        return None, f"the device it names, {json.dumps(redact_url(given))}, is none: {e}"
    if device is not None and name != (told := store.device_name(device)):
        return None, (f"the file names the device {name}, not {told} (--device): leave --device out to store each "
                      "row under the device it names")
    return name, None


def _rows_said(first: int, count: int) -> str:
    return f"row {first}" if count == 1 else f"rows {first}-{first + count - 1}"


def import_table(
    store: ImportStore,
    path: str | Path,
    device: str | None,
    how: str | None = None,
    force: bool = False,
    allow_duplicates: bool = False,
    shown_device: str | None = None,
) -> ImportResult:
    """Store the measurement table at ``path`` for ``device``; on any bad row nothing is stored.

    A history file's rows that name their device are stored under it: ``device`` (None: not
    told) must then be the same device. Raises :class:`~stickslip.measurements.TableError` listing every bad row, and
    :class:`ImportRefused` when the file was imported before (unless ``force``) or rows are
    stored already (unless ``allow_duplicates``; ``shown_device`` names the device in the
    message, without secrets). ``how`` (default ``"imported"``) is for a table: a history
    file's rows keep their own, and a ``how`` given with one is refused.
    """
    regular_file(path, "table")  # a FIFO or a device is refused before anything opens it (file_digest hung on one)
    history = is_history_file(path)
    if history and how is not None:
        raise ImportRefused(f"{path} is a history file: its rows keep their own 'how'; leave --how out")
    if not history and device is None:
        raise ImportRefused(f"{path} is a measurement table, which does not say its device: give the device it was "
                            "measured on (--device URL, e.g. mm3a:///dev/ttyUSB0 or sim://)")
    digest = file_digest(path)
    if store.has_source(digest) and not force:
        raise ImportRefused(f"{path} was imported before (same contents); use --force to import it again")
    days: set[str] = set()
    dup: dict[str, list[int]] = {}
    n = 0
    problems: list[str] = []
    for given, rows in _rows(path, history, device):  # the first pass: every row checked, compared with the stored
        name, why = _named(store, given, device)
        if name is None:
            problems.append(f"{path}: {_rows_said(n + 2, len(rows))}: {why}")
        elif not allow_duplicates and not problems:
            dup.setdefault(name, []).extend(n + k for k in store.duplicates(rows, name))
        days.update(t.day for t in rows)
        n += len(rows)
    if problems:
        raise TableError(problems[:20] + ([f"... and {len(problems) - 20} more"] if len(problems) > 20 else []))
    if found := {name: rows for name, rows in dup.items() if rows}:
        said = (shown_device or device) if device is not None else ", ".join(found)
        every = sorted(k for rows in found.values() for k in rows)
        listed = ", ".join(str(k + 2) for k in every[:5]) + (" ..." if len(every) > 5 else "")
        raise ImportRefused(
            f"{path}: {len(every)} of {n} rows are already stored for {said} "
            f"(same day, pose, interval and steps; rows {listed}); nothing imported. "
            "Use --allow-duplicates if they are genuine repeats"
        )
    if history:  # every row was named above: one told by the file goes to its device, another to device
        ids = store.add_with_provenance((r for batch in read_history(path) for r in batch), device=device)
    else:
        assert device is not None  # a table without one was refused above
        ids = store.add_traverses(
            (t for _, rows in _rows(path, False, device) for t in rows), device=device, how=how or "imported",
            source=digest,
        )
    return ImportResult(ids, sorted(days))
