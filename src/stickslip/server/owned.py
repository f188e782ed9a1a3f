"""The device and the store as the server holds them: opened once, shared by every procedure it calls.

A procedure (:func:`stickslip.procedures.move.move` and its siblings) opens its
controller through an ``opener`` and closes it when done, and holds the device's lock in
the store while it drives. The server opens the controller once and holds the lock for
its whole life, so it hands the procedures

* :class:`OwnedController`: the one open controller, whose ``close`` is the server's
  (a no-op for a procedure), with STOP built in: :meth:`~OwnedController.halt` sends no
  further burst and tells the controller to stop at once;
* :class:`HeldStore`: the store with the lock already held (the server's motion slot
  lets one motion run at a time) and every saved state kept in memory too, for the live
  view.
"""

from __future__ import annotations

import copy
import json
import threading
from collections.abc import Callable, Sequence
from typing import Any

from ..calibration import Calibration
from ..devices.base import (
    BurstStopped,
    Controller,
    DeviceError,
    DeviceInfo,
    KnowsTruePosition,
    StepsUncertain,
)
from ..measurements import Traverse
from ..storage import Store

__all__ = ["HeldStore", "OwnedController", "StoreFactory"]


class OwnedController:
    """The server's one open controller, as the procedures see it (a :class:`~stickslip.devices.base.Controller`).

    ``close`` does nothing (the server closes :attr:`dev` when it stops). Capabilities the
    controller has (a pose to set, a true position, a clock, a microphone) are answered
    by the controller itself, so a procedure treats a served simulator as it treats one
    it opened.

    After :meth:`halt` (STOP) no burst is sent until :meth:`resume` (the next motion):
    a burst asked for raises :class:`~stickslip.devices.base.BurstStopped` with no step
    made. A burst in progress is told to stop; a controller that counts what it made
    (the simulator in real time) says so itself, while for a real controller whose
    burst returned normally although STOP came during it, the burst may have been cut
    short, and :class:`~stickslip.devices.base.StepsUncertain` keeps the joint uncertain
    over it.
    """

    def __init__(self, dev: Controller):
        self.dev = dev
        self._halted = threading.Event()
        self._exact = isinstance(dev, KnowsTruePosition)  # a simulator: a burst that returned was made whole
        self.before_burst: Callable[[], str | None] | None = None
        """Called before each burst while not halted: a reason (the rig's STOP, pressed on another arm's page) ends
        the motion there, no step made (the room halts this controller as for its own STOP)."""

    def __getattr__(self, name: str) -> Any:
        dev = self.__dict__.get("dev")
        if dev is None:
            raise AttributeError(name)
        return getattr(dev, name)  # set_pose, position, clock_s, microphone, ... where the controller has them

    @property
    def info(self) -> DeviceInfo:
        """The controller's info."""
        return self.dev.info

    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint`` (Hz)."""
        self.dev.set_frequency(joint, hz)

    def frequency(self, joint: int) -> float:
        """The stepping frequency of ``joint`` (Hz)."""
        return self.dev.frequency(joint)

    def step(self, joint: int, n: int) -> None:
        """Send a burst, unless STOP was pressed since the motion began (see the class)."""
        if self.before_burst is not None and not self._halted.is_set() and (why := self.before_burst()) is not None:
            raise BurstStopped(why, 0)
        if self._halted.is_set():
            raise BurstStopped("stopped (STOP): no further burst sent", 0)
        try:
            self.dev.step(joint, n)
        except StepsUncertain:
            raise
        if self._halted.is_set() and not self._exact:
            raise StepsUncertain("stopped (STOP) during a burst, which may have been cut short", 0, n)

    def stop(self, joint: int | None = None) -> None:
        """Tell the controller to stop ``joint`` (or all)."""
        self.dev.stop(joint)

    def settings(self) -> dict[str, object]:
        """The controller's settings."""
        return self.dev.settings()

    def close(self) -> None:
        """Nothing: the server closes the controller when it stops (:meth:`shutdown`)."""

    @property
    def halted(self) -> bool:
        """Whether STOP was pressed since the current motion began."""
        return self._halted.is_set()

    def halt(self) -> None:
        """STOP: send no further burst, and tell the controller to stop every joint now. Never raises."""
        self._halted.set()
        try:
            self.dev.stop()
        except (DeviceError, OSError, ValueError):
            pass  # no further burst is sent either way

    def resume(self) -> None:
        """A new motion begins: bursts may be sent again."""
        self._halted.clear()

    def shutdown(self) -> None:
        """Stop everything and close the controller (the server is stopping)."""
        self.halt()
        try:
            self.dev.close()
        except (DeviceError, OSError):
            pass


StoreFactory = Callable[[], Store]
"""Opens a :class:`~stickslip.storage.Store` (one per thread: a SQLite connection stays in its thread)."""


class HeldStore:
    """The server's store as a procedure sees it: the device lock held, saved states seen live.

    Each thread gets its own connection (SQLite connections stay in the thread that opened
    them); :meth:`close_thread` closes the calling thread's. ``acquire_lock`` always
    succeeds: the server took the device's lock when it started and keeps it, and lets
    one motion run at a time. Every ``set_state`` of the kept positions is also handed
    to ``on_state(device, value)`` (the live view reads that, not the database).
    """

    def __init__(self, factory: StoreFactory, on_state: Callable[[str, dict[str, Any]], None]):
        self._factory = factory
        self._local = threading.local()
        self._on_state = on_state
        self._all: list[Store] = []
        self._lock = threading.Lock()

    def store(self) -> Store:
        """The calling thread's store (opened on first use)."""
        s: Store | None = getattr(self._local, "store", None)
        if s is None:
            s = self._factory()
            self._local.store = s
            with self._lock:
                self._all.append(s)
        return s

    def close_thread(self) -> None:
        """Close the calling thread's connection (a motion's thread, when it ends)."""
        s: Store | None = getattr(self._local, "store", None)
        if s is not None:
            self._local.store = None
            with self._lock:
                if s in self._all:
                    self._all.remove(s)
            s.close()

    def close_all(self) -> None:
        """Close every connection still open (the server is stopping)."""
        with self._lock:
            stores, self._all = self._all, []
        for s in stores:
            try:
                s.close()
            except Exception:  # noqa: BLE001 - closing at exit: a connection of a thread that died
                pass

    # -- what the procedures call ----------------------------------------------------------

    def acquire_lock(self, device: str, holder: dict[str, Any]) -> dict[str, Any] | None:
        """The server holds the lock: always taken (the motion slot admits one motion)."""
        return None

    def release_lock(self, device: str, pid: int) -> None:
        """The server keeps the lock until it stops."""

    def get_state(self, device: str, key: str, default: Any = None) -> Any:
        """A kept value of ``device`` (the store's)."""
        return self.store().get_state(device, key, default)

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        """Keep a value of ``device``; the kept positions are also shown live."""
        self.store().set_state(device, key, value_json)
        if key == "positions":
            value = json.loads(value_json) if isinstance(value_json, str) else copy.deepcopy(value_json)
            self._on_state(device, value)

    def add_traverse(self, t: Traverse, device: str = "sim://", how: str = "audio") -> int:
        """Store a measured traverse; its id."""
        return self.store().add_traverse(t, device=device, how=how)

    def add_calibration(self, cal: Calibration, device: str = "sim://", traverse_ids: Sequence[int] = ()) -> int:
        """Store a calibration and the traverses it used; its id."""
        return self.store().add_calibration(cal, device, list(traverse_ids))
