"""The safety envelope: check a whole planned path of one arm before one step is sent.

A path is a list of poses (rad, rad, m) joined by straight lines in joint space (a move
of one joint is one line; a named position reached joint by joint is one line per
joint). Along it every link of the arm (a capsule of the arm's ``radius`` around a
segment, :meth:`~.model.Arm.segments`) must keep

* out of every keep-out volume by the volume's ``margin``,
* away from every other arm's links (at their kept poses) by the rig's ``arm_distance``,
* within each joint's range and soft limits,

with every margin widened by ``n_sigma`` standard deviations of the tip's position where
the arm is on the path (the Kalman filter's joint σ through the Jacobian, as
:func:`stickslip.kinematics.tip_sd`: a tip that may be there counts as there). The joint
σ may be one value per joint for the whole path, or :class:`SigmaGrowth`: the σ the
Kalman model predicts at each point of the path, growing with the steps taken to get
there (docs/rig.md).

How nothing between samples is missed (docs/rig.md): at one pose the distance from a
link segment to a volume is computed exactly (a half-space and another arm's segment in
closed form; a box from the convex piecewise quadratic along the segment, all of whose
pieces are checked; a cylinder by golden-section search of the convex distance along the
segment, to a few nm). Between two poses of a straight joint-space line every point of
the arm moves at most ``D = sum_i r_i |dq_i|`` (:meth:`~.model.Arm.reach_radii`), and a
distance to a set changes no faster than the point moves, so a stretch whose end
clearances ``c_a``, ``c_b`` satisfy ``(c_a + c_b - D) / 2 >= 0`` is clear everywhere in
between. A stretch not shown clear is cut in 8 and checked again, until it is either
shown clear, or a pose on it is closer than allowed (refused: that pose and its closest
point are named), or it is shorter than ``tol`` (refused too: the path then comes within
the margin plus ``tol``; 0.1 µm by default). So an accepted path never enters a volume's
margin, and a refused path does, or comes within ``tol`` of doing so.

A path that starts inside a margin (not inside a volume: that is refused) may take the
arm out (docs/rig.md, "Starting inside a margin"): until each link is out of each margin
it started in, its clearance from that obstacle (σ margin included) must not fall, and
from every other one it must stay positive, checked at poses ``tol`` of motion apart;
once every link is ``tol`` clear, the rest of the path is checked as above.

The σ margin on a stretch is bounded the same way: each joint's variance is convex along
a straight joint move (a quadratic in the distance moved, :class:`SigmaGrowth`), so its
largest value on a stretch is at one of the stretch's ends; and the tip's σ is
``|J(q) σ|`` whose rotary columns are distances from a joint's axis (joint 1: the tip's
distance from its axis; joint 2: ``length + q3``), which change no faster than the arm
moves, so over a stretch it grows by at most ``D`` times the rotary joints' σ.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..kinematics import Geometry, tip_sd
from .model import Arm, Box, Cylinder, HalfSpace, Rig

__all__ = [
    "SIGMA_MAX",
    "TOLERANCE",
    "EnvelopeViolation",
    "Refusal",
    "SigmaGrowth",
    "check_path",
    "clearances",
    "safe_fraction",
    "segment_distance",
    "tip_margin",
]

TOLERANCE = 1e-7
"""Shortest stretch of path (m of the arm's largest motion) the check cuts a path into: 0.1 µm."""

SIGMA_MAX = 1e3
"""Largest joint position σ a path is checked with, rad or m: any larger is no position's σ (and its square would
overflow a float)."""

_GOLDEN_STEPS = 40  # 0.618**40 ~ 4e-9 of a segment's length: nm for a link of tens of mm
_SPLIT = 8
_MAX_ROUNDS = 40

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Refusal:
    """Why a path was refused: the obstacle, where, how close (SI units, rig frame).

    Attributes
    ----------
    arm : str
    obstacle : str
        The volume's name, ``"arm NAME"`` for another arm, or ``"joint J limit"``.
    point : tuple of 3 floats or None
        The closest point of the arm to the obstacle, m, rig frame (``None`` for a limit).
    distance : float
        Its distance from the obstacle, m (0 inside it); for a limit, how far beyond (rad or m).
    allowed : float
        The least distance allowed (margin + radii + n_sigma σ), m.
    sigma : float
        Of which the σ margin (``n_sigma`` times the tip's σ there), m.
    q : tuple of 3 floats
        The pose where it happens (rad or m per joint).
    units : tuple of 3 str
        Each joint's unit, ``"rad"`` or ``"m"``.
    fraction : float
        How far along the path, 0 (start) to 1 (end).
    undecided : bool
        True when the path comes within ``tol`` of the allowed distance without crossing
        it (refused as the envelope cannot show it clear).
    start : str
        ``""``; ``"margin"``: the path starts inside this obstacle's margin and goes deeper;
        ``"volume"``: the arm starts inside the volume (``allowed`` is then the distance at
        which the link touches it: its radius, or both arms' radii); ``"sweep"``: the path starts
        within the distance kept from another arm's swept box (``distance`` and ``allowed`` from the box's
        middle pose, ``allowed`` with the box's pad): no way out is taken from an arm that may be anywhere there.
    """

    arm: str
    obstacle: str
    point: tuple[float, float, float] | None
    distance: float
    allowed: float
    q: tuple[float, float, float]
    fraction: float
    undecided: bool = False
    units: tuple[str, str, str] = ("rad", "rad", "m")
    sigma: float = 0.0
    start: str = ""

    def message(self) -> str:
        """One line in display units (µm, deg)."""
        shown = [f"{math.degrees(v):.3f} deg" if u == "rad" else f"{v * 1e6:.1f} µm"
                 for v, u in zip(self.q, self.units, strict=True)]
        pose = f"q = ({', '.join(shown)})"
        where = f"{self.fraction * 100:.0f}% along the path"
        if self.point is None:
            return f"arm {self.arm!r}: the path goes beyond the {self.obstacle} at {where}, {pose}"
        p = ", ".join(f"{v * 1e6:.1f}" for v in self.point)
        if self.start == "volume":
            return (f"arm {self.arm!r} is inside {self.obstacle!r} already (a collision: "
                    f"{self.distance * 1e6:.2f} µm from it, {self.allowed * 1e6:.2f} µm or less is touching) "
                    f"at ({p}) µm in the rig frame, {pose}: no move is planned from there")
        if self.start == "sweep":
            return (f"arm {self.arm!r} starts within the distance kept from the poses {self.obstacle!r} may take "
                    f"(its swept box: {self.distance * 1e6:.2f} µm from the box's middle pose at ({p}) µm in the "
                    f"rig frame, {self.allowed * 1e6:.2f} µm kept with how far the box lets it move), {pose}: no "
                    "way out is planned while it may be anywhere there")
        if self.start == "margin":
            sig = (f" ({self.sigma * 1e6:.2f} µm of it the position's σ)" if self.sigma > 0.0 else "")
            return (f"arm {self.arm!r} starts within the margin of {self.obstacle!r} and the path goes "
                    f"deeper: {self.distance * 1e6:.2f} µm from it at ({p}) µm in the rig frame, "
                    f"{self.allowed * 1e6:.2f} µm kept{sig}, {where}, {pose}; move away from "
                    f"{self.obstacle!r}, or observe or reference its joints to shrink σ")
        how = (
            f"reaches the edge of the {self.allowed * 1e6:.2f} µm kept around {self.obstacle!r}"
            if self.undecided else
            f"enters {self.obstacle!r} (touches or crosses it, {self.allowed * 1e6:.2f} µm kept)"
            if self.distance <= _NOISE else
            f"comes {self.distance * 1e6:.2f} µm from {self.obstacle!r}, closer than the "
            f"{self.allowed * 1e6:.2f} µm allowed"
        )
        hint = ""
        if self.fraction == 0.0 and self.sigma > 0.0 and self.distance > self.allowed - self.sigma:
            hint = (f"; the arm starts there, and {self.sigma * 1e6:.2f} µm of the margin is its position's σ: "
                    "observe or reference its joints to shrink it")
        return f"arm {self.arm!r}: the path {how} at ({p}) µm in the rig frame, {where}, {pose}{hint}"


class EnvelopeViolation(ValueError):
    """A planned path leaves the envelope; ``refusal`` says where. Nothing was sent."""

    def __init__(self, refusal: Refusal) -> None:
        super().__init__(refusal.message())
        self.refusal = refusal


# ---------------------------------------------------------------- distances from segments


def _seg_halfspace(a: Array, b: Array, v: HalfSpace) -> Array:
    n, p0 = np.asarray(v.normal), np.asarray(v.point)
    s = np.minimum(-(a - p0) @ n, -(b - p0) @ n)  # outside where (p - p0).n < 0
    return np.asarray(np.maximum(s, 0.0), dtype=float)


def _seg_seg(a: Array, b: Array, c: Array, d: Array) -> tuple[Array, Array]:
    """Distance between segments ab and cd (broadcast), and the parameter on ab of the closest point."""
    d1, d2, r = b - a, d - c, a - c
    aa = np.sum(d1 * d1, axis=-1)
    ee = np.sum(d2 * d2, axis=-1)
    ff = np.sum(d2 * r, axis=-1)
    cc = np.sum(d1 * r, axis=-1)
    bb = np.sum(d1 * d2, axis=-1)
    den = aa * ee - bb * bb
    tiny = 1e-30
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > tiny * np.maximum(aa * ee, tiny), np.clip((bb * ff - cc * ee) / den, 0.0, 1.0), 0.0)
        t = np.where(ee > tiny, (bb * s + ff) / np.where(ee > tiny, ee, 1.0), 0.0)
        s_lo = np.where(aa > tiny, np.clip(-cc / np.where(aa > tiny, aa, 1.0), 0.0, 1.0), 0.0)
        s_hi = np.where(aa > tiny, np.clip((bb - cc) / np.where(aa > tiny, aa, 1.0), 0.0, 1.0), 0.0)
    s = np.where(t < 0.0, s_lo, np.where(t > 1.0, s_hi, s))
    t = np.clip(t, 0.0, 1.0)
    p = a + s[..., None] * d1
    q = c + t[..., None] * d2
    return np.asarray(np.linalg.norm(p - q, axis=-1), dtype=float), np.asarray(s, dtype=float)


