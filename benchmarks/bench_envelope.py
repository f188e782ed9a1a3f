"""The safety envelope: a 1000-segment path against 20 volumes and 2 other arms (issue 32: <= 5 ms).

A rig of three arms (two MM3As and an xyz stack, ``stickslip.rig``) with 20 keep-out
volumes (8 boxes, 6 cylinders, 6 half-spaces) placed at random around the work area,
none touching the path, so the whole path has to be shown clear (the slowest case: a
refused path stops at its first problem). The moving MM3A follows a random walk in
joint space of 1000 segments (each joint by up to ±0.2° or ±5 µm per segment, about
what a reach's segments are). Printed: the median time of ``check_path`` over repeats,
its ratio to the 5 ms budget, and, side by side in the same run, a naive check (the
links sampled at 50 points at 10 poses per segment, point distances only, which does not
prove the stretches between samples clear) for scale.

Also, side by side: the same check with the σ margin grown along the path
(:class:`~stickslip.rig.envelope.SigmaGrowth`, today's calibration: a 1 % step-scale σ;
over the random walk's back-and-forth the + and - scales' difference piles up to a
margin of about a millimetre), timed with ``safe_fraction``, which also prints how far
along the path it is clear.
Each row: the median and fastest wall-clock time and the median CPU time per check.

Run: ``.venv/bin/python benchmarks/bench_envelope.py [REPEATS]`` (default 30; seconds).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable

import numpy as np

from stickslip.kinematics import Geometry
from stickslip.rig import Arm, Box, Cylinder, HalfSpace, Joint, Mount, Rig, check_path
from stickslip.rig.envelope import SigmaGrowth, _box_sq, _cyl_dist, safe_fraction, segment_distance

BUDGET = 5e-3


def make_rig(seed: int = 0) -> tuple[Rig, np.ndarray, dict[str, list[float]]]:
    rng = np.random.default_rng(seed)
    mm3a = (Joint(1, 1, 1, "rotary", -2.09, 2.09), Joint(2, 2, 1, "rotary", -3.66, 0.52),
            Joint(3, 3, 1, "prismatic", 0.0, 0.012))
    xyz = tuple(Joint(i, i, 1, "prismatic", -0.01, 0.01) for i in (1, 2, 3))
    arms = (
        Arm("a", "mm3a", "sim://", mm3a, Mount((-0.03, 0.0, 0.0)), Geometry(0.0, 0.021), radius=5e-4),
        Arm("b", "mm3a", "sim://?seed=2", mm3a, Mount((0.03, 0.0, 0.0), (0.0, 0.0, math.pi)), Geometry(0.0, 0.021),
            radius=5e-4),
        Arm("c", "xyz", "sim://?seed=3", xyz, Mount((0.0, 0.03, 0.0)), tool=(0.0, 0.0, -0.01),  # type: ignore[arg-type]
            radius=3e-4),
    )
    q0 = np.array([0.0, -math.pi / 2 + 0.3, 0.004])
    steps = rng.uniform(-1, 1, size=(1000, 3)) * np.array([math.radians(0.2), math.radians(0.2), 5e-6])
    path = q0 + np.vstack((np.zeros(3), np.cumsum(steps, axis=0)))
    path[:, 2] = np.clip(path[:, 2], 0.0, 0.012)
    swept = arms[0].segments(path).reshape(-1, 3)
    lo, hi = swept.min(axis=0), swept.max(axis=0)
    volumes: list[Box | Cylinder | HalfSpace] = []
    while len(volumes) < 20:
        i = len(volumes)
        c = rng.uniform(-0.05, 0.05, size=3)
        size = rng.uniform(0.002, 0.01)
        if i < 8:
            v: Box | Cylinder | HalfSpace = Box(f"box{i}", tuple(c), (size, size / 2, size), 2e-4)  # type: ignore[arg-type]
        elif i < 14:
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            v = Cylinder(f"cyl{i}", tuple(c), tuple(axis), size / 2, size * 2, 2e-4)  # type: ignore[arg-type]
        else:
            n = rng.normal(size=3)
            n /= np.linalg.norm(n)
            far = max(float(np.max(swept @ n)), 0.0) + rng.uniform(0.001, 0.01)
            v = HalfSpace(f"half{i}", tuple(n * far), tuple(n), 2e-4)  # type: ignore[arg-type]
        if not isinstance(v, HalfSpace) and np.all(c > lo - 0.012) and np.all(c < hi + 0.012):
            continue
        d, _ = segment_distance(arms[0].segments(path)[..., 0, :], arms[0].segments(path)[..., 1, :], v)
        if float(np.min(d)) > 1e-3:
            volumes.append(v)
    rig = Rig("bench", "bench", arms, tuple(volumes), arm_distance=1e-3)
    others = {"b": [0.0, -math.pi / 2, 0.0], "c": [0.0, 0.0, 0.0]}
    return rig, path, others


def naive(rig: Rig, path: np.ndarray) -> float:
    arm = rig.arms[0]
    t = np.linspace(0, 1, 5, endpoint=False)
    q = (path[:-1, None, :] + t[None, :, None] * np.diff(path, axis=0)[:, None, :]).reshape(-1, 3)
    segs = arm.segments(q)
    u = np.linspace(0, 1, 20)
    pts = (segs[..., 0, None, :] + u[:, None] * (segs[..., 1, None, :] - segs[..., 0, None, :])).reshape(-1, 3)
    best = math.inf
    for v in rig.volumes:
        if isinstance(v, HalfSpace):
            d = np.maximum((np.asarray(v.point) - pts) @ np.asarray(v.normal), 0.0)
        elif isinstance(v, Cylinder):
            d = _cyl_dist(pts, v)
        else:
            d = np.sqrt(_box_sq((pts - np.asarray(v.centre)) @ v.matrix(), np.asarray(v.half)))
        best = min(best, float(np.min(d)))
    return best


def growth() -> SigmaGrowth:
    """A σ that grows along the path as the Kalman filter predicts (today's calibration: a 1 % scale σ)."""
    var, c = 0.01**2, 0.5 * 0.01**2
    P = tuple(((sd**2, 0.0, 0.0), (0.0, var, c), (0.0, c, var)) for sd in (1e-5, 1e-5, 1e-7))
    return SigmaGrowth(P, (40e-6, 40e-6, 0.8e-6), 0.03, 1e-4, (0.01, 0.01, 0.01), 0.5)


def timed(f: Callable[[], object], repeats: int) -> tuple[float, float, float]:
    """Median and fastest wall-clock time, and CPU time per call, s."""
    wall, cpu = [], []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        f()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return float(np.median(wall)), float(np.min(wall)), float(np.median(cpu))


def main(repeats: int = 30) -> None:
    rig, path, others = make_rig()
    small = growth()
    check_path(rig, "a", path, others=others, q_sd=(1e-5, 1e-5, 1e-7))  # warm up; raises if the path is refused
    rows = [
        ("check_path, σ fixed", timed(lambda: check_path(rig, "a", path, others=others, q_sd=(1e-5, 1e-5, 1e-7)),
                                      repeats)),
        ("check_path, σ grown", timed(lambda: safe_fraction(rig, "a", path, others=others, q_sd=small), repeats)),
        ("naive sampling (no proof)", timed(lambda: naive(rig, path), 3)),
    ]
    print(f"path of {len(path) - 1} segments, {len(rig.volumes)} volumes, 2 other arms, {repeats} repeats")
    print(f"{'check':<28}{'median ms':>10}{'min ms':>8}{'cpu ms':>8}{'/ budget':>10}")
    for name, (med, low, cpu) in rows:
        print(f"{name:<28}{med * 1e3:>10.2f}{low * 1e3:>8.2f}{cpu * 1e3:>8.2f}{med / BUDGET:>10.2f}")
    med = rows[0][1][0]
    print(f"σ grown: clear {safe_fraction(rig, 'a', path, others=others, q_sd=small)[0]:.0%} of the path")
    print(f"grown / fixed: {rows[1][1][0] / med:.2f}; check_path / naive: {med / rows[2][1][0]:.4f}; "
          f"budget 5 ms: {'met' if med <= BUDGET else 'NOT met'} (median, σ fixed)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 30)
