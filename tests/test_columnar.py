"""The columnar (vectorised) table parsers against the row-by-row parser they replaced.

``measurements_rowwise`` is the parser as it was before it was vectorised. On hostile
tables (hypothesis: odd numbers, whitespace, unicode, wrong lengths, quoted line breaks,
blank lines, chunk boundaries) both must accept the same rows with the same values, or
refuse with the same messages (file, line, reason) in the same order.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import astuple

import measurements_rowwise as old
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip import measurements as new

NUMBERS = [
    "0", "0.0", "-0", "1e-3", "0.006", "0.012", "0.0120001", "0.013", "-1.5707963267948966", "-1.5707963", "1.5707963",
    "3.14159", "3.1416", "-3.2", "0.5235987755982988", "-3.665191429188092", "-3.67", "2.2", " 0.1 ", "\u20030.2",
    "1_0", "nan", "inf", "-inf", "1e999", "", " ", "abc", "0x10", "١", "+0.5", ".5", "5.", "1e-320", "0\x00",
]
JOINTS = ["1", "2", "3", " 3", "03", "+2", "4", "0", "", "x", "3.0", "3\x00"]
DIRS = ["+", "-", " +", "pos", "neg", "−", "1", "-1", "+1", "", "x", "+\x00"]
STEPS = ["1", "100", "12000", "0", "-5", "1e3", "12.5", "12.0", "12.000", "1.234.567", "-1.000", "1_000",
         "10000000000000", "99999999999999999999", "",
         " 7 ", "inf", "nan"]
DAYS = ["2026-01-02", "d1", " d2 ", "", " ", "ä", "a,b", "x\ny",
        "2026-13-45", "2026-2-3", "2028-02-29 pm", "2026-02-29", "x" * 65, "22.11.2026", "31.02.2026", "11/22/26",
        "22-Nov-2026", "1.2.3"]

cell = st.sampled_from
measurement_row = st.tuples(
    cell(DAYS), cell(JOINTS), cell(DIRS), *(cell(NUMBERS) for _ in range(7)), cell(STEPS)
).map(list)
odd_row = st.one_of(
    st.just([]),
    st.just(["", " ", ""]),
    st.lists(cell(NUMBERS), min_size=1, max_size=13),
)
rows_strategy = st.lists(st.one_of(measurement_row, measurement_row, measurement_row, odd_row), max_size=25)


def _csv(header: list[str], rows: list[list[str]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow(r)
    return buf.getvalue()


def _outcome(parse, text: str):
    try:
        return "ok", parse(text)
    except old.TableError as e:  # the reference's own class
        return "error", e.problems
    except new.TableError as e:
        return "error", e.problems


@pytest.fixture(params=[3, new.CHUNK_ROWS], ids=["chunks of 3", "default chunks"])
def chunk(request, monkeypatch):
    monkeypatch.setattr(new.chunks, "CHUNK_ROWS", request.param)  # where the chunked reader reads it
    _, chunks = new.chunks._open_table("a,b\n" + "1,2\n" * 7)  # the patch reaches the reader: 7 rows, ceil(7/n) chunks
    assert len(list(chunks(2, 0))) == -(-7 // request.param)
    return request.param


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=rows_strategy, layout=st.sampled_from(["plain", "crlf", "blank lines"]))
def test_measurement_table_agrees_with_the_row_by_row_parser(chunk, rows, layout):
    text = _csv(list(new.HEADER), rows)
    if layout == "crlf":
        text = text.replace("\n", "\r\n")
    elif layout == "blank lines":
        text = text.replace("\n", "\n\n", 3)
    kind_old, res_old = _outcome(lambda t: old.parse_measurements(t, "m.csv"), text)
    kind_new, res_new = _outcome(lambda t: new.parse_measurements(t, "m.csv"), text)
    assert kind_new == kind_old, (res_old, res_new)
    if kind_old == "error":
        assert res_new == res_old
        return
    assert [astuple(t) for t in res_new] == [astuple(t) for t in res_old]
    for a, b in zip(res_new, res_old, strict=True):  # same types too (int steps, str day)
        assert [type(x) for x in astuple(a)] == [type(x) for x in astuple(b)]
    table = new.parse_measurement_table(text, "m.csv")
    np.testing.assert_array_equal(table.gamma, [t.gamma for t in res_old])


pose_header = st.lists(
    st.sampled_from(["joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "day", "", " note "]),
    min_size=5, max_size=12,
)
pose_row = st.lists(st.one_of(cell(NUMBERS), cell(JOINTS), cell(DIRS)), min_size=0, max_size=13)


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(header=pose_header, rows=st.lists(pose_row, max_size=20), blank=st.booleans())
def test_pose_table_agrees_with_the_row_by_row_parser(chunk, header, rows, blank):
    text = _csv(header, rows)
    if blank:  # blank lines between rows: both must still name the line in the file
        text = text.replace("\n", "\n\n", 3)
    kind_old, res_old = _outcome(lambda t: old.parse_pose_table(t, "p.csv"), text)
    kind_new, res_new = _outcome(lambda t: new.parse_pose_table(t, "p.csv"), text)
    assert kind_new == kind_old, (res_old, res_new)
    if kind_old == "error":
        assert res_new == res_old
        return
    h_old, r_old, q_old = res_old
    h_new, r_new, q_new = res_new
    assert h_new == h_old
    assert r_new == r_old
    assert [astuple(q) for q in q_new] == [astuple(q) for q in q_old]


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    rows=st.lists(
        st.tuples(
            st.sampled_from(["1", "2", "3"]),
            st.sampled_from(["+", "-", ""]),
            *(st.floats(-0.5, 0.5).map(repr) for _ in range(5)),
            st.floats(-0.3, 0.3).map(repr),
            st.floats(-0.3, 0.3).map(repr),
        ).map(list),
        min_size=1,
        max_size=30,
    )
)
def test_valid_pose_tables_parse_alike(chunk, rows):
    """Mostly valid tables (random finite values): the fast path, not only the fallback, is exercised."""
    header = ["joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end"]
    text = _csv(header, rows)
    kind_old, res_old = _outcome(lambda t: old.parse_pose_table(t, "p.csv"), text)
    kind_new, res_new = _outcome(lambda t: new.parse_pose_table(t, "p.csv"), text)
    assert kind_new == kind_old
    if kind_old == "ok":
        assert [astuple(q) for q in res_new[2]] == [astuple(q) for q in res_old[2]]
    else:
        assert res_new == res_old


def test_a_valid_table_takes_the_fast_path_with_exact_values():
    """A clean table of full-precision floats: every value as float() reads it, line numbers from 2."""
    rng = np.random.default_rng(3)
    n = 500
    q2 = rng.uniform(-3.6, 0.5, n)
    rows = [
        ["d", "3", "+", "0.0", repr(float(a)), "0.0", "-0.1", "0.2", "0.0", "0.012", str(10000 + i)]
        for i, a in enumerate(q2)
    ]
    table = new.parse_measurement_table(_csv(list(new.HEADER), rows), "m.csv")
    assert table.q2.tolist() == q2.tolist()
    assert table.lines.tolist() == list(range(2, n + 2))
    assert table.steps.tolist() == [10000 + i for i in range(n)]
    assert math.isclose(table.gamma[0], 0.012 / 10000, rel_tol=0, abs_tol=0)
    again = new.TraverseTable.from_traverses(table.traverses())
    assert again.q2.tolist() == table.q2.tolist() and again.day.tolist() == table.day.tolist()


# ----------------------------------------------------------------------------- predict, end to end


def _old_predict(text: str, cal) -> str:
    """``stickslip predict`` as it was: the row-by-row parser, one model call per row, DictWriter."""
    header, rows, queries = old.parse_pose_table(text, "p.csv")
    preds = []
    for q in queries:
        m = cal.model(q.joint, q.direction)
        if q.is_traverse:
            preds.append(float(m.average_gamma(q.start, q.end, q.q1, q.q2, q.q3, q.theta, q.psi)))
        else:
            preds.append(float(m.gamma(q.q1, q.q2, q.q3, q.theta, q.psi)))
    out_header = header + (["gamma_pred"] if "gamma_pred" not in header else [])
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=out_header, lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    w.writerows([{**row, "gamma_pred": repr(g)} for row, g in zip(rows, preds, strict=True)])
    return buf.getvalue()


@pytest.fixture(scope="module")
def paper_cal(tmp_path_factory):
    from synth import paper_table

    from stickslip.calibration import calibrate

    cal = calibrate(paper_table())
    path = tmp_path_factory.mktemp("cal") / "cal.json"
    cal.save(path)
    return cal, path


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    rows=st.lists(
        st.tuples(
            st.sampled_from(["2", "3", " 3"]),
            st.sampled_from(["+", "-", "", "pos"]),
            st.sampled_from(["0", "0.1", "-0.2"]),
            st.floats(-3.6, 0.5).map(lambda v: f"{v:.6g}"),
            st.floats(0, 0.012).map(lambda v: f"{v:.6g}"),
            st.floats(-1.5, 0.0).map(repr),
            st.sampled_from(["0", "0.3", " 0.1 "]),
            st.sampled_from([("", ""), ("0.5", "-3.5"), ("-3.5", "0.4"), ("0", "0.012"), ("0.012", "0.001")]),
            st.sampled_from(["", "note", "a,b", 'say "hi"']),
        ),
        min_size=1,
        max_size=12,
    ),
    extra=st.sampled_from([[], ["gamma_pred"], ["day"]]),
    crlf=st.booleans(),
)
def test_predict_writes_what_the_row_by_row_command_wrote(tmp_path, paper_cal, rows, extra, crlf):
    from typer.testing import CliRunner

    from stickslip.cli import app

    cal, cal_path = paper_cal
    header = ["joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "note", *extra]
    body = [[j, d, q1, q2, q3, th, ps, se[0], se[1], note, *(["x"] * len(extra))]
            for j, d, q1, q2, q3, th, ps, se, note in rows]
    text = _csv(header, body)
    if crlf:
        text = text.replace("\n", "\r\n")
    try:
        want = _old_predict(text, cal)
    except (old.TableError, KeyError, ValueError):
        return  # refused tables are covered by the parser tests
    path = tmp_path / "p.csv"
    path.write_bytes(text.encode())
    r = CliRunner().invoke(app, ["predict", "-c", str(cal_path), str(path)])
    assert r.exit_code == 0, r.output
    assert r.stdout == want  # byte for byte: the same cells, the same numbers (vectorised = scalar here)