def _box_sq(p: Array, h: Array) -> Array:
    e = np.maximum(np.abs(p) - h, 0.0)
    return np.asarray(np.sum(e * e, axis=-1), dtype=float)


def _seg_box(a: Array, b: Array, v: Box) -> tuple[Array, Array]:
    r, c, h = v.matrix(), np.asarray(v.centre), np.asarray(v.half)
    la, lb = (a - c) @ r, (b - c) @ r
    d = lb - la
    with np.errstate(divide="ignore", invalid="ignore"):
        brk = np.concatenate(((h - la) / d, (-h - la) / d), axis=-1)
    brk = np.where(np.isfinite(brk), np.clip(brk, 0.0, 1.0), 0.0)
    zeros = np.zeros(la.shape[:-1] + (1,))
    u = np.sort(np.concatenate((zeros, zeros + 1.0, brk), axis=-1), axis=-1)  # (..., 8)
    lo, hi = u[..., :-1], u[..., 1:]
    mid = (lo + hi) / 2.0
    pm = la[..., None, :] + mid[..., None] * d[..., None, :]
    target = np.where(pm > h, h, np.where(pm < -h, -h, np.nan))
    active = ~np.isnan(target)
    dd = np.where(active, d[..., None, :], 0.0)
    num = np.sum(np.where(active, dd * (target - la[..., None, :]), 0.0), axis=-1)
    den = np.sum(dd * dd, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ustar = np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), mid)
    ustar = np.clip(ustar, lo, hi)
    cand = np.concatenate((u, ustar), axis=-1)  # (..., 15)
    pts = la[..., None, :] + cand[..., None] * d[..., None, :]
    f = _box_sq(pts, h)
    i = np.argmin(f, axis=-1)
    best = np.take_along_axis(f, i[..., None], axis=-1)[..., 0]
    return np.asarray(np.sqrt(best), dtype=float), np.asarray(np.take_along_axis(cand, i[..., None], axis=-1)[..., 0])


def _cyl_dist(p: Array, v: Cylinder) -> Array:
    ax = np.asarray(v.axis)
    rel = p - np.asarray(v.base)
    z = rel @ ax
    rho = np.linalg.norm(rel - z[..., None] * ax, axis=-1)
    er = np.maximum(rho - v.radius, 0.0)
    ez = np.maximum(np.maximum(z - v.height, -z), 0.0)
    return np.asarray(np.hypot(er, ez), dtype=float)


def _seg_cylinder(a: Array, b: Array, v: Cylinder) -> tuple[Array, Array]:
    """Golden-section search of the distance along the segment (convex: the cylinder is convex)."""
    g = (math.sqrt(5.0) - 1.0) / 2.0
    d = b - a
    lo = np.zeros(a.shape[:-1])
    hi = np.ones(a.shape[:-1])
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1 = _cyl_dist(a + x1[..., None] * d, v)
    f2 = _cyl_dist(a + x2[..., None] * d, v)
    for _ in range(_GOLDEN_STEPS):
        left = f1 <= f2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        nx = np.where(left, hi - g * (hi - lo), lo + g * (hi - lo))
        fn = _cyl_dist(a + nx[..., None] * d, v)
        x2, f2, x1, f1 = np.where(left, x1, nx), np.where(left, f1, fn), np.where(left, nx, x2), np.where(left, fn, f2)
    cand = np.stack((np.zeros_like(lo), np.ones_like(lo), x1, x2), axis=-1)
    f = _cyl_dist(a[..., None, :] + cand[..., None] * d[..., None, :], v)
    i = np.argmin(f, axis=-1)
    return (np.asarray(np.take_along_axis(f, i[..., None], axis=-1)[..., 0], dtype=float),
            np.asarray(np.take_along_axis(cand, i[..., None], axis=-1)[..., 0], dtype=float))


def segment_distance(a: ArrayLike, b: ArrayLike, volume: Box | Cylinder | HalfSpace) -> tuple[Array, Array]:
    """Distance from segments ``a``-``b`` (``(..., 3)``, m) to ``volume`` (0 if they touch it), and closest points."""
    aa, bb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if isinstance(volume, HalfSpace):
        n, p0 = np.asarray(volume.normal), np.asarray(volume.point)
        sa, sb = -(aa - p0) @ n, -(bb - p0) @ n
        pts = np.where((sa <= sb)[..., None], aa, bb)
        return np.asarray(np.maximum(np.minimum(sa, sb), 0.0), dtype=float), pts
    dist, u = _seg_box(aa, bb, volume) if isinstance(volume, Box) else _seg_cylinder(aa, bb, volume)
    return dist, np.asarray(aa + u[..., None] * (bb - aa), dtype=float)


