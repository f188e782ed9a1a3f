"""Calibrating the step-size models from traverses (the paper's Section 3.3, 3.5).

Three ways in, one result object (:class:`Calibration`):

* **paper** — the paper's procedure. Prismatic joint: six traverses at
  ``(q2, theta, psi) = (-pi/2, 0, 0), (0, -pi/2, 0), (0, 0, 0)``, Eqs. (4)–(6), in any
  order. Rotary joint: eight full-range traverses at ``(q3, theta, psi) = (0, 0, 0),
  (12 mm, 0, 0), (12 mm, -pi/2, 0), (0, -pi/2, 0)``; the unloaded ones give
  ``gamma0`` directly, and ``d`` is found by *inverting the exact relation*
  ``gamma_measured = range / integral dq / (gamma0 + d L(q))`` with a bracketed root
  find (:func:`invert_d_exact`), where the paper fitted a quadratic to simulations.
* **paper-quadratic** — the paper's own Eq. 9 method, kept as a comparator
  (:func:`fit_paper_quadratic`): simulate many ``(gamma0, d)``, fit
  ``d = p2 D^2 + p1 D + p0`` with ``D = gamma(theta=0) - gamma0``, invert with it.
  Eq. 9 *as printed* (``3.41 D^2 + 0.025 D + 6.42e-7``) cannot be right: for the
  ``|D| <= 9.2 µrad`` the paper quotes it gives ``d < 1 µrad``, while Fig. 10 reports
  ``d`` up to 24 µrad; the exact relation gives ``d ≈ 2.4 D`` for small ``D``.
* **lsq** — nonlinear least squares on any set of traverses
  (``scipy.optimize.least_squares``), with standard errors, refusing with a clear
  message when the poses cannot determine a parameter.

All values SI: prismatic steps in m, rotary steps in rad.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from . import kinematics as kin
from . import records
from .clock import now_utc
from .measurements import Traverse, measurements_to_csv
from .models import (
    DIRECTIONS,
    JointModel,
    NonPhysicalError,
    Params,
    PrismaticParams,
    RotaryParams,
    direction_label,
    sinusoid_range,
    steps_between,
)

__all__ = [
    "CalibrationError",
    "Calibration",
    "calibrate",
    "calibrate_paper",
    "calibrate_lsq",
    "invert_d_exact",
    "PaperQuadratic",
    "fit_paper_quadratic",
    "EQ9_PRINTED",
    "eq9_printed",
    "ValidationResult",
    "validate",
    "PRISMATIC_PAPER_POSES",
    "ROTARY_PAPER_POSES",
]

FORMAT = "stickslip.calibration"
FORMAT_VERSION = 1

PRISMATIC_PAPER_POSES = {
    "a": (-math.pi / 2, 0.0, 0.0),  # Eq. (4): no axial load, full efficiency
    "b": (0.0, -math.pi / 2, 0.0),  # Eq. (5): no axial load, efficiency 1 - b
    "c": (0.0, 0.0, 0.0),  # Eq. (6): full axial load, efficiency 1 - b
}
"""The paper's prismatic calibration poses ``(q2, theta, psi)`` (rad), by the parameter each yields."""

ROTARY_PAPER_POSES = (
    (0.0, 0.0, 0.0),
    (kin.Q3_MAX, 0.0, 0.0),
    (kin.Q3_MAX, -math.pi / 2, 0.0),
    (0.0, -math.pi / 2, 0.0),
)
"""The paper's joint-2 calibration poses ``(q3 [m], theta, psi)`` (Fig. 7)."""

_POSE_TOL = 1e-3  # rad; poses typed by hand to 3-4 decimals still match
_Q3_TOL = 1e-5  # m
_LOAD_ZERO = 1e-6  # a load coefficient below this counts as "no gravity torque"

UNITS = {
    ("prismatic", "a"): "m",
    ("prismatic", "b"): "1",
    ("prismatic", "c"): "m",
    ("rotary", "gamma0"): "rad",
    ("rotary", "d"): "rad",
}


class CalibrationError(ValueError):
    """The traverses given cannot produce a (physical) calibration; the message says why."""


# ----------------------------------------------------------------------------- exact inversion


def _load_range(start: float, end: float, alpha: float, beta: float) -> tuple[float, float]:
    """Min and max of the load ``alpha cos q + beta sin q`` for q between start and end."""
    mn, mx = sinusoid_range(min(start, end), max(start, end), alpha, beta)
    return float(mn), float(mx)


