"""The three joints of one stick-slip arm as one ophyd-async device.

:class:`StickSlipManipulator` holds ``q1``, ``q2`` (rad) and ``q3`` (m) as
:class:`~stickslip.bluesky.axis.StickSlipAxis` children on one controller and one
database (:class:`~stickslip.bluesky.axis.DeviceLink`): moves through it run one at a
time, as the controller drives one channel at a time. It also carries what the
calibration-day plan reads: the last traverse (:class:`TraverseReadout`).

The tip's ``x, y, z`` (m) are pseudo-axes ``tip.x``, ``tip.y``, ``tip.z``
(:class:`~stickslip.bluesky.tip.Tip`): readback by forward kinematics of the kept joints,
moves planned by the task-space planner as straight tip moves.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from ophyd_async.core import StandardReadable, soft_signal_r_and_setter
from ophyd_async.core import StandardReadableFormat as Format

from .. import kinematics as kin
from ..calibration import Calibration
from ..devices.base import Controller
from ..measurements import Traverse
from ..rig.guard import Guard
from .axis import MAX_BURST_S, DeviceLink, StickSlipAxis
from .tip import Tip

__all__ = ["CalibrationReadout", "StickSlipManipulator", "TraverseReadout"]


class TraverseReadout(StandardReadable):
    """The last measured traverse, as signals (what a calibration-day event holds).

    Signals: ``joint``, ``direction`` (``"+"``/``"-"``), ``steps`` (counted), ``gamma``
    (average step, m or rad: ``|end - start| / steps``), ``start``/``end`` (m or rad),
    the fixed pose ``q1, q2, q3`` (rad, rad, m) and tilt ``theta, psi`` (rad).
    """

    def __init__(self, name: str = "") -> None:
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.steps, self._steps = soft_signal_r_and_setter(int, 0, units="steps")
            self.gamma, self._gamma = soft_signal_r_and_setter(float, math.nan)
        with self.add_children_as_readables(Format.UNCACHED_SIGNAL):
            self.joint, self._joint = soft_signal_r_and_setter(int, 0)
            self.direction, self._direction = soft_signal_r_and_setter(str, "")
            self.start, self._start = soft_signal_r_and_setter(float, math.nan)
            self.end, self._end = soft_signal_r_and_setter(float, math.nan)
            self.q1, self._q1 = soft_signal_r_and_setter(float, math.nan, units="rad")
            self.q2, self._q2 = soft_signal_r_and_setter(float, math.nan, units="rad")
            self.q3, self._q3 = soft_signal_r_and_setter(float, math.nan, units="m")
            self.theta, self._theta = soft_signal_r_and_setter(float, math.nan, units="rad")
            self.psi, self._psi = soft_signal_r_and_setter(float, math.nan, units="rad")
        super().__init__(name=name)

    def show(self, t: Traverse) -> None:
        """Put traverse ``t`` into the signals (call on the event loop)."""
        self._joint(t.joint)
        self._direction(t.direction)
        self._steps(int(t.steps))
        self._gamma(float(t.gamma))
        self._start(float(t.start))
        self._end(float(t.end))
        for k in ("q1", "q2", "q3", "theta", "psi"):
            getattr(self, f"_{k}")(float(getattr(t, k)))


class CalibrationReadout(StandardReadable):
    """A calibration as signals: ``json`` (the calibration file's JSON, SI units), ``method``, ``day``."""

    def __init__(self, name: str = "") -> None:
        with self.add_children_as_readables(Format.UNCACHED_SIGNAL):
            self.json, self._json = soft_signal_r_and_setter(str, "")
            self.method, self._method = soft_signal_r_and_setter(str, "")
            self.day, self._day = soft_signal_r_and_setter(str, "")
        super().__init__(name=name)

    def show(self, text: str, method: str, day: str) -> None:
        """Put a calibration (its JSON text, method and day) into the signals."""
        self._json(text)
        self._method(method)
        self._day(day)


class StickSlipManipulator(StandardReadable):
    """A three-joint stick-slip arm (MM3A type): axes ``q1``, ``q2`` (rad), ``q3`` (m) and the tip.

    ``tip.x``, ``tip.y``, ``tip.z`` (m, base frame) are pseudo-axes over the three joints
    (:class:`~stickslip.bluesky.tip.Tip`).

    Parameters
    ----------
    device : str or Controller
        Controller URL (``sim://``, ``mm3a:///dev/ttyUSB0``, ...) or an open controller.
    calibration : Calibration, path or None
        Its calibration; an axis whose joint it lacks (or all, for ``None``) refuses to
        move until :meth:`use_calibration` (the calibration-day plan calls it).
    name : str
    burst : int
        Steps per burst for every axis.
    db : path, optional
        The database keeping positions (default ``$STICKSLIP_DB``).
    geometry : Geometry
        The arm's lengths for the tip (:class:`stickslip.kinematics.Geometry`; default
        21 mm, no offset: measure yours, docs/taskspace.md).
    max_burst_s : float
        Longest burst on a controller stepping in real time, s (bounds how long a stop takes).
    guard : Guard, optional
        A rig's envelope (:func:`stickslip.procedures.arms.guard_for`): every joint move and
        every tip move's whole path is checked against it before a step is sent.
    """

    def __init__(
        self,
        device: str | Controller,
        calibration: Calibration | str | os.PathLike[str] | None = None,
        name: str = "",
        *,
        burst: int = 1000,
        db: str | os.PathLike[str] | None = None,
        geometry: kin.Geometry = kin.DEFAULT_GEOMETRY,
        max_burst_s: float = MAX_BURST_S,
        guard: Guard | None = None,
    ) -> None:
        cal = None if calibration is None else _load(calibration)
        self.link = DeviceLink(device, db)
        self.calibration = cal
        with self.add_children_as_readables():
            self.q1, self.q2, self.q3 = (
                StickSlipAxis(
                    self.link, j, cal if cal is None or j in cal.joints else None, burst=burst,
                    max_burst_s=max_burst_s, guard=guard,
                )
                for j in (1, 2, 3)
            )
            self.tip = Tip(
                self.link, lambda: self.calibration, geometry, burst=burst, max_burst_s=max_burst_s, guard=guard
            )
        for axis in (self.q1, self.q2, self.q3):
            axis.observers.append(self.tip.observe)  # a joint's move moves the tip's readbacks
            self.tip._driver.observers.append(axis.show)  # a tip move moves the joints' readbacks
        self.traverse = TraverseReadout()
        self.calibration_readout = CalibrationReadout()
        super().__init__(name=name)

    @property
    def axes(self) -> dict[int, StickSlipAxis]:
        """``{joint: axis}``."""
        return {1: self.q1, 2: self.q2, 3: self.q3}

    def use_calibration(self, calibration: Calibration | str | os.PathLike[str]) -> None:
        """Plan every joint the calibration covers with it from now on."""
        cal = _load(calibration)
        for j, axis in self.axes.items():
            if j in cal.joints:
                axis.use_calibration(cal)
        self.calibration = cal

    def close(self) -> None:
        """Close the controller if the manipulator opened it from a URL."""
        self.link.close()

    def __repr__(self) -> str:
        day = None if self.calibration is None else self.calibration.day
        return f"StickSlipManipulator(name={self.name!r}, device={self.link.key!r}, calibration_day={day!r})"


def _load(calibration: Calibration | str | os.PathLike[str]) -> Calibration:
    return calibration if isinstance(calibration, Calibration) else Calibration.load(Path(calibration))
