"""Which simulated arm a ``sim://`` URL opens.

``sim://?...`` opens the closed-form arm (:func:`stickslip.sim.arm.open_url`);
``sim+physics://?...`` or ``sim://?physics=1&...`` the physics-based arm
(:func:`stickslip.sim.physics.open_url`). This is the function
:data:`stickslip.devices.base.BACKENDS` names for both schemes, so that neither arm
module imports the other.
"""

from __future__ import annotations

from urllib.parse import parse_qsl, urlsplit

from ..devices.base import Controller
from . import arm, physics

__all__ = ["open_url"]


def open_url(url: str = "sim://") -> Controller:
    """Open the simulated arm ``url`` names (``ValueError`` naming a bad option)."""
    parts = urlsplit(url)
    if parts.scheme == "sim+physics" or ("physics", "1") in parse_qsl(parts.query):
        return physics.open_url(url)
    return arm.open_url(url)