def _bound_sphere(v: Box | Cylinder) -> tuple[Array, float]:
    if isinstance(v, Box):
        return np.asarray(v.centre), float(np.linalg.norm(v.half))
    return np.asarray(v.base) + np.asarray(v.axis) * v.height / 2.0, math.hypot(v.radius, v.height / 2.0)


# ---------------------------------------------------------------- the position's σ along the path


@dataclass(frozen=True)
class SigmaGrowth:
    """Each joint's position σ along a path as the Kalman model predicts it (:mod:`stickslip.motion.tracking`).

    Per joint, the covariance ``P`` of ``(q, s+, s-)`` (m² or rad², m or rad, 1) at the
    path's start; a move of ``δ`` in direction ``k`` at ``n = |δ| / step`` steps adds
    ``2 δ P[0, k] + δ² P[k, k] + step_noise² |δ| step`` to the position's variance
    (the filter's predict: the step scale's uncertainty carried over the distance, and the
    per-step scatter) and ``scale_walk² n`` to the scale's. A joint that starts to move
    after another joint has moved since its own last move (its pose changed) first gets
    ``sigma_model²`` added to its scales' variance (correlation ``correlation``), as the
    filter does after a move in a new pose; along one path (and one jog session) that
    happens at most once per joint: the model's error in the path's nearby poses is one
    bias, not a new one at each of a reach's segments.

    Attributes
    ----------
    P : tuple of 3 3x3 nested tuples
        Joint 1, 2, 3's covariance at the start.
    step : tuple of 3 floats
        A step of each joint, m or rad (for the per-step scatter and the step count).
    step_noise, scale_walk : float
        Relative per-step scatter (1) and the log scale's random walk per sqrt(step).
    sigma_model : tuple of 3 floats
        Each joint's relative model error, added to the scales' variance in a new pose.
    correlation : float
        The prior correlation of the + and - scales' added variance.
    last_pose : tuple of 3 (tuple of 3 floats or None)
        Each joint's other joints at its last move before the path (``None``: unknown,
        no pose change counted at its first move).
    bumped : tuple of 3 bools
        Whether each joint's new-pose error was added already (:meth:`after` carries it).
    """

    P: tuple[tuple[tuple[float, float, float], ...], ...]
    step: tuple[float, float, float]
    step_noise: float = 0.0
    scale_walk: float = 0.0
    sigma_model: tuple[float, float, float] = (0.0, 0.0, 0.0)
    correlation: float = 0.0
    last_pose: tuple[tuple[float, float, float] | None, ...] = (None, None, None)
    bumped: tuple[bool, ...] = (False, False, False)

    def __post_init__(self) -> None:
        numbers = {"P": self.P, "step": self.step, "step_noise": self.step_noise, "scale_walk": self.scale_walk,
                   "sigma_model": self.sigma_model, "correlation": self.correlation}
        for name, value in numbers.items():  # a NaN σ would read as none, an infinite one as clear everywhere
            if not np.all(np.isfinite(np.asarray(value, dtype=float))):
                raise ValueError(f"the σ model's {name} must be finite, got {value!r}")

    @classmethod
    def constant(cls, q_sd: ArrayLike) -> SigmaGrowth:
        """No growth: the σ ``q_sd`` (rad, rad, m) all along; ``ValueError`` unless three finite numbers >= 0."""
        sd = np.asarray(q_sd, dtype=float)
        if sd.shape != (3,) or not np.all(np.isfinite(sd)) or np.any(sd < 0) or np.any(sd > SIGMA_MAX):
            raise ValueError(
                f"the joints' position σ must be three numbers in 0..{SIGMA_MAX:g} (rad, rad, m), got {q_sd!r}"
            )
        z = (0.0, 0.0, 0.0)
        return cls(tuple(((float(v) ** 2, 0.0, 0.0), z, z) for v in sd), (1.0, 1.0, 1.0))

    def starts(self, path: Array) -> Array:
        """Each segment's start covariance, per joint, after a new pose's addition: ``(n, 3, 6)``.

        The six numbers are ``P00, P01, P02, P11, P12, P22``.
        """
        return self._propagate(np.asarray(path, dtype=float))[0]

    def after(self, path: ArrayLike) -> SigmaGrowth:
        """The σ model at the end of ``path`` (poses, rad or m): what a jog's next tick starts from."""
        _, P, last, bumped = self._propagate(np.asarray(path, dtype=float))
        return dataclasses.replace(self, P=P, last_pose=last, bumped=bumped)

    def _propagate(self, path: Array) -> tuple[Array, tuple[tuple[tuple[float, float, float], ...], ...],
                                               tuple[tuple[float, float, float] | None, ...], tuple[bool, ...]]:
        n = len(path) - 1
        out = np.empty((max(n, 0), 3, 6))
        if self.step_noise == 0 and not any(self.P[j][a][b] for j in range(3) for a in range(3) for b in range(3)
                                            if (a, b) != (0, 0)):
            out[:] = 0.0  # nothing grows: the start's σ all along
            out[:, :, 0] = [self.P[j][0][0] for j in range(3)]
            return out, self.P, self.last_pose, self.bumped
        ends, lasts, bumps = [], [], []
        rounded = np.round(path[:-1], 9)

        def excl(v: Array) -> tuple[Array, float]:  # the sums before each segment, and the whole sum
            c = np.cumsum(v)
            return np.concatenate(([0.0], c[:-1])), float(c[-1]) if len(c) else 0.0

        for j in range(3):
            p = self.P[j]
            d = np.diff(path[:, j])
            up, down = d > 0, d < 0
            moving = np.flatnonzero(d != 0)
            last, bumped = self.last_pose[j], self.bumped[j]
            bump = np.zeros(n)
            sm2 = self.sigma_model[j] ** 2
            if len(moving):
                others = rounded[moving].copy()
                others[:, j] = 0.0
                changed = np.zeros(len(moving), dtype=bool)
                changed[1:] = np.any(others[1:] != others[:-1], axis=1)
                if last is not None:  # the first move against the track's pose (kept with Python's round)
                    first = [round(float(path[moving[0], i]), 9) if i != j else 0.0 for i in range(3)]
                    changed[0] = tuple(first) != tuple(last)
                if sm2 > 0.0 and not bumped and np.any(changed):
                    bump[moving[int(np.argmax(changed))]:] = 1.0
                    bumped = True
                row = [round(float(path[moving[-1], i]), 9) if i != j else 0.0 for i in range(3)]
                last = (row[0], row[1], row[2])
            gamma = max(abs(self.step[j]), 1e-300)
            steps = np.abs(d) / gamma
            w2 = self.scale_walk**2
            walk_up, walk_up_all = excl(np.where(up, w2 * steps, 0.0))
            walk_dn, walk_dn_all = excl(np.where(down, w2 * steps, 0.0))
            p11 = p[1][1] + sm2 * bump + walk_up
            p22 = p[2][2] + sm2 * bump + walk_dn
            p12 = p[1][2] + self.correlation * sm2 * bump
            p01, p01_all = excl(np.where(up, d * p11, np.where(down, d * p12, 0.0)))
            p02, p02_all = excl(np.where(up, d * p12, np.where(down, d * p22, 0.0)))
            p01, p02 = p[0][1] + p01, p[0][2] + p02
            inc = np.where(up, 2.0 * d * p01 + d * d * p11, np.where(down, 2.0 * d * p02 + d * d * p22, 0.0))
            p00, p00_all = excl(inc + self.step_noise**2 * np.abs(d) * gamma)
            p00 = p[0][0] + p00
            out[:, j] = np.stack((p00, p01, p02, p11, p12, p22), axis=1)
            b = sm2 * (float(bump[-1]) if n else 0.0)
            e11, e22 = p[1][1] + b + walk_up_all, p[2][2] + b + walk_dn_all
            e12 = p[1][2] + self.correlation * b
            e00, e01, e02 = p[0][0] + p00_all, p[0][1] + p01_all, p[0][2] + p02_all
            ends.append(((e00, e01, e02), (e01, e11, e12), (e02, e12, e22)))
            lasts.append(last)
            bumps.append(bumped)
        return out, tuple(ends), tuple(lasts), tuple(bumps)

    def sd_at(self, path: Array, starts: Array, s: Array) -> Array:
        """Each joint's σ (rad, rad, m) at path parameters ``s`` (``k + t`` on segment ``k``): ``(M, 3)``.

        ``starts`` is :meth:`starts` of ``path``.
        """
        n = len(path) - 1
        k = np.minimum(np.floor(s).astype(int), n - 1)
        t = (s - k)[:, None]
        d = path[k + 1] - path[k]  # (M, 3)
        c = starts[k]  # (M, 3, 6)
        up = d > 0
        p0k = np.where(up, c[..., 1], c[..., 2])
        pkk = np.where(up, c[..., 3], c[..., 5])
        td = t * d
        noise = np.array([self.step_noise**2 * abs(g) for g in self.step])
        var = c[..., 0] + 2.0 * td * p0k + td * td * pkk + np.abs(td) * noise[None, :]
        return np.asarray(np.sqrt(np.maximum(var, 0.0)), dtype=float)


