"""The joints of the MM3A-type arm: which are rotary, which prismatic, and their end stops.

This is the one place that knows that joints 1 and 2 turn (radians) and joint 3 slides
(metres): everything else asks :func:`joint_spec` (``joint_spec(j).rotary``,
``.unit``, ``.lower``/``.upper``) instead of testing ``j == 3``. It sits at the bottom
of the package (standard library only) so that units, file checks and physics can all
use it.

Ranges (docs/design.md §2): joints 1 and 2 span 4π/3 rad, ``q2`` in [−7π/6, π/6];
joint 3 spans [0, 0.012] m. The numbers are read from the MM3A's description shipped
with the package (:data:`MM3A_FILE`, a rig file: docs/rig.md), as is its geometry
(:data:`MM3A_GEOMETRY`, which :class:`stickslip.kinematics.Geometry` defaults to).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

__all__ = [
    "JOINTS",
    "MAX_STROKE",
    "MAX_TURN",
    "MM3A_FILE",
    "MM3A_GEOMETRY",
    "NOMINAL_STEP",
    "Q3_MAX",
    "ROTARY_SPAN",
    "STEP_MODELS",
    "TILT_LIMIT",
    "JointSet",
    "JointSpec",
    "coordinate_bound",
    "coordinate_problem",
    "joint_spec",
    "tilt_problem",
]

MM3A_FILE = Path(__file__).parent / "rig" / "mm3a.toml"
"""The MM3A's description: a rig file of one arm shipped with the package (docs/rig.md)."""

_SI = {"deg": math.pi / 180.0, "rad": 1.0, "mm": 1e-3, "um": 1e-6, "m": 1.0}


def _si(text: Any) -> float:
    """``"-210deg"``, ``"12mm"`` or a bare SI number from the shipped file (the few units it uses)."""
    m = re.fullmatch(r"\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)\s*([a-z]*)\s*", str(text))
    if m is None or m.group(2) not in ("", *_SI):
        raise ValueError(f"{MM3A_FILE.name}: cannot read {text!r}")
    if m.group(2) == "deg":  # pi * (d / 180) as a fraction: -210deg is exactly -7 * pi / 6
        f = Fraction(m.group(1)) / 180
        return math.pi * f.numerator / f.denominator
    return float(m.group(1)) * _SI.get(m.group(2), 1.0)


def _mm3a() -> tuple[dict[int, tuple[str, float, float]], tuple[float, float]]:
    arm = tomllib.loads(MM3A_FILE.read_text(encoding="utf-8"))["arm"][0]
    joints = {int(j["number"]): (str(j["kind"]), _si(j["range"][0]), _si(j["range"][1])) for j in arm["joint"]}
    geometry = arm["geometry"]
    return joints, (_si(geometry["offset"]), _si(geometry["length"]))


_RANGES, MM3A_GEOMETRY = _mm3a()
"""``MM3A_GEOMETRY``: the MM3A's ``(offset, length)``, m, from :data:`MM3A_FILE`."""

ROTARY_SPAN = _RANGES[1][2] - _RANGES[1][1]
"""Range of motion of rotary joints 1 and 2, rad (the paper's R_j): 4π/3."""
Q3_MAX = _RANGES[3][2]
"""Stroke of prismatic joint 3, m: 12 mm."""



MAX_TURN = 2.0 * math.pi
"""rad: no rotary joint's coordinate is beyond a full turn either way (beyond: degrees read as radians)."""
MAX_STROKE = 1.0
"""m: no prismatic joint's coordinate is beyond a metre either way (beyond: mm or µm read as metres)."""
TILT_LIMIT = math.pi + 1e-6
"""rad: a base tilt (``theta``, ``psi``) lies within [-pi, pi] (and a rounding's margin)."""

NOMINAL_STEP = {"prismatic": 0.8e-6, "rotary": 40e-6}
"""A small step of each kind of joint (m, rad): what is assumed without a calibration or a rig file's ``step``."""

STEP_MODELS = ("paper", "constant")
"""How a joint's step size is planned: the paper's load-dependent model, or a constant step per direction."""


