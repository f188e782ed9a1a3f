"""Core benchmark: planning latency, traverse-average methods, exact vs Eq. 9 inversion.

Everything is measured side by side in one run and printed as ratios, so the table
means the same on a slow or a fast machine.

Run: ``.venv/bin/python benchmarks/bench_core.py`` (about 20 s on 2 cores).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "support"))

from synth import paper_table  # noqa: E402

from stickslip.calibration import calibrate, fit_paper_quadratic, invert_d_exact  # noqa: E402
from stickslip.kinematics import JOINTS, Pose  # noqa: E402
from stickslip.models import simulate_traverse_steps, steps_between, steps_between_quad  # noqa: E402
from stickslip.motion.planning import Planner, plan_move  # noqa: E402


def per_call(fn, n: int) -> float:
    """Median seconds per call over 5 repeats of n calls."""
    times = []
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(n):
            fn()
        times.append((time.perf_counter() - t) / n)
    return float(np.median(times))


def main() -> None:
    cal = calibrate(paper_table())
    pose = Pose(q3=0.006, theta=-0.3)
    planner = Planner(cal, 2, pose)
    lo, hi = JOINTS[2].lower, JOINTS[2].upper

    print("planning latency (joint 2, exact integral, one move of 110 deg)")
    rows = [
        ("Planner.steps (precomputed pose)", per_call(lambda: planner.steps(0.17, -1.75), 20000)),
        ("Planner.plan (steps + dead reckoning)", per_call(lambda: planner.plan(0.17, -1.75), 5000)),
        ("plan_move (one call, new pose)", per_call(lambda: plan_move(cal, 2, 0.17, -1.75, pose), 2000)),
    ]
    base = rows[0][1]
    print(f"  {'method':42s} {'µs/move':>9s} {'ratio':>7s} {'moves per 1 ms tick':>20s}")
    for name, t in rows:
        print(f"  {name:42s} {t * 1e6:9.2f} {t / base:7.1f} {1e-3 / t:20.0f}")

    print("\naverage step over joint 2's full range: three ways to the same number")
    m = cal.model(2, "-")
    A, al, be = (float(x) for x in m.rotary_coefficients(0, 0, 0.012, 0, 0))
    exact = float(steps_between(hi, lo, A, al, be))
    quad = steps_between_quad(hi, lo, A, al, be)
    t_exact = per_call(lambda: steps_between(hi, lo, A, al, be), 2000)
    t_quad = per_call(lambda: steps_between_quad(hi, lo, A, al, be), 200)
    t0 = time.perf_counter()
    n_sim = simulate_traverse_steps(hi, lo, lambda q: A + al * math.cos(q) + be * math.sin(q))
    t_sim = time.perf_counter() - t0
    print(f"  {'method':34s} {'steps':>14s} {'rel. diff':>10s} {'µs/call':>11s} {'ratio':>9s}")
    for name, val, t in (("closed form (atan)", exact, t_exact), ("adaptive quadrature (1e-12)", quad, t_quad),
                         ("step-by-step simulation", float(n_sim), t_sim)):
        print(f"  {name:34s} {val:14.4f} {val / exact - 1:10.1e} {t * 1e6:11.1f} {t / t_exact:9.0f}")
    v = np.linspace(hi, lo, 1000)
    t_vec = per_call(lambda: steps_between(hi, v, A, al, be), 200)
    print(f"  closed form, 1000 traverses vectorised: {t_vec / 1000 * 1e6:.2f} µs each "
          f"({t_exact / (t_vec / 1000):.0f}x the single call)")

    print("\nrotary calibration: exact inversion vs the paper's Eq. 9 method (simulate grid, fit quadratic)")
    t0 = time.perf_counter()
    quad_steps = fit_paper_quadratic(simulate="steps")
    t_fit_steps = time.perf_counter() - t0
    t0 = time.perf_counter()
    quad_exact = fit_paper_quadratic(simulate="exact")
    t_fit_exact = time.perf_counter() - t0
    p2, p1, p0 = quad_steps.coefficients
    print(f"  our Eq. 9 refit (step simulation, {t_fit_steps:.1f} s; exact-integral grid {t_fit_exact * 1e3:.0f} ms): "
          f"d = {p2 * 1e-6:.4f}/µrad·Δ² + {p1:.4f}·Δ + {p0 * 1e6:.4f} µrad")
    dp1 = quad_exact.coefficients[1] / p1 - 1
    print(f"  (grid from the exact integral instead: linear coefficient differs by {dp1:.1e} relative)")
    print("  printed Eq. 9: d = 3.41 Δ² + 0.025 Δ + 6.42e-7 (gives d < 1 µrad at Δ = 9.2 µrad; Fig. 10 has 24)")
    print(f"  {'gamma0':>8s} {'Δ':>7s} {'d exact':>9s} {'d Eq.9 fit':>11s} {'error':>8s}   (µrad)")
    errs, t_inv = [], []
    for g0 in (30e-6, 45e-6, 60e-6, 100e-6):
        for delta in (-9.2e-6, -4e-6, 2e-6, 6e-6, 9.2e-6):
            t0 = time.perf_counter()
            try:
                d = invert_d_exact(g0 + delta, g0, hi, lo, 0.0, -1.0)
            except ValueError:
                continue
            t_inv.append(time.perf_counter() - t0)
            dq = float(quad_steps.d(delta))
            errs.append(abs(dq - d))
            print(f"  {g0 * 1e6:8.0f} {delta * 1e6:7.1f} {d * 1e6:9.3f} {dq * 1e6:11.3f} {(dq - d) * 1e6:8.3f}")
    print(f"  max |error| of the Eq. 9 method: {max(errs) * 1e6:.2f} µrad; exact inversion: "
          f"{np.median(t_inv) * 1e3:.1f} ms per d (bracketed root find, < 1e-6 µrad)")


if __name__ == "__main__":
    main()