def levers(arm: Arm, q: Array) -> Array:
    """The norms of the Jacobian's columns at poses ``q`` ``(P, 3)``: how far the tip moves per unit of each joint.

    An MM3A: the tip's distance from joint 1's axis, ``length + q3``, 1; an xyz stack: the
    axes' lengths. ``n_sigma`` times ``|levers * σ|`` is the tip's σ margin.
    """
    if arm.kind == "mm3a":
        g = arm.geometry or Geometry()
        r = g.length + q[:, 2]
        return np.stack((np.abs(g.offset - r * np.sin(q[:, 1])), np.abs(r), np.ones(len(q))), axis=1)
    return np.broadcast_to(np.linalg.norm(np.asarray(arm.axes, dtype=float), axis=1), q.shape).astype(float)


@dataclass(frozen=True)
class _Margins:
    """The σ margin along one path: at points, and a bound over a stretch (m)."""

    arm: Arm
    path: Array
    n_sigma: float
    growth: SigmaGrowth | None  # None: no σ anywhere
    starts: Array
    fixed: Array | None = None  # the same σ all along

    @classmethod
    def of(cls, arm: Arm, path: Array, n_sigma: float, q_sd: ArrayLike | SigmaGrowth) -> _Margins:
        g = q_sd if isinstance(q_sd, SigmaGrowth) else SigmaGrowth.constant(q_sd)
        if n_sigma == 0 or not (any(g.P[j][0][0] > 0 or g.P[j][1][1] > 0 or g.P[j][2][2] > 0 for j in range(3))
                                or g.step_noise > 0):
            return cls(arm, path, n_sigma, None, np.zeros((0, 3, 6)))
        if not isinstance(q_sd, SigmaGrowth):
            return cls(arm, path, n_sigma, g, np.zeros((0, 3, 6)), np.sqrt([g.P[j][0][0] for j in range(3)]))
        return cls(arm, path, n_sigma, g, g.starts(path))

    def rest(self, before: Array, path: Array) -> _Margins:
        """The margins along ``path``, which follows the poses ``before`` (rad or m) of this one."""
        if self.growth is None or self.fixed is not None:
            return dataclasses.replace(self, path=path)
        g = self.growth.after(before)
        return dataclasses.replace(self, path=path, growth=g, starts=g.starts(path))

    def sd(self, s: Array) -> Array:
        """Each joint's σ at path parameters ``s``, ``(M, 3)``."""
        if self.fixed is not None:
            return np.broadcast_to(self.fixed, (len(s), 3))
        assert self.growth is not None
        return self.growth.sd_at(self.path, self.starts, s)

    def at(self, s: Array, q: Array) -> Array:
        """``n_sigma`` times the tip's σ at path parameters ``s`` (poses ``q``), m."""
        if self.growth is None:
            return np.zeros(len(s))
        return np.asarray(self.n_sigma * np.linalg.norm(levers(self.arm, q) * self.sd(s), axis=1), dtype=float)

    def over(self, s0: Array, s1: Array, q0: Array, q1: Array, span: Array) -> Array:
        """An upper bound of :meth:`at` over each stretch ``[s0, s1]`` (which moves the arm by at most ``span``)."""
        if self.growth is None:
            return np.zeros(len(s0))
        big = np.maximum(self.sd(s0), self.sd(s1))
        tip = np.minimum(np.linalg.norm(levers(self.arm, q0) * big, axis=1),
                         np.linalg.norm(levers(self.arm, q1) * big, axis=1))
        if self.arm.kind == "mm3a":  # its rotary levers change no faster than the arm moves
            tip = tip + span * np.linalg.norm(big[:, :2], axis=1)
        return np.asarray(self.n_sigma * tip, dtype=float)

    @property
    def largest(self) -> float:
        """A bound of the margin anywhere on the path, m: the largest σ of each joint (at a vertex: each variance
        is convex along a segment) through the arm's reach radii (which bound the Jacobian's columns)."""
        if self.growth is None:
            return 0.0
        n = len(self.path) - 1
        sd = self.sd(np.arange(n + 1, dtype=float)).max(axis=0)
        return float(self.n_sigma * np.linalg.norm(np.asarray(self.arm.reach_radii()) * sd))


# ---------------------------------------------------------------- the obstacles of one arm


@dataclass(frozen=True)
class _Obstacles:
    """What one arm must keep from: volumes and other arms' segments, each with its allowed distance (m).

    Columns: the volumes in the rig's order, then the other arms' links.
    """

    volumes: tuple[Box | Cylinder | HalfSpace, ...]
    allowed_v: Array
    others: Array  # (K, 2, 3) other arms' segments
    allowed_o: Array  # (K,)
    other_names: tuple[str, ...]
    contact: Array  # (V + K,) the distance at which the link's capsule touches the obstacle, m
    half: tuple[int, ...] = ()  # columns of half-spaces
    bounded: tuple[int, ...] = ()  # columns of boxes and cylinders
    owner: tuple[int, ...] = ()  # each other arm's link: its cell (:class:`_Cell`)

    @property
    def count(self) -> int:
        """Number of obstacles (columns of :func:`clearances`)."""
        return len(self.volumes) + len(self.others)


def tip_margin(arm: Arm, q: ArrayLike, q_sd: ArrayLike, n_sigma: float) -> float:
    """``n_sigma`` times the tip's position σ at ``q`` (m) for joint σ ``q_sd`` (rad, rad, m)."""
    sd = np.asarray(q_sd, dtype=float).reshape(3)
    if not np.any(sd > 0) or n_sigma == 0:
        return 0.0
    if arm.kind == "mm3a":
        return float(n_sigma * np.linalg.norm(tip_sd(np.asarray(q, dtype=float), sd, arm.geometry or Geometry())))
    return float(n_sigma * np.linalg.norm(sd * np.linalg.norm(np.asarray(arm.axes), axis=1)))


