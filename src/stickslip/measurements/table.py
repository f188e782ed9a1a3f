"""The measurement table as a whole: :class:`TraverseTable` (columns), reading, parsing and writing."""

from __future__ import annotations

import csv
import io
import operator
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from ..clock import day_label_problem
from ..joints import JointSet
from ..records import MAX_TABLE_BYTES, atomic_write, guard_cell, read_text_bounded, text_lines, unguard_cell
from .chunks import _Chunk, _equal, _floats, _ints, _joint_cells, _moving_within, _open_table, _pose_ok, stream_table
from .rows import HEADER, MAX_STEPS, TableError, Traverse, _csv_problem, _value_problems, check_header, parse_row


@dataclass(frozen=True, eq=False)
class TraverseTable:
    """A measurement table as columns (one numpy array per column of design.md §7).

    The columnar form of a list of :class:`Traverse`: what :func:`parse_measurement_table`
    returns, so that a table of a million rows is parsed, checked and modelled without a
    Python object per row. :meth:`traverses` gives the row objects when wanted.

    Attributes
    ----------
    day : ndarray of str (object)
        Session labels.
    joint : ndarray of int
        Moving joint, 1, 2 or 3.
    direction : ndarray of str
        ``"+"`` or ``"-"``.
    q1, q2, q3, theta, psi : ndarray of float
        Fixed joints (rad, rad, m) and base tilt (rad).
    start, end : ndarray of float
        Traversed interval (rad or m).
    steps : ndarray of int
        Steps counted, > 0.
    lines : ndarray of int
        Line of each row in its file (record number; the header is line 1).
    """

    day: NDArray[np.object_]
    joint: NDArray[np.int64]
    direction: NDArray[np.str_]
    q1: NDArray[np.float64]
    q2: NDArray[np.float64]
    q3: NDArray[np.float64]
    theta: NDArray[np.float64]
    psi: NDArray[np.float64]
    start: NDArray[np.float64]
    end: NDArray[np.float64]
    steps: NDArray[np.int64]
    lines: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.joint.size)

    @property
    def gamma(self) -> NDArray[np.float64]:
        """Average step sizes ``|end - start| / steps`` (m or rad)."""
        return np.abs(self.end - self.start) / self.steps

    def traverses(self) -> list[Traverse]:
        """The rows as :class:`Traverse` objects (Python floats and ints, as :func:`parse_row` makes them)."""
        cols = [getattr(self, f.name).tolist() for f in fields(Traverse)]
        return list(map(Traverse, *cols))

    @classmethod
    def from_traverses(cls, traverses: Sequence[Traverse], lines: Sequence[int] | None = None) -> TraverseTable:
        """The columns of a sequence of traverses (``lines`` default 2, 3, ...)."""
        n = len(traverses)
        cols: dict[str, Any] = {f.name: [getattr(t, f.name) for t in traverses] for f in fields(Traverse)}
        def f(k: str) -> NDArray[np.float64]:
            return np.array(cols[k], dtype=float).reshape(n)

        return cls(
            np.array(cols["day"], dtype=object).reshape(n),
            np.array(cols["joint"], dtype=np.int64).reshape(n),
            np.array(cols["direction"], dtype="<U1").reshape(n),
            f("q1"),
            f("q2"),
            f("q3"),
            f("theta"),
            f("psi"),
            f("start"),
            f("end"),
            np.array(cols["steps"], dtype=np.int64).reshape(n),
            np.arange(2, n + 2, dtype=np.int64) if lines is None else np.array(lines, dtype=np.int64).reshape(n),
        )

    @classmethod
    def concat(cls, parts: Sequence[TraverseTable]) -> TraverseTable:
        """One table of several, in order."""
        names = [f.name for f in fields(cls)]
        if not parts:
            return cls.from_traverses([])
        return cls(*(np.concatenate([getattr(p, k) for p in parts]) for k in names))

    def take(self, index: NDArray[np.intp] | NDArray[np.bool_]) -> TraverseTable:
        """The rows selected by an index array or a boolean mask."""
        return TraverseTable(*(getattr(self, f.name)[index] for f in fields(TraverseTable)))


