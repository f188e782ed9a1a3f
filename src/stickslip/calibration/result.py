"""The calibration result: per joint and direction a step-size model, its standard
errors, the constant-step comparator, provenance; JSON save/load, report and plot."""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from .. import records
from ..clock import now_utc
from ..measurements import Traverse, measurements_to_csv
from ..models import (
    DIRECTIONS,
    JointModel,
    NonPhysicalError,
    Params,
    PrismaticParams,
    RotaryParams,
    direction_label,
)

FORMAT = "stickslip.calibration"
FORMAT_VERSION = 1

UNITS = {
    ("prismatic", "a"): "m",
    ("prismatic", "b"): "1",
    ("prismatic", "c"): "m",
    ("rotary", "gamma0"): "rad",
    ("rotary", "d"): "rad",
}


class CalibrationError(ValueError):
    """The traverses given cannot produce a (physical) calibration; the message says why."""


# ----------------------------------------------------------------------------- the result object


@dataclass
class Calibration:
    """A calibration: per joint and direction, a step-size model with its parameters.

    Attributes
    ----------
    models : dict
        ``(joint, direction) -> JointModel``.
    stderr : dict
        ``(joint, direction) -> array`` of standard errors in the order of
        ``params.names()`` (SI), or ``None`` where unknown (exactly determined).
    constant_steps : dict
        ``(joint, direction) -> float``: the paper's constant-step comparator (m or rad).
    day : str
        Session label of the traverses (ISO date preferred).
    method : str
        ``"paper"``, ``"paper-quadratic"`` or ``"lsq"`` (older files say ``"seed"``).
    provenance : dict
        Where the traverses came from (file, sha256, rows used, notes).
    """

    models: dict[tuple[int, str], JointModel]
    stderr: dict[tuple[int, str], NDArray[np.float64] | None]
    constant_steps: dict[tuple[int, str], float]
    day: str
    method: str
    provenance: dict[str, object] = field(default_factory=dict)
    created: str = field(default_factory=lambda: now_utc().isoformat(timespec="seconds"))
    covariance: dict[tuple[int, str], NDArray[np.float64]] = field(default_factory=dict)
    """``(joint, direction) -> covariance`` of the parameters (SI, order of ``params.names()``), where known."""
    sigma_model: dict[tuple[int, str], float] = field(default_factory=dict)
    """``(joint, direction) ->`` relative model error (1 sigma) for prediction intervals, where known."""
    selection: dict[tuple[int, str], dict[str, object]] = field(default_factory=dict)
    """``(joint, direction) ->`` the family chosen, why, and the CV error of every family."""

    # -- access
    @property
    def joints(self) -> list[int]:
        """Joints with a model, ascending."""
        return sorted({j for j, _ in self.models})

    def model(self, joint: int, direction: str | int) -> JointModel:
        """The :class:`JointModel` of ``joint`` in ``direction``; KeyError names what is calibrated."""
        key = (int(joint), direction_label(direction))
        if key not in self.models:
            have = ", ".join(f"{j}{d}" for j, d in sorted(self.models))
            raise KeyError(f"joint {key[0]} direction {key[1]} is not in this calibration (it has: {have})")
        return self.models[key]

    def constant_step(self, joint: int, direction: str | int) -> float:
        """The paper's constant-step comparator for ``joint``/``direction`` (m or rad)."""
        return self.constant_steps[(int(joint), direction_label(direction))]

    def gamma(self, joint: int, direction: str | int, pose: kin.Pose, q: float | None = None) -> float:
        """Mean step size (m or rad) of ``joint`` at ``pose``; ``q`` overrides the joint's own coordinate."""
        p = pose._replace(**{f"q{joint}": q}) if q is not None else pose
        return float(self.model(joint, direction).gamma(p.q1, p.q2, p.q3, p.theta, p.psi))

    def predict(self, traverse: Traverse) -> float:
        """Predicted average step over a traverse (exact; m or rad)."""
        t = traverse
        return float(self.model(t.joint, t.direction).average_gamma(t.start, t.end, t.q1, t.q2, t.q3, t.theta, t.psi))

    def predict_many(self, traverses: Sequence[Traverse]) -> NDArray[np.float64]:
        """Predicted average steps for many traverses (vectorised per joint and direction)."""
        out = np.empty(len(traverses))
        groups: dict[tuple[int, str], list[int]] = {}
        for i, t in enumerate(traverses):
            groups.setdefault((t.joint, t.direction), []).append(i)
        for key, idx in groups.items():
            m = self.model(*key)
            ts = [traverses[i] for i in idx]
            cols = {
                k: np.array([getattr(t, k) for t in ts]) for k in ("start", "end", "q1", "q2", "q3", "theta", "psi")
            }
            out[idx] = m.average_gamma(
                cols["start"], cols["end"], cols["q1"], cols["q2"], cols["q3"], cols["theta"], cols["psi"]
            )
        return out

    def parameters(self) -> list[dict[str, object]]:
        """Every parameter as a record: joint, direction, name, q3 (rotary), value, stderr, unit (SI)."""
        out = []
        for (j, d), m in sorted(self.models.items()):
            se = self.stderr.get((j, d))
            for i, ((name, q3), value) in enumerate(zip(m.params.names(), m.params.as_vector(), strict=True)):
                out.append(
                    {
                        "joint": j,
                        "direction": d,
                        "name": name,
                        "q3": q3,
                        "value": float(value),
                        "stderr": None if se is None or not np.isfinite(se[i]) else float(se[i]),
                        "unit": m.params.unit(name) if hasattr(m.params, "unit") else UNITS[(m.params.kind, name)],
                    }
                )
        return out

    # -- persistence
    def to_dict(self) -> dict[str, object]:
        """A JSON-ready dict (SI units, named).

        A calibration with a model family beyond the paper's is written as version 2 (its
        parameters under ``families``, so that a reader of version 1 refuses it instead of
        misreading it); the others stay version 1, readable by every earlier release.
        """
        from ._ext_json import ext_fields

        ext = ext_fields(self)
        base = {
            "format": FORMAT,
            "version": FORMAT_VERSION if not ext.get("families") else 2,
            "day": self.day,
            "method": self.method,
            "created": self.created,
            "units": "SI: prismatic steps in m, rotary steps in rad, q3 in m; b is dimensionless",
            "parameters": self.parameters(),
            "constant_steps": [
                {"joint": j, "direction": d, "value": v, "unit": "m" if j == 3 else "rad"}
                for (j, d), v in sorted(self.constant_steps.items())
            ],
            "provenance": self.provenance,
        }
        base["parameters"] = [p for p in self.parameters() if not _is_family(self, p)]
        base.update(ext)
        return base

    @classmethod
    def from_dict(cls, data: dict) -> Calibration:
        """Rebuild from :meth:`to_dict` output; raises ``ValueError`` with the reason on bad input."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f'not a stickslip calibration (expected "format": "{FORMAT}")')
        records.check_calibration_dict(data)
        if data.get("version") not in (FORMAT_VERSION, 2):
            raise ValueError(
                f"calibration format version {data.get('version')!r} is not supported (expected {FORMAT_VERSION} or 2)"
            )
        try:
            by_key: dict[tuple[int, str], list[dict]] = {}
            for rec in data["parameters"]:
                by_key.setdefault((int(rec["joint"]), direction_label(rec["direction"])), []).append(rec)
            models, stderr = {}, {}
            for (j, d), recs in by_key.items():
                vals = {(r["name"], r.get("q3")): (float(r["value"]), r.get("stderr")) for r in recs}
                if j == 3:
                    names = [("a", None), ("b", None), ("c", None)]
                    params: Params = PrismaticParams(*(vals[n][0] for n in names))
                else:
                    knots = sorted({float(q3) for (n, q3) in vals if n == "gamma0"})
                    if len(knots) != 2:
                        raise ValueError(f"joint {j}{d}: expected gamma0 at two q3 values, found {len(knots)}")
                    names = [("gamma0", knots[0]), ("gamma0", knots[1]), ("d", knots[0]), ("d", knots[1])]
                    params = RotaryParams(
                        (vals[names[0]][0], vals[names[1]][0]),
                        (vals[names[2]][0], vals[names[3]][0]),
                        (knots[0], knots[1]),
                    )
                models[(j, d)] = JointModel(j, d, params)
                se = [vals[n][1] for n in names]
                stderr[(j, d)] = (
                    None if all(s is None for s in se) else np.array([np.nan if s is None else s for s in se])
                )
            consts = {
                (int(c["joint"]), direction_label(c["direction"])): float(c["value"]) for c in data["constant_steps"]
            }
        except (KeyError, TypeError) as e:
            raise ValueError(f"calibration file is missing or has a malformed field: {e}") from None
        cal = cls(
            models,
            stderr,
            consts,
            str(data.get("day", "")),
            str(data.get("method", "")),
            dict(data.get("provenance") or {}),
            str(data.get("created", "")),
        )
        from ._ext_json import read_ext_fields

        read_ext_fields(cal, data)
        return cal

    def save(self, path: str | Path) -> None:
        """Write the calibration as JSON."""
        records.atomic_write_text(path, json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a calibration JSON file; raises ``ValueError`` naming the file and the reason."""
        p = Path(path)
        try:
            data = json.loads(records.read_json_text(p, "calibration"))
        except FileNotFoundError:
            raise ValueError(f"{p}: no such calibration file") from None
        except json.JSONDecodeError as e:
            raise ValueError(f"{p}: not valid JSON ({e.msg} at line {e.lineno})") from None
        try:
            return cls.from_dict(data)
        except ValueError as e:
            raise ValueError(f"{p}: {e}") from None

    # -- people
    def report(self) -> str:
        """A readable text report of the parameters with standard errors (nm, µrad)."""
        lines = [f"stickslip calibration — day {self.day or '?'}, method {self.method}"]
        for j in self.joints:
            kind = "prismatic" if j == 3 else "rotary"
            lines.append(f"joint {j} ({kind}):")
            for rec in self.parameters():
                if rec["joint"] != j:
                    continue
                scale, unit = _display(rec["name"], j)
                where = f" @ q3 = {rec['q3'] * 1e3:g} mm" if rec["q3"] is not None else ""
                se = f" ± {rec['stderr'] * scale:.3g}" if rec["stderr"] is not None else ""
                lines.append(
                    f"  {rec['name']}{rec['direction']}{where}: {rec['value'] * scale:.5g}{se} {unit}".rstrip()
                )
            for d in DIRECTIONS:
                if (j, d) in self.constant_steps:
                    scale, unit = _display("a" if j == 3 else "gamma0", j)
                    lines.append(f"  constant-step comparator {d}: {self.constant_steps[(j, d)] * scale:.5g} {unit}")
        notes = self.provenance.get("notes") if isinstance(self.provenance, dict) else None
        for n in notes or []:
            lines.append(f"note: {n}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()

    def plot(self, joint: int = 3, ax=None, thetas: Sequence[float] = (0.0, -math.pi / 3, -math.pi / 2)):
        """Model step size against zeta (psi = 0, q1 = 0), like the paper's Figs. 4 and 10.

        Joint 3: one curve per direction and tilt ``theta`` (nm). Rotary joints: one curve
        per direction at q3 = 0 and 12 mm, theta = 0 (µrad). Returns the matplotlib Axes.
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 4))
        spec = kin.JOINTS[2]
        q2 = np.linspace(spec.lower, spec.upper, 400)
        zeta_deg = np.degrees(-q2)
        for d in DIRECTIONS:
            if (joint, d) not in self.models:
                continue
            m = self.models[(joint, d)]
            if joint == 3:
                for th in thetas:
                    g = m.gamma(0.0, q2, 0.0, th, 0.0)
                    ax.plot(zeta_deg, g * 1e9, label=f"γ3{d}, θ = {math.degrees(th):.0f}°")
            else:
                for q3 in (0.0, kin.Q3_MAX):
                    qj = q2 if joint == 2 else np.linspace(kin.JOINTS[1].lower, kin.JOINTS[1].upper, 400)
                    args = (0.0, qj, q3, 0.0, 0.0) if joint == 2 else (qj, -math.pi / 2, q3, -math.pi / 2, 0.0)
                    ax.plot(zeta_deg if joint == 2 else np.degrees(qj), m.gamma(*args) * 1e6,
                            label=f"γ{joint}{d}, q3 = {q3 * 1e3:g} mm")
        ax.set_xlabel("ζ = ψ − q2 (deg)" if joint != 1 else "q1 (deg)")
        ax.set_ylabel("mean step size (nm)" if joint == 3 else "mean step size (µrad)")
        ax.set_title(f"joint {joint}, calibration of {self.day} ({self.method})")
        ax.legend(fontsize="small")
        return ax


def _is_family(cal: Calibration, rec: dict[str, object]) -> bool:
    m = cal.models.get((int(rec["joint"]), str(rec["direction"])))  # type: ignore[call-overload]
    return m is not None and hasattr(m.params, "family")


def _display(name: str, joint: int) -> tuple[float, str]:
    if name in ("b", "b2", "k"):
        return 1.0, ""
    return (1e9, "nm") if joint == 3 else (1e6, "µrad")


# ----------------------------------------------------------------------------- helpers




def _constant_step(joint: int, direction: str, model: JointModel) -> float:
    """The paper's constant-step comparator, computed from a model.

    Prismatic: ``gamma_3i(-pi/2, 0, 0) = a_i``. Joint 2: the full-range average at
    ``(q3, theta, psi) = (0, 0, 0)``. Joint 1 (roles interchanged): the full-range
    average at ``theta = -pi/2``, arm outstretched, ``q3 = 0``.
    """
    if joint == 3:
        return float(model.gamma(0.0, -math.pi / 2, 0.0, 0.0, 0.0))
    spec = kin.JOINTS[joint]
    start, end = (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)
    theta = 0.0 if joint == 2 else -math.pi / 2
    return float(model.average_gamma(start, end, 0.0, -math.pi / 2, 0.0, theta, 0.0))


def _provenance(traverses: Sequence[Traverse], source: str | None, used: int, notes: list[str]) -> dict:
    text = measurements_to_csv(traverses)
    return {
        "source": source,
        "sha256": hashlib.sha256(text.encode()).hexdigest(),
        "rows": len(traverses),
        "rows_used": used,
        "days": sorted({t.day for t in traverses}),
        "notes": notes,
    }


def _day_of(traverses: Sequence[Traverse], day: str | None) -> str:
    if day:
        return day
    days = sorted({t.day for t in traverses})
    return days[-1] if days else ""


def _check_physical(models: dict[tuple[int, str], JointModel]) -> None:
    for (j, d), m in sorted(models.items()):
        try:
            m.params.check_physical()
        except NonPhysicalError as e:
            raise CalibrationError(f"joint {j}{d}: non-physical calibration refused: {e}") from None


def _group(traverses: Iterable[Traverse]) -> dict[tuple[int, str], list[Traverse]]:
    g: dict[tuple[int, str], list[Traverse]] = {}
    for t in traverses:
        g.setdefault((t.joint, t.direction), []).append(t)
    return g