@dataclass(frozen=True)
class _Cell:
    """Another arm over a box of poses (each joint anywhere in ``lo``..``hi``, rad or m; one pose: ``lo == hi``).

    It is checked as its links at the box's centre kept ``pad`` farther away: every point of
    the arm is within ``pad`` of where it is at the centre, anywhere in the box (the reach
    radii, :meth:`~.model.Arm.reach_radii`, bound how far it moves along the straight
    line from the centre), so a distance to the centre's links less ``pad`` is a lower
    bound of the distance to every pose of the box (the swept set). A box whose bound is
    too coarse is cut (:meth:`split`) and checked again (:func:`_check_swept`).
    """

    arm: Arm
    lo: Array
    hi: Array

    @property
    def centre(self) -> Array:
        return np.asarray((self.lo + self.hi) / 2.0, dtype=float)

    @property
    def pad(self) -> float:
        """How far a point of the arm may be from where it is at the centre, anywhere in the box, m."""
        return float(np.asarray(self.arm.reach_radii()) @ ((self.hi - self.lo) / 2.0))

    def split(self) -> list[_Cell]:
        """The box cut in ``_SPLIT`` along the joint that moves the arm most over it."""
        j = int(np.argmax(np.asarray(self.arm.reach_radii()) * (self.hi - self.lo)))
        cuts = np.linspace(self.lo[j], self.hi[j], _SPLIT + 1)
        out = []
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            lo, hi = self.lo.copy(), self.hi.copy()
            lo[j], hi[j] = a, b
            out.append(_Cell(self.arm, lo, hi))
        return out


def _cells(rig: Rig, arm: Arm, others: Mapping[str, ArrayLike], swept: Mapping[str, ArrayLike]) -> list[_Cell]:
    """The other arms to keep from: a kept pose (``others``), or a box of poses (``swept``, ``(3, 2)`` lo, hi)."""
    out = []
    for other in rig.arms:
        if other.name == arm.name:
            continue
        if other.name in swept:
            box = np.asarray(swept[other.name], dtype=float).reshape(3, 2)
            if not np.all(np.isfinite(box)):
                raise ValueError(f"arm {other.name!r}'s swept box must be finite, got {box.tolist()!r}")
            out.append(_Cell(other, box.min(axis=1), box.max(axis=1)))
        elif other.name in others:
            q = np.asarray(others[other.name], dtype=float).reshape(3)
            out.append(_Cell(other, q, q.copy()))
    return out


def _obstacles(rig: Rig, arm: Arm, cells: list[_Cell]) -> _Obstacles:
    vols = rig.volumes
    allowed_v = np.array([v.margin + arm.radius for v in vols], dtype=float)
    segs, allowed_o, names, owner = [], [], [], []
    for i, cell in enumerate(cells):
        pad = cell.pad
        for link in cell.arm.segments(cell.centre):
            segs.append(link)
            allowed_o.append(rig.arm_distance + arm.radius + cell.arm.radius + pad)
            names.append(f"arm {cell.arm.name}")
            owner.append(i)
    return _Obstacles(
        vols, allowed_v, np.asarray(segs, dtype=float).reshape(-1, 2, 3), np.asarray(allowed_o, dtype=float),
        tuple(names), np.asarray([arm.radius] * len(vols) + [a - rig.arm_distance for a in allowed_o], dtype=float),
        tuple(i for i, v in enumerate(vols) if isinstance(v, HalfSpace)),
        tuple(i for i, v in enumerate(vols) if not isinstance(v, HalfSpace)),
        tuple(owner),
    )


def _sphere_gap(mid: Array, half: Array, centres: Array, radii: Array) -> Array:
    """Lower bound of the distance between segments (midpoints, half lengths) and spheres: ``(M, B)``, m."""
    d2 = np.sum(mid * mid, axis=1)[:, None] - 2.0 * (mid @ centres.T) + np.sum(centres * centres, axis=1)[None, :]
    return np.asarray(np.sqrt(np.maximum(d2, 0.0)) - half[:, None] - radii[None, :], dtype=float)


def clearances(arm: Arm, obstacles: _Obstacles, q: Array, pad: float | Array = 0.0) -> Array:
    """Clearance of the arm at poses ``q`` ``(P, 3)`` from each obstacle, m: distance minus allowed, ``(P, V + K)``.

    A box, cylinder or other arm's link whose bounding sphere is farther than ``pad`` (m;
    one value, or one per pose) beyond the allowed distance from a link gets a lower bound
    (the spheres' gap), not its exact distance: that is all a stretch's test needs.
    """
    return np.asarray(_link_clearances(arm, obstacles, q, pad).min(axis=1), dtype=float)


def _link_clearances(arm: Arm, obstacles: _Obstacles, q: Array, pad: float | Array = 0.0) -> Array:
    """:func:`clearances` of each link (the tip's is its last link's): ``(P, L, V + K)``, m."""
    segs = arm.segments(q)  # (P, L, 2, 3)
    n_pose, n_link = segs.shape[0], segs.shape[1]
    pad = np.repeat(np.broadcast_to(np.asarray(pad, dtype=float), (n_pose,)), n_link)  # per link row
    a, b = segs[..., 0, :].reshape(-1, 3), segs[..., 1, :].reshape(-1, 3)
    nv = len(obstacles.volumes)
    out = np.empty((len(a), obstacles.count))
    if obstacles.half:
        normals = np.array([obstacles.volumes[i].normal for i in obstacles.half]).T  # type: ignore[union-attr]
        offsets = np.array([np.dot(obstacles.volumes[i].point, obstacles.volumes[i].normal)  # type: ignore[union-attr]
                            for i in obstacles.half])
        sa, sb = offsets - a @ normals, offsets - b @ normals
        out[:, list(obstacles.half)] = np.maximum(np.minimum(sa, sb), 0.0)
    mid, half = (a + b) / 2.0, np.linalg.norm(b - a, axis=1) / 2.0
    if obstacles.bounded:
        spheres = [_bound_sphere(obstacles.volumes[i]) for i in obstacles.bounded]  # type: ignore[arg-type]
        gap = _sphere_gap(mid, half, np.array([c for c, _ in spheres]), np.array([r for _, r in spheres]))
        for col, i in enumerate(obstacles.bounded):
            v = obstacles.volumes[i]
            near = gap[:, col] < obstacles.allowed_v[i] + pad
            d = np.maximum(gap[:, col], 0.0)
            if np.any(near) and isinstance(v, Box):
                d[near], _ = _seg_box(a[near], b[near], v)
            elif np.any(near) and isinstance(v, Cylinder):
                d[near], _ = _seg_cylinder(a[near], b[near], v)
            out[:, i] = d
    if len(obstacles.others):
        oa, ob = obstacles.others[:, 0, :], obstacles.others[:, 1, :]
        gap = _sphere_gap(mid, half, (oa + ob) / 2.0, np.linalg.norm(ob - oa, axis=1) / 2.0)
        near = gap < obstacles.allowed_o[None, :] + pad[:, None]
        d = np.maximum(gap, 0.0)
        rows, cols = np.nonzero(near)
        if len(rows):
            d[rows, cols], _ = _seg_seg(a[rows], b[rows], oa[cols], ob[cols])
        out[:, nv:] = d
    out -= np.concatenate((obstacles.allowed_v, obstacles.allowed_o))[None, :]
    return out.reshape(n_pose, n_link, -1)


# ---------------------------------------------------------------- the path