def invert_d_exact(
    gamma_measured: float,
    gamma0: float,
    start: float,
    end: float,
    alpha: float,
    beta: float,
) -> float:
    """Solve the paper's Eq. 8 for ``d`` from an average step over a traverse, exactly.

    Finds ``d`` such that ``|end - start| / integral dq / (gamma0 + d (alpha cos q +
    beta sin q)) = gamma_measured``. The step count is convex in ``d``; the physical
    root lies on the branch that contains ``d = 0``, between the ``d`` at which the
    step first reaches zero on the way and the ``d`` of the largest reachable
    average. Solved by Brent's method on a bracket, to ~1e-15 rad.

    Parameters
    ----------
    gamma_measured : float
        Average step measured over the traverse, rad.
    gamma0 : float
        Step with no gravity torque at the same q3, rad.
    start, end : float
        The traversed interval of the joint, rad.
    alpha, beta : float
        Load coefficients along the traverse (:func:`stickslip.kinematics.rotary_load_coefficients`).

    Returns
    -------
    float
        ``d``, rad.
    """
    from scipy.optimize import brentq, minimize_scalar

    if not (gamma_measured > 0 and gamma0 > 0):
        raise CalibrationError(f"step sizes must be positive (measured {gamma_measured:.4g}, gamma0 {gamma0:.4g})")
    lmin, lmax = _load_range(start, end, alpha, beta)
    if max(abs(lmin), abs(lmax)) < _LOAD_ZERO:
        raise CalibrationError("the traverse has no gravity torque along it: d cannot be determined from it")
    span = abs(end - start)

    def avg(d: float) -> float:
        return span / float(steps_between(start, end, gamma0, d * alpha, d * beta))

    # d-domain where the step stays > 0 along the traverse
    d_lo = -gamma0 / lmax if lmax > 0 else -math.inf
    d_hi = gamma0 / (-lmin) if lmin < 0 else math.inf
    shrink = 1e-7
    lo = d_lo * (1 - shrink) if math.isfinite(d_lo) else -50 * gamma0
    hi = d_hi * (1 - shrink) if math.isfinite(d_hi) else 50 * gamma0
    # The step count is convex in d, so the average has a single maximum at d_peak.
    # The physical root lies on the side of d_peak that contains d = 0 (no load effect).
    res = minimize_scalar(lambda d: -avg(d), bounds=(lo, hi), method="bounded", options={"xatol": 1e-9 * gamma0})
    d_peak = float(res.x)
    g_peak = avg(d_peak)
    if gamma_measured >= g_peak:
        if gamma_measured > g_peak * (1 + 1e-9):
            raise CalibrationError(
                f"measured average {gamma_measured * 1e6:.4g} µrad is larger than any d can give with "
                f"gamma0 = {gamma0 * 1e6:.4g} µrad (at most {g_peak * 1e6:.4g} µrad): check the traverse and gamma0"
            )
        return d_peak
    a, b = (lo, d_peak) if d_peak >= 0.0 else (d_peak, hi)
    if (avg(a) - gamma_measured) * (avg(b) - gamma_measured) > 0:
        raise CalibrationError(
            f"measured average {gamma_measured * 1e6:.4g} µrad cannot be reached with gamma0 = "
            f"{gamma0 * 1e6:.4g} µrad: the joint would stall on the way"
        )
    return float(brentq(lambda d: avg(d) - gamma_measured, a, b, xtol=1e-18, rtol=1e-14, maxiter=500))


# ----------------------------------------------------------------------------- Eq. 9 comparator

EQ9_PRINTED = (3.41, 0.025, 6.42e-7)
"""Eq. 9 as printed in the paper: ``d = 3.41 D^2 + 0.025 D + 6.42e-7`` (SI, rad)."""


def eq9_printed(delta: float | NDArray[np.float64]) -> NDArray[np.float64]:
    """Eq. 9 exactly as printed (rad in, rad out). Kept to show it is inconsistent with Fig. 10."""
    p2, p1, p0 = EQ9_PRINTED
    delta = np.asarray(delta, dtype=float)
    return p2 * delta**2 + p1 * delta + p0


