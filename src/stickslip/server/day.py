"""The control room's calibration day: the paper's traverses guided from the page, then the calibration."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..clock import today_label
from ..procedures.day import DAY_PLAN, DayProgress, DayRequest, DayTraverse, calibration_day
from ..procedures.move import is_simulator
from ..units import format_step
from .slot import Conflict, Motion, MotionSlot, Refused

__all__ = ["CalibrationDay"]


class CalibrationDay(MotionSlot):
    """The guided calibration day as the room's motion: start or resume it, the pose it waits for, its state."""

    def day_start(self, day: str | None = None, resume: bool = False) -> Motion:
        """Start (or resume) the guided calibration day (:func:`~stickslip.procedures.day.calibration_day`)."""
        with self._lock:
            before = self._day
        done: list[tuple[Any, int]] = []
        label = day or today_label()
        if resume:
            if before is None or not before.get("done"):
                raise Conflict("no calibration day to resume: start one")
            done = list(before["done_rows"])
            label = str(before["day_label"])
        tunings = {j: self._tuning(j) for j in sorted({t.joint for t in DAY_PLAN})}
        request = DayRequest(self.url, label, tunings, burst=self._burst(2) * 5, start_at=len(done))
        simulator = is_simulator(self.url)

        def set_pose(index: int, t: DayTraverse) -> None:
            if not simulator:  # on the simulator the traverse places the arm
                self._wait_for_pose(index, t)

        def body(m: Motion, ready: Callable[[], None]) -> dict[str, Any]:
            st = self.state()
            for i, t in enumerate(DAY_PLAN[len(done):], start=len(done)):  # with a rig: every sweep, first
                p = t.pose
                self.check_sweep(t.joint, t.direction, [p.q1, p.q2, p.q3], st, f"traverse {i + 1} of the day")
            ready()

            def progress(p: DayProgress) -> None:
                self._day_progress(m, p)

            try:
                r = calibration_day(self.store, request, set_pose=set_pose, progress=progress, done=done,
                                    opener=self._opener)
            finally:
                with self._lock:
                    self._level = None
            self.calibration = r.calibration
            self.calibration_source = f"the calibration day {label} (id {r.calibration_id})"
            out = r.as_dict()
            with self._lock:
                if self._day is not None:
                    self._day["result"] = out
            return out

        with self._lock:
            self._day = {"day_label": label, "total": len(DAY_PLAN), "done": len(done), "waiting_for_pose": False,
                         "progress": None, "plan": [t.as_dict() for t in DAY_PLAN], "simulator": simulator,
                         "done_rows": list(done), "result": None}
        return self.launch("day", f"calibration day {label}", body)

    def day_pose_set(self) -> dict[str, Any]:
        """The operator has set the pose the day waits for (a real arm)."""
        with self._lock:
            waiting = self._day is not None and self._day.get("waiting_for_pose")
        if not waiting:
            raise Conflict("the calibration day is not waiting for a pose")
        self._day_pose.set()
        return {"day": "pose set"}

    def day(self) -> dict[str, Any]:
        """The day's plan, progress and result (``{"day": None}`` before one started)."""
        with self._lock:
            d = dict(self._day) if self._day is not None else None
        if d is not None:
            d.pop("done_rows", None)
        return {"day": d}

    def _wait_for_pose(self, index: int, t: DayTraverse) -> None:
        """Wait until the operator says the pose of traverse ``index`` is set (or STOP)."""
        with self._lock:
            if self._day is not None:
                self._day["waiting_for_pose"] = True
            self._day_pose.clear()
        self.event("info", f"calibration day: set the pose for traverse {index + 1}: {t.describe()}")
        while not self._day_pose.wait(0.5):
            pass
        with self._lock:
            if self._day is not None:
                self._day["waiting_for_pose"] = False
        if self.owned.halted:
            raise Refused("stopped (STOP) while waiting for the pose")

    def _day_progress(self, m: Motion, p: DayProgress) -> None:
        """The day's progress into its state, the motion and (a traverse measured) an event and the level."""
        d = p.as_dict()
        with self._lock:
            if self._day is not None:
                self._day["progress"] = d
                if p.stage == "measured" and p.row is not None and p.traverse_id is not None:
                    self._day["done"] = p.index + 1
                    self._day["done_rows"].append((p.row, p.traverse_id))
        if p.stage == "measured" and p.gamma is not None:
            joint = p.traverse.joint
            self.event("info", f"traverse {p.index + 1} of {p.total} measured: joint {joint}"
                       f"{p.traverse.direction}, {p.steps} steps commanded, average step "
                       f"{format_step(p.gamma, joint)}")
            self._level = {"level_db": p.level_db, "band_hz": d["band_hz"]} if p.level_db is not None else None
        m.progress = d
