"""A history file: stored traverses with their provenance (``stickslip export --json``, read by ``import``).

The measurement table (design.md §7) is a contract other tools read, header exactly;
it has no place for how a traverse was measured, when, from what, or why it is excluded.
A history file carries those too, so that a history moved with ``export --json`` and
``import`` is the same record (docs/storage.md). It is JSON Lines, UTF-8: line 1
``{"format": "stickslip-history", "version": 2}``, then one object per traverse with the
table's columns (numbers as JSON numbers) and ``how``, ``source``, ``measured_at`` (ISO
8601 with its UTC offset), ``excluded`` (the reason, or null when the row is used) and
``device`` (the name the row was stored under: a history of several devices says whose
each row is; version 1 had no ``device`` and is still read). A provenance field left out
means what importing a table means: ``how`` imported, the import's time, no exclusion, no
source, the device the import is told. The store keeps no checksum of a history file: importing
one twice is refused by its rows (the same device, day, pose and steps), not by its bytes.
Text in it (a source, a reason) may hold any character: JSON escapes it on one line.

The table's columns are checked by the table's own rules (:func:`.rows.parse_row`), the
provenance here; every problem is listed as ``file:line: reason``, as for a table.
"""

from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from ..joints import JointSet
from ..records import atomic_write, regular_file, text_lines
from .rows import HEADER, TableError, Traverse, parse_row

__all__ = ["FORMAT", "PROVENANCE", "Provenance", "is_history_file", "read_history", "write_history"]

FORMAT = {"format": "stickslip-history", "version": 2}
READS = (1, 2)  # version 1 (stop 63) had no "device" field
PROVENANCE = ("how", "source", "measured_at", "excluded", "device")
_BATCH = 10_000  # rows per yielded batch: memory bounded by a batch, whatever the file's length


@dataclass(frozen=True)
class Provenance:
    """How a stored traverse came to be: ``how``, ``source`` (or None), ``measured_at`` (ISO, UTC offset),
    ``excluded`` (the reason it is left out of analyses, or None when used) and ``device`` (the name it was
    stored under, or None: a history file of version 1, or a row that does not say)."""

    how: str
    measured_at: str | None = None  # None: now, when it is stored
    source: str | None = None
    excluded: str | None = None
    device: str | None = None


def is_history_file(path: str | Path) -> bool:
    """Whether ``path`` starts like a history file (its first character ``{``), not a CSV table."""
    try:
        with open(regular_file(path, "table"), "rb") as f:  # a FIFO or device is never opened
            head = f.read(64).lstrip(b"\xef\xbb\xbf \t\r\n")
    except (OSError, ValueError):
        return False  # the table reader says why it cannot be read
    return head.startswith(b"{")


def write_history(path: str | Path, rows: Iterable[tuple[Traverse, Provenance]]) -> int:
    """Write ``rows`` as a history file, streamed, the file appearing only when complete; returns the count."""
    count = [0]

    def write(f: TextIO) -> None:
        f.write(json.dumps(FORMAT) + "\n")
        for t, p in rows:
            obj: dict[str, Any] = {h: getattr(t, h) for h in HEADER}
            obj.update(how=p.how, source=p.source, measured_at=p.measured_at, excluded=p.excluded)
            if p.device is not None:
                obj["device"] = p.device
            f.write(json.dumps(obj, ensure_ascii=False, allow_nan=False) + "\n")
            count[0] += 1

    atomic_write(path, write)
    return count[0]


def read_history(path: str | Path, joints: JointSet | None = None) -> Iterator[list[tuple[Traverse, Provenance]]]:
    """The rows of a history file in batches; :class:`TableError` listing every bad line once it is read whole
    (no batch is yielded after the first problem), at once for a file that is not a history file.

    ``joints``: the arm's joints where they are not the MM3A's, as for a table (:func:`.rows.parse_row`).
    """
    source = str(path)
    try:
        lines = enumerate(text_lines(path, "history"), start=1)
        version = _check_format(next(lines, (1, "")), source)
        problems: list[str] = []
        batch: list[tuple[Traverse, Provenance]] = []
        n = 0
        for lineno, line in lines:
            if not line.strip():
                continue
            row, errs = _parse_line(line, f"{source}:{lineno}", joints, version)
            problems += errs
            n += 1
            if row is not None and not problems:
                batch.append(row)
                if len(batch) >= _BATCH:
                    yield batch
                    batch = []
    except TableError:
        raise
    except ValueError as e:  # not UTF-8, not a regular file
        raise TableError([str(e)]) from None
    if problems:
        raise TableError(problems)
    if not n:
        raise TableError([f"{source}:2: the history file has no traverses"])
    if batch:
        yield batch


def _check_format(first: tuple[int, str], source: str) -> int:
    if not first[1].strip():  # is_history_file looks past blank lines: say what is wrong, not 'not a history file'
        raise TableError([f"{source}:1: line 1 is empty: a history file's first line is {json.dumps(FORMAT)} "
                          "(delete the empty lines above it)"])
    try:
        head = json.loads(first[1])
    except ValueError:
        head = None
    if not isinstance(head, dict) or head.get("format") != FORMAT["format"]:
        raise TableError([f"{source}:1: neither a stickslip history file (line 1 must be {json.dumps(FORMAT)}) "
                          f"nor a table (its first character is '{{'; a table's line 1 is its header "
                          f"{','.join(HEADER)})"])
    version = head.get("version")
    if type(version) is not int or version not in READS:
        raise TableError([f"{source}:1: history file version {version!r}: this stickslip reads versions "
                          f"{' and '.join(map(str, READS))} (a newer stickslip wrote it?)"])
    return version


