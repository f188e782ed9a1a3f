"""A physics-based stick-slip arm: a truth that is not the paper's model (``sim://?physics=1``).

The closed-form simulator (:mod:`.arm`) draws its steps around Eqs. 3/8, so a
calibration of Eqs. 3/8 fits it by construction. This one computes the mean step from
the dynamics of one drive period, so models can be developed and tested against a
generator that follows no closed form. What is simulated (docs/models.md §1 lists the
assumptions and where each number comes from):

* **The cell** (:func:`simulate_cell`, vectorised over cells): a sawtooth voltage (slow
  rise over ``1 - t_fall`` of the period, fast fall over ``t_fall``) drives the piezo's
  extension ``e`` through a second-order lag (resonance ``1/tau_p`` periods, damping
  ``zeta_p``). The piezo sits on a compliant mount (mass ``m_b``, stiffness ``k_b``,
  damping ``zeta_b``) that recoils under the friction force. The slider (mass
  ``kappa``) touches the piezo's tip through friction with stiction and the Stribeck
  effect: static capacity ``n``, kinetic ``mu_ratio * n`` rising to ``n`` below the
  Stribeck velocity ``v_s``, plus viscous ``sigma``. A constant external force ``u``
  (the static load along the direction of motion) acts on the slider. Stick to slip
  when the force needed to keep the slider on the tip exceeds ``n``; slip to stick
  where the relative velocity crosses zero, the crossing located within the time step
  by linear interpolation. Units are the period, the piezo's stroke and the static
  friction capacity at the nominal normal load; the step is the slider's travel over
  the second period (the first starts from rest).
* **The grid**: the mean step over ``(u, n, mount compliance, kappa)`` on a grid,
  computed once per process (a few seconds) and interpolated linearly
  (:func:`step_grid`).
* **The arm**: per joint and direction, the static load ``u`` from gravity along the
  axis (prismatic) or the gravity torque over the contact radius (rotary, growing
  with the lever ``r0 + q3``); the normal load ``n`` from the preload plus gravity
  across the axis, times a friction profile that varies along the travel; the
  inertia ``kappa`` (rotary: growing with ``(r0 + q3)^2``); the mount compliance seen
  by joint 3, which depends on ``q2``. Backlash: after a reversal the first
  ``backlash`` of motion is lost. Warm-up: the step is ``1 + warmup`` times larger
  when the joint is cold and relaxes with the joint's stepping time (``warmup_tau``).
  Day-to-day drift of stroke, friction and load coupling, seeded by ``(seed, day)``.
  Per-step lognormal noise.

:class:`PhysicsMM3A` is a :class:`~stickslip.devices.base.Controller` like the
closed-form arm (same virtual clock, microphone and end stops); :func:`traverse`
measures one traverse directly, without sound, for benchmarks and tests.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from urllib.parse import parse_qsl, urlsplit

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import kinematics as kin
from ..calibration.result import Parameter
from ..devices.base import DeviceError, DeviceInfo
from ..joints import joint_spec
from ..measurements import Traverse
from ..models import direction_label, direction_sign
from .arm import _CHUNK, SimulatedMM3A, day_key

__all__ = [
    "CellParams",
    "JointPhysics",
    "NOMINAL_PHYSICS",
    "PhysicsMM3A",
    "simulate_cell",
    "step_grid",
    "open_url",
    "traverse",
]


# ---------------------------------------------------------------- the cell


@dataclass(frozen=True)
class CellParams:
    """Dimensionless parameters of one stick-slip cell (period 1, stroke 1, static friction 1).

    Attributes
    ----------
    t_fall : float
        Duration of the sawtooth's fast edge, periods.
    tau_p : float
        Natural period of the piezo's extension (its first resonance), periods.
    zeta_p : float
        Damping ratio of the piezo, 1.
    mu_ratio : float
        Kinetic over static friction coefficient, 1.
    v_s : float
        Stribeck velocity, strokes per period.
    sigma : float
        Viscous friction, static capacities per (stroke / period).
    m_b : float
        Mass of the mount, in units of static capacity * period^2 / stroke.
    k_b0 : float
        Mount stiffness at compliance 1 is ``k_b0 / 1.05``; at 0, ``k_b0 / 0.05``.
    zeta_b : float
        Damping ratio of the mount, 1.
    n_steps : int
        Time steps per period (semi-implicit Euler).
    """

    t_fall: float = 0.01
    tau_p: float = 0.01
    zeta_p: float = 0.25
    mu_ratio: float = 0.7
    v_s: float = 2.0
    sigma: float = 0.02
    m_b: float = 2e-3
    k_b0: float = 50.0
    zeta_b: float = 0.2
    n_steps: int = 2000


def simulate_cell(
    u: ArrayLike, n: ArrayLike, mount: ArrayLike, kappa: ArrayLike, cell: CellParams = CellParams()
) -> NDArray[np.float64]:
    """Slider travel over one drive period in steady state, strokes (vectorised over cells).

    Parameters
    ----------
    u : array_like
        External force on the slider along the direction of motion, in units of the
        nominal static friction capacity (positive helps the motion).
    n : array_like
        Normal load over its nominal value (scales static and kinetic friction), 1.
    mount : array_like
        Mount compliance, 1 (0 stiff, 1 soft).
    kappa : array_like
        Slider mass (or inertia over contact radius squared), static capacity *
        period^2 / stroke.
    cell : CellParams
    """
    arrays = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (u, n, mount, kappa)))
    shape = arrays[0].shape
    uu, nn, mm, kk = (a.ravel().copy() for a in arrays)
    size = uu.size
    dt = 1.0 / cell.n_steps
    w = 2.0 * math.pi / cell.tau_p
    kb = cell.k_b0 / (0.05 + mm)
    cb = 2.0 * cell.zeta_b * np.sqrt(kb * cell.m_b)
    fs = nn
    fc = nn * cell.mu_ratio
    e = np.zeros(size)
    ed = np.zeros(size)
    xb = np.zeros(size)
    vb = np.zeros(size)
    xs = np.zeros(size)
    vs = np.zeros(size)
    ff = np.zeros(size)
    stick = np.ones(size, dtype=bool)
    rise = 1.0 - cell.t_fall
    start_of_last = xs
    for period in range(2):
        if period == 1:
            start_of_last = xs.copy()
        for k in range(cell.n_steps):
            t = (k + 0.5) * dt
            volt = t / rise if t < rise else 1.0 - (t - rise) / cell.t_fall
            edd = w * w * (volt - e) - 2.0 * cell.zeta_p * w * ed
            ed = ed + dt * edd
            e = e + dt * ed
            ab = (-kb * xb - cb * vb - ff) / cell.m_b
            vb = vb + dt * ab
            xb = xb + dt * vb
            vp = vb + ed
            ap = ab + edd
            need = kk * ap - uu  # friction force that keeps the slider on the tip
            stick = stick & ~(np.abs(need) > fs)
            vr = vs - vp
            sgn = np.where(vr != 0.0, np.sign(vr), -np.sign(need))
            fk = -sgn * (fc + (fs - fc) * np.exp(-((vr / cell.v_s) ** 2))) - cell.sigma * vr
            ff = np.where(stick, need, fk)
            a_s = np.where(stick, ap, (fk + uu) / kk)
            vs_new = vs + dt * a_s
            vr_new = vs_new - vp
            cross = ~stick & (vr * vr_new < 0.0)
            frac = np.where(cross, vr / np.where(cross, vr - vr_new, 1.0), 1.0)  # where in the step vr = 0
            to_stick = cross & (np.abs(need) <= fs)
            v_cross = vs + frac * dt * a_s
            x_slip = xs + dt * 0.5 * (vs + vs_new)
            x_cross = xs + dt * (frac * 0.5 * (vs + v_cross) + (1.0 - frac) * 0.5 * (v_cross + vp))
            xs = np.where(stick, xs + dt * vp, np.where(to_stick, x_cross, x_slip))
            vs = np.where(stick | to_stick, vp, vs_new)
            stick = stick | to_stick
    out: NDArray[np.float64] = (xs - start_of_last).reshape(shape)
    return out


GRID_U = np.linspace(-0.5, 0.5, 21)
GRID_N = np.array([0.6, 0.8, 1.0, 1.2, 1.4])
GRID_MOUNT = np.array([0.0, 0.5, 1.0, 1.5])
GRID_KAPPA = np.array([0.6e-3, 1.0e-3, 1.6e-3, 2.4e-3])


@functools.lru_cache(maxsize=2)
def step_grid(cell: CellParams = CellParams()) -> tuple[tuple[NDArray[np.float64], ...], NDArray[np.float64]]:
    """The mean step (strokes) on the grid ``(u, n, mount, kappa)``, computed once per process."""
    axes = (GRID_U, GRID_N, GRID_MOUNT, GRID_KAPPA)
    mesh = np.meshgrid(*axes, indexing="ij")
    values = simulate_cell(mesh[0], mesh[1], mesh[2], mesh[3], cell=cell)
    return axes, values


def interpolate_step(
    u: ArrayLike, n: ArrayLike, mount: ArrayLike, kappa: ArrayLike, cell: CellParams = CellParams()
) -> NDArray[np.float64]:
    """Mean step (strokes) by multilinear interpolation in :func:`step_grid` (clamped to the grid)."""
    axes, values = step_grid(cell)
    pts = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (u, n, mount, kappa)))
    shape = pts[0].shape
    idx = []
    wts = []
    for ax, p in zip(axes, pts, strict=True):
        pc = np.clip(p.ravel(), ax[0], ax[-1])
        i = np.clip(np.searchsorted(ax, pc) - 1, 0, len(ax) - 2)
        idx.append(i)
        wts.append((pc - ax[i]) / (ax[i + 1] - ax[i]))
    out = np.zeros(idx[0].shape)
    for corner in range(16):
        bits = [(corner >> k) & 1 for k in range(4)]
        wgt = np.ones_like(out)
        sel = []
        for k in range(4):
            wgt = wgt * (wts[k] if bits[k] else 1.0 - wts[k])
            sel.append(idx[k] + bits[k])
        out = out + wgt * values[tuple(sel)]
    result: NDArray[np.float64] = out.reshape(shape)
    return result


# ---------------------------------------------------------------- the arm


@dataclass(frozen=True)
class JointPhysics:
    """How one joint and direction maps a pose onto the cell (SI where dimensional).

    Attributes
    ----------
    stroke : float
        Step length per stroke of the cell: m (joint 3) or rad (rotary).
    load : float
        Cell force ``|u|`` per unit gravity load term (prismatic: gravity along the axis;
        rotary: the torque term at the full lever), 1; its sign follows the physics.
    normal_across : float
        Change of the normal load per unit gravity across the axis (prismatic: along
        ``x2``, in the plane of joint 2; rotary: along the arm), 1.
    normal_axis : float
        Rotary only: change of the normal load per unit gravity along the joint axis, 1.
    kappa : float
        Cell inertia at q3 = 0 (prismatic: constant).
    kappa_lever : float
        Rotary: added inertia at the full lever, as a fraction of ``kappa``.
    mount : float
        Mount compliance (rotary: constant).
    mount_q2 : float
        Joint 3: added compliance ``mount_q2 * |cos q2|^1.5`` when the arm is vertical.
    friction_ripple : float
        Relative amplitude of the friction profile along the travel.
    backlash : float
        Lost motion after a reversal, m or rad.
    """

    stroke: float
    load: float
    normal_across: float
    normal_axis: float
    kappa: float
    kappa_lever: float
    mount: float
    mount_q2: float
    friction_ripple: float
    backlash: float


LEVER_R0 = 0.020
"""Lever of the distal mass about joints 1, 2 at q3 = 0, m (the arm's length beyond the joints)."""

NOMINAL_PHYSICS: dict[tuple[int, str], JointPhysics] = {
    (3, "+"): JointPhysics(1.9e-6, 0.18, 0.12, 0.0, 1.0e-3, 0.0, 0.2, 1.0, 0.03, 0.4e-6),
    (3, "-"): JointPhysics(1.8e-6, 0.20, 0.10, 0.0, 1.1e-3, 0.0, 0.2, 0.9, 0.03, 0.4e-6),
    (2, "+"): JointPhysics(100e-6, 0.33, 0.10, 0.08, 0.9e-3, 1.2, 0.4, 0.0, 0.02, 20e-6),
    (2, "-"): JointPhysics(95e-6, 0.36, 0.12, 0.06, 0.9e-3, 1.3, 0.4, 0.0, 0.02, 20e-6),
    (1, "+"): JointPhysics(98e-6, 0.30, 0.08, 0.06, 1.0e-3, 1.1, 0.4, 0.0, 0.02, 20e-6),
    (1, "-"): JointPhysics(93e-6, 0.32, 0.10, 0.05, 1.0e-3, 1.2, 0.4, 0.0, 0.02, 20e-6),
}
"""Nominal joint physics (see docs/models.md §1 for the sources of these numbers)."""


MOUNT_SHARE = 0.35
"""Fraction of the piezo's stroke taken by the mount at compliance 1 (series compliance)."""


def _lever(q3: NDArray[np.float64]) -> NDArray[np.float64]:
    return (LEVER_R0 + q3) / (LEVER_R0 + kin.Q3_MAX)


def cell_inputs(
    joint: int,
    sign: int,
    phys: JointPhysics,
    q: NDArray[np.float64],
    pose: kin.Pose,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(u, n, mount, kappa)`` of the cell along the travel ``q`` of ``joint`` in ``pose``.

    ``u`` is the force along the direction of motion (the load term's sign convention
    times the direction); ``n`` excludes the friction profile along the travel.
    """
    q1, q2, q3, th, ps = (np.full_like(q, float(v)) for v in pose)
    if joint == 1:
        q1 = q
    elif joint == 2:
        q2 = q
    else:
        q3 = q
    g = kin.gravity_base(th, ps)
    z2 = kin.arm_axis(q1, q2)
    z1 = kin.joint2_axis(q1)
    x2 = np.cross(z1, z2)
    along_arm = -np.sum(g * z2, axis=-1)  # the prismatic load term
    across = -np.sum(g * x2, axis=-1)
    along_j2 = -np.sum(g * z1, axis=-1)
    if joint_spec(joint).prismatic:
        u = -phys.load * along_arm * sign  # gravity along -z2 (inwards) helps the - direction
        n = 1.0 + phys.normal_across * across
        mount = phys.mount + phys.mount_q2 * np.abs(np.cos(q2)) ** 1.5
        kappa = np.full_like(q, phys.kappa)
    else:
        lever = _lever(q3)
        term = kin.load_term(joint, q1, q2, q3, th, ps)
        u = -phys.load * term * lever * sign  # the load term is minus the torque about the axis
        if joint == 2:
            n = 1.0 + phys.normal_across * along_arm * lever + phys.normal_axis * np.abs(along_j2)
        else:
            n = 1.0 + phys.normal_across * np.abs(g[..., 2]) + phys.normal_axis * (-g[..., 2]) * lever
        mount = np.full_like(q, phys.mount)
        kappa = phys.kappa * (1.0 + phys.kappa_lever * lever**2)
    return u, n, mount, kappa


def _friction_profile(joint: int, q: NDArray[np.float64], amp: float, phase: float) -> NDArray[np.float64]:
    spec = kin.JOINTS[joint]
    x = (q - spec.lower) / spec.span
    bump = np.exp(-(((x - 0.5 - 0.3 * math.sin(phase)) / 0.08) ** 2))
    out: NDArray[np.float64] = 1.0 + amp * (np.sin(2 * math.pi * 2.3 * x + phase) + 0.8 * bump)
    return out


class PhysicsMM3A(SimulatedMM3A):
    """The physics-based simulated MM3A (``sim://?physics=1``): a Controller on a virtual clock.

    Parameters as :class:`~.arm.SimulatedMM3A`, plus

    drift : float
        Relative standard deviation of the day-to-day drift of each joint's stroke
        (friction and load coupling drift by half as much). Default 0.08, in [0, 0.3].
    warmup : float
        Relative excess of a cold joint's step, default 0.03, in [0, 0.3].
    warmup_tau : float
        Stepping time over which the excess relaxes, s (default 120).
    physics : dict, optional
        ``{(joint, direction): JointPhysics}`` in place of :data:`NOMINAL_PHYSICS`.
    cell : CellParams, optional
    """

    def __init__(
        self,
        seed: int = 0,
        day: str | int = 0,
        step_noise: float = 0.03,
        drift: float = 0.08,
        sample_rate: int = 48_000,
        soundscape_kwargs: dict[str, object] | None = None,
        pose: kin.Pose | None = None,
        url: str = "sim://?physics=1",
        warmup: float = 0.03,
        warmup_tau: float = 120.0,
        physics: dict[tuple[int, str], JointPhysics] | None = None,
        cell: CellParams | None = None,
    ) -> None:
        if not 0.0 <= float(drift) <= 0.3:
            raise ValueError(f"drift = {drift!r} is outside [0, 0.3] (relative standard deviation)")
        if not 0.0 <= float(warmup) <= 0.3:
            raise ValueError(f"warmup = {warmup!r} is outside [0, 0.3]")
        if not float(warmup_tau) > 0.0:
            raise ValueError(f"warmup_tau = {warmup_tau!r} s must be > 0")
        super().__init__(seed, day, step_noise, min(float(drift), 0.2), sample_rate, soundscape_kwargs, pose, url)
        self.drift = float(drift)
        self.warmup = float(warmup)
        self.warmup_tau = float(warmup_tau)
        self.cell = cell or CellParams()
        rng = np.random.default_rng([self.seed, day_key(day), 7])

        def z() -> float:
            return float(np.clip(rng.standard_normal(), -2.5, 2.5))

        base = physics or NOMINAL_PHYSICS
        self.physics: dict[tuple[int, str], JointPhysics] = {}
        friction_day = {j: 1.0 + 0.5 * self.drift * z() for j in (1, 2, 3)}
        for key, p in sorted(base.items()):
            self.physics[key] = replace(
                p,
                stroke=p.stroke * (1.0 + self.drift * z()),
                load=p.load * (1.0 + 0.5 * self.drift * z()) / friction_day[key[0]],
            )
        self._friction_phase = {j: float(rng.uniform(0, 2 * math.pi)) for j in (1, 2, 3)}
        self._active_s = {1: 0.0, 2: 0.0, 3: 0.0}
        self._last_sign: dict[int, int] = {}
        self._slack = {1: 0.0, 2: 0.0, 3: 0.0}
        self._profiles: dict[tuple[int, int, kin.Pose], tuple[NDArray[np.float64], NDArray[np.float64]]] = {}

    @property
    def info(self) -> DeviceInfo:
        """Model, URL, joints and the simulation settings."""
        base = super().info
        extra = dict(base.extra)
        extra.update({"physics": True, "warmup": self.warmup, "warmup_tau_s": self.warmup_tau})
        return DeviceInfo(base.url, "simulated MM3A (physics)", base.joints, extra, base.identity)

    # ------------------------------------------------------------ the truth

    def true_models(self) -> dict[tuple[int, str], object]:  # type: ignore[override]  # no closed form
        """The physics arm has no closed-form model: an empty dict."""
        return {}

    def true_parameters(self) -> list[Parameter]:
        """The physics arm has no Eq. 3/8 parameters: an empty list."""
        return []

    def _profile(self, joint: int, sign: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Mean step (no warm-up) along the whole travel of ``joint`` in the current pose: ``(q, gamma)``."""
        pose = self.pose._replace(**{f"q{joint}": 0.0})
        key = (joint, sign, pose)
        hit = self._profiles.get(key)
        if hit is not None:
            return hit
        spec = kin.JOINTS[joint]
        q = np.linspace(spec.lower, spec.upper, 513)
        phys = self.physics[(joint, direction_label(sign))]
        u, n, mount, kappa = cell_inputs(joint, sign, phys, q, pose)
        n = n * _friction_profile(joint, q, phys.friction_ripple, self._friction_phase[joint])
        # the piezo's free stroke is shared with the compliant mount in series
        gamma = interpolate_step(u, n, mount, kappa, self.cell) * phys.stroke / (1.0 + MOUNT_SHARE * mount)
        if not np.all(gamma > 0.0):
            raise DeviceError(f"joint {joint} would not step {direction_label(sign)} in this pose (the load wins)")
        if len(self._profiles) > 256:
            self._profiles.clear()
        self._profiles[key] = (q, gamma)
        return q, gamma

    def true_mean_step(self, joint: int, direction: str | int, q: float | NDArray[np.float64] | None = None) -> NDArray[np.float64]:  # noqa: E501
        """The true mean step (m or rad) of ``joint`` in ``direction`` at ``q`` (no warm-up, no noise)."""
        joint = self._joint(joint)
        sign = direction_sign(direction)
        qs, g = self._profile(joint, sign)
        qq = self._q[joint] if q is None else q
        out: NDArray[np.float64] = np.interp(np.asarray(qq, dtype=float), qs, g)
        return out

    def _warm(self, t_s: np.ndarray) -> np.ndarray:
        """Warm-up factor of steps made after ``t_s`` seconds of the joint's stepping (1 when warm)."""
        return 1.0 + self.warmup * np.exp(-t_s / self.warmup_tau)

    def _advance(self, joint: int, sign: int, n: int) -> tuple[int, float]:
        """``n`` steps with backlash and warm-up; ``(k_stop, q_end)`` as the closed-form arm."""
        spec = kin.JOINTS[joint]
        stop = spec.upper if sign > 0 else spec.lower
        q = self._q[joint]
        if self._last_sign.get(joint, sign) != sign:
            self._slack[joint] = self.physics[(joint, direction_label(sign))].backlash
        self._last_sign[joint] = sign
        t0, hz = self._active_s[joint], self._hz[joint]
        self._active_s[joint] += n / hz  # every step is driven (against the stop too): it all warms the joint
        if sign * (stop - q) <= 0.0:
            return 0, stop
        qs, g = self._profile(joint, sign)
        tol = 1e-12 * spec.span
        done = 0
        while done < n:
            m = min(_CHUNK, n - done)
            warm = self._warm(t0 + (done + np.arange(m)) / hz)  # step by step: a burst can be minutes long
            eps = np.exp(self._sigma * self._rng.standard_normal(m) - 0.5 * self._sigma**2)
            p = np.full(m, q)
            sizes = np.zeros(m)
            for _ in range(12):
                sizes = np.interp(p, qs, g) * eps * warm
                if self._slack[joint] > 0.0:
                    lost = np.minimum(np.cumsum(sizes), self._slack[joint])
                    sizes = sizes - np.diff(np.concatenate(([0.0], lost)))
                csum = np.cumsum(sizes)
                p_new = q + sign * np.concatenate(([0.0], csum[:-1]))
                change = float(np.max(np.abs(p_new - p)))
                p = p_new
                if change <= tol:
                    break
            if self._slack[joint] > 0.0:
                raw = np.interp(p, qs, g) * eps * warm
                self._slack[joint] = max(0.0, self._slack[joint] - float(np.sum(raw)))
            ends = p + sign * sizes
            hit = np.nonzero(sign * (ends - stop) >= 0.0)[0]
            if hit.size:
                return done + int(hit[0]) + 1, stop
            q = float(ends[-1])
            done += m
        return n, q


def traverse(arm: PhysicsMM3A, joint: int, direction: str, pose: kin.Pose, day: str | None = None) -> Traverse:
    """Measure one full-range traverse of ``joint`` in ``direction`` at ``pose``, without sound.

    The joint is first driven onto its start stop (so backlash is taken up as on a
    real arm); the steps counted are those up to the first step that ends at the far
    stop. Returns the measurement-table row.
    """
    spec = kin.JOINTS[joint]
    sign = direction_sign(direction)
    start, end = (spec.lower, spec.upper) if sign > 0 else (spec.upper, spec.lower)
    arm.set_pose(**{f"q{k}": v for k, v in zip((1, 2, 3), pose[:3], strict=True) if k != joint})
    arm.set_pose(theta=pose.theta, psi=pose.psi)
    arm.set_pose(**{f"q{joint}": start + 0.02 * sign * spec.span})
    arm.step(joint, -sign * 5_000)  # onto the start stop (2 % of the travel is < 2000 steps)
    arm.set_pose(**{f"q{joint}": start})
    total = 0
    while True:
        with arm._lock:
            k_stop, q_end = arm._advance(joint, sign, 500_000)
            arm._q[joint] = q_end
        if k_stop < 500_000:
            total += k_stop
            break
        total += 500_000
    p = arm.pose
    return Traverse(
        str(day if day is not None else arm.day_label), joint, direction_label(sign),
        p.q1, p.q2, p.q3, p.theta, p.psi, start, end, int(total),
    )


# ---------------------------------------------------------------- URL

_URL_KEYS = {"seed": int, "day": str, "noise": float, "drift": float, "rate": int, "gain_db": float,
             "physics": str, "warmup": float}


def open_url(url: str = "sim://?physics=1") -> PhysicsMM3A:
    """Open the physics arm from ``sim://?physics=1&seed=3&day=...`` (or ``sim+physics://?...``).

    Options as the closed-form arm's (``seed``, ``day``, ``noise``, ``drift``, ``rate``,
    ``gain_db``) plus ``warmup``. Unknown keys or bad values raise ``ValueError``.
    """
    parts = urlsplit(url)
    if parts.scheme not in ("sim", "sim+physics", ""):
        raise ValueError(f"not a sim:// URL: {url!r}")
    if parts.path not in ("", "/") or parts.netloc not in ("", "mm3a", "localhost"):
        raise ValueError(f"a sim:// URL takes only query options (e.g. sim://?physics=1&seed=3), got {url!r}")
    opts: dict[str, object] = {}
    for key, value in parse_qsl(parts.query, keep_blank_values=True):
        if key not in _URL_KEYS:
            raise ValueError(f"unknown sim:// option {key!r} in {url!r} (known: {', '.join(sorted(_URL_KEYS))})")
        try:
            opts[key] = _URL_KEYS[key](value)
        except ValueError:
            raise ValueError(f"sim:// option {key}={value!r} is not a valid {_URL_KEYS[key].__name__}") from None
    scape: dict[str, object] | None = {"gain_db": opts["gain_db"]} if "gain_db" in opts else None

    def num(key: str, default: float) -> float:
        v = opts.get(key, default)
        assert isinstance(v, (int, float))
        return float(v)

    seed = opts.get("seed", 0)
    assert isinstance(seed, int)
    return PhysicsMM3A(
        seed=seed,
        day=str(opts.get("day", 0)) if "day" in opts else 0,
        step_noise=num("noise", 0.03),
        drift=num("drift", 0.08),
        sample_rate=int(num("rate", 48_000)),
        soundscape_kwargs=scape,
        url=url,
        warmup=num("warmup", 0.03),
    )
