"""Units at the human-facing edges.

Everything inside stickslip is SI (metres, radians, seconds, hertz). This module
parses quantities people type (``-90deg``, ``12mm``, ``850nm``, ``40urad``) into SI
floats and formats SI floats for people (``972.0 nm``, ``38.41 µrad``).
"""

from __future__ import annotations

import math
import re

from .joints import JointSpec, joint_spec

__all__ = [
    "parse_typed",
    "LENGTH_UNITS",
    "ANGLE_UNITS",
    "UnitError",
    "parse_quantity",
    "parse_angle",
    "parse_length",
    "format_step",
    "format_position",
    "step_scale",
    "param_scale",
    "DIMENSIONLESS_PARAMETERS",
    "position_scale",
    "step_display_unit",
    "position_display_unit",
    "format_quantity",
    "format_spread",
    "bare_number_problem",
    "khz_slip",
]

LENGTH_UNITS: dict[str, float] = {
    "m": 1.0,
    "mm": 1e-3,
    "um": 1e-6,
    "µm": 1e-6,
    "μm": 1e-6,
    "nm": 1e-9,
    "pm": 1e-12,
}
ANGLE_UNITS: dict[str, float] = {
    "rad": 1.0,
    "mrad": 1e-3,
    "urad": 1e-6,
    "µrad": 1e-6,
    "μrad": 1e-6,
    "nrad": 1e-9,
    "deg": math.pi / 180.0,
    "°": math.pi / 180.0,
}

_NUMBER = r"[-+−]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_PI = r"(?:(?P<pimul>" + _NUMBER + r")?\*?pi(?:/(?P<pidiv>\d+(?:\.\d*)?))?)"
_QUANTITY = re.compile(r"^\s*(?:(?P<num>" + _NUMBER + r")|(?P<sign>[-+−])?" + _PI + r")\s*(?P<unit>[^\d\s]*)\s*$")


class UnitError(ValueError):
    """A quantity could not be read, or has the wrong kind of unit."""


def parse_quantity(text: str | float, kind: str | None = None) -> float:
    """Parse a number with an optional unit suffix into SI.

    Parameters
    ----------
    text : str or float
        ``"12mm"``, ``"-90deg"``, ``"850 nm"``, ``"40urad"``, ``"-pi/2"``,
        ``"0.5"`` (a bare number is already SI), or a float.
    kind : {"length", "angle", None}
        Which units are allowed. ``None`` accepts either.

    Returns
    -------
    float
        The value in metres (length) or radians (angle).

    Raises
    ------
    UnitError
        If the text is not a number with a known unit of the right kind, or the value is
        not finite (NaN, infinite, or beyond a float: ``"1e400um"``).
    """
    value = _read_quantity(text, kind)
    if not math.isfinite(value):  # nan, inf, or digits beyond a float ('1e400um'): no position or step is that
        raise UnitError(f"{text!r} is not a finite {kind or 'amount'} (NaN, infinite, or beyond a float)")
    return value


def _read_quantity(text: str | float, kind: str | None) -> float:
    if isinstance(text, (int, float)):
        try:
            return float(text)
        except OverflowError:  # an integer beyond a float (a TOML file's 400 digits): not finite, refused as such
            return math.inf
    m = _QUANTITY.match(str(text).replace("−", "-"))
    if not m:
        raise UnitError(f"cannot read {text!r} as a number with an optional unit")
    if m.group("num") is not None:
        value = float(m.group("num"))
    else:
        mul = m.group("pimul")
        value = (float(mul) if mul not in (None, "", "+", "-") else 1.0) * math.pi
        if mul == "-" or m.group("sign") == "-":
            value = -value
        if m.group("pidiv"):
            divisor = float(m.group("pidiv"))
            if divisor == 0:
                raise UnitError(f"{str(text).strip()!r} divides by zero")
            value /= divisor
    unit = m.group("unit")
    if not unit:
        return value
    table: dict[str, float] = {}
    if kind in (None, "length"):
        table.update(LENGTH_UNITS)
    if kind in (None, "angle"):
        table.update(ANGLE_UNITS)
    if unit not in table:
        allowed = ", ".join(sorted({k for k in table if k.isascii()}))
        what = f"{kind} " if kind else ""
        raise UnitError(f"unknown {what}unit {unit!r} in {text!r} (use one of: {allowed})")
    return value * table[unit]


def parse_angle(text: str | float) -> float:
    """Parse an angle (``-90deg``, ``40urad``, ``-pi/2``, bare radians) to radians."""
    return parse_quantity(text, "angle")


def parse_length(text: str | float) -> float:
    """Parse a length (``12mm``, ``850nm``, bare metres) to metres."""
    return parse_quantity(text, "length")


def format_quantity(value: float, unit: str, digits: int = 4) -> str:
    """Format an SI value in the given display unit, e.g. ``format_quantity(9.7e-7, "nm")``."""
    table = {**LENGTH_UNITS, **ANGLE_UNITS}
    if unit not in table:
        raise UnitError(f"unknown unit {unit!r}")
    return f"{value / table[unit]:.{digits}g} {unit}"


def step_scale(joint: int | JointSpec) -> tuple[float, str]:
    """``(factor, unit)`` to show a step size of ``joint``: SI value × factor is in ``unit``.

    nm for the prismatic joint, µrad for rotary ones (the paper's units).

    >>> step_scale(3), step_scale(2)
    ((1000000000.0, 'nm'), (1000000.0, 'µrad'))
    """
    return (1e6, "µrad") if joint_spec(joint).rotary else (1e9, "nm")


