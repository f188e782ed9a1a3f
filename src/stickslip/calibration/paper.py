"""The paper's calibration procedure: Eqs. (4)-(6) for the prismatic joint, and
``gamma0`` plus the exactly inverted ``d`` for joint 2 (Section 3.3, 3.5)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..measurements import Traverse
from ..models import (
    JointModel,
    PrismaticParams,
    RotaryParams,
)
from .groups import TraverseGroups, group_traverses
from .inversion import _LOAD_ZERO, PaperQuadratic, fit_paper_quadratic, invert_d_exact_many
from .result import Calibration, CalibrationError, Provenance, _check_physical, _constant_step, _day_of, _provenance

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


# ----------------------------------------------------------------------------- paper's method


def _paper_prismatic_rows(ts: Sequence[Traverse]) -> dict[str, list[Traverse]] | None:
    found: dict[str, list[Traverse]] = {k: [] for k in PRISMATIC_PAPER_POSES}
    for t in ts:
        for k, (q2, th, ps) in PRISMATIC_PAPER_POSES.items():
            if _close(t.q2, q2) and _close(t.theta, th) and _close(t.psi, ps):
                found[k].append(t)
    return found if all(found.values()) else None


def _classify_rotary(t: Traverse) -> tuple[float, float]:
    return _load_coefficients(t.joint, t.q1, t.q2, t.q3, t.theta, t.psi)


@functools.lru_cache(maxsize=4096)
def _load_coefficients(joint: int, q1: float, q2: float, q3: float, theta: float, psi: float) -> tuple[float, float]:
    """Load coefficients of a pose, memoised: a long table repeats a few calibration poses."""
    al, be = kin.rotary_load_coefficients(joint, q1, q2, q3, theta, psi)
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


def paper_applicable(traverses: Sequence[Traverse] | TraverseGroups) -> bool:
    """Whether every (joint, direction) present has the paper's calibration poses."""
    groups = group_traverses(traverses).as_dict()
    if not groups:
        return False
    for (j, _d), ts in groups.items():
        if (_paper_prismatic_rows(ts) if kin.joint_spec(j).prismatic else _paper_rotary_rows(ts)) is None:
            return False
    return True




def only_paper_poses(ts: Sequence[Traverse]) -> bool:
    """Whether the traverses of one joint and direction are the paper's calibration set and nothing else."""
    if not ts:
        return False
    j = ts[0].joint
    rows = _paper_prismatic_rows(ts) if j == 3 else _paper_rotary_rows(ts)
    if rows is None or sum(len(v) for v in rows.values()) != len(ts):
        return False
    for t in ts:
        if j == 3:
            ok = _close(t.q1, 0.0) and any(
                _close(t.q2, q2) and _close(t.theta, th) and _close(t.psi, ps)
                for q2, th, ps in PRISMATIC_PAPER_POSES.values()
            )
        elif j == 2:
            ok = _close(t.q1, 0.0) and any(
                abs(t.q3 - q3) <= _Q3_TOL and _close(t.theta, th) and _close(t.psi, ps)
                for q3, th, ps in ROTARY_PAPER_POSES
            )
        else:
            ok = True
        if not ok:
            return False
    return True


def calibrate_paper(
    traverses: Sequence[Traverse] | TraverseGroups,
    day: str | None = None,
    source: str | None = None,
    rotary_inversion: str = "exact",
    quadratic: PaperQuadratic | None = None,
    provenance: Provenance | None = None,
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
    provenance : Provenance, optional
        The table's provenance when the caller has it (hashing a long table once); the
        rows used and the notes are this procedure's.
    """
    if rotary_inversion not in ("exact", "paper-quadratic"):
        raise ValueError(f"rotary_inversion must be 'exact' or 'paper-quadratic', got {rotary_inversion!r}")
    grouped = group_traverses(traverses)
    groups = grouped.as_dict()
    traverses = grouped.traverses
    if not groups:
        raise CalibrationError("no traverses to calibrate from")
    if rotary_inversion == "paper-quadratic":
        quad = quadratic or fit_paper_quadratic()

        def invert(loaded: Sequence[Traverse], g0: float) -> NDArray[np.float64]:
            return np.array([float(quad.d(t.gamma - g0)) for t in loaded])
    else:

        def invert(loaded: Sequence[Traverse], g0: float) -> NDArray[np.float64]:
            # one bracket per traverse and pose, then every average of it at once (a long log repeats the
            # same few calibration traverses thousands of times)
            ds = np.empty(len(loaded))
            by_pose: dict[tuple[float, float, float, float], list[int]] = {}
            for i, t in enumerate(loaded):
                by_pose.setdefault((t.start, t.end, *_classify_rotary(t)), []).append(i)
            for (start, end, al, be), idx in by_pose.items():
                gam = np.array([loaded[i].gamma for i in idx])
                ds[idx] = invert_d_exact_many(gam, g0, start, end, al, be)
            return ds

    models: dict[tuple[int, str], JointModel] = {}
    used = 0
    notes: list[str] = []
    for (j, d), ts in sorted(groups.items()):
        params, n = _paper_prismatic(d, ts) if kin.joint_spec(j).prismatic else _paper_rotary(j, d, ts, invert)
        models[(j, d)] = JointModel(j, d, params)
        used += n
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
        _provenance(provenance, traverses, source, used, notes),
    )


def _paper_prismatic(d: str, ts: Sequence[Traverse]) -> tuple[PrismaticParams, int]:
    """Eqs. (4)-(6) from the traverses of joint 3 in direction ``d``; the parameters and how many rows they used."""
    rows = _paper_prismatic_rows(ts)
    if rows is None:
        missing = [
            f"(q2, theta, psi) = ({', '.join(f'{v:.4g}' for v in pose)})"
            for pose in PRISMATIC_PAPER_POSES.values()
            if not any(_close(t.q2, pose[0]) and _close(t.theta, pose[1]) and _close(t.psi, pose[2]) for t in ts)
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
    return PrismaticParams(a, b, c), sum(len(v) for v in rows.values())


def _paper_rotary(
    j: int, d: str, ts: Sequence[Traverse], invert: Callable[[Sequence[Traverse], float], NDArray[np.float64]]
) -> tuple[RotaryParams, int]:
    """gamma0 from the unloaded traverses and d by ``invert`` from the loaded ones, at q3 = 0 and 12 mm."""
    rot = _paper_rotary_rows(ts)
    if rot is None:
        raise CalibrationError(
            f"joint {j}{d}: the paper's method needs full-range traverses at q3 = 0 and 12 mm, each with and "
            "without gravity torque (for joint 2: theta = 0 and theta = -pi/2); "
            "use method 'lsq' for other poses"
        )
    g0s, dvals, used = [], [], 0
    for knot in (0, 1):
        g0 = float(np.mean([t.gamma for t in rot[(knot, "free")]]))
        dvals.append(float(np.mean(invert(rot[(knot, "loaded")], g0))))
        g0s.append(g0)
        used += len(rot[(knot, "free")]) + len(rot[(knot, "loaded")])
    return RotaryParams((g0s[0], g0s[1]), (dvals[0], dvals[1])), used


def _close(a: float, b: float, tol: float = _POSE_TOL) -> bool:
    return abs(a - b) <= tol
