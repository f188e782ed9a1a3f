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
exclusion): the moved history is the same record. It is told from a table by its first
character, ``{``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from ..measurements import Traverse, stream_measurement_table
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

    def add_with_provenance(self, rows: Iterable[tuple[Traverse, Provenance]], device: str = ...) -> list[int]: ...


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


def _rows(path: str | Path, history: bool = False) -> Iterator[Sequence[Traverse]]:
    if history:
        for batch in read_history(path):
            yield [t for t, _ in batch]
        return
    for part in stream_measurement_table(path):
        yield part.traverses()


def import_table(
    store: ImportStore,
    path: str | Path,
    device: str,
    how: str | None = None,
    force: bool = False,
    allow_duplicates: bool = False,
    shown_device: str | None = None,
) -> ImportResult:
    """Store the measurement table at ``path`` for ``device``; on any bad row nothing is stored.

    Raises :class:`~stickslip.measurements.TableError` listing every bad row, and
    :class:`ImportRefused` when the file was imported before (unless ``force``) or rows are
    stored already (unless ``allow_duplicates``; ``shown_device`` names the device in the
    message, without secrets). ``how`` (default ``"imported"``) is for a table: a history
    file's rows keep their own, and a ``how`` given with one is refused.
    """
    regular_file(path, "table")  # a FIFO or a device is refused before anything opens it (file_digest hung on one)
    history = is_history_file(path)
    if history and how is not None:
        raise ImportRefused(f"{path} is a history file: its rows keep their own 'how'; leave --how out")
    digest = file_digest(path)
    if store.has_source(digest) and not force:
        raise ImportRefused(f"{path} was imported before (same contents); use --force to import it again")
    days: set[str] = set()
    dup: list[int] = []
    n = 0
    for rows in _rows(path, history):  # the first pass: every row checked, compared with the stored ones
        days.update(t.day for t in rows)
        if not allow_duplicates:
            dup += [n + k for k in store.duplicates(rows, device)]
        n += len(rows)
    if dup:
        listed = ", ".join(str(k + 2) for k in dup[:5]) + (" ..." if len(dup) > 5 else "")
        raise ImportRefused(
            f"{path}: {len(dup)} of {n} rows are already stored for {shown_device or device} "
            f"(same day, pose, interval and steps; rows {listed}); nothing imported. "
            "Use --allow-duplicates if they are genuine repeats"
        )
    if history:
        ids = store.add_with_provenance((r for batch in read_history(path) for r in batch), device=device)
    else:
        ids = store.add_traverses(
            (t for rows in _rows(path) for t in rows), device=device, how=how or "imported", source=digest
        )
    return ImportResult(ids, sorted(days))
