"""The camera against the manipulator: finding the tip by moving a joint, and the camera calibration.

:func:`acquire_tip` steps a joint back and forth and takes what moved
(:func:`stickslip.vision.acquire.find_moving_tip`). :func:`calibrate_camera` moves each
joint a few known step counts out and back at the current pose, tracks the tip after each
(:class:`stickslip.vision.track.TipTracker`), fits each direction's image Jacobian
(:func:`stickslip.vision.jacobian.fit_image_jacobian`) and turns it into the step size at
this pose (:func:`stickslip.vision.jacobian.step_size`): rows of the step-size table
(:class:`stickslip.measurements.StepSize`, method ``camera``) that ``stickslip calibrate``
takes beside traverses. A joint whose tip is lost, whose motion is not linear in its steps
or that moves the tip along the optical axis is refused with the reason; the others are
measured.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .. import kinematics as kin
from ..devices.base import Controller
from ..devices.positions import DeviceState
from ..measurements import StepSize
from ..vision.acquire import find_moving_tip
from ..vision.camera import Camera
from ..vision.jacobian import (
    MIN_VISIBILITY,
    CameraCalibration,
    DirectionFit,
    JacobianError,
    StepSizeEstimate,
    fit_image_jacobian,
    step_size,
    visibility,
)
from ..vision.track import Fix, Lost, TemplateError, TipTracker, TrackerParams
from ..vision.view import TOP_VIEW, View

__all__ = [
    "JointResult",
    "CameraCalibrationResult",
    "acquire_tip",
    "calibrate_camera",
    "dead_reckon",
    "mark_stepped",
]


Progress = Callable[[int, int], None]


def acquire_tip(
    device: Controller, camera: Camera, joint: int = 1, steps: int = 20, frames: int = 2
) -> tuple[float, float]:
    """The tip's pixel now, found by stepping ``joint`` by ``steps`` and back (``frames`` frames at each end).

    The joint ends where it began to within the steps' scatter. Raises
    :class:`stickslip.vision.acquire.AcquireError` when nothing moved or no needle's tip shows.
    """
    if steps == 0:
        raise ValueError("the joint must move: give a step count other than 0")
    device.step(joint, steps)
    moved = [camera.grab().image for _ in range(frames)]
    device.step(joint, -steps)
    back = [camera.grab().image for _ in range(frames)]
    return find_moving_tip(moved, back)


@dataclass(frozen=True)
class JointResult:
    """One joint's part of the camera calibration.

    Attributes
    ----------
    joint : int
    fits : tuple of DirectionFit
        The image motion of ``+`` then ``-`` (those measured).
    step_sizes : tuple of StepSizeEstimate
        The step size of each direction at this pose.
    refused : str or None
        Why the joint gave no step size (the tip lost, a motion not linear in the
        steps, a joint along the optical axis).
    net_q : float
        How far the joint ended from where it began (rad or m), by the measured steps.
    """

    joint: int
    fits: tuple[DirectionFit, ...] = ()
    step_sizes: tuple[StepSizeEstimate, ...] = ()
    refused: str | None = None
    net_q: float = 0.0


@dataclass(frozen=True)
class CameraCalibrationResult:
    """The camera calibration at one pose.

    Attributes
    ----------
    pose : Pose
        The pose it began at.
    tip : tuple of float
        The tip's pixel at the start.
    joints : tuple of JointResult
    rows : tuple of StepSize
        The step sizes as rows of the step-size table (method ``camera``).
    calibration : CameraCalibration or None
        What turns later fixes into joint positions (the joints measured), ``None`` if none was.
    pixel_size_m : float or None
    """

    pose: kin.Pose
    tip: tuple[float, float]
    joints: tuple[JointResult, ...]
    rows: tuple[StepSize, ...]
    calibration: CameraCalibration | None
    pixel_size_m: float | None
    notes: tuple[str, ...] = field(default_factory=tuple)

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: the pose, the tip, each joint's fits, step sizes and refusal (SI, px)."""
        return {
            "pose": dict(self.pose._asdict()),
            "tip": list(self.tip),
            "pixel_size_m": self.pixel_size_m,
            "joints": [
                {
                    "joint": r.joint,
                    "refused": r.refused,
                    "fits": [f.as_dict() for f in r.fits],
                    "step_sizes": [
                        {"direction": s.direction, "gamma": s.gamma, "sigma": s.sigma, "steps": s.steps,
                         "visibility": s.visibility}
                        for s in r.step_sizes
                    ],
                }
                for r in self.joints
            ],
            "notes": list(self.notes),
        }


