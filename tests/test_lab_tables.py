"""Tables as labs write them (audit41): Excel in another locale, LabVIEW, hand edits.

Each is read right or refused with the file, the row, the value and the reason; never read wrong.
"""

import pytest

from stickslip.measurements import (
    TableError,
    parse_measurement_table,
    parse_measurements,
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