def _limit_refusal(arm: Arm, path: Array) -> Refusal | None:
    n = len(path) - 1
    lo = np.array([j.limits[0] for j in arm.joints])
    hi = np.array([j.limits[1] for j in arm.joints])
    bad = (path < lo - 1e-12) | (path > hi + 1e-12)
    if not np.any(bad):
        return None
    k = int(np.argmax(np.any(bad, axis=1)))
    j = arm.joints[int(np.argmax(bad[k]))]
    v = float(path[k, j.number - 1])
    below = v < j.limits[0]
    bound = j.limits[0] if below else j.limits[1]
    which = "soft limit" if bound in (j.soft_lower, j.soft_upper) else "range"
    qk = path[k]
    return Refusal(arm.name, f"joint {j.number} {which}", None, v - bound, 0.0,
                   (float(qk[0]), float(qk[1]), float(qk[2])), k / max(n, 1), units=_units(arm))


def _node_clearances(
    arm: Arm, obs: _Obstacles, margins: _Margins, nodes: Array, qn: Array, longest: float, extra: float
) -> tuple[Array, Array]:
    """The clearances at the nodes without the σ margin ``(P, V + K)``, and the σ margin at each node (m).

    The exact distances are computed where they may matter: within the longest stretch's
    motion plus the node's margin (or, with one σ all along, the path's largest margin).
    """
    if margins.fixed is None and margins.growth is not None:  # a growing σ: the margin at every node
        at = margins.at(nodes, qn)
        return clearances(arm, obs, qn, longest + at), at
    c = clearances(arm, obs, qn, longest + extra)
    at = np.zeros(len(nodes))
    near = np.min(c, axis=1) < extra  # one σ all along: its margin where it may matter
    if np.any(near):
        at[near] = margins.at(nodes[near], qn[near])
    return c, at


def _bad(m: Array, c: Array, allowed: Array) -> NDArray[np.bool_]:
    """Which poses break the envelope, from their clearances with (``m``) and without (``c``) the σ margin.

    Inside (or touching) an obstacle is bad with nothing kept around it too: a volume of no
    margin, links of no radius and no σ give a clearance of 0 there, which is not below 0. Within
    ``_NOISE`` is touching (the distances' rounding: two arms' links along one line were 1e-18 m apart).
    """
    return np.asarray(np.any((m < 0) | (c <= _NOISE - allowed), axis=1), dtype=bool)


def _search(arm: Arm, obs: _Obstacles, path: Array, tol: float, margins: _Margins) -> tuple[float, Refusal | None]:
    """The fraction of the path shown clear from its start, and the refusal at its first problem (``None``: none)."""
    radii = np.asarray(arm.reach_radii())
    n = len(path) - 1
    rate = np.abs(np.diff(path, axis=0)) @ radii  # m of motion per unit of s on each segment
    s0 = np.arange(n, dtype=float)
    s1 = s0 + 1.0
    seg = np.arange(n)
    first_bad: tuple[float, int, bool] | None = None  # (s, obstacle, undecided)
    extra = margins.largest
    allowed = np.concatenate((obs.allowed_v, obs.allowed_o))[None, :]

    def pose(s: Array, k: Array) -> Array:
        return np.asarray(path[k] + (s - k)[:, None] * (path[k + 1] - path[k]), dtype=float)

    for _ in range(_MAX_ROUNDS):
        if not len(s0):
            break
        span = (s1 - s0) * rate[seg]
        if obs.count == 0:
            break
        nodes, back = np.unique(np.concatenate((s0, s1)), return_inverse=True)
        kn = np.minimum(np.floor(nodes).astype(int), n - 1)
        qn = pose(nodes, kn)
        c, at = _node_clearances(arm, obs, margins, nodes, qn, float(np.max(span)) if len(span) else 0.0, extra)
        i0, i1 = back[: len(s0)], back[len(s0):]
        c0, c1 = c[i0], c[i1]
        m0, m1 = c0 - at[i0][:, None], c1 - at[i1][:, None]
        bad0, bad1 = _bad(m0, c0, allowed), _bad(m1, c1, allowed)
        for mask, s, cc in ((bad0, s0, m0), (bad1, s1, m1)):
            if np.any(mask):
                i = int(np.argmin(np.where(mask, s, np.inf)))
                if first_bad is None or s[i] < first_bad[0]:
                    first_bad = (float(s[i]), int(np.argmin(cc[i])), False)
        mid = np.min(c0 + c1, axis=1) / 2.0 - span / 2.0
        clear = mid - extra >= 0.0  # clear even with the largest σ margin of the path
        if not np.all(clear):  # else the σ margin anywhere on each stretch, at most
            rest = ~clear
            clear[rest] = mid[rest] - margins.over(s0[rest], s1[rest], qn[i0[rest]], qn[i1[rest]], span[rest]) >= 0.0
        open_ = ~clear & ~bad0  # a stretch that ends badly is cut too: where does it begin to?
        tiny = open_ & (span <= tol)
        if np.any(tiny):
            i = int(np.argmin(np.where(tiny, s0, np.inf)))
            if first_bad is None or s0[i] < first_bad[0]:
                first_bad = (float(s0[i]), int(np.argmin((m0[i] + m1[i]) / 2.0)), True)
        keep = open_ & ~tiny
        if first_bad is not None:
            keep &= s0 < first_bad[0]  # what lies beyond the first problem does not matter
        if not np.any(keep):
            break
        k0, k1, ks = s0[keep], s1[keep], seg[keep]
        frac = np.linspace(0.0, 1.0, _SPLIT + 1)
        cuts = k0[:, None] + (k1 - k0)[:, None] * frac[None, :]
        s0, s1 = cuts[:, :-1].ravel(), cuts[:, 1:].ravel()
        seg = np.repeat(ks, _SPLIT)
    if first_bad is None:
        return 1.0, None
    at_s, which, undecided = first_bad
    k = min(int(at_s), n - 1)
    q = path[k] + (at_s - k) * (path[k + 1] - path[k])
    sigma = float(margins.at(np.array([at_s]), q[None, :])[0])
    return at_s / n, _refusal(arm, obs, q, which, at_s / n, undecided, sigma)


_NOISE = 1e-9  # m: a clearance may fall by this (the distances' rounding) and still count as not decreasing
_CHUNK = 2048  # poses per round of the way out of a margin


def _pose(path: Array, s: Array) -> Array:
    k = np.minimum(np.floor(s).astype(int), len(path) - 2)
    return np.asarray(path[k] + (s - k)[:, None] * (path[k + 1] - path[k]), dtype=float)


def _samples(rate: Array, tol: float) -> Iterator[Array]:
    """The path parameters ``k + t`` (``t`` in (0, 1]) at most ``tol`` of motion apart, a chunk at a time."""
    for k, r in enumerate(rate):
        m = max(1, math.ceil(float(r) / tol))
        for i in range(0, m, _CHUNK):
            yield k + np.arange(i + 1, min(i + _CHUNK, m) + 1, dtype=float) / m