@dataclass(frozen=True)
class PaperQuadratic:
    """The paper's simulate-and-fit relation ``d = p2 D^2 + p1 D + p0`` (its Eq. 9 method).

    Attributes
    ----------
    coefficients : tuple of float
        ``(p2, p1, p0)`` in SI: ``p2`` in 1/rad, ``p1`` dimensionless, ``p0`` in rad.
    grid : dict
        The simulated grid: arrays ``gamma0``, ``d``, ``delta`` (rad).
    """

    coefficients: tuple[float, float, float]
    grid: dict[str, NDArray[np.float64]] = field(repr=False)

    def d(self, delta: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """``d`` (rad) from ``D = gamma(theta=0) - gamma0`` (rad)."""
        p2, p1, p0 = self.coefficients
        delta = np.asarray(delta, dtype=float)
        return p2 * delta**2 + p1 * delta + p0


def _simulate_full_range_averages(
    gamma0: NDArray, d: NDArray, start: float, end: float, alpha: float, beta: float
) -> NDArray:
    """Step-by-step simulation of each (gamma0, d) pair (the paper's Fig. 8 simulation)."""
    sign = 1.0 if end > start else -1.0
    cos, sin = math.cos, math.sin
    out = np.empty(len(gamma0))
    for i, (g0, dd) in enumerate(zip(gamma0.tolist(), d.tolist(), strict=True)):
        a, b = dd * alpha, dd * beta
        q, n = float(start), 0
        while (end - q) * sign > 0.0:
            g = g0 + a * cos(q) + b * sin(q)
            if g <= 0.0:
                raise NonPhysicalError("a simulated step size is <= 0: shrink the grid")
            q += sign * g
            n += 1
        out[i] = abs(end - start) / n
    return out


def fit_paper_quadratic(
    gamma0_values: Sequence[float] = tuple(np.linspace(20e-6, 100e-6, 5)),
    delta_range: float = 9.2e-6,
    n_d: int = 9,
    start: float = kin.JOINTS[2].upper,
    end: float = kin.JOINTS[2].lower,
    alpha: float = 0.0,
    beta: float = -1.0,
    simulate: str = "exact",
) -> PaperQuadratic:
    """Reproduce the paper's Eq. 9 method: simulate a grid of ``(gamma0, d)``, fit a quadratic.

    For each ``gamma0`` the ``d`` grid is chosen so that ``D = gamma(theta=0) - gamma0``
    spans about ``±delta_range`` (the paper used ±9.2 µrad). Averages come from a
    step-by-step simulation (``simulate="steps"``, as the paper did; seconds) or from the
    exact integral (``"exact"``, the default; the two differ by less than one step in
    ~10^5). The default traverse is joint 2 over its full range at
    ``theta = psi = 0`` (load ``-sin q2``).

    Returns
    -------
    PaperQuadratic
    """
    g0s, ds = [], []
    # first-order slope: D ≈ d * mean load along the traverse
    qs = np.linspace(min(start, end), max(start, end), 2001)
    mload = float(np.mean(alpha * np.cos(qs) + beta * np.sin(qs)))
    lmin, lmax = _load_range(start, end, alpha, beta)
    for g0 in gamma0_values:
        dmax = delta_range / abs(mload)
        # keep every simulated step >= 10 % of gamma0 along the traverse
        d_lo = max(-dmax, -0.9 * g0 / lmax) if lmax > 0 else -dmax
        d_hi = min(dmax, 0.9 * g0 / -lmin) if lmin < 0 else dmax
        for d in np.linspace(d_lo, d_hi, n_d):
            g0s.append(g0)
            ds.append(d)
    g0a, da = np.array(g0s), np.array(ds)
    if simulate == "steps":
        avg = _simulate_full_range_averages(g0a, da, start, end, alpha, beta)
    elif simulate == "exact":
        avg = abs(end - start) / steps_between(start, end, g0a, da * alpha, da * beta)
    else:
        raise ValueError(f"simulate must be 'steps' or 'exact', got {simulate!r}")
    # keep the physical branch only: for each gamma0 the average must still rise with d
    keep = np.ones(len(g0a), dtype=bool)
    for g0 in np.unique(g0a):
        idx = np.nonzero(g0a == g0)[0]
        falling = np.nonzero(np.diff(avg[idx]) <= 0)[0]
        if len(falling):
            keep[idx[falling[0] + 1 :]] = False
    g0a, da, avg = g0a[keep], da[keep], avg[keep]
    delta = avg - g0a
    p2, p1, p0 = np.polyfit(delta, da, 2)
    return PaperQuadratic((float(p2), float(p1), float(p0)), {"gamma0": g0a, "d": da, "delta": delta})


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
                        "unit": UNITS[(m.params.kind, name)],
                    }
                )
        return out

    # -- persistence
    def to_dict(self) -> dict[str, object]:
        """A JSON-ready dict (SI units, named)."""
        return {
            "format": FORMAT,
            "version": FORMAT_VERSION,
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

    @classmethod
    def from_dict(cls, data: dict) -> Calibration:
        """Rebuild from :meth:`to_dict` output; raises ``ValueError`` with the reason on bad input."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f'not a stickslip calibration (expected "format": "{FORMAT}")')
        records.check_calibration_dict(data)
        if data.get("version") != FORMAT_VERSION:
            raise ValueError(
                f"calibration format version {data.get('version')!r} is not supported (expected {FORMAT_VERSION})"
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
        return cls(
            models,
            stderr,
            consts,
            str(data.get("day", "")),
            str(data.get("method", "")),
            dict(data.get("provenance") or {}),
            str(data.get("created", "")),
        )

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


def _display(name: str, joint: int) -> tuple[float, str]:
    if name == "b":
        return 1.0, ""
    return (1e9, "nm") if joint == 3 else (1e6, "µrad")


# ----------------------------------------------------------------------------- helpers


def _close(a: float, b: float, tol: float = _POSE_TOL) -> bool:
    return abs(a - b) <= tol


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


# ----------------------------------------------------------------------------- paper's method


def _paper_prismatic_rows(ts: Sequence[Traverse]) -> dict[str, list[Traverse]] | None:
    found: dict[str, list[Traverse]] = {k: [] for k in PRISMATIC_PAPER_POSES}
    for t in ts:
        for k, (q2, th, ps) in PRISMATIC_PAPER_POSES.items():
            if _close(t.q2, q2) and _close(t.theta, th) and _close(t.psi, ps):
                found[k].append(t)
    return found if all(found.values()) else None


def _classify_rotary(t: Traverse) -> tuple[float, float]:
    al, be = kin.rotary_load_coefficients(t.joint, t.q1, t.q2, t.q3, t.theta, t.psi)
    return float(al), float(be)


def _paper_rotary_rows(ts: Sequence[Traverse]) -> dict[tuple[int, str], list[Traverse]] | None:
    """Group rotary traverses by (q3 knot, 'free'|'loaded'); None unless all four groups exist."""
    found: dict[tuple[int, str], list[Traverse]] = {(k, s): [] for k in (0, 1) for s in ("free", "loaded")}
    for t in ts:
        knot = 0 if abs(t.q3) <= _Q3_TOL else 1 if abs(t.q3 - kin.Q3_MAX) <= _Q3_TOL else None
        if knot is None:
            continue
        al, be = _classify_rotary(t)
        state = "free" if math.hypot(al, be) < _LOAD_ZERO else "loaded"
        found[(knot, state)].append(t)
    return found if all(found.values()) else None


def paper_applicable(traverses: Sequence[Traverse]) -> bool:
    """Whether every (joint, direction) present has the paper's calibration poses."""
    groups = _group(traverses)
    if not groups:
        return False
    for (j, _d), ts in groups.items():
        if (_paper_prismatic_rows(ts) if j == 3 else _paper_rotary_rows(ts)) is None:
            return False
    return True


def _group(traverses: Iterable[Traverse]) -> dict[tuple[int, str], list[Traverse]]:
    g: dict[tuple[int, str], list[Traverse]] = {}
    for t in traverses:
        g.setdefault((t.joint, t.direction), []).append(t)
    return g


def calibrate_paper(
    traverses: Sequence[Traverse],
    day: str | None = None,
    source: str | None = None,
    rotary_inversion: str = "exact",
    quadratic: PaperQuadratic | None = None,
) -> Calibration:
    """The paper's procedure: Eqs. (4)–(6) for joint 3, exact inversion of Eq. (8) for rotary joints.

    Repeated traverses at the same calibration pose are averaged (mean of their
    average steps). Traverses in other poses are not used; the provenance notes say
    how many.

    Parameters
    ----------
    traverses : sequence of Traverse
    day : str, optional
        Session label; default the latest day in the traverses.
    source : str, optional
        Where the traverses came from (file name), for the provenance.
    rotary_inversion : {"exact", "paper-quadratic"}
        ``"paper-quadratic"`` reproduces the paper's Eq. 9 method (with ``quadratic``,
        default :func:`fit_paper_quadratic`) instead of the exact inversion.
    """
    groups = _group(traverses)
    if not groups:
        raise CalibrationError("no traverses to calibrate from")
    models: dict[tuple[int, str], JointModel] = {}
    used = 0
    notes: list[str] = []
    if rotary_inversion == "paper-quadratic" and quadratic is None:
        quadratic = fit_paper_quadratic()
    for (j, d), ts in sorted(groups.items()):
        if j == 3:
            rows = _paper_prismatic_rows(ts)
            if rows is None:
                missing = [
                    f"(q2, theta, psi) = ({', '.join(f'{v:.4g}' for v in pose)})"
                    for k, pose in PRISMATIC_PAPER_POSES.items()
                    if not any(
                        _close(t.q2, pose[0]) and _close(t.theta, pose[1]) and _close(t.psi, pose[2]) for t in ts
                    )
                ]
                raise CalibrationError(
                    f"joint 3{d}: the paper's method needs traverses at {', '.join(missing)} (rad); "
                    "use method 'lsq' for other poses"
                )
            g = {k: float(np.mean([t.gamma for t in rows[k]])) for k in rows}
            a = g["a"]  # Eq. (4)
            b = 1.0 - g["b"] / a  # Eq. (5)
            if not b < 1.0:
                raise CalibrationError(f"joint 3{d}: b = {b:.4g} >= 1 from Eq. (5): non-physical calibration refused")
            c = a - g["c"] / (1.0 - b)  # Eq. (6)
            models[(j, d)] = JointModel(j, d, PrismaticParams(a, b, c))
            used += sum(len(v) for v in rows.values())
        else:
            rows = _paper_rotary_rows(ts)
            if rows is None:
                raise CalibrationError(
                    f"joint {j}{d}: the paper's method needs full-range traverses at q3 = 0 and 12 mm, each with and "
                    "without gravity torque (for joint 2: theta = 0 and theta = -pi/2); "
                    "use method 'lsq' for other poses"
                )
            g0s, dvals = [], []
            for knot in (0, 1):
                g0 = float(np.mean([t.gamma for t in rows[(knot, "free")]]))
                ds = []
                for t in rows[(knot, "loaded")]:
                    al, be = _classify_rotary(t)
                    if rotary_inversion == "exact":
                        ds.append(invert_d_exact(t.gamma, g0, t.start, t.end, al, be))
                    elif rotary_inversion == "paper-quadratic":
                        assert quadratic is not None
                        ds.append(float(quadratic.d(t.gamma - g0)))
                    else:
                        raise ValueError(
                            f"rotary_inversion must be 'exact' or 'paper-quadratic', got {rotary_inversion!r}"
                        )
                g0s.append(g0)
                dvals.append(float(np.mean(ds)))
                used += len(rows[(knot, "free")]) + len(rows[(knot, "loaded")])
            models[(j, d)] = JointModel(j, d, RotaryParams((g0s[0], g0s[1]), (dvals[0], dvals[1])))
    _check_physical(models)
    if used < len(traverses):
        notes.append(
            f"{len(traverses) - used} of {len(traverses)} traverses are not at the paper's calibration "
            "poses and were not used (method 'lsq' fits all of them)"
        )
    consts = {k: _constant_step(k[0], k[1], m) for k, m in models.items()}
    method = "paper" if rotary_inversion == "exact" else "paper-quadratic"
    return Calibration(
        models,
        {k: None for k in models},
        consts,
        _day_of(traverses, day),
        method,
        _provenance(traverses, source, used, notes),
    )


# ----------------------------------------------------------------------------- least squares

# the fit works in nm (a, c), 1 (b) and µrad (gamma0, d) so the problem is well scaled
_PRISMATIC_SCALE = np.array([1e-9, 1.0, 1e-9])
_ROTARY_SCALE = np.array([1e-6, 1e-6, 1e-6, 1e-6])
_HINTS = {
    "a": "traverses at two different |cos q2| (e.g. q2 = -pi/2 and q2 = 0) with a known axial load",
    "b": "traverses at two different |cos q2| (e.g. q2 = -pi/2 and q2 = 0)",
    "c": "a traverse with an axial load (cos(zeta) cos(theta) != 0, e.g. (q2, theta, psi) = (0, 0, 0))",
    "gamma0": "traverses at two different q3 (e.g. 0 and 12 mm), at least one without gravity torque",
    "d": "traverses with gravity torque (e.g. theta = 0) at two different q3",
}


def _residual_fn(j: int, ts: Sequence[Traverse], knots: tuple[float, float]):
    """Relative residuals of joint ``j``'s traverses as a function of the scaled parameters.

    Returns ``(resid, scale)``: ``resid(x)`` is ``predicted / measured - 1`` per traverse
    with SI parameters ``x * scale``.
    """
    cols = {
        k: np.array([getattr(t, k) for t in ts], dtype=float)
        for k in ("start", "end", "q1", "q2", "q3", "theta", "psi")
    }
    meas = np.array([t.gamma for t in ts])
    span = np.abs(cols["end"] - cols["start"])
    if j == 3:
        load = kin.prismatic_load(cols["q1"], cols["q2"], cols["theta"], cols["psi"])
        absc = np.abs(np.cos(cols["q2"]))
        scale = _PRISMATIC_SCALE

        def pred(x: NDArray) -> NDArray:
            a, b, c = x * scale
            return (1.0 - b * absc) * (a - c * load)
    else:
        al, be = kin.rotary_load_coefficients(j, cols["q1"], cols["q2"], cols["q3"], cols["theta"], cols["psi"])
        w = (cols["q3"] - knots[0]) / (knots[1] - knots[0])
        scale = _ROTARY_SCALE

        def pred(x: NDArray) -> NDArray:
            g00, g01, d0, d1 = x * scale
            g0 = g00 + (g01 - g00) * w
            d = d0 + (d1 - d0) * w
            A = g0
            # where the step would be <= 0 along a traverse, return a large residual instead of failing
            with np.errstate(all="ignore"):
                B = np.abs(d) * np.hypot(al, be)
                ok = A > B
                n = np.full(A.shape, np.inf)
                if ok.any():
                    n[ok] = steps_between(cols["start"][ok], cols["end"][ok], A[ok], (d * al)[ok], (d * be)[ok])
            return span / n

    def resid(x: NDArray) -> NDArray:
        return pred(x) / meas - 1.0

    return resid, scale


def _initial_guess(j: int, ts: Sequence[Traverse]) -> NDArray:
    g = np.array([t.gamma for t in ts])
    if j == 3:
        return np.array([np.max(g) * 1e9, 0.2, 0.0])
    m = float(np.median(g)) * 1e6
    return np.array([m, m, 0.0, 0.0])


def _identifiability(j: int, d: str, names: list[tuple[str, float | None]], jac: NDArray) -> None:
    """Refuse when the Jacobian is rank deficient, naming the parameters the poses leave free."""
    n, p = jac.shape
    colnorm = np.linalg.norm(jac, axis=0)
    colnorm[colnorm == 0] = 1.0
    jn = jac / colnorm
    _, s, vt = np.linalg.svd(jn, full_matrices=True)
    s_full = np.zeros(p)
    s_full[: len(s)] = s
    tol = max(n, p) * np.finfo(float).eps * 1e4 * (s_full[0] if s_full[0] > 0 else 1.0)
    null = vt[s_full <= max(tol, 1e-9 * s_full[0])]
    if len(null) == 0:
        return
    involved = np.nonzero(np.any(np.abs(null) > 0.1, axis=0))[0]
    labels = []
    for i in involved:
        name, q3 = names[i]
        labels.append(f"{name}{d}" + (f" (q3 = {q3 * 1e3:g} mm)" if q3 is not None else ""))
    hints = sorted({_HINTS[names[i][0]] for i in involved})
    raise CalibrationError(
        f"joint {j}{d}: the poses given cannot determine {', '.join(labels)} "
        f"({n} traverse{'s' if n != 1 else ''}, {p} parameters, only {p - len(null)} independent); "
        f"add {'; and '.join(hints)}"
    )


def calibrate_lsq(
    traverses: Sequence[Traverse],
    day: str | None = None,
    source: str | None = None,
    knots: tuple[float, float] = (0.0, kin.Q3_MAX),
) -> Calibration:
    """Nonlinear least squares on any set of traverses, per joint and direction.

    Minimises the relative residuals ``gamma_pred / gamma_meas - 1`` of the traverse
    averages (predicted exactly, with the closed-form integral for rotary joints).
    Standard errors come from ``s^2 (J^T J)^-1`` with ``s^2 = RSS / (n - p)``; they are
    ``None`` when the traverses exactly determine the parameters (``n = p``).

    Raises
    ------
    CalibrationError
        When the poses cannot determine a parameter (rank-deficient Jacobian, with the
        parameter named and a hint which pose would help), or the fit is non-physical.
    """
    from scipy.optimize import least_squares

    groups = _group(traverses)
    if not groups:
        raise CalibrationError("no traverses to calibrate from")
    models: dict[tuple[int, str], JointModel] = {}
    stderr: dict[tuple[int, str], NDArray | None] = {}
    notes: list[str] = []
    for (j, d), ts in sorted(groups.items()):
        resid, scale = _residual_fn(j, ts, knots)
        x0 = _initial_guess(j, ts)
        if j == 3:
            names = PrismaticParams(0, 0, 0).names()
            lb, ub = np.array([0.0, 0.0, -np.inf]), np.array([np.inf, 0.999999, np.inf])
            probe = x0 + np.array([0.0, 0.0, 0.05 * x0[0]])
        else:
            names = RotaryParams((0, 0), (0, 0), knots).names()
            lb, ub = np.array([0.0, 0.0, -np.inf, -np.inf]), np.full(4, np.inf)
            probe = x0 + np.array([0.0, 0.0, 0.05 * x0[0], 0.05 * x0[0]])
        # identifiability at a generic point (non-zero load sensitivity), before fitting
        jac0 = _numjac(resid, probe)
        _identifiability(j, d, names, jac0)
        res = least_squares(
            resid, x0, bounds=(lb, ub), x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000, method="trf"
        )
        if not np.all(np.isfinite(res.fun)):
            raise CalibrationError(f"joint {j}{d}: the fit did not converge to a physical model (a step would be <= 0)")
        jac = _numjac(resid, res.x)
        _identifiability(j, d, names, jac)
        n, p = len(ts), len(x0)
        x = res.x * scale
        if n > p:
            s2 = float(res.fun @ res.fun) / (n - p)
            try:
                cov = np.linalg.inv(jac.T @ jac) * s2
                se = np.sqrt(np.clip(np.diag(cov), 0, None)) * scale
            except np.linalg.LinAlgError:
                se = np.full(p, np.nan)
            stderr[(j, d)] = se
        else:
            stderr[(j, d)] = None
            notes.append(f"joint {j}{d}: {n} traverses for {p} parameters: exactly determined, no standard errors")
        params: Params = PrismaticParams.from_vector(x) if j == 3 else RotaryParams.from_vector(x, knots)
        models[(j, d)] = JointModel(j, d, params)
    _check_physical(models)
    consts = {k: _constant_step(k[0], k[1], m) for k, m in models.items()}
    return Calibration(
        models, stderr, consts, _day_of(traverses, day), "lsq", _provenance(traverses, source, len(traverses), notes)
    )


def _numjac(f, x: NDArray) -> NDArray:
    """Central-difference Jacobian of ``f`` at ``x`` (x is well scaled: nm / µrad / 1)."""
    x = np.asarray(x, dtype=float)
    f0 = f(x)
    jac = np.empty((len(f0), len(x)))
    for i in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[i]))
        e = np.zeros_like(x)
        e[i] = h
        jac[:, i] = (f(x + e) - f(x - e)) / (2 * h)
    return jac