DIMENSIONLESS_PARAMETERS = frozenset({"b", "b2", "k"})
"""Model parameters without a unit: ``b`` of Eq. (2) and the ratios of the model families beyond it."""


def param_scale(name: str, joint: int | JointSpec) -> tuple[float, str]:
    """``(factor, unit)`` to show calibration parameter ``name`` of ``joint``.

    Dimensionless parameters (``b`` of Eq. (2), :data:`DIMENSIONLESS_PARAMETERS`) are shown
    as they are (unit ``""``); every other parameter is a step size or a step-size slope
    and shown like :func:`step_scale`.
    """
    return (1.0, "") if name in DIMENSIONLESS_PARAMETERS else step_scale(joint)


def position_scale(joint: int | JointSpec) -> tuple[float, str]:
    """``(factor, unit)`` to show a position of ``joint``: µm for the prismatic, degrees for rotary.

    ``joint`` is a joint number of the MM3A (:data:`stickslip.joints.JOINTS`) or an arm's
    own :class:`~stickslip.joints.JointSpec` (a rig file's stage: µm for each of its joints);
    so for every function here.
    """
    return (180.0 / math.pi, "deg") if joint_spec(joint).rotary else (1e6, "µm")


def step_display_unit(joint: int | JointSpec) -> str:
    """The unit people read step sizes of ``joint`` in: nm for the prismatic, µrad for rotary."""
    return step_scale(joint)[1]


def position_display_unit(joint: int | JointSpec) -> str:
    """The unit people read positions of ``joint`` in: µm for the prismatic, degrees for rotary."""
    return position_scale(joint)[1]


def format_step(value: float, joint: int | JointSpec, digits: int = 4) -> str:
    """Format a step size for ``joint`` (nm for the prismatic joint, µrad for rotary ones)."""
    return format_quantity(value, step_display_unit(joint), digits)


def format_position(value: float, joint: int | JointSpec, digits: int = 6) -> str:
    """Format a joint position (µm for the prismatic joint, degrees for rotary ones)."""
    return format_quantity(value, position_display_unit(joint), digits)


def format_spread(sd: float, joint: int | JointSpec) -> str:
    """A position's spread (a standard deviation, an interval's half-width) of ``joint`` for a person.

    µm for the prismatic joint; µrad for the rotary joints, in degrees from 1 mrad
    (``1.37e+05 µrad`` would tell nobody it is 7.85 deg).
    """
    if not joint_spec(joint).rotary:
        return f"{sd * 1e6:.3g} µm"
    return f"{sd * 1e6:.3g} µrad" if abs(sd) < 1e-3 else f"{math.degrees(sd):.3g} deg"


def parse_typed(text: str, kind: str) -> float:
    """A length (m) or angle (rad), ``kind``, as a person types it: :func:`parse_length` / :func:`parse_angle`, and a
    bare number other than 0 refused with :func:`bare_number_problem`'s did-you-mean (:class:`UnitError`)."""
    bare = bare_number_problem(text, kind)
    if bare is not None:
        raise UnitError(bare)
    return parse_angle(text) if kind == "angle" else parse_length(text)


_SUGGEST = {"angle": ("deg",), "length": ("um", "mm")}


def bare_number_problem(text: str, kind: str, span: float | None = None) -> str | None:
    """Why ``text`` cannot be an amount typed on the command line: a number without its unit.

    On the command line every length and angle carries its unit (``30um``, ``2deg``,
    ``-pi/2`` is radians): a bare ``30`` could be 30 m or 30 µm, a bare ``1`` 1 rad
    (57 deg) or 1 deg. Zero needs none. Returns ``None`` for anything else (a unit given,
    zero, or not a number at all: the parser says what is wrong with that), else a
    message with a did-you-mean: degrees for an angle; µm and mm for a length, only
    those within ``span`` (m; the joint's range) when given.

    >>> bare_number_problem("-60", "angle")
    '-60 has no unit: did you mean -60deg? (an angle takes deg, rad, mrad or urad)'
    >>> bare_number_problem("30", "length", span=0.012)
    '30 has no unit: did you mean 30um? (a length takes m, mm, um or nm)'
    """
    t = str(text).strip().replace("−", "-")
    try:
        value = float(t)
    except ValueError:
        return None
    if value == 0.0 or not math.isfinite(value):
        return None
    table = ANGLE_UNITS if kind == "angle" else LENGTH_UNITS
    options = [u for u in _SUGGEST[kind] if span is None or abs(value) * table[u] <= span + 1e-15]
    if not options:  # beyond the range in every unit: the smallest is the likeliest meant
        options = [_SUGGEST[kind][0]]
    mean = " or ".join(f"{t}{u}" for u in options)
    takes = "an angle takes deg, rad, mrad or urad" if kind == "angle" else "a length takes m, mm, um or nm"
    return f"{t} has no unit: did you mean {mean}? ({takes})"


def khz_slip(hz: float, lo: float, hi: float) -> str:
    """`` (in kHz? 48 kHz is 48000 Hz: rates are in Hz)`` for a rate outside ``[lo, hi]`` Hz that is inside it
    read in kHz (a sound card's 48 for 48 kHz), else ``""``.

    >>> khz_slip(48, 1000, 1e6)
    ' (in kHz? 48 kHz is 48000 Hz: rates are in Hz)'
    """
    if not math.isfinite(hz) or lo <= hz <= hi or not lo <= hz * 1e3 <= hi:
        return ""
    return f" (in kHz? {hz:g} kHz is {hz * 1e3:g} Hz: rates are in Hz)"
