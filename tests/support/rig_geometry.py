"""An independent geometric check of the safety envelope (tests only).

Written from the definitions, not from ``stickslip.rig.envelope``: the arm's links from
the forward kinematics of docs/design.md §9 and docs/rig.md (an MM3A: joint 1's axis,
an elbow at ``offset`` along the turned x axis, the tip at ``length + q3`` along
``(-sin q2, 0, cos q2)`` turned by ``q1``; an xyz stack: the holder at ``sum q_i a_i``,
the tip at holder + tool), then *point* distances to each volume computed the obvious
way (the nearest point of a box by clamping in its own frame, of a cylinder by clamping
the axial and radial parts, of a half-space by projection). A path is sampled densely
(poses and points along each link): the smallest sampled clearance bounds the true one
from above.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def rot(angles: tuple[float, float, float]) -> Array:
    """The rotation about x by a, then y by b, then z by c (docs/rig.md)."""
    a, b, c = angles
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return np.asarray(rz @ ry @ rx, dtype=float)


def links(arm: Any, q: Array) -> list[tuple[Array, Array]]:
    """The arm's link segments at one pose ``q``, rig frame, m."""
    r = rot(arm.mount.rotation)
    o = np.asarray(arm.mount.origin, dtype=float)
    if arm.kind == "mm3a":
        off, length = arm.geometry.offset, arm.geometry.length
        q1, q2, q3 = (float(v) for v in q)
        turn = np.array([[math.cos(q1), -math.sin(q1), 0.0], [math.sin(q1), math.cos(q1), 0.0], [0.0, 0.0, 1.0]])
        elbow = turn @ np.array([off, 0.0, 0.0])
        tip = turn @ (np.array([off, 0.0, 0.0]) + (length + q3) * np.array([-math.sin(q2), 0.0, math.cos(q2)]))
        pts = [np.zeros(3), elbow, tip]
        return [(r @ pts[i] + o, r @ pts[i + 1] + o) for i in range(2)]
    holder = sum(float(q[i]) * np.asarray(arm.axes[i], dtype=float) for i in range(3))
    tip = holder + np.asarray(arm.tool, dtype=float)
    return [(r @ holder + o, r @ tip + o)]


def point_distance(p: Array, v: Any) -> Array:
    """Distance of points ``p`` ``(N, 3)`` from volume ``v`` (0 inside), m."""
    if v.shape == "half-space":
        n = np.asarray(v.normal)
        return np.asarray(np.maximum((np.asarray(v.point) - p) @ n, 0.0), dtype=float)
    if v.shape == "box":
        local = (p - np.asarray(v.centre)) @ np.asarray(v.rotation).reshape(3, 3)
        half = np.asarray(v.half)
        nearest = np.clip(local, -half, half)
        return np.asarray(np.linalg.norm(local - nearest, axis=1), dtype=float)
    ax = np.asarray(v.axis)
    rel = p - np.asarray(v.base)
    z = rel @ ax
    radial = rel - np.outer(z, ax)
    rho = np.linalg.norm(radial, axis=1)
    zc = np.clip(z, 0.0, v.height)
    scale = np.where(rho > v.radius, v.radius / np.maximum(rho, 1e-300), 1.0)
    nearest = np.outer(zc, ax) + radial * scale[:, None]
    return np.asarray(np.linalg.norm(rel - nearest, axis=1), dtype=float)


def point_segment(p: Array, a: Array, b: Array) -> Array:
    """Distance of points ``p`` from the segment ab, m."""
    d = b - a
    t = np.clip(((p - a) @ d) / max(float(d @ d), 1e-300), 0.0, 1.0)
    return np.asarray(np.linalg.norm(p - (a + np.outer(t, d)), axis=1), dtype=float)


def dense_clearance(rig: Any, arm: Any, path: Array, margin_extra: float = 0.0,
                    poses_per_segment: int = 200, points_per_link: int = 200) -> tuple[float, str]:
    """The smallest sampled clearance (distance minus allowed, m) of ``arm`` along ``path``, and its volume."""
    best, name = math.inf, ""
    u = np.linspace(0.0, 1.0, points_per_link)[:, None]
    for k in range(len(path) - 1):
        for t in np.linspace(0.0, 1.0, poses_per_segment):
            q = path[k] + t * (path[k + 1] - path[k])
            pts = np.vstack([a + u * (b - a) for a, b in links(arm, q)])
            for v in rig.volumes:
                c = float(np.min(point_distance(pts, v))) - (v.margin + arm.radius + margin_extra)
                if c < best:
                    best, name = c, v.name
    return best, name


def link_distance(a: Array, b: Array, v: Any, points: int = 64, rounds: int = 60) -> float:
    """Distance of the segment ab from volume ``v``, m: the distance along a segment from a convex set is
    convex, so the best of ``points`` samples is refined by ternary search between its neighbours."""
    t = np.linspace(0.0, 1.0, points)
    d = point_distance(a + np.outer(t, b - a), v)
    i = int(np.argmin(d))
    lo, hi = t[max(i - 1, 0)], t[min(i + 1, points - 1)]
    for _ in range(rounds):
        m1, m2 = lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0
        f = point_distance(np.vstack((a + m1 * (b - a), a + m2 * (b - a))), v)
        lo, hi = (lo, m2) if f[0] <= f[1] else (m1, hi)
    return float(min(float(np.min(d)), float(point_distance((a + (lo + hi) / 2.0 * (b - a))[None, :], v)[0])))


def pair_clearances(rig: Any, arm: Any, path: Array, poses_per_segment: int) -> Array:
    """Each (link, volume) pair's clearance (distance minus margin and radius, m) at poses sampled evenly along
    ``path``: ``(poses, links, volumes)``."""
    out = []
    for k in range(len(path) - 1):
        for t in np.linspace(0.0, 1.0, poses_per_segment, endpoint=k == len(path) - 2):
            q = path[k] + t * (path[k + 1] - path[k])
            out.append([[link_distance(a, b, v) - v.margin - arm.radius for v in rig.volumes]
                        for a, b in links(arm, q)])
    return np.asarray(out, dtype=float)
