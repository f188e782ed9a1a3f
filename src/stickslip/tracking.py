"""Dead reckoning with sparse position feedback: a Kalman filter over position and step scale.

A stick-slip joint has no sensor, but now and then its position is known: a microscope
image gives it to a few µm, an end stop reached gives it exactly. :class:`PositionTracker`
keeps the state ``x = (q, s)`` of one joint, its position ``q`` (m or rad) and the log of
a step scale ``s`` (the day's steps are ``exp(s)`` times the calibration's), with
covariance ``P``:

* :meth:`PositionTracker.step` (predict): after ``n`` signed steps the calibration's
  planner dead-reckons a displacement ``Δ`` (scale 1); then ``q ← q + e^s Δ``, with
  Jacobian ``F = [[1, e^s Δ], [0, 1]]``, and process noise from the per-step scatter
  (``n (σ_step γ e^s)^2``), the model error (``(σ_model e^s Δ)^2``) and a slow random walk
  of the scale (``τ^2 |n|``);
* :meth:`PositionTracker.observe` (update) with a measured position and its standard
  deviation: the usual Kalman update with ``H = [1, 0]``; the scale is corrected
  through the correlation that the moves built up.

The position estimate is never silently wrong: :attr:`PositionTracker.sd` is its
standard deviation, which only a measurement shrinks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import kinematics as kin
from .calibration import Calibration
from .planning import Planner

__all__ = ["PositionTracker"]


@dataclass
class PositionTracker:
    """Kalman filter over (position, log step scale) of one joint in one pose.

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
        Prior standard deviation of the log step scale (relative), default 0.1.
    sigma_model : float
        Relative model error of a move (default: the calibration's, else 0.05).
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
    scale_sd: float = 0.1
    sigma_model: float | None = None
    step_noise: float = 0.03
    scale_walk: float = 1e-4
    x: NDArray[np.float64] = field(init=False)
    P: NDArray[np.float64] = field(init=False)

    def __post_init__(self) -> None:
        if not (self.q0_sd >= 0 and self.scale_sd > 0 and self.step_noise >= 0 and self.scale_walk >= 0):
            raise ValueError("standard deviations must be >= 0 (scale_sd > 0)")
        self._planner = Planner(self.calibration, self.joint, self.pose)
        if self.sigma_model is None:
            vals = [v for (j, _), v in self.calibration.sigma_model.items() if j == self.joint and math.isfinite(v)]
            self.sigma_model = max(vals) if vals else 0.05
        self.x = np.array([float(self.q0), 0.0])
        self.P = np.diag([float(self.q0_sd) ** 2, float(self.scale_sd) ** 2])

    @property
    def position(self) -> float:
        """Estimated position, m or rad."""
        return float(self.x[0])

    @property
    def sd(self) -> float:
        """Standard deviation of the position estimate, m or rad."""
        return math.sqrt(max(float(self.P[0, 0]), 0.0))

    @property
    def scale(self) -> float:
        """Estimated step scale relative to the calibration (1)."""
        return math.exp(float(self.x[1]))

    def step(self, signed_steps: int) -> float:
        """Predict after ``signed_steps`` steps; returns the new position estimate."""
        if signed_steps == 0:
            return self.position
        q, s = self.x
        delta = self._planner.position_after(q, signed_steps) - q
        es = math.exp(s)
        n = abs(signed_steps)
        gamma = abs(delta) / n
        F = np.array([[1.0, es * delta], [0.0, 1.0]])
        assert self.sigma_model is not None
        qv = n * (self.step_noise * gamma * es) ** 2 + (self.sigma_model * es * delta) ** 2
        Q = np.diag([qv, self.scale_walk**2 * n])
        self.x = np.array([q + es * delta, s])
        self.P = F @ self.P @ F.T + Q
        return self.position

    def observe(self, q_measured: float, sd: float) -> float:
        """Update with a measured position (m or rad) of standard deviation ``sd`` (>= 0; 0 at an end stop)."""
        if not (math.isfinite(q_measured) and sd >= 0):
            raise ValueError("a measured position must be finite with a standard deviation >= 0")
        H = np.array([1.0, 0.0])
        S = float(H @ self.P @ H) + sd**2
        if S <= 0:
            self.x[0] = q_measured
            return self.position
        K = self.P @ H / S
        self.x = self.x + K * (q_measured - self.x[0])
        self.P = (np.eye(2) - np.outer(K, H)) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
        return self.position
