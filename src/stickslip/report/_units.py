"""Display units of the report: SI inside, nm / µrad / mm / degrees on the page.

A stand-in with the names and signatures of ``stickslip.display`` (issue 9), which
will replace it: the scale is chosen by the joint's kind
(:func:`stickslip.kinematics.joint_spec`), never by its number.
"""

from __future__ import annotations

import math

from .. import kinematics as kin

__all__ = ["step_scale", "param_scale", "position_scale"]


def step_scale(joint: int) -> tuple[float, str]:
    """``(factor, unit)`` that turn a step size in SI into display units.

    ``(1e9, "nm")`` for the prismatic joint (steps of about a micrometre),
    ``(1e6, "µrad")`` for rotary ones (tens of microradians).
    """
    return (1e6, "µrad") if kin.joint_spec(joint).rotary else (1e9, "nm")


def param_scale(name: str, joint: int) -> tuple[float, str]:
    """``(factor, unit)`` of a model parameter: ``b`` of Eq. (2) is dimensionless, the rest are steps."""
    if name == "b":
        return 1.0, ""
    return step_scale(joint)


def position_scale(joint: int) -> tuple[float, str]:
    """``(factor, unit)`` of a joint coordinate: degrees for rotary joints, mm for the prismatic one."""
    return (180.0 / math.pi, "°") if kin.joint_spec(joint).rotary else (1e3, "mm")
