"""Tables as labs write them (audit41): Excel in another locale, LabVIEW, hand edits.

Each is read right or refused with the file, the row, the value and the reason; never read wrong.
"""

import pytest

from stickslip.measurements import (
    TableError,
    parse_measurement_table,
    parse_measurements,
    parse_pose_table,
    read_measurements,
    read_pose_table,
    read_step_sizes,
    stream_measurement_table,
    stream_pose_table,
)

HEAD = "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n"
ROW = "2026-11-22,3,+,0,-1.5707963,0,0,0,0,0.012,{}\n"


@pytest.mark.parametrize("cell", ["12.000", "1.234", "12.000.000", "12,000"])
def test_step_count_with_thousands_separator_is_refused(cell):
    # '12.000' is 12 000 steps in a German spreadsheet: before, it was read as 12 steps (a step 1000 times too big)
    text = HEAD + ROW.format(12345) + ROW.format(f'"{cell}"')
    for parse in (parse_measurements, lambda t, s: parse_measurement_table(t, s).traverses()):
        with pytest.raises(TableError) as e:
            parse(text, "m.csv")
        assert e.value.problems == [
            f"m.csv:3: steps = '{cell}' reads as a number written with a thousands separator: "
            "write the step count as a plain integer (12000, not 12.000 or 12,000)"
        ]


@pytest.mark.parametrize("cell, steps", [("12000", 12000), ("12000.0", 12000), ("1.2e4", 12000), ("1.2E+04", 12000)])
def test_step_counts_written_as_floats_are_read(cell, steps):
    (t,) = parse_measurements(HEAD + ROW.format(cell), "m.csv")
    assert t.steps == steps


STEP_HEAD = "day,joint,direction,q1,q2,q3,theta,psi,gamma,sigma,steps,method"
STEP_ROW = "2026-11-22,3,+,0.0,0.0,0.004,0.0,0.0,1e-06,5e-08,200,camera"
SEMI = "the columns are separated by ';': save the table with commas between columns and '.' before decimals"


def _step_header_problem(tmp_path, text):
    p = tmp_path / "st.csv"
    p.write_text(text)
    with pytest.raises(TableError) as e:
        read_step_sizes(p)
    (problem,) = e.value.problems
    return problem.removeprefix(f"{p}:1: header must be exactly {STEP_HEAD} ")


def test_step_size_header_refusals_say_why(tmp_path):
    # before, each of these said only 'header must be exactly day,joint,...,method'
    semi = STEP_HEAD.replace(",", ";") + "\n" + STEP_ROW.replace(",", ";").replace(".", ",") + "\n"
    assert _step_header_problem(tmp_path, semi) == f"({SEMI})"
    tab = STEP_HEAD.replace(",", "\t") + "\n" + STEP_ROW.replace(",", "\t") + "\n"
    assert _step_header_problem(tmp_path, tab).startswith("(the columns are separated by a tab: save the table")
    index = "," + STEP_HEAD + "\n0," + STEP_ROW + "\n"
    assert _step_header_problem(tmp_path, index) == (
        "(the first column has no name: a row index (pandas: to_csv(..., index=False)); delete it)"
    )
    trailing = STEP_HEAD + ",,\n" + STEP_ROW + ",,\n"
    assert _step_header_problem(tmp_path, trailing) == (
        "(2 columns without a name: delete the empty columns at the end)"
    )
    renamed = STEP_HEAD.replace("gamma", "gamma [m]") + "\n" + STEP_ROW + "\n"
    assert _step_header_problem(tmp_path, renamed) == (  # (units58: a column named with its unit is told so)
        "(missing gamma; unexpected gamma [m]; gamma [m] names a unit: the columns are SI and named without one "
        "(call it gamma))"
    )


def test_measurement_header_names_a_pandas_index_column():
    text = ",day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n0," + ROW.format(12000)
    with pytest.raises(TableError) as e:
        parse_measurements(text, "m.csv")
    assert e.value.problems == [
        f"m.csv:1: header must be exactly {HEAD.strip()} "
        "(the first column has no name: a row index (pandas: to_csv(..., index=False)); delete it)"
    ]


