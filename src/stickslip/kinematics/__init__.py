"""Kinematics of the MM3A-type arm: frames, joint ranges, gravity load terms, and the tip.

* :mod:`.frames` — frames, joint specs and ranges, the static-load terms of the paper's
  models (docs/design.md §2);
* :mod:`.tip` — the tip in task space: forward kinematics, the Jacobian, inverse
  kinematics with joint limits and singularities (docs/design.md §9);
* :mod:`.stage` — a Cartesian arm (three prismatic stages carrying a tool): its tip
  and inverse, linear.

Everything is importable from ``stickslip.kinematics`` directly.
"""

from __future__ import annotations

from .frames import *  # noqa: F403  (the names of frames.__all__)
from .frames import __all__ as _frames_all
from .stage import Stage
from .tip import *  # noqa: F403  (the names of tip.__all__)
from .tip import __all__ as _tip_all

__all__ = [*_frames_all, *_tip_all, "Stage"]