def _escape(
    arm: Arm, obs: _Obstacles, path: Array, tol: float, margins: _Margins
) -> tuple[float, float, Refusal | None]:
    """The way out of the margins a path starts in (docs/rig.md, "Starting inside a margin").

    Returns the path parameter where every link is ``tol`` clear of every margin (0: the
    start is; ``n``: the whole path is the way out), the last parameter shown good, and the
    refusal (``None``: none). Each (link, obstacle) pair that starts inside its margin must
    not lose clearance (distance minus allowed, σ margin included) until it is out, and
    then stays out; every other pair stays out: checked at poses at most ``tol`` of motion
    apart, so between two of them a clearance falls by at most ``tol`` / 2.
    """
    n = len(path) - 1
    zero = np.zeros(1)
    at0 = margins.at(zero, path[:1])
    c = _link_clearances(arm, obs, path[:1], at0)[0] - at0[0]  # (L, C)
    allowed = np.concatenate((obs.allowed_v, obs.allowed_o))
    dist = c + at0[0] + allowed[None, :]
    hit = ((dist <= obs.contact[None, :]) & (c < 0.0)) | (dist <= _NOISE)  # (inside one kept no distance from too)
    if np.any(hit):
        which = int(np.argmax(np.any(hit, axis=0)))
        r = _refusal(arm, obs, path[0], which, 0.0, False, float(at0[0]))
        return 0.0, 0.0, dataclasses.replace(r, allowed=float(obs.contact[which]), start="volume")
    if np.all(c >= 0.0):
        return 0.0, 0.0, None
    inside = c < 0.0
    best = c.copy()  # each pair's largest clearance so far
    rate = np.abs(np.diff(path, axis=0)) @ np.asarray(arm.reach_radii())
    last = 0.0
    for s in _samples(rate, tol):
        q = _pose(path, s)
        at = margins.at(s, q)
        cs = _link_clearances(arm, obs, q, at) - at[:, None, None]  # (P, L, C)
        before = np.maximum.accumulate(np.concatenate((best[None], cs[:-1])), axis=0)
        floor = np.where(inside[None], np.minimum(before, 0.0) - _NOISE, 0.0)
        bad = np.any(cs < floor, axis=(1, 2))
        out = np.all(cs >= tol, axis=(1, 2))
        i_bad = int(np.argmax(bad)) if np.any(bad) else len(s)
        i_out = int(np.argmax(out)) if np.any(out) else len(s)
        if i_out < i_bad:
            return float(s[i_out]), float(s[i_out]), None
        if i_bad < len(s):
            short = cs[i_bad] - floor[i_bad]
            link, col = np.unravel_index(int(np.argmin(short)), short.shape)
            deeper = bool(inside[link, col])
            r = _refusal(arm, obs, q[i_bad], int(col), float(s[i_bad]) / n, False, float(at[i_bad]))
            prev = float(s[i_bad - 1]) if i_bad else last
            return prev, prev, dataclasses.replace(r, start="margin") if deeper else r
        best = np.maximum(best, cs.max(axis=0))
        last = float(s[-1])
    return float(n), float(n), None


def _check(arm: Arm, obs: _Obstacles, path: Array, tol: float, margins: _Margins,
           pose_only: bool = False) -> tuple[float, Refusal | None]:
    """The fraction of the path shown clear from its start, and the refusal at its first problem.

    A path that starts inside a margin first takes its way out (:func:`_escape`), then the
    rest of it is checked as any other path (``pose_only``: a pose, no way out).
    """
    n = len(path) - 1
    frac, refusal = _search(arm, obs, path, tol, margins)
    if refusal is None or refusal.fraction > 0.0 or pose_only:  # only a start inside a margin stops at 0
        return frac, refusal
    s_out, good, out = _escape(arm, obs, path, tol, margins)
    if out is not None:
        return good / n, out
    if s_out == 0.0:  # the start is clear: the search's refusal stands
        return frac, refusal
    if s_out >= n:
        return 1.0, None
    k1 = math.floor(s_out) + 1
    here = _pose(path, np.array([s_out]))
    rest = np.vstack((here, path[k1:]))
    first = k1 - s_out
    frac, refusal = _search(arm, obs, rest, tol, margins.rest(np.vstack((path[:k1], here)), rest))
    t = frac * (len(rest) - 1)
    whole = (s_out + t * first if t <= 1.0 else k1 + (t - 1.0)) / n
    if refusal is not None:
        refusal = dataclasses.replace(refusal, fraction=whole)
    return whole, refusal


def _refusal(
    arm: Arm, obs: _Obstacles, q: Array, which: int, fraction: float, undecided: bool, sigma: float = 0.0
) -> Refusal:
    segs = arm.segments(q)
    a, b = segs[:, 0, :], segs[:, 1, :]
    nv = len(obs.volumes)
    if which < nv:
        v = obs.volumes[which]
        d, pts = segment_distance(a, b, v)
        name, allowed = v.name, float(obs.allowed_v[which])
    else:
        o = obs.others[which - nv]
        d, u = _seg_seg(a, b, o[0][None, :], o[1][None, :])
        pts = a + u[:, None] * (b - a)
        name, allowed = obs.other_names[which - nv], float(obs.allowed_o[which - nv])
    i = int(np.argmin(d))
    p = pts[i]
    return Refusal(arm.name, name, (float(p[0]), float(p[1]), float(p[2])), float(d[i]), allowed + sigma,
                   (float(q[0]), float(q[1]), float(q[2])), fraction, undecided, _units(arm), sigma)


def _units(arm: Arm) -> tuple[str, str, str]:
    u = [j.unit for j in arm.joints]
    return (u[0], u[1], u[2])


_SWEEP_ROUNDS = 200  # checks of one path against other arms' swept boxes, as they are cut finer
_SWEEP_CELLS = 1000  # boxes at most (a check slows with their links): beyond, the refusal at the coarser bound
# stands (refused: safe). A path starting near a swept set of two joints took 15794 links and 17 s to cut; 2.3 s here
_WITNESSES = 65  # poses of the rest of a path tried against the boxes' centres after a refusal at a bound


def _check_swept(rig: Rig, arm: Arm, cells: list[_Cell], path: Array, tol: float, margins: _Margins,
                 pose_only: bool = False) -> tuple[float, Refusal | None]:
    """:func:`_check` against other arms over boxes of poses (:class:`_Cell`), each box cut until the path is shown
    clear of it or refused: a refusal at a box's bound cuts every box coarser than ``tol`` the refused pose comes
    near, and the path is checked again. One pose per arm: one check.

    A refusal stands when the path comes closer than allowed to a pose of a box (its centre) at or after the
    refused pose (:func:`_witness`: that pose and distance are named, and the fraction returned is the refused
    pose's, where the path is shown clear up to), or within ``tol`` of a box's swept set. Cutting never makes a
    path's first problem come earlier (the cut boxes' bounds lie within the whole box's).
    """
    frac, refusal = 1.0, None
    cells = _cut_at_start(rig, arm, cells, path, tol, margins)
    at_start = _start_in_sweep(rig, arm, cells, path, margins)
    if at_start is not None:
        return 0.0, at_start
    for _ in range(_SWEEP_ROUNDS):
        obs = _obstacles(rig, arm, cells)
        frac, refusal = _check(arm, obs, path, tol, margins, pose_only)
        if refusal is None or refusal.point is None or not any(c.pad > 0.0 for c in cells):
            return frac, refusal
        if not refusal.start:  # (a start in a margin: cut first, the way out is judged against the finer boxes)
            seen = _witness(rig, arm, cells, path, refusal.fraction, margins)
            if seen is not None:
                return frac, seen
        near = _near_cells(arm, obs, cells, refusal, tol)
        if not near or len(cells) + (_SPLIT - 1) * len(near) > _SWEEP_CELLS:
            return frac, refusal
        cells = [c for i, c in enumerate(cells) if i not in near] + [p for i in sorted(near) for p in cells[i].split()]
    return frac, refusal