_OLD_METHOD_NAMES = {"seed": "paper", "seed-quadratic": "paper-quadratic"}
"""Method names of earlier versions (the paper was called "the seed"), still accepted."""


def calibrate(
    traverses: Sequence[Traverse], method: str = "auto", day: str | None = None, source: str | None = None
) -> Calibration:
    """Calibrate every joint and direction present in ``traverses``.

    Parameters
    ----------
    traverses : sequence of Traverse
    method : {"auto", "paper", "paper-quadratic", "lsq"}
        ``auto`` uses the paper's procedure for every joint and direction whose
        calibration poses the table has, and least squares for the others (the
        calibration's method then reads e.g. ``"paper (3+ 3-), lsq (2+ 2-)"``). The names
        ``"seed"`` and ``"seed-quadratic"`` of earlier versions are still accepted.
    day : str, optional
        Session label (default: the latest day among the traverses).
    source : str, optional
        Where the traverses came from, for the provenance.
    """
    traverses = list(traverses)
    method = _OLD_METHOD_NAMES.get(method, method)
    if method == "auto":
        groups = _group(traverses)
        seed_keys = {k for k, ts in groups.items() if paper_applicable(ts)}
        if not seed_keys:
            method = "lsq"
        elif len(seed_keys) == len(groups):
            method = "paper"
        else:
            by_seed = [t for t in traverses if (t.joint, t.direction) in seed_keys]
            by_lsq = [t for t in traverses if (t.joint, t.direction) not in seed_keys]
            return _merge(calibrate_paper(by_seed, day, source), calibrate_lsq(by_lsq, day, source), traverses, day)
    if method == "paper":
        return calibrate_paper(traverses, day, source)
    if method == "paper-quadratic":
        return calibrate_paper(traverses, day, source, rotary_inversion="paper-quadratic")
    if method == "lsq":
        return calibrate_lsq(traverses, day, source)
    raise ValueError(f"unknown calibration method {method!r} (use auto, paper, paper-quadratic or lsq)")