def _parse_line(
    line: str, where: str, joints: JointSet | None, version: int = 2
) -> tuple[tuple[Traverse, Provenance] | None, list[str]]:
    """One line's traverse and provenance, or its problems."""
    try:
        obj = json.loads(line, parse_constant=_no_constant, object_pairs_hook=_once_each)
    except _Twice as e:
        return None, [f"{where}: {e}"]
    except ValueError as e:
        return None, [f"{where}: not a JSON object ({e})"]
    if not isinstance(obj, dict):
        return None, [f"{where}: not a JSON object (a traverse is {{\"day\": ..., \"joint\": ..., ...}})"]
    problems = []
    known = PROVENANCE if version >= 2 else PROVENANCE[:-1]  # version 1 had no device
    if unknown := [k for k in obj if k not in HEADER and k not in known]:
        problems.append(f"{where}: unknown field{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}")
    cells = {h: _cell(obj.get(h)) for h in HEADER}
    t, errs = parse_row(cells, where, joints)
    prov, perrs = _provenance(obj, where)
    problems += errs + perrs
    if problems or t is None or prov is None:
        return None, problems
    return (t, prov), []


class _Twice(ValueError):
    """A field given twice in one line."""


def _once_each(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object whose fields are each given once: ``json`` keeps the last of two silently, so
    ``{"q1": 0.1, ..., "q1": 0.5}`` (a hand edit, a merge) would store 0.5 without a word."""
    obj: dict[str, Any] = {}
    for k, v in pairs:
        if k in obj:
            raise _Twice(f"field {k!r} given twice ({json.dumps(obj[k])} and {json.dumps(v)}): keep one")
        obj[k] = v
    return obj


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number a traverse can have")


def _cell(value: object) -> str:
    """A JSON value as the table's cell text (a number as Python writes it: exact)."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return json.dumps(value)  # 'true': refused by the row's rules, not read as 1
    return str(value)


def _provenance(obj: dict[str, Any], where: str) -> tuple[Provenance | None, list[str]]:
    """The provenance fields of one line, checked: a missing one means what it means for a CSV row."""
    problems = []
    texts: dict[str, str | None] = {}
    for k in ("how", "source", "excluded", "device"):
        v = obj.get(k)
        if v is not None and not isinstance(v, str):
            problems.append(f"{where}: {k} must be text or null, got {json.dumps(v)}")
        elif isinstance(v, str) and (why := _unstorable(v)):
            problems.append(f"{where}: {k} {why}")
        texts[k] = v if isinstance(v, str) else None
    if texts["excluded"] is not None and not texts["excluded"].strip():
        problems.append(f"{where}: excluded is empty (give the reason, or null when the row is used)")
    if texts["how"] is not None and not texts["how"].strip():
        problems.append(f"{where}: how is empty (e.g. audio, imported, camera)")
    if texts["device"] is not None and not texts["device"].strip():
        problems.append(f"{where}: device is empty (the URL it was measured on, e.g. sim://, or null)")
    when = obj.get("measured_at")
    iso = None
    if when is not None:  # missing: the time of the import, as for a table's row
        iso, why = _measured_at(when)
        if why:
            problems.append(f"{where}: measured_at {json.dumps(when, ensure_ascii=False)}: {why}")
    if problems:
        return None, problems
    return Provenance(texts["how"] or "imported", iso, texts["source"], texts["excluded"], texts["device"]), []


def _unstorable(text: str) -> str | None:
    """Why a store cannot keep ``text`` as it is, or None: a NUL (PostgreSQL refuses it; SQLite would keep it, so a
    history could not move on), or a lone surrogate escape such as ``\\ud800`` (not a character: not UTF-8)."""
    if "\x00" in text:
        return "holds a NUL character (\\u0000), which a PostgreSQL store cannot keep: remove it"
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as e:
        return (f"holds \\u{ord(text[e.start]):04x}, half of a UTF-16 pair and no character (not UTF-8): write the "
                "character itself, or its pair")
    return None


def _measured_at(value: object) -> tuple[str | None, str | None]:
    """``value`` as the store keeps a time (UTC, microseconds), or why it cannot be one."""
    if not isinstance(value, str):
        return None, "must be text (ISO 8601 with its UTC offset)"
    try:
        t = _dt.datetime.fromisoformat(value.strip())
    except ValueError:
        return None, "not an ISO 8601 date and time (e.g. 2026-11-21T09:30:00+00:00)"
    if t.tzinfo is None:
        return None, "has no UTC offset (add +00:00 for UTC): a local time is another instant on every PC"
    try:
        return t.astimezone(_dt.UTC).isoformat(timespec="microseconds"), None
    except OverflowError:  # 0001-01-01T00:00+01:00 is in year 0 in UTC, 9999-12-31T23:59-01:00 in year 10000
        return None, "is outside the years 1 to 9999 once in UTC"
