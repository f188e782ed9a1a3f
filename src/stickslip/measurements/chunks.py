"""Reading a CSV table a chunk of rows at a time, as columns, and the vectorised cell checks."""

from __future__ import annotations

import csv
import io
import itertools
import math
import operator
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..joints import coordinate_bound
from .rows import _TILT_LIMIT

CHUNK_ROWS = 65536
"""Rows parsed at a time: memory stays bounded by the chunk, not the table, beyond the result arrays."""


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
    for j in (1, 2, 3):  # the moving joint's own q is ignored, but within a turn (a metre): the store refuses it else
        q = nums[f"q{j}"]
        ok &= ((joint == j) & (np.abs(q) <= coordinate_bound(j))) | _within(j, q)
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



def _blocks(lines: Iterator[str]) -> Iterator[str]:
    """Up to :data:`CHUNK_ROWS` lines at a time as one text, never cutting a quoted cell: a block
    ends only where it holds an even number of quotes (a cell's line break is inside quotes)."""
    while True:
        part = list(itertools.islice(lines, CHUNK_ROWS))
        if not part:
            return
        text = "".join(part)
        while text.count('"') % 2:
            more = next(lines, None)
            if more is None:
                break
            text += more
        yield text


def stream_table(lines: Iterator[str]) -> tuple[list[str] | None, Callable[[int, int], Iterator[_Chunk]]]:
    """:func:`_open_table` over lines read as they come (:func:`stickslip.records.text_lines`).

    The header record (``None`` for an empty file) and a function that yields the rest in
    chunks of :data:`CHUNK_ROWS` records; each block of lines is parsed as the whole text
    would be (plain lines split at commas, others by :mod:`csv`), so records, cells and
    their numbering are the same. Memory is bounded by a chunk.
    """
    blocks = _blocks(lines)
    first = next(blocks, "")
    header, rest_chunks = _open_table(first)
    if header is None:
        return None, lambda width, key: iter(())

    def chunks(width: int, key: int) -> Iterator[_Chunk]:
        yield from rest_chunks(width, key)
        for text in blocks:
            yield from _open_table_body(text, width, key)

    return header, chunks


def _open_table_body(text: str, width: int, key: int) -> Iterator[_Chunk]:
    """The records of ``text`` (no header) in chunks, as :func:`_open_table` yields them after its header."""
    _, chunks = _open_table("h\n" + text)
    yield from chunks(width, key)
