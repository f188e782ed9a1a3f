"""A third physics-based arm for the model tests: Dahl friction, Hertzian contact compliance.

Written for issue 33 *before* the model selection and intervals were changed, and never
tuned to them. It shares no code and no modelling choice with the library's physics arm
(``stickslip.sim.physics``: Coulomb friction with stiction and Stribeck, a piezo with a
2nd-order lag, a mass-spring mount) nor with the LuGre arm (``lugre_arm.py``: bristles,
first-order piezo lag, scipy rotations):

* **friction**: the Dahl model (P. R. Dahl, 1968; rate-independent pre-sliding
  hysteresis), ``dF/dz = sigma (1 - F/Fc sgn(dz))`` along the relative displacement ``z``
  of piezo tip and slider, integrated exactly over each time step (the force relaxes
  exponentially in displacement towards ``±Fc``): no static friction peak, no velocity
  dependence, no stick/slip switching;
* **contact compliance**: a Hertzian contact, whose tangential (pre-sliding) stiffness
  grows with the normal load as ``N^(1/3)`` (the contact radius), and whose capacity is
  ``Fc = mu N``;
* **drive**: a kinematic piezo (no lag): linear rise over ``1 - t_fall`` of the period, a
  half-cosine fall over ``t_fall``;
* **mount**: a *static* division of the stroke between the piezo and a compliant mount
  (no mount dynamics): the mount's compliance is anisotropic in the base frame (softer
  vertically than horizontally: the paper finds the step smaller with the arm upright)
  and stiffens under the gravity moment on joint 2's bearing (a Hertzian ball bearing,
  stiffness ``∝ load^(1/3)``);
* **poses**: frames from explicit rotation matrices written here (not
  ``stickslip.kinematics``, not scipy); the prismatic slider's normal load from the gravity
  pressing it onto its rail and a side guide; joint 2's contact loaded by the thrust along
  its axis; a rod whose mass is spread along the arm, so joint 2's torque and inertia grow
  with ``q3`` in a way that is not a straight line;
* **along the travel**: the friction level varies smoothly (three random sinusoids, ±2 %);
* **day to day** (seeded by seed and day): stroke (7 %) and friction level (5 %, which moves
  the contact's stiffness with it); per-step noise 3 % (its Gaussian limit over a traverse's count) and a
  traverse-to-traverse jitter of 0.2 % (temperature).

The physical parameters were chosen, before any fitting was changed, so that the steps are
0.5-0.95 strokes and a constant step errs by tens of per cent (prismatic) and ~10 %
(rotary) over the workspace, as the paper reports for its arm; they were not changed after.
Joints 2 and 3 only.
"""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import RegularGridInterpolator

from stickslip.measurements import Traverse

FloatArray = NDArray[np.float64]

# ------------------------------------------------------------------ the Dahl cell (dimensionless)
# time in drive periods, length in strokes, force in the friction capacity at the nominal normal load

T_FALL = 0.015  # duration of the fast edge, periods
SIGMA = 150.0  # Dahl pre-sliding stiffness at the nominal normal load, capacities per stroke
STEPS_PER_PERIOD = 2400


def dahl_cell(u: ArrayLike, n: ArrayLike, kappa: ArrayLike, sigma_scale: float = 1.0) -> FloatArray:
    """Slider travel over the third drive period (strokes), vectorised over cells.

    ``u``: constant external force on the slider along the direction of motion
    (capacities); ``n``: normal load relative to nominal (capacity ``Fc = n``, stiffness
    ``SIGMA n^(1/3)``); ``kappa``: the slider's (or rotor's) mass, capacities per
    stroke/period².
    """
    ua, na, ka = (np.asarray(x, dtype=float).ravel() for x in np.broadcast_arrays(u, n, kappa))
    fc = na
    sig = SIGMA * sigma_scale * np.cbrt(na)
    dt = 1.0 / STEPS_PER_PERIOD
    rise = 1.0 - T_FALL
    t = (np.arange(STEPS_PER_PERIOD) + 1.0) * dt
    tip = np.where(t < rise, t / rise, 0.5 * (1.0 + np.cos(math.pi * (t - rise) / T_FALL)))
    dtip = np.diff(np.concatenate(([0.0], tip)))
    x = np.zeros_like(ua)
    v = np.zeros_like(ua)
    f = np.zeros_like(ua)
    mark = x
    for period in range(3):
        if period == 2:
            mark = x.copy()
        for k in range(STEPS_PER_PERIOD):
            dz = dtip[k] - v * dt  # tip relative to slider over the step
            s = np.sign(dz)
            f = s * fc + (f - s * fc) * np.exp(-sig * np.abs(dz) / fc)  # exact Dahl update along dz
            v = v + dt * (f + ua) / ka
            x = x + dt * v
    return x - mark


GRID_U = np.linspace(-0.6, 0.6, 17)
GRID_N = np.array([0.6, 0.8, 1.0, 1.2, 1.45, 1.7])
GRID_K = np.array([0.5e-3, 0.8e-3, 1.2e-3, 1.8e-3, 2.6e-3])


