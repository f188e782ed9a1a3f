"""The measurement table: exact header, every bad row reported with file:line and reason."""

import math

import pytest
from synth import paper_table

from stickslip.measurements import (
    HEADER,
    TableError,
    measurements_to_csv,
    parse_measurements,
    parse_pose_table,
    read_measurements,
)

GOOD = "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n2026-11-22,3,+,0,-1.5707963,0,0,0,0,0.012,12345\n"


def test_round_trip(tmp_path):
    rows = paper_table()
    p = tmp_path / "m.csv"
    p.write_text(measurements_to_csv(rows))
    assert read_measurements(p) == rows
    assert p.read_text().splitlines()[0] == ",".join(HEADER)


def test_good_row():
    (t,) = parse_measurements(GOOD)
    assert t.joint == 3 and t.direction == "+" and t.steps == 12345
    assert t.gamma == pytest.approx(0.012 / 12345)


@pytest.mark.parametrize(
    "row, reason",
    [
        ("d,4,+,0,0,0,0,0,0,1,3", "unknown joint '4'"),
        ("d,3,up,0,0,0,0,0,0,0.01,3", "direction must be '+' or '-'"),
        ("d,3,+,0,x,0,0,0,0,0.01,3", "q2 must be a number"),
        ("d,3,+,0,nan,0,0,0,0,0.01,3", "q2 must be finite"),
        ("d,3,+,0,0,0,0,0,0,0.01,-2", "steps must be a positive integer"),
        ("d,3,+,0,0,0,0,0,0,0.01,2.5", "steps must be a positive integer"),
        ("d,3,+,0,0,0,0,0,0.01,0.001,3", "direction '+' disagrees with end - start"),
        ("d,3,-,0,0,0,0,0,0.001,0.01,3", "direction '-' disagrees"),
        ("d,3,+,0,0,0,0,0,0,0.02,3", "end = 0.02 m is outside joint 3's range"),
        ("d,3,+,0,1.0,0,0,0,0,0.01,3", "q2 = 1 rad is outside joint 2's range"),
        ("d,2,+,0,0,0.02,0,0,-1,0,3", "q3 = 0.02 m is outside joint 3's range"),
        ("d,3,+,0,0,0,4.0,0,0,0.01,3", "theta = 4 rad is outside [-pi, pi]"),
        (",3,+,0,0,0,0,0,0,0.01,3", "day is empty"),
        ("d,3,+,0,0,0,0,0,0.005,0.005,3", "start and end are equal"),
        ("d,3,+,0,0,0", "expected 11 columns, found 6"),
    ],
)
def test_bad_rows_are_reported_with_line_and_reason(row, reason):
    text = GOOD + row + "\n"
    with pytest.raises(TableError) as e:
        parse_measurements(text, "m.csv")
    assert any(p.startswith("m.csv:3: ") and reason in p for p in e.value.problems), e.value.problems


def test_every_bad_row_is_reported_not_just_the_first():
    text = GOOD + "d,4,+,0,0,0,0,0,0,1,3\n" + GOOD.splitlines()[1] + "\n" + "d,3,+,0,0,0,0,0,0,0.01,0\n"
    with pytest.raises(TableError) as e:
        parse_measurements(text, "m.csv")
    assert [p.split(":")[1] for p in e.value.problems] == ["3", "5"]


def test_header_must_be_exact():
    with pytest.raises(TableError, match=r"m.csv:1: header must be exactly .*missing steps"):
        parse_measurements("day,joint,direction,q1,q2,q3,theta,psi,start,end\n", "m.csv")
    with pytest.raises(TableError, match="columns out of order"):
        parse_measurements("joint,day,direction,q1,q2,q3,theta,psi,start,end,steps\n", "m.csv")
    with pytest.raises(TableError, match="empty"):
        parse_measurements("", "m.csv")


def test_rounded_stops_are_accepted():
    # pi/6 written to 6 decimals lies 2.4e-7 rad beyond the stop: accepted, not clipped
    (t,) = parse_measurements(GOOD.splitlines()[0] + "\nd,2,-,0,0,0,0,0,0.523599,-3.665191,83000\n")
    assert t.start == 0.523599 and math.isclose(t.end, -3.665191)