def _track(tracker: TipTracker, camera: Camera) -> Fix | Lost:
    return tracker.update(camera.grab())


def calibrate_camera(
    device: Controller,
    camera: Camera,
    pose: kin.Pose,
    joints: Sequence[int] = (3, 1, 2),
    increments: Sequence[int] | None = None,
    tip: tuple[float, float] | None = None,
    view: View = TOP_VIEW,
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY,
    pixel_size_m: float | None = None,
    day: str = "",
    auto_joint: int = 1,
    auto_steps: int = 20,
    params: TrackerParams = TrackerParams(),
    progress: Progress | None = None,
    max_steps: int = 200,
    probe: int = 10,
    max_move_px: float = 16.0,
) -> CameraCalibrationResult:
    """Measure each joint's image motion and step size at ``pose`` (see the module docstring).

    Parameters
    ----------
    device, camera
        The arm, and a camera that sees its tip.
    pose : Pose
        Where the arm is (joints rad, rad, m; tilt rad): the kept positions.
    joints : sequence of int
        Joints to measure, in order.
    increments : sequence of int, optional
        Positive step counts of the moves out; the moves back repeat them. Default: a
        probe of ``probe`` steps, then moves of at most ``max_move_px`` px each (the
        tracker follows the tip from frame to frame) up to ``max_steps`` steps or a
        third of the field, whichever comes first.
    tip : tuple of float, optional
        The tip's pixel now; default: found by stepping ``auto_joint`` by ``auto_steps``
        and back (:func:`acquire_tip`).
    view : View
        How the camera looks at the rig (default: straight down).
    geometry : Geometry
        The arm's tip geometry, m.
    pixel_size_m : float, optional
        Pixel size, m; default the camera's. Without one the image Jacobians are measured
        but no step size.
    day : str
        Session label for the rows.
    progress : callable, optional
        ``progress(done, total)`` after each move.
    """
    _check_arguments(joints, increments, probe, max_steps)
    if pixel_size_m is None:
        pixel_size_m = camera.info.pixel_size_m
    notes: list[str] = []
    if tip is None:
        tip = acquire_tip(device, camera, auto_joint, auto_steps)
        notes.append(
            f"tip found at ({tip[0]:.1f}, {tip[1]:.1f}) px by stepping joint {auto_joint} {auto_steps} and back"
        )
    if pixel_size_m is None:
        notes.append("the camera's pixel size is unknown: image Jacobians only, no step sizes (give pixel= in its URL)")
    start_tip = (float(tip[0]), float(tip[1]))
    total = len(joints) * 2 * (len(increments) if increments else max(4, int(max_steps // probe)))
    session = _Session(device, camera, pose, view, geometry, pixel_size_m, day, params, increments, probe, max_steps,
                       max_move_px, progress, total)
    results: list[JointResult] = []
    rows: list[StepSize] = []
    fits_all: list[DirectionFit] = []
    current = start_tip
    for j in joints:
        result, joint_rows, current, lost_tip = _measure_joint(session, j, current)
        results.append(result)
        rows += joint_rows
        fits_all += list(result.fits) if result.refused is None else []
        if lost_tip:
            rest = [k for k in joints if k not in {r.joint for r in results}]
            for k in rest:
                results.append(JointResult(k, refused=f"joint {k}: not measured, the tip was not found again after "
                                                      f"joint {j} went back (give the tip again and measure it alone)"))
            break
    cal = None
    if fits_all and pixel_size_m is not None:
        cal = CameraCalibration.from_fits(fits_all, pose, start_tip, pixel_size_m, view, geometry)
    return CameraCalibrationResult(pose, start_tip, tuple(results), tuple(rows), cal, pixel_size_m, tuple(notes))


def _check_arguments(joints: Sequence[int], increments: Sequence[int] | None, probe: int, max_steps: int) -> None:
    """``ValueError`` for an unknown joint, a step count that is not positive, a probe outside 1..max_steps."""
    if increments is not None and (not increments or any(int(n) <= 0 for n in increments)):
        raise ValueError(f"increments must be positive step counts, got {list(increments)}")
    if not (1 <= probe <= max_steps):
        raise ValueError(f"probe = {probe} steps must be in 1..max_steps ({max_steps})")
    for j in joints:
        kin.joint_spec(j)


@dataclass
class _Session:
    """One camera calibration: the arm, the camera, the pose and how to move; the moves made so far."""

    device: Controller
    camera: Camera
    pose: kin.Pose
    view: View
    geometry: kin.Geometry
    pixel_size_m: float | None
    day: str
    params: TrackerParams
    increments: Sequence[int] | None
    probe: int
    max_steps: int
    max_move_px: float
    progress: Progress | None
    total: int
    done: int = 0

    def moved(self) -> None:
        """One move out made: the progress callback is told."""
        self.done += 1
        if self.progress is not None:
            self.progress(min(self.done, self.total), self.total)


class _Refusal(Exception):
    """Why a joint gave no step size (the tip lost, a motion not linear in its steps)."""


@dataclass
class _JointRun:
    """One joint moved out and back while the tracker follows the tip: its plan of moves, the steps it is out."""

    session: _Session
    joint: int
    tracker: TipTracker
    current: tuple[float, float]
    plan: list[int]
    moved: int = 0  # signed steps sent on this joint

    def direction(self, sign: int) -> DirectionFit:
        """Move out in ``sign``'s direction (the probe, then the plan), tracking; the direction's image motion."""
        se, j = self.session, self.joint
        d = "+" if sign > 0 else "-"
        counts, points, sigmas = [0], [self.current], [0.05]
        n = 0
        steps_this_way = list(self.plan) if self.plan else [se.probe]
        k = 0
        misses = 0
        while k < len(steps_this_way):
            inc = steps_this_way[k]
            k += 1
            se.device.step(j, sign * int(inc))
            self.moved += sign * int(inc)
            n += int(inc)
            se.moved()
            r = _track(self.tracker, se.camera)
            if isinstance(r, Lost) and not self.plan:  # the probe's frame refused: another look, without moving
                r = _track(self.tracker, se.camera)
            if isinstance(r, Lost):
                misses += 1
                if misses >= 2 or not self.plan:  # one frame may be refused; the tip must come back in the next
                    raise _Refusal(f"joint {j}{d}: the tip was lost after {n} steps ({r.reason}: {r.detail})")
                continue
            misses = 0
            counts.append(n)
            points.append((r.x, r.y))
            sigmas.append(r.sigma)
            if not self.plan and k == 1:  # after the probe: the moves that keep the tip in view, a few px each
                speed = math.hypot(r.x - self.current[0], r.y - self.current[1]) / max(n, 1)
                self.plan = _plan(speed, n, camera_shape(se.camera, self.tracker), se.max_steps, se.max_move_px)
                steps_this_way += self.plan[1:]
            self.current = (r.x, r.y)
        try:
            return fit_image_jacobian(j, d, counts, points, sigmas)
        except JacobianError as e:
            raise _Refusal(str(e)) from None

    def back(self) -> bool:
        """Bring the joint back to where it began, in step count, a move at a time, following the tip.

        True if the tip was lost on the way.
        """
        if not self.moved:
            return False
        per = max(1, max(self.plan) if self.plan else self.session.probe)
        last: Fix | Lost | None = None
        while self.moved:
            back = -self.moved if abs(self.moved) <= per else (-per if self.moved > 0 else per)
            self.session.device.step(self.joint, back)
            self.moved += back
            last = _track(self.tracker, self.session.camera)
        if isinstance(last, Fix):
            self.current = (last.x, last.y)
            return False
        return True


def _measure_joint(
    se: _Session, j: int, current: tuple[float, float]
) -> tuple[JointResult, list[StepSize], tuple[float, float], bool]:
    """Joint ``j`` measured from the tip at ``current``: its result, its rows, the tip after, whether it was lost."""
    if se.pixel_size_m is not None:
        m = visibility(j, se.pose, se.view, se.geometry)
        if m < MIN_VISIBILITY:
            return JointResult(j, refused=(
                f"joint {j} moves the tip mostly along the camera's optical axis at this pose "
                f"(only {100 * m:.0f} % "
                "of its motion is in the image): not moved; tilt the camera or measure it in another pose"
            )), [], current, False
    try:
        tracker = TipTracker(se.camera.grab(), current, se.params)
    except TemplateError as e:
        refusal = f"joint {j}: not measured, the tip could not be learned ({e})"
        return JointResult(j, refused=refusal), [], current, False
    run = _JointRun(se, j, tracker, current, [int(n) for n in se.increments] if se.increments else [])
    fits: list[DirectionFit] = []
    refused: str | None = None
    try:
        for sign in (1, -1):
            fits.append(run.direction(sign))
    except _Refusal as e:
        refused = str(e)
    lost_tip = run.back()
    sizes: list[StepSizeEstimate] = []
    rows: list[StepSize] = []
    if refused is None and se.pixel_size_m is not None:
        try:
            sizes, rows = _step_sizes(se, j, fits, se.pixel_size_m)
        except JacobianError as e:
            refused = str(e)
    net = 0.0
    if len(sizes) == 2:
        net = sizes[0].gamma * sizes[0].steps - sizes[1].gamma * sizes[1].steps
    return JointResult(j, tuple(fits), tuple(sizes), refused, net), rows, run.current, lost_tip


def _step_sizes(
    se: _Session, j: int, fits: list[DirectionFit], pixel_size_m: float
) -> tuple[list[StepSizeEstimate], list[StepSize]]:
    """The step size of ``+`` and ``-`` at the middle of each one's travel, and as rows (method ``camera``)."""
    pose, view, geometry = se.pose, se.view, se.geometry
    q0 = (pose.q1, pose.q2, pose.q3)[j - 1]
    plus = step_size(fits[0], _at(pose, j, q0), pixel_size_m, view, geometry)
    q_far = q0 + plus.gamma * plus.steps
    q_mid = q0 + 0.5 * plus.gamma * plus.steps
    plus = step_size(fits[0], _at(pose, j, q_mid), pixel_size_m, view, geometry)
    minus = step_size(fits[1], _at(pose, j, q_far), pixel_size_m, view, geometry)
    minus = step_size(fits[1], _at(pose, j, q_far - 0.5 * minus.gamma * minus.steps), pixel_size_m,
                      view, geometry)
    rows: list[StepSize] = []
    for s, q_mid in ((plus, q0 + 0.5 * plus.gamma * plus.steps),
                     (minus, q_far - 0.5 * minus.gamma * minus.steps)):
        p = _at(pose, j, q_mid)
        rows.append(StepSize(se.day, j, s.direction, p.q1, p.q2, p.q3, p.theta, p.psi, s.gamma, s.sigma,
                             s.steps, "camera"))
    return [plus, minus], rows


def mark_stepped(state: DeviceState, joints: Sequence[int]) -> None:
    """Keep ``joints`` uncertain over their range while a camera calibration steps them (saved before the first step).

    Its end is written after the measurement (:func:`dead_reckon`); a device error, Ctrl-C or a
    kill before that left the positions from before it kept, as if the joints had not moved
    (some hundreds of steps out and back, the tip found by stepping the auto joint).
    """
    for j in sorted(set(joints)):
        spec = state.spec(j)
        state.mark_uncertain(j, spec.lower, spec.upper, "a camera calibration was interrupted")


def dead_reckon(state: DeviceState, result: CameraCalibrationResult) -> None:
    """Put the measured joints where they ended, by the steps the camera saw (within their stops, ``dead-reckoned``)."""
    for jr in result.joints:
        if jr.net_q:
            q = min(max(state.positions[jr.joint] + jr.net_q, kin.JOINTS[jr.joint].lower), kin.JOINTS[jr.joint].upper)
            state.set_position(jr.joint, q, "dead-reckoned")


def camera_shape(camera: Camera, tracker: TipTracker) -> tuple[int, int]:
    """The frames' ``(height, width)``, px."""
    return tracker.shape


def _plan(speed: float, done: int, shape: tuple[int, int], max_steps: int, max_move_px: float) -> list[int]:
    """The moves of one direction after a probe of ``done`` steps that moved the tip ``speed`` px per step.

    Up to ``max_steps`` in all, or as many as move the tip a third of the field's smaller
    side; each move at most ``max_move_px``; at least three moves (the fit needs them).
    """
    if speed <= 0:
        return [done, done, done]
    total = int(min(max_steps, max(3 * done, min(shape) / 3.0 / speed)))
    per = max(1, int(max_move_px / speed))
    out = [done]
    left = total - done
    while left > 0:
        step = min(per, left)
        out.append(step)
        left -= step
    while len(out) < 3:
        out.append(done)
    return out


def _at(pose: kin.Pose, joint: int, q: float) -> kin.Pose:
    """``pose`` with joint ``joint`` at ``q``."""
    return pose._replace(**{f"q{joint}": float(q)})
