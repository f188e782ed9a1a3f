"""Measurement tables in notebooks: to and from pandas, and a table that shows itself.

* :func:`to_pandas` turns traverses (design.md §7 rows) into a ``pandas.DataFrame`` with
  the table's columns in SI units (rad, m) and an added ``gamma`` column (the average
  step, m or rad); ``df.attrs["units"]`` names each column's unit.
* :func:`from_pandas` reads such a frame back, through the same checks as reading a CSV
  measurement table (:func:`stickslip.measurements.parse_measurements`): a bad row is
  refused with its row number and reason, never used.
* :class:`TraverseTable` is a list of traverses with ``__repr__`` and ``_repr_html_``
  (steps and average steps in nm / µrad, positions in µm / deg).

pandas is imported lazily (it is in the ``stats`` extra).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from ..notebook import html_table
from ..units import position_scale, step_scale
from .rows import HEADER, Traverse
from .table import parse_measurements

__all__ = ["TraverseTable", "UNITS", "from_pandas", "to_pandas"]

UNITS: dict[str, str] = {
    "day": "",
    "joint": "",
    "direction": "",
    "q1": "rad",
    "q2": "rad",
    "q3": "m",
    "theta": "rad",
    "psi": "rad",
    "start": "m or rad (the moving joint's unit)",
    "end": "m or rad (the moving joint's unit)",
    "steps": "steps",
    "gamma": "m or rad (the moving joint's unit)",
}
"""The unit of each column of :func:`to_pandas` (SI)."""


def _pandas() -> Any:
    try:
        import pandas as pd
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("tables need pandas: pip install 'stickslip[stats]'") from e
    return pd


def to_pandas(traverses: Iterable[Traverse]) -> Any:
    """A ``pandas.DataFrame`` of ``traverses``: the measurement table's columns plus ``gamma`` (SI)."""
    pd = _pandas()
    rows = [{**t.as_row(), "gamma": t.gamma} for t in _traverses(traverses)]
    df = pd.DataFrame(rows, columns=[*HEADER, "gamma"])
    df = df.astype({"joint": "int64", "steps": "int64"})
    df.attrs["units"] = dict(UNITS)
    return df


def from_pandas(df: Any, source: str = "<DataFrame>") -> list[Traverse]:
    """The traverses of a frame with the measurement table's columns (extra columns such as ``gamma`` are ignored).

    Raises :class:`stickslip.measurements.TableError` listing every bad row (line 1 is
    the header, so the frame's first row is line 2), ``ValueError`` for missing columns.
    """
    if not hasattr(df, "columns") or not hasattr(df, "itertuples"):
        raise TypeError(f"from_pandas takes a pandas DataFrame, got {type(df).__name__}")
    missing = [c for c in HEADER if c not in df.columns]
    if missing:
        raise ValueError(f"{source}: missing column(s) {missing}; a measurement table has {list(HEADER)}")
    lines = [",".join(HEADER)]
    for values in df[list(HEADER)].itertuples(index=False, name=None):
        lines.append(",".join(_cell(v) for v in values))
    return parse_measurements("\n".join(lines) + "\n", source)


def _cell(v: object) -> str:
    """One CSV cell: floats with every digit (``repr``), so the round trip is exact."""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    text = str(v)
    return text.replace(",", " ").replace("\n", " ")  # a cell never splits a row; the parser judges the value


def _traverses(rows: Iterable[Traverse]) -> list[Traverse]:
    """``rows`` as a list; ``TypeError`` naming the first that is not a :class:`Traverse` (a number, a dict, a path)."""
    if isinstance(rows, (str, bytes)) or not isinstance(rows, Iterable):
        raise TypeError(f"expected traverses (a list of Traverse), got {type(rows).__name__}")
    out = list(rows)
    for i, t in enumerate(out):
        if not isinstance(t, Traverse):
            raise TypeError(f"item {i} is a {type(t).__name__}, not a Traverse (read a table with parse_measurements)")
    return out


class TraverseTable(list[Traverse]):
    """Traverses that show themselves as a table in Jupyter (and as a summary in a console)."""

    def __init__(self, rows: Iterable[Traverse] = ()) -> None:
        super().__init__(_traverses(rows))

    def to_pandas(self) -> Any:
        """:func:`to_pandas` of this table."""
        return to_pandas(self)

    @classmethod
    def from_pandas(cls, df: Any) -> TraverseTable:
        """:func:`from_pandas` as a table."""
        return cls(from_pandas(df))

    def __repr__(self) -> str:
        joints = sorted({t.joint for t in self})
        days = sorted({t.day for t in self})
        return f"TraverseTable({len(self)} traverses; joints {joints}; days {days})"

    def _repr_html_(self) -> str:
        rows = []
        for t in self:
            k, pu = position_scale(t.joint)
            s, su = step_scale(t.joint)
            rows.append([
                t.day, t.joint, t.direction, f"{math.degrees(t.q1):.4g}", f"{math.degrees(t.q2):.4g}",
                f"{t.q3 * 1e3:.4g}", f"{math.degrees(t.theta):.4g}", f"{math.degrees(t.psi):.4g}",
                f"{t.start * k:.6g} {pu}", f"{t.end * k:.6g} {pu}", t.steps, f"{t.gamma * s:.5g} {su}",
            ])
        return html_table(
            f"{len(self)} traverses",
            ["day", "joint", "dir", "q1 (deg)", "q2 (deg)", "q3 (mm)", "theta (deg)", "psi (deg)",
             "start", "end", "steps", "average step"],
            rows,
        )
