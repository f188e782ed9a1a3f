"""Dead reckoning with sparse position feedback: a Kalman filter over position and step scale.

A stick-slip joint has no sensor, but now and then its position is known: a microscope
image gives it to a few µm, an end stop reached gives it exactly. The filter keeps, per
joint, the state ``x = (q, s+, s-)``: its position ``q`` (m or rad) and the logs of the
step scales of its two directions (the day's steps are ``exp(s±)`` times the
calibration's; the directions drift apart, so one scale per joint would let back-and-forth
moves pile up an error the filter could not see), with covariance ``P`` (docs/models.md §7):

* **predict** (:meth:`JointTrack.predict`), after ``n`` signed steps that the calibration
  scaled by ``exp(s±)`` dead-reckons as a displacement ``Δ``: ``q ← q + Δ``,
  ``∂q/∂s± = Δ`` for the direction moved (``Δ = e^s Δ₀``), process noise
  ``n (σ_step γ)²`` on ``q`` from the per-step scatter (``γ = |Δ|/n``) and ``τ² n`` on the
  scale moved (a slow random walk);
* **update** (:meth:`JointTrack.observe`) with a measured position of standard deviation
  ``σ``: ``H = [1, 0, 0]``, the usual Kalman gain; the scales are corrected through the
  correlation the moves built up.

The model's error in a pose (what the calibration gets wrong there) is a bias of the
step in that pose, i.e. a scale error, not noise that averages out over moves: it is part
of the scales' variance, ``var(s±) = drift² + σ_model²`` at the start (correlation
:data:`SCALE_CORRELATION` between the directions: the piezo's stroke drifts for both), and when the pose
changes (other joints or the tilt) ``σ_model²`` is added again, as the model's error in
the new pose is not the old one's.

:class:`JointTrack` is the state a device keeps between commands (``stickslip move``,
``stickslip observe``, ``stickslip where``; JSON in the device state);
:class:`PositionTracker` runs it for one joint in a Python session. The position's
standard deviation is always available and only a measurement shrinks it; it never exceeds the joint's span
(:meth:`JointTrack.cap_position`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..calibration import Calibration
from ..calibration.intervals import relative_sd
from ..calibration.update import DRIFT_PRIOR, STEP_NOISE, day_drift, model_sigma, scaled_model
from .planning import Planner

__all__ = [
    "JointTrack",
    "PositionTracker",
    "SCALE_WALK",
    "SCALE_CORRELATION",
    "MAX_LOG_SCALE",
    "calibration_id",
    "scaled_calibration",
    "joint_sigma_model",
    "track_for",
]

SCALE_CORRELATION = 0.5
"""Assumed prior correlation of the + and - step scales' day-to-day changes (1)."""

SCALE_WALK = 1e-4
"""Random walk of the log step scale, per sqrt(step) (relative): 1 % over 10 000 steps."""

MAX_LOG_SCALE = 5.0
"""Largest magnitude of a log step scale a track keeps (1): steps x148 or /148 the calibration's are a slip or a
wrong reading, not a day's drift; :meth:`JointTrack.observe` refuses to learn one, :meth:`JointTrack.from_json`
refuses to read one."""

_MIN_SCALE_VAR = 1e-6
"""Smallest prior variance of a log step scale (0.1 %²): an observation can always teach it."""


def calibration_id(cal: Calibration) -> str:
    """What a kept step scale is relative to: the calibration's day, method and creation time."""
    return f"{cal.day}|{cal.method}|{cal.created}"


def scaled_calibration(cal: Calibration, joint: int, factor: float | dict[str, float]) -> Calibration:
    """``cal`` with every step of ``joint`` multiplied by ``factor`` (1; or ``{direction: factor}``).

    Its models and its constant steps (what a stage's joint is planned with) alike.
    """
    factors = factor if isinstance(factor, dict) else {"+": factor, "-": factor}
    for f in factors.values():
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"a step scale must be finite and > 0, got {f!r}")
    if all(f == 1.0 for f in factors.values()):
        return cal
    models = {k: (scaled_model(m, factors.get(k[1], 1.0)) if k[0] == joint else m) for k, m in cal.models.items()}
    constant = {k: (v * factors.get(k[1], 1.0) if k[0] == joint else v) for k, v in cal.constant_steps.items()}
    return dataclasses.replace(cal, models=models, constant_steps=constant)


