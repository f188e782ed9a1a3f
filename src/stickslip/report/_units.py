"""Units of the report's pages: step sizes and parameters as everywhere else
(:mod:`stickslip.units`: nm, µrad), joint positions on figure axes in mm and degrees."""

from __future__ import annotations

import math

from ..joints import joint_spec
from ..units import param_scale, step_scale

__all__ = ["param_scale", "position_scale", "step_scale"]


def position_scale(joint: int) -> tuple[float, str]:
    """``(factor, unit)`` of a joint coordinate on a figure axis: degrees (rotary) or mm (prismatic)."""
    return (180.0 / math.pi, "°") if joint_spec(joint).rotary else (1e3, "mm")
