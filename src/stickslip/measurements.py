"""The measurement table: one traverse per row (docs/design.md §7).

CSV header, exactly::

    day,joint,direction,q1,q2,q3,theta,psi,start,end,steps

``day`` is a session label (ISO date preferred); ``q1, q2, q3`` hold the fixed joints
(the moving joint's column is ignored); ``start, end`` is the traversed interval of
the moving joint; ``steps`` a positive integer. All values SI (rad, m).

Rows that break these rules are never skipped: :func:`read_measurements` collects
every problem as ``file:line: reason`` and raises :class:`TableError`.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import operator
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from . import kinematics as kin
from .models import direction_label
from .records import MAX_TABLE_BYTES, atomic_write, read_text_bounded

__all__ = [
    "HEADER",
    "POSE_COLUMNS",
    "Traverse",
    "TraverseTable",
    "PoseTable",
    "TableError",
    "read_measurements",
    "parse_measurements",
    "read_measurement_table",
    "parse_measurement_table",
    "read_pose_columns",
    "parse_pose_columns",
    "write_measurements",
    "measurements_to_csv",
    "check_pose",
]

HEADER = ("day", "joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps")
POSE_COLUMNS = ("q1", "q2", "q3", "theta", "psi")
_TILT_LIMIT = math.pi + 1e-6


@dataclass(frozen=True)
class Traverse:
    """One measured traverse of one joint (a row of the measurement table).

    Attributes
    ----------
    day : str
        Session label (ISO date preferred).
    joint : int
        Moving joint, 1, 2 or 3.
    direction : str
        ``"+"`` (q increasing) or ``"-"``.
    q1, q2, q3 : float
        Fixed joints (rad, rad, m); the moving joint's value is ignored.
    theta, psi : float
        Base tilt, rad.
    start, end : float
        Traversed interval of the moving joint (rad or m).
    steps : int
        Steps counted, > 0.
    """

    day: str
    joint: int
    direction: str
    q1: float
    q2: float
    q3: float
    theta: float
    psi: float
    start: float
    end: float
    steps: int

    @property
    def gamma(self) -> float:
        """Average step size ``|end - start| / steps`` (m or rad)."""
        return abs(self.end - self.start) / self.steps

    @property
    def sign(self) -> int:
        return 1 if self.direction == "+" else -1

    def pose(self) -> dict[str, float]:
        """The fixed pose as a dict of ``q1, q2, q3, theta, psi``."""
        return {k: getattr(self, k) for k in POSE_COLUMNS}

    def as_row(self) -> dict[str, object]:
        return asdict(self)

    def with_moving(self, q: float) -> Traverse:
        """A copy whose moving joint's column holds ``q`` (handy for evaluating the model)."""
        if self.joint == 1:
            return replace(self, q1=q)
        if self.joint == 2:
            return replace(self, q2=q)
        return replace(self, q3=q)


