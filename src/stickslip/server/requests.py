"""A request's body and its amounts: the JSON bodies of the API and the parsing of values with units.

A JSON number is SI (m, rad); a string carries its unit (``"30um"``, ``"2deg"``), as on the
command line. A value that cannot be used is refused (:class:`~.slot.Refused`) with one line.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field

from ..joints import joint_spec
from ..procedures.move import PoseUpdate
from ..procedures.named import NAME_PATTERN
from ..procedures.reach import MAX_TIP_M
from ..units import UnitError, bare_number_problem, parse_angle, parse_length
from .slot import Motion, Refused, one_line

__all__ = [
    "Amount", "DayBody", "JogBody", "MoveBody", "ObserveBody", "PositionBody", "ReachBody", "StepBody",
    "TraverseBody", "WhereBody", "accepted", "joint_value", "pose", "value", "vector",
]

Amount = Annotated[
    float | str,
    Field(description="SI (m or rad) as a JSON number, or a string with its unit: '30um', '2deg', '-pi/2'"),
]


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid")


class MoveBody(_Body):
    """A planned move of one joint: ``by`` or ``to`` (exactly one)."""

    joint: int = Field(ge=1, le=3, strict=True, description="1, 2 (rotary) or 3 (prismatic)")
    by: Amount | None = None
    to: Amount | None = Field(None, description="a position, or 'min'/'max' for an end stop")


class StepBody(_Body):
    """Raw steps, no calibration (the joint is then uncertain until referenced)."""

    joint: int = Field(ge=1, le=3, strict=True)
    steps: int = Field(ge=-10_000_000, le=10_000_000, strict=True, description="signed steps, not 0")


class ReachBody(_Body):
    """A straight tip move, base frame before the tilt: ``to`` or ``by`` (exactly one), three lengths each."""

    to: list[Amount] | None = Field(None, min_length=3, max_length=3)
    by: list[Amount] | None = Field(None, min_length=3, max_length=3)


class JogBody(_Body):
    """A jog direction held (send it again at least every 50 ms while held: the dead man's switch)."""

    direction: Literal["+x", "-x", "+y", "-y", "+z", "-z"]
    speed: int | None = Field(None, ge=1, le=7, strict=True, description="preset 1-7: 0.1, 0.3, 1, 3, 10, 30, 100 µm/s")


class WhereBody(_Body):
    """Record references (a joint put at a known point) or a pose; ``set`` maps a joint to a position or min/max."""

    set: dict[Literal["1", "2", "3"], Amount] | None = None
    q1: Amount | None = None
    q2: Amount | None = None
    q3: Amount | None = None
    theta: Amount | None = None
    psi: Amount | None = None


class ObserveBody(_Body):
    """A measured position of one joint (a microscope reading, an end stop reached)."""

    joint: int = Field(ge=1, le=3, strict=True)
    q: Amount
    sd: Amount | None = None
    at_stop: bool = Field(False, strict=True)
    force: bool = Field(False, strict=True)


class TraverseBody(_Body):
    """One traverse of a joint from stop to stop, timed by the limit switch."""

    joint: int = Field(ge=1, le=3, strict=True)
    direction: Literal["+", "-"]


class PositionBody(_Body):
    """Save the current positions under a name."""

    name: str = Field(pattern=NAME_PATTERN)


class DayBody(_Body):
    """Start the calibration day (or resume a stopped one)."""

    day: str | None = Field(None, pattern=r"^[0-9A-Za-z][0-9A-Za-z_.:+-]{0,39}$", description="session label")
    resume: bool = Field(False, strict=True)


# ------------------------------------------------------------------------------ parsing with units


def value(text: Amount, kind: str, what: str, span: float | None = None) -> float:
    """An amount: a JSON number is SI; a string needs its unit (a bare number other than 0 is refused)."""
    if isinstance(text, (int, float)):
        v = float(text)
    else:
        bare = bare_number_problem(text, kind, span)
        if bare is not None:
            raise Refused(f"{what}: {bare}")
        try:
            v = parse_angle(text) if kind == "angle" else parse_length(text)
        except (UnitError, ValueError, ArithmeticError) as e:
            raise Refused(f"{what}: {one_line(e)}") from None
    if not math.isfinite(v):
        raise Refused(f"{what}: {text!r} is not a finite value")
    return v


def joint_value(joint: int, text: Amount, what: str, stops: bool = False) -> float:
    """A position or displacement of ``joint``: a length (joint 3) or an angle (1, 2); ``min``/``max`` if ``stops``."""
    spec = joint_spec(joint)
    if stops and isinstance(text, str) and text.strip().lower() in ("min", "lower", "max", "upper"):
        return spec.lower if text.strip().lower() in ("min", "lower") else spec.upper
    return value(text, "angle" if spec.rotary else "length", what, spec.span)


def pose(body: WhereBody) -> PoseUpdate:
    def q(j: int, v: Amount | None) -> float | None:
        return None if v is None else joint_value(j, v, f"q{j}")

    def a(name: str, v: Amount | None) -> float | None:
        return None if v is None else value(v, "angle", name)

    return PoseUpdate(q(1, body.q1), q(2, body.q2), q(3, body.q3), a("theta", body.theta), a("psi", body.psi))


def vector(values: list[Amount], what: str) -> tuple[float, float, float]:
    """Three lengths of a tip target or displacement, m; each within :data:`~stickslip.procedures.reach.MAX_TIP_M`,
    as ``stickslip reach`` takes them."""
    out = [value(v, "length", f"{what}[{i}]") for i, v in enumerate(values)]
    for i, v in enumerate(out):
        if abs(v) > MAX_TIP_M:
            raise Refused(f"{what}[{i}] = {v:.6g} m is not a length within {MAX_TIP_M:g} m")
    return (out[0], out[1], out[2])



def accepted(m: Motion) -> JSONResponse:
    status = 202 if m.active else 200
    return JSONResponse(m.as_dict(full=not m.active), status_code=status)

