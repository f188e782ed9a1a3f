import math

import pytest

from stickslip.units import UnitError, format_step, parse_angle, parse_length, parse_quantity


@pytest.mark.parametrize(
    "text, value",
    [("-90deg", -math.pi / 2), ("12mm", 0.012), ("850nm", 850e-9), ("40urad", 40e-6), ("40µrad", 40e-6),
     ("0.5", 0.5), ("-pi/2", -math.pi / 2), ("pi/6", math.pi / 6), ("30 um", 30e-6), ("1e-3", 1e-3),
     ("−90deg", -math.pi / 2), ("2*pi/3", 2 * math.pi / 3)],
)
def test_parse(text, value):
    assert parse_quantity(text) == pytest.approx(value, rel=1e-15)


def test_kinds_are_enforced():
    with pytest.raises(UnitError, match="unknown angle unit 'mm'"):
        parse_angle("12mm")
    with pytest.raises(UnitError, match="unknown length unit 'deg'"):
        parse_length("3deg")
    with pytest.raises(UnitError, match="cannot read"):
        parse_length("twelve")


def test_format_step():
    assert format_step(972e-9, 3) == "972 nm"
    assert format_step(38.41e-6, 2) == "38.41 µrad"


@pytest.mark.parametrize(
    "value, kind, line",
    [
        (float("nan"), "length", "nan is not a finite length (NaN, infinite, or beyond a float)"),
        (float("-inf"), "angle", "-inf is not a finite angle (NaN, infinite, or beyond a float)"),
        ("1e400um", "length", "'1e400um' is not a finite length (NaN, infinite, or beyond a float)"),
        ("-1e400deg", "angle", "'-1e400deg' is not a finite angle (NaN, infinite, or beyond a float)"),
        ("1e999", None, "'1e999' is not a finite amount (NaN, infinite, or beyond a float)"),
    ],
)
def test_a_quantity_that_is_not_finite_is_refused(value, kind, line):
    """parse_length(float('nan')) returned nan, parse_length('1e400um') inf and parse_angle('-1e400deg') -inf
    (the text 'nan um' was refused): every front end checked after it, a script calling the API got inf."""
    with pytest.raises(UnitError) as e:
        parse_quantity(value, kind)
    assert str(e.value) == line
