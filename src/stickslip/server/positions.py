"""The control room's named positions: list, save, forget, and drive back to one.

Without a rig these are the device's saved positions (:mod:`stickslip.procedures.named`).
With a rig (``serve --rig``) they are one set: the rig file's positions of the room's arm
(read-only, each with its order) and those saved through the server; every one is
reached in its safe order with the whole path checked against the rig's envelope
(:func:`stickslip.procedures.arms.go_to_position`). A saved position has no order of its
own: joint 3 moves first when it retracts, last when it extends
(:func:`~stickslip.procedures.arms.safe_order`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .. import kinematics as kin
from ..procedures import named
from ..procedures.arms import go_to_position, safe_order
from ..rig import NamedPosition as RigPosition
from ..units import format_position
from .slot import Busy, Conflict, Motion, MotionSlot, NotFound, one_line, refusals

__all__ = ["NamedPositions"]


class NamedPositions(MotionSlot):
    """The device's named positions (:mod:`stickslip.procedures.named`), and a rig's, as the room's verbs."""

    def _rig_positions(self) -> dict[str, RigPosition]:
        """The rig file's named positions of the room's arm, by name (none without a rig)."""
        rig = self.options.rig
        if rig is None:
            return {}
        arm = rig.arm(self.options.arm).name
        return {p.name: p for p in rig.positions if p.arm == arm}

    def positions(self) -> list[dict[str, object]]:
        """The named positions: the rig file's first (``source`` ``"rig"``, with their order), then the saved ones."""
        rig = self._rig_positions()
        out: list[dict[str, object]] = []
        for p in rig.values():
            out.append({
                "name": p.name, "q": list(p.q), "saved_at": None, "source": "rig", "order": list(p.order),
                "display": ["unchanged" if v is None else format_position(v, j)
                            for j, v in zip((1, 2, 3), p.q, strict=True)],
            })
        try:
            with refusals():
                saved = named.positions(self.store, self.url)
        finally:
            self.store.close_thread()
        for s in saved:
            if s.name not in rig:  # a name the rig file has is the rig file's (saving one is refused)
                out.append({**s.as_dict(), "source": "saved", "order": None})
        return out

    def save_position(self, name: str) -> dict[str, object]:
        """Keep the current positions under ``name`` (refused while a motion runs, or for a rig file's name)."""
        cur = self.current()
        if cur is not None:
            raise Busy(f"{cur.what} is running: a position is saved only while nothing moves")
        if name in self._rig_positions():
            where = self.options.rig.path if self.options.rig is not None else ""
            raise Conflict(f"{name!r} is a named position of the rig file {where}: it is changed there, not here; "
                           "choose another name")
        try:
            with refusals():
                p = named.save_position(self.store, self.url, name)
        finally:
            self.store.close_thread()
        self.event("info", f"position {name!r} saved")
        return {**p.as_dict(), "source": "saved", "order": None}

    def delete_position(self, name: str) -> dict[str, object]:
        """Forget the named position ``name`` (:class:`NotFound` if there is none; a rig file's is refused)."""
        if name in self._rig_positions():
            raise Conflict(f"{name!r} is a named position of the rig file: it is removed there, not here")
        try:
            named.delete_position(self.store, self.url, name)
        except KeyError as e:
            raise NotFound(one_line(e)) from None
        finally:
            self.store.close_thread()
        return {"deleted": name}

    def go_to(self, name: str) -> Motion:
        """Drive to the named position ``name`` (:func:`~stickslip.procedures.named.go_to`), as a motion.

        With a rig: in the position's order (a saved one: :func:`~stickslip.procedures.arms.safe_order`),
        the whole path checked against the envelope first.
        """
        cal, _ = self._need_calibration("going to a position", borrow=True)
        known = {str(p["name"]): p for p in self.positions()}
        if name not in known:
            raise NotFound(f"{self.key} has no position named {name!r}")
        st = self.state()
        q0 = [st.positions[j] for j in (1, 2, 3)]
        raw = known[name]["q"]
        q_to = [a if b is None else float(b) for a, b in zip(q0, raw if isinstance(raw, list) else q0, strict=True)]
        order = known[name].get("order")
        order = tuple(order) if isinstance(order, list) else safe_order(q0, q_to)
        poses, q = [list(q0)], list(q0)
        for j in order:
            q[j - 1] = q_to[j - 1]
            poses.append(list(q))
        path = [[float(v) for v in kin.tip([a + (b - a) * k / 8 for a, b in zip(p0, p1, strict=True)],
                                           self.options.geometry)]
                for p0, p1 in zip(poses[:-1], poses[1:], strict=True) for k in range(9)]
        rig = self.options.rig

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            if rig is None:
                r = named.go_to(self.store, self.url, name, cal, burst=self._burst(), warn=self._warn(m), ready=ready,
                                opener=self._opener)
                out = r.as_dict()
                out["failure"] = r.failure()
                return out
            target = RigPosition(name, rig.arm(self.options.arm).name,
                                 (q_to[0], q_to[1], q_to[2]), order)
            moves = go_to_position(self.store, rig, self.options.arm, target, cal, burst=self._burst(),
                                   warn=self._warn(m), ready=ready, opener=self._opener, device=self.url)
            return {"position": {k: v for k, v in known[name].items()}, "order": list(order),
                    "moves": [r.as_dict() for r in moves],
                    "failure": next((f for f in (r.failure() for r in moves) if f is not None), None)}

        return self.launch("goto", f"go to {name!r}", body, path)
