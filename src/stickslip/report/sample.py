"""In-sample or out-of-sample: are the validated traverses the ones the calibration was made from?

A calibration records where its traverses came from (``provenance``: the sha256 of
the measurement table as :func:`stickslip.measurements.measurements_to_csv` writes it,
the sha256 of the same rows sorted, the number of rows and the days). The report
compares the table it validates on with that record and says so in the figure titles
and on the page: a model always fits the data it was fitted to better than new data,
and a reader must be told which one a number is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from ..calibration import Provenance, table_digests
from ..measurements import Traverse

if TYPE_CHECKING:  # pragma: no cover
    from ..calibration import Calibration

__all__ = ["SampleKind", "Sample", "classify_days", "classify_sample", "table_sha256"]

SampleKind = Literal["in-sample", "out-of-sample", "overlapping", "mixed", "unknown"]


@dataclass(frozen=True)
class Sample:
    """How a validation table relates to the calibration's own data.

    Attributes
    ----------
    kind : {"in-sample", "out-of-sample", "overlapping", "mixed", "unknown"}
        ``in-sample``: the same table the calibration was made from (same sha256).
        ``out-of-sample``: a separate validation table, or a table with no day in
        common with the calibration's. ``overlapping``: another table that shares
        days with the calibration's, so it may share traverses. ``unknown``: the
        calibration records no provenance. ``mixed``: days of different kinds
        (:func:`classify_days` tells each).
    reason : str
        One sentence for the page: what was compared.
    """

    kind: SampleKind
    reason: str

    @property
    def title(self) -> str:
        """The label figure titles carry, e.g. ``"in-sample"``."""
        return {
            "in-sample": "in-sample",
            "out-of-sample": "out-of-sample",
            "overlapping": "may overlap the calibration data",
            "mixed": "in-sample and out-of-sample days",
            "unknown": "sample unknown",
        }[self.kind]


def table_sha256(traverses: Sequence[Traverse]) -> str:
    """sha256 of the table as the calibration's provenance computes it (hex)."""
    return table_digests(traverses)[0]


def _same_table(traverses: Sequence[Traverse], prov: Provenance) -> bool:
    """The provenance's table: the same rows in the same order, or (where it keeps the sorted digest) in any."""
    table, rows = table_digests(traverses)
    return table == prov.sha256 or (prov.rows_sha256 is not None and rows == prov.rows_sha256)


def classify_days(calibration: Calibration, traverses: Sequence[Traverse], separate: bool = False) -> dict[str, Sample]:
    """In-sample or out-of-sample, day by day: compare ``traverses`` with ``calibration.provenance``.

    The calibration's provenance holds the sha256, row count and days of the table it
    was made from. A day is in-sample when the table (or the rows of the
    calibration's days in it) hashes to that sha256; out-of-sample when it is not one
    of the calibration's days, or when ``separate`` (the user gave a separate
    validation table) and the table is not the calibration's own; ``overlapping``
    when it is one of the calibration's days but the rows differ; ``unknown`` when
    the calibration records no provenance.

    Returns
    -------
    dict
        ``day -> Sample`` for every day in ``traverses``.
    """
    days = sorted({t.day for t in traverses})
    prov = calibration.provenance
    sha, rows, cal_days = prov.sha256, prov.rows, prov.days
    if not sha:
        return {d: Sample("unknown", "the calibration records no provenance (sha256 of its table)") for d in days}
    own = f"the table the calibration was made from (sha256 {sha[:12]}…, {rows} rows)"
    if _same_table(traverses, prov):
        return {d: Sample("in-sample", f"these traverses are {own}") for d in days}
    cal_set = set(cal_days)
    shared = [t for t in traverses if t.day in cal_set]
    same_rows = bool(shared) and _same_table(shared, prov)
    out: dict[str, Sample] = {}
    for d in days:
        if d not in cal_set:
            out[d] = Sample("out-of-sample", f"day {d} is not a day of the calibration's table ({rows} rows)")
        elif same_rows:  # the calibration's own rows, even inside a 'separate' table
            out[d] = Sample("in-sample", f"the rows of day {d} are {own}")
        elif separate:
            out[d] = Sample("out-of-sample", f"a separate validation table; day {d} is also a day of {own}")
        else:
            out[d] = Sample(
                "overlapping",
                f"day {d} is a day of {own}, but the rows differ: they may share traverses "
                "(a table that holds none of them is out-of-sample when given as a separate validation table)",
            )
    return out


def classify_sample(calibration: Calibration, traverses: Sequence[Traverse], separate: bool = False) -> Sample:
    """One label for a whole table: the days' common kind, or ``mixed`` with the kind of each day.

    See :func:`classify_days` for the rule and ``separate``.
    """
    by_day = classify_days(calibration, traverses, separate)
    kinds = {s.kind for s in by_day.values()}
    if not by_day:
        return Sample("unknown", "no traverses")
    if len(kinds) == 1:
        first = next(iter(by_day.values()))
        if len(by_day) == 1 or first.kind in ("in-sample", "unknown"):
            return first
        return Sample(first.kind, "; ".join(s.reason for s in by_day.values()))
    return Sample("mixed", "; ".join(f"day {d}: {s.kind}" for d, s in by_day.items()))
