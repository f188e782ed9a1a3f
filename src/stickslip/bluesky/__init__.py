"""Bluesky / ophyd-async devices and plans for stick-slip manipulators (the ``bluesky`` extra).

* :class:`StickSlipAxis`: one joint as an ophyd-async device (Movable, Locatable,
  Stoppable, Readable), moved with the calibrated load-aware step-size model;
* :class:`StickSlipManipulator`: the three joints of one arm on one controller, and
  the tip's ``x, y, z`` as pseudo-axes (:class:`Tip`, :class:`TipAxis`);
* :func:`calibration_day`: the paper's calibration traverses as a Bluesky plan;
* :class:`ServedAxis`: one joint of a rig that ``stickslip serve`` owns, moved by the server
  through :class:`stickslip.client.Rig`.

See docs/bluesky.md.
"""

from .axis import MAX_BURST_S, STOP_RETURN_S, DeviceLink, MoveError, StickSlipAxis
from .manipulator import StickSlipManipulator
from .plans import PAPER_POSES, calibration_day
from .served import ServedAxis
from .tip import Tip, TipAxis

__all__ = [
    "DeviceLink",
    "MoveError",
    "StickSlipAxis",
    "StickSlipManipulator",
    "ServedAxis",
    "Tip",
    "TipAxis",
    "PAPER_POSES",
    "calibration_day",
    "MAX_BURST_S",
    "STOP_RETURN_S",
]
