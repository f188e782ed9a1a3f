"""A rig as data (docs/rig.md): its arms, keep-out volumes, named positions, and the safety envelope.

* :mod:`.model` — the frozen dataclasses (:class:`Rig`, :class:`Arm`, :class:`Joint`,
  the volumes) and the arms' links in the rig frame;
* :mod:`.load` — the rig file (TOML) read and checked, one-line errors naming file,
  line and key; the MM3A's description shipped with the package (:func:`mm3a_rig`);
* :mod:`.secrets` — an arm's controller password from the environment or the OS keyring;
* :mod:`.envelope` — a whole planned path checked against volumes, other arms and soft
  limits before one step is sent;
* :mod:`.guard` — the one call the procedures make (``stickslip.procedures`` plan, then
  ask it), and the controller that maps joints to an arm's channels;
* :mod:`.draw` — the picture ``stickslip rig check -o`` draws (two views).
"""

from __future__ import annotations

from .envelope import EnvelopeViolation, Refusal, check_path, safe_fraction
from .load import RigError, load_rig, mm3a_rig, parse_rig
from .model import Arm, Box, Cylinder, HalfSpace, Joint, Mount, NamedPosition, Rig
from .secrets import PasswordMissing, controller_url

__all__ = [
    "Arm",
    "Box",
    "Cylinder",
    "EnvelopeViolation",
    "HalfSpace",
    "Joint",
    "Mount",
    "NamedPosition",
    "PasswordMissing",
    "Refusal",
    "Rig",
    "RigError",
    "check_path",
    "controller_url",
    "load_rig",
    "mm3a_rig",
    "parse_rig",
    "safe_fraction",
]
