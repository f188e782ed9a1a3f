"""One row of the measurement table: :class:`Traverse`, its columns, and the row-by-row checks (docs/design.md §7)."""

from __future__ import annotations

import csv
import math
import numbers
import re
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace

from .. import kinematics as kin
from ..clock import day_label_problem
from ..joints import TILT_LIMIT, coordinate_problem, tilt_problem
from ..models import direction_label
from ..records import unguard_cell
from ..units import ANGLE_UNITS, LENGTH_UNITS

HEADER = ("day", "joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps")
POSE_COLUMNS = ("q1", "q2", "q3", "theta", "psi")
_TILT_LIMIT = TILT_LIMIT


@dataclass(frozen=True)
class Traverse:
    """One measured traverse of one joint (a row of the measurement table).

    Attributes
    ----------
    day : str
        Session label (ISO date preferred).
    joint : int
        Moving joint, 1, 2 or 3.
    direction : str
        ``"+"`` (q increasing) or ``"-"``.
    q1, q2, q3 : float
        Fixed joints (rad, rad, m); the moving joint's value is ignored.
    theta, psi : float
        Base tilt, rad.
    start, end : float
        Traversed interval of the moving joint (rad or m).
    steps : int
        Steps counted, > 0.
    """

    day: str
    joint: int
    direction: str
    q1: float
    q2: float
    q3: float
    theta: float
    psi: float
    start: float
    end: float
    steps: int

    @property
    def gamma(self) -> float:
        """Average step size ``|end - start| / steps`` (m or rad): the paper's Eq. 1."""
        return abs(self.end - self.start) / self.steps

    @property
    def sign(self) -> int:
        return 1 if self.direction == "+" else -1

    def pose(self) -> dict[str, float]:
        """The fixed pose as a dict of ``q1, q2, q3, theta, psi``."""
        return {k: getattr(self, k) for k in POSE_COLUMNS}

    def as_row(self) -> dict[str, object]:
        return asdict(self)

    def with_moving(self, q: float) -> Traverse:
        """A copy whose moving joint's column holds ``q`` (handy for evaluating the model)."""
        if self.joint == 1:
            return replace(self, q1=q)
        if self.joint == 2:
            return replace(self, q2=q)
        return replace(self, q3=q)


