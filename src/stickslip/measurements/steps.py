"""Step sizes measured at a pose (a camera, not a traverse): :class:`StepSize` and its table.

A traverse gives a joint's *average* step between its end stops; a camera that tracks the
tip over a few hundred steps gives its *local* mean step at the pose it works in, with a
standard deviation (``stickslip camera calibrate``). Its table (CSV), header exactly::

    day,joint,direction,q1,q2,q3,theta,psi,gamma,sigma,steps,method

``q1, q2, q3`` hold the pose, the moving joint's column its position at the middle of
the measured travel; ``gamma`` the mean step (m for joint 3, rad for joints 1 and 2),
``sigma`` its standard deviation (same unit, > 0), ``steps`` how many steps it rests on,
``method`` how it was measured (``camera``). All SI. Rows that break these rules are
refused with the line and the reason, never skipped.

:meth:`StepSize.as_traverse` is the same measurement as a short traverse (``steps``
steps centred on the pose, ``gamma`` on average): the calibration's model of a traverse
then predicts it without a second code path.
"""

from __future__ import annotations

import csv
import io
import math
import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from .. import kinematics as kin
from ..clock import day_label_problem
from ..models import direction_label
from ..records import (
    MAX_TABLE_BYTES,
    STEP_RANGE,
    atomic_write,
    guard_cell,
    read_text_bounded,
    step_unit_slip,
    unguard_cell,
)
from .rows import TableError, Traverse, _csv_problem, _parse_steps, check_header, check_pose, number_problem

__all__ = [
    "STEP_HEADER",
    "STEP_METHODS",
    "StepSize",
    "parse_step_sizes",
    "read_step_sizes",
    "write_step_sizes",
    "step_sizes_to_csv",
]

STEP_HEADER = ("day", "joint", "direction", "q1", "q2", "q3", "theta", "psi", "gamma", "sigma", "steps", "method")
STEP_METHODS = ("camera",)
"""How a step size at a pose may have been measured."""


@dataclass(frozen=True)
class StepSize:
    """A joint's mean step size measured at a pose (a row of the step-size table).

    Attributes
    ----------
    day : str
        Session label (ISO date preferred).
    joint : int
        1, 2 or 3.
    direction : str
        ``"+"`` or ``"-"``.
    q1, q2, q3 : float
        The pose (rad, rad, m); the moving joint's value is where it was measured.
    theta, psi : float
        Base tilt, rad.
    gamma : float
        Mean step, m (joint 3) or rad (joints 1, 2).
    sigma : float
        Standard deviation of ``gamma``, same unit, > 0.
    steps : int
        Steps the measurement rests on.
    method : str
        ``"camera"``.
    """

    day: str
    joint: int
    direction: str
    q1: float
    q2: float
    q3: float
    theta: float
    psi: float
    gamma: float
    sigma: float
    steps: int
    method: str = "camera"

    @property
    def relative_sigma(self) -> float:
        """``sigma / gamma``, 1."""
        return self.sigma / self.gamma

    def as_traverse(self) -> Traverse:
        """The same measurement as a short traverse: ``steps`` steps of mean ``gamma`` centred on the pose."""
        q = (self.q1, self.q2, self.q3)[self.joint - 1]
        half = 0.5 * self.gamma * self.steps
        sign = 1.0 if self.direction == "+" else -1.0
        return Traverse(
            self.day, self.joint, self.direction, self.q1, self.q2, self.q3, self.theta, self.psi,
            q - sign * half, q + sign * half, self.steps,
        )


