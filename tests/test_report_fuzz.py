"""Fuzzed tables through the figure data: no traverse is lost, duplicated or moved to another day.

An independent peer of the grouping in stickslip.report: for any table, the multiset of
(day, direction, average step) drawn in the panels equals the one recomputed from the
raw rows (|end - start| / steps, design.md §2), and the in-/out-of-sample rule holds
for any split of the calibration's table into days.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

import pytest
from analysis_tables import simulated_table  # tests/support
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.calibration import Calibration, calibrate
from stickslip.measurements import Traverse
from stickslip.report import StepFigure, classify_days, prismatic_data, rotary_interval_data

pytest.importorskip("matplotlib")
DAYS = ("2026-11-20", "2026-11-21", "2026-11-23")
ANGLES = [k * math.pi / 12 for k in range(-14, 3)]  # q2 and psi on a grid, so poses repeat


@pytest.fixture(scope="module")
def cal() -> Calibration:
    return calibrate(simulated_table(5, noise=0.01, day=DAYS[0]), method="lsq")


def _prismatic_row() -> st.SearchStrategy[Traverse]:
    return st.builds(
        lambda day, d, q2, th, ps, steps: Traverse(
            day, 3, d, 0.0, q2, 0.0, th, ps, *((0.0, 0.012) if d == "+" else (0.012, 0.0)), steps
        ),
        st.sampled_from(DAYS),
        st.sampled_from("+-"),
        st.sampled_from(ANGLES),
        st.sampled_from([0.0, -math.pi / 4, -math.pi / 3, -math.pi / 2]),
        st.sampled_from([0.0, math.pi / 6, -math.pi / 6]),
        st.integers(8000, 40000),
    )


def _rotary_row() -> st.SearchStrategy[Traverse]:
    def make(day: str, d: str, k0: int, k1: int, q3: float, th: float, steps: int) -> Traverse:
        lo, hi = -7 * math.pi / 6 + k0 * math.pi / 6, -7 * math.pi / 6 + (k0 + k1) * math.pi / 6
        s, e = (lo, hi) if d == "+" else (hi, lo)
        return Traverse(day, 2, d, 0.0, 0.0, q3, th, 0.0, s, e, steps)

    return st.builds(
        make,
        st.sampled_from(DAYS),
        st.sampled_from("+-"),
        st.integers(0, 7),
        st.integers(1, 8),
        st.sampled_from([0.0, 0.006, 0.012]),
        st.sampled_from([0.0, -math.pi / 4, -math.pi / 2]),
        st.integers(5000, 100000),
    ).filter(lambda t: max(t.start, t.end) <= math.pi / 6 + 1e-9)


def _want(rows: list[Traverse]) -> Counter[tuple[str, str, float]]:
    return Counter((t.day, t.direction, round(abs(t.end - t.start) / t.steps, 15)) for t in rows)


def _got(fig: StepFigure) -> Counter[tuple[str, str, float]]:
    return Counter(
        (p.day, p.direction, round(float(g), 15)) for p in fig.panels for c in p.curves for g in c.gamma_data
    )


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(_prismatic_row(), min_size=1, max_size=25))
def test_fig4_draws_every_prismatic_row_once_in_its_days_panel(cal, rows):
    fig = prismatic_data(cal, rows)
    assert _got(fig) == _want(rows)
    assert fig.days == sorted({t.day for t in rows})
    for p in fig.panels:
        for c in p.curves:
            assert c.gamma_pred.size == c.gamma_data.size and (c.gamma_pred > 0).all()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(_rotary_row(), min_size=1, max_size=25))
def test_fig6_draws_every_rotary_row_once_in_its_days_panel(cal, rows):
    fig = rotary_interval_data(cal, rows, 2)
    assert _got(fig) == _want(rows)
    for p in fig.panels:
        for c in p.curves:
            assert (c.x_halfwidth > 0).all() and (c.x_halfwidth <= 2 * math.pi / 3 + 1e-12).all()


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(st.lists(st.sampled_from(DAYS), min_size=1, max_size=40), st.booleans())
def test_only_the_calibrations_own_rows_are_in_sample(days, separate):
    table = simulated_table(3, noise=0.01, day=DAYS[0])
    cal = calibrate(table, method="lsq")
    others = [dataclasses.replace(t, day=day) for day, t in zip(days, table, strict=False)]
    labels = classify_days(cal, table + others, separate)
    for day, s in labels.items():
        if day != DAYS[0]:
            assert s.kind == "out-of-sample"  # not a day of the calibration's table
        elif others and any(t.day == DAYS[0] for t in others):
            assert s.kind in ("overlapping", "out-of-sample")  # the calibration's day, other rows too
        else:
            assert s.kind == "in-sample"  # exactly the calibration's rows
