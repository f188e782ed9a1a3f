"""The calibration result: per joint and direction a step-size model, its standard
errors, the constant-step comparator, provenance; JSON save/load, report and plot."""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from matplotlib.axes import Axes

from .. import kinematics as kin
from .. import plotting, records
from ..clock import day_label_problem, now_utc
from ..measurements import Traverse, check_pose, check_traverses, measurements_to_csv
from ..models import (
    DIRECTIONS,
    JointModel,
    NonPhysicalError,
    Params,
    PrismaticParams,
    RotaryParams,
    direction_label,
)
from ..models.families import FamilyParams
from ..records import check_unit, finite_number, natural_order
from ..units import param_scale, step_scale
from .errormodel import Predictive

FORMAT = "stickslip.calibration"
FORMAT_VERSION = 1

UNITS = {
    ("prismatic", "a"): "m",
    ("prismatic", "b"): "1",
    ("prismatic", "c"): "m",
    ("rotary", "gamma0"): "rad",
    ("rotary", "d"): "rad",
}


def checked_pose(pose: kin.Pose | Sequence[float], joint: int | None = None, q: float | None = None) -> kin.Pose:
    """``pose`` (a Pose or its five numbers) with ``q{joint}`` set to ``q``, checked: within the MM3A's ranges
    and finite, as :class:`~stickslip.motion.Planner` checks a pose, or ``ValueError`` naming the value
    (``q2 = -90`` in degrees gave a step size, silently)."""
    p = pose if isinstance(pose, kin.Pose) else kin.Pose(*pose)
    if joint is not None and q is not None:
        p = p._replace(**{f"q{joint}": q})
    problems = check_pose(0, {k: float(v) for k, v in p._asdict().items()})  # (0: every joint checked)
    if problems:
        raise ValueError("pose: " + "; ".join(problems))
    return p


class CalibrationError(ValueError):
    """The traverses given cannot produce a (physical) calibration; the message says why."""


_CONDITION_RANGES = {"frequency_hz": (1e-3, 1e6), "amplitude_v": (0.0, 1e3), "temperature_c": (-273.15, 500.0)}


@dataclass(frozen=True)
class Conditions:
    """What a calibration was made with, so that using it elsewhere can be questioned.

    Every field is optional (``None`` = not recorded); older calibration files have none.

    Attributes
    ----------
    device : str or None
        The device's identity (its URL without options or secrets, as
        :func:`stickslip.devices.device_key` gives it).
    frequency_hz : float or None
        Stepping (drive) frequency of the traverses, Hz.
    amplitude_v : float or None
        Drive amplitude, V (or the controller's amplitude units, as the controller reports it).
    temperature_c : float or None
        Room or stage temperature, °C, if known.
    """

    device: str | None = None
    frequency_hz: float | None = None
    amplitude_v: float | None = None
    temperature_c: float | None = None

    def __post_init__(self) -> None:
        if self.device is not None and (not isinstance(self.device, str) or len(self.device) > 2000):
            raise ValueError(f"conditions.device must be a device URL string, got {self.device!r:.80}")
        for name, (lo, hi) in _CONDITION_RANGES.items():
            v = getattr(self, name)
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or not lo <= v <= hi:
                raise ValueError(f"conditions.{name} must be a finite number in [{lo:g}, {hi:g}], got {v!r}")

    @property
    def recorded(self) -> bool:
        """Whether anything is recorded."""
        return any(getattr(self, k) is not None for k in ("device", "frequency_hz", "amplitude_v", "temperature_c"))

    def to_dict(self) -> dict[str, object]:
        """The recorded fields (SI-labelled names), ``None`` where not recorded."""
        return {
            "device": self.device,
            "frequency_hz": self.frequency_hz,
            "amplitude_v": self.amplitude_v,
            "temperature_c": self.temperature_c,
        }

    @classmethod
    def from_dict(cls, data: object) -> Conditions:
        """Rebuild from :meth:`to_dict` output; ``ValueError`` names the bad field."""
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise ValueError(f"conditions must be an object, got {records.json_kind(data)}")
        unknown = sorted(set(data) - {"device", "frequency_hz", "amplitude_v", "temperature_c"})
        if unknown:
            raise ValueError(f"conditions: unknown field(s) {', '.join(map(str, unknown))}")
        return cls(**{k: data.get(k) for k in ("device", "frequency_hz", "amplitude_v", "temperature_c")})

    def differences(self, now: Conditions, rel_tol: float = 0.01, temp_tol_c: float = 2.0) -> list[str]:
        """How ``now`` differs from these conditions, one phrase per field that both record.

        Frequencies and amplitudes differ when they are more than ``rel_tol`` apart
        (relative); temperatures when more than ``temp_tol_c`` °C apart.
        """
        out: list[str] = []
        if self.device and now.device and self.device != now.device:
            out.append(f"made on {self.device}, this is {now.device}")
        for name, label, unit in (("frequency_hz", "stepping frequency", "Hz"), ("amplitude_v", "amplitude", "V")):
            a, b = getattr(self, name), getattr(now, name)
            if a is not None and b is not None and abs(a - b) > rel_tol * max(abs(a), abs(b)):
                out.append(f"{label} {a:g} {unit} then, {b:g} {unit} now")
        a, b = self.temperature_c, now.temperature_c
        if a is not None and b is not None and abs(a - b) > temp_tol_c:
            out.append(f"temperature {a:g} °C then, {b:g} °C now")
        return out


