"""The measurement-table parser as it was before it was vectorised (row by row), kept as the reference the
columnar parser must agree with exactly: the same rows, values, line numbers and messages."""

from __future__ import annotations

import csv
import datetime
import io
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from stickslip import kinematics as kin
from stickslip.joints import coordinate_problem
from stickslip.models import direction_label
from stickslip.records import MAX_TABLE_BYTES, atomic_write_text, read_text_bounded

__all__ = [
    "HEADER",
    "POSE_COLUMNS",
    "Traverse",
    "TableError",
    "read_measurements",
    "parse_measurements",
    "write_measurements",
    "measurements_to_csv",
    "check_pose",
]

HEADER = ("day", "joint", "direction", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps")
POSE_COLUMNS = ("q1", "q2", "q3", "theta", "psi")
_TILT_LIMIT = math.pi + 1e-6


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
        """Average step size ``|end - start| / steps`` (m or rad)."""
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
        changes: dict[str, Any] = {f"q{self.joint}": q}
        return replace(self, **changes)


class TableError(ValueError):
    """A measurement (or pose) table has problems; ``problems`` holds one line each.

    Each line reads ``file:line: reason`` (line 1 is the header).
    """

    def __init__(self, problems: Sequence[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


def check_pose(joint: int, values: dict[str, float]) -> list[str]:
    """Range problems of a pose for a traverse of ``joint`` (empty if fine).

    The fixed joints must lie within their stops; ``theta`` and ``psi`` within
    [-pi, pi]. Values use the tolerance of :meth:`JointSpec.contains`.
    """
    problems = []
    for j in (1, 2, 3):
        if j == joint:
            continue
        problem = kin.JOINTS[j].range_problem(f"q{j}", values[f"q{j}"])
        if problem:
            problems.append(problem)
    for name in ("theta", "psi"):
        v = values[name]
        if not -_TILT_LIMIT <= v <= _TILT_LIMIT:
            problems.append(f"{name} = {v:.6g} rad is outside [-pi, pi] (angles are in radians)")
    return problems


def _parse_float(name: str, text: str) -> tuple[float | None, str | None]:
    try:
        v = float(text)
    except ValueError:
        return None, f"{name} must be a number in SI units, got {text!r}"
    if not math.isfinite(v):
        return None, f"{name} must be finite, got {text!r}"
    return v, None


MAX_STEPS = 10**12
"""Largest step count accepted in a table (a full traverse is ~1e4..1e7 steps; SQLite holds < 2**63)."""


def _grouped(t: str) -> bool:
    """12.000 or 12,000 (a count with thousands separators), by hand (the peer of rows._GROUPED)."""
    body = t[1:] if t[:1] in "+-" else t
    for sep in ".,":
        head, *groups = body.split(sep)
        if groups and 1 <= len(head) <= 3 and all(len(g) == 3 for g in groups) and \
                all(c.isascii() and c.isdigit() for c in head + "".join(groups)):
            return True
    return False


def _parse_steps(text: str) -> tuple[int | None, str | None]:
    t = text.strip()
    if _grouped(t):
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


def _digit_run(text: str, i: int) -> tuple[str, int]:
    j = i
    while j < len(text) and text[j].isascii() and text[j].isdigit():
        j += 1
    return text[i:j], j


def _iso_or_none(y: int, m: int, d: int) -> str | None:
    try:
        return datetime.date(y, m, d).isoformat()
    except ValueError:
        return None


_MONTH_NAMES = ["jan", "feb", "mar", "apr", "may", "jun", "jul", "aug", "sep", "oct", "nov", "dec"]


def _sheet_date_problem(text: str) -> str | None:
    """A label starting 22.11.2026, 11/22/26 or 22-Nov-2026 (the peer of clock._other_date_problem, by hand)."""
    a, i = _digit_run(text, 0)
    if not 1 <= len(a) <= 2 or i >= len(text):
        return None
    sep = text[i]
    iso = None
    if sep in "./":
        b, j = _digit_run(text, i + 1)
        if not (1 <= len(b) <= 2 and j < len(text) and text[j] == sep):
            return None
        c, _ = _digit_run(text, j + 1)
        if len(c) not in (2, 4):
            return None
        if sep == "." and len(c) == 4:
            iso = _iso_or_none(int(c), int(b), int(a))
    elif sep == "-":
        mon = text[i + 1 : i + 4]
        if not (len(mon) == 3 and mon.isascii() and mon.isalpha() and text[i + 4 : i + 5] == "-"):
            return None
        if mon.lower() not in _MONTH_NAMES:
            return None
        c, _ = _digit_run(text, i + 5)
        if len(c) != 4:
            return None
        iso = _iso_or_none(int(c), _MONTH_NAMES.index(mon.lower()) + 1, int(a))
    else:
        return None
    as_iso = f"write it as {iso}" if iso else "write the date as YYYY-MM-DD"
    return (f"the session label {text!r} is a date as a spreadsheet writes it: {as_iso} (YYYY-MM-DD), so that it "
            "has an age and sorts with its session")


def _label_problem(text: str) -> str | None:
    """The session-label rule written again without a regular expression (the peer of clock.day_label_problem)."""
    if len(text) > 64:
        return f"the session label is {len(text)} characters long (at most 64)"
    for ch in text:
        if not ch.isprintable():
            return (f"the session label {text[:64]!r} holds a control character or an invisible "
                    f"one (U+{ord(ch):04X}: a tab, a line break, a zero-width space)")
    sheet = _sheet_date_problem(text)
    if sheet is not None:
        return sheet
    head = text[:4]
    parts = text[5:].split("-", 1) if len(text) > 5 and head.isascii() and head.isdigit() and text[4] == "-" else []
    if len(parts) != 2:
        return None
    month = parts[0]
    day_digits = ""
    for ch in parts[1]:
        if not (ch.isascii() and ch.isdigit()):
            break
        day_digits += ch
    if not (month and month.isascii() and month.isdigit() and day_digits):
        return None
    shaped = f"{head}-{month}-{day_digits}"
    try:
        iso = datetime.date(int(head), int(month), int(day_digits)).isoformat()
    except (ValueError, OverflowError) as e:
        return f"the session label {text!r} starts like a date but is not one ({e})"
    if shaped != iso:
        return f"the session label {text!r}: write the date as {iso} (YYYY-MM-DD)"
    return None


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_row(row: dict[str, str], where: str) -> tuple[Traverse | None, list[str]]:
    """Validate one CSV row (a dict of strings). Returns the traverse or the problems."""
    numeric = [(row.get(k) or "").strip() for k in ("joint", "q1", "q2", "q3", "theta", "psi", "start", "end", "steps")]
    if any(numeric) and not any(_number(c) for c in numeric):
        return None, [f"{where}: not a data row: no number in q1 to steps (a line of units or column names, as "
                      "LabVIEW or Origin write under the header, or a second header?): delete it"]
    problems: list[str] = []
    day = (row.get("day") or "").strip()
    if not day:
        problems.append(f"{where}: day is empty (use a session label, e.g. an ISO date)")
    elif (why := _label_problem(day)) is not None:
        problems.append(f"{where}: day: {why}")
    jtext = (row.get("joint") or "").strip()
    joint: int | None
    try:
        joint = int(jtext)
        kin.joint_spec(joint)
    except ValueError:
        problems.append(f"{where}: unknown joint {jtext!r} (joints are 1, 2 and 3)")
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
            nums[name] = v  # type: ignore[assignment]
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
        problem = kin.JOINTS[joint].range_problem(name, nums[name])
        if problem:
            problems.append(f"{where}: {problem}")
    problems += [f"{where}: {p}" for p in check_pose(joint, nums)]
    # the moving joint's own coordinate is not used, but no arm is beyond a full turn (joints 1, 2) or a metre
    # (joint 3): such a row is refused, not read and then refused by the store unnamed (the contract since audit61)
    own = nums[f"q{joint}"]
    if abs(own) > (1.0 if joint == 3 else 2 * math.pi):
        problems.append(f"{where}: {coordinate_problem(f'q{joint}', joint, own)}")
    if problems:
        return None, problems
    return Traverse(
        day, joint, direction, nums["q1"], nums["q2"], nums["q3"], nums["theta"], nums["psi"], start, end, steps
    ), []


def parse_measurements(text: str, source: str = "<string>") -> list[Traverse]:
    """Parse measurement-table CSV text. Raises :class:`TableError` listing every bad row."""
    try:
        return _parse_measurements(text, source)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None


def _csv_problem(source: str, e: csv.Error) -> str:
    text = str(e)
    if "field limit" in text:
        text = f"a cell is longer than {csv.field_size_limit()} characters"
    return f"{source}: not a readable CSV table ({text})"


def _parse_measurements(text: str, source: str) -> list[Traverse]:
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader)
    except StopIteration:
        raise TableError([f"{source}:1: the file is empty (expected the header {','.join(HEADER)})"]) from None
    header = [h.strip() for h in header]
    if tuple(header) != HEADER:
        missing = [h for h in HEADER if h not in header]
        extra = [h for h in header if h not in HEADER]
        detail = []
        if missing:
            detail.append("missing " + ", ".join(missing))
        if extra:
            detail.append("unexpected " + ", ".join(extra))
        if not detail:
            detail.append("columns out of order")
        if len(header) == 1 and (";" in header[0] or "\t" in header[0]):  # the same message as the library's
            detail = ["the columns are separated by ';': save the table with commas between columns and '.' before "
                      "decimals" if ";" in header[0] else "the columns are separated by a tab: save the table with "
                      "commas (CSV)"]
        raise TableError([f"{source}:1: header must be exactly {','.join(HEADER)} ({'; '.join(detail)})"])
    out: list[Traverse] = []
    problems: list[str] = []
    for lineno, cells in enumerate(reader, start=2):
        if not cells or all(not c.strip() for c in cells):
            continue  # blank line: not data
        where = f"{source}:{lineno}"
        if len(cells) != len(HEADER):
            problems.append(f"{where}: expected {len(HEADER)} columns, found {len(cells)}")
            continue
        t, errs = parse_row(dict(zip(HEADER, cells, strict=True)), where)
        if errs:
            problems += errs
        else:
            out.append(t)  # type: ignore[arg-type]
    if problems:
        raise TableError(problems)
    if not out:
        raise TableError([f"{source}:2: the table has a header but no rows"])
    return out


def _read_table_text(path: str | Path) -> str:
    """The text of a CSV table (a regular file, at most :data:`records.MAX_TABLE_BYTES`).

    A missing file, a folder, a pipe or device (never opened, so it cannot hang), a file
    over the size limit or non-UTF-8 text raises :class:`TableError`.
    """
    p = Path(path)
    if not p.exists():
        raise TableError([f"{p}: no such file"])
    try:
        return read_text_bounded(p, "CSV", MAX_TABLE_BYTES)
    except ValueError as e:
        raise TableError([str(e)]) from None


def read_measurements(path: str | Path) -> list[Traverse]:
    """Read a measurement table from a CSV file. Raises :class:`TableError` on any bad row."""
    return parse_measurements(_read_table_text(path), str(path))


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return repr(v)
    return str(v)


def measurements_to_csv(traverses: Iterable[Traverse]) -> str:
    """The CSV text of a measurement table (full float precision)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(HEADER)
    for t in traverses:
        w.writerow([_fmt(getattr(t, f.name)) for f in fields(Traverse)])
    return buf.getvalue()


def write_measurements(path: str | Path, traverses: Iterable[Traverse]) -> None:
    """Write a measurement table to a CSV file."""
    atomic_write_text(path, measurements_to_csv(traverses))  # a failed write keeps the old file


def as_arrays(traverses: Sequence[Traverse]) -> dict[str, np.ndarray]:
    """Column arrays of a list of traverses (for vectorised model evaluation)."""
    cols = {f.name: [getattr(t, f.name) for t in traverses] for f in fields(Traverse)}
    out: dict[str, np.ndarray] = {}
    for k, v in cols.items():
        out[k] = np.asarray(v, dtype=object if k in ("day", "direction") else float)
    out["joint"] = out["joint"].astype(int)
    out["steps"] = out["steps"].astype(int)
    return out


# ----------------------------------------------------------------------------- pose tables (predict)

POSE_TABLE_REQUIRED = ("joint", "q1", "q2", "q3", "theta", "psi")


@dataclass(frozen=True)
class PoseQuery:
    """One row of a pose table for ``predict``.

    ``start``/``end`` given: the average step over that traverse is asked for.
    Otherwise: the step size at the pose (the moving joint at ``q{joint}``).
    """

    joint: int
    direction: str
    q1: float
    q2: float
    q3: float
    theta: float
    psi: float
    start: float | None = None
    end: float | None = None

    @property
    def is_traverse(self) -> bool:
        return self.start is not None


def parse_pose_table(text: str, source: str = "<string>") -> tuple[list[str], list[dict[str, str]], list[PoseQuery]]:
    """Parse a pose table (CSV): columns joint, q1, q2, q3, theta, psi, and direction and/or start, end.

    A row with start and end is a traverse; its direction may be left out (it is the
    sign of end - start). A row without them asks for the step size at the pose and
    needs a direction. Other columns (day, steps, notes, ...) are kept and passed through. Returns the
    header, the raw rows and the parsed queries; raises :class:`TableError` listing
    every bad row as ``file:line: reason``.
    """
    try:
        return _parse_pose_table(text, source)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None


def _parse_pose_table(text: str, source: str) -> tuple[list[str], list[dict[str, str]], list[PoseQuery]]:
    reader = csv.DictReader(io.StringIO(text))
    try:
        header = [h.strip() for h in (reader.fieldnames or [])]
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None
    dup = sorted({h for h in header if h and header.count(h) > 1})
    if dup:
        raise TableError([f"{source}:1: column(s) {', '.join(dup)} appear more than once; keep one of each"])
    if not header:
        raise TableError([f"{source}:1: the file is empty (expected a header with {','.join(POSE_TABLE_REQUIRED)})"])
    reader.fieldnames = header
    missing = [c for c in POSE_TABLE_REQUIRED if c not in header]
    if missing:
        raise TableError(
            [
                f"{source}:1: header lacks {', '.join(missing)} (needs {','.join(POSE_TABLE_REQUIRED)}, "
                "and direction and/or start,end)"
            ]
        )
    has_traverse = "start" in header and "end" in header
    rows: list[dict[str, str]] = []
    queries: list[PoseQuery] = []
    problems: list[str] = []
    for row in reader:
        lineno = reader.line_num  # the row's line in the file: blank lines count
        if None in row:
            problems.append(f"{source}:{lineno}: more cells than header columns")
            continue
        if all(not (v or "").strip() for v in row.values()):
            continue
        where = f"{source}:{lineno}"
        errs: list[str] = []
        jtext = (row.get("joint") or "").strip()
        try:
            joint = int(jtext)
            kin.joint_spec(joint)
        except ValueError:
            errs.append(f"{where}: unknown joint {jtext!r} (joints are 1, 2 and 3)")
            joint = 0
        dtext = (row.get("direction") or "").strip()
        direction: str | None = None
        if dtext:
            try:
                direction = direction_label(dtext)
            except ValueError:
                errs.append(f"{where}: direction must be '+' or '-', got {dtext!r}")
        nums: dict[str, float] = {}
        for name in ("q1", "q2", "q3", "theta", "psi"):
            v, err = _parse_float(name, (row.get(name) or "").strip())
            if err:
                errs.append(f"{where}: {err}")
            else:
                nums[name] = v  # type: ignore[assignment]
        start = end = None
        if has_traverse:
            st, en = (row.get("start") or "").strip(), (row.get("end") or "").strip()
            if st or en:
                if not (st and en):
                    errs.append(f"{where}: give both start and end (a traverse) or neither (a pose)")
                else:
                    start, e1 = _parse_float("start", st)
                    end, e2 = _parse_float("end", en)
                    errs += [f"{where}: {e}" for e in (e1, e2) if e]
        if not errs and joint:
            spec = kin.JOINTS[joint]
            if start is not None and end is not None:
                if start == end:
                    errs.append(f"{where}: start and end are equal: a traverse must move")
                elif direction is None:
                    direction = "+" if end > start else "-"
                elif (end > start) != (direction == "+"):
                    errs.append(f"{where}: direction {direction!r} disagrees with end - start = {end - start:.6g}")
                checks = [("start", start), ("end", end)]
            else:
                if direction is None:
                    errs.append(f"{where}: the step size at a pose needs a direction ('+' or '-')")
                checks = [(f"q{joint}", nums[f"q{joint}"])]
            errs += [f"{where}: {p}" for name, v in checks if (p := spec.range_problem(name, v))]
            errs += [f"{where}: {p}" for p in check_pose(joint, nums)]
        if errs:
            problems += errs
            continue
        rows.append({k: (v or "") for k, v in row.items()})
        assert direction is not None
        queries.append(
            PoseQuery(joint, direction, nums["q1"], nums["q2"], nums["q3"], nums["theta"], nums["psi"], start, end)
        )
    if problems:
        raise TableError(problems)
    return header, rows, queries


def read_pose_table(path: str | Path) -> tuple[list[str], list[dict[str, str]], list[PoseQuery]]:
    """Read a pose table from a CSV file (see :func:`parse_pose_table`)."""
    return parse_pose_table(_read_table_text(path), str(path))