@pytest.mark.parametrize("sep, words", [(";", SEMI), ("\t", "the columns are separated by a tab: save the table")])
def test_a_pose_table_saved_with_semicolons_or_tabs_says_so(sep, words):
    # before: 'header lacks joint, q1, q2, q3, theta, psi', of a header that holds every one of them
    text = sep.join(["joint", "direction", "q1", "q2", "q3", "theta", "psi"]) + "\n" + sep.join("3+00000") + "\n"
    with pytest.raises(TableError) as e:
        parse_pose_table(text, "p.csv")
    (problem,) = e.value.problems
    assert problem.startswith(f"p.csv:1: {words}"), problem


def test_a_blank_first_line_is_named():
    # before: 'missing day, joint, direction, ... steps', every column, of a table whose header is on line 2
    with pytest.raises(TableError) as e:
        parse_measurements("\n" + HEAD + ROW.format(12000), "m.csv")
    assert e.value.problems == [
        f"m.csv:1: header must be exactly {HEAD.strip()} (line 1 is empty: the header must be the first line)"
    ]


EXCEL_CSV = "save it as UTF-8 (a spreadsheet's 'CSV UTF-8'; its plain 'CSV' is Windows-1252)"


def test_a_windows_1252_table_says_how_to_save_it(tmp_path):
    # Excel's plain 'CSV' writes the µ of a unit in Windows-1252 (byte 0xb5); before: 'not UTF-8 text (byte 59)'
    p = tmp_path / "p.csv"
    p.write_bytes("joint,direction,q1,q2,q3,theta,psi,dq (µm)\n3,+,0,0,0,0,0,1\n".encode("cp1252"))
    for read in (read_pose_table, lambda q: stream_pose_table(q)[0]):
        with pytest.raises(TableError) as e:
            read(p)
        (problem,) = e.value.problems
        assert problem.startswith(f"{p}: not UTF-8 text (") and problem.endswith(f"): {EXCEL_CSV}"), problem


def test_a_utf16_table_is_named_when_streamed(tmp_path):
    # the whole-file reader said 'UTF-16 text'; the streaming one (import, predict): 'not UTF-8 text (line 1, ...)'
    p = tmp_path / "m.csv"
    p.write_bytes(("\ufeff" + HEAD + ROW.format(12000)).encode("utf-16-le"))
    for read in (read_measurements, lambda q: list(stream_measurement_table(q))):
        with pytest.raises(TableError) as e:
            read(p)
        assert e.value.problems[0].startswith(f"{p}: UTF-16 text, not UTF-8: save it as UTF-8"), e.value.problems


@pytest.mark.parametrize(
    "day, fix",
    [
        ("22.11.2026", "write it as 2026-11-22"),
        ("22-Nov-2026", "write it as 2026-11-22"),  # MATLAB's datetime in writetable
        ("11/22/2026", "write the date as YYYY-MM-DD"),  # US or UK order: not guessed
        ("22/11/2026 pm", "write the date as YYYY-MM-DD"),
        ("22.11.26", "write the date as YYYY-MM-DD"),
    ],
)
def test_a_day_a_spreadsheet_reformatted_is_refused(day, fix):
    # before: read as a free label, so the table's 'latest day' was 30.10.2026 over 22.11.2026 (sorted by number)
    # and a calibration of it never warned it was old (no date)
    with pytest.raises(TableError) as e:
        parse_measurements(HEAD + ROW.format(12000).replace("2026-11-22", day), "m.csv")
    assert e.value.problems == [
        f"m.csv:2: day: the session label {day!r} is a date as a spreadsheet writes it: {fix} (YYYY-MM-DD), so that "
        "it has an age and sorts with its session"
    ]


@pytest.mark.parametrize("day", ["2026-11-22", "day1", "run 3.1", "11/22", "1.2.3 test", "22-Novel-2026"])
def test_labels_that_are_not_dates_are_kept(day):
    (t,) = parse_measurements(HEAD + ROW.format(12000).replace("2026-11-22", day), "m.csv")
    assert t.day == day


def test_a_calibration_made_before_with_a_spreadsheet_date_still_loads(tmp_path):
    from synth import paper_table

    from stickslip.calibration import calibrate
    from stickslip.calibration.result import Calibration

    cal = calibrate(paper_table())
    data = cal.to_dict()
    data["day"] = "22.11.2026"  # what a table of such labels gave before they were refused
    assert Calibration.from_dict(data).day == "22.11.2026"


