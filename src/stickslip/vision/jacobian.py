"""The camera against the manipulator: the image Jacobian, step sizes seen by the camera, and joint observations.

Near a pose the tip's image moves linearly with the steps of one joint in one direction
(docs/design.md §10):

    u(n) = u(0) + J · n          (u px, n steps, J px per step: one column of J_img)

:func:`fit_image_jacobian` fits ``J`` to the tracked tip after each of a few known step
counts, with the residuals, and refuses when the motion is not a straight line in the
steps (an end stop reached, a slipping joint, the tip lost). With the pixel size ``s``
and the camera's view the step size follows (:func:`step_size`): the joint's column of
the tip's Jacobian ``J_tip`` (m per rad or m per m, :func:`stickslip.kinematics.jacobian`)
shows in the image shortened by ``m = sqrt(1 - (v · e)²)`` (``e`` its direction, ``v`` the
optical axis), so

    gamma = s |J| / (|J_tip| m)         (m or rad per step)

A joint that moves the tip mostly along the optical axis (``m`` small) shows only as
focus and is refused. :class:`CameraCalibration` keeps what the fit learned at one pose;
:func:`joint_observation` turns a later fix of the tip into a measured joint position with
its standard deviation: the seam through which a closed loop feeds the tracker's fixes to
the dead reckoning's Kalman filter (:class:`stickslip.motion.tracking.JointTrack`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..joints import joint_spec
from ..models import direction_label
from .view import View, image_axes

__all__ = [
    "JacobianError",
    "DirectionFit",
    "fit_image_jacobian",
    "StepSizeEstimate",
    "step_size",
    "visibility",
    "CameraCalibration",
    "JointObservation",
    "joint_observation",
    "MIN_VISIBILITY",
    "MAX_NONLINEARITY",
]

FloatArray = NDArray[np.float64]

MIN_VISIBILITY = 0.3
"""Least share of a joint's tip motion that must lie in the image plane (``m``): below it the
joint moves the tip mostly along the optical axis, and its step cannot be measured from this view."""

MAX_NONLINEARITY = 0.05
"""Largest departure of a tracked point from the fitted line, as a share of the whole travel
(beyond the tracking and stepping noise): more, and the motion is not linear in the steps."""

STEP_SCATTER = 0.03
"""Relative standard deviation of a single step assumed in the fit's uncertainty (docs/models.md §4)."""


class JacobianError(ValueError):
    """The tracked motion cannot give an image Jacobian or a step size (the message says why)."""


@dataclass(frozen=True)
class DirectionFit:
    """The image motion of one joint in one direction.

    Attributes
    ----------
    joint : int
    direction : str
        ``"+"`` or ``"-"``.
    steps : tuple of int
        Steps made before each fix (0 first), counted in this direction.
    points : ndarray, shape (k, 2)
        The tip's fixes, px.
    jacobian : ndarray, shape (2,)
        Pixels per step, ``J`` (the signed image motion of one step in this direction).
    jacobian_sd : float
        Standard deviation of ``|J|``, px per step.
    residuals : ndarray, shape (k,)
        Distance of each fix from the fitted line, px.
    """

    joint: int
    direction: str
    steps: tuple[int, ...]
    points: FloatArray
    jacobian: FloatArray
    jacobian_sd: float
    residuals: FloatArray

    @property
    def travel_px(self) -> float:
        """The whole travel in the image, px."""
        return float(np.linalg.norm(self.jacobian)) * (self.steps[-1] - self.steps[0])

    def as_dict(self) -> dict[str, object]:
        return {
            "joint": self.joint,
            "direction": self.direction,
            "steps": list(self.steps),
            "px_per_step": [float(v) for v in self.jacobian],
            "px_per_step_sd": self.jacobian_sd,
            "residuals_px": [float(v) for v in self.residuals],
            "travel_px": self.travel_px,
        }