@dataclass(frozen=True)
class Parameter:
    """One calibrated (or true) parameter of a joint's step-size model, in SI units.

    Attributes
    ----------
    joint : int
        1, 2 or 3.
    direction : str
        ``"+"`` or ``"-"``.
    name : str
        ``a``, ``b``, ``c`` (prismatic, Eqs. 2-3) or ``gamma0``, ``d`` (rotary, Eq. 8).
    q3 : float or None
        The knot (m) a rotary parameter belongs to; ``None`` for the prismatic joint.
    value : float
        The value (m for a, c; 1 for b; rad for gamma0, d).
    stderr : float or None
        Its standard error, same unit (``None`` where the procedure gives none).
    unit : str
        ``"m"``, ``"1"`` or ``"rad"``.
    """

    joint: int
    direction: str
    name: str
    q3: float | None
    value: float
    stderr: float | None
    unit: str

    @property
    def key(self) -> tuple[int, str, str, float | None]:
        """What identifies the parameter: joint, direction, name and knot (q3 rounded to 1 nm)."""
        return (self.joint, self.direction, self.name, None if self.q3 is None else round(self.q3, 9))

    @property
    def label(self) -> str:
        """A short label people read, e.g. ``"j2 d+ (q3=12 mm)"``."""
        where = f" (q3={self.q3 * 1e3:g} mm)" if self.q3 is not None else ""
        return f"j{self.joint} {self.name}{self.direction}{where}"

    def to_dict(self) -> dict[str, object]:
        """The JSON record (the calibration file's ``parameters`` entries)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Provenance:
    """Where a calibration's traverses came from.

    Attributes
    ----------
    source : str or None
        The table's file name or the device URL they were measured on.
    sha256 : str or None
        Hash of the traverses as a measurement table (design.md §7), to recognise the data.
    rows_sha256 : str or None
        Hash of the same rows in sorted order (:func:`table_digests`): a re-sorted copy of
        the table is still recognised as the calibration's own. ``None`` in files written
        before it existed.
    rows, rows_used : int
        Traverses given, and used by the method.
    days : tuple of str
        Session labels among them.
    notes : tuple of str
        What the method did that a reader should know (poses not used, methods merged).
    extra : dict
        Any other fields of the file, kept as they were.
    """

    source: str | None = None
    sha256: str | None = None
    rows: int = 0
    rows_used: int = 0
    days: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    extra: dict[str, object] = field(default_factory=dict)
    rows_sha256: str | None = None

    @classmethod
    def of(cls, traverses: Sequence[Traverse], source: str | None, used: int, notes: Sequence[str]) -> Provenance:
        """The provenance of a calibration from ``traverses`` (``used`` of them) with ``notes``."""
        table, rows = table_digests(traverses)
        return cls(
            source=source,
            sha256=table,
            rows_sha256=rows,
            rows=len(traverses),
            rows_used=used,
            days=tuple(sorted({t.day for t in traverses}, key=natural_order)),
            notes=tuple(notes),
        )

    def to_dict(self) -> dict[str, object]:
        """The JSON record (``extra`` fields merged back in)."""
        return {
            **self.extra,
            "source": self.source,
            "sha256": self.sha256,
            **({"rows_sha256": self.rows_sha256} if self.rows_sha256 else {}),
            "rows": self.rows,
            "rows_used": self.rows_used,
            "days": list(self.days),
            "notes": list(self.notes),
        }

    @classmethod
    def from_dict(cls, data: object) -> Provenance:
        """Rebuild from :meth:`to_dict` output (missing fields take their defaults); ``ValueError`` if malformed."""
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise ValueError(f"provenance must be an object, got {records.json_kind(data)}")
        known = {"source", "sha256", "rows_sha256", "rows", "rows_used", "days", "notes"}

        def text(key: str) -> str | None:
            v = data.get(key)
            if v is not None and not isinstance(v, str):
                raise ValueError(f"provenance.{key} must be a string, got {v!r:.60}")
            return v

        def count(key: str) -> int:
            v = data.get(key, 0)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"provenance.{key} must be a count >= 0, got {v!r:.60}")
            return v

        def texts(key: str) -> tuple[str, ...]:
            v = data.get(key) or []
            if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                raise ValueError(f"provenance.{key} must be a list of strings")
            return tuple(v)

        return cls(
            text("source"),
            text("sha256"),
            count("rows"),
            count("rows_used"),
            texts("days"),
            texts("notes"),
            {k: v for k, v in data.items() if k not in known},
            text("rows_sha256"),
        )


def table_digests(traverses: Sequence[Traverse]) -> tuple[str, str]:
    """The two sha256 digests (hex) a calibration's provenance keeps of its table.

    The first hashes the measurement table as :func:`~stickslip.measurements.measurements_to_csv`
    writes it, rows in the order given; the second hashes the header and the same rows sorted,
    so that a re-sorted copy of the table (by day, by joint) is still recognised.
    """
    text = measurements_to_csv(traverses)
    header, _, body = text.partition("\n")
    rows = "\n".join([header, *sorted(body.splitlines())]) + "\n"
    return hashlib.sha256(text.encode()).hexdigest(), hashlib.sha256(rows.encode()).hexdigest()


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
        ``(joint, direction) -> float``: the paper's constant-step comparator (m or rad); for a
        stage (:mod:`.stage`) the mean step it is planned with.
    day : str
        Session label of the traverses (ISO date preferred).
    method : str
        ``"paper"``, ``"paper-quadratic"`` or ``"lsq"`` (older files say ``"seed"``).
    provenance : Provenance
        Where the traverses came from (file, sha256, rows used, notes).
    created : str
        When the calibration was computed (UTC, ISO 8601).
    conditions : Conditions
        Device, drive frequency, amplitude and temperature it was made with, where known.
    """

    models: dict[tuple[int, str], JointModel]
    stderr: dict[tuple[int, str], NDArray[np.float64] | None]
    constant_steps: dict[tuple[int, str], float]
    day: str
    method: str
    provenance: Provenance = field(default_factory=Provenance)
    created: str = field(default_factory=lambda: now_utc().isoformat(timespec="seconds"))
    conditions: Conditions = field(default_factory=Conditions)
    covariance: dict[tuple[int, str], NDArray[np.float64]] = field(default_factory=dict)
    """``(joint, direction) -> covariance`` of the parameters (SI, order of ``params.names()``), where known."""
    sigma_model: dict[tuple[int, str], float] = field(default_factory=dict)
    """``(joint, direction) ->`` relative model error (1 sigma) for prediction intervals, where known."""
    selection: dict[tuple[int, str], dict[str, object]] = field(default_factory=dict)
    """``(joint, direction) ->`` the family chosen, why, and the CV error of every family."""
    predictive: dict[tuple[int, str], Predictive] = field(default_factory=dict)
    """``(joint, direction) ->`` what a prediction's interval is made of in each pose (docs/models.md §4),
    where known (a family calibration); elsewhere the interval is the constant ``sigma_model``."""
    kinds: dict[int, str] = field(default_factory=dict)
    """``joint -> "prismatic" | "rotary"`` where the calibrated arm's joint is not the MM3A's kind
    (a stage's joints 1 and 2 are prismatic); the units written come from it (:meth:`kind`)."""
    constant_stderr: dict[tuple[int, str], float] = field(default_factory=dict)
    """``(joint, direction) ->`` standard error of the constant step (m or rad), where measured."""
    constant_traverses: dict[tuple[int, str], int] = field(default_factory=dict)
    """``(joint, direction) ->`` how many traverses the constant step was averaged from, where recorded."""

    def __post_init__(self) -> None:
        self.kinds = _differing_kinds(self.kinds)

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

    def kind(self, joint: int) -> str:
        """``"prismatic"`` or ``"rotary"``: the calibrated arm's joint (:attr:`kinds`, else the MM3A's)."""
        return self.kinds.get(int(joint)) or _mm3a_kind(int(joint))

    def unit(self, joint: int) -> str:
        """The SI unit of ``joint``'s steps in this calibration: ``"m"`` (prismatic) or ``"rad"`` (rotary)."""
        return "m" if self.kind(joint) == "prismatic" else "rad"

    def gamma(
        self, joint: int, direction: str | int, pose: kin.Pose | Sequence[float], q: float | None = None
    ) -> float:
        """Mean step size (m or rad) of ``joint`` at ``pose``; ``q`` overrides the joint's own coordinate.

        ``pose``: a :class:`~stickslip.kinematics.Pose` or ``(q1, q2, q3, theta, psi)`` (rad, rad, m,
        rad, rad), within the MM3A's ranges (:func:`checked_pose`) or ``ValueError``.
        """
        p = checked_pose(pose, None if q is None else int(joint), q)
        return float(self.model(joint, direction).gamma(p.q1, p.q2, p.q3, p.theta, p.psi))

    def predict(self, traverse: Traverse) -> float:
        """Predicted average step over a traverse (exact; m or rad); one that could not be a table row
        (:func:`~stickslip.measurements.check_traverses`: a tilt in degrees, a nan) raises ``TableError``."""
        check_traverses([traverse])
        t = traverse
        return float(self.model(t.joint, t.direction).average_gamma(t.start, t.end, t.q1, t.q2, t.q3, t.theta, t.psi))

    def predict_many(self, traverses: Sequence[Traverse]) -> NDArray[np.float64]:
        """Predicted average steps for many traverses (vectorised per joint and direction; checked as by predict)."""
        check_traverses(traverses)
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

    def parameters(self) -> list[Parameter]:
        """Every parameter as a :class:`Parameter` (SI), by joint, direction and name."""
        out = []
        for (j, d), m in sorted(self.models.items()):
            se = self.stderr.get((j, d))
            for i, ((name, q3), value) in enumerate(zip(m.params.names(), m.params.as_vector(), strict=True)):
                err = None if se is None or not np.isfinite(se[i]) else float(se[i])
                unit = m.params.unit(name) if isinstance(m.params, FamilyParams) else UNITS[(m.params.kind, name)]
                out.append(Parameter(j, d, name, q3, float(value), err, unit))
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
            "day": self.day or None,  # no day known: null, which reads back as such ("" is no session label)
            "method": self.method,
            "created": self.created,
            "units": "SI: prismatic steps in m, rotary steps in rad, q3 in m; b is dimensionless",
            "parameters": [p.to_dict() for p in self.parameters() if not _is_family(self, p)],
            "constant_steps": [_constant_record(self, j, d) for j, d in sorted(self.constant_steps)],
            "provenance": self.provenance.to_dict(),
            "conditions": self.conditions.to_dict(),
        }
        base.update(ext)
        return base

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Calibration:
        """Rebuild from :meth:`to_dict` output; raises ``ValueError`` with the reason on bad input."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f'not a stickslip calibration (expected "format": "{FORMAT}")')
        records.check_calibration_dict(data)
        # a calibration made before spreadsheet dates (22.11.2026) were refused in tables stays readable
        if isinstance(data.get("day"), str) and (why := day_label_problem(data["day"], False)) is not None:
            raise ValueError(f"day: {why}")
        if isinstance(data.get("version"), bool) or data.get("version") not in (FORMAT_VERSION, 2):
            raise ValueError(
                f"calibration format version {data.get('version')!r} is not supported (expected {FORMAT_VERSION} or 2)"
            )
        try:
            by_key: dict[tuple[int, str], list[dict[str, Any]]] = {}
            for rec in data["parameters"]:
                by_key.setdefault((int(rec["joint"]), direction_label(rec["direction"])), []).append(rec)
            models: dict[tuple[int, str], JointModel] = {}
            stderr: dict[tuple[int, str], NDArray[np.float64] | None] = {}
            for (j, d), recs in by_key.items():
                models[(j, d)], stderr[(j, d)] = _paper_model(j, d, recs)
            consts = {
                (int(c["joint"]), direction_label(c["direction"])): float(c["value"]) for c in data["constant_steps"]
            }
            kinds, const_se, const_n = _constant_records(data["constant_steps"], models)
            conditions = Conditions.from_dict(data.get("conditions"))
        except (KeyError, TypeError) as e:
            raise ValueError(f"calibration file is missing or has a malformed field: {e}") from None
        cal = cls(
            models,
            stderr,
            consts,
            data.get("day") or "",  # null or left out: no day known (str(None) was the label 'None')
            data.get("method") or "",
            Provenance.from_dict(data.get("provenance")),
            data.get("created") or "",
            conditions,
            kinds=kinds,
            constant_stderr=const_se,
            constant_traverses=const_n,
        )
        from ._ext_json import read_ext_fields

        read_ext_fields(cal, data)
        return cal

    def save(self, path: str | Path) -> None:
        """Write the calibration as JSON."""
        records.atomic_write_text(path, records.dumps_json(self.to_dict(), str(path), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a calibration JSON file; raises ``ValueError`` naming the file and the reason.

        The paper's parameters are checked as ``calibrate`` checks them (:meth:`PrismaticParams.check_physical`,
        :meth:`RotaryParams.check_physical`: the step > 0 in every pose): a file whose step would be <= 0
        somewhere is refused, naming the joint and direction.
        """
        p = Path(path)
        try:
            data = records.read_json(p, "calibration")
        except FileNotFoundError:
            raise ValueError(f"{p}: no such calibration file") from None
        try:
            cal = cls.from_dict(data)
            _check_physical(cal.models)  # a hand edit (c > a) would step backwards where the plan refused to move
        except ValueError as e:
            raise ValueError(f"{p}: {e}") from None
        return cal

    # -- people
    def report(self) -> str:
        """A readable text report of the parameters with standard errors (nm, µrad)."""
        lines = [f"stickslip calibration — day {self.day or '?'}, method {self.method}"]
        for j in sorted({*self.joints, *(jj for jj, _ in self.constant_steps)}):
            kind = self.kind(j)
            lines.append(f"joint {j} ({kind}):")
            for rec in self.parameters():
                if rec.joint != j:
                    continue
                scale, unit = param_scale(rec.name, j)
                where = f" @ q3 = {rec.q3 * 1e3:g} mm" if rec.q3 is not None else ""
                se = f" ± {rec.stderr * scale:.3g}" if rec.stderr is not None else ""
                lines.append(f"  {rec.name}{rec.direction}{where}: {rec.value * scale:.5g}{se} {unit}".rstrip())
            lines += [_constant_line(self, j, d) for d in DIRECTIONS if (j, d) in self.constant_steps]
        if self.conditions.recorded:
            c = self.conditions
            parts = [
                f"device {c.device}" if c.device else None,
                f"{c.frequency_hz:g} Hz" if c.frequency_hz is not None else None,
                f"{c.amplitude_v:g} V" if c.amplitude_v is not None else None,
                f"{c.temperature_c:g} °C" if c.temperature_c is not None else None,
            ]
            lines.append("made with: " + ", ".join(x for x in parts if x))
        for n in self.provenance.notes:
            lines.append(f"note: {n}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()

    def __repr__(self) -> str:
        return (
            f"Calibration(day={self.day!r}, method={self.method!r}, joints={self.joints}, "
            f"parameters={len(self.parameters())}, units=SI)"
        )

    def _repr_html_(self) -> str:
        """The parameters as a table (nm, µrad; b dimensionless), for Jupyter."""
        from ..notebook import html_table

        rows = []
        for rec in self.parameters():
            scale, unit = param_scale(rec.name, rec.joint)
            rows.append(
                [
                    rec.joint,
                    rec.direction,
                    rec.name,
                    "" if rec.q3 is None else f"{rec.q3 * 1e3:g}",
                    f"{rec.value * scale:.5g}",
                    "" if rec.stderr is None else f"{rec.stderr * scale:.3g}",
                    unit or "1",
                ]
            )
        notes = [line for line in self.report().splitlines() if line.startswith(("made with", "note"))]
        return html_table(
            f"stickslip calibration: day {self.day or '?'}, method {self.method}",
            ["joint", "dir", "parameter", "q3 knot (mm)", "value", "std. error", "unit"],
            rows,
            notes,
        )

    def plot(
        self, joint: int = 3, ax: Axes | None = None, thetas: Sequence[float] = (0.0, -math.pi / 3, -math.pi / 2)
    ) -> Axes:
        """Model step size against zeta (psi = 0, q1 = 0), like the paper's Figs. 4 and 10.

        Joint 3: one curve per direction and tilt ``theta`` (nm). Rotary joints: one curve
        per direction at q3 = 0 and 12 mm, theta = 0 (µrad). Direction + solid, - dashed. Returns the Axes.
        """
        if isinstance(joint, bool) or not isinstance(joint, int) or joint not in self.joints:
            raise ValueError(f"joint {joint!r} is not in this calibration (it has joints {self.joints})")
        ax = plotting.axes(ax, (6, 4))
        spec = kin.JOINTS[2]
        q2 = np.linspace(spec.lower, spec.upper, 400)
        zeta_deg = np.degrees(-q2)
        for d in DIRECTIONS:
            if (joint, d) not in self.models:
                continue
            m = self.models[(joint, d)]
            ls = "-" if d == "+" else "--"  # the direction by line style, not by hue alone
            if kin.joint_spec(joint).prismatic:
                for th in thetas:
                    g = m.gamma(0.0, q2, 0.0, th, 0.0)
                    ax.plot(zeta_deg, g * step_scale(joint)[0], ls=ls, label=f"γ3{d}, θ = {math.degrees(th):.0f}°")
            else:
                for q3 in (0.0, kin.Q3_MAX):
                    qj = q2 if joint == 2 else np.linspace(kin.JOINTS[1].lower, kin.JOINTS[1].upper, 400)
                    args = (0.0, qj, q3, 0.0, 0.0) if joint == 2 else (qj, -math.pi / 2, q3, -math.pi / 2, 0.0)
                    ax.plot(
                        zeta_deg if joint == 2 else np.degrees(qj),
                        m.gamma(*args) * step_scale(joint)[0],
                        ls=ls,
                        label=f"γ{joint}{d}, q3 = {q3 * 1e3:g} mm",
                    )
        ax.set_xlabel("ζ = ψ − q2 (deg)" if joint != 1 else "q1 (deg)")
        ax.set_ylabel(f"mean step size ({step_scale(joint)[1]})")
        ax.set_title(f"joint {joint}, calibration of {self.day} ({self.method})")
        ax.legend(fontsize="small")
        return ax


def _differing_kinds(kinds: dict[int, str]) -> dict[int, str]:
    """``kinds`` checked, keeping what differs from the MM3A's (so that a file read back equals the one written)."""
    for j, k in kinds.items():
        if k not in ("prismatic", "rotary"):
            raise ValueError(f"joint {j}: kind must be 'prismatic' or 'rotary', got {k!r}")
    return {j: k for j, k in sorted(kinds.items()) if _mm3a_kind(j) != k}


def _constant_record(cal: Calibration, j: int, d: str) -> dict[str, object]:
    """A ``constant_steps`` entry of the file: value, unit (from the joint's kind), standard error and count."""
    out: dict[str, object] = {"joint": j, "direction": d, "value": cal.constant_steps[(j, d)], "unit": cal.unit(j)}
    if (j, d) in cal.constant_stderr:
        out["stderr"] = cal.constant_stderr[(j, d)]
    if (j, d) in cal.constant_traverses:
        out["traverses"] = cal.constant_traverses[(j, d)]
    return out


def _constant_line(cal: Calibration, j: int, d: str) -> str:
    """The report's line of a constant step (nm or µrad), with its standard error and count where known."""
    scale, unit = (1e9, "nm") if cal.kind(j) == "prismatic" else step_scale(j)
    se = cal.constant_stderr.get((j, d))
    pm = f" ± {se * scale:.3g}" if se is not None else ""
    count = cal.constant_traverses.get((j, d))
    of = f" ({count} traverse{'s' if count != 1 else ''})" if count is not None else ""
    what = "mean step" if not cal.models else "constant-step comparator"
    return f"  {what} {d}: {cal.constant_steps[(j, d)] * scale:.5g}{pm} {unit}{of}"


def _mm3a_kind(joint: int) -> str:
    """The MM3A's kind of ``joint`` (what a calibration's joint is unless it says otherwise)."""
    spec = kin.JOINTS.get(joint)
    return spec.kind if spec is not None else "prismatic"


def _paper_model(j: int, d: str, recs: list[dict[str, Any]]) -> tuple[JointModel, NDArray[np.float64] | None]:
    """One joint and direction's model (Eqs. 3-4) and standard errors from its ``parameters`` records.

    ``KeyError`` for a missing parameter; ``ValueError`` for rotary knots that are not two, or a
    ``unit`` other than the one stickslip writes (:func:`~stickslip.records.check_unit`).
    """
    vals = {(r["name"], r.get("q3")): (float(r["value"]), r.get("stderr")) for r in recs}
    names: list[tuple[str, float | None]]
    if kin.joint_spec(j).prismatic:
        names = [("a", None), ("b", None), ("c", None)]
        params: Params = PrismaticParams(*(vals[n][0] for n in names))
    else:
        knots = sorted({float(q3) for (n, q3) in vals if n == "gamma0" and q3 is not None})
        if len(knots) != 2:
            raise ValueError(f"joint {j}{d}: expected gamma0 at two q3 values, found {len(knots)}")
        names = [("gamma0", knots[0]), ("gamma0", knots[1]), ("d", knots[0]), ("d", knots[1])]
        params = RotaryParams(
            (vals[names[0]][0], vals[names[1]][0]),
            (vals[names[2]][0], vals[names[3]][0]),
            (knots[0], knots[1]),
        )
    for r in recs:
        check_unit(r.get("unit"), UNITS.get((params.kind, str(r["name"]))), f"joint {j}{d} {r['name']}")
    se = [vals[n][1] for n in names]
    return JointModel(j, d, params), (
        None if all(s is None for s in se) else np.array([np.nan if s is None else s for s in se])
    )


def _constant_records(
    records_: list[dict[str, Any]], models: dict[tuple[int, str], JointModel]
) -> tuple[dict[int, str], dict[tuple[int, str], float], dict[tuple[int, str], int]]:
    """The joints' kinds (from each constant step's ``unit``), standard errors and traverse counts of a file.

    A file written before units followed the joints' kinds labels each as the MM3A's joint;
    a unit other than ``m`` or ``rad``, two units for one joint, or a unit that contradicts
    the joint's model is refused (``ValueError``).
    """
    kinds: dict[int, str] = {}
    stderr: dict[tuple[int, str], float] = {}
    count: dict[tuple[int, str], int] = {}
    for c in records_:
        key = (int(c["joint"]), direction_label(c["direction"]))
        unit = c.get("unit")
        if unit is not None:
            if unit not in ("m", "rad"):
                raise ValueError(
                    f"constant step of joint {key[0]}{key[1]}: unit must be 'm' or 'rad', got {unit!r:.40}"
                )
            kind = "prismatic" if unit == "m" else "rotary"
            if kinds.setdefault(key[0], kind) != kind:
                raise ValueError(f"joint {key[0]}: its constant steps are labelled both m and rad")
            m = models.get(key)
            if m is not None and (m.params.kind == "prismatic") != (kind == "prismatic"):
                raise ValueError(f"joint {key[0]}{key[1]}: the constant step is in {unit}, but the joint's model "
                                 f"is {m.params.kind}")
        if c.get("stderr") is not None:
            stderr[key] = finite_number(c["stderr"], f"constant step of joint {key[0]}{key[1]}: stderr")
        if c.get("traverses") is not None:
            n = c["traverses"]
            if isinstance(n, bool) or not isinstance(n, int) or n < 1:
                raise ValueError(f"constant step of joint {key[0]}{key[1]}: traverses must be a count >= 1, "
                                 f"got {n!r:.40}")
            count[key] = n
    return kinds, stderr, count


def _is_family(cal: Calibration, p: Parameter) -> bool:
    """Whether ``p`` belongs to a model family beyond the paper's (written under ``families``)."""
    m = cal.models.get((p.joint, p.direction))
    return m is not None and isinstance(m.params, FamilyParams)


# ----------------------------------------------------------------------------- helpers


def _constant_step(joint: int, direction: str, model: JointModel) -> float:
    """The paper's constant-step comparator, computed from a model.

    Prismatic: ``gamma_3i(-pi/2, 0, 0) = a_i``. Joint 2: the full-range average at
    ``(q3, theta, psi) = (0, 0, 0)``. Joint 1 (roles interchanged): the full-range
    average at ``theta = -pi/2``, arm outstretched, ``q3 = 0``.
    """
    if kin.joint_spec(joint).prismatic:
        return float(model.gamma(0.0, -math.pi / 2, 0.0, 0.0, 0.0))
    spec = kin.JOINTS[joint]
    start, end = (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)
    theta = 0.0 if joint == 2 else -math.pi / 2
    return float(model.average_gamma(start, end, 0.0, -math.pi / 2, 0.0, theta, 0.0))


def _day_of(traverses: Sequence[Traverse], day: str | None) -> str:
    if day:
        return day
    days = sorted({t.day for t in traverses}, key=natural_order)  # day10 after day9
    return days[-1] if days else ""


def _check_physical(models: dict[tuple[int, str], JointModel]) -> None:
    for (j, d), m in sorted(models.items()):
        try:
            m.params.check_physical()
        except NonPhysicalError as e:
            raise CalibrationError(f"joint {j}{d}: non-physical calibration refused: {e}") from None


def _provenance(
    base: Provenance | None, traverses: Sequence[Traverse], source: str | None, used: int, notes: Sequence[str]
) -> Provenance:
    """``base`` (the table's provenance, hashed once by the caller) with ``used`` and ``notes``, or a new one."""
    if base is None:
        return Provenance.of(traverses, source, used, notes)
    return dataclasses.replace(base, rows_used=used, notes=tuple(notes))


def _group(traverses: Iterable[Traverse]) -> dict[tuple[int, str], list[Traverse]]:
    g: dict[tuple[int, str], list[Traverse]] = {}
    for t in traverses:
        g.setdefault((t.joint, t.direction), []).append(t)
    return g
