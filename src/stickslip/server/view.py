"""The control room's live view: the kept state as each procedure saves it, the calibration, the history.

Built from memory (:meth:`LiveView.snapshot`), so the live view costs no database read.
"""

from __future__ import annotations

import math
from typing import Any

from .. import kinematics as kin
from ..devices.base import KnowsTruePosition
from ..devices.positions import load_state
from ..procedures.jog import JogStatus
from ..procedures.where import state_rows
from ..units import format_position, format_spread
from .slot import Conflict, MotionSlot, one_line, refusals

__all__ = ["LiveView"]


class LiveView(MotionSlot):
    """The live view of the room: joints ± sd, the tip ± sd, the motion, jog, day, audio level; the calibration."""

    def _saw_state(self, device: str, value: dict[str, Any]) -> None:
        if device != self.key:
            return
        try:
            st = load_state(_OneValue(value), device)
        except ValueError:
            return
        with self._lock:
            self._state = st

    def snapshot(self) -> dict[str, Any]:
        """The live view: joints ± sd, the tip ± sd, the simulator's truth, the motion, jog, day, audio level."""
        state = self.state()
        rows = state_rows(state)
        with self._lock:
            running = self._motion is not None and self._motion.active
        geom = self.options.geometry
        q = [state.positions[j] for j in (1, 2, 3)]
        sd = []
        for j, r in zip((1, 2, 3), rows, strict=True):
            spec = kin.joint_spec(j)
            r["lower"], r["upper"] = spec.lower, spec.upper
            s = r.get("sd")
            if j in state.uncertain:
                lo, hi = state.uncertain[j]
                s = (hi - lo) / math.sqrt(12.0)  # spread of a position known only to lie in [lo, hi]
                r["uncertain_display"] = f"{format_position(lo, j)} to {format_position(hi, j)}"
                if running:  # a burst in flight (journalled before it is sent): moving, not lost
                    r["source"] = "moving"
            sd.append(float(s) if isinstance(s, (int, float)) else 0.0)
            shown = j not in state.uncertain  # an uncertain joint shows its bounds instead
            r["sd_display"] = format_spread(float(s), j) if shown and isinstance(s, (int, float)) else None
        tip = [float(v) for v in kin.tip(q, geom)]
        tip_sd = [float(v) for v in kin.tip_sd(q, sd, geom)]
        truth = None
        dev = self.owned.dev
        if isinstance(dev, KnowsTruePosition):
            tq = [float(dev.position(j)) for j in (1, 2, 3)]
            truth = {"q": tq, "tip": [float(v) for v in kin.tip(tq, geom)],
                     "display": [format_position(v, j) for j, v in zip((1, 2, 3), tq, strict=True)]}
        with self._lock:
            m = self._motion
            motion = m.as_dict(full=False) if m is not None else None
            if motion is not None:
                motion["path"] = m.path if m is not None and m.active else None
            jog_status = _jog_dict(self._jog_status) if self._pad is not None and self._jog_status else None
            day = {k: v for k, v in self._day.items() if k != "done_rows"} if self._day is not None else None
            level = dict(self._level) if self._level is not None else None
        return {
            "device": self.key, "model": self.info.model, "joints": rows, "tip": tip, "tip_sd": tip_sd, "truth": truth,
            "theta": state.theta, "psi": state.psi,
            "moving": bool(m is not None and m.active and m.status == "running"),
            "motion": motion, "jog": jog_status, "day": day, "audio": level,
            "calibration": self.calibration_summary(), "rig": self.rig_summary(),
        }

    def rig_summary(self) -> dict[str, Any] | None:
        """The rig the room drives an arm of: its name, the arm, its volumes and margins (None without one)."""
        rig = self.options.rig
        if rig is None:
            return None
        return {"name": rig.name, "arm": rig.arm(self.options.arm).name, "n_sigma": rig.n_sigma,
                "arm_distance": rig.arm_distance, "volumes": [{"name": v.name, "shape": v.shape, "margin": v.margin}
                                                              for v in rig.volumes]}

    def calibration_summary(self) -> dict[str, Any] | None:
        """The calibration in use: day, method, joints, where it came from (None without one)."""
        cal = self.calibration
        if cal is None:
            return None
        return {"day": cal.day, "method": cal.method, "joints": sorted(cal.joints), "source": self.calibration_source}

    def calibration_detail(self) -> dict[str, Any]:
        """The calibration in use: summary, parameters with standard errors (SI), its report."""
        cal = self.calibration
        if cal is None:
            return {"calibration": None}
        params = [{**p.to_dict(), "label": p.label} for p in cal.parameters()]
        return {"calibration": self.calibration_summary(), "parameters": params, "report": cal.report()}

    def history(self) -> dict[str, Any]:
        """The device's sessions (``stickslip history``) and its calibrations."""
        try:
            s = self.store.store()
            return {"device": self.key, "sessions": s.history(self.key), "calibrations": s.calibrations(self.key)}
        finally:
            self.store.close_thread()

    def anova(self) -> dict[str, Any]:
        """The ANOVA of the device's stored traverses (:func:`stickslip.analysis.anova`, as ``stickslip anova``)."""
        from ..analysis import anova

        try:
            traverses = self.store.store().traverses(device=self.key)
        finally:
            self.store.close_thread()
        if not traverses:
            return {"traverses": 0, "tests": [], "skipped": [],
                    "report": f"no traverses stored for {self.key} yet: run the calibration day"}
        try:
            with refusals():
                res = anova(traverses)
        except ImportError as e:
            raise Conflict(f"the ANOVA needs the stats extra (pip install 'stickslip[stats]'): {one_line(e)}") from None
        return {"traverses": len(traverses), "tests": res.rows(), "skipped": res.skipped, "report": res.report()}


class _OneValue:
    """A state store holding one device's kept positions (to read what a procedure just saved)."""

    def __init__(self, value: dict[str, Any]):
        self.value = value

    def get_state(self, device: str, key: str, default: Any = None) -> Any:
        return self.value if key == "positions" else default

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        raise AssertionError("read only")


def _jog_dict(s: JogStatus) -> dict[str, Any]:
    return {
        "q": list(s.q), "tip": list(s.tip), "speed": s.speed, "velocity": list(s.velocity), "rates": list(s.rates),
        "sent": list(s.sent), "message": s.message,
    }
