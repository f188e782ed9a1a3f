"""Which simulated arm a ``sim://`` URL opens.

``sim://?...`` opens the closed-form arm (:func:`stickslip.sim.arm.open_url`);
``sim+physics://?...`` or ``sim://?physics=1&...`` the physics-based arm
(:func:`stickslip.sim.physics.open_url`). ``realtime=1`` (with ``speed=K``, default 1)
wraps either so that its bursts take device time on the wall clock
(:class:`stickslip.sim.realtime.RealtimeArm`); ``realtime=0`` is the virtual clock, as
without the option. This is the function :data:`stickslip.devices.base.BACKENDS` names
for both schemes, so that neither arm module imports the other.
"""

from __future__ import annotations

from urllib.parse import parse_qsl, urlencode, urlsplit

from ..devices.base import Controller
from . import arm, physics
from .realtime import RealtimeArm, check_speed

__all__ = ["open_url", "virtual_clock_url"]

_TRUE = {"1": True, "true": True, "yes": True, "0": False, "false": False, "no": False}


def open_url(url: str = "sim://") -> Controller:
    """Open the simulated arm ``url`` names (``ValueError`` naming a bad option)."""
    parts = urlsplit(url)
    query = parse_qsl(parts.query, keep_blank_values=True)
    options = dict(query)
    realtime_text = options.get("realtime", "0").strip().lower()
    if realtime_text not in _TRUE:
        raise ValueError(f"sim:// option realtime={options['realtime']!r} must be 1 or 0")
    realtime = _TRUE[realtime_text]
    if "speed" in options and not realtime:
        raise ValueError("sim:// option speed= needs realtime=1 (the virtual clock has no speed: it is instant)")
    speed = 1.0
    if "speed" in options:
        try:
            speed = check_speed(options["speed"])
        except ValueError as e:
            raise ValueError(f"sim:// option {e}") from None
    rest = [(k, v) for k, v in query if k not in ("realtime", "speed")]
    inner_url = url if len(rest) == len(query) else virtual_clock_url(url)
    if parts.scheme == "sim+physics" or ("physics", "1") in rest:
        sim: arm.SimulatedMM3A = physics.open_url(inner_url)
    else:
        sim = arm.open_url(inner_url)
    return RealtimeArm(sim, speed, url=url) if realtime else sim


def virtual_clock_url(url: str) -> str:
    """``url`` without its ``realtime`` and ``speed`` options: the same arm on the virtual clock.

    >>> virtual_clock_url("sim://?seed=3&realtime=1&speed=10&day=d1")
    'sim://?seed=3&day=d1'
    """
    parts = urlsplit(url)
    rest = [(k, v) for k, v in parse_qsl(parts.query, keep_blank_values=True) if k not in ("realtime", "speed")]
    query = f"?{urlencode(rest)}" if rest else ""
    return f"{parts.scheme}://{parts.netloc}{parts.path}{query}"