def _problems(row: dict[str, str], where: str) -> tuple[StepSize | None, list[str]]:
    problems: list[str] = []
    day = unguard_cell(row.get("day") or "").strip()  # a label written guarded against formulas
    if not day:
        problems.append(f"{where}: day is empty (use a session label, e.g. an ISO date)")
    elif (why := day_label_problem(day)) is not None:
        problems.append(f"{where}: day: {why}")
    joint = None
    jtext = (row.get("joint") or "").strip()
    try:
        joint = int(jtext)
        kin.joint_spec(joint)
    except ValueError:
        problems.append(f"{where}: unknown joint {jtext!r} (joints are 1, 2 and 3)")
        joint = None
    direction = None
    try:
        direction = direction_label((row.get("direction") or "").strip())
    except ValueError:
        problems.append(f"{where}: direction must be '+' or '-', got {(row.get('direction') or '').strip()!r}")
    nums: dict[str, float] = {}
    for name in ("q1", "q2", "q3", "theta", "psi", "gamma", "sigma"):
        text = (row.get(name) or "").strip()
        try:
            v = float(text)
        except ValueError:
            problems.append(f"{where}: {number_problem(name, text)}")
            continue
        if not math.isfinite(v):
            problems.append(f"{where}: {name} must be finite, got {text!r}")
            continue
        nums[name] = v
    steps, err = _parse_steps(row.get("steps") or "")  # as the measurement table reads them (12000.0, 1.2e4)
    if err:
        problems.append(f"{where}: {err}")
    method = (row.get("method") or "").strip()
    if method not in STEP_METHODS:
        problems.append(f"{where}: method must be {' or '.join(STEP_METHODS)}, got {method!r}")
    if problems or joint is None or direction is None or steps is None:
        return None, problems
    unit = kin.joint_spec(joint).unit
    lo, hi = STEP_RANGE[unit]
    if not lo <= nums["gamma"] <= hi:
        slip = step_unit_slip(nums["gamma"], unit)
        problems.append(f"{where}: gamma = {nums['gamma']:.6g} {unit} is not a step size of joint {joint} "
                        f"({lo:g}..{hi:g} {unit}; SI units{f'; {slip}' if slip else ''})")
    if not 0 < nums["sigma"] <= nums["gamma"]:
        problems.append(f"{where}: sigma = {nums['sigma']:.6g} {unit} must be > 0 and at most gamma")
    problem = kin.JOINTS[joint].range_problem(f"q{joint}", nums[f"q{joint}"])
    if problem:
        problems.append(f"{where}: {problem}")
    problems += [f"{where}: {p}" for p in check_pose(joint, nums)]
    if problems:
        return None, problems
    return StepSize(day, joint, direction, nums["q1"], nums["q2"], nums["q3"], nums["theta"], nums["psi"],
                    nums["gamma"], nums["sigma"], steps, method), []


def parse_step_sizes(text: str, source: str = "<string>") -> list[StepSize]:
    """Parse step-size table CSV text. Raises :class:`TableError` listing every bad row (``file:line: reason``)."""
    try:
        reader = csv.reader(io.StringIO(text))
        check_header(next(reader, None), source, STEP_HEADER)
        out: list[StepSize] = []
        problems: list[str] = []
        for lineno, cells in enumerate(reader, start=2):
            if not cells or all(not c.strip() for c in cells):
                continue
            if len(cells) != len(STEP_HEADER):
                problems.append(f"{source}:{lineno}: expected {len(STEP_HEADER)} columns, found {len(cells)}")
                continue
            row, errs = _problems(dict(zip(STEP_HEADER, cells, strict=True)), f"{source}:{lineno}")
            problems += errs
            if row is not None:
                out.append(row)
    except csv.Error as e:
        raise TableError([_csv_problem(source, e)]) from None
    if problems:
        raise TableError(problems)
    if not out:
        raise TableError([f"{source}:2: the table has a header but no rows"])
    return out


def read_step_sizes(path: str | Path) -> list[StepSize]:
    """Read a step-size table. Raises :class:`TableError` for a missing or unreadable file or any bad row."""
    p = Path(path)
    try:
        text = read_text_bounded(p, "CSV", MAX_TABLE_BYTES)
    except ValueError as e:
        raise TableError([str(e)]) from None
    return parse_step_sizes(text, str(p))


def step_sizes_to_csv(rows: Iterable[StepSize]) -> str:
    """The CSV text of a step-size table (floats at full precision)."""
    buf = io.StringIO()
    _write(buf, rows)
    return buf.getvalue()


def _write(f: TextIO, rows: Iterable[StepSize]) -> None:
    w = csv.writer(f, lineterminator="\n")
    w.writerow(STEP_HEADER)
    rest = operator.attrgetter(*STEP_HEADER[1:])
    w.writerows((guard_cell(str(r.day)), *rest(r)) for r in rows)  # a label a spreadsheet would run: guarded


def write_step_sizes(path: str | Path, rows: Sequence[StepSize]) -> None:
    """Write a step-size table; the file appears only when complete (a failed write keeps the old one)."""
    atomic_write(path, lambda f: _write(f, rows))
