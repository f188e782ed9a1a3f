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
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..joints import joint_spec
from ..models import direction_label
from .view import View, image_axes

if TYPE_CHECKING:
    from ..calibration import Calibration

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
    "JACOBIAN_VERSION",
    "MeasuredDirection",
    "MeasuredJacobian",
    "measured_jacobian",
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


# ---------------------------------------------------------------- the measured image Jacobian, kept in a file

JACOBIAN_VERSION = 1
"""Version of the image-Jacobian file (``camera calibrate --jacobian``) this release writes and reads."""

PIXEL_SIZE_MATCH = 1e-6
"""Largest relative difference between the file's pixel size and the camera's."""

BASE_TILT_MATCH = math.radians(0.1)
"""Largest difference between the base tilt (theta, psi) the Jacobian was measured at and the arm's now, rad."""


@dataclass(frozen=True)
class MeasuredDirection:
    """One joint and direction of a measured image Jacobian.

    Attributes
    ----------
    joint : int
    direction : str
        ``"+"`` or ``"-"``.
    px_per_step : tuple of float
        The tip's image motion per step in this direction, px (the fit, :class:`DirectionFit`).
    px_per_step_sd : float
        Standard deviation of its length, px per step.
    residual_px : float
        The largest distance of a fix from the fitted line, px.
    steps : int
        Steps the fit spans.
    gamma : float
        The step calibration's mean step over those steps, m or rad (what turns px per
        step into px per m or rad).
    """

    joint: int
    direction: str
    px_per_step: tuple[float, float]
    px_per_step_sd: float
    residual_px: float
    steps: int
    gamma: float

    @property
    def px_per_unit(self) -> tuple[float, float]:
        """The tip's image motion per unit of the joint, px per m (joint 3) or px per rad: ``± J / gamma``."""
        sign = 1.0 if self.direction == "+" else -1.0
        return (sign * self.px_per_step[0] / self.gamma, sign * self.px_per_step[1] / self.gamma)


