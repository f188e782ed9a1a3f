"""Closing the loop with the camera: ``move`` and ``reach`` that look at the tip after each leg.

:func:`move_seen` and :func:`reach_seen` drive a joint move or a straight tip move in
*legs* (each short enough that the tip moves at most :attr:`CameraLoop.max_leg_px` in the
image, so the tracker follows it from frame to frame). After each leg the camera is
grabbed, the tip tracked (:class:`stickslip.vision.track.TipTracker`) and the fix turned
into joint observations through the image Jacobian (:func:`stickslip.vision.jacobian.joint_observation`):

* the image Jacobian at the kept pose ``q_k`` is ``G = A J_tip(q_k)``
  (:func:`stickslip.kinematics.jacobian`), ``A`` the image map (:func:`image_map`): the
  kinematic ``P / s`` of the assumed view (:func:`stickslip.vision.view.base_to_image`),
  or the camera fitted to the image Jacobian ``camera calibrate`` measured
  (:attr:`CameraLoop.jacobian`, :meth:`stickslip.vision.jacobian.MeasuredJacobian.image_map`);
* the tip is expected at ``u_k = u_0 + A (tip(q_k) - tip(q_0))``, ``u_0`` the fix at
  the start ``q_0``; the fix's difference from ``u_k`` gives the joints moved in the leg
  (one joint: ``joint_observation``; several: the same least squares over their columns);
* each observation goes into the joint's Kalman filter as ``stickslip observe`` does
  (:class:`stickslip.motion.tracking.JointTrack`, the same innovation gate,
  :data:`stickslip.procedures.observe.MAX_INNOVATION`): the position is corrected and,
  through the correlation the leg built, the day's step scale, with which the next leg
  is planned. The joint is kept as ``seen``.

The camera measures motion from the start: a seen position is as good as the start's
position (its standard deviation is added back at the end) plus the camera's.

The loop ends when the tip is within the tolerance of the target (default: 1 px or
0.5 µm, whichever is larger), or stops with its reason: the tip lost (the joints moved
since the last look stay dead-reckoned, their uncertainty grown, not seen), no progress
(a correction that does not shrink the error by a fifth, or an error smaller than the
steps can make), the camera disagreeing with the dead reckoning beyond the gate (a slip,
a wrong fix: the joint is kept uncertain over both), a limit (a target out of range or
reach, a motion the camera cannot see, a device error), or too many
corrections (a *correction* is a leg planned after the dead reckoning had reached the
target: the open-loop move takes none).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, ExitStack
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from .. import kinematics as kin
from ..calibration import Calibration
from ..calibration.update import day_drift
from ..devices.base import Controller, DeviceError, KnowsTruePosition, PoseSettable, device_key, open_device
from ..devices.identity import open_checked
from ..devices.positions import DeviceState, StateStore, load_state, save_state
from ..motion.planning import Planner
from ..motion.reach import plan_reach
from ..motion.tracking import JointTrack, joint_sigma_model, scaled_calibration, track_for
from ..rig.envelope import EnvelopeViolation
from ..rig.guard import Guard
from ..units import format_position
from ..vision.acquire import AcquireError
from ..vision.camera import Camera, CameraError, open_camera
from ..vision.jacobian import (
    MIN_VISIBILITY,
    CameraCalibration,
    JacobianError,
    MeasuredJacobian,
    joint_observation,
    visibility,
)
from ..vision.track import Fix, TipTracker
from ..vision.view import TOP_VIEW, View, base_to_image
from .camera import acquire_tip
from .conditions import calibration_device_problem, usage_warnings
from .move import (
    Interrupted,
    MoveRefused,
    MoveRequest,
    MoveStore,
    check_envelope_path,
    claim_and_check,
    claimed,
    device_lock,
    drive,
    joint_line,
    kept_after_interrupt,
    reference_problem,
    release_claim,
    sharing_controller,
    sigma_growth,
    target_of,
)
from .observe import MAX_INNOVATION
from .reach import ReachRequest, drive_reach, joint_path, referenced_state

__all__ = [
    "FINDING_TIP",
    "CameraLoop",
    "JogEyes",
    "image_map",
    "Look",
    "LoopResult",
    "move_seen",
    "reach_seen",
    "tolerance_m",
]

Vec3 = tuple[float, float, float]

AUTO_STEPS = 20
"""Steps out (and back) of the joint stepped to find the tip when none is given."""

LOOK_AGAIN = 2
"""Frames grabbed again, without moving, after a refused one before the tip counts as lost."""

CameraOpener = Callable[[str, Controller], Camera]

FINDING_TIP = "was stepped out and back to find the tip"
"""What ``where`` says of the joint stepped to find the tip until it is back (its journal: the steps out may
have been sent and the steps back not, so a front end's stop there leaves it uncertain)."""


@dataclass(frozen=True)
class CameraLoop:
    """How the loop looks at the tip.

    Attributes
    ----------
    camera : str
        Camera URL (``simcam://?pixel=1um``, ``opencv://0?pixel=0.5um``): it must know its pixel size.
    tip : tuple of float or None
        The tip's pixel now (x right, y down, the centre of the top-left pixel at (0, 0));
        ``None``: found by stepping joint ``auto_joint`` back and forth
        (:func:`stickslip.procedures.camera.acquire_tip`).
    tolerance_px, tolerance : float
        The move ends when the seen tip is within the larger of ``tolerance_px`` pixels and
        ``tolerance`` m of the target (default 1 px or 0.5 µm).
    max_corrections : int
        Most legs after the dead reckoning has reached the target.
    max_leg_px : float
        Longest leg, px of expected image motion (the tracker searches ±32 px around its last fix).
    view : View
        How the camera looks at the rig (default straight down).
    auto_joint : int
        The joint stepped to find the tip when ``tip`` is ``None``.
    jacobian : MeasuredJacobian or None
        The image Jacobian ``stickslip camera calibrate --jacobian`` measured with this
        camera (``--camera-calibration``): the loop's image Jacobian is then the camera
        fitted to it (:meth:`~stickslip.vision.jacobian.MeasuredJacobian.image_map`),
        ``view`` filling in only what it did not measure. ``None``: the kinematic one of ``view``.
    scale_warn_sd : float
        A step scale the camera taught more than this many prior standard deviations (a day's change of step and
        the calibration's model error, as the filter starts them) from the calibration's is said in a warning,
        1: the loop cannot tell steps that changed from a camera whose stated pixel size is wrong, and a wrong
        pixel size ends the move "reached" at a wrong place (a pixel stated 0.67 of its size: the tip at 89 µm
        for 60 µm). 3: a day's change beyond it happens about once in 370 days.
    """

    camera: str
    tip: tuple[float, float] | None = None
    tolerance_px: float = 1.0
    tolerance: float = 0.5e-6
    max_corrections: int = 4
    max_leg_px: float = 16.0
    view: View = TOP_VIEW
    auto_joint: int = 3
    jacobian: MeasuredJacobian | None = None
    scale_warn_sd: float = 3.0

    def __post_init__(self) -> None:
        if not isinstance(self.camera, str):  # an opened camera object: the loop opens its own, on the arm it drives
            raise TypeError(
                f"CameraLoop's camera is a camera URL (simcam://?pixel=1um, opencv://0?pixel=0.5um), not a "
                f"{type(self.camera).__name__}: the loop opens the camera itself"
            )
        for name in ("tolerance_px", "tolerance", "max_leg_px", "scale_warn_sd"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r} must be finite and > 0")
        if not 0 <= self.max_corrections <= 100:
            raise ValueError(f"max_corrections = {self.max_corrections} must be in 0..100")
        if self.tip is not None and not all(math.isfinite(v) for v in self.tip):
            raise ValueError(f"the tip {self.tip} must be a finite pixel")


@dataclass(frozen=True)
class Look:
    """One look at the tip after a leg.

    Attributes
    ----------
    steps : tuple of int
        Signed steps of joints 1, 2, 3 sent in the leg.
    pixel : tuple of float or None
        The fix, px (``None``: refused).
    seen : dict
        ``{joint: (q, sd)}``: the observed positions (rad or m) and their standard deviations.
    q : tuple of float
        The kept joint positions after the Kalman update (rad, rad, m).
    error : float
        The tip's distance from the target by the kept positions, m.
    correction : bool
        The leg was a correction (planned after the dead reckoning had reached the target).
    step_scale : dict
        ``{joint: scale}`` after the update (1).
    """

    steps: tuple[int, int, int]
    pixel: tuple[float, float] | None
    seen: dict[int, tuple[float, float]]
    q: Vec3
    error: float
    correction: bool
    step_scale: dict[int, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        return {
            "steps": list(self.steps), "pixel": None if self.pixel is None else list(self.pixel),
            "seen": {str(j): {"q": q, "sd": s} for j, (q, s) in sorted(self.seen.items())},
            "q": list(self.q), "error": self.error, "correction": self.correction,
            "step_scale": {str(j): s for j, s in sorted(self.step_scale.items())},
        }


@dataclass(frozen=True)
class LoopResult:
    """What a closed-loop move did (SI units).

    Attributes
    ----------
    device : str
        The device's key.
    reached : bool
        The seen tip ended within the tolerance.
    reason : str or None
        Why it stopped short (``None`` when reached).
    looks : tuple of Look
    target : tuple of float
        The tip's target, base frame, m.
    tolerance : float
        The tolerance used, m.
    state : DeviceState
        The kept state after the move.
    sim_true : tuple of float or None
        The simulator's true joints at the end (rad, rad, m); ``None`` on a real controller.
    geometry : Geometry
    """

    device: str
    reached: bool
    reason: str | None
    looks: tuple[Look, ...]
    target: Vec3
    tolerance: float
    state: DeviceState
    sim_true: Vec3 | None = None
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY

    @property
    def corrections(self) -> int:
        """Legs planned after the dead reckoning had reached the target."""
        return sum(1 for k in self.looks if k.correction)

    @property
    def error(self) -> float:
        """The tip's distance from the target by the kept positions at the end, m."""
        return self.looks[-1].error if self.looks else math.nan

    @property
    def sim_true_error(self) -> float | None:
        """The simulator's true tip's distance from the target, m."""
        if self.sim_true is None:
            return None
        return math.dist(kin.tip(self.sim_true, self.geometry), self.target)

    def as_dict(self) -> dict[str, object]:
        """The ``camera`` part of ``move --camera --json`` and ``reach --camera --json``."""
        out: dict[str, object] = {
            "device": self.device, "reached": self.reached, "reason": self.reason, "corrections": self.corrections,
            "legs": len(self.looks), "error": self.error, "tolerance": self.tolerance, "target": list(self.target),
            "looks": [k.as_dict() for k in self.looks],
            "sources": {str(j): "uncertain" if j in self.state.uncertain else self.state.sources[j] for j in (1, 2, 3)},
        }
        if self.sim_true is not None:
            out["sim_true"] = {"q": list(self.sim_true), "error": self.sim_true_error}
        return out


def tolerance_m(loop: CameraLoop, pixel_size_m: float) -> float:
    """The tolerance, m: the larger of ``loop.tolerance_px`` pixels and ``loop.tolerance``."""
    return max(loop.tolerance_px * pixel_size_m, loop.tolerance)


# ---------------------------------------------------------------- seeing the joints


def image_map(loop: CameraLoop, pixel_size_m: float, pose: kin.Pose, geometry: kin.Geometry) -> np.ndarray:
    """The loop's 2 x 3 image map at ``pose`` (px per m of a base-frame displacement).

    The kinematic ``P / s`` of ``loop.view``, or, with a measured Jacobian
    (``loop.jacobian``), the camera fitted to it.
    """
    A0 = base_to_image(loop.view, pixel_size_m, pose.theta, pose.psi)
    if loop.jacobian is None:
        return A0
    return loop.jacobian.image_map(A0, geometry)


def image_calibration(
    pose: kin.Pose, reference_px: tuple[float, float], pixel_size_m: float, view: View, geometry: kin.Geometry,
    range_px: float, image_map: np.ndarray | None = None,
) -> CameraCalibration:
    """The camera calibration at ``pose``: each visible joint's image motion per unit (px per rad or m).

    ``G = A J_tip(q)`` with ``A`` the image map (default the kinematic ``P / s`` of
    ``view``), the columns of the joints that move the tip at least
    :data:`~stickslip.vision.jacobian.MIN_VISIBILITY` of their motion's length in the image.
    """
    J = kin.jacobian((pose.q1, pose.q2, pose.q3), geometry)
    if image_map is None:
        G = base_to_image(view, pixel_size_m, pose.theta, pose.psi) @ J
        seen = [j for j in (1, 2, 3) if visibility(j, pose, view, geometry) >= MIN_VISIBILITY]
    else:
        G = np.asarray(image_map, dtype=float) @ J
        seen = [j for j in (1, 2, 3)
                if float(np.linalg.norm(G[:, j - 1])) * pixel_size_m
                >= MIN_VISIBILITY * float(np.linalg.norm(J[:, j - 1])) > 0]
    cols = {j: (float(G[0, j - 1]), float(G[1, j - 1])) for j in seen}
    return CameraCalibration(pose, reference_px, cols, pixel_size_m, view, geometry, range_px)


def seen_share(loop: CameraLoop, pose: kin.Pose, geometry: kin.Geometry, motion: npt.ArrayLike) -> float:
    """The share of a base-frame tip ``motion`` that lies in the image (0..1; 0 for no motion).

    Through the loop's image map at ``pose`` (the view's, or the measured camera's), as
    :func:`image_calibration` judges a joint's column.
    """
    s = loop.jacobian.pixel_size_m if loop.jacobian is not None else 1e-6  # the share does not depend on it
    v = np.asarray(motion, dtype=float)
    norm = float(np.linalg.norm(v))
    return float(np.linalg.norm(image_map(loop, s, pose, geometry) @ v)) * s / norm if norm > 0 else 0.0


def unseen_problem(loop: CameraLoop, joint: int, pose: kin.Pose, geometry: kin.Geometry) -> str | None:
    """Why the camera cannot close a one-joint loop of ``joint`` at ``pose``, or ``None``.

    The joint moves the tip mostly along the camera's line of sight: less than
    :data:`~stickslip.vision.jacobian.MIN_VISIBILITY` of its motion lies in the image, as
    :func:`image_calibration` leaves such a joint out (:func:`seen_share`).
    """
    share = seen_share(loop, pose, geometry, kin.jacobian((pose.q1, pose.q2, pose.q3), geometry)[:, joint - 1])
    if share >= MIN_VISIBILITY:
        return None
    return (
        f"joint {joint} moves the tip along the camera's line of sight here ({share:.0%} of its motion in the "
        f"image, at least {MIN_VISIBILITY:.0%} needed): the camera cannot see it move; move it without --camera"
    )


def observe_joints(
    cal: CameraCalibration, joints: Sequence[int], x: float, y: float, sigma_px: float
) -> dict[int, tuple[float, float]]:
    """``{joint: (q, sd)}`` from a fix at ``(x, y)`` ± ``sigma_px`` px, the ``joints`` having moved since ``cal.pose``.

    One joint: :func:`~stickslip.vision.jacobian.joint_observation`. Several: least squares
    over their columns of ``cal.px_per_unit``, the standard deviations from ``sigma_px² (GᵀG)⁻¹``;
    a fix more than ``3 sigma_px + 1`` px from their plane is refused as the seam refuses.
    Joints not calibrated (not seen from this view) are left out.
    """
    moved = [j for j in joints if j in cal.px_per_unit]
    if not moved:
        return {}
    if len(moved) == 1:
        o = joint_observation(cal, moved[0], x, y, sigma_px, off_line_limit=3.0 * sigma_px + 1.0)
        return {o.joint: (o.q, o.sigma)}
    G = np.array([cal.px_per_unit[j] for j in moved], dtype=float).T  # 2 x k
    du = np.array([x - cal.reference_px[0], y - cal.reference_px[1]])
    dq, *_ = np.linalg.lstsq(G, du, rcond=None)
    off = float(np.linalg.norm(du - G @ dq))
    if off > 3.0 * sigma_px + 1.0:
        raise JacobianError(f"the tip is {off:.3g} px off where joints {moved} can put it: a slip or a wrong fix")
    cov = sigma_px**2 * np.linalg.pinv(G.T @ G)
    q_ref = (cal.pose.q1, cal.pose.q2, cal.pose.q3)
    return {j: (q_ref[j - 1] + float(dq[k]), math.sqrt(max(float(cov[k, k]), 0.0))) for k, j in enumerate(moved)}


# ---------------------------------------------------------------- the loop


@dataclass
class _Run:
    """The loop's working state (one device, one camera, one tracker)."""

    dev: Controller
    cam: Camera
    tracker: TipTracker
    state: DeviceState
    store: StateStore
    calibration: Calibration
    loop: CameraLoop
    geometry: kin.Geometry
    pixel_size_m: float
    q0: Vec3
    u0: tuple[float, float]
    sigma0: float
    sd0: dict[int, float]
    tracks: dict[int, JointTrack]
    looks: list[Look] = field(default_factory=list)

    def save(self, st: DeviceState) -> None:
        save_state(self.store, st)

    def q(self) -> Vec3:
        p = self.state.positions
        return (p[1], p[2], p[3])

    def scaled(self) -> Calibration:
        cal = self.calibration
        for j, t in self.tracks.items():
            if j in {k for k, _ in cal.models}:
                cal = scaled_calibration(cal, j, {d: t.scale_of(d) for d in "+-"})
        return cal

    def predict(self, before: Vec3, steps: tuple[int, int, int]) -> None:
        """Propagate the tracks of the joints moved from ``before`` by ``steps``."""
        for j in (1, 2, 3):
            n = steps[j - 1]
            if n and j in self.tracks and j not in self.state.uncertain:
                delta = self.state.positions[j] - before[j - 1]
                self.tracks[j].predict(delta, n, self.state.pose, j, joint_sigma_model(self.calibration, j),
                                       ceiling=self.state.spec(j).span)
                self.state.track[j] = self.tracks[j].to_json()

    def look(self, steps: tuple[int, int, int], target: Vec3, correction: bool) -> str | None:
        """Grab, track, observe the moved joints, update; the reason to stop, or ``None``."""
        moved = [j for j in (1, 2, 3) if steps[j - 1]]
        try:
            r = self.tracker.update(self.cam.grab())
            for _ in range(LOOK_AGAIN):  # one frame may be refused (a particle, noise): look again without moving
                if isinstance(r, Fix):
                    break
                r = self.tracker.update(self.cam.grab())
        except (CameraError, ValueError) as e:  # no frame, or one the tracker cannot take (another size: ImageError)
            self.looks.append(Look(steps, None, {}, self.q(), self._error(target), correction, self._scales()))
            return f"the camera failed ({e}); the positions are dead-reckoned, not seen"
        if not isinstance(r, Fix):
            self.looks.append(Look(steps, None, {}, self.q(), self._error(target), correction, self._scales()))
            return f"the tip was lost ({r.reason}: {r.detail}); the positions are dead-reckoned, not seen"
        pose = self.state.pose
        A = self.image_map()
        u_k = np.asarray(self.u0) + A @ (
            np.asarray(kin.tip(self.q(), self.geometry)) - np.asarray(kin.tip(self.q0, self.geometry))
        )
        cal = image_calibration(pose, (float(u_k[0]), float(u_k[1])), self.pixel_size_m, self.loop.view,
                                self.geometry, range_px=4.0 * self.loop.max_leg_px, image_map=A)
        sigma_px = math.hypot(r.sigma, self.sigma0)
        try:
            seen = observe_joints(cal, moved, r.x, r.y, sigma_px)
        except JacobianError as e:
            self.looks.append(Look(steps, (r.x, r.y), {}, self.q(), self._error(target), correction, self._scales()))
            return f"the camera does not agree with the joints moved: {e}"
        for j, (q_meas, sd) in seen.items():
            track = self.tracks[j]
            q_before = self.state.positions[j]
            s_pred = math.hypot(track.sd, sd)
            if s_pred > 0 and abs(q_meas - q_before) > MAX_INNOVATION * s_pred:
                self._disputed(j, q_before, q_meas, sd)
                self.save(self.state)
                self.looks.append(Look(steps, (r.x, r.y), seen, self.q(), self._error(target), correction,
                                       self._scales()))
                return (
                    f"the camera sees joint {j} at {format_position(q_meas, j)}, "
                    f"{abs(q_meas - q_before) / s_pred:.3g} standard deviations from its dead reckoning "
                    f"{format_position(q_before, j)}: a slip or a wrong fix; not used, and joint {j} is kept uncertain "
                    "over both until it is referenced again"
                )
            q_new = track.observe(q_before, q_meas, sd)
            spec = kin.joint_spec(j)
            self.state.set_position(j, min(max(q_new, spec.lower), spec.upper), "seen")
            self.state.track[j] = track.to_json()
        self.save(self.state)
        self.looks.append(Look(steps, (r.x, r.y), seen, self.q(), self._error(target), correction, self._scales()))
        return None

    def _disputed(self, joint: int, q_reckoned: float, q_seen: float, sd_seen: float) -> None:
        """The camera and the dead reckoning of ``joint`` disagree beyond the gate: a slip (the camera right) or
        a wrong fix (the reckoning right). The joint is kept *uncertain* over both, each widened by 3 of its
        standard deviations (the reckoning's with the start's own), until it is referenced again."""
        sd_reckoned = math.hypot(self.tracks[joint].sd, self.sd0.get(joint, 0.0))
        lo = min(q_reckoned - 3.0 * sd_reckoned, q_seen - 3.0 * sd_seen)
        hi = max(q_reckoned + 3.0 * sd_reckoned, q_seen + 3.0 * sd_seen)
        self.state.mark_uncertain(joint, lo, hi, "the camera and the dead reckoning disagreed: a slip or a wrong fix")

    def image_map(self) -> np.ndarray:
        """The image map at the kept pose (px per m of a base-frame displacement): :func:`image_map`."""
        return image_map(self.loop, self.pixel_size_m, self.state.pose, self.geometry)

    def _scales(self) -> dict[int, float]:
        return {j: t.scale for j, t in self.tracks.items()}

    def _error(self, target: Vec3) -> float:
        return math.dist(kin.tip(self.q(), self.geometry), target)

    def finish(self) -> None:
        """Put the start's own uncertainty back into the positions' variance (the camera saw motion from it)."""
        for j, t in self.tracks.items():
            if self.sd0.get(j):
                t.P[0, 0] += self.sd0[j] ** 2
                self.state.track[j] = t.to_json()
        self.save(self.state)


Leg = Callable[[_Run, bool], tuple[tuple[int, int, int], str | None, bool]]
"""``leg(run, correction)``: drive one leg; the signed steps sent, a device error, whether it was the last."""


class LegRefused(Exception):
    """A leg the rig's envelope refused before a step of it was sent (the loop stops with this reason)."""


def check_leg(run: _Run, guard: Guard | None, path: Sequence[Sequence[float]]) -> None:
    """A leg's planned path (poses, rad or m) against a rig's envelope: :class:`LegRefused` naming the obstacle.

    The margin is the σ the joints' tracks predict along the leg (:func:`~.move.sigma_growth`),
    with the start's own σ, which the loop keeps apart while it looks, added back.
    """
    if guard is None:
        return
    growth = sigma_growth(run.state, run.calibration)
    P = tuple(((p[0][0] + run.sd0.get(j + 1, 0.0) ** 2, p[0][1], p[0][2]), p[1], p[2])
              for j, p in enumerate(growth.P))
    try:
        guard.check(path, replace(growth, P=P))
    except EnvelopeViolation as e:
        raise LegRefused(f"the next leg was refused by the rig's envelope: {e}") from None


def _run_loop(run: _Run, target: Vec3, leg: Leg) -> tuple[bool, str | None]:
    """Legs and looks until the tip is within the tolerance or a reason to stop."""
    tol = tolerance_m(run.loop, run.pixel_size_m)
    arrived = False
    corrections = 0
    error_at_arrival = math.inf
    for _ in range(10_000):
        if run.looks and run.looks[-1].error <= tol:
            return True, None
        if arrived:
            if corrections >= run.loop.max_corrections:
                return False, (
                    f"too many corrections: {corrections}, the tip still "
                    f"{run.looks[-1].error * 1e6:.3g} µm from the target (tolerance {tol * 1e6:.3g} µm)"
                )
            corrections += 1
        before = run.q()
        try:
            steps, error, last = leg(run, arrived)
        except LegRefused as e:
            return False, str(e)
        if error is not None:
            return False, error  # the device's own words (a link, an end stop, the rig's STOP), not a guess at why
        if not any(steps):
            left = run._error(target)
            if left <= tol:  # before any look (after one, the check above ends it): already there, nothing to move
                return True, None
            return False, (
                f"no progress: the tip is {left * 1e6:.3g} µm from the target, less than a step "
                f"makes (tolerance {tol * 1e6:.3g} µm)"
            )
        run.predict(before, steps)
        why = run.look(steps, target, arrived)
        if why is not None:
            return False, why
        err = run.looks[-1].error
        if arrived and err > 0.8 * error_at_arrival and err > tol:
            return False, f"no progress: a correction left the tip {err * 1e6:.3g} µm from the target"
        if last:
            arrived = True
            error_at_arrival = err
    return False, "too many legs"  # pragma: no cover - a bound, not a path


def _run_kept(
    run: _Run, target: Vec3, leg: Leg, what: str, key: str, warn: Callable[[str], None]
) -> tuple[bool, str | None]:
    """:func:`_run_loop`, the start's own σ put back into the kept tracks (:meth:`_Run.finish`) however it
    ends: reached, stopped, or by an exception (a front end's stop between bursts, a device's error, Ctrl-C:
    :class:`~.move.Interrupted` with the state as stored); at the end, a step scale the camera taught far from
    the calibration's is said (:func:`scale_warnings`)."""
    try:
        reached, reason = _run_loop(run, target, leg)
    except BaseException as e:
        run.finish()
        if isinstance(e, KeyboardInterrupt):
            if run.state.claim:  # taken back first: the state read back is what the next command reads
                release_claim(run.store, run.state)
            raise Interrupted(what, kept_after_interrupt(run.store, key, run.state)) from None
        raise
    run.finish()
    for w in scale_warnings(run.tracks, run.calibration, run.loop.scale_warn_sd):
        warn(w)
    return reached, reason


def _open(
    dev: Controller, state: DeviceState, loop: CameraLoop, camera_opener: CameraOpener,
    journal: Callable[[], Callable[[], None]],
) -> tuple[Camera, TipTracker, tuple[float, float], float]:
    """Open the camera, find the tip, learn it: the camera, the tracker, the start pixel and its sigma.

    Without a tip given, ``journal()`` is called just before a joint is stepped out and back
    to find it, and what it returns once the steps are made.
    """
    if isinstance(dev, PoseSettable):
        dev.set_pose(*state.pose)
    cam = camera_opener(loop.camera, dev)
    try:
        if cam.info.pixel_size_m is None:
            raise ValueError(f"the camera {loop.camera} does not know its pixel size: give pixel= in its URL")
        if loop.jacobian is not None:
            loop.jacobian.check_camera(loop.camera, cam.info.pixel_size_m)
            loop.jacobian.check_base(state.pose)
        tip = loop.tip
        if tip is None:
            kept = journal()
            try:
                tip = acquire_tip(dev, cam, loop.auto_joint, AUTO_STEPS)
            except AcquireError:  # the steps were made, the tip not found: they are kept all the same
                kept()
                raise
            kept()
        tracker = TipTracker(cam.grab(), tip)
        first = tracker.update(cam.grab())
        if not isinstance(first, Fix):
            raise ValueError(f"the tip at {tip[0]:.1f}, {tip[1]:.1f} px is not seen ({first.reason}: {first.detail})")
    except BaseException:
        cam.close()
        raise
    return cam, tracker, (first.x, first.y), first.sigma


def _out_and_back(state: DeviceState, calibration: Calibration, joint: int) -> Callable[[], None]:
    """Journal :data:`AUTO_STEPS` steps of ``joint`` out and back (uncertain over the way out) and return what keeps
    their end: the model's position after them (the two directions' steps differ), the track propagated."""
    q0, pose, source = state.positions[joint], state.pose, state.sources[joint]
    planner = Planner(calibration, joint, pose)
    q_out = float(planner.position_after(q0, AUTO_STEPS))
    out = Planner(calibration, joint, pose._replace(**{f"q{joint}": q_out}))
    q_back = float(out.position_after(q_out, -AUTO_STEPS))
    state.intend(joint, q0 + 1.5 * (q_out - q0), f"joint {joint} {FINDING_TIP}")

    def keep() -> None:
        state.set_position(joint, q_back, "dead-reckoned" if source != "assumed" else source)
        track, _ = track_for(state.track.get(joint), calibration, joint)
        sigma_model = joint_sigma_model(calibration, joint)
        span = state.spec(joint).span
        track.predict(q_out - q0, AUTO_STEPS, pose, joint, sigma_model, ceiling=span)
        track.predict(q_back - q_out, -AUTO_STEPS, pose, joint, sigma_model, ceiling=span)
        state.track[joint] = track.to_json()

    return keep


def _check_start(state: DeviceState, loop: CameraLoop, joint: int | None = None) -> None:
    """Before anything moves: the loop's settings, and the camera sees ``joint`` (a one-joint move's:
    :func:`unseen_problem`); :class:`~.move.MoveRefused` if not. The rig's envelope: :func:`_claimed_start`."""
    if not isinstance(loop, CameraLoop):  # a URL alone: the loop's settings are a CameraLoop
        raise TypeError(f"the camera is a CameraLoop (CameraLoop({loop!r}, tip=...)), not a {type(loop).__name__}")
    unseen = None if joint is None else unseen_problem(loop, joint, state.pose, kin.DEFAULT_GEOMETRY)
    if unseen:
        raise MoveRefused(unseen)


def _claimed_start(
    store: StateStore, guard: Guard | None, state: DeviceState, calibration: Calibration, loop: CameraLoop,
    path: Sequence[Sequence[float]],
) -> AbstractContextManager[None]:
    """The whole planned path, and the steps out and back that may find the tip, checked against a rig's
    envelope and claimed for the ``with`` block, as ``move`` does ("mark, then check": :func:`~.move.claimed`);
    :class:`~.move.MoveRefused` naming the obstacle. Each leg is checked again, against the other arms as kept
    then, and widens the claim if it goes beyond it (:func:`claim_leg`)."""
    paths = [[list(p) for p in path]]
    if guard is not None and loop.tip is None:  # the tip is found by stepping a joint out and back
        j = loop.auto_joint
        q0 = state.positions[j]
        q_out = float(Planner(calibration, j, state.pose).position_after(q0, AUTO_STEPS))
        q = [state.positions[i] for i in (1, 2, 3)]
        out = list(q)
        out[j - 1] = q0 + 1.5 * (q_out - q0)  # as far as the journal allows
        paths.append([q, out, q])

    def check(g: Guard | None) -> None:
        for p in paths:
            check_envelope_path(g, state, p, calibration)

    return claimed(store, state, guard, [p for part in paths for p in part], calibration, check=check)


def claim_leg(run: _Run, guard: Guard | None, path: Sequence[Sequence[float]]) -> None:
    """A leg's planned path, checked against the other arms as kept now (:func:`check_leg`) once the move's claim
    holds it ("mark, then check", widened first if the leg goes beyond it: :func:`~.move.claim_and_check`):
    :class:`LegRefused` naming the obstacle, the claim taken back."""
    claim_and_check(run.store, run.state, guard, path, run.calibration, check=lambda g: check_leg(run, g, path),
                    widen=True)


def _start(
    store: StateStore, dev: Controller, state: DeviceState, calibration: Calibration, loop: CameraLoop,
    geometry: kin.Geometry, camera_opener: CameraOpener, joints: Sequence[int],
) -> _Run:
    def journal() -> Callable[[], None]:  # the tip found by stepping a joint out and back: journalled first
        keep = _out_and_back(state, calibration, loop.auto_joint)
        save_state(store, state)

        def kept() -> None:  # then kept as the model says
            keep()
            save_state(store, state)

        return kept

    measured_on = loop.jacobian.device if loop.jacobian is not None else ""
    if measured_on and measured_on != device_key(state.device):  # before the camera opens or a step is sent
        raise MoveRefused(f"the camera calibration (--camera-calibration) was measured on {measured_on}, not on "
                          f"{device_key(state.device)}: each arm has its own image Jacobian (camera calibrate "
                          "--jacobian on this arm)")
    cam, tracker, u0, sigma0 = _open(dev, state, loop, camera_opener, journal)
    tracks: dict[int, JointTrack] = {}
    sd0: dict[int, float] = {}
    for j in joints:
        t, _ = track_for(state.track.get(j), calibration, j)
        sd0[j] = t.sd
        t.reset_position(0.0)  # the camera measures from here: the start's own sd is added back at the end
        tracks[j] = t
    pix = float(cam.info.pixel_size_m or 0.0)
    q = state.positions
    return _Run(dev, cam, tracker, state, store, calibration, loop, geometry, pix, (q[1], q[2], q[3]), u0, sigma0,
                sd0, tracks)


def _true(dev: Controller) -> Vec3 | None:
    if isinstance(dev, KnowsTruePosition):
        return (float(dev.position(1)), float(dev.position(2)), float(dev.position(3)))
    return None


def _close(dev: Controller, cam: Camera | None) -> None:
    if cam is not None:
        cam.close()
    try:
        dev.close()
    except DeviceError:
        pass


def _leg_px(run: _Run, joint: int) -> float:
    """Pixels the tip moves per unit of ``joint`` at the kept pose (px per rad or m)."""
    G = run.image_map() @ kin.jacobian(run.q(), run.geometry)
    return float(np.linalg.norm(G[:, joint - 1])) or 1.0


def scale_warnings(tracks: dict[int, JointTrack], calibration: Calibration, within_sd: float) -> list[str]:
    """One line per joint whose camera-taught step scale lies beyond ``within_sd`` prior standard deviations
    of the calibration's (:attr:`CameraLoop.scale_warn_sd`; :func:`~stickslip.calibration.update.day_drift`,
    :func:`joint_sigma_model`)."""
    out = []
    for j, t in sorted(tracks.items()):
        prior = math.hypot(day_drift(calibration), joint_sigma_model(calibration, j))
        worst = max((t.scale_of(d) for d in "+-"), key=lambda v: abs(math.log(v)))
        if prior > 0 and abs(math.log(worst)) > within_sd * prior:
            out.append(
                f"joint {j}: the camera makes its steps x{worst:.3g} of the calibration's, more than "
                f"{within_sd:g} times the change expected ({prior:.0%}): check the camera's pixel size "
                "(pixel=; a wrong one moves the tip to a wrong place the camera calls reached), else recalibrate"
            )
    return out


def move_seen(
    store: MoveStore,
    request: MoveRequest,
    calibration: Calibration,
    loop: CameraLoop,
    *,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = lambda: None,
    opener: Callable[[str], Controller] | None = None,
    camera_opener: CameraOpener = open_camera,
) -> LoopResult:
    """Move one joint as ``request`` says, looking at the tip after each leg (see the module docstring).

    Refusals raise before anything is sent, as :func:`~stickslip.procedures.move.move`'s do
    (:class:`~.move.MoveRefused`, ``KeyError``, ``ValueError``, :class:`DeviceError`, the
    camera's errors); a stop during the move is in the result's ``reason``.
    """
    key = device_key(request.device)
    joint = request.joint
    made_on = calibration_device_problem(calibration, request.device)
    if made_on and not request.trust_calibration:
        raise MoveRefused(made_on)
    with device_lock(store, key), ExitStack() as claim:
        state = load_state(store, key)
        request.pose.apply(state)
        problem = reference_problem(state, joint, request.device, calibration) or state.uncertainty_problem(joint)
        if problem:
            raise MoveRefused(problem + " (a closed-loop move starts from a known position)")
        _, q_to = target_of(state, joint, request.by, request.to)
        _check_start(state, loop, joint)
        loop_geometry = kin.DEFAULT_GEOMETRY
        claim.enter_context(_claimed_start(store, request.guard, state, calibration, loop,
                                           joint_line(state, joint, q_to)))  # mark, then check, as move does
        dev = open_checked(store, request.device, opener or open_device, state,
                           *sharing_controller(store, request.guard))
        cam: Camera | None = None
        try:
            for w in usage_warnings(calibration, dev, request.device, joint, request.max_age_days):
                warn(w)
            run = _start(store, dev, state, calibration, loop, loop_geometry, camera_opener, (joint,))
            cam = run.cam
            q_target = list(run.q())  # after the tip was found (a joint stepped out and back, if it was)
            q_target[joint - 1] = q_to
            target = kin.tip(q_target, loop_geometry)
            target_v: Vec3 = (float(target[0]), float(target[1]), float(target[2]))
            ready()

            def leg(run: _Run, correction: bool) -> tuple[tuple[int, int, int], str | None, bool]:
                cal = run.scaled()
                q_from = run.state.positions[joint]
                planner = Planner(cal, joint, run.state.pose)
                n = int(planner.plan(q_from, q_to).signed_steps)
                if n == 0:
                    return (0, 0, 0), None, True
                per_step = abs(float(planner.position_after(q_from, n)) - q_from) / abs(n)
                cap = max(1, int(run.loop.max_leg_px / max(_leg_px(run, joint) * per_step, 1e-12)))
                last = abs(n) <= cap
                n = n if last else int(math.copysign(cap, n))

                def reckon(m: int) -> float:
                    return float(planner.position_after(q_from, m))

                end = list(run.q())
                end[joint - 1] = reckon(n)
                claim_leg(run, request.guard, [list(run.q()), end])
                out = drive(dev, run.state, joint, n, request.burst, reckon, run.save)
                steps = [0, 0, 0]
                steps[joint - 1] = out.sent
                return (steps[0], steps[1], steps[2]), out.error, last

            reached, reason = _run_kept(run, target_v, leg, f"move of joint {joint}", key, warn)
            true_q = _true(dev)
        finally:
            _close(dev, cam)
    return LoopResult(key, reached, reason, tuple(run.looks), target_v, tolerance_m(loop, run.pixel_size_m), state,
                      true_q, loop_geometry)


def reach_seen(
    store: MoveStore,
    request: ReachRequest,
    calibration: Calibration,
    loop: CameraLoop,
    *,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = lambda: None,
    opener: Callable[[str], Controller] | None = None,
    camera_opener: CameraOpener = open_camera,
) -> LoopResult:
    """Move the tip in a straight line as ``request`` says, looking at the tip after each leg.

    Each leg is the first segments of the straight line from the kept (seen) tip to the
    target, planned with the joints' corrected step scales, up to :attr:`CameraLoop.max_leg_px`
    of image motion. Refusals raise before anything is sent, as
    :func:`~stickslip.procedures.reach.reach`'s do; a stop is in the result's ``reason``.
    """
    if request.dry_run:
        raise ValueError("a closed-loop reach drives the arm: --dry-run plans without the camera")
    key = device_key(request.device)
    made_on = calibration_device_problem(calibration, request.device)
    if made_on and not request.trust_calibration:
        raise MoveRefused(made_on)
    geometry = request.geometry
    with device_lock(store, key), ExitStack() as claim:
        state = referenced_state(store, request.device, request.pose, calibration, request.from_unreferenced)
        first = plan_reach(calibration, state.pose, to=request.to, by=request.by, geometry=geometry,
                           segment=request.segment)  # refused here when out of reach, before anything moves
        _check_start(state, loop)
        share = seen_share(loop, state.pose, geometry, np.subtract(first.target, first.tip_start))
        if first.length > 0 and share < MIN_VISIBILITY:
            raise MoveRefused(
                f"the tip would move along the camera's line of sight ({share:.0%} of the move in the image, at "
                f"least {MIN_VISIBILITY:.0%} needed): the camera cannot see it; reach without --camera"
            )
        claim.enter_context(_claimed_start(store, request.guard, state, calibration, loop, joint_path(first)))
        target_v = first.target
        save_state(store, state)
        dev = open_checked(store, request.device, opener or open_device, state,
                           *sharing_controller(store, request.guard))
        cam: Camera | None = None
        try:
            for w in usage_warnings(calibration, dev, request.device, 3, request.max_age_days):
                warn(w)
            joints = tuple(j for j in (1, 2, 3) if any(k[0] == j for k in calibration.models))
            run = _start(store, dev, state, calibration, loop, geometry, camera_opener, joints)
            cam = run.cam
            ready()
            max_leg_m = run.loop.max_leg_px * run.pixel_size_m

            def leg(run: _Run, correction: bool) -> tuple[tuple[int, int, int], str | None, bool]:
                cal = run.scaled()
                plan = plan_reach(cal, run.state.pose, to=target_v, geometry=geometry,
                                  segment=min(request.segment, 0.5 * max_leg_m))
                if not any(plan.total_steps):
                    return (0, 0, 0), None, True
                start = np.asarray(plan.tip_start)
                k = 1
                while k < len(plan.segments) and np.linalg.norm(np.asarray(plan.segments[k].tip) - start) <= max_leg_m:
                    k += 1
                part = replace(plan, segments=plan.segments[:k])
                claim_leg(run, request.guard, joint_path(part))
                out = drive_reach(dev, run.state, part, cal, run.save, request.burst, scale_tracks=False)
                s = out.sent
                return (s[0], s[1], s[2]), out.error, k == len(plan.segments)

            reached, reason = _run_kept(run, target_v, leg, "a straight tip move", key, warn)
            true_q = _true(dev)
        finally:
            _close(dev, cam)
    return LoopResult(key, reached, reason, tuple(run.looks), target_v, tolerance_m(loop, run.pixel_size_m), state,
                      true_q, geometry)


# ---------------------------------------------------------------- jogging with the camera


class JogEyes:
    """The camera of a jog session: looks at the tip once it has moved a leg's worth, or stopped.

    :func:`stickslip.procedures.jog.run_jog` calls :meth:`after` after every tick with the
    steps the tick sent; the kept positions of the joints seen become ``seen`` (as in
    :func:`move_seen`), and :meth:`calibration` gives the jog law the corrected step
    scales. A lost tip is a message, not the end of the session: the joints stay
    dead-reckoned until the tip is seen again.
    """

    def __init__(self, run: _Run):
        self.run = run
        self.before = run.q()
        self.pending = [0, 0, 0]

    @classmethod
    def open(
        cls, store: StateStore, dev: Controller, state: DeviceState, calibration: Calibration, loop: CameraLoop,
        geometry: kin.Geometry = kin.DEFAULT_GEOMETRY, camera_opener: CameraOpener = open_camera,
    ) -> JogEyes:
        """Open ``loop.camera`` on ``dev`` and learn the tip (the arm at ``state``'s pose)."""
        joints = tuple(j for j in (1, 2, 3) if any(k[0] == j for k in calibration.models))
        return cls(_start(store, dev, state, calibration, loop, geometry, camera_opener, joints))

    def calibration(self) -> Calibration:
        """The calibration with each joint's step scale as the camera has corrected it."""
        return self.run.scaled()

    def sources(self) -> tuple[str, str, str]:
        """Each joint's kept source (``seen``, ``dead-reckoned``, ...)."""
        s = self.run.state.sources
        return (s[1], s[2], s[3])

    def after(self, steps: tuple[int, int, int]) -> tuple[Vec3 | None, str | None]:
        """After a tick that sent ``steps``: the kept joints if the camera looked (else ``None``), and why not seen."""
        for k in range(3):
            self.pending[k] += steps[k]
        if not any(self.pending):
            return None, None
        run = self.run
        moved = np.subtract(kin.tip(run.q(), run.geometry), kin.tip(self.before, run.geometry))
        px = float(np.linalg.norm(run.image_map() @ moved))
        if any(steps) and px < 0.5 * run.loop.max_leg_px:
            return None, None  # still moving, less than half a leg since the last look
        sent = (self.pending[0], self.pending[1], self.pending[2])
        run.predict(self.before, sent)
        here = kin.tip(run.q(), run.geometry)
        why = run.look(sent, (float(here[0]), float(here[1]), float(here[2])), False)
        self.pending = [0, 0, 0]
        self.before = run.q()
        return run.q(), why

    def close(self) -> None:
        """Keep the positions' full variance and release the camera."""
        try:
            self.run.finish()
        finally:
            self.run.cam.close()
