"""The joints of the MM3A-type arm: which are rotary, which prismatic, and their end stops.

This is the one place that knows that joints 1 and 2 turn (radians) and joint 3 slides
(metres): everything else asks :func:`joint_spec` (``joint_spec(j).rotary``,
``.unit``, ``.lower``/``.upper``) instead of testing ``j == 3``. It sits at the bottom
of the package (standard library only) so that units, file checks and physics can all
use it.

Ranges (docs/design.md §2): joints 1 and 2 span 4π/3 rad, ``q2`` in [−7π/6, π/6];
joint 3 spans [0, 0.012] m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["JOINTS", "Q3_MAX", "ROTARY_SPAN", "JointSpec", "joint_spec"]

ROTARY_SPAN = 4.0 * math.pi / 3.0
"""Range of motion of rotary joints 1 and 2, rad (the paper's R_j)."""
Q3_MAX = 0.012
"""Stroke of prismatic joint 3, m."""



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
    """

    number: int
    kind: str
    lower: float
    upper: float
    unit: str

    @property
    def span(self) -> float:
        """Full range of motion (rad or m)."""
        return self.upper - self.lower

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
        """``"name = q unit is outside joint j's range [lo, hi] unit"``, or ``None`` if ``q`` is within it."""
        if math.isfinite(q) and self.contains(q):
            return None
        return (
            f"{name} = {q:.6g} {self.unit} is outside joint {self.number}'s range "
            f"[{self.lower:.6g}, {self.upper:.6g}] {self.unit}"
        )


# Joint 1's stops are not given by the paper; we take the same span as joint 2,
# centred on zero. Joint 2: q2 in [-7pi/6, pi/6]. Joint 3: [0, 12 mm].
JOINTS: dict[int, JointSpec] = {
    1: JointSpec(1, "rotary", -ROTARY_SPAN / 2, ROTARY_SPAN / 2, "rad"),
    2: JointSpec(2, "rotary", -7.0 * math.pi / 6.0, math.pi / 6.0, "rad"),
    3: JointSpec(3, "prismatic", 0.0, Q3_MAX, "m"),
}


def joint_spec(joint: int) -> JointSpec:
    """The :class:`JointSpec` of ``joint`` (1, 2 or 3); raises ``ValueError`` otherwise."""
    try:
        return JOINTS[int(joint)]
    except (KeyError, ValueError, TypeError):
        raise ValueError(f"unknown joint {joint!r}: joints are 1, 2 (rotary) and 3 (prismatic)") from None
