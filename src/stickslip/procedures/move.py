"""The burst-and-journal loop of a planned move, and the one-process-per-device lock.

A move of ``N`` steps is sent in bursts. Before each burst the joint is journalled as
*in flight* between its last confirmed position and the burst's intended end
(:meth:`~stickslip.devices.positions.DeviceState.intend`, saved); after the controller
confirms the burst, the dead-reckoned end is saved and the mark cleared. A link drop,
a crash or Ctrl-C between the two leaves the joint *uncertain* with bounds, which
``stickslip where`` shows and ``stickslip move`` refuses to plan from until the joint
is re-referenced. So the stored position is exact (to the model) or marked, never
silently wrong.

:func:`device_lock` makes sure one process drives a device at a time: a lock row in
the database names the holder (pid, host, since); a second process is refused with
that name. The lock is portable (SQLite transactions, no ``fcntl``).
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

from .. import kinematics as kin
from ..clock import now_utc
from ..devices.base import Controller, DeviceError, StepsUncertain
from ..devices.positions import DeviceState

__all__ = ["DeviceBusy", "LockStore", "MoveOutcome", "device_lock", "drive"]


class DeviceBusy(RuntimeError):
    """Another process holds the device's lock (the message names it)."""


class LockStore(Protocol):
    """What :func:`device_lock` needs (``stickslip.storage.Store`` implements it)."""

    def acquire_lock(self, device: str, holder: dict[str, Any]) -> dict[str, Any] | None: ...

    def release_lock(self, device: str, pid: int) -> None: ...


@contextmanager
def device_lock(store: LockStore, device: str) -> Iterator[dict[str, Any]]:
    """Hold ``device``'s lock for the ``with`` block; :class:`DeviceBusy` if another process has it."""
    pid = os.getpid()
    me: dict[str, Any] = {"pid": pid, "host": socket.gethostname(), "since": now_utc().isoformat(timespec="seconds")}
    holder = store.acquire_lock(device, me)
    if holder is not None:
        raise DeviceBusy(
            f"{device} is being driven by another stickslip process (pid {holder.get('pid')} on "
            f"{holder.get('host')} since {holder.get('since')}); wait for it to finish, or if that "
            f"process is gone, release the lock with `stickslip where -d {device} --unlock`"
        )
    try:
        yield me
    finally:
        store.release_lock(device, pid)


@dataclass
class MoveOutcome:
    """What a :func:`drive` did: steps sent and confirmed, the bursts, the device error if any."""

    sent: int = 0
    bursts: list[int] = field(default_factory=list)
    error: str | None = None


def drive(
    dev: Controller,
    state: DeviceState,
    joint: int,
    steps: int,
    burst: int,
    reckon: Callable[[int], float],
    save: Callable[[DeviceState], None],
) -> MoveOutcome:
    """Send ``steps`` (signed) to ``joint`` in bursts of at most ``burst``, journalling each.

    ``reckon(n)`` is the dead-reckoned position (rad or m) after ``n`` signed steps from
    the start; ``save(state)`` stores the state (one transaction). A :class:`DeviceError`
    stops the loop and is returned in the outcome with the joint left *uncertain* over
    the failed burst; any other exception (Ctrl-C) propagates with the journal saved.
    A :class:`~stickslip.devices.base.StepsUncertain` narrows that: its ``made`` steps
    are kept as dead-reckoned, the joint is uncertain only up to ``at_most`` (up to its
    end stop if ``None``: a channel may still be driving), or not at all if they agree.
    """
    out = MoveOutcome()
    if burst < 1:
        raise ValueError(f"burst must be >= 1 step, got {burst}")
    sign = 1 if steps > 0 else -1
    while out.sent != steps:
        n = sign * min(burst, abs(steps - out.sent))
        state.intend(joint, reckon(out.sent + n))
        save(state)  # write-ahead: intended before it is sent
        try:
            dev.step(joint, n)
        except StepsUncertain as e:
            out.error = str(e)
            if e.made:
                out.sent += e.made
                out.bursts.append(e.made)
                state.set_position(joint, reckon(out.sent), "dead-reckoned")
            else:  # nothing certainly made: back to the confirmed position, then widen below
                state.set_position(joint, state.positions[joint], state.sources[joint])
            if e.at_most is None:
                spec = kin.joint_spec(joint)
                state.intend(joint, spec.upper if sign > 0 else spec.lower)
            elif e.at_most != e.made:
                state.intend(joint, reckon(out.sent - e.made + e.at_most))
            save(state)
            return out
        except DeviceError as e:
            out.error = str(e)
            return out
        out.sent += n
        out.bursts.append(n)
        state.set_position(joint, reckon(out.sent), "dead-reckoned")
        save(state)  # done: the controller confirmed the burst
    return out