def _cut_at_start(rig: Rig, arm: Arm, cells: list[_Cell], path: Array, tol: float, margins: _Margins) -> list[_Cell]:
    """``cells`` with every box coarser than ``tol`` whose bound the path's start is inside cut until it is not (one
    pose a round): a start inside the margin of a box's pad only took the way out of a margin (:func:`_escape`,
    poses ``tol`` of motion apart over the whole path) against the coarse box, 62 s for one check. The boxes as
    given if that would need more than ``_SWEEP_CELLS``: the check then goes as before (the same boxes)."""
    q0 = path[:1]
    sigma = float(margins.at(np.zeros(1), q0)[0])
    out = cells
    for _ in range(_SWEEP_ROUNDS):
        obs = _obstacles(rig, arm, out)
        if not len(obs.others):
            return out
        nv = len(obs.volumes)
        c = _link_clearances(arm, obs, q0, np.inf)[0, :, nv:].min(axis=0) - sigma  # exact, pad included in allowed
        inside = {obs.owner[k] for k in np.flatnonzero(c < 0.0) if out[obs.owner[k]].pad > tol}
        if not inside:
            return out
        if len(out) + (_SPLIT - 1) * len(inside) > _SWEEP_CELLS:
            return cells
        out = [cell for i, cell in enumerate(out) if i not in inside] + [
            part for i in sorted(inside) for part in out[i].split()]
    return cells


def _start_in_sweep(rig: Rig, arm: Arm, cells: list[_Cell], path: Array, margins: _Margins) -> Refusal | None:
    """The refusal of a path whose start is already within the allowed distance (σ margin and pad included) of
    another arm's swept set, once :func:`_cut_at_start` has cut the boxes there: no way out of a margin is taken
    from an arm that may be anywhere in its box (wait for its move to end). The way out (:func:`_escape`, poses
    ``tol`` of motion apart) walked against the boxes took minutes (audit55: one check over 400 s) where this
    refuses at once; a start clear of every box goes on to :func:`_check` as before."""
    q0 = path[:1]
    sigma = float(margins.at(np.zeros(1), q0)[0])
    obs = _obstacles(rig, arm, cells)
    if not len(obs.others):
        return None
    nv = len(obs.volumes)
    c = _link_clearances(arm, obs, q0, np.inf)[0, :, nv:].min(axis=0) - sigma
    if not np.any(c < 0.0):
        return None
    refusal = _refusal(arm, obs, path[0], nv + int(np.argmin(c)), 0.0, False, sigma)
    return dataclasses.replace(refusal, start="sweep")


def _witness(rig: Rig, arm: Arm, cells: list[_Cell], path: Array, fraction: float,
             margins: _Margins) -> Refusal | None:
    """The first of ``_WITNESSES`` poses from ``fraction`` of the path to its end closer than allowed (σ margin
    included) to another arm at a box's centre, refused there (``None``: none of them is)."""
    n = len(path) - 1
    s = np.linspace(fraction * n, float(n), _WITNESSES)
    q = _pose(path, s)
    at = margins.at(s, q)
    obs = _obstacles(rig, arm, [_Cell(c.arm, c.centre, c.centre) for c in cells])
    nv = len(obs.volumes)
    c = _link_clearances(arm, obs, q, 0.0)[:, :, nv:].min(axis=1) - at[:, None]  # (poses, other arms' links)
    bad = np.flatnonzero(np.any(c < 0.0, axis=1))
    if not len(bad):
        return None
    i = int(bad[0])
    return _refusal(arm, obs, q[i], nv + int(np.argmin(c[i])), float(s[i]) / n, False, float(at[i]))


def _near_cells(arm: Arm, obs: _Obstacles, cells: list[_Cell], refusal: Refusal, tol: float) -> set[int]:
    """The boxes coarser than ``tol`` to cut at the refused pose: whose bound's clearance there is less than the
    bound itself, or than ``2 tol`` (an undecided stretch, whose σ margin is bounded over the stretch)."""
    if not len(obs.others):
        return set()
    q = np.asarray(refusal.q, dtype=float)[None, :]
    nv = len(obs.volumes)
    c = _link_clearances(arm, obs, q, np.inf)[0, :, nv:].min(axis=0) - refusal.sigma  # exact distances
    pads = np.array([cells[i].pad for i in obs.owner])
    near = c < np.maximum(pads, 2.0 * tol) + _NOISE
    return {obs.owner[k] for k in np.flatnonzero(near) if cells[obs.owner[k]].pad > tol}


def _prepare(
    rig: Rig, arm: str | None, path: ArrayLike, q_sd: ArrayLike | SigmaGrowth, others: Mapping[str, ArrayLike] | None,
    swept: Mapping[str, ArrayLike] | None = None,
) -> tuple[Arm, list[_Cell], Array, _Margins]:
    a = rig.arm(arm)
    p = np.asarray(path, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 1 or not np.all(np.isfinite(p)):
        raise ValueError(f"a path is a list of finite poses (q1 rad, q2 rad, q3 m), got shape {p.shape}")
    if len(p) == 1:
        p = np.vstack((p, p))
    return a, _cells(rig, a, others or {}, swept or {}), p, _Margins.of(a, p, rig.n_sigma, q_sd)


def check_path(
    rig: Rig,
    arm: str | None,
    path: ArrayLike,
    *,
    q_sd: ArrayLike | SigmaGrowth = (0.0, 0.0, 0.0),
    others: Mapping[str, ArrayLike] | None = None,
    swept: Mapping[str, ArrayLike] | None = None,
    tol: float = TOLERANCE,
) -> None:
    """Refuse ``path`` (poses ``(N, 3)`` rad, rad, m, joined by straight joint-space lines) if it leaves the envelope.

    Parameters
    ----------
    rig, arm
        The rig and the moving arm's name (``None``: the first arm).
    q_sd
        The joints' position σ (rad, rad, m) from the Kalman filter, the same all along;
        or :class:`SigmaGrowth`, the σ the filter predicts at each point of the path.
        ``rig.n_sigma`` times the tip's σ where the arm is widens every margin there.
    others
        The other arms' kept poses by name; an arm not given is not checked against.
    swept
        Other arms that may be anywhere over a box of poses (a move in flight, claimed, or
        interrupted), by name: ``(3, 2)``, each joint's (lo, hi), rad or m (a joint that
        stays put: its kept value twice). The path keeps ``arm_distance`` from every pose of
        the box (:class:`_Cell`); it overrides the arm's pose in ``others``.
    tol
        The shortest stretch the path is cut into, m (module docstring).

    Raises
    ------
    EnvelopeViolation
        At the path's first problem: a joint beyond its range or soft limit, a link within a
        volume's margin or too near another arm (the obstacle and closest point named).
    """
    a, cells, p, margins = _prepare(rig, arm, path, q_sd, others, swept)
    limit = _limit_refusal(a, p)
    _, refusal = _check_swept(rig, a, cells, p, tol, margins, pose_only=np.asarray(path).shape[0] == 1)
    if limit is not None and (refusal is None or limit.fraction <= refusal.fraction):
        raise EnvelopeViolation(limit)
    if refusal is not None:
        raise EnvelopeViolation(refusal)


def safe_fraction(
    rig: Rig,
    arm: str | None,
    path: ArrayLike,
    *,
    q_sd: ArrayLike | SigmaGrowth = (0.0, 0.0, 0.0),
    others: Mapping[str, ArrayLike] | None = None,
    swept: Mapping[str, ArrayLike] | None = None,
    tol: float = TOLERANCE,
) -> tuple[float, Refusal | None]:
    """How far along ``path`` (0 to 1) the arm may go, and the refusal that stops it (``None``: all the way).

    What a jog uses to stop at the boundary. The path is clear up to the fraction returned
    (to ``tol``); a path whose start is already outside the envelope gets 0. Joint limits
    are left to the jog (it clamps to them).
    """
    a, cells, p, margins = _prepare(rig, arm, path, q_sd, others, swept)
    return _check_swept(rig, a, cells, p, tol, margins)