def parse_measurements(text: str, source: str = "<string>", joints: JointSet | None = None) -> list[Traverse]:
    """Parse measurement-table CSV text. Raises :class:`TableError` listing every bad row.

    ``joints``: an arm's own joints (numbers, kinds, ranges; e.g. a rig file's stage,
    :meth:`stickslip.rig.Arm.joint_specs`) to check the rows against instead of the MM3A's.
    """
    try:
        return _parse_measurements(text, source, joints)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None

def _parse_measurements(text: str, source: str, joints: JointSet | None = None) -> list[Traverse]:
    return _parse_measurement_columns(text, source, joints).traverses()


def parse_measurement_table(text: str, source: str = "<string>") -> TraverseTable:
    """Parse measurement-table CSV text into columns. Raises :class:`TableError` listing every bad row.

    The same rules, row numbers and messages as :func:`parse_measurements`; the rows are
    checked a chunk at a time with numpy, and only rows that fail a check are parsed one
    by one (by :func:`parse_row`) to say why.
    """
    try:
        return _parse_measurement_columns(text, source)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None


def _parse_measurement_columns(text: str, source: str, joints: JointSet | None = None) -> TraverseTable:
    header, chunks = _open_table(text)
    parts = list(_measurement_parts(header, chunks, source, joints))
    table = TraverseTable.concat(parts)
    if not len(table):
        raise TableError([f"{source}:2: the table has a header but no rows"])
    return table


def _check_header(header: list[str] | None, source: str) -> None:
    check_header(header, source, HEADER)


def _measurement_parts(
    header: list[str] | None, chunks: Callable[[int, int], Iterator[_Chunk]], source: str,
    joints: JointSet | None = None,
) -> Iterator[TraverseTable]:
    """The table's rows a chunk at a time, checked; after the last, :class:`TableError` with every bad row
    if there was one (no chunk is yielded after the first problem)."""
    _check_header(header, source)
    problems: list[tuple[int, str]] = []  # (line, reason): sorted by line at the end, stable within a line
    lineno = 1
    for chunk in chunks(len(HEADER), 0):
        if chunk.cols is not None:  # the common case: no blank or short rows
            lines = list(range(lineno + 1, lineno + 1 + chunk.n))
            lineno += chunk.n
            cols = chunk.cols
        else:
            rows: list[list[str]] = []
            lines = []
            for cells in chunk.records or []:
                lineno += 1
                if not cells or all(not c.strip() for c in cells):
                    continue  # blank line: not data
                if len(cells) != len(HEADER):
                    problems.append(
                        (lineno, f"{source}:{lineno}: expected {len(HEADER)} columns, found {len(cells)}")
                    )
                    continue
                rows.append(cells)
                lines.append(lineno)
            cols = list(zip(*rows, strict=True))
        if lines:
            part, errs = _measurement_chunk(cols, lines, source, joints)
            problems += errs
            if not problems:
                yield part
    if problems:
        raise TableError([p for _, p in sorted(problems, key=lambda lp: lp[0])])


def stream_measurement_table(path: str | Path) -> Iterator[TraverseTable]:
    """A measurement table read a chunk at a time, as columns (any length, memory bounded by a chunk).

    The same rules, line numbers and messages as :func:`read_measurement_table`: a bad file or
    header raises :class:`TableError` at once, bad rows when the table has been read to its
    end (every one listed; no chunk is yielded after the first), and a table with a header
    but no rows then too.
    """
    source = str(path)
    try:
        header, chunks = stream_table(text_lines(path, "CSV"))
    except (ValueError, csv.Error) as e:
        raise TableError([_csv_problem(source, e) if isinstance(e, csv.Error) else str(e)]) from None
    _check_header(header, source)
    return _streamed(_measurement_parts(header, chunks, source), source)