@functools.lru_cache(maxsize=4)
def cell_table(sigma_scale: float = 1.0) -> RegularGridInterpolator:
    """The cell's step on a grid of (u, n, kappa), computed once per Dahl stiffness (about a second)."""
    mesh = np.meshgrid(GRID_U, GRID_N, GRID_K, indexing="ij")
    vals = dahl_cell(mesh[0], mesh[1], mesh[2], sigma_scale).reshape(mesh[0].shape)
    return RegularGridInterpolator((GRID_U, GRID_N, GRID_K), vals, method="cubic", bounds_error=False,
                                   fill_value=None)


# ------------------------------------------------------------------ frames (written here, design.md §2)


def _rx(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def gravity_base(theta: float, psi: float) -> FloatArray:
    """Unit gravity in the base frame: the base turned by theta about x, then psi about the new y."""
    r = _rx(theta) @ _ry(psi)
    return np.asarray(r.T @ np.array([0.0, 0.0, -1.0]), dtype=float)


def arm_frame(q1: FloatArray, q2: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(z2 the arm axis, z1 joint 2's axis, x2 = z1 x z2) in the base frame, shape (..., 3) each."""
    c1, s1, c2, s2 = np.cos(q1), np.sin(q1), np.cos(q2), np.sin(q2)
    # Rz(q1) applied to (-sin q2, 0, cos q2) and to (0, -1, 0)
    z2 = np.stack([-c1 * s2, -s1 * s2, c2], axis=-1)
    z1 = np.stack([s1, -c1, np.zeros_like(q1)], axis=-1)
    return z2, z1, np.cross(z1, z2)


# ------------------------------------------------------------------ the arm


@dataclass(frozen=True)
class JointData:
    stroke: float  # m or rad per stroke
    weight: float  # gravity force of what the joint carries along its motion, capacities
    rail: float  # normal-load change per unit gravity pressing on the rail (prismatic) / thrust (rotary)
    guide: float  # normal-load change per unit gravity across, on the side guide (prismatic) / radial (rotary)
    kappa: float  # mass (prismatic) or rotor inertia at q3 = 0 (rotary), dimensionless
    stiff_ratio: float  # piezo stiffness over the mount's (prismatic); 0 for rotary


JOINTS = {
    (3, "+"): JointData(1.6e-6, 0.30, 0.18, 0.06, 1.0e-3, 0.35),
    (3, "-"): JointData(1.5e-6, 0.33, 0.15, 0.08, 0.95e-3, 0.30),
    (2, "+"): JointData(80e-6, 0.26, 0.14, 0.05, 1.2e-3, 0.0),
    (2, "-"): JointData(75e-6, 0.29, 0.12, 0.07, 1.1e-3, 0.0),
}
ROD = 0.030  # rod length beyond joint 3's zero, m (its mass spread along it)
TIP = 0.014  # lever of the tip's mass at q3 = 0, m
ROD_SHARE = 0.4  # share of the carried mass that is the rod
R_CONTACT = 0.004  # joint 2's friction radius, m (converts torque lever into the cell's force)
COMPLIANCE_H, COMPLIANCE_V = 0.3, 1.0  # mount compliance horizontal / vertical (relative): the paper finds b > 0
BEARING = 0.8  # stiffening of joint 2's bearing per unit gravity moment (Hertzian, cube root)
RANGES = {2: (-7 * math.pi / 6, math.pi / 6), 3: (0.0, 0.012)}


class DahlArm:
    """True mean steps and traverse counts of the Dahl arm on one day (seeded by seed and day)."""

    def __init__(self, seed: int, day: str, noise: float = 0.03, jitter: float = 0.002):
        key = zlib.crc32(day.encode())
        rng = np.random.default_rng([seed, key, 33])
        self.rng = np.random.default_rng([seed, key, 34])
        self.noise = noise
        self.jitter = jitter

        def z() -> float:
            return float(np.clip(rng.standard_normal(), -2.5, 2.5))

        self.friction = 1.0 + 0.05 * z()
        self.joints = {k: JointData(j.stroke * (1 + 0.07 * z()), j.weight, j.rail, j.guide, j.kappa, j.stiff_ratio)
                       for k, j in sorted(JOINTS.items())}
        prof = np.random.default_rng([seed, 35])  # the travel's friction profile belongs to the arm, not the day
        self.profile = {jt: (prof.uniform(0, 2 * math.pi, 3), prof.uniform(0.004, 0.009, 3)) for jt in (2, 3)}

    def _along(self, joint: int, q: FloatArray) -> FloatArray:
        lo, hi = RANGES[joint]
        x = (q - lo) / (hi - lo)
        phases, amps = self.profile[joint]
        out = np.ones_like(x)
        for k, (p, a) in enumerate(zip(phases, amps, strict=True)):
            out = out + a * np.sin(2 * math.pi * (k + 1) * x + p)
        return out

    def mean_step(
        self, joint: int, direction: str, q1: ArrayLike, q2: ArrayLike, q3: ArrayLike, theta: float, psi: float
    ) -> FloatArray:
        """Mean step (m or rad) at poses (arrays broadcast)."""
        if joint not in (2, 3):
            raise ValueError("the Dahl arm models joints 2 and 3 only")
        q1a, q2a, q3a = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (q1, q2, q3)))
        g = gravity_base(theta, psi)
        z2, z1, x2 = arm_frame(q1a, q2a)
        p = self.joints[(joint, direction)]
        sign = 1.0 if direction == "+" else -1.0
        moving = joint - 2  # 0: joint 2, 1: joint 3
        along = self._along(joint, q2a if moving == 0 else q3a)
        if joint == 3:
            u = p.weight * sign * (z2 @ g)  # gravity along the direction of motion helps it
            press = np.maximum(-(x2 @ g), -0.9 / p.rail)  # gravity pressing the carriage onto its rail
            n = self.friction * along * (1.0 + p.rail * press + p.guide * np.abs(z1 @ g))
            kappa = np.full_like(u, p.kappa)
            # the mount: compliance projected on the arm axis (base frame), stiffened by the bearing's moment
            vert = z2[..., 2] ** 2
            moment = np.abs(np.sum(np.cross(z2, g) * z1, axis=-1))
            comp = (COMPLIANCE_H * (1.0 - vert) + COMPLIANCE_V * vert) / np.cbrt(1.0 + BEARING * moment)
            share = 1.0 / (1.0 + p.stiff_ratio * comp)
            return np.asarray(self._cell(u, n, kappa) * p.stroke * share, dtype=float)
        # joint 2: the tip's mass at TIP + q3; the rod (length ROD) slides with joint 3, its far end at the tip
        lever_tip = TIP + q3a
        lever_rod = TIP + q3a - ROD / 2.0  # centre of the rod's mass (partly behind the axis)
        arm_moment = (1.0 - ROD_SHARE) * lever_tip + ROD_SHARE * lever_rod
        inertia = (1.0 - ROD_SHARE) * lever_tip**2 + ROD_SHARE * (lever_rod**2 + ROD**2 / 12.0)
        ref_m = TIP + 0.006 - ROD_SHARE * ROD / 2.0  # the moment at mid travel
        ref_i = (1.0 - ROD_SHARE) * (TIP + 0.006) ** 2 + ROD_SHARE * ((TIP + 0.006 - ROD / 2) ** 2 + ROD**2 / 12)
        torque = np.sum(np.cross(z2, g) * z1, axis=-1)  # gravity torque about joint 2's axis, per unit lever
        u = p.weight * sign * torque * arm_moment / ref_m
        thrust = np.abs(z1 @ g)
        radial = np.sqrt(np.maximum(1.0 - thrust**2, 0.0))
        n = self.friction * along * (1.0 + p.rail * thrust + p.guide * radial * (arm_moment / ref_m))
        kappa = p.kappa * (0.5 + 0.5 * inertia / ref_i)
        return np.asarray(self._cell(u, n, kappa) * p.stroke, dtype=float)

    def _cell(self, u: FloatArray, n: FloatArray, kappa: FloatArray) -> FloatArray:
        table = cell_table()
        pts = np.stack([np.clip(u, GRID_U[0], GRID_U[-1]), np.clip(n, GRID_N[0], GRID_N[-1]),
                        np.clip(kappa, GRID_K[0], GRID_K[-1])], axis=-1)
        return np.asarray(table(pts.reshape(-1, 3)).reshape(u.shape), dtype=float)

    def traverse(self, joint: int, direction: str, pose: Sequence[float], day: str) -> Traverse:
        """A full-range traverse at ``pose`` (q1, q2, q3, theta, psi): steps = integral dq / gamma, plus noise."""
        lo, hi = RANGES[joint]
        q = np.linspace(lo, hi, 241)
        cols = [np.full_like(q, float(pose[0])), np.full_like(q, float(pose[1])), np.full_like(q, float(pose[2]))]
        cols[joint - 1] = q
        gamma = self.mean_step(joint, direction, cols[0], cols[1], cols[2], float(pose[3]), float(pose[4]))
        if not np.all(gamma > 0):
            raise ValueError("the Dahl arm stalls in this pose")
        inv = 1.0 / gamma
        steps = float(np.sum(0.5 * (inv[1:] + inv[:-1]) * np.diff(q)))
        rel = math.hypot(self.noise / math.sqrt(steps), self.jitter)
        steps *= 1.0 + rel * float(self.rng.standard_normal())
        start, end = (lo, hi) if direction == "+" else (hi, lo)
        vals = [float(v) for v in pose]
        vals[joint - 1] = 0.0
        return Traverse(day, joint, direction, vals[0], vals[1], vals[2], vals[3], vals[4], start, end,
                        max(1, round(steps)))
