"""A second physics-based arm, independent of ``stickslip.sim.physics``: LuGre friction.

The library's physics arm (``stickslip.sim.physics``) uses Coulomb friction with stiction
and the Stribeck effect, a piezo with a 2nd-order lag, a compliant mount in series and
a mount compliance ``|cos q2|^1.5``. This arm shares none of that code or those choices:

* **friction**: the LuGre bristle model (Canudas de Wit et al., IEEE TAC 1995): a bristle
  deflection ``z`` with ``dz/dt = v - σ0 |v| z / g(v)``, ``g(v) = Fc + (Fs - Fc) exp(-(v/vs)^2)``,
  force ``σ0 z + σ1 dz/dt + σ2 v``; no stick/slip switching at all (pre-sliding
  displacement and frictional lag come out of the bristle dynamics). The bristle ODE is
  integrated implicitly in ``z`` (stable for stiff bristles);
* **drive**: the piezo follows a sawtooth smoothed by a first-order lag (no resonance);
* **pose**: gravity by composing scipy ``Rotation``s (``tests/support/hidden_arm.py``), the loads
  by projection and cross products; the prismatic joint's efficiency from a *slack* that
  grows as ``sin^2`` of the arm's elevation (not ``|cos q2|``); the normal load from the
  gravity across the axis through a quadratic (not linear) preload law;
* **day-to-day**: stroke, friction level and load coupling drift (seeded by seed and day);
  per-step noise enters the traverse's count as its Gaussian limit.

It was written after the selection method and is not used while developing it; tests
assert the issue's acceptance numbers on it.
"""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from hidden_arm import RANGES, arm_rotation, gravity_in_base
from numpy.typing import ArrayLike
from scipy.interpolate import RegularGridInterpolator

from stickslip.measurements import Traverse

# ------------------------------------------------------------------ the LuGre cell

SIGMA0 = 4000.0  # bristle stiffness, static capacities per stroke
SIGMA1 = 2.0 * math.sqrt(SIGMA0 * 1e-3)  # bristle damping (about critical for the slider)
SIGMA2 = 0.03  # viscous
FC_FS = 0.65  # Coulomb over static level
VS = 1.5  # Stribeck velocity, strokes per period
T_FALL = 0.012  # fast edge, periods
TAU = 0.002  # piezo lag, periods


def lugre_cell(u: np.ndarray, n: np.ndarray, kappa: np.ndarray, steps: int = 3000) -> np.ndarray:
    """Slider travel over the third drive period (strokes), vectorised over cells."""
    u, n, kappa = (np.asarray(x, dtype=float).ravel() for x in np.broadcast_arrays(u, n, kappa))
    dt = 1.0 / steps
    e = np.zeros_like(u)
    xs = np.zeros_like(u)
    vs = np.zeros_like(u)
    z = np.zeros_like(u)
    rise = 1.0 - T_FALL
    mark = xs
    for period in range(3):
        if period == 2:
            mark = xs.copy()
        for k in range(steps):
            t = (k + 0.5) * dt
            target = t / rise if t < rise else 1.0 - (t - rise) / T_FALL
            e_new = e + dt * (target - e) / TAU
            vp = (e_new - e) / dt
            e = e_new
            v = vp - vs  # piezo relative to slider: friction drags the slider along
            g = n * (FC_FS + (1.0 - FC_FS) * np.exp(-((v / VS) ** 2)))
            z = (z + dt * v) / (1.0 + dt * SIGMA0 * np.abs(v) / g)
            zdot = v - SIGMA0 * np.abs(v) * z / g
            f = SIGMA0 * z + SIGMA1 * zdot + SIGMA2 * v
            vs = vs + dt * (f + u) / kappa
            xs = xs + dt * vs
    return xs - mark


GRID_U = np.linspace(-0.45, 0.45, 13)
GRID_N = np.array([0.7, 0.9, 1.1, 1.3, 1.5])
GRID_K = np.array([0.8e-3, 1.3e-3, 2.0e-3, 3.0e-3])


@functools.lru_cache(maxsize=1)
def cell_table() -> RegularGridInterpolator:
    """The cell's step on a grid of (u, n, kappa), computed once (a few seconds)."""
    mesh = np.meshgrid(GRID_U, GRID_N, GRID_K, indexing="ij")
    vals = lugre_cell(mesh[0], mesh[1], mesh[2]).reshape(mesh[0].shape)
    return RegularGridInterpolator((GRID_U, GRID_N, GRID_K), vals, method="cubic", bounds_error=False,
                                   fill_value=None)


def cell_step(u: ArrayLike, n: ArrayLike, kappa: ArrayLike) -> np.ndarray:
    ua, na, ka = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (u, n, kappa)))
    pts = np.stack([np.clip(ua, GRID_U[0], GRID_U[-1]), np.clip(na, GRID_N[0], GRID_N[-1]),
                    np.clip(ka, GRID_K[0], GRID_K[-1])], axis=-1)
    return np.asarray(cell_table()(pts.reshape(-1, 3)).reshape(ua.shape), dtype=float)


