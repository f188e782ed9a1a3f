"""One joint of a served rig as an ophyd-async device: Bluesky drives ``stickslip serve`` through the client.

:class:`ServedAxis` is :class:`~stickslip.bluesky.axis.StickSlipAxis`'s counterpart for a
rig that a ``stickslip serve`` process owns: it opens nothing itself and plans nothing
itself; ``set`` asks the server for a move (:meth:`stickslip.client.Rig.move`, the same
procedure the command line runs there: the tracked step scale, the journal, one motion
at a time), the readback is the server's kept position, ``stop`` is the server's STOP.
A Bluesky session, the page and a notebook can then share one arm.
"""

from __future__ import annotations

import asyncio
import math
from typing import Any

from bluesky.protocols import Locatable, Location, Reading, Stoppable
from ophyd_async.core import AsyncStatus, StandardReadable, soft_signal_r_and_setter
from ophyd_async.core import StandardReadableFormat as Format

from .. import kinematics as kin
from ..client import MotionFailed, Rig, RigError
from .axis import MoveError

__all__ = ["ServedAxis"]


class ServedAxis(StandardReadable, Locatable[float], Stoppable):
    """One joint of a served manipulator (``stickslip serve``), moved by the server.

    Parameters
    ----------
    rig : Rig
        The client of the server (:class:`stickslip.client.Rig`).
    joint : int
        1, 2 (rotary, rad) or 3 (prismatic, m).
    name : str
        Device name (the readback's data key).

    Signals
    -------
    readback : m or rad
        The server's kept (dead-reckoned) position (hinted).
    setpoint : m or rad
        The last target.
    sd : m or rad
        The kept position's standard deviation (NaN before a tracked move).
    uncertain : bool
        The server keeps the position as uncertain (a burst cut short, raw steps): re-reference the joint.
    """

    def __init__(self, rig: Rig, joint: int, name: str = "") -> None:
        self.rig = rig
        self.spec = kin.joint_spec(joint)
        self.joint = self.spec.number
        unit = self.spec.unit
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.readback, self._set_readback = soft_signal_r_and_setter(float, math.nan, units=unit)
        with self.add_children_as_readables(Format.UNCACHED_SIGNAL):
            self.setpoint, self._set_setpoint = soft_signal_r_and_setter(float, math.nan, units=unit)
            self.sd, self._set_sd = soft_signal_r_and_setter(float, math.nan, units=unit)
            self.uncertain, self._set_uncertain = soft_signal_r_and_setter(bool, False)
        self._stop_success = False
        super().__init__(name=name)

    def set_name(self, name: str, *, child_name_separator: str | None = None) -> None:
        super().set_name(name, child_name_separator=child_name_separator)
        self.readback.set_name(name)

    async def refresh(self) -> float:
        """Read the server's kept position into the signals; the position (m or rad)."""
        try:
            where = await asyncio.to_thread(self.rig.where)
        except RigError as e:
            raise MoveError(str(e)) from None
        q, sd, uncertain = _kept(where, self.joint)
        self._set_readback(q)
        self._set_sd(sd)
        self._set_uncertain(uncertain)
        if math.isnan(await self.setpoint.get_value()):
            self._set_setpoint(q)
        return q

    async def read(self) -> dict[str, Reading[Any]]:
        """The signals, the kept position read in first (the page may have moved it): no stale event."""
        await self.refresh()
        return await super().read()

    async def locate(self) -> Location[float]:
        """Setpoint (the last target) and readback (the server's kept position), m or rad."""
        readback = await self.refresh()
        return Location(setpoint=await self.setpoint.get_value(), readback=readback)

    def set(self, value: float) -> AsyncStatus[None]:
        """Ask the server to move the joint to ``value`` (m or rad); the status ends with the move.

        Fails with :class:`~stickslip.bluesky.axis.MoveError` (the server's one line) for a
        refused or failed move, and after ``stop(success=False)``.
        """
        self._stop_success = False
        return self._set(value)

    @AsyncStatus.wrap
    async def _set(self, value: float) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
            raise ValueError(f"the target of joint {self.joint} must be a number in {self.spec.unit}, got {value!r}")
        self._set_setpoint(float(value))
        try:
            await asyncio.to_thread(self.rig.move, self.joint, None, float(value))
        except MotionFailed as e:
            if not (self._stop_success and e.motion.get("status") == "stopped"):
                raise MoveError(str(e)) from None
        except RigError as e:
            self._set_uncertain(True)  # the move's end unknown (the server gone?): until the server says again
            raise MoveError(str(e)) from None
        finally:
            await self.refresh()  # a server gone fails here too (the flag stays): the same MoveError

    async def stop(self, success: bool = False) -> None:
        """The server's STOP (every axis of the rig: there is one STOP); ``success``: the move's status completes."""
        self._stop_success = success
        try:
            await asyncio.to_thread(self.rig.stop)
        except RigError as e:
            raise MoveError(str(e)) from None


def _kept(where: object, joint: int) -> tuple[float, float, bool]:
    """``(q, sd, uncertain)`` of ``joint`` in the server's ``/api/where`` answer; :class:`MoveError` if it has none.

    A position that is not a finite number, or a row for another joint, is not taken as
    the joint's position (a proxy's error page, another program on the port).
    """
    rows = where.get("joints") if isinstance(where, dict) else None
    row = rows[joint - 1] if isinstance(rows, list) and len(rows) >= joint else None
    q = row.get("q") if isinstance(row, dict) else None
    if (
        not isinstance(row, dict) or row.get("joint") != joint or isinstance(q, bool)
        or not isinstance(q, (int, float)) or not math.isfinite(q)
    ):
        raise MoveError(f"the server's answer has no position for joint {joint} (not a stickslip server's /api/where)")
    sd = row.get("sd")
    sd_value = float(sd) if isinstance(sd, (int, float)) and not isinstance(sd, bool) else math.nan
    return float(q), sd_value, row.get("uncertain") is not None