def _streamed(parts: Iterator[TraverseTable], source: str) -> Iterator[TraverseTable]:
    rows = 0
    while True:
        try:
            part = next(parts, None)
        except (ValueError, csv.Error) as e:
            if isinstance(e, TableError):
                raise
            raise TableError([_csv_problem(source, e) if isinstance(e, csv.Error) else str(e)]) from None
        if part is None:
            break
        rows += len(part)
        yield part
    if not rows:
        raise TableError([f"{source}:2: the table has a header but no rows"])


def _measurement_chunk(
    cols: Sequence[Sequence[str]], lines: list[int], source: str, joints: JointSet | None = None
) -> tuple[TraverseTable, list[tuple[int, str]]]:
    """Check 11-cell rows (as columns) with numpy; rows failing a check are re-parsed by :func:`parse_row`.

    With an arm's own ``joints`` (the vector checks know the MM3A's ranges only) every row is
    checked by :func:`parse_row` against them.
    """
    # a guarded label (records.guard_cell) loses its guard before it is stripped: "'\t" is a tab, a blank label
    quoted = {d: unguard_cell(d).strip() for d in set(cols[0]) if d.startswith("'")}
    days = [quoted[c] if c in quoted else c.strip() for c in cols[0]] if quoted else [c.strip() for c in cols[0]]
    ok = ~_equal(days, "")
    bad_labels = {d for d in set(days) if d and day_label_problem(d) is not None}  # a table holds few labels
    if bad_labels:
        ok &= ~np.isin(np.array(days, dtype=object), list(bad_labels))
    joint = _joint_cells(cols[1])
    ok &= joint > 0
    plus = _equal(cols[2], "+")
    ok &= plus | _equal(cols[2], "-")
    nums: dict[str, NDArray[np.float64]] = {}
    for i, name in enumerate(("q1", "q2", "q3", "theta", "psi", "start", "end"), start=3):
        v, good = _floats(cols[i])
        nums[name] = v
        ok &= good
    steps, good = _ints(cols[10], 1, MAX_STEPS)
    ok &= good
    start, end = nums["start"], nums["end"]
    with np.errstate(invalid="ignore"):
        ok &= (end != start) & ((end > start) == plus)
        ok &= _moving_within(joint, start) & _moving_within(joint, end)
        ok &= _pose_ok(joint, nums)
    if joints is not None:
        ok[:] = False
    problems: list[tuple[int, str]] = []
    bad = np.flatnonzero(~ok)
    for i in bad.tolist():
        t, errs = parse_row({h: c[i] for h, c in zip(HEADER, cols, strict=True)}, f"{source}:{lines[i]}", joints)
        if errs or t is None:
            problems += [(lines[i], e) for e in errs]
            continue
        # a row the vector check was too strict for (" 3", "+1", "1e3" steps): take parse_row's values
        ok[i] = True
        days[i] = t.day
        joint[i] = t.joint
        plus[i] = t.direction == "+"
        for name in ("q1", "q2", "q3", "theta", "psi", "start", "end"):
            nums[name][i] = getattr(t, name)
        steps[i] = t.steps
    table = TraverseTable(
        np.array(days, dtype=object),
        joint,
        np.where(plus, "+", "-"),
        nums["q1"],
        nums["q2"],
        nums["q3"],
        nums["theta"],
        nums["psi"],
        start,
        end,
        steps,
        np.array(lines, dtype=np.int64),
    )
    return (table.take(ok) if bad.size else table), problems


def _read_table_text(path: str | Path, max_bytes: int | None = None) -> str:
    """The text of a CSV table (a regular file, at most ``max_bytes``, default :data:`records.MAX_TABLE_BYTES`).

    A missing file, a folder, a pipe or device (never opened, so it cannot hang), a file
    over the size limit or non-UTF-8 text raises :class:`TableError`. The limit is there
    because a table read whole is held in memory (text, columns and a row object each, about
    ten times the file); :func:`stream_measurement_table` and ``predict`` stream instead.
    """
    p = Path(path)
    try:
        os.stat(p)
    except FileNotFoundError:
        raise TableError([f"{p}: no such file"]) from None
    except OSError:  # a name too long (Path.exists raised it on 3.11): read_text_bounded says why in one line
        pass
    limit = MAX_TABLE_BYTES if max_bytes is None else int(max_bytes)
    try:
        return read_text_bounded(p, "CSV", limit)
    except ValueError as e:
        text = str(e)
        if "limit" in text:
            text += " (a table read whole is held in memory, about ten times the file)"
        raise TableError([text]) from None