@dataclass(frozen=True)
class MeasuredJacobian:
    """The image Jacobian ``camera calibrate`` measured, as the closed loop uses it (``--camera-calibration``).

    Attributes
    ----------
    camera : str
        The camera's URL, secrets redacted: the file is refused for another camera.
    pixel_size_m : float
        The camera's pixel size, m: refused for another.
    pose : Pose
        The pose the joints were stepped from (rad, rad, m; base tilt rad).
    tip_px : tuple of float
        The tip's pixel at ``pose``.
    directions : tuple of MeasuredDirection
    calibration_day : str
        The day of the step calibration whose steps scaled the fits.
    device : str
        The arm's device key (:func:`~stickslip.devices.base.device_key`) the joints were stepped on: the closed
        loop refuses the file on another arm (``""``: a file written before, not checked).
    """

    camera: str
    pixel_size_m: float
    pose: kin.Pose
    tip_px: tuple[float, float]
    directions: tuple[MeasuredDirection, ...]
    calibration_day: str = ""
    device: str = ""

    def px_per_unit(self) -> dict[int, tuple[float, float]]:
        """``{joint: (dx, dy)}``: each measured joint's image motion per unit (px per rad or m), its two
        directions averaged."""
        out: dict[int, list[tuple[float, float]]] = {}
        for d in self.directions:
            out.setdefault(d.joint, []).append(d.px_per_unit)
        return {j: (float(np.mean([v[0] for v in vs])), float(np.mean([v[1] for v in vs]))) for j, vs in out.items()}

    def image_map(self, fallback: FloatArray, geometry: kin.Geometry = kin.DEFAULT_GEOMETRY) -> FloatArray:
        """``A`` (2 × 3, px per m of a base-frame displacement): the camera fitted to the measured columns.

        ``A J_tip(q_c)`` equals the measured columns ``G`` (the joints measured at the pose
        ``q_c``); what they do not fix is taken from ``fallback`` (the kinematic ``P / s`` of
        the assumed view): ``A = A0 + (G - A0 J_c) J_c⁺`` with ``J_c`` the measured joints'
        columns of the tip's Jacobian. At another pose the image Jacobian is ``A J_tip(q)``
        (an orthographic microscope: ``A`` does not depend on the pose).
        """
        cols = self.px_per_unit()
        joints = sorted(cols)
        A0 = np.asarray(fallback, dtype=float)
        if not joints:
            return A0
        Jt = kin.jacobian((self.pose.q1, self.pose.q2, self.pose.q3), geometry)
        Jc = Jt[:, [j - 1 for j in joints]]
        G = np.array([cols[j] for j in joints], dtype=float).T
        return np.asarray(A0 + (G - A0 @ Jc) @ np.linalg.pinv(Jc), dtype=float)

    def against(
        self, fallback: FloatArray, geometry: kin.Geometry = kin.DEFAULT_GEOMETRY
    ) -> dict[int, tuple[float, float]]:
        """``{joint: (length ratio, angle deg)}``: each measured column against the assumed view's at the pose.

        ``fallback`` is the assumed view's ``P / s`` (px per m). A ratio other than 1 is a
        tilted view or steps off the calibration by that much (the camera cannot tell which);
        an angle is a turned or tilted view. A joint the view does not see has ratio ``inf``.
        """
        J = np.asarray(fallback, dtype=float) @ kin.jacobian((self.pose.q1, self.pose.q2, self.pose.q3), geometry)
        out: dict[int, tuple[float, float]] = {}
        for j, g in sorted(self.px_per_unit().items()):
            c = J[:, j - 1]
            gn, cn = math.hypot(*g), float(np.linalg.norm(c))
            if cn <= 1e-9 * gn:
                out[j] = (math.inf, math.nan)
                continue
            cos = float(np.dot(g, c)) / (gn * cn)
            out[j] = (gn / cn, math.degrees(math.acos(min(1.0, max(-1.0, cos)))))
        return out

    def check_camera(self, url: str, pixel_size_m: float | None) -> None:
        """:class:`JacobianError` (one line) unless ``url`` and ``pixel_size_m`` are the file's camera's."""
        from ..devices.base import redact_url

        if redact_url(url) != self.camera:
            raise JacobianError(
                f"the camera calibration was measured with {self.camera}, not {redact_url(url)}: "
                "measure it with this camera (stickslip camera calibrate --jacobian)"
            )
        if pixel_size_m is None or abs(pixel_size_m - self.pixel_size_m) > PIXEL_SIZE_MATCH * self.pixel_size_m:
            got = "unknown" if pixel_size_m is None else f"{pixel_size_m * 1e6:.6g} µm"
            raise JacobianError(
                f"the camera calibration's pixel is {self.pixel_size_m * 1e6:.6g} µm, the camera's {got}: "
                "measure it again at this magnification"
            )

    def check_base(self, pose: kin.Pose) -> None:
        """:class:`JacobianError` (one line) unless the arm's base is tilted as it was when measured.

        ``A`` is the camera seen from the base: a base tilted otherwise turns it.
        """
        for name in ("theta", "psi"):
            was, now = getattr(self.pose, name), getattr(pose, name)
            if abs(was - now) > BASE_TILT_MATCH:
                raise JacobianError(
                    f"the camera calibration was measured with the base's {name} at {math.degrees(was):.3g} deg, "
                    f"the arm's is {math.degrees(now):.3g} deg: measure it again in this set-up"
                )

    def to_dict(self) -> dict[str, object]:
        """The file's content (SI units, px), ``"version"`` first."""
        return {
            "version": JACOBIAN_VERSION,
            "kind": "stickslip image jacobian",
            "camera": self.camera,
            "pixel_size_m": self.pixel_size_m,
            "pose": dict(self.pose._asdict()),
            "tip_px": list(self.tip_px),
            "calibration_day": self.calibration_day,
            "device": self.device,
            "directions": [
                {"joint": d.joint, "direction": d.direction, "px_per_step": list(d.px_per_step),
                 "px_per_step_sd": d.px_per_step_sd, "residual_px": d.residual_px, "steps": d.steps,
                 "gamma": d.gamma, "px_per_unit": list(d.px_per_unit)}
                for d in self.directions
            ],
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the JSON file atomically (a failed write keeps the old file)."""
        from .. import records

        records.atomic_write_text(path, records.dumps_json(self.to_dict(), str(path), indent=2) + "\n")

    @classmethod
    def from_dict(cls, data: object, where: str = "the camera calibration") -> MeasuredJacobian:
        """Read :meth:`to_dict`'s content; :class:`JacobianError` naming the field and the reason."""
        from ..records import check_version, finite_number

        try:
            check_version(data, where, "image jacobian", JACOBIAN_VERSION)
        except ValueError as e:
            raise JacobianError(str(e)) from None
        if not isinstance(data, dict) or data.get("kind") != "stickslip image jacobian":
            raise JacobianError(f"{where}: not an image Jacobian written by stickslip camera calibrate --jacobian")

        def num(v: object, name: str, positive: bool = False, nonneg: bool = False) -> float:
            try:
                x = finite_number(v, f"{where}: {name}")
            except ValueError as e:
                raise JacobianError(str(e)) from None
            if positive and x <= 0:
                raise JacobianError(f"{where}: {name} must be > 0, got {x!r}")
            if nonneg and x < 0:
                raise JacobianError(f"{where}: {name} must be >= 0, got {x!r}")
            return x

        def pair(v: object, name: str) -> tuple[float, float]:
            if not isinstance(v, list) or len(v) != 2:
                raise JacobianError(f"{where}: {name} must be a pair of numbers, got {v!r}")
            return (num(v[0], name), num(v[1], name))

        camera = data.get("camera")
        if not isinstance(camera, str) or not camera:
            raise JacobianError(f"{where}: camera must be the camera's URL, got {camera!r}")
        pose = _pose(data.get("pose"), where, num)
        raw = data.get("directions")
        if not isinstance(raw, list) or not raw:
            raise JacobianError(f"{where}: directions must be a non-empty list")
        dirs: list[MeasuredDirection] = []
        for i, r in enumerate(raw):
            name = f"directions[{i}]"
            if not isinstance(r, dict):
                raise JacobianError(f"{where}: {name} must be an object")
            j, d, steps = r.get("joint"), r.get("direction"), r.get("steps")
            if j not in (1, 2, 3) or isinstance(j, bool) or d not in ("+", "-"):
                raise JacobianError(f"{where}: {name}: joint must be 1, 2 or 3 and direction + or -")
            if isinstance(steps, bool) or not isinstance(steps, int) or steps <= 0:
                raise JacobianError(f"{where}: {name}.steps must be a positive whole number, got {steps!r}")
            assert isinstance(j, int) and isinstance(d, str)
            px = pair(r.get("px_per_step"), f"{name}.px_per_step")
            if math.hypot(*px) <= 0:
                raise JacobianError(f"{where}: {name}.px_per_step is zero: the joint did not move the tip")
            dirs.append(MeasuredDirection(
                j, d, px, num(r.get("px_per_step_sd"), f"{name}.px_per_step_sd", nonneg=True),
                num(r.get("residual_px"), f"{name}.residual_px", nonneg=True), steps,
                num(r.get("gamma"), f"{name}.gamma", positive=True),
            ))
            _check_per_unit(dirs[-1], f"{where}: {name}")
        if len({(d.joint, d.direction) for d in dirs}) != len(dirs):
            raise JacobianError(f"{where}: a joint and direction is given twice")
        return cls(camera, num(data.get("pixel_size_m"), "pixel_size_m", positive=True), pose,
                   pair(data.get("tip_px"), "tip_px"), tuple(dirs), *_day_and_device(data, where))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> MeasuredJacobian:
        """Read ``camera calibrate --jacobian``'s file; :class:`JacobianError` (one line) naming it and the reason."""
        from ..records import read_json

        try:
            data = read_json(path, "camera calibration")
        except FileNotFoundError:
            raise JacobianError(f"{path}: no such camera calibration file") from None
        except (OSError, ValueError) as e:
            text = str(e)
            raise JacobianError(text if str(path) in text else f"{path}: {text}") from None
        return cls.from_dict(data, str(path))


def _pose(value: object, where: str, num: Callable[[object, str], float]) -> kin.Pose:
    """A camera calibration's pose, each number read by ``num``; :class:`JacobianError` naming the file."""
    if not isinstance(value, dict) or set(value) != set(kin.Pose._fields):
        raise JacobianError(f"{where}: pose must have {', '.join(kin.Pose._fields)}")
    numbers = {k: num(value[k], f"pose.{k}") for k in kin.Pose._fields}
    try:
        return kin.Pose(**numbers)
    except ValueError as e:  # no arm's pose (a Pose checks itself): named with the file, as every other field
        raise JacobianError(f"{where}: pose: {e}") from None


def _day_and_device(data: dict[str, object], where: str) -> tuple[str, str]:
    """The file's ``calibration_day`` (``""`` if not text) and ``device`` (``""`` in a file written before it was
    kept; :class:`JacobianError` if not text)."""
    day, device = data.get("calibration_day", ""), data.get("device", "")
    if not isinstance(device, str):
        raise JacobianError(f"{where}: device must be the arm's device URL, got {device!r}")
    return (day if isinstance(day, str) else ""), device


def _check_per_unit(d: MeasuredDirection, where: str) -> None:
    """:class:`JacobianError` unless ``d``'s px per m or rad is a usable number (``px / gamma`` can overflow or
    underflow: a gamma of 1e-320 gives inf, px of 1e-320 a subnormal the loop would divide by)."""
    per_unit = math.hypot(*d.px_per_unit)
    if not (math.isfinite(per_unit) and per_unit >= sys.float_info.min):
        raise JacobianError(f"{where}: px_per_step {d.px_per_step!r} over gamma {d.gamma!r} gives "
                            f"{per_unit!r} px per m or rad, not a usable number")


def measured_jacobian(
    fits: Sequence[DirectionFit], pose: kin.Pose, tip_px: tuple[float, float], calibration: Calibration,
    camera: str, pixel_size_m: float, device: str = "",
) -> MeasuredJacobian:
    """The fits of ``camera calibrate`` as a :class:`MeasuredJacobian`, each scaled by ``calibration``'s steps;
    ``device``: the arm's device key, kept so that the closed loop refuses the file on another arm.

    The ``+`` fit of a joint starts at ``pose``; its ``-`` fit where the ``+`` steps
    ended (by the model). ``gamma`` is the model's mean step over each fit's steps: the
    px per m or rad are as good as the calibration is at this pose *now*; measure right
    after ``stickslip calibrate``, and the closed loop corrects the steps' drift since.
    """
    from ..devices.base import redact_url
    from ..motion.planning import Planner

    out: list[MeasuredDirection] = []
    far: dict[int, float] = {}
    for f in sorted(fits, key=lambda f: (f.joint, f.direction != "+")):
        j = f.joint
        q0 = (pose.q1, pose.q2, pose.q3)[j - 1]
        n = f.steps[-1] - f.steps[0]
        planner = Planner(calibration, j, pose)
        if f.direction == "+":
            q_end = float(planner.position_after(q0, n))
            far[j] = q_end
            gamma = (q_end - q0) / n
        else:
            start = far.get(j, q0)
            gamma = (start - float(planner.position_after(start, -n))) / n
        if not (math.isfinite(gamma) and gamma > 0):
            raise JacobianError(f"joint {j}{f.direction}: the calibration gives no step at this pose")
        out.append(MeasuredDirection(j, f.direction, (float(f.jacobian[0]), float(f.jacobian[1])), f.jacobian_sd,
                                     float(np.max(f.residuals)), n, gamma))
    return MeasuredJacobian(redact_url(camera), float(pixel_size_m), pose, (float(tip_px[0]), float(tip_px[1])),
                            tuple(out), calibration.day, device)