def joint_sigma_model(cal: Calibration, joint: int, pose: kin.Pose | None = None) -> float:
    """The larger relative model error of ``joint``'s two directions (1; assumed where not measured).

    In ``pose`` (the other joints and the tilt): the calibration's expected error there, the
    standard deviation ``predict --interval`` and ``plan`` use (docs/models.md §4); without
    a pose, its error over the workspace.
    """
    dirs = [d for (j, d) in cal.models if j == joint]
    if pose is None:
        vals = [model_sigma(cal, joint, d)[0] for d in dirs]
    else:
        vals = [float(relative_sd(cal, joint, d, *pose)) for d in dirs]
    return max(vals) if vals else 0.05


def _other_joints(joint: int, pose: kin.Pose) -> tuple[float, ...]:
    vals = [float(v) for v in pose]
    vals[joint - 1] = 0.0
    return tuple(round(v, 9) for v in vals)


def _prior(var: float, q_var: float = 0.0) -> NDArray[np.float64]:
    c = SCALE_CORRELATION * var
    return np.array([[q_var, 0.0, 0.0], [0.0, var, c], [0.0, c, var]])


@dataclass
class JointTrack:
    """Kalman state of one joint's dead reckoning: log step scales and covariance with the position.

    The position itself is kept by the caller (the device state's position); this holds
    what goes with it.

    Attributes
    ----------
    log_scale : ndarray, shape (2,)
        ``(s+, s-)``: the day's steps are ``exp(s)`` times the calibration's, 1.
    P : ndarray, shape (3, 3)
        Covariance of ``(q, s+, s-)``: m² or rad², m or rad, 1.
    calibration : str
        :func:`calibration_id` of the calibration the scales are relative to.
    pose : tuple of float or None
        The other joints and the tilt of the last move (rad, m), for the model-error bookkeeping.
    """

    log_scale: NDArray[np.float64] = field(default_factory=lambda: np.zeros(2))
    P: NDArray[np.float64] = field(default_factory=lambda: np.zeros((3, 3)))
    calibration: str = ""
    pose: tuple[float, ...] | None = None

    @classmethod
    def fresh(
        cls, cal: Calibration, joint: int, q_sd: float = 0.0, drift: float | None = None
    ) -> JointTrack:
        """A new track: scales 1 with ``var(s±) = drift² + σ_model²``, position sd ``q_sd`` (m or rad).

        ``drift`` (relative) defaults to 0 for a calibration made today (:func:`stickslip.clock.today`)
        and to :data:`~stickslip.calibration.update.DRIFT_PRIOR` (a day's change of step
        scale) for one from another or an unknown day: a fresh calibration's step is known
        to within its model error, not to a day's drift.
        """
        if drift is None:
            drift = day_drift(cal)
        if not (math.isfinite(q_sd) and q_sd >= 0 and math.isfinite(drift) and drift >= 0):
            raise ValueError("q_sd and drift must be finite and >= 0")
        sm = joint_sigma_model(cal, joint)
        var = max(drift**2 + sm**2, _MIN_SCALE_VAR)
        return cls(np.zeros(2), _prior(var, q_sd**2), calibration_id(cal))

    def scale_of(self, direction: str) -> float:
        """Estimated step scale of ``direction`` (``"+"`` or ``"-"``) relative to the calibration, 1."""
        return math.exp(float(self.log_scale[0 if direction == "+" else 1]))

    @property
    def scale(self) -> float:
        """The geometric mean of the two directions' step scales, 1 (for display)."""
        return math.exp(float(np.mean(self.log_scale)))

    @property
    def sd(self) -> float:
        """Standard deviation of the position, m or rad."""
        return math.sqrt(max(float(self.P[0, 0]), 0.0))

    @property
    def scale_sd(self) -> float:
        """The larger standard deviation of the two log step scales (relative), 1."""
        return math.sqrt(max(float(self.P[1, 1]), float(self.P[2, 2]), 0.0))

    def predict(
        self,
        delta: float,
        n_steps: int,
        pose: kin.Pose | None = None,
        joint: int = 3,
        sigma_model: float = 0.0,
        step_noise: float = STEP_NOISE,
        scale_walk: float = SCALE_WALK,
        ceiling: float = math.inf,
    ) -> None:
        """Propagate the covariance over a move of ``n_steps`` signed steps that dead-reckoned ``delta`` (m or rad).

        ``delta`` is the displacement at the current scale of the direction moved. With
        ``pose`` given and different from the last move's (other joints, tilt),
        ``sigma_model²`` is added to the scales' variance first (the model's error in a new pose).
        ``ceiling`` (m or rad, the joint's span): the position's σ is capped there (:meth:`cap_position`).
        """
        n = abs(int(n_steps))
        if n == 0:
            return
        if pose is not None:
            key = _other_joints(joint, pose)
            if self.pose is not None and key != self.pose:
                self.P[1:, 1:] += _prior(sigma_model**2)[1:, 1:]
            self.pose = key
        k = 1 if n_steps > 0 else 2
        gamma = abs(delta) / n
        F = np.eye(3)
        F[0, k] = delta
        Q = np.zeros((3, 3))
        Q[0, 0] = n * (step_noise * gamma) ** 2
        Q[k, k] = scale_walk**2 * n
        self.P = F @ self.P @ F.T + Q
        self.cap_position(ceiling)

    def cap_position(self, ceiling: float) -> bool:
        """Cap the position's σ at ``ceiling`` (m or rad: the joint's span); whether it was capped.

        The kept position is clipped to the joint's range and the joint is within it, so the error is never more
        than the span: a larger σ (58 m on a 12 mm joint after 1e5 unobserved moves) says nothing. The span, not
        the range's uniform sd (span/sqrt(12)): a σ is used as a margin (the rig's envelope widens by n_sigma ≥ 1
        σ, as it takes an uncertain joint's farthest bound as one σ), and a third of the span would cover less than
        where the joint may be. At the cap the position is uncorrelated with the scales (their covariance set to 0):
        a position clipped at a stop no longer follows the scale's error, so a reading re-references it and teaches
        no scale (a capped σ is not knowledge). ``ValueError`` unless ``ceiling`` > 0.
        """
        if not ceiling > 0.0:
            raise ValueError(f"a position's σ ceiling must be > 0, got {ceiling!r}")
        if not float(self.P[0, 0]) > ceiling * ceiling:
            return False
        self.P[0, :] = 0.0
        self.P[:, 0] = 0.0
        self.P[0, 0] = ceiling * ceiling
        return True

    def observe(self, q_predicted: float, q_measured: float, sd: float) -> float:
        """Kalman update with a measured position (m or rad) of standard deviation ``sd`` (0: exact).

        Returns the new position estimate; the scales are updated in place.
        """
        if not (math.isfinite(q_measured) and math.isfinite(q_predicted) and math.isfinite(sd) and sd >= 0):
            raise ValueError("a measured position must be finite with a standard deviation >= 0")
        S = float(self.P[0, 0]) + sd**2
        if S <= 0.0:  # both exact: the measurement wins, nothing to learn (and no covariance of an exact position:
            self.P[0, :] = 0.0  # a move of 1e-300 leaves its variance 0 and its covariance 1e-302)
            self.P[:, 0] = 0.0
            return float(q_measured)
        K = self.P[:, 0] / S
        innovation = q_measured - q_predicted
        log_scale = self.log_scale + K[1:] * innovation
        if not bool(np.all(np.abs(log_scale) < MAX_LOG_SCALE)):  # (a --force past the gate: kept, no move read it)
            worst = float(log_scale[np.argmax(np.abs(log_scale))])
            raise ValueError(
                f"this reading would make the step scale x{math.exp(min(worst, 700.0)):.4g}, beyond the "
                f"x{math.exp(-MAX_LOG_SCALE):.3g} to x{math.exp(MAX_LOG_SCALE):.3g} a kept track holds: a slip or a "
                "wrong reading, not a change of step; re-reference the joint's position instead "
                "(stickslip where --set JOINT=VALUE)"
            )
        self.log_scale = log_scale
        # P - K P[0, :], with the position's row in the form that cannot cancel: (1 - P00 / S) = sd² / S, so an
        # exact measurement leaves a row of exact zeros (the subtraction left ~1e-22 beside a variance of 0: a
        # correlation of 1e129 that from_json refuses, the device state unreadable after an end stop)
        P = self.P - np.outer(K, self.P[0, :])
        P[0, :] = self.P[0, :] * (sd**2 / S)
        P[:, 0] = P[0, :]
        self.P = 0.5 * (P + P.T)
        return float(q_predicted + K[0] * innovation)

    def reset_position(self, q_sd: float = 0.0) -> None:
        """The position was set by hand (``sd`` m or rad): its variance and correlations start again."""
        self.P[0, :] = 0.0
        self.P[:, 0] = 0.0
        self.P[0, 0] = q_sd**2

    def to_json(self) -> dict[str, Any]:
        """The JSON shape kept in the device state (SI)."""
        return {
            "log_scale": [float(v) for v in self.log_scale],
            "P": [[float(v) for v in row] for row in self.P],
            "calibration": self.calibration,
            "pose": list(self.pose) if self.pose is not None else None,
        }

    @classmethod
    def from_json(cls, raw: Any) -> JointTrack:
        """Read :meth:`to_json`'s shape; ``ValueError`` for anything else (non-finite, not a covariance)."""
        if not isinstance(raw, dict):
            raise ValueError(f"the kept step-scale state is not an object of scales and covariance: {raw!r:.40}")
        s, P = _numbers(raw, "log_scale", "two numbers"), _numbers(raw, "P", "a 3 x 3 matrix of numbers")
        cal = str(raw.get("calibration", ""))
        pose = None if raw.get("pose") is None else tuple(float(v) for v in _numbers(raw, "pose", "five numbers").flat)
        ok = (
            s.shape == (2,) and P.shape == (3, 3) and bool(np.all(np.isfinite(P)))
            and bool(np.all(np.isfinite(s))) and bool(np.all(np.abs(s) < MAX_LOG_SCALE))
        )
        if ok:
            with np.errstate(over="ignore", invalid="ignore"):  # entries near 1e308, or a covariance of a tiny
                P = 0.5 * (P + P.T)                              # variance and a huge one: not finite, refused
                scale = np.sqrt(np.maximum(np.diag(P), 1e-300))
                R = P / np.outer(scale, scale)
            ok = bool(np.all(np.isfinite(R)) and np.all(np.diag(P) >= 0))
            ok = ok and float(np.min(np.linalg.eigvalsh(R))) > -1e-6
        ok = ok and (pose is None or (len(pose) == 5 and all(math.isfinite(v) for v in pose)))
        if not ok:
            raise ValueError("the kept step-scale state is not a valid (scales, covariance) pair")
        return cls(s, P, cal, pose)