def test_a_quoted_decimal_comma_says_so():
    # a spreadsheet that writes commas between columns but keeps decimal commas quotes them: "0,012"
    text = HEAD + '2026-11-22,3,+,0,"-1,5707963",0,0,0,0,0.012,12000\n'
    with pytest.raises(TableError) as e:
        parse_measurements(text, "m.csv")
    assert e.value.problems == ["m.csv:2: q2 must be a number in SI units, got '-1,5707963' (a decimal comma: "
                                "write -1.5707963)"]
    with pytest.raises(TableError) as e:
        parse_pose_table('joint,direction,q1,q2,q3,theta,psi\n3,+,0,"0,3",0,0,0\n', "p.csv")
    assert e.value.problems == ["p.csv:2: q2 must be a number in SI units, got '0,3' (a decimal comma: write 0.3)"]


@pytest.mark.parametrize("cell, steps", [("200", 200), ("200.0", 200), ("2e2", 200)])
def test_step_sizes_read_step_counts_as_the_measurement_table_does(tmp_path, cell, steps):
    # pandas writes an integer column that had an empty cell as floats (200.0); before, the step-size table refused
    # 200.0 and 2e2 that the measurement table reads
    p = tmp_path / "st.csv"
    p.write_text(STEP_HEAD + "\n" + STEP_ROW.replace(",200,", f",{cell},") + "\n")
    (s,) = read_step_sizes(p)
    assert s.steps == steps


def test_step_sizes_refuse_a_step_count_with_a_thousands_separator(tmp_path):
    p = tmp_path / "st.csv"
    p.write_text(STEP_HEAD + "\n" + STEP_ROW.replace(",200,", ",1.200,") + "\n")
    with pytest.raises(TableError) as e:
        read_step_sizes(p)
    assert e.value.problems == [f"{p}:2: steps = '1.200' reads as a number written with a thousands separator: "
                                "write the step count as a plain integer (12000, not 12.000 or 12,000)"]


@pytest.mark.parametrize(
    "line",
    [
        ",,,rad,rad,m,rad,rad,m|rad,m|rad,",  # a unit line under the header (LabVIEW, Origin)
        "Day,Joint,Direction,Q1,Q2,Q3,Theta,Psi,Start,End,Steps",  # Origin's long names
        HEAD.strip(),  # two tables concatenated: the second's header
    ],
)
def test_a_line_of_units_or_names_under_the_header_is_one_reason(line):
    # before: eleven reasons for the one line (day is empty, unknown joint '', q1 must be a number, ...)
    with pytest.raises(TableError) as e:
        parse_measurements(HEAD + line + "\n" + ROW.format(12000), "m.csv")
    assert e.value.problems == [
        "m.csv:2: not a data row: no number in q1 to steps (a line of units or column names, as LabVIEW or Origin "
        "write under the header, or a second header?): delete it"
    ]


def test_a_pose_row_one_cell_short_is_refused_not_read_shifted(tmp_path):
    # header ...,psi,gamma_cam and the row 3,+,0,0.002,0,0,1e-8 (q1 lost): it was padded with an empty last cell
    # and predicted at q2 = 0.002, q3 = 0, theta = 0, psi = 1e-8, a pose read wrong without a word (audit41's Q1)
    from stickslip.measurements import TableError
    from stickslip.procedures.predict import check_pose_file

    poses = tmp_path / "poses.csv"
    poses.write_text("joint,direction,q1,q2,q3,theta,psi,gamma_cam\n3,+,0,-1.5,0.002,0,0,1e-8\n3,+,0,0.002,0,0,1e-8\n")
    with pytest.raises(TableError) as e:
        check_pose_file(poses)
    assert str(e.value).count("\n") == 0 and f"{poses}:3: 7 cells, the header has 8 columns" in str(e.value)
    poses.write_text("joint,direction,q1,q2,q3,theta,psi,gamma_cam\n3,+,0,-1.5,0.002,0,0,\n")  # the empty cell written
    assert check_pose_file(poses) == 1