class TableError(ValueError):
    """A measurement (or pose) table has problems; ``problems`` holds one line each.

    Each line reads ``file:line: reason`` (line 1 is the header).
    """

    def __init__(self, problems: Sequence[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


def check_pose(joint: int, values: dict[str, float], joints: Mapping[int, kin.JointSpec] | None = None) -> list[str]:
    """Range problems of a pose for a traverse of ``joint`` (empty if fine).

    The fixed joints must lie within their stops (the MM3A's, or ``joints``: an arm's own,
    :meth:`stickslip.rig.Arm.joint_specs`); ``theta`` and ``psi`` within [-pi, pi]. Values
    use the tolerance of :meth:`JointSpec.contains`.
    """
    specs = kin.JOINTS if joints is None else joints
    problems = []
    for j in (1, 2, 3):
        if j == joint or j not in specs:
            continue
        problem = specs[j].range_problem(f"q{j}", values[f"q{j}"])
        if problem:
            problems.append(problem)
    problems += [p for name in ("theta", "psi") if (p := tilt_problem(name, values[name]))]
    return problems


_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?")
"""A number written with a decimal comma (0,0021; 1,5E-05), as a spreadsheet in German or French keeps it in quotes."""


def number_problem(name: str, text: str) -> str:
    """Why a cell is not a number, said for a decimal comma (with the number written right)."""
    if _DECIMAL_COMMA.fullmatch(text.strip()):
        right = text.strip().replace(",", ".")
        return f"{name} must be a number in SI units, got {text!r} (a decimal comma: write {right})"
    return f"{name} must be a number in SI units, got {text!r}"


def _parse_float(name: str, text: str) -> tuple[float | None, str | None]:
    try:
        v = float(text)
    except ValueError:
        return None, number_problem(name, text)
    if not math.isfinite(v):
        return None, f"{name} must be finite, got {text!r}"
    return v, None


MAX_STEPS = 10**12
"""Largest step count accepted in a table (a full traverse is ~1e4..1e7 steps; SQLite holds < 2**63)."""


_GROUPED = re.compile(r"[+-]?\d{1,3}(?:\.\d{3})+|[+-]?\d{1,3}(?:,\d{3})+")
"""A count written with thousands separators (12.000, 12,000): 12 or 12 000 steps cannot be told apart."""


def _parse_steps(text: str) -> tuple[int | None, str | None]:
    t = text.strip()
    if _GROUPED.fullmatch(t):  # a German spreadsheet's 12.000 is 12 000 steps; float() read it as 12
        return None, (f"steps = {t!r} reads as a number written with a thousands separator: write the step "
                      "count as a plain integer (12000, not 12.000 or 12,000)")
    try:
        v = int(t)
    except ValueError:
        try:
            f = float(t)
        except ValueError:
            return None, f"steps must be a positive integer, got {text!r}"
        if not math.isfinite(f) or f != int(f):
            return None, f"steps must be a positive integer, got {text!r}"
        v = int(f)
    if v <= 0:
        return None, f"steps must be a positive integer, got {text!r}"
    if v > MAX_STEPS:
        return None, f"steps = {text.strip()[:30]} is more than {MAX_STEPS:.0e} steps (over any joint's full range)"
    return v, None


_NUMERIC = ("joint", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps")


def _not_data(row: dict[str, str], where: str) -> str | None:
    """The one reason for a row with text but not a number where the numbers go (a unit line, a second header)."""
    cells = [(row.get(name) or "").strip() for name in _NUMERIC]
    if not any(cells) or any(map(_is_number, cells)):
        return None
    return (f"{where}: not a data row: no number in q1 to steps (a line of units or column names, as LabVIEW or "
            "Origin write under the header, or a second header?): delete it")


def parse_row(
    row: dict[str, str], where: str, joints: Mapping[int, kin.JointSpec] | None = None
) -> tuple[Traverse | None, list[str]]:
    """Validate one CSV row (a dict of strings). Returns the traverse or the problems.

    ``joints``: the arm's own joints (their numbers, kinds and ranges) where the table is
    not the MM3A's, e.g. a rig file's stage (:meth:`stickslip.rig.Arm.joint_specs`).
    """
    if (not_data := _not_data(row, where)) is not None:
        return None, [not_data]
    problems: list[str] = []
    day = unguard_cell(row.get("day") or "").strip()  # a label written guarded against formulas
    if not day:
        problems.append(f"{where}: day is empty (use a session label, e.g. an ISO date)")
    elif (why := day_label_problem(day)) is not None:
        problems.append(f"{where}: day: {why}")
    jtext = (row.get("joint") or "").strip()
    joint: int | None
    try:
        joint = int(jtext)
        if joints is None:
            kin.joint_spec(joint)
        elif joint not in joints:
            raise ValueError(joint)
    except ValueError:
        have = "1, 2 and 3" if joints is None else ", ".join(map(str, sorted(joints)))
        problems.append(f"{where}: unknown joint {jtext!r} (joints are {have})")
        joint = None
    dtext = (row.get("direction") or "").strip()
    try:
        direction = direction_label(dtext)
    except ValueError:
        problems.append(f"{where}: direction must be '+' or '-', got {dtext!r}")
        direction = None
    nums: dict[str, float] = {}
    for name in ("q1", "q2", "q3", "theta", "psi", "start", "end"):
        v, err = _parse_float(name, (row.get(name) or "").strip())
        if err:
            problems.append(f"{where}: {err}")
        else:
            nums[name] = v  # type: ignore[assignment]  # no error: _parse_float gave a float
    steps, err = _parse_steps(row.get("steps") or "")
    if err:
        problems.append(f"{where}: {err}")
    if problems or joint is None or direction is None or steps is None:
        return None, problems
    start, end = nums["start"], nums["end"]
    if end == start:
        problems.append(f"{where}: start and end are equal ({start:.6g}): a traverse must move")
    elif (end > start) != (direction == "+"):
        problems.append(
            f"{where}: direction {direction!r} disagrees with end - start = {end - start:.6g} ('+' means end > start)"
        )
    for name in ("start", "end"):
        problem = (kin.JOINTS if joints is None else joints)[joint].range_problem(name, nums[name])
        if problem:
            problems.append(f"{where}: {problem}")
    problems += [f"{where}: {p}" for p in check_pose(joint, nums, joints)]
    if own := coordinate_problem(f"q{joint}", joint, nums[f"q{joint}"]):  # the moving joint's: ignored, but the
        problems.append(f"{where}: {own}")  # store refuses it (no arm's): a row read here was refused unnamed there
    if problems:
        return None, problems
    return Traverse(
        day, joint, direction, nums["q1"], nums["q2"], nums["q3"], nums["theta"], nums["psi"], start, end, steps
    ), []



def _csv_problem(source: str, e: csv.Error) -> str:
    text = str(e)
    if "field limit" in text:
        text = f"a cell is longer than {csv.field_size_limit()} characters"
    elif "new-line character seen in unquoted field" in text:  # Python's advice is for a programmer
        text = "a line ends in a bare carriage return (CR, an old Mac export): save the table with LF or CRLF ends"
    return f"{source}: not a readable CSV table ({text})"



def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def separator_problem(header: Sequence[str]) -> str | None:
    """What to do about a header record that is one cell holding ';' or tabs (a table not separated by commas)."""
    if len(header) != 1 or not any(sep in header[0] for sep in ";\t"):
        return None
    if ";" in header[0]:  # a spreadsheet in a language with decimal commas (German, French, Dutch) writes ';'
        return "the columns are separated by ';': save the table with commas between columns and '.' before decimals"
    return "the columns are separated by a tab: save the table with commas (CSV)"


def is_history_header(header: Sequence[str]) -> bool:
    """Whether a table's first record (as ``csv`` splits it) is a history file's first line (``export --json``)."""
    return bool(header) and header[0].strip().startswith("{") and "stickslip-history" in ",".join(header)


_JOINTS = "rad or m, the joint's unit"
_SI_COLUMN = {"q1": "rad", "q2": "rad", "theta": "rad", "psi": "rad", "q3": "m", "start": _JOINTS, "end": _JOINTS,
              "gamma": _JOINTS, "sigma": _JOINTS}
_UNIT_NAMED = re.compile(r"(?P<col>[A-Za-z0-9]+)\s*(?:[_ ]\s*|\[\s*|\(\s*)(?P<unit>[^\s\])]+)\s*[\])]?")
_UNIT_WORDS = {"degrees", "degree", "microns", "micron"}
_SI_WORDS = {"radians", "radian", "metres", "meters", "metre", "meter"}


def unit_column_problem(names: Sequence[str], expected: Sequence[str]) -> str | None:
    """What the columns of ``names`` named with their unit (``q2_deg``, ``q2 [deg]``, ``start_um``) should be.

    A table's columns are SI and carry no unit in their names: a column named with another
    unit is in it more often than not, so the message says to convert it, not only to rename
    it; one named with its SI unit (``gamma [m]``) is told its name. ``None`` when no name is
    a column of ``expected`` with a unit.
    """
    named: dict[str, list[str]] = {}  # SI unit -> columns in another unit
    renamed: list[str] = []  # columns named with their SI unit: the values may be right, the name is not
    shown = []
    for name in names:
        m = _UNIT_NAMED.fullmatch(name.strip())
        if m is None or m.group("col") not in expected or m.group("col") not in _SI_COLUMN:
            continue
        unit, col = m.group("unit"), m.group("col")
        if unit in ("m", "rad") or unit.lower() in _SI_WORDS:
            renamed.append(col)
        elif unit in LENGTH_UNITS or unit in ANGLE_UNITS or unit.lower() in _UNIT_WORDS:
            named.setdefault(_SI_COLUMN[col], []).append(col)
        else:
            continue
        shown.append(name.strip())
    if not shown:
        return None
    what = [f"write {', '.join(cols)} in {si}" for si, cols in named.items()]
    what += [f"call it {', '.join(renamed)}"] if renamed else []
    verb = "names" if len(shown) == 1 else "name"
    return f"{', '.join(shown)} {verb} a unit: the columns are SI and named without one ({'; '.join(what)})"


def check_header(header: list[str] | None, source: str, expected: Sequence[str]) -> None:
    """Raise :class:`TableError` unless ``header`` (a table's first record) is exactly ``expected``, saying why."""
    if header is None:
        raise TableError([f"{source}:1: the file is empty (expected the header {','.join(expected)})"])
    header = [h.strip() for h in header]
    if tuple(header) == tuple(expected):
        return
    if is_history_header(header):
        raise TableError([f"{source}:1: a stickslip history file (export --json), not a table: import it "
                          f"(stickslip import {source} -d URL) and read the store (--db, no table), or write a "
                          "table (stickslip export -o TABLE.csv)"])
    missing = [h for h in expected if h not in header]
    extra = [h for h in header if h not in expected]
    detail = []
    if missing:
        detail.append("missing " + ", ".join(missing))
    if [h for h in extra if h]:
        detail.append("unexpected " + ", ".join(h for h in extra if h))
    if header and header[0] == "" and tuple(header[1:]) == tuple(expected):  # pandas' to_csv writes its index, unnamed
        detail = ["the first column has no name: a row index (pandas: to_csv(..., index=False)); delete it"]
    elif "" in extra:  # a spreadsheet's trailing commas: 'unexpected , ' said nothing
        n = extra.count("")
        detail.append(f"{n} column{'s' if n > 1 else ''} without a name: delete the empty columns at the end")
    if not detail:
        detail.append("columns out of order")
    if (named := unit_column_problem(extra, expected)) is not None:
        detail.append(named)
    if not set(header) & set(expected) and sum(_is_number(h) for h in header) >= 3:  # a table whose top was cut
        detail = ["line 1 is a row of numbers, not the header: the table's first line is missing (was the top "
                  "of the file cut?); put the header line back"]
    if (sep := separator_problem(header)) is not None:
        detail = [sep]
    if not any(header):  # a blank first line (a spreadsheet's title row left empty)
        detail = ["line 1 is empty: the header must be the first line"]
    raise TableError([f"{source}:1: header must be exactly {','.join(expected)} ({'; '.join(detail)})"])


def traverse_problems(t: Traverse) -> list[str]:
    """Why ``t`` could not be a row of a measurement table, whatever the arm (empty if it can).

    What :func:`parse_row` refuses that does not depend on the arm's joint ranges: the
    session label, a joint other than 1, 2, 3, a direction other than ``"+"``/``"-"``, a
    number that is not finite, a step count that is not a whole number in 1 ..
    :data:`MAX_STEPS`, a traverse that does not move or moves against its direction,
    a position no arm's joint takes (:func:`~stickslip.joints.coordinate_problem`: beyond a full
    turn, or a metre for joint 3: degrees, or mm as m), a base tilt outside [-pi, pi]. The store
    refuses such a traverse, so that every stored one is exported as a table that imports again.
    """
    why = day_label_problem(str(t.day))
    return ([f"day: {why}"] if why is not None else []) + _value_problems(t)


def check_traverses(traverses: Sequence[Traverse], limit: int = 20) -> None:
    """Raise :class:`TableError` naming each traverse (by its index) that :func:`traverse_problems` refuses.

    What a calibration checks before it fits (a tilt or ``q2`` in degrees, steps 0, a nan): rows built in
    Python, not read from a table, were fitted as they were. The session label is checked once
    per label, without the spreadsheet-date rule (a label stored before it is still fitted);
    at most ``limit`` lines.
    """
    problems: list[str] = []
    labels: dict[object, str | None] = {}
    for i, t in enumerate(traverses):
        if t.day not in labels:
            labels[t.day] = day_label_problem(str(t.day), spreadsheet_dates=False)
        why = labels[t.day]
        for p in ([f"day: {why}"] if why is not None else []) + _value_problems(t):
            problems.append(f"traverse {i}: {p}")
        if len(problems) >= limit:
            break
    if problems:
        raise TableError(problems[:limit])


def _value_problems(t: Traverse) -> list[str]:
    """:func:`traverse_problems` but the session label's (checked once per label where a table is written)."""
    problems = []
    if type(t.joint) is not int and (isinstance(t.joint, bool) or not isinstance(t.joint, numbers.Integral)) or (
        t.joint not in (1, 2, 3)
    ):
        problems.append(f"joint must be 1, 2 or 3, got {t.joint!r}")
    if t.direction not in ("+", "-") or not isinstance(t.direction, str):
        problems.append(f"direction must be '+' or '-', got {t.direction!r}")
    nums = {name: getattr(t, name) for name in ("q1", "q2", "q3", "theta", "psi", "start", "end")}
    bad = [k for k, v in nums.items() if not _finite_real(v)]
    problems += [f"{k} must be a finite number in SI units, got {nums[k]!r}" for k in bad]
    steps = t.steps
    if not _finite_real(steps) or not float(steps).is_integer() or not 0 < steps <= MAX_STEPS:
        problems.append(f"steps must be a whole number in 1 .. {MAX_STEPS:.0e}, got {steps!r}")
    if bad:
        return problems
    start, end = float(t.start), float(t.end)
    if end == start:
        problems.append(f"start and end are equal ({start:.6g}): a traverse must move")
    elif (end > start) != (t.direction == "+") and t.direction in ("+", "-"):
        problems.append(
            f"direction {t.direction!r} disagrees with end - start = {end - start:.6g} ('+' means end > start)"
        )
    if t.joint in (1, 2, 3):  # no arm's position (arm-independent: an arm's stops are the table reader's)
        at = {"q1": 1, "q2": 2, "q3": 3, "start": t.joint, "end": t.joint}
        problems += [p for name, j in at.items() if (p := coordinate_problem(name, j, float(nums[name])))]
    problems += [p for name in ("theta", "psi") if (p := tilt_problem(name, float(nums[name])))]
    return problems


def _finite_real(v: object) -> bool:
    """A finite real number (a Python or numpy int or float; not a bool, not text)."""
    try:  # an int too large for a float (10**400) is none: math.isfinite raised OverflowError, a traceback
        if type(v) is float or type(v) is int:  # the common case without the ABC's isinstance (0.7 µs a call)
            return math.isfinite(v)
        return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)
    except OverflowError:
        return False
