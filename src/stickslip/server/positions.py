"""The control room's named positions: list, save, forget, and drive back to one."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .. import kinematics as kin
from ..procedures import named
from .slot import Busy, Motion, MotionSlot, NotFound, one_line, refusals

__all__ = ["NamedPositions"]


class NamedPositions(MotionSlot):
    """The device's named positions (:mod:`stickslip.procedures.named`) as the room's verbs."""

    def positions(self) -> list[dict[str, object]]:
        """The named positions of the device."""
        try:
            with refusals():
                return [p.as_dict() for p in named.positions(self.store, self.url)]
        finally:
            self.store.close_thread()

    def save_position(self, name: str) -> dict[str, object]:
        """Keep the current positions under ``name`` (refused while a motion runs)."""
        cur = self.current()
        if cur is not None:
            raise Busy(f"{cur.what} is running: a position is saved only while nothing moves")
        try:
            with refusals():
                p = named.save_position(self.store, self.url, name)
        finally:
            self.store.close_thread()
        self.event("info", f"position {name!r} saved")
        return p.as_dict()

    def delete_position(self, name: str) -> dict[str, object]:
        """Forget the named position ``name`` (:class:`NotFound` if there is none)."""
        try:
            named.delete_position(self.store, self.url, name)
        except KeyError as e:
            raise NotFound(one_line(e)) from None
        finally:
            self.store.close_thread()
        return {"deleted": name}

    def go_to(self, name: str) -> Motion:
        """Drive back to the named position ``name`` (:func:`~stickslip.procedures.named.go_to`), as a motion."""
        cal, _ = self._need_calibration("going to a position", borrow=True)
        known = {str(p["name"]): p for p in self.positions()}
        if name not in known:
            raise NotFound(f"{self.key} has no position named {name!r}")
        q_to = known[name]["q"]
        st = self.state()
        path = None
        if isinstance(q_to, list):
            q0 = [st.positions[j] for j in (1, 2, 3)]
            path = [[float(v) for v in kin.tip([a + (b - a) * k / 16 for a, b in zip(q0, q_to, strict=True)],
                                                self.options.geometry)] for k in range(17)]

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            r = named.go_to(self.store, self.url, name, cal, burst=self._burst(), warn=self._warn(m), ready=ready,
                            opener=self._opener)
            out = r.as_dict()
            out["failure"] = r.failure()
            return out

        return self.launch("goto", f"go to {name!r}", body, path)

