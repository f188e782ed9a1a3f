"""The control room's STOP: this arm's, and the rig's (every arm of it, whichever server drives it).

STOP on the page, ``POST /api/stop`` or the socket's ``stop`` halts this server's controller
at once (:class:`~.owned.OwnedController`) and, on a rig's server (``serve --rig``), presses
the rig's STOP in the store (:func:`stickslip.procedures.rigstop.press`), from a thread of its
own. Every server of the rig reads it before each burst (:meth:`Stopping._rig_poll`, the
controller's ``before_burst``) and stops there as for its own STOP, saying why.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from ..procedures import rigstop
from ..rig import Rig
from .slot import MotionSlot, Presses, one_line

__all__ = ["Stopping"]


class Stopping(MotionSlot):
    """STOP, this arm's and the rig's (see the module docstring)."""

    _presses: Presses
    _jog_latched: bool

    def stop(self, press: str | None = None) -> dict[str, Any]:
        """STOP: no further burst, the controller told to stop now, a jog or a day ended. Never refused; said once
        per ``press`` (:class:`~.slot.Presses`). A rig's server also presses the rig's STOP (every arm's server
        stops before its next burst: :mod:`stickslip.procedures.rigstop`), once per press, from a thread of its
        own (this one never waits on the store)."""
        out, first = self._stop_here(press)
        rig = self.options.rig
        if first and rig is not None:
            threading.Thread(target=self._press_rig, args=(rig,), name="rig-stop", daemon=True).start()
        return out

    def _press_rig(self, rig: Rig) -> None:
        arm = rig.arm(self.options.arm).name
        try:
            rigstop.press(self.store, rig, arm)
            self.event("warning", f"STOP sent to every arm of rig {rig.name!r}")
        except Exception as e:  # noqa: BLE001 - said, not raised: this arm stopped either way
            self.event("error", f"STOP did not reach the other arms of rig {rig.name!r} ({one_line(e)}): press "
                       "STOP on each arm's page")
        finally:
            self.store.close_thread()

    def _rig_poll(self) -> str | None:
        """Before a burst: the rig's STOP pressed on another arm's page since this motion began stops it here (why)."""
        watch = self._rig_watch
        why = None if watch is None else watch.stopped(self.store)
        if why is not None:
            self._stop_here(None, why)
        return why

    def _stop_here(self, press: str | None, why: str | None = None) -> tuple[dict[str, Any], bool]:
        """This arm's STOP (``why``: the rig's, pressed elsewhere); what :meth:`stop` says, and whether the press
        was new."""
        t = time.monotonic()
        self.owned.halt()
        with self._lock:
            m = self._motion
            pad = self._pad
            running = m is not None and m.active
            if running and m is not None and m.stop_requested is None:
                m.stop_requested = t
            self._day_pose.set()  # a day waiting for a pose wakes up to find the STOP
            if pad is not None:  # the key still held (its keep-alives) must not start the jog again
                self._jog_latched = True
        if pad is not None:
            pad.end()
        what = m.what if running and m is not None else None
        first = self._presses.first(press)
        if why is not None:
            self.event("warning", f"{what}: {why}" if what else why)
        elif first:
            self.event("warning", f"STOP: {what} stopped" if what else "STOP (nothing was moving)")
        return {"stopped": what, "motion": m.id if running and m is not None else None}, first