def fit_image_jacobian(
    joint: int,
    direction: str | int,
    steps: Sequence[int],
    points: Sequence[tuple[float, float]],
    sigma_px: Sequence[float] | float = 0.3,
) -> DirectionFit:
    """Fit the image motion ``u(n) = u0 + J n`` of one joint in one direction.

    Parameters
    ----------
    joint : int
    direction : str or int
        ``"+"``/``"-"`` (or ``+1``/``-1``).
    steps : sequence of int
        Steps made in this direction before each fix, increasing from 0.
    points : sequence of (float, float)
        The tip's fix after each, px.
    sigma_px : float or sequence of float
        Standard deviation of each fix, px.

    Raises
    ------
    JacobianError
        With fewer than three fixes, steps that do not increase, a tip that did not move,
        or a motion that is not a straight line in the steps (a fix further from the line
        than the tracking and stepping noise allow, plus :data:`MAX_NONLINEARITY` of the
        travel): an end stop reached, a slipping joint, a tip followed wrongly.
    """
    d = direction_label(direction)
    n = np.asarray(steps, dtype=float)
    u = np.asarray(points, dtype=float).reshape(-1, 2)
    sig = np.broadcast_to(np.asarray(sigma_px, dtype=float), n.shape).astype(float)
    where = f"joint {joint}{d}"
    if n.size != u.shape[0]:
        raise JacobianError(f"{where}: {n.size} step counts for {u.shape[0]} fixes")
    if n.size < 3:
        raise JacobianError(f"{where}: {n.size} fixes; the fit needs at least 3 (the start and two step counts)")
    if not np.all(np.diff(n) > 0) or n[0] < 0:
        raise JacobianError(f"{where}: the step counts must increase from 0, got {list(map(int, n))}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(sig)) and np.all(sig >= 0)):
        raise JacobianError(f"{where}: a fix or its sigma is not finite")
    nc = n - n.mean()
    slope = (nc[:, None] * (u - u.mean(axis=0))).sum(axis=0) / float((nc * nc).sum())
    speed = float(np.linalg.norm(slope))
    total = speed * float(n[-1] - n[0])
    if total < 3.0 * float(np.max(sig)) + 1.0:
        raise JacobianError(
            f"{where}: the tip moved {total:.2g} px in {int(n[-1] - n[0])} steps, within the tracking noise "
            "(the joint did not move, or moves the tip along the optical axis)"
        )
    line = u.mean(axis=0) + nc[:, None] * slope
    resid = np.linalg.norm(u - line, axis=1)
    # what the line may miss by: the fixes' noise and the steps' own scatter (a random walk of sd 3 % a step)
    allowed = 3.0 * np.hypot(sig, STEP_SCATTER * speed * np.sqrt(np.maximum(n - n[0], 1.0))) + MAX_NONLINEARITY * total
    worst = int(np.argmax(resid - allowed))
    if resid[worst] > allowed[worst]:
        raise JacobianError(
            f"{where}: the motion is not linear in the steps: after {int(n[worst])} steps the tip is "
            f"{resid[worst]:.2g} px off the line (at most {allowed[worst]:.2g} px): an end stop, a slipping joint, "
            "or a lost tip"
        )
    # |J|'s uncertainty: the end points' noise and the steps' random walk over the travel
    span = float(n[-1] - n[0])
    sd = math.hypot(math.sqrt(2.0) * float(np.max(sig)), STEP_SCATTER * speed * math.sqrt(span)) / span
    return DirectionFit(joint, d, tuple(int(v) for v in n), u, np.asarray(slope, dtype=float), sd, resid)


def visibility(joint: int, pose: kin.Pose, view: View, geometry: kin.Geometry = kin.DEFAULT_GEOMETRY) -> float:
    """``m``: the share of joint ``joint``'s tip motion at ``pose`` that lies in the image plane (0..1)."""
    J = kin.jacobian((pose.q1, pose.q2, pose.q3), geometry)[:, joint - 1]
    norm = float(np.linalg.norm(J))
    if norm == 0.0:
        return 0.0
    v = image_axes(view, pose.theta, pose.psi)[2]
    c = float(np.dot(v, J / norm))
    return math.sqrt(max(0.0, 1.0 - c * c))


@dataclass(frozen=True)
class StepSizeEstimate:
    """A joint's mean step size at a pose, measured by the camera.

    Attributes
    ----------
    joint : int
    direction : str
    gamma : float
        Mean step, m (joint 3) or rad (joints 1, 2).
    sigma : float
        Its standard deviation, same unit.
    steps : int
        Steps the estimate rests on.
    visibility : float
        ``m``, the share of the tip's motion in the image plane, 1.
    """

    joint: int
    direction: str
    gamma: float
    sigma: float
    steps: int
    visibility: float


def step_size(
    fit: DirectionFit,
    pose: kin.Pose,
    pixel_size_m: float,
    view: View,
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY,
    pixel_size_sd: float = 0.0,
) -> StepSizeEstimate:
    """The step size of ``fit``'s joint and direction at ``pose`` (the pose the steps began at; the moving
    joint at the middle of its travel): ``gamma = s |J| / (|J_tip| m)``.

    ``pixel_size_sd`` is the pixel size's relative standard deviation (a calibrated
    microscope: 0.5 % or so). Raises :class:`JacobianError` when the joint moves the tip
    mostly along the optical axis (``m <`` :data:`MIN_VISIBILITY`) or the pose is singular.
    """
    if not (math.isfinite(pixel_size_m) and pixel_size_m > 0):
        raise JacobianError(f"the pixel size {pixel_size_m!r} m must be a positive length (give pixel=... in the URL)")
    j = fit.joint
    m = visibility(j, pose, view, geometry)
    where = f"joint {j}{fit.direction}"
    if m < MIN_VISIBILITY:
        raise JacobianError(
            f"{where} moves the tip mostly along the camera's optical axis at this pose (only {100 * m:.0f} % of its "
            "motion is in the image): its step shows as focus, not pixels; measure it with the camera tilted, or "
            "in another pose"
        )
    J_tip = float(np.linalg.norm(kin.jacobian((pose.q1, pose.q2, pose.q3), geometry)[:, j - 1]))
    if J_tip <= 0:
        raise JacobianError(f"{where}: the joint does not move the tip at this pose (a singular pose)")
    speed = float(np.linalg.norm(fit.jacobian))
    gamma = pixel_size_m * speed / (J_tip * m)
    rel = math.hypot(fit.jacobian_sd / speed, pixel_size_sd)
    span = fit.steps[-1] - fit.steps[0]
    return StepSizeEstimate(j, fit.direction, gamma, gamma * rel, span, m)


@dataclass(frozen=True)
class CameraCalibration:
    """The camera against the manipulator at one pose: what turns a fix into joint positions.

    Attributes
    ----------
    pose : Pose
        The pose the calibration began at (joints rad, rad, m; tilt rad).
    reference_px : tuple of float
        The tip's pixel at ``pose``.
    px_per_unit : dict
        ``{joint: (dx, dy)}``: the tip's image motion per unit of the joint (px per rad
        or px per m), measured direction and kinematic length.
    pixel_size_m : float
    view : View
    geometry : Geometry
    range_px : float
        How far from ``reference_px`` the calibration was measured, px: the linear model
        holds within it.
    """

    pose: kin.Pose
    reference_px: tuple[float, float]
    px_per_unit: dict[int, tuple[float, float]]
    pixel_size_m: float
    view: View
    geometry: kin.Geometry
    range_px: float

    @classmethod
    def from_fits(
        cls, fits: Sequence[DirectionFit], pose: kin.Pose, reference_px: tuple[float, float], pixel_size_m: float,
        view: View, geometry: kin.Geometry = kin.DEFAULT_GEOMETRY,
    ) -> CameraCalibration:
        """From the fits of each joint's two directions: each joint's image direction (the mean of ``+`` and the
        reverse of ``-``), scaled to the kinematic length ``|P J_tip| / s`` (px per rad or m)."""
        by_joint: dict[int, list[FloatArray]] = {}
        reach = 0.0
        for f in fits:
            sign = 1.0 if f.direction == "+" else -1.0
            by_joint.setdefault(f.joint, []).append(sign * f.jacobian / max(float(np.linalg.norm(f.jacobian)), 1e-300))
            reach = max(reach, f.travel_px)
        out: dict[int, tuple[float, float]] = {}
        for j, dirs in by_joint.items():
            d = np.mean(dirs, axis=0)
            d = d / max(float(np.linalg.norm(d)), 1e-300)
            J_tip = float(np.linalg.norm(kin.jacobian((pose.q1, pose.q2, pose.q3), geometry)[:, j - 1]))
            length = J_tip * visibility(j, pose, view, geometry) / pixel_size_m
            out[j] = (float(d[0] * length), float(d[1] * length))
        return cls(pose, (float(reference_px[0]), float(reference_px[1])), out, pixel_size_m, view, geometry, reach)


@dataclass(frozen=True)
class JointObservation:
    """A joint's position measured by the camera.

    Attributes
    ----------
    joint : int
    q : float
        The joint's position, rad or m.
    sigma : float
        Its standard deviation, rad or m.
    off_line_px : float
        How far the fix lies from the joint's line through the reference pixel, px.
    """

    joint: int
    q: float
    sigma: float
    off_line_px: float


def joint_observation(
    cal: CameraCalibration, joint: int, x: float, y: float, sigma_px: float, off_line_limit: float | None = None
) -> JointObservation:
    """The position of ``joint`` from a fix of the tip at ``(x, y)`` (px, standard deviation ``sigma_px``).

    Only ``joint`` is taken to have moved since ``cal.pose``: ``q = q_ref + (du · g) / |g|²``
    with ``g`` the joint's image motion per unit (``cal.px_per_unit``), ``sigma = sigma_px /
    |g|``. Raises :class:`JacobianError` when the joint was not calibrated, when the fix lies
    off the joint's line by more than ``off_line_limit`` px (default ``3 sigma_px + 1``:
    another joint moved, the tip slipped, or the camera moved), or beyond twice the
    calibrated range (the linear model no longer holds there).
    """
    spec = joint_spec(joint)
    if joint not in cal.px_per_unit:
        raise JacobianError(f"joint {joint} was not calibrated against the camera (calibrated: "
                            f"{', '.join(map(str, sorted(cal.px_per_unit))) or 'none'})")
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(sigma_px) and sigma_px >= 0):
        raise JacobianError(f"the fix ({x}, {y}) ± {sigma_px} px is not finite")
    g = np.asarray(cal.px_per_unit[joint], dtype=float)
    g2 = float(g @ g)
    if g2 <= 0:
        raise JacobianError(f"joint {joint} does not move the tip in the image")
    du = np.array([x - cal.reference_px[0], y - cal.reference_px[1]])
    dq = float(du @ g) / g2
    off = float(np.linalg.norm(du - g * dq))
    limit = 3.0 * sigma_px + 1.0 if off_line_limit is None else off_line_limit
    if off > limit:
        raise JacobianError(
            f"the tip is {off:.3g} px off joint {joint}'s line (at most {limit:.3g} px): another joint moved, "
            "the tip slipped, or the camera moved; calibrate the camera again"
        )
    if float(np.linalg.norm(du)) > 2.0 * max(cal.range_px, 1.0):
        raise JacobianError(
            f"the tip is {float(np.linalg.norm(du)):.0f} px from where the camera was calibrated, beyond twice its "
            f"range ({cal.range_px:.0f} px): calibrate the camera at this pose"
        )
    q_ref = (cal.pose.q1, cal.pose.q2, cal.pose.q3)[joint - 1]
    q = q_ref + dq
    del spec
    return JointObservation(joint, q, sigma_px / math.sqrt(g2), off)