@dataclass(frozen=True)
class JointSpec:
    """Static description of one joint.

    Attributes
    ----------
    number : int
        1, 2 or 3.
    kind : {"rotary", "prismatic"}
    lower, upper : float
        End stops, rad for rotary joints, m for the prismatic joint.
    unit : str
        SI unit of the joint coordinate ("rad" or "m").
    nominal_step : float
        A small step of the joint, rad or m: how many steps surely reach a stop without a
        calibration. ``nan`` (the default) means :data:`NOMINAL_STEP` of its kind.
    home : float
        The position assumed before the joint is referenced, rad or m.
    step_model : {"paper", "constant"}
        ``"paper"``: the calibration's load-dependent model of the MM3A's joint
        (docs/design.md §3); ``"constant"``: the calibration's constant step of each
        direction (a positioner stage: docs/rig.md).
    """

    number: int
    kind: str
    lower: float
    upper: float
    unit: str
    nominal_step: float = math.nan
    home: float = 0.0
    step_model: str = "paper"

    @property
    def small_step(self) -> float:
        """:attr:`nominal_step`, or :data:`NOMINAL_STEP` of the joint's kind where none is given (rad or m)."""
        return self.nominal_step if math.isfinite(self.nominal_step) else NOMINAL_STEP[self.kind]

    @property
    def span(self) -> float:
        """Full range of motion (rad or m)."""
        return self.upper - self.lower

    @property
    def bound(self) -> float:
        """No position of a joint of this kind lies beyond ``±bound``: :data:`MAX_TURN` (rotary, rad) or
        :data:`MAX_STROKE` (prismatic, m), whatever the arm; beyond, the value is in another unit."""
        return MAX_TURN if self.rotary else MAX_STROKE

    @property
    def rotary(self) -> bool:
        """True for a rotary joint (coordinate in rad), False for the prismatic one (m)."""
        return self.kind == "rotary"

    @property
    def prismatic(self) -> bool:
        """True for the prismatic joint (coordinate in m)."""
        return self.kind == "prismatic"

    def contains(self, q: float, tol: float | None = None) -> bool:
        """Whether ``q`` is within the end stops (to ``tol``, default 1e-5 of the span)."""
        if tol is None:
            tol = 1e-5 * self.span
        return self.lower - tol <= q <= self.upper + tol

    def range_problem(self, name: str, q: float) -> str | None:
        """``"name = q unit is outside joint j's range [lo, hi] unit"`` (or not finite), else ``None``."""
        if math.isfinite(q) and self.contains(q):
            return None
        if not math.isfinite(q):
            return f"{name} must be a finite number in {self.unit}, got {q!r}"
        slip = self.unit_slip(q)
        return (
            f"{name} = {q:.6g} {self.unit} is outside joint {self.number}'s range "
            f"[{self.lower:.6g}, {self.upper:.6g}] {self.unit}" + (f" ({slip})" if slip else "")
        )

    def unit_slip(self, q: float) -> str | None:
        """The likely unit slip of an SI value ``q`` well outside the stops, if read in another unit it is inside.

        Degrees for a rotary joint (``q2 = -90``: -90 deg is inside, -90 rad is not); mm or µm
        for the prismatic joint (``q3 = 5``: 5 mm is inside). ``None`` when no such reading fits,
        or for a near miss: ``q`` beyond a stop by less than the joint's span (``q2 = 0.6`` rad,
        34 deg against the 30 deg stop; ``q3 = 0.02`` m) is a position too far, not in another unit.

        >>> JOINTS[2].unit_slip(-90.0)
        'in degrees? -90 deg is -1.5708 rad: angles are in radians'
        >>> JOINTS[3].unit_slip(5.0)
        'in mm or µm? 5 mm is 0.005 m, 5 µm is 5e-06 m: lengths are in metres'
        """
        if not math.isfinite(q) or self.lower - self.span <= q <= self.upper + self.span:
            return None
        return _slip(q, self.rotary, self.contains)


# Joint 1's stops are not given by the paper; the shipped file takes the same span as
# joint 2, centred on zero. Joint 2: q2 in [-7pi/6, pi/6]. Joint 3: [0, 12 mm].
# The MM3A's assumed pose before it is referenced: outstretched (q2 = -pi/2), joint 3 retracted.
_HOME = {1: 0.0, 2: -math.pi / 2, 3: 0.0}
JOINTS: dict[int, JointSpec] = {
    j: JointSpec(j, kind, lo, hi, "rad" if kind == "rotary" else "m", home=_HOME[j])
    for j, (kind, lo, hi) in sorted(_RANGES.items())
}

JointSet = Mapping[int, JointSpec]
"""An arm's joints by number (1, 2, 3): :data:`JOINTS` for the MM3A, an arm's own from a rig file."""