def _numbers(raw: dict[str, Any], key: str, what: str) -> NDArray[np.float64]:
    """``raw[key]`` as an array of floats; ``ValueError`` naming the key and what it should be (not Python's words)."""
    if key not in raw:
        raise ValueError(f"the kept step-scale state has no {key!r}")
    try:
        a = np.array(raw[key], dtype=float)  # (null is read as NaN: refused below with the rest)
    except (TypeError, ValueError, OverflowError):
        a = np.array([np.nan])
    if a.ndim == 0 or not np.all(np.isfinite(a)):
        raise ValueError(f"the kept step-scale state's {key!r} is not {what}: {raw[key]!r:.60}")
    return a


@dataclass
class PositionTracker:
    """Kalman filter over (position, log step scale) of one joint in one pose (a Python session).

    Parameters
    ----------
    calibration : Calibration
    joint : int
    pose : Pose
        The other joints and the tilt (the joint's own column is ignored).
    q0 : float
        Starting position, m or rad.
    q0_sd : float
        Its standard deviation, m or rad (0 at an end stop).
    scale_sd : float
        Prior standard deviation of the day's log step scale (relative), default 0.15
        (:data:`~stickslip.calibration.update.DRIFT_PRIOR`); the model error is added to it.
    sigma_model : float
        Relative model error in this pose (default: the calibration's, else assumed).
    step_noise : float
        Relative scatter of a single step (default 0.03).
    scale_walk : float
        Random walk of the log scale per step (relative, per sqrt(step)), default 1e-4.
    """

    calibration: Calibration
    joint: int
    pose: kin.Pose
    q0: float
    q0_sd: float = 0.0
    scale_sd: float = DRIFT_PRIOR
    sigma_model: float | None = None
    step_noise: float = STEP_NOISE
    scale_walk: float = SCALE_WALK
    track: JointTrack = field(init=False)
    q: float = field(init=False)

    def __post_init__(self) -> None:
        if not (self.q0_sd >= 0 and self.scale_sd > 0 and self.step_noise >= 0 and self.scale_walk >= 0):
            raise ValueError("standard deviations must be >= 0 (scale_sd > 0)")
        self._planner = Planner(self.calibration, self.joint, self.pose)
        if self.sigma_model is None:
            self.sigma_model = joint_sigma_model(self.calibration, self.joint, self.pose)
        self.track = JointTrack(
            np.zeros(2), _prior(self.scale_sd**2 + self.sigma_model**2, float(self.q0_sd) ** 2),
            calibration_id(self.calibration),
        )
        self.q = float(self.q0)

    @property
    def position(self) -> float:
        """Estimated position, m or rad."""
        return self.q

    @property
    def sd(self) -> float:
        """Standard deviation of the position estimate, m or rad."""
        return self.track.sd

    @property
    def scale(self) -> float:
        """Estimated step scale relative to the calibration (1)."""
        return self.track.scale

    def step(self, signed_steps: int) -> float:
        """Predict after ``signed_steps`` steps; returns the new position estimate."""
        if signed_steps == 0:
            return self.position
        factor = self.track.scale_of("+" if signed_steps > 0 else "-")
        delta = factor * (self._planner.position_after(self.q, signed_steps) - self.q)
        self.track.predict(
            delta, signed_steps, step_noise=self.step_noise, scale_walk=self.scale_walk, ceiling=self._planner.spec.span
        )
        self.q += delta
        return self.position

    def observe(self, q_measured: float, sd: float) -> float:
        """Update with a measured position (m or rad) of standard deviation ``sd`` (>= 0; 0 at an end stop)."""
        self.q = self.track.observe(self.q, q_measured, sd)
        return self.position


def track_for(raw: Any, cal: Calibration, joint: int) -> tuple[JointTrack, str | None]:
    """The kept track of ``joint`` (JSON or ``None``) for a move with ``cal``, and a note if it was restarted.

    A scale learned with another calibration means nothing for this one: the track starts
    again at scale 1 (keeping the position's standard deviation). ``ValueError`` if the
    kept JSON is unreadable.
    """
    if raw is None:
        return JointTrack.fresh(cal, joint), None
    t = JointTrack.from_json(raw)
    if t.calibration == calibration_id(cal):
        return t, None
    note = None
    if t.calibration:
        note = (
            f"joint {joint}'s step scale x{t.scale:.4f} was learned with another calibration; "
            "it starts again at 1 for this one"
        )
    return JointTrack.fresh(cal, joint, q_sd=t.sd), note
