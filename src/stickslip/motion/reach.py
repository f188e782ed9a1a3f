"""Straight-line tip moves: task-space plans made of signed step counts.

A move of the tip from where it is to a target (docs/design.md §9) is cut into short
segments along the straight line. For each segment:

1. the ideal joint position at the segment's end comes from the closed-form inverse
   kinematics (:func:`stickslip.kinematics.inverse`, the branch continued from the
   start);
2. each joint's increment is measured from the *predicted* position after the
   previous segment's whole steps, so the fraction of a step not taken in one segment
   (the rounding remainder) is carried into the next one;
3. the exact (real) step count of joint 1, then 2, then 3 (the order they are
   stepped in) comes from the calibrated step-size model in the current pose (gravity
   and direction included; rotary joints integrated exactly, as
   :mod:`stickslip.motion.planning` does), and the predicted position after whole steps is
   dead-reckoned. Each count is rounded down or up: of those (at most 8) choices the
   one that keeps the tip closest to the line is taken (on the last segment, the one
   that ends closest to the target), so every joint stays within a step of its ideal
   position and the predicted end is within half a step of each joint of the target.

A segment is no longer than ``segment`` (default 10 µm) and, so that the staircase of
joint-by-joint stepping stays close to the line on short moves, no longer than
:data:`LINE_FRACTION` of the move (but not shorter than :data:`MIN_SEGMENT`).

The whole line is checked before a step is planned: every segment end must be within
the joints' ranges (:class:`~stickslip.kinematics.OutOfReach` names the limit and how
far along the line it is met) and the line must keep ``min_reach`` away from joint 1's
axis (:class:`~stickslip.kinematics.SingularPose`).

With ``step_model="constant"`` the paper's constant step of each joint and direction
replaces the model: the comparator of the benchmark.

A Cartesian arm (``stage``: three prismatic stages carrying a tool, a rig file's
``xyz`` arm, :class:`stickslip.kinematics.Stage`) is planned the same way with its own
kinematics: its task space is its joint space turned by its axes, so the ideal joint
path is a straight line and there is no singular pose; each stage steps with the
calibration's constant step of its direction (its :class:`~stickslip.joints.JointSpec`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import kinematics as kin
from ..calibration import Calibration
from ..models import JointModel, NonPhysicalError
from .planning import Planner

__all__ = [
    "LINE_FRACTION",
    "MIN_SEGMENT",
    "MAX_SEGMENTS",
    "ReachSegment",
    "ReachPlan",
    "JointStepper",
    "plan_reach",
    "borrow_joint1",
]

LINE_FRACTION = 0.02
"""Longest segment as a fraction of the move (dimensionless): the staircase inside a
segment then strays at most about 1 % of the move from the line."""
MIN_SEGMENT = 50e-9
"""Shortest segment the line fraction may ask for, m (a step is ~1 µm at the tip)."""
MAX_SEGMENTS = 200_000
"""More segments than this is refused (a move of kilometres, or a segment of picometres)."""

Vec3 = tuple[float, float, float]


def _vec(a: ArrayLike) -> Vec3:
    x, y, z = (float(v) for v in np.asarray(a, dtype=float).reshape(3))
    return (x, y, z)


@dataclass(frozen=True)
class ReachSegment:
    """One segment of a straight tip move.

    Attributes
    ----------
    steps : tuple of int
        Signed steps of joints 1, 2, 3, sent in that order.
    q : tuple of float
        Predicted joint coordinates after the segment (rad, rad, m).
    tip : tuple of float
        Predicted tip after the segment, base frame, m.
    aim : tuple of float
        The point on the straight line this segment aims at, m.
    """

    steps: tuple[int, int, int]
    q: Vec3
    tip: Vec3
    aim: Vec3

    def as_dict(self) -> dict[str, list[float] | list[int]]:
        """``{"steps": [n1, n2, n3], "q": [...], "tip": [...]}`` (rad, m)."""
        return {"steps": list(self.steps), "q": list(self.q), "tip": list(self.tip)}


@dataclass(frozen=True)
class ReachPlan:
    """A planned straight tip move: the start, the target and the segments.

    Attributes
    ----------
    q_start : tuple of float
        Joint coordinates at the start (rad, rad, m).
    tip_start, target : tuple of float
        Tip at the start and the target, base frame, m.
    segments : list of ReachSegment
    geometry : Geometry
    theta, psi : float
        Base tilt, rad.
    step_model : str
        ``"calibrated"`` or ``"constant"``.
    stage : Stage or None
        A Cartesian arm's kinematics (then ``geometry`` is not used); ``None``: the MM3A's.
    """

    q_start: Vec3
    tip_start: Vec3
    target: Vec3
    segments: list[ReachSegment]
    geometry: kin.Geometry
    theta: float = 0.0
    psi: float = 0.0
    step_model: str = "calibrated"
    segment_length: float = field(default=0.0)
    stage: kin.Stage | None = None

    def tip_of(self, q: ArrayLike) -> NDArray[np.float64]:
        """The tip at joints ``q`` (base frame, m) with this plan's arm: the MM3A's geometry or the stage."""
        return self.stage.tip(q) if self.stage is not None else kin.tip(q, self.geometry)

    @property
    def q_end(self) -> Vec3:
        """Predicted joint coordinates at the end (rad, rad, m)."""
        return self.segments[-1].q if self.segments else self.q_start

    @property
    def tip_end(self) -> Vec3:
        """Predicted tip at the end, m."""
        return self.segments[-1].tip if self.segments else self.tip_start

    @property
    def length(self) -> float:
        """Length of the straight move, m."""
        return float(np.linalg.norm(np.subtract(self.target, self.tip_start)))

    @property
    def total_steps(self) -> tuple[int, int, int]:
        """Sum of ``|steps|`` per joint."""
        n = np.sum(np.abs([s.steps for s in self.segments]), axis=0) if self.segments else np.zeros(3)
        return (int(n[0]), int(n[1]), int(n[2]))

    @property
    def end_error(self) -> float:
        """Distance of the predicted end from the target, m."""
        return float(np.linalg.norm(np.subtract(self.tip_end, self.target)))

    def deviation(self, points: ArrayLike) -> NDArray[np.float64]:
        """Distance of each point (``(..., 3)``, m) from the straight segment start–target, m."""
        return line_distance(points, self.tip_start, self.target)

    def as_dict(self) -> dict[str, Any]:
        """The JSON shape of ``stickslip reach --json`` (metres and radians)."""
        return {
            "start": {"q": list(self.q_start), "tip": list(self.tip_start)},
            "target": list(self.target),
            "segments": [s.as_dict() for s in self.segments],
            "end": {"q": list(self.q_end), "tip": list(self.tip_end)},
        }

    def plot(self, ax: Any = None, true_tips: ArrayLike | None = None, plane: str = "xy") -> Any:
        """Draw the line, the predicted tip after each segment and optionally a true path (µm).

        ``plane`` is two of ``x, y, z``; ``true_tips`` an ``(n, 3)`` array of tip
        positions, m (e.g. read from the simulator after each segment). Returns the Axes.
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(constrained_layout=True)
        ix = ["xyz".index(c) for c in plane]
        line = np.array([self.tip_start, self.target]) * 1e6
        ax.plot(line[:, ix[0]], line[:, ix[1]], "k--", lw=1, label="straight line")
        pred = np.array([self.tip_start] + [s.tip for s in self.segments]) * 1e6
        ax.plot(pred[:, ix[0]], pred[:, ix[1]], ".-", label=f"predicted ({self.step_model})")
        if true_tips is not None:
            tt = np.asarray(true_tips, dtype=float) * 1e6
            ax.plot(tt[:, ix[0]], tt[:, ix[1]], "x:", label="true")  # not the predicted path's style in another hue
        ax.set_xlabel(f"{plane[0]} (µm)")
        ax.set_ylabel(f"{plane[1]} (µm)")
        ax.set_title(f"straight move of the tip in {len(self.segments)} segments ({plane[0]}-{plane[1]} plane)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend()
        return ax


def line_distance(points: ArrayLike, a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Distance of ``points`` (``(..., 3)``, m) from the closed segment ``a``–``b``, m."""
    p = np.asarray(points, dtype=float)
    a_ = np.asarray(a, dtype=float)
    d = np.asarray(b, dtype=float) - a_
    dd = float(d @ d)
    t = np.zeros(p.shape[:-1]) if dd == 0.0 else np.clip(((p - a_) @ d) / dd, 0.0, 1.0)
    return np.asarray(np.linalg.norm(p - (a_ + t[..., None] * d), axis=-1), dtype=float)


def borrow_joint1(calibration: Calibration) -> tuple[Calibration, bool]:
    """A calibration whose joint 1 borrows joint 2's parameters, if it has none of its own.

    The paper (Section 4): joint 1 "has the same range as joint 2 and the same
    properties except for the change in static load value". So, for a calibration with
    joint 2 but no joint 1 (the paper's procedure and ``stickslip demo`` calibrate
    joints 2 and 3 only), joint 1's step is planned with joint 2's ``gamma0`` and ``d``
    and joint 1's *own* gravity load term. Returns ``(calibration, borrowed)``; the
    input is returned unchanged (``borrowed`` False) if joint 1 has a model or joint 2
    has none. Callers should say so: the step sizes of joint 1 are then not measured.
    """
    joints = {j for j, _ in calibration.models}
    if 1 in joints or 2 not in joints:
        return calibration, False
    models = dict(calibration.models)
    stderr = dict(calibration.stderr)
    constant = dict(calibration.constant_steps)
    for (j, d), m in calibration.models.items():
        if j == 2:
            models[(1, d)] = JointModel(1, d, m.params)
            stderr[(1, d)] = None
            if (2, d) in constant:
                constant[(1, d)] = constant[(2, d)]
    notes = (*calibration.provenance.notes, "joint 1 borrows joint 2's parameters (not measured)")
    provenance = replace(calibration.provenance, notes=notes)
    return replace(calibration, models=models, stderr=stderr, constant_steps=constant, provenance=provenance), True


class JointStepper:
    """Signed steps and dead reckoning for one joint in one pose, by the model or a constant step.

    Parameters
    ----------
    calibration : Calibration
    joint : int or JointSpec
        The MM3A's joint, or an arm's own (:class:`~.planning.Planner`).
    pose : Pose
        The pose at the moment the joint is stepped (its own coordinate ignored).
    step_model : {"calibrated", "constant"}
    """

    def __init__(
        self, calibration: Calibration, joint: int | kin.JointSpec, pose: kin.Pose, step_model: str = "calibrated"
    ):
        self.joint = kin.joint_spec(joint).number
        self.step_model = step_model
        if step_model == "calibrated":
            self._planner: Planner | None = Planner(calibration, joint, pose)
            self._const: dict[int, float] = {}
        elif step_model == "constant":
            self._planner = None
            self._const = {}
            for sign, label in ((1, "+"), (-1, "-")):
                try:
                    self._const[sign] = float(calibration.constant_step(self.joint, label))
                except KeyError:
                    continue
        else:
            raise ValueError(f"step_model must be 'calibrated' or 'constant', got {step_model!r}")

    def _constant(self, sign: int) -> float:
        try:
            return self._const[sign]
        except KeyError:
            raise KeyError(
                f"joint {self.joint} direction {'+' if sign > 0 else '-'} has no constant step in this calibration"
            ) from None

    def exact_steps(self, q_from: float, q_to: float) -> float:
        """Signed, unrounded steps from ``q_from`` to ``q_to`` (rad or m)."""
        if q_to == q_from:
            return 0.0
        sign = 1 if q_to > q_from else -1
        if self._planner is not None:
            return sign * self._planner.exact_steps(q_from, q_to)
        return (q_to - q_from) / self._constant(sign)

    def position_after(self, q_from: float, n: int) -> float:
        """Predicted position after ``n`` signed steps from ``q_from`` (rad or m)."""
        if n == 0:
            return float(q_from)
        if self._planner is not None:
            return float(self._planner.position_after(q_from, n))
        return float(q_from + n * self._constant(1 if n > 0 else -1))


def _segment_count(length: float, segment: float) -> tuple[int, float]:
    if not (math.isfinite(segment) and MIN_SEGMENT / 5 <= segment <= 1e-3):
        raise ValueError(f"segment = {segment:.6g} m must be between {MIN_SEGMENT / 5 * 1e9:g} nm and 1 mm")
    if length == 0.0:
        return 0, 0.0
    seg = min(segment, max(LINE_FRACTION * length, MIN_SEGMENT))
    n = math.ceil(length / seg - 1e-9)
    if n > MAX_SEGMENTS:
        raise ValueError(
            f"a {length * 1e6:.6g} µm move in segments of {seg * 1e6:.3g} µm needs {n} segments, "
            f"more than {MAX_SEGMENTS}"
        )
    return max(n, 1), length / max(n, 1)


def _check_line_clear_of_axis(p0: NDArray[np.float64], p1: NDArray[np.float64], min_reach: float) -> None:
    """The closest approach of the line to joint 1's axis (z0), in the xy plane."""
    a, d = p0[:2], (p1 - p0)[:2]
    dd = float(d @ d)
    t = 0.0 if dd == 0.0 else min(max(-float(a @ d) / dd, 0.0), 1.0)
    rho = float(np.linalg.norm(a + t * d))
    if rho < min_reach:
        where = (
            f"the target is {rho * 1e3:.3g} mm from joint 1's axis"
            if t == 1.0
            else f"the straight line passes {rho * 1e3:.3g} mm from joint 1's axis ({t:.0%} of the way)"
        )
        raise kin.SingularPose(
            f"{where}, closer than {min_reach * 1e3:.3g} mm: a singular pose; move in two legs around it, "
            f"or tilt the arm (joint 2) away from the vertical first"
        )


def _ideal_path(
    q0: NDArray[np.float64],
    p0: NDArray[np.float64],
    p1: NDArray[np.float64],
    n: int,
    geometry: kin.Geometry,
    min_reach: float,
    stage: kin.Stage | None = None,
    joints: kin.JointSet | None = None,
) -> list[NDArray[np.float64]]:
    """Joint coordinates on the line at the end of each segment (the branch continued from ``q0``)."""
    out = []
    prev = q0
    for k in range(1, n + 1):
        aim = p0 + (p1 - p0) * (k / n)
        if stage is not None:
            q = stage.inverse(aim)
        else:
            q = kin.inverse(aim, geometry, near=prev, min_reach=min_reach, check_limits=False)
        problem = kin.limit_problem(q, joints)
        if problem:
            shown = ", ".join(f"{v * 1e6:.1f}" for v in aim)
            raise kin.OutOfReach(
                f"the straight line leaves the arm's reach {k / n:.0%} of the way, at ({shown}) µm: {problem}"
            )
        if stage is None and (abs(q[0] - prev[0]) > 0.5 or abs(q[1] - prev[1]) > 0.5):  # a branch flip
            raise kin.SingularPose("the straight line crosses joint 1's axis (a singular pose); move in two legs")
        out.append(q)
        prev = q
    return out


_ALONG_WEIGHT = 0.25  # how much a segment's lag along the line counts against its distance from it


def _segment_steps(
    calibration: Calibration,
    step_model: str,
    q: Vec3,
    goal: NDArray[np.float64],
    tilt: tuple[float, float],
    geometry: kin.Geometry,
    p0: NDArray[np.float64],
    p1: NDArray[np.float64],
    aim: NDArray[np.float64],
    last: bool,
    stage: kin.Stage | None = None,
    joints: kin.JointSet | None = None,
) -> tuple[tuple[int, int, int], Vec3]:
    """Whole steps of joints 1, 2, 3 for one segment, and the predicted joints after them.

    Each joint's exact (real) count from its predicted position to ``goal`` is rounded
    down or up; of those (at most 8) choices, stepped in the order 1, 2, 3, the one
    whose tip stays closest to the line (the largest distance after each joint, plus
    :data:`_ALONG_WEIGHT` times the distance from ``aim``) is taken, and on the last
    segment the one that ends closest to the target. Either way every joint is within
    one step of its ideal position, and the fraction not taken is carried to the next
    segment (its counts start from the predicted position).
    """
    d = p1 - p0
    dd = float(d @ d)
    specs = kin.JOINTS if joints is None else joints

    def tip_at(qq: Vec3) -> NDArray[np.float64]:
        return stage.tip(qq) if stage is not None else kin.tip(qq, geometry)

    def off_line(p: NDArray[np.float64]) -> float:
        r = p - p0
        return float(np.linalg.norm(r - (float(r @ d) / dd) * d))

    best: tuple[float, tuple[int, int, int], Vec3] | None = None

    def expand(j: int, qq: Vec3, steps: tuple[int, ...], worst: float) -> None:
        nonlocal best
        if j == 4:
            tip_end = tip_at(qq)
            miss = float(np.linalg.norm(tip_end - aim))
            score = miss if last else worst + _ALONG_WEIGHT * miss
            if best is None or score < best[0]:
                best = (score, (steps[0], steps[1], steps[2]), qq)
            return
        target = float(goal[j - 1])
        if target == qq[j - 1]:  # a joint the move does not use needs no calibration
            expand(j + 1, qq, (*steps, 0), worst)
            return
        here = kin.Pose(qq[0], qq[1], qq[2], *tilt)
        try:
            stepper = JointStepper(calibration, specs[j], here, step_model)
            exact = stepper.exact_steps(qq[j - 1], target)
        except NonPhysicalError as e:
            raise ValueError(f"joint {j} cannot step in this pose: {e}") from None
        spec = specs[j]
        choices: set[tuple[int, float]] = set()
        for nj in {math.floor(exact), math.ceil(exact)}:
            q_new = stepper.position_after(qq[j - 1], nj)
            while nj and not spec.lower <= q_new <= spec.upper:  # never plan past an end stop
                nj -= 1 if nj > 0 else -1
                q_new = stepper.position_after(qq[j - 1], nj)
            choices.add((nj, q_new))
        for nj, q_new in sorted(choices):
            moved = list(qq)
            moved[j - 1] = q_new
            q_next = (moved[0], moved[1], moved[2])
            worst_next = max(worst, off_line(tip_at(q_next))) if dd else 0.0
            expand(j + 1, q_next, (*steps, nj), worst_next)

    expand(1, q, (), 0.0)
    assert best is not None  # every branch reaches joint 3 (a choice past a stop is cut back to it)
    return best[1], best[2]


def plan_reach(
    calibration: Calibration,
    pose: kin.Pose,
    to: ArrayLike | None = None,
    by: ArrayLike | None = None,
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY,
    segment: float = 10e-6,
    min_reach: float = kin.MIN_REACH,
    step_model: str = "calibrated",
    stage: kin.Stage | None = None,
    joints: kin.JointSet | None = None,
) -> ReachPlan:
    """Plan a straight move of the tip to ``to`` or by ``by`` (m, base frame) from ``pose``.

    Parameters
    ----------
    calibration : Calibration
        Step-size models of joints 1, 2 and 3 (those the move needs).
    pose : Pose
        The arm's joints (rad, rad, m) and base tilt (rad) at the start.
    to, by : array_like of 3 floats
        Target tip position, or displacement, m; exactly one.
    geometry : Geometry
    segment : float
        Longest segment, m (default 10 µm); see the module docstring.
    min_reach : float
        Closest the line may pass joint 1's axis, m.
    step_model : {"calibrated", "constant"}
    stage : Stage or None
        A Cartesian arm's kinematics (the module docstring); ``geometry`` and
        ``min_reach`` are then not used.
    joints : JointSet or None
        The arm's joints (ranges, how each steps): the MM3A's by default.

    Returns
    -------
    ReachPlan

    Raises
    ------
    OutOfReach, SingularPose
        Before anything is planned, if the line leaves the joints' ranges or passes too
        close to joint 1's axis.
    ValueError, KeyError
        A bad argument or pose; a joint or direction the move needs is not calibrated.
    """
    if (to is None) == (by is None):
        raise ValueError("give exactly one of to and by")
    q0 = np.array(pose[:3], dtype=float)
    problem = kin.limit_problem(q0, joints)
    if problem:
        raise kin.OutOfReach(f"the start pose is outside the joints' ranges: {problem}")
    p0 = stage.tip(q0) if stage is not None else kin.tip(q0, geometry)
    vec = np.asarray(to if to is not None else by, dtype=float).reshape(3)
    if not np.all(np.isfinite(vec)):
        raise ValueError(f"the {'target' if to is not None else 'displacement'} {vec.tolist()} is not finite")
    p1 = vec if to is not None else p0 + vec
    length = float(np.linalg.norm(p1 - p0))
    n, seg_len = _segment_count(length, float(segment))
    rho0 = math.inf if stage is not None else float(kin.distance_from_axis(q0, geometry))
    if n and rho0 < min_reach:
        raise kin.SingularPose(
            f"the tip is {rho0 * 1e3:.3g} mm from joint 1's axis, closer than {min_reach * 1e3:.3g} mm: a singular "
            f"pose; tilt the arm (joint 2) away from the vertical first"
        )
    if n and stage is None:
        _check_line_clear_of_axis(p0, p1, min_reach)
    ideal = _ideal_path(q0, p0, p1, n, geometry, min_reach, stage, joints)
    theta, psi = float(pose[3]), float(pose[4])
    q: Vec3 = _vec(q0)
    segments: list[ReachSegment] = []
    for k, goal in enumerate(ideal, start=1):
        aim = p0 + (p1 - p0) * (k / n)
        steps, q = _segment_steps(calibration, step_model, q, goal, (theta, psi), geometry, p0, p1, aim, k == n,
                                  stage, joints)
        tip = stage.tip(q) if stage is not None else kin.tip(q, geometry)
        segments.append(ReachSegment(steps, q, _vec(tip), _vec(aim)))
    return ReachPlan(_vec(q0), _vec(p0), _vec(p1), segments, geometry, theta, psi, step_model, seg_len, stage)
