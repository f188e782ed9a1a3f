"""The rig-wide STOP: one press stops every arm of a rig, whichever process drives it (docs/rig.md).

Each arm of a rig may be driven by a process of its own (a ``stickslip serve --rig R --arm A``,
a ``stickslip move --rig R --arm A``); what they share is the store. A STOP pressed for one arm
(:func:`press`) counts up the rig's stop in the store, under the rig's name; every process that
drives an arm of the rig reads it before each burst (:class:`RigStopWatch`, through
:func:`stoppable`) and sends no further burst once it has changed since its motion began: the
burst is refused with :class:`~stickslip.devices.base.BurstStopped` (no step made), so the
move ends with its position kept exact. A motion begun after the press is not stopped by it.
The latency is one burst (the one being sent when the press is read) plus one read of the store.
Each press is told apart by a token of its own, not by its count alone: two presses at once (from two
servers, or a server and a terminal) both read count N and both write N + 1, and a motion begun
between the two writes must still be stopped by the second.

The count is a small JSON value in the store's per-device state (portable: one SQLite or
PostgreSQL transaction, no file lock), under the device name ``rig://stop/NAME`` (:func:`_device`).
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Callable
from typing import Any
from urllib.parse import quote

from ..clock import now_utc
from ..devices.base import BurstStopped, Controller, ControllerProxy
from ..devices.positions import StateStore
from ..rig import Rig

__all__ = ["RigStopWatch", "press", "pressed", "stoppable"]

_KEY = "stop"


def _device(rig: Rig) -> str:
    """The name the rig's stop is kept under in the store's per-device state: a URL of its own scheme (the store
    names every device by its URL's key), the rig's name percent-encoded (any text a rig file gives it) in its
    path, which the key keeps as written (a URL's host is lowercased: rigs 'Bench' and 'bench' shared one STOP)."""
    return f"rig://stop/{quote(rig.name, safe='')}"


def pressed(store: StateStore, rig: Rig) -> dict[str, Any]:
    """The rig's last STOP as kept: ``{"count": N, "arm": name, "at": ISO time}`` (``count`` 0: never pressed)."""
    raw = store.get_state(_device(rig), _KEY)
    if not _readable(raw):  # hand-edited or corrupted (a string, a bool, a negative count): never pressed
        return {"count": 0, "arm": None, "at": None}
    return dict(raw)


def _readable(raw: object) -> bool:
    """Whether ``raw`` is a STOP record as :func:`press` writes it (a count >= 0, an arm's name or none)."""
    if not isinstance(raw, dict):
        return False
    count, arm = raw.get("count"), raw.get("arm")
    return type(count) is int and count >= 0 and (arm is None or isinstance(arm, str))


def _identity(p: dict[str, Any]) -> tuple[int, str | None]:
    """What tells one press from another: its count and its token (two presses at once may write one count)."""
    token = p.get("press")
    return int(p["count"]), token if isinstance(token, str) else None


def press(store: StateStore, rig: Rig, arm: str | None) -> int:
    """Press the rig's STOP for ``arm`` (where it was pressed; ``None``: a terminal, ``stickslip rig stop``): every
    arm's process stops before its next burst. The new count. ``OSError`` (or the store's error) if the store
    cannot be written."""
    count = int(pressed(store, rig)["count"]) + 1
    store.set_state(_device(rig), _KEY, {"count": count, "arm": arm, "at": now_utc().isoformat(timespec="seconds"),
                                         "pid": os.getpid(), "press": secrets.token_hex(8)})
    return count


class RigStopWatch:
    """Whether the rig's STOP was pressed since :meth:`begin` (a motion's start), by another arm than ``arm``."""

    def __init__(self, rig: Rig, arm: str) -> None:
        self.rig, self.arm = rig, arm
        self._seen: tuple[int, str | None] = (0, None)

    def begin(self, store: StateStore) -> None:
        """A motion begins: presses before now do not stop it."""
        self._seen = _identity(pressed(store, self.rig))

    def stopped(self, store: StateStore) -> str | None:
        """Why this arm must stop (one line), if the rig's STOP was pressed since :meth:`begin`; else ``None``.
        A press for this same arm is its own STOP (its process stopped itself already): ``None``. A store that
        cannot be read (SQLite's "database is locked", a file gone bad) stops it too, the safe side: it is read
        inside a controller's ``step``, where its ``OSError`` would read as the driver's own failure
        (:data:`~stickslip.procedures.move.DRIVER_FAILURES`) and leave the joint uncertain over a burst never sent."""
        try:
            p = pressed(store, self.rig)
        except (OSError, ValueError) as e:
            return f"stopped: the rig's STOP could not be read ({e}); no further burst sent"
        if _identity(p) == self._seen:
            return None
        self._seen = _identity(p)
        if p.get("arm") == self.arm:
            return None
        if not p["count"]:  # the record gone or unreadable since the motion began: stopped, the safe side
            return "stopped: the rig's STOP record in the store was removed or is unreadable; no further burst sent"
        where = "from a terminal" if p.get("arm") is None else f"for arm {p.get('arm')!r}"
        return f"stopped by the rig's STOP (pressed {where} at {p.get('at')}): no further burst sent"


class _Stoppable(ControllerProxy):
    """A controller that reads the rig's STOP before each burst (:func:`stoppable`)."""

    def __init__(self, inner: Controller, store: StateStore, watch: RigStopWatch) -> None:
        super().__init__(inner)
        self._store, self._watch = store, watch

    def step(self, joint: int, n: int) -> None:
        why = self._watch.stopped(self._store)
        if why is not None:
            raise BurstStopped(why, 0)
        self._inner.step(joint, n)


def stoppable(
    opener: Callable[[str], Controller], store: StateStore, rig: Rig, arm: str
) -> Callable[[str], Controller]:
    """An opener whose controllers send no further burst once the rig's STOP is pressed for another arm (what a
    command driving one arm of a rig opens its controller with); a press before it opens does not count."""

    def open_stoppable(url: str) -> Controller:
        watch = RigStopWatch(rig, arm)
        watch.begin(store)
        return _Stoppable(opener(url), store, watch)

    return open_stoppable
