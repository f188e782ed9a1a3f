"""Straight tip moves on the simulator: the calibrated model against constant step sizes.

The simulated MM3A (``sim://?seed=1``, its per-step noise, ripple and day drift) is
calibrated the way a user would do it: full-range traverses of joints 1, 2 and 3 at
the paper's poses (joint 1 with the roles of theta = 0 and -pi/2 interchanged),
counted with the oracle limit switch, then ``stickslip.calibration.calibrate``. Then,
for random straight moves of 5–500 µm (log-uniform) in random directions at random
poses (q1 in ±57°, q2 between -163° and -17°, q3 in 1–11 mm, theta in [-90°, 0],
psi in ±30°), ``plan_reach`` plans the move with the calibrated models and with the
constant step sizes (the paper's comparator); each plan is sent to the simulator one
step at a time and the true tip is read after every step. Printed: the tip's distance
from the target at the end and its largest distance from the straight line, as a
fraction of the move's length and in µm, by range of move length.

Run: ``.venv/bin/python benchmarks/bench_reach.py [MOVES]`` (default 120 moves; about
a minute on 2 cores).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from stickslip import kinematics as kin
from stickslip.calibration import Calibration, calibrate
from stickslip.motion.reach import ReachPlan, line_distance, plan_reach
from stickslip.procedures.traverse import measure_traverse
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.oracle import OracleStopDetector

DAY = "2026-11-22"
P = math.pi
CAL_POSES = [
    (3, {"q1": 0.0, "q2": -P / 2, "theta": 0.0, "psi": 0.0}),
    (3, {"q1": 0.0, "q2": 0.0, "theta": -P / 2, "psi": 0.0}),
    (3, {"q1": 0.0, "q2": 0.0, "theta": 0.0, "psi": 0.0}),
    (2, {"q1": 0.0, "q3": 0.0, "theta": 0.0, "psi": 0.0}),
    (2, {"q1": 0.0, "q3": 0.012, "theta": 0.0, "psi": 0.0}),
    (2, {"q1": 0.0, "q3": 0.012, "theta": -P / 2, "psi": 0.0}),
    (2, {"q1": 0.0, "q3": 0.0, "theta": -P / 2, "psi": 0.0}),
    (1, {"q2": -P / 2, "q3": 0.0, "theta": 0.0, "psi": 0.0}),
    (1, {"q2": -P / 2, "q3": 0.012, "theta": 0.0, "psi": 0.0}),
    (1, {"q2": -P / 2, "q3": 0.012, "theta": -P / 2, "psi": 0.0}),
    (1, {"q2": -P / 2, "q3": 0.0, "theta": -P / 2, "psi": 0.0}),
]
BINS = ((5e-6, 20e-6), (20e-6, 100e-6), (100e-6, 500e-6), (5e-6, 500e-6))


def calibrate_on(sim: SimulatedMM3A) -> Calibration:
    """Traverses at the calibration poses with the oracle limit switch, then calibrate."""
    mic = sim.microphone(silent=True)
    detectors = {j: OracleStopDetector(sim, j, delay_s=0.03) for j in (1, 2, 3)}
    rows = []
    for joint, pose in CAL_POSES:
        spec = kin.JOINTS[joint]
        for direction in ("+", "-"):
            if direction == "+":
                sim.set_pose(**{**pose, f"q{joint}": spec.lower})  # type: ignore[arg-type]
            r = measure_traverse(
                sim, joint, direction, detector=detectors[joint], audio_blocks=mic, pose=sim.pose, day=DAY
            )
            rows.append(r.traverse)
    return calibrate(rows)


def run_on_sim(sim: SimulatedMM3A, plan: ReachPlan) -> np.ndarray:
    """Send the plan one step at a time; the true tip after every step, ``(n, 3)`` m."""
    sim.set_pose(*plan.q_start, plan.theta, plan.psi)
    tips = [kin.tip(plan.q_start, plan.geometry)]
    for seg in plan.segments:
        for j, n in zip((1, 2, 3), seg.steps, strict=True):
            for _ in range(abs(n)):
                sim.step(j, 1 if n > 0 else -1)
                tips.append(kin.tip([sim.position(1), sim.position(2), sim.position(3)], plan.geometry))
    return np.array(tips)


def main() -> None:
    moves = int(sys.argv[1]) if len(sys.argv) > 1 and sys.argv[1].isdigit() else 120
    sim = SimulatedMM3A(seed=1, day=DAY)
    t = time.perf_counter()
    cal = calibrate_on(sim)
    print(f"calibrated from {2 * len(CAL_POSES)} simulated traverses in {time.perf_counter() - t:.1f} s")
    rng = np.random.default_rng(2026)
    rows = []
    t = time.perf_counter()
    for _ in range(moves):
        pose = kin.Pose(
            rng.uniform(-1.0, 1.0),
            rng.uniform(-P + 0.3, -0.3),
            rng.uniform(0.001, 0.011),
            rng.uniform(-P / 2, 0.0),
            rng.uniform(-P / 6, P / 6),
        )
        length = math.exp(rng.uniform(math.log(5e-6), math.log(500e-6)))
        v = rng.normal(size=3)
        by = v * length / np.linalg.norm(v)
        row = [length]
        for model in ("calibrated", "constant"):
            plan = plan_reach(cal, pose, by=by, step_model=model)
            tips = run_on_sim(sim, plan)
            row += [
                float(np.linalg.norm(tips[-1] - np.array(plan.target))),
                float(line_distance(tips, plan.tip_start, plan.target).max()),
            ]
        rows.append(row)
    print(f"{moves} moves x 2 plans executed step by step in {time.perf_counter() - t:.1f} s\n")
    a = np.array(rows)
    print(
        "| moves | steps from | end error, median / 95 % / max | largest distance from the line, median / 95 % / max |"
    )
    print("| --- | --- | --- | --- |")
    for lo, hi in BINS:
        sel = a[(a[:, 0] >= lo) & (a[:, 0] <= hi)]
        if not len(sel):
            continue
        label = f"{lo * 1e6:.0f}–{hi * 1e6:.0f} µm (n = {len(sel)})"
        for name, col in (("model", 1), ("constant", 3)):
            end, dev = sel[:, col] / sel[:, 0], sel[:, col + 1] / sel[:, 0]
            cells = [" / ".join(f"{np.percentile(x, p):.1%}" for p in (50, 95, 100)) for x in (end, dev)]
            um = f" ({np.median(sel[:, col]) * 1e6:.2f} µm median end error)"
            print(f"| {label} | {name} | {cells[0]}{um} | {cells[1]} |")


if __name__ == "__main__":
    main()
