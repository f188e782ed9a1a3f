"""A picture of a rig: its arms at given poses and its volumes, seen from the side (x-z) and from above (x-y)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..plotting import pyplot
from ..records import atomic_write
from .model import Box, Cylinder, HalfSpace, Rig

__all__ = ["draw", "figure"]


def _surface(v: Box | Cylinder) -> np.ndarray:
    """Points on the volume's surface (its corners, or its end circles), m."""
    if isinstance(v, Box):
        h = np.asarray(v.half)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
        return np.asarray(corners @ v.matrix().T + np.asarray(v.centre))
    ax = np.asarray(v.axis)
    u = np.cross(ax, [1.0, 0.0, 0.0] if abs(ax[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(ax, u)
    t = np.linspace(0, 2 * math.pi, 48)
    ring = v.radius * (np.outer(np.cos(t), u) + np.outer(np.sin(t), w))
    base = np.asarray(v.base)
    return np.vstack((base + ring, base + ax * v.height + ring))


def _label_at(p: np.ndarray, d: np.ndarray, n: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[float, float]:
    """Where a half-space's name goes: inside it (nothing may be there), halfway to the view's edge, near the left.

    ``p`` is on its edge line, ``d`` along the line, ``n`` into the half-space (the view's two axes). At ``p``, a
    plane through the origin wrote "sample" on the objective's name; on the line's end, on an arm's.
    """
    a = 0 if abs(d[0]) >= abs(d[1]) else 1
    q = p + (lo[a] + 0.03 * (hi[a] - lo[a]) - p[a]) / d[a] * d
    u = n / np.linalg.norm(n)
    reach = [((hi[b] if u[b] > 0 else lo[b]) - q[b]) / u[b] for b in (0, 1) if abs(u[b]) > 1e-9]
    x, y = q + u * max(0.0, min(reach)) / 2
    return float(x), float(y)


def draw(rig: Rig, poses: Mapping[str, Sequence[float]], path: str | Path) -> None:
    """Draw ``rig`` with each arm at ``poses[name]`` (rad or m) into the PNG ``path`` (mm on the axes)."""
    fig = figure(rig, poses)
    try:
        # whole or not at all, never into a folder or a device (records.atomic_write: every output file)
        atomic_write(path, lambda f: fig.savefig(f, dpi=100, format="png"), mode="wb")
    finally:
        pyplot().close(fig)


def figure(rig: Rig, poses: Mapping[str, Sequence[float]]) -> Any:
    """The matplotlib Figure :func:`draw` saves: the side (x-z) and top (x-y) views, mm."""
    from scipy.spatial import ConvexHull

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10.0, 5.0))
    try:
        pts_all = [np.zeros((1, 3))]
        for a in rig.arms:
            pts_all.append(a.segments(np.asarray(poses[a.name], dtype=float)).reshape(-1, 3))
        for v in rig.volumes:
            if not isinstance(v, HalfSpace):
                pts_all.append(_surface(v))
        everything = np.vstack(pts_all) * 1e3
        lo, hi = everything.min(axis=0) - 5.0, everything.max(axis=0) + 5.0
        for ax, (i, k), title in ((axes[0], (0, 2), "side (x-z)"), (axes[1], (0, 1), "top (x-y)")):
            for v in rig.volumes:
                if isinstance(v, HalfSpace):
                    n, p = np.asarray(v.normal), np.asarray(v.point) * 1e3
                    d = np.array([-n[k], n[i]])
                    if np.linalg.norm(d) < 1e-9:
                        ax.text(p[i], p[k], v.name, fontsize=8)
                        continue
                    d /= np.linalg.norm(d)
                    span = float(np.max(hi - lo))
                    line = np.array([p[[i, k]] - d * span, p[[i, k]] + d * span])
                    ax.plot(line[:, 0], line[:, 1], color="tab:red", lw=1)
                    ax.fill(np.r_[line[:, 0], line[::-1, 0] + n[i] * span],
                            np.r_[line[:, 1], line[::-1, 1] + n[k] * span], color="tab:red", alpha=0.12)
                    at = _label_at(p[[i, k]], d, n[[i, k]], lo[[i, k]], hi[[i, k]])
                    ax.text(*at, v.name, fontsize=8, color="tab:red", va="center")
                    continue
                flat = _surface(v)[:, [i, k]] * 1e3
                hull = ConvexHull(flat, qhull_options="QJ")
                poly = flat[hull.vertices]
                ax.fill(poly[:, 0], poly[:, 1], color="tab:red", alpha=0.3)
                ax.text(*poly.mean(axis=0), v.name, fontsize=8)
            for a in rig.arms:
                segs = a.segments(np.asarray(poses[a.name], dtype=float)) * 1e3
                for s in segs:
                    ax.plot(s[:, i], s[:, k], color="tab:blue", lw=2)
                tip = segs[-1, 1]
                ax.plot(tip[i], tip[k], "o", color="tab:blue", ms=3)
                ax.text(segs[0, 0, i], segs[0, 0, k], a.name, fontsize=8, color="tab:blue")
            ax.set_xlim(lo[i], hi[i])
            ax.set_ylim(lo[k], hi[k])
            ax.set_aspect("equal")
            ax.set_xlabel(f"{'xyz'[i]} (mm)")
            ax.set_ylabel(f"{'xyz'[k]} (mm)")
            ax.set_title(title)
        fig.suptitle(f"rig {rig.name}")
        fig.tight_layout()
    except BaseException:
        plt.close(fig)
        raise
    return fig