def _merge(seed: Calibration, lsq: Calibration, traverses: Sequence[Traverse], day: str | None) -> Calibration:
    """One calibration from a paper's-procedure part and a least-squares part (disjoint joints/directions)."""

    def keys(c: Calibration) -> str:
        return " ".join(f"{j}{d}" for j, d in sorted(c.models))

    notes = [
        f"the paper's procedure for {keys(seed)}; least squares for {keys(lsq)}, whose traverses are not all "
        "at the paper's calibration poses",
        *seed.provenance.get("notes", []),  # type: ignore[misc]
        *lsq.provenance.get("notes", []),  # type: ignore[misc]
    ]
    prov = _provenance(traverses, seed.provenance.get("source"), len(traverses), notes)  # type: ignore[arg-type]
    prov["rows_used"] = int(seed.provenance["rows_used"]) + int(lsq.provenance["rows_used"])  # type: ignore[call-overload]
    return Calibration(
        {**seed.models, **lsq.models},
        {**seed.stderr, **lsq.stderr},
        {**seed.constant_steps, **lsq.constant_steps},
        _day_of(traverses, day),
        f"paper ({keys(seed)}), lsq ({keys(lsq)})",
        prov,
    )


# ----------------------------------------------------------------------------- validation


@dataclass(frozen=True)
class ValidationResult:
    """Model against the paper's constant-step comparator on a set of traverses.

    Attributes
    ----------
    traverses : list of Traverse
    measured, predicted, constant : ndarray
        Average steps (m or rad) measured, predicted by the model, and by the constant step.
    """

    traverses: list[Traverse]
    measured: NDArray[np.float64]
    predicted: NDArray[np.float64]
    constant: NDArray[np.float64]

    @property
    def model_error(self) -> NDArray[np.float64]:
        """Relative error of the model per traverse, ``predicted / measured - 1``."""
        return self.predicted / self.measured - 1.0

    @property
    def constant_error(self) -> NDArray[np.float64]:
        """Relative error of the constant step per traverse."""
        return self.constant / self.measured - 1.0

    def rows(self) -> list[dict[str, object]]:
        """Per joint: n, max and mean |relative error| of model and constant step (fractions)."""
        out = []
        joints = np.array([t.joint for t in self.traverses])
        for j in sorted(set(joints.tolist())):
            sel = joints == j
            me, ce = np.abs(self.model_error[sel]), np.abs(self.constant_error[sel])
            out.append(
                {
                    "joint": int(j),
                    "n": int(sel.sum()),
                    "model_max_rel_error": float(me.max()),
                    "model_mean_rel_error": float(me.mean()),
                    "constant_max_rel_error": float(ce.max()),
                    "constant_mean_rel_error": float(ce.mean()),
                }
            )
        return out

    def report(self) -> str:
        lines = ["joint   n   model max  model mean   const max  const mean"]
        for r in self.rows():
            lines.append(
                f"{r['joint']:>5} {r['n']:>3} {r['model_max_rel_error']:>10.2%} {r['model_mean_rel_error']:>11.2%} "
                f"{r['constant_max_rel_error']:>11.2%} {r['constant_mean_rel_error']:>11.2%}"
            )
        return "\n".join(lines)

    def plot(self, ax=None):
        """Relative error of each traverse's average step, model against constant step; returns the Axes.

        Relative errors (%) put the prismatic (nm) and rotary (µrad) joints on one honest
        axis. Traverses are grouped by joint along x.
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4))
        x0 = 0
        for j in sorted({t.joint for t in self.traverses}):
            sel = np.array([t.joint == j for t in self.traverses])
            x = x0 + np.arange(int(sel.sum()))
            ax.plot(x, self.model_error[sel] * 100, "o", label=f"joint {j}: calibrated model")
            ax.plot(x, self.constant_error[sel] * 100, "x", label=f"joint {j}: constant step (paper's comparator)")
            x0 += int(sel.sum()) + 1
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel("traverse (grouped by joint)")
        ax.set_ylabel("predicted / measured average step − 1 (%)")
        ax.legend(fontsize="small")
        return ax


def validate(calibration: Calibration, traverses: Sequence[Traverse]) -> ValidationResult:
    """Compare the model and the constant-step comparator with measured traverses."""
    traverses = list(traverses)
    if not traverses:
        raise ValueError("no traverses to validate against")
    measured = np.array([t.gamma for t in traverses])
    predicted = calibration.predict_many(traverses)
    constant = np.array([calibration.constant_step(t.joint, t.direction) for t in traverses])
    return ValidationResult(traverses, measured, predicted, constant)
