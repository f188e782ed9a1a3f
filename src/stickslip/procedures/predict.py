"""Predicting the step sizes of a pose table, a chunk at a time (``stickslip predict``).

A pose table of any length is read, checked, predicted and written in chunks
(:func:`stickslip.measurements.stream_pose_table`): memory is bounded by a chunk, not by
the table. Each row gets ``gamma_pred`` (the average step over its traverse, or the step at
its pose) and, asked for, ``gamma_pi95``, the half-width of its 95 % prediction interval in
its pose (:func:`stickslip.calibration.intervals.relative_sd`). Every other cell is passed
through as it stands.

The whole table is checked as it streams: a bad row anywhere fails the run with every bad
row's reason (:class:`~stickslip.measurements.TableError`), a row the calibration cannot
answer with the first such row (:class:`PredictionError`), and a writer that has been
handed rows discards them (``records.atomic_write``); :func:`check_pose_file` runs the checks
alone, for output that cannot be taken back (a terminal).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..calibration.intervals import relative_sd
from ..measurements import PoseChunk, PoseTable, TableError, stream_pose_table
from ..measurements.poses import POSE_COLUMNS
from ..models import NonPhysicalError
from ..records import guard_cell, needs_guard, unguard_cell

__all__ = ["PredictionError", "PredictedChunk", "predict_pose_file", "check_pose_file", "write_csv", "write_json"]


BLOCK = 8192
"""Rows evaluated at a time within a chunk (a rotary traverse's average takes 48 nodes of every load)."""


class PredictionError(ValueError):
    """A row the calibration cannot answer: ``"<file>: row N: <reason>"`` (rows counted from 1)."""


@dataclass(frozen=True, eq=False)
class PredictedChunk:
    """The predictions of a chunk of a pose table.

    Attributes
    ----------
    header : list of str
    table : PoseTable
        The chunk's rows as columns.
    cells : list of sequence of str
        Each row's cells.
    gamma : ndarray
        ``gamma_pred`` of each row (m or rad).
    pi95 : ndarray or None
        ``gamma_pi95`` of each row (m or rad), when asked for.
    """

    header: list[str]
    table: PoseTable
    cells: list[Sequence[str]]
    gamma: NDArray[np.float64]
    pi95: NDArray[np.float64] | None


def check_pose_file(path: str | Path) -> int:
    """Check a pose table as :func:`predict_pose_file` reads it (no calibration needed); its number of rows.

    Raises :class:`TableError` listing every bad row.
    """
    _, chunks = stream_pose_table(path)
    problems: list[tuple[int, str]] = []
    rows = 0
    for ch in chunks:
        problems += ch.problems
        rows += len(ch.table)
    if problems:
        raise TableError([p for _, p in sorted(problems, key=lambda lp: lp[0])])
    return rows


def predict_pose_file(
    cal: Calibration, path: str | Path, interval: bool = False, drift: float = 0.0
) -> tuple[list[str], Iterator[PredictedChunk]]:
    """A pose table's header and its predictions, a chunk at a time.

    ``drift`` (relative) is added in quadrature to each row's relative error in ``gamma_pi95``:
    a day's change of step scale for a calibration from another day
    (:func:`stickslip.calibration.update.day_drift`), 0 for today's.

    A bad file or header raises :class:`TableError` here. The chunks raise (when the table
    has been read to its end) :class:`TableError` with every bad row, else
    :class:`PredictionError` for the first row the calibration cannot answer; no chunk is
    yielded after the first problem.
    """
    if not (math.isfinite(drift) and drift >= 0):
        raise ValueError(f"drift must be finite and >= 0, got {drift!r}")
    header, chunks = stream_pose_table(path)
    return header, _predicted(cal, path, interval, drift, header, chunks)


def _predicted(
    cal: Calibration, path: str | Path, interval: bool, drift: float, header: list[str], chunks: Iterator[PoseChunk]
) -> Iterator[PredictedChunk]:
    problems: list[tuple[int, str]] = []
    failure: PredictionError | None = None
    done = 0
    for ch in chunks:
        problems += ch.problems
        if not problems and failure is None and len(ch.table):
            try:
                gamma = _predict(cal, ch.table, str(path), done)
                pi95 = _interval(cal, ch.table, gamma, drift) if interval else None
            except PredictionError as e:
                failure = e
            else:
                yield PredictedChunk(header, ch.table, ch.cells, gamma, pi95)
        done += len(ch.table)
    if problems:
        raise TableError([p for _, p in sorted(problems, key=lambda lp: lp[0])])
    if failure is not None:
        raise failure


def _predict(cal: Calibration, table: PoseTable, source: str, offset: int) -> NDArray[np.float64]:
    """gamma_pred of every row, vectorised per joint, direction and kind (pose or traverse)."""
    out = np.empty(len(table))
    trav = table.is_traverse
    first_error: tuple[int, str] | None = None
    cols = (table.q1, table.q2, table.q3, table.theta, table.psi)
    for j in np.unique(table.joint).tolist():
        for d in ("+", "-"):
            group = (table.joint == j) & (table.direction == d)
            if not group.any():
                continue
            try:
                m = cal.model(j, d)
            except KeyError as e:
                first_error = _earlier(first_error, (int(np.flatnonzero(group)[0]), str(e.args[0])))
                continue
            for kind in (True, False):
                idx = np.flatnonzero(group & (trav == kind))
                if not idx.size:
                    continue
                try:
                    for b in range(0, idx.size, BLOCK):  # a rotary average holds 48 nodes a row: by blocks
                        ib = idx[b : b + BLOCK]
                        c = [v[ib] for v in cols]
                        out[ib] = m.average_gamma(table.start[ib], table.end[ib], *c) if kind else m.gamma(*c)
                except NonPhysicalError:
                    for i in idx.tolist():  # the first row that fails, as a row-by-row loop would find it
                        try:
                            v = [float(x[i]) for x in cols]
                            if kind:
                                m.average_gamma(float(table.start[i]), float(table.end[i]), *v)
                            else:
                                m.gamma(*v)
                        except NonPhysicalError as e:
                            first_error = _earlier(first_error, (i, str(e)))
                            break
    if first_error is not None:
        raise PredictionError(f"{source}: row {first_error[0] + offset + 1}: {first_error[1]}")
    return out


def _earlier(known: tuple[int, str] | None, found: tuple[int, str]) -> tuple[int, str]:
    """The problem of the earlier row (of one row: the one known first), with its reason."""
    return found if known is None or found[0] < known[0] else known


def _interval(cal: Calibration, table: PoseTable, gamma: NDArray[np.float64], drift: float) -> NDArray[np.float64]:
    """Half-width of each prediction's 95 % interval: 1.96 x its relative standard deviation in its pose, with
    ``drift`` added in quadrature."""
    sd = np.zeros(len(table))
    for j in np.unique(table.joint).tolist():
        for d in ("+", "-"):
            group = (table.joint == j) & (table.direction == d)
            for b in range(0, int(group.sum()), BLOCK):
                ib = np.flatnonzero(group)[b : b + BLOCK]
                sd[ib] = relative_sd(cal, int(j), d, table.q1[ib], table.q2[ib], table.q3[ib], table.theta[ib],
                                     table.psi[ib])
    out: NDArray[np.float64] = 1.96 * np.hypot(sd, drift) * gamma
    return out


def _texts(values: NDArray[np.float64]) -> Iterator[str]:
    """repr of each value, a block at a time (one repr of a list runs in C)."""
    for i in range(0, len(values), 65536):
        yield from repr(values[i : i + 65536].tolist())[1:-1].split(", ")


def write_csv(header: list[str], chunks: Iterator[PredictedChunk], f: TextIO, interval: bool = False) -> int:
    """Write the predictions as CSV: the rows as they stand plus ``gamma_pred`` (and ``gamma_pi95``);
    a ``gamma_pred`` column already there is replaced. Returns the rows written.

    A cell a spreadsheet would run as a formula is written guarded (``records.guard_cell``;
    guarding a cell that needs none gives it back as it is). The pose columns hold checked
    numbers and signs; a chunk whose own columns and names need no guard passes through as
    it stands.
    """
    gamma_at = [i for i, h in enumerate(header) if h == "gamma_pred"]
    out_header = header + (["gamma_pred"] if not gamma_at else [])
    # a cell of a repeated (empty) column name holds the last such cell, as a dict of the row would
    last = {h: i for i, h in enumerate(header)}
    take = [last[h] for h in header]
    k = gamma_at[0] if gamma_at else len(take)
    own = [i for i, h in enumerate(header) if h not in POSE_COLUMNS]
    safe_header = not any(map(needs_guard, header))
    w = csv.writer(f, lineterminator="\n")
    head = [guard_cell(unguard_cell(h)) for h in out_header]
    first = next(chunks, None)  # a table whose first chunk fails leaves nothing written, not a lone header
    w.writerow([*head, "gamma_pi95"] if interval else head)
    n = 0
    for ch in itertools.chain([first] if first is not None else [], chunks):
        n += len(ch.table)
        texts = _texts(ch.gamma)
        safe = safe_header and not (own and any(needs_guard(cs[i]) for cs in ch.cells for i in own))
        rows = ch.cells if safe else [[guard_cell(unguard_cell(c)) for c in cs] for cs in ch.cells]
        if ch.pi95 is not None:
            w.writerows(
                [*(cells[i] for i in take[:k]), g, *(cells[i] for i in take[k + 1 :]), repr(h)]
                for cells, g, h in zip(rows, texts, ch.pi95.tolist(), strict=True)
            )
        elif ch.table.raw is not None and not gamma_at and safe:
            # plain rows (no quotes, none blank or short): csv would write each back as it stands
            lines = map("{},{}\n".format, ch.table.raw, texts)
            while part := "".join(itertools.islice(lines, 65536)):
                f.write(part)
        elif gamma_at:
            w.writerows(
                [*(cells[i] for i in take[:k]), g, *(cells[i] for i in take[k + 1 :])]
                for cells, g in zip(rows, texts, strict=True)
            )
        else:
            w.writerows([*(cells[i] for i in take), g] for cells, g in zip(rows, texts, strict=True))
    return n


def _maybe_number(v: str) -> object:
    """A cell as JSON has it: an int or float where it reads as one (NaN and infinity: null), else the text."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return v
    if not math.isfinite(x):
        return None
    if x.is_integer() and v.strip().lstrip("+-").isdigit():
        return int(x)
    return x


def write_json(header: list[str], chunks: Iterator[PredictedChunk], f: TextIO) -> int:
    """Write the predictions as a JSON array of row objects (the cells as numbers where they are numbers,
    ``gamma_pred``, ``gamma_pi95``), formatted as ``json.dumps(rows, indent=2)`` would, a row at a time."""
    last = {h: i for i, h in enumerate(header)}
    n = 0
    for ch in chunks:
        pi95 = ch.pi95.tolist() if ch.pi95 is not None else None
        for r_i, (cells, g) in enumerate(zip(ch.cells, ch.gamma.tolist(), strict=True)):
            row: dict[str, object] = {h: _maybe_number(unguard_cell(cells[i])) for h, i in last.items()}
            row["gamma_pred"] = g
            if pi95 is not None:
                row["gamma_pi95"] = pi95[r_i]
            text = json.dumps(row, indent=2).replace("\n", "\n  ")
            f.write(("[\n  " if n == 0 else ",\n  ") + text)
            n += 1
    f.write("[]\n" if n == 0 else "\n]\n")
    return n
