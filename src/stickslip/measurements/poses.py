"""Pose tables (what ``stickslip predict`` reads): a pose or a traverse per row, other columns passed through."""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..models import direction_label
from .chunks import _Chunk, _equal, _floats, _joint_cells, _moving_within, _open_table, _pose_ok, stream_table
from .rows import (
    TableError,
    _csv_problem,
    _parse_float,
    check_pose,
    is_history_header,
    separator_problem,
    unit_column_problem,
)
from .table import _read_table_text

POSE_TABLE_REQUIRED = ("joint", "q1", "q2", "q3", "theta", "psi")
POSE_COLUMNS = ("joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end")
"""The columns a pose table's rows are checked in (numbers, a joint, a direction); any other is passed through."""


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
    if missing and is_history_header(header):
        raise TableError([f"{source}:1: a stickslip history file (export --json), not a pose table: write its "
                          "rows as a table (stickslip export -o TABLE.csv) and give that"])
    if missing and (sep := separator_problem(header)) is not None:
        raise TableError([f"{source}:1: {sep}"])
    if missing:
        named = unit_column_problem(header, (*POSE_TABLE_REQUIRED, "start", "end"))
        raise TableError(
            [
                f"{source}:1: header lacks {', '.join(missing)} (needs {','.join(POSE_TABLE_REQUIRED)}, "
                "and direction and/or start,end)" + (f"; {named}" if named else "")
            ]
        )
    return header


def _pose_records(
    chunks: Iterator[_Chunk], header: list[str]
) -> Iterator[tuple[list[int], list[Sequence[str]], list[tuple[int, str]], list[str] | None]]:
    """Per chunk of a pose table: ``(lines, cols, ragged, raw)``, numbered by line in the file.

    ``cols`` holds the data rows as columns; ``lines`` their line numbers. Empty records (blank lines) are skipped but
    counted, as in measurement tables, so ``file:line`` names the line; records
    whose cells are blank (of a repeated column name, the last cell) are counted and
    skipped; ``ragged`` lists ``(line, reason)`` of the records with more or fewer cells
    than the header (fewer: a cell lost in the middle would shift every value after it into
    the next column, a pose read wrong; a row leaving trailing cells empty writes their commas).
    ``raw``: the chunk's text lines when every one of them is a data row as it stands (for
    passing rows through), else None.
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
        ragged: list[tuple[int, str]] = []
        rows: list[list[str]] = []
        for cells in chunk.records or []:
            lineno += 1
            if not cells:
                continue  # a blank line: not data, but counted, so file:line points at the line
            if len(cells) > width:
                ragged.append((lineno, "more cells than header columns"))
                continue
            if all(i >= len(cells) or not cells[i].strip() for i in used):
                continue
            if len(cells) < width:
                ragged.append((lineno, f"{len(cells)} cells, the header has {width} columns: a cell lost would "
                                       "shift the values after it into the next column; write a comma for each "
                                       "cell left empty"))
                continue
            lines.append(lineno)
            rows.append(cells)
        cols: list[Sequence[str]] = list(zip(*rows, strict=True)) if rows else [()] * width
        yield lines, cols, ragged, None


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
        for _lines, cols, _ragged, _raw in _pose_records(chunks(len(self.header), key), self.header):
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
    for lines, cols, ragged, raw_part in _pose_records(chunks(len(header), header.index("joint")), header):
        problems += [(n, f"{source}:{n}: {why}") for n, why in ragged]
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


@dataclass(frozen=True, eq=False)
class PoseChunk:
    """A chunk of a pose table read as it streams (:func:`stream_pose_table`).

    Attributes
    ----------
    table : PoseTable
        The chunk's good rows as columns (``raw``: their text lines when plain, as
        :class:`PoseTable` keeps them; ``text`` empty).
    cells : list of sequence of str
        Each good row's cells, as many as the header has (missing cells empty).
    problems : list of (int, str)
        ``(line, reason)`` of every bad row of the chunk.
    """

    table: PoseTable
    cells: list[Sequence[str]]
    problems: list[tuple[int, str]]


def stream_pose_table(path: str | Path) -> tuple[list[str], Iterator[PoseChunk]]:
    """A pose table (see :func:`parse_pose_table`) read a chunk at a time: the header, and the chunks.

    The same rules, line numbers and messages as :func:`read_pose_columns`, with no size
    limit: memory is bounded by a chunk (:data:`~.chunks.CHUNK_ROWS` rows). A problem with
    the file itself or its header raises :class:`TableError` here; each chunk reports its bad
    rows (a file that stops being UTF-8 or CSV further on raises :class:`TableError` there).
    """
    from ..records import text_lines

    source = str(path)
    try:
        header_record, chunks = stream_table(text_lines(path, "CSV"))
    except (ValueError, csv.Error) as e:
        raise TableError([_csv_problem(source, e) if isinstance(e, csv.Error) else str(e)]) from None
    header = _pose_header(header_record, source)
    has_traverse = "start" in header and "end" in header
    where_col = {h: i for i, h in enumerate(header)}
    plain_header = len(set(header)) == len(header)

    def gen() -> Iterator[PoseChunk]:
        records = _pose_records(chunks(len(header), header.index("joint")), header)
        while True:
            try:
                item = next(records, None)
            except (ValueError, csv.Error) as e:
                raise TableError([_csv_problem(source, e) if isinstance(e, csv.Error) else str(e)]) from None
            if item is None:
                return
            lines, cols, ragged, raw_part = item
            problems = [(n, f"{source}:{n}: {why}") for n, why in ragged]
            if not lines:
                yield PoseChunk(_empty_pose_table(header), [], problems)
                continue
            (joint, direction, nums, lines_a), errs = _pose_chunk(cols, lines, source, where_col, has_traverse,
                                                                  header)
            problems += errs
            table = PoseTable(header, joint, direction, nums["q1"], nums["q2"], nums["q3"], nums["theta"],
                              nums["psi"], nums["start"], nums["end"], lines_a, "",
                              raw_part if raw_part is not None and plain_header and not errs else None)
            rows: list[Sequence[str]] = list(zip(*cols, strict=True))
            if errs:
                kept = set(lines_a.tolist())
                rows = [r for r, n in zip(rows, lines, strict=True) if n in kept]
            yield PoseChunk(table, rows, problems)

    return header, gen()


def _empty_pose_table(header: list[str]) -> PoseTable:
    z = np.zeros(0)
    return PoseTable(header, np.zeros(0, np.int64), np.zeros(0, "<U1"), z, z, z, z, z, z, z, np.zeros(0, np.int64))