class TableError(ValueError):
    """A measurement (or pose) table has problems; ``problems`` holds one line each.

    Each line reads ``file:line: reason`` (line 1 is the header).
    """

    def __init__(self, problems: Sequence[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


def check_pose(joint: int, values: dict[str, float]) -> list[str]:
    """Range problems of a pose for a traverse of ``joint`` (empty if fine).

    The fixed joints must lie within their stops; ``theta`` and ``psi`` within
    [-pi, pi]. Values use the tolerance of :meth:`JointSpec.contains`.
    """
    problems = []
    for j in (1, 2, 3):
        if j == joint:
            continue
        problem = kin.JOINTS[j].range_problem(f"q{j}", values[f"q{j}"])
        if problem:
            problems.append(problem)
    for name in ("theta", "psi"):
        v = values[name]
        if not -_TILT_LIMIT <= v <= _TILT_LIMIT:
            problems.append(f"{name} = {v:.6g} rad is outside [-pi, pi] (angles are in radians)")
    return problems


def _parse_float(name: str, text: str) -> tuple[float | None, str | None]:
    try:
        v = float(text)
    except ValueError:
        return None, f"{name} must be a number in SI units, got {text!r}"
    if not math.isfinite(v):
        return None, f"{name} must be finite, got {text!r}"
    return v, None


MAX_STEPS = 10**12
"""Largest step count accepted in a table (a full traverse is ~1e4..1e7 steps; SQLite holds < 2**63)."""


def _parse_steps(text: str) -> tuple[int | None, str | None]:
    t = text.strip()
    try:
        v = int(t)
    except ValueError:
        try:
            f = float(t)
        except ValueError:
            return None, f"steps must be a positive integer, got {text!r}"
        if not math.isfinite(f) or f != int(f):
            return None, f"steps must be a positive integer, got {text!r}"
        v = int(f)
    if v <= 0:
        return None, f"steps must be a positive integer, got {text!r}"
    if v > MAX_STEPS:
        return None, f"steps = {text.strip()[:30]} is more than {MAX_STEPS:.0e} steps (over any joint's full range)"
    return v, None


def parse_row(row: dict[str, str], where: str) -> tuple[Traverse | None, list[str]]:
    """Validate one CSV row (a dict of strings). Returns the traverse or the problems."""
    problems: list[str] = []
    day = (row.get("day") or "").strip()
    if not day:
        problems.append(f"{where}: day is empty (use a session label, e.g. an ISO date)")
    jtext = (row.get("joint") or "").strip()
    joint: int | None
    try:
        joint = int(jtext)
        kin.joint_spec(joint)
    except ValueError:
        problems.append(f"{where}: unknown joint {jtext!r} (joints are 1, 2 and 3)")
        joint = None
    dtext = (row.get("direction") or "").strip()
    try:
        direction = direction_label(dtext)
    except ValueError:
        problems.append(f"{where}: direction must be '+' or '-', got {dtext!r}")
        direction = None
    nums: dict[str, float] = {}
    for name in ("q1", "q2", "q3", "theta", "psi", "start", "end"):
        v, err = _parse_float(name, (row.get(name) or "").strip())
        if err:
            problems.append(f"{where}: {err}")
        else:
            nums[name] = v  # type: ignore[assignment]  # no error: _parse_float gave a float
    steps, err = _parse_steps(row.get("steps") or "")
    if err:
        problems.append(f"{where}: {err}")
    if problems or joint is None or direction is None or steps is None:
        return None, problems
    start, end = nums["start"], nums["end"]
    if end == start:
        problems.append(f"{where}: start and end are equal ({start:.6g}): a traverse must move")
    elif (end > start) != (direction == "+"):
        problems.append(
            f"{where}: direction {direction!r} disagrees with end - start = {end - start:.6g} ('+' means end > start)"
        )
    for name in ("start", "end"):
        problem = kin.JOINTS[joint].range_problem(name, nums[name])
        if problem:
            problems.append(f"{where}: {problem}")
    problems += [f"{where}: {p}" for p in check_pose(joint, nums)]
    if problems:
        return None, problems
    return Traverse(
        day, joint, direction, nums["q1"], nums["q2"], nums["q3"], nums["theta"], nums["psi"], start, end, steps
    ), []


def parse_measurements(text: str, source: str = "<string>") -> list[Traverse]:
    """Parse measurement-table CSV text. Raises :class:`TableError` listing every bad row."""
    try:
        return _parse_measurements(text, source)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None


def _csv_problem(source: str, e: csv.Error) -> str:
    text = str(e)
    if "field limit" in text:
        text = f"a cell is longer than {csv.field_size_limit()} characters"
    return f"{source}: not a readable CSV table ({text})"


CHUNK_ROWS = 65536
"""Rows parsed at a time: memory stays bounded by the chunk, not the table, beyond the result arrays."""


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


def _floats(cells: Sequence[str]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """``float(cell)`` of each cell and whether it is a finite number (vectorised where all parse)."""
    n = len(cells)
    try:
        v = np.fromiter(map(float, cells), dtype=float, count=n)
    except ValueError:
        v = np.empty(n)
        for i, c in enumerate(cells):
            try:
                v[i] = float(c)
            except ValueError:
                v[i] = math.nan
    return v, np.isfinite(v)


def _ints(cells: Sequence[str], lo: int, hi: int) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """``int(cell)`` of each cell and whether it is an integer in ``[lo, hi]``."""
    n = len(cells)
    try:
        v = np.fromiter(map(int, cells), dtype=np.int64, count=n)
        return v, (v >= lo) & (v <= hi)
    except (ValueError, OverflowError):
        v = np.zeros(n, dtype=np.int64)
        ok = np.zeros(n, dtype=bool)
        for i, c in enumerate(cells):
            try:
                x = int(c)
            except ValueError:
                continue
            if lo <= x <= hi:
                v[i], ok[i] = x, True
        return v, ok


def _within(joint: int, q: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Vectorised :meth:`JointSpec.contains` (same tolerance, same comparisons)."""
    spec = kin.JOINTS[joint]
    tol = 1e-5 * spec.span
    return (spec.lower - tol <= q) & (q <= spec.upper + tol)


def _pose_ok(joint: NDArray[np.int64], nums: dict[str, NDArray[np.float64]]) -> NDArray[np.bool_]:
    """Vectorised ``not check_pose(joint, nums)``: fixed joints within their stops, tilt within [-pi, pi]."""
    ok = np.ones(joint.size, dtype=bool)
    for j in (1, 2, 3):
        ok &= (joint == j) | _within(j, nums[f"q{j}"])
    for name in ("theta", "psi"):
        v = nums[name]
        ok &= (-_TILT_LIMIT <= v) & (v <= _TILT_LIMIT)
    return ok


def _moving_within(joint: NDArray[np.int64], q: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether ``q`` lies within the range of each row's own joint."""
    ok = np.zeros(joint.size, dtype=bool)
    for j in (1, 2, 3):
        sel = joint == j
        ok[sel] = _within(j, q[sel])
    return ok


_JOINT_CELL = {"1": 1, "2": 2, "3": 3}


def _joint_cells(cells: Sequence[str]) -> NDArray[np.int64]:
    """1, 2 or 3 where a cell is exactly that digit, else 0 (the row is then checked one by one)."""
    return np.fromiter(map(_JOINT_CELL.get, cells, itertools.repeat(0)), dtype=np.int64, count=len(cells))


def _equal(cells: Sequence[str], text: str) -> NDArray[np.bool_]:
    """Cells exactly equal to ``text`` (Python string equality: numpy's str arrays would drop trailing NULs)."""
    return np.fromiter(map(text.__eq__, cells), dtype=bool, count=len(cells))


def _records(text: str) -> Iterator[list[str]]:
    return csv.reader(io.StringIO(text))


@dataclass
class _Chunk:
    """Up to :data:`CHUNK_ROWS` records after the header, as columns when they are all regular.

    ``cols`` (the fast case): every record has the table's width and a non-blank key
    cell, so none is blank or short; one sequence per column. Otherwise ``records``:
    the records as :mod:`csv` reads them (``[]`` for an empty line), to be sorted out
    one by one. ``lines``: the chunk's raw text lines when the text is plain (see
    :func:`_plain_lines`), for passing rows through unchanged.
    """

    n: int
    cols: list[Sequence[str]] | None = None
    records: list[list[str]] | None = None
    lines: list[str] | None = None


def _plain_lines(text: str) -> list[str] | None:
    """The text's lines when :mod:`csv` would read each line as one record split at commas.

    True when there are no quotes, carriage returns or NULs and no line is longer than
    csv's cell limit: then the records are exactly ``line.split(",")`` (``[]`` for an
    empty line), and ``str.split`` is several times faster than the csv reader. ``None``
    otherwise (the csv reader is used).
    """
    if '"' in text or "\r" in text or "\x00" in text:
        return None
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()  # the newline that ends the last line starts no record
    if lines and max(map(len, lines)) > csv.field_size_limit():
        return None
    return lines


def _open_table(text: str) -> tuple[list[str] | None, Callable[[int, int], Iterator[_Chunk]]]:
    """The header record (``None`` for an empty text) and a function that yields the rest in chunks.

    ``chunks(width, key)`` yields :class:`_Chunk` objects; a chunk comes as columns when
    all its records have ``width`` cells and a non-blank cell ``key``.
    """
    plain = _plain_lines(text)
    if plain is None:
        reader = _records(text)
        header = next(reader, None)

        def csv_chunks(width: int, key: int) -> Iterator[_Chunk]:
            while chunk := list(itertools.islice(reader, CHUNK_ROWS)):
                if _all_wide_and_filled(chunk, width, key):
                    yield _Chunk(len(chunk), cols=list(zip(*chunk, strict=True)))
                else:
                    yield _Chunk(len(chunk), records=chunk)

        return header, csv_chunks
    if not plain:
        return None, lambda width, key: iter(())
    head, body = plain[0], plain[1:]

    def plain_chunks(width: int, key: int) -> Iterator[_Chunk]:
        for i in range(0, len(body), CHUNK_ROWS):
            part = body[i : i + CHUNK_ROWS]
            if width >= 2 and set(map(str.count, part, itertools.repeat(","))) == {width - 1}:
                cells = ",".join(part).split(",")
                cols: list[Sequence[str]] = [cells[k::width] for k in range(width)]
                if all(map(str.strip, cols[key])):
                    yield _Chunk(len(part), cols=cols, lines=part)
                    continue
            yield _Chunk(len(part), records=[ln.split(",") if ln else [] for ln in part], lines=part)

    return (head.split(",") if head else []), plain_chunks


def _all_wide_and_filled(chunk: list[list[str]], width: int, key: int) -> bool:
    """Whether every record has exactly ``width`` cells and a non-blank cell ``key`` (so none is blank)."""
    if not chunk or width == 0:
        return False
    widths = set(map(len, chunk))
    return widths == {width} and all(map(str.strip, map(operator.itemgetter(key), chunk)))


def _parse_measurements(text: str, source: str) -> list[Traverse]:
    return _parse_measurement_columns(text, source).traverses()


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


def _parse_measurement_columns(text: str, source: str) -> TraverseTable:
    header, chunks = _open_table(text)
    if header is None:
        raise TableError([f"{source}:1: the file is empty (expected the header {','.join(HEADER)})"])
    header = [h.strip() for h in header]
    if tuple(header) != HEADER:
        missing = [h for h in HEADER if h not in header]
        extra = [h for h in header if h not in HEADER]
        detail = []
        if missing:
            detail.append("missing " + ", ".join(missing))
        if extra:
            detail.append("unexpected " + ", ".join(extra))
        if not detail:
            detail.append("columns out of order")
        raise TableError([f"{source}:1: header must be exactly {','.join(HEADER)} ({'; '.join(detail)})"])
    parts: list[TraverseTable] = []
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
            part, errs = _measurement_chunk(cols, lines, source)
            parts.append(part)
            problems += errs
    if problems:
        raise TableError([p for _, p in sorted(problems, key=lambda lp: lp[0])])
    table = TraverseTable.concat(parts)
    if not len(table):
        raise TableError([f"{source}:2: the table has a header but no rows"])
    return table


def _measurement_chunk(
    cols: Sequence[Sequence[str]], lines: list[int], source: str
) -> tuple[TraverseTable, list[tuple[int, str]]]:
    """Check 11-cell rows (as columns) with numpy; rows failing a check are re-parsed by :func:`parse_row`."""
    days = [c.strip() for c in cols[0]]
    ok = ~_equal(days, "")
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
    problems: list[tuple[int, str]] = []
    bad = np.flatnonzero(~ok)
    for i in bad.tolist():
        t, errs = parse_row({h: c[i] for h, c in zip(HEADER, cols, strict=True)}, f"{source}:{lines[i]}")
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


def _read_table_text(path: str | Path) -> str:
    """The text of a CSV table (a regular file, at most :data:`records.MAX_TABLE_BYTES`).

    A missing file, a folder, a pipe or device (never opened, so it cannot hang), a file
    over the size limit or non-UTF-8 text raises :class:`TableError`.
    """
    p = Path(path)
    if not p.exists():
        raise TableError([f"{p}: no such file"])
    try:
        return read_text_bounded(p, "CSV", MAX_TABLE_BYTES)
    except ValueError as e:
        raise TableError([str(e)]) from None


def read_measurements(path: str | Path) -> list[Traverse]:
    """Read a measurement table from a CSV file. Raises :class:`TableError` on any bad row."""
    return parse_measurements(_read_table_text(path), str(path))


def read_measurement_table(path: str | Path) -> TraverseTable:
    """Read a measurement table from a CSV file into columns (see :func:`parse_measurement_table`)."""
    return parse_measurement_table(_read_table_text(path), str(path))


def measurements_to_csv(traverses: Iterable[Traverse]) -> str:
    """The CSV text of a measurement table (full float precision: floats as ``repr``, as csv writes them)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(HEADER)
    row = operator.attrgetter(*HEADER)
    w.writerows(map(row, traverses))
    return buf.getvalue()


def write_measurements(path: str | Path, traverses: Iterable[Traverse]) -> None:
    """Write a measurement table to a CSV file, row by row as ``traverses`` yields them.

    Streamed (an iterator of a million stored traverses is never held as text); the
    file appears only when complete: a failed write keeps the old file.
    """
    row = operator.attrgetter(*HEADER)

    def write(f: TextIO) -> None:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(HEADER)
        w.writerows(map(row, traverses))

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


# ----------------------------------------------------------------------------- pose tables (predict)

POSE_TABLE_REQUIRED = ("joint", "q1", "q2", "q3", "theta", "psi")


@dataclass(frozen=True)
class PoseQuery:
    """One row of a pose table for ``predict``.

    ``start``/``end`` given: the average step over that traverse is asked for.
    Otherwise: the step size at the pose (the moving joint at ``q{joint}``).
    """

    joint: int
    direction: str
    q1: float
    q2: float
    q3: float
    theta: float
    psi: float
    start: float | None = None
    end: float | None = None

    @property
    def is_traverse(self) -> bool:
        return self.start is not None


def parse_pose_table(text: str, source: str = "<string>") -> tuple[list[str], list[dict[str, str]], list[PoseQuery]]:
    """Parse a pose table (CSV): columns joint, q1, q2, q3, theta, psi, and direction and/or start, end.

    A row with start and end is a traverse; its direction may be left out (it is the
    sign of end - start). A row without them asks for the step size at the pose and
    needs a direction. Other columns (day, steps, notes, ...) are kept and passed through. Returns the
    header, the raw rows and the parsed queries; raises :class:`TableError` listing
    every bad row as ``file:line: reason``.
    """
    try:
        return _parse_pose_table(text, source)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None


def _pose_header(record: list[str] | None, source: str) -> list[str]:
    """The stripped header of a pose table, checked (as ``csv.DictReader`` reads it: the first record)."""
    header = [h.strip() for h in record or []]
    dup = sorted({h for h in header if h and header.count(h) > 1})
    if dup:
        raise TableError([f"{source}:1: column(s) {', '.join(dup)} appear more than once; keep one of each"])
    if not header:
        raise TableError([f"{source}:1: the file is empty (expected a header with {','.join(POSE_TABLE_REQUIRED)})"])
    missing = [c for c in POSE_TABLE_REQUIRED if c not in header]
    if missing:
        raise TableError(
            [
                f"{source}:1: header lacks {', '.join(missing)} (needs {','.join(POSE_TABLE_REQUIRED)}, "
                "and direction and/or start,end)"
            ]
        )
    return header


def _pose_records(
    chunks: Iterator[_Chunk], header: list[str]
) -> Iterator[tuple[list[int], list[Sequence[str]], list[int], list[str] | None]]:
    """Per chunk of a pose table: ``(lines, cols, overlong, raw)``, numbered by line in the file.

    ``cols`` holds the data rows as columns, padded with empty cells to the header's
    width; ``lines`` their line numbers. Empty records (blank lines) are skipped but
    counted, as in measurement tables, so ``file:line`` names the line; records
    whose cells are blank (of a repeated column name, the last cell) are counted and
    skipped; ``overlong`` lists the lines of
    records with more cells than the header. ``raw``: the chunk's text lines when
    every one of them is a data row as it stands (for passing rows through), else None.
    """
    width = len(header)
    used = sorted({h: i for i, h in enumerate(header)}.values())
    lineno = 1
    for chunk in chunks:
        if chunk.cols is not None:  # the common case: every record full and not blank
            yield list(range(lineno + 1, lineno + 1 + chunk.n)), chunk.cols, [], chunk.lines
            lineno += chunk.n
            continue
        lines: list[int] = []
        overlong: list[int] = []
        rows: list[list[str]] = []
        for cells in chunk.records or []:
            lineno += 1
            if not cells:
                continue  # a blank line: not data, but counted, so file:line points at the line
            if len(cells) > width:
                overlong.append(lineno)
                continue
            if all(i >= len(cells) or not cells[i].strip() for i in used):
                continue
            if len(cells) < width:
                cells = cells + [""] * (width - len(cells))
            lines.append(lineno)
            rows.append(cells)
        cols: list[Sequence[str]] = list(zip(*rows, strict=True)) if rows else [()] * width
        yield lines, cols, overlong, None


def _pose_row(
    row: dict[str, str], where: str, has_traverse: bool
) -> tuple[PoseQuery | None, list[str]]:
    """Validate one pose-table row (a dict of strings, missing cells empty): the query or the problems."""
    errs: list[str] = []
    jtext = (row.get("joint") or "").strip()
    try:
        joint = int(jtext)
        kin.joint_spec(joint)
    except ValueError:
        errs.append(f"{where}: unknown joint {jtext!r} (joints are 1, 2 and 3)")
        joint = 0
    dtext = (row.get("direction") or "").strip()
    direction: str | None = None
    if dtext:
        try:
            direction = direction_label(dtext)
        except ValueError:
            errs.append(f"{where}: direction must be '+' or '-', got {dtext!r}")
    nums: dict[str, float] = {}
    for name in ("q1", "q2", "q3", "theta", "psi"):
        v, err = _parse_float(name, (row.get(name) or "").strip())
        if err or v is None:
            errs.append(f"{where}: {err}")
        else:
            nums[name] = v
    start = end = None
    if has_traverse:
        st, en = (row.get("start") or "").strip(), (row.get("end") or "").strip()
        if st or en:
            if not (st and en):
                errs.append(f"{where}: give both start and end (a traverse) or neither (a pose)")
            else:
                start, e1 = _parse_float("start", st)
                end, e2 = _parse_float("end", en)
                errs += [f"{where}: {e}" for e in (e1, e2) if e]
    if not errs and joint:
        spec = kin.JOINTS[joint]
        if start is not None and end is not None:
            if start == end:
                errs.append(f"{where}: start and end are equal: a traverse must move")
            elif direction is None:
                direction = "+" if end > start else "-"
            elif (end > start) != (direction == "+"):
                errs.append(f"{where}: direction {direction!r} disagrees with end - start = {end - start:.6g}")
            checks = [("start", start), ("end", end)]
        else:
            if direction is None:
                errs.append(f"{where}: the step size at a pose needs a direction ('+' or '-')")
            checks = [(f"q{joint}", nums[f"q{joint}"])]
        errs += [f"{where}: {p}" for name, v in checks if (p := spec.range_problem(name, v))]
        errs += [f"{where}: {p}" for p in check_pose(joint, nums)]
    if errs:
        return None, errs
    assert direction is not None
    return PoseQuery(joint, direction, nums["q1"], nums["q2"], nums["q3"], nums["theta"], nums["psi"], start, end), []


@dataclass(frozen=True, eq=False)
class PoseTable:
    """A pose table for ``predict`` as columns, with the text to pass its cells through.

    Attributes
    ----------
    header : list of str
        The stripped header.
    joint : ndarray of int
    direction : ndarray of str
        ``"+"`` or ``"-"`` (for a traverse row without one: the sign of ``end - start``).
    q1, q2, q3, theta, psi : ndarray of float
        The pose (rad, m).
    start, end : ndarray of float
        The traversed interval, NaN on rows that ask for the step at the pose.
    lines : ndarray of int
        Line of each row (as :func:`parse_pose_table` numbers them).
    raw : list of str or None
        The rows' text lines, when each is a row as it stands: no quotes, no blank or
        short rows (then a row can be passed through without parsing it again).
    """

    header: list[str]
    joint: NDArray[np.int64]
    direction: NDArray[np.str_]
    q1: NDArray[np.float64]
    q2: NDArray[np.float64]
    q3: NDArray[np.float64]
    theta: NDArray[np.float64]
    psi: NDArray[np.float64]
    start: NDArray[np.float64]
    end: NDArray[np.float64]
    lines: NDArray[np.int64]
    text: str = ""
    raw: list[str] | None = None

    def __len__(self) -> int:
        return int(self.joint.size)

    @property
    def is_traverse(self) -> NDArray[np.bool_]:
        """Rows with ``start, end`` (the average over a traverse is asked for)."""
        return ~np.isnan(self.start)

    def cells(self) -> Iterator[Sequence[str]]:
        """Each row's cells, as many as the header has (missing cells empty), read again from the text."""
        _, chunks = _open_table(self.text)
        key = self.header.index("joint")
        for _lines, cols, _overlong, _raw in _pose_records(chunks(len(self.header), key), self.header):
            yield from zip(*cols, strict=True)

    def queries(self) -> list[PoseQuery]:
        """The rows as :class:`PoseQuery` objects."""
        st = [None if math.isnan(v) else v for v in self.start.tolist()]
        en = [None if math.isnan(v) else v for v in self.end.tolist()]
        cols = [getattr(self, k).tolist() for k in ("joint", "direction", "q1", "q2", "q3", "theta", "psi")]
        return list(map(PoseQuery, *cols, st, en))


def _parse_pose_table(text: str, source: str) -> tuple[list[str], list[dict[str, str]], list[PoseQuery]]:
    table = _parse_pose_columns(text, source)
    rows = [dict(zip(table.header, cells, strict=True)) for cells in table.cells()]
    return table.header, rows, table.queries()


def parse_pose_columns(text: str, source: str = "<string>") -> PoseTable:
    """Parse a pose table (see :func:`parse_pose_table`) into columns; the same rules and messages."""
    try:
        return _parse_pose_columns(text, source)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None


def read_pose_columns(path: str | Path) -> PoseTable:
    """Read a pose table from a CSV file into columns (see :func:`parse_pose_columns`)."""
    return parse_pose_columns(_read_table_text(path), str(path))


def _parse_pose_columns(text: str, source: str) -> PoseTable:
    record, chunks = _open_table(text)
    header = _pose_header(record, source)
    has_traverse = "start" in header and "end" in header
    # the cell a column's value comes from: the last of equal names, as in a dict (only '' can repeat)
    where_col = {h: i for i, h in enumerate(header)}
    problems: list[tuple[int, str]] = []  # (line, reason), sorted by line at the end
    parts: list[tuple[NDArray[np.int64], NDArray[np.str_], dict[str, NDArray[np.float64]], NDArray[np.int64]]] = []
    raw: list[str] | None = []
    for lines, cols, overlong, raw_part in _pose_records(chunks(len(header), header.index("joint")), header):
        problems += [(n, f"{source}:{n}: more cells than header columns") for n in overlong]
        if raw is not None and raw_part is not None:
            raw += raw_part
        else:
            raw = None
        if not lines:
            continue
        part, errs = _pose_chunk(cols, lines, source, where_col, has_traverse, header)
        problems += errs
        parts.append(part)
    if problems:
        raise TableError([p for _, p in sorted(problems, key=lambda lp: lp[0])])
    if parts:
        joint = np.concatenate([p[0] for p in parts])
        direction = np.concatenate([p[1] for p in parts])
        nums = {k: np.concatenate([p[2][k] for p in parts]) for k in parts[0][2]}
        lines_a = np.concatenate([p[3] for p in parts])
    else:
        joint, direction, lines_a = np.zeros(0, np.int64), np.zeros(0, "<U1"), np.zeros(0, np.int64)
        nums = {k: np.zeros(0) for k in ("q1", "q2", "q3", "theta", "psi", "start", "end")}
    return PoseTable(
        header,
        joint,
        direction,
        nums["q1"],
        nums["q2"],
        nums["q3"],
        nums["theta"],
        nums["psi"],
        nums["start"],
        nums["end"],
        lines_a,
        text,
        raw if raw is not None and len(set(header)) == len(header) else None,
    )


def _pose_chunk(
    cols: Sequence[Sequence[str]],
    lines: list[int],
    source: str,
    where_col: dict[str, int],
    has_traverse: bool,
    header: list[str],
) -> tuple[
    tuple[NDArray[np.int64], NDArray[np.str_], dict[str, NDArray[np.float64]], NDArray[np.int64]],
    list[tuple[int, str]],
]:
    """Check a chunk of pose rows with numpy; rows that fail anything are re-parsed by :func:`_pose_row`."""
    n = len(lines)

    def col(name: str) -> Sequence[str]:
        return cols[where_col[name]] if name in where_col else ("",) * n

    joint = _joint_cells(col("joint"))
    ok = joint > 0
    dcol = col("direction")
    plus, minus, nodir = _equal(dcol, "+"), _equal(dcol, "-"), _equal(dcol, "")
    ok &= plus | minus | nodir
    nums: dict[str, NDArray[np.float64]] = {}
    for name in ("q1", "q2", "q3", "theta", "psi"):
        v, good = _floats(col(name))
        nums[name] = v
        ok &= good
    if has_traverse:
        scol, ecol = col("start"), col("end")
        both_empty = _equal(scol, "") & _equal(ecol, "")
        start, sgood = _floats(scol)
        end, egood = _floats(ecol)
        trav = sgood & egood
        ok &= trav | both_empty
        start[~trav] = np.nan
        end[~trav] = np.nan
    else:
        trav = np.zeros(n, dtype=bool)
        start, end = np.full(n, np.nan), np.full(n, np.nan)
    with np.errstate(invalid="ignore"):
        up = end > start
        # a traverse moves and agrees with its direction (or gives it); a pose needs a direction
        ok &= np.where(trav, (end != start) & (nodir | (up == plus)), ~nodir)
        plus = np.where(trav & nodir, up, plus)
        own = nums["q1"].copy()
        own[joint == 2] = nums["q2"][joint == 2]
        own[joint == 3] = nums["q3"][joint == 3]
        ok &= np.where(trav, _moving_within(joint, start) & _moving_within(joint, end), _moving_within(joint, own))
        ok &= _pose_ok(joint, nums)
    problems: list[tuple[int, str]] = []
    bad = np.flatnonzero(~ok)
    for i in bad.tolist():
        row = {h: c[i] for h, c in zip(header, cols, strict=True)}
        q, errs = _pose_row(row, f"{source}:{lines[i]}", has_traverse)
        if errs or q is None:
            problems += [(lines[i], e) for e in errs]
            continue
        ok[i] = True  # a row the vector check was too strict for (" 3", "pos", " 0.1"): take _pose_row's values
        joint[i] = q.joint
        plus[i] = q.direction == "+"
        for name in ("q1", "q2", "q3", "theta", "psi"):
            nums[name][i] = getattr(q, name)
        start[i] = math.nan if q.start is None else q.start
        end[i] = math.nan if q.end is None else q.end
    nums["start"], nums["end"] = start, end
    keep = ok if bad.size else slice(None)
    direction = np.where(plus, "+", "-")
    return (
        (joint[keep], direction[keep], {k: v[keep] for k, v in nums.items()}, np.array(lines, dtype=np.int64)[keep]),
        problems,
    )


def read_pose_table(path: str | Path) -> tuple[list[str], list[dict[str, str]], list[PoseQuery]]:
    """Read a pose table from a CSV file (see :func:`parse_pose_table`)."""
    return parse_pose_table(_read_table_text(path), str(path))