# ------------------------------------------------------------------ the arm


@dataclass(frozen=True)
class Joint:
    stroke: float  # m or rad per stroke
    load: float  # cell force per unit gravity load
    preload: float  # normal-load change per unit gravity across (quadratic law)
    kappa: float
    kappa_lever: float
    slack: float  # prismatic: stroke lost at a vertical arm (sin^2 elevation)


JOINTS = {
    (3, "+"): Joint(2.1e-6, 0.22, 0.15, 1.2e-3, 0.0, 0.22),
    (3, "-"): Joint(2.0e-6, 0.25, 0.12, 1.3e-3, 0.0, 0.18),
    (2, "+"): Joint(110e-6, 0.28, 0.12, 1.1e-3, 1.0, 0.0),
    (2, "-"): Joint(104e-6, 0.30, 0.10, 1.0e-3, 1.1, 0.0),
}
R0 = 0.018  # lever of the distal mass at q3 = 0, m


class LugreArm:
    """True mean steps and traverse counts of the LuGre arm on one day (seeded by seed and day)."""

    def __init__(self, seed: int, day: str, noise: float = 0.03):
        key = zlib.crc32(day.encode())
        rng = np.random.default_rng([seed, key, 99])
        self.noise = noise
        self.rng = np.random.default_rng([seed, key, 100])

        def z() -> float:
            return float(np.clip(rng.standard_normal(), -2.5, 2.5))

        friction = 1.0 + 0.05 * z()
        self.friction = friction
        self.joints = {k: Joint(j.stroke * (1 + 0.07 * z()), j.load * (1 + 0.04 * z()), j.preload, j.kappa,
                                j.kappa_lever, j.slack) for k, j in sorted(JOINTS.items())}

    def mean_step(
        self, joint: int, direction: str, q1: ArrayLike, q2: ArrayLike, q3: ArrayLike, theta: float, psi: float
    ) -> np.ndarray:
        """Mean step (m or rad) at poses (arrays broadcast)."""
        q1a, q2a, q3a = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (q1, q2, q3)))
        g = gravity_in_base(theta, psi)
        flat = [arm_rotation(a, b) for a, b in zip(q1a.ravel(), q2a.ravel(), strict=True)]
        z2 = np.array([r.apply([0.0, 0.0, 1.0]) for r in flat]).reshape(q1a.shape + (3,))
        z1 = np.stack([np.sin(q1a), -np.cos(q1a), np.zeros_like(q1a)], axis=-1)  # Rz(q1) (0, -1, 0)
        p = self.joints[(joint, direction)]
        sign = 1.0 if direction == "+" else -1.0
        along = -(z2 @ g)
        across2 = np.maximum(1.0 - along**2, 0.0)
        n = self.friction * (1.0 + p.preload * across2 - 0.5 * p.preload * across2**2)
        if joint == 3:
            u = -p.load * along * sign
            elevation = np.arcsin(np.clip(z2[..., 2], -1.0, 1.0))
            eff = 1.0 - p.slack * np.sin(elevation) ** 2
            return np.asarray(cell_step(u, n, p.kappa) * p.stroke * eff, dtype=float)
        lever = (R0 + q3a) / (R0 + 0.012)
        torque = np.cross(z2, np.broadcast_to(g, z2.shape))
        t = -np.sum(torque * z1, axis=-1)  # gravity torque term about joint 2's axis
        u = -p.load * t * lever * sign
        kappa = p.kappa * (1.0 + p.kappa_lever * lever**2)
        return cell_step(u, n, kappa) * p.stroke

    def traverse(self, joint: int, direction: str, pose: Sequence[float], day: str) -> Traverse:
        """A full-range traverse at ``pose`` (q1, q2, q3, theta, psi): steps = integral dq / gamma, plus noise."""
        lo, hi = RANGES[joint]
        q = np.linspace(lo, hi, 241)
        cols = [np.full_like(q, float(pose[0])), np.full_like(q, float(pose[1])), np.full_like(q, float(pose[2]))]
        cols[joint - 1] = q
        gamma = self.mean_step(joint, direction, cols[0], cols[1], cols[2], float(pose[3]), float(pose[4]))
        if not np.all(gamma > 0):
            raise ValueError("the LuGre arm stalls in this pose")
        inv = 1.0 / gamma
        steps = float(np.sum(0.5 * (inv[1:] + inv[:-1]) * np.diff(q)))
        steps *= 1.0 + self.noise / math.sqrt(steps) * float(self.rng.standard_normal())
        start, end = (lo, hi) if direction == "+" else (hi, lo)
        vals = [float(v) for v in pose]
        vals[joint - 1] = 0.0
        return Traverse(day, joint, direction, vals[0], vals[1], vals[2], vals[3], vals[4], start, end,
                        max(1, round(steps)))