def read_measurements(path: str | Path, max_bytes: int | None = None, joints: JointSet | None = None) -> list[Traverse]:
    """Read a measurement table from a CSV file. Raises :class:`TableError` on any bad row.

    ``max_bytes`` (default :data:`records.MAX_TABLE_BYTES`, 64 MiB) bounds the file: it is
    read whole and held in memory. ``joints``: an arm's own joints to check the rows
    against (:func:`parse_measurements`).
    """
    return parse_measurements(_read_table_text(path, max_bytes), str(path), joints)


def read_measurement_table(path: str | Path) -> TraverseTable:
    """Read a measurement table from a CSV file into columns (see :func:`parse_measurement_table`)."""
    return parse_measurement_table(_read_table_text(path), str(path))


def _csv_rows(traverses: Iterable[Traverse], checked: bool = False) -> Iterator[tuple[Any, ...]]:
    """The rows a table is written with: the session label guarded against spreadsheet formulas.

    A label such as ``=HYPERLINK(...)`` is written ``'=HYPERLINK(...)`` (records.guard_cell);
    every other cell is a number or a direction, left as it is. Labels are few: each is
    guarded once. ``checked``: a traverse that could not be read back
    (:func:`~.rows.traverse_problems`: steps 0, a tilt in degrees, a direction ``"x"``) raises
    :class:`TableError`.
    """
    rest = operator.attrgetter(*HEADER[1:])
    guarded: dict[str, str] = {}
    for i, t in enumerate(traverses):
        day = guarded.get(t.day)
        if day is None:
            # (a label from before the spreadsheet-date rule is still exported: the store may hold one)
            if checked and (why := day_label_problem(str(t.day), spreadsheet_dates=False)) is not None:
                raise TableError([f"traverse {i}: day: {why} (nothing written)"])
            day = guarded[t.day] = guard_cell(str(t.day))
        if checked and (problems := _value_problems(t)):
            raise TableError([f"traverse {i}: {p} (nothing written)" for p in problems])
        yield (day, *rest(t))


def measurements_to_csv(traverses: Iterable[Traverse]) -> str:
    """The CSV text of a measurement table (full float precision: floats as ``repr``, as csv writes them).

    Unchecked (a calibration's table hash, a test's hostile table): :func:`write_measurements` refuses
    a traverse that would not read back.
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(HEADER)
    w.writerows(_csv_rows(traverses))
    return buf.getvalue()


def write_measurements(path: str | Path, traverses: Iterable[Traverse]) -> None:
    """Write a measurement table to a CSV file, row by row as ``traverses`` yields them.

    Streamed (an iterator of a million stored traverses is never held as text); the
    file appears only when complete: a failed write keeps the old file. Raises
    :class:`TableError` naming the first traverse that :func:`read_measurements` would refuse
    whatever the arm (:func:`traverse_problems`), so every file written reads again.
    """

    def write(f: TextIO) -> None:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(HEADER)
        w.writerows(_csv_rows(traverses, checked=True))

    atomic_write(path, write)


def as_arrays(traverses: Sequence[Traverse]) -> dict[str, np.ndarray]:
    """Column arrays of a list of traverses (for vectorised model evaluation)."""
    cols = {f.name: [getattr(t, f.name) for t in traverses] for f in fields(Traverse)}
    out: dict[str, np.ndarray] = {}
    for k, v in cols.items():
        out[k] = np.asarray(v, dtype=object if k in ("day", "direction") else float)
    out["joint"] = out["joint"].astype(int)
    out["steps"] = out["steps"].astype(int)
    return out