def joint_spec(joint: int | JointSpec, joints: JointSet | None = None) -> JointSpec:
    """The :class:`JointSpec` of ``joint`` (1, 2 or 3) in ``joints`` (the MM3A's by default); ``ValueError`` otherwise.

    A :class:`JointSpec` given as ``joint`` is returned as it is (an arm's own joint).
    """
    if isinstance(joint, JointSpec):
        return joint
    try:
        if isinstance(joint, bool) or (not isinstance(joint, str) and int(joint) != joint):
            raise TypeError  # True is not joint 1, nor 2.5 joint 2
        return (JOINTS if joints is None else joints)[int(joint)]
    except (KeyError, ValueError, TypeError, OverflowError):
        raise ValueError(f"unknown joint {joint!r}: joints are 1, 2 (rotary) and 3 (prismatic)") from None


def _slip(q: float, rotary: bool, fits: Callable[[float], bool]) -> str | None:
    """``"in degrees? ..."`` / ``"in mm or µm? ..."``: the readings of ``q`` in another unit that ``fits``
    (else ``None``)."""
    factors = (("degrees", "deg", math.pi / 180.0),) if rotary else (("mm", "mm", 1e-3), ("µm", "µm", 1e-6))
    found = [(name, unit, q * f) for name, unit, f in factors if fits(q * f)]
    if not found:
        return None
    si = "rad" if rotary else "m"
    said = ", ".join(f"{q:.6g} {unit} is {v:.6g} {si}" for _, unit, v in found)
    kind = "angles are in radians" if rotary else "lengths are in metres"
    return f"in {' or '.join(name for name, _, _ in found)}? {said}: {kind}"


def _finite(q: object) -> float | None:
    """``q`` as a finite float, or None: not a number (a bool, a text), not finite, or an int too large for a float
    (a JSON ``1000...0`` of 400 digits made ``float`` raise OverflowError, a traceback where a message was due)."""
    if isinstance(q, bool) or not isinstance(q, (int, float)) and not hasattr(q, "__float__"):
        return None
    try:
        v = float(q)  # (an object with __float__)
    except (OverflowError, ValueError, TypeError):
        return None
    return v if math.isfinite(v) else None


def _shown(q: object) -> str:
    """``repr(q)``, at most 40 characters (an int of 400 digits is not written out)."""
    text = repr(q)
    return text if len(text) <= 40 else f"{text[:20]}...({len(text)} characters)"


def coordinate_bound(joint: int) -> float:
    """No arm's coordinate of joint ``joint`` lies beyond ``±`` this, whatever the arm: :data:`MAX_STROKE` (m) for
    joint 3, prismatic on every arm; :data:`MAX_TURN` (rad) for joints 1 and 2 (a stage's are prismatic, within a
    metre: within a turn too)."""
    return MAX_STROKE if joint == 3 else MAX_TURN


def coordinate_problem(name: str, joint: int, q: float) -> str | None:
    """Why ``q`` can be no arm's coordinate of joint ``joint`` (1, 2, 3), whatever the arm; ``None`` if it can.

    Arm-independent (an arm's stops are checked by :meth:`JointSpec.range_problem`): ``q`` is a
    finite real number, and joint 3, prismatic on every arm, lies within :data:`MAX_STROKE`;
    joints 1 and 2, rotary on an MM3A (a stage's are prismatic, within a metre: within a turn
    too), within :data:`MAX_TURN`. Beyond, the message names the likely unit slip
    (``q2 = -90``: degrees).
    """
    v = _finite(q)
    if v is None:
        return f"{name} must be a finite number in SI units, got {_shown(q)}"
    rotary = joint != 3
    bound = coordinate_bound(joint)
    if abs(v) <= bound:
        return None
    slip = _slip(v, rotary, lambda r: abs(r) <= bound)
    what = f"a full turn ({MAX_TURN:.6g} rad)" if rotary else f"a metre ({MAX_STROKE:g} m)"
    return f"{name} = {v:.6g} is no arm's position of joint {joint}: beyond {what}" + (f" ({slip})" if slip else "")


def tilt_problem(name: str, value: float) -> str | None:
    """Why ``value`` is no base tilt (``theta``, ``psi``): not finite, or outside [-pi, pi] (degrees?)."""
    v = _finite(value)
    if v is None:
        return f"{name} must be a finite number in SI units, got {_shown(value)}"
    if -TILT_LIMIT <= v <= TILT_LIMIT:
        return None
    return f"{name} = {v:.6g} rad is outside [-pi, pi] (angles are in radians)"