def test_pose_table():
    text = "joint,direction,q1,q2,q3,theta,psi,start,end,note\n3,+,0,0,0,0,0,,,a\n2,-,0,0,0,0,0,0.5,-3,b\n"
    header, rows, queries = parse_pose_table(text, "p.csv")
    assert header[-1] == "note" and rows[1]["note"] == "b"
    assert not queries[0].is_traverse and queries[1].is_traverse
    with pytest.raises(TableError, match="p.csv:2: give both start and end"):
        parse_pose_table("joint,direction,q1,q2,q3,theta,psi,start,end\n3,+,0,0,0,0,0,0.001,\n", "p.csv")
    with pytest.raises(TableError, match="header lacks psi"):
        parse_pose_table("joint,direction,q1,q2,q3,theta\n", "p.csv")
    # no direction column: a traverse's direction is the sign of end - start; a pose needs one
    _, _, qs = parse_pose_table("joint,q1,q2,q3,theta,psi,start,end\n2,0,0,0,0,0,0.5,-3\n3,0,0,0,0,0,0,0.01\n")
    assert [q.direction for q in qs] == ["-", "+"]
    with pytest.raises(TableError, match="p.csv:2: the step size at a pose needs a direction"):
        parse_pose_table("joint,q1,q2,q3,theta,psi\n3,0,0,0,0,0\n", "p.csv")


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_pose_table_errors_name_the_line_in_the_file_blank_lines_included(newline):
    # a user opens the file at the line the error names: blank lines must count (they did not,
    # which sent the user two lines too high here)
    text = newline.join(
        ["joint,direction,q1,q2,q3,theta,psi", "", "3,+,0,0,0.001,0,0", "", "", "3,+,0,0,abc,0,0", ""]
    )
    with pytest.raises(TableError) as e:
        parse_pose_table(text, "p.csv")
    assert e.value.problems == ["p.csv:6: q3 must be a number in SI units, got 'abc'"]
    _, rows, queries = parse_pose_table(text.replace("abc", "0.002"), "p.csv")
    assert [q.q3 for q in queries] == [0.001, 0.002] and len(rows) == 2


def test_a_table_saved_with_semicolons_or_tabs_says_so(tmp_path):
    # a European spreadsheet saves CSV with ';': the header error says what to do instead of listing every column
    from stickslip.measurements import HEADER, read_measurements

    for sep, words in ((";", "separated by ';'"), ("\t", "separated by a tab")):
        p = tmp_path / "m.csv"
        row = ["d", "3", "+", "0", "0", "0", "0", "0", "0", "0.012", "9"]
        p.write_text(sep.join(HEADER) + "\n" + sep.join(row) + "\n")
        with pytest.raises(TableError, match=words + ": save the table with commas"):
            read_measurements(p)


def test_a_table_whose_top_was_cut_says_so(tmp_path):
    """audit25: a table whose first line(s) were cut (mid-row, or at a row's end) said 'missing day, joint, ...;
    unexpected 23, 3, +, 0.0, ...'; now it says line 1 is data and the header is missing. Exit 2 on the CLI."""
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import HEADER, read_measurements

    rows = "".join(f"2026-11-23,3,+,0.0,0.0,0.0,{t},0.0,0.0,0.012,{9000 + k}\n" for k, t in enumerate((0.0, -1.5)))
    want = (f"header must be exactly {','.join(HEADER)} (line 1 is a row of numbers, not the header: the table's "
            "first line is missing (was the top of the file cut?); put the header line back)")
    p = tmp_path / "m.csv"
    for text in (rows, rows[7:]):
        p.write_text(text)
        with pytest.raises(TableError) as e:
            read_measurements(p)
        assert e.value.problems == [f"{p}:1: {want}"]
    r = CliRunner().invoke(app, ["fit", str(p)])
    assert r.exit_code == 2 and r.stderr == f"error: {p}:1: {want}\n"
    p.write_text("a,b\n1,2\n")  # other names: named as before
    with pytest.raises(TableError, match=r"\(missing day, joint, .*; unexpected a, b\)"):
        read_measurements(p)


def test_a_spreadsheets_empty_columns_at_the_end_are_named_as_such(tmp_path):
    # 'day,...,steps,,' (a spreadsheet that saved two empty columns) said '(unexpected , )'
    from stickslip.measurements import HEADER, read_measurements

    p = tmp_path / "m.csv"
    p.write_text(",".join(HEADER) + ",,\n" + "d,3,+,0,0,0,0,0,0,0.012,9,,\n")
    with pytest.raises(TableError) as e:
        read_measurements(p)
    assert e.value.problems == [f"{p}:1: header must be exactly {','.join(HEADER)} (2 columns without a name: "
                                "delete the empty columns at the end)"]
    p.write_text(",".join(HEADER) + ",note,\n" + "d,3,+,0,0,0,0,0,0,0.012,9,x,\n")
    with pytest.raises(TableError, match=r"\(unexpected note; 1 column without a name: delete the empty"):
        read_measurements(p)
