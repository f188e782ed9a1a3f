"""Simulated MM3A benchmark: how fast the virtual arm steps and how fast a traverse runs.

Measured in one run and printed as a table:

* moving steps simulated per second by ``SimulatedMM3A.step`` (bursts back and forth
  about mid-range, prismatic joint 3 and rotary joint 2, whose step depends on its
  position);
* full-range traverses with :func:`stickslip.procedures.traverse.measure_traverse`: wall time
  against the time on the simulator's virtual clock, with the limit switch
  (a) the tuned audio detector on the rendered virtual microphone, listening all the
  way, (b) the same listening only after 80 % of the predicted count (what the demo
  does) and (c) the oracle switch with a silent microphone (physics and bookkeeping
  only);
* the whole ``stickslip demo`` story (``run_demo``), wall time and device time.

Run: ``.venv/bin/python benchmarks/bench_sim.py`` (about a minute on 2 cores).
"""

from __future__ import annotations

import math
import time

from stickslip import kinematics as kin
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.oracle import OracleStopDetector

DAY = "2026-11-22"


def _steps_per_second(joint: int, burst: int, total: int = 1_000_000) -> float:
    """Moving steps per second: bursts either way from mid-range (no stop reached)."""
    sim = SimulatedMM3A(seed=0, day=DAY)
    spec = kin.JOINTS[joint]
    middle = {"q3": 0.006, f"q{joint}": spec.lower + 0.5 * spec.span}
    sign, done, stops = 1, 0, 0
    t = time.perf_counter()
    while done < total:
        sim.set_pose(**middle)  # back to mid-range (+ and - steps differ, so it drifts)
        sim.step(joint, sign * burst)
        done += burst
        sign = -sign
        stops += sim.at_stop(joint) is not None
    el = time.perf_counter() - t
    assert stops == 0
    return done / el


def _traverse(joint: int, switch: str, listen_fraction: float) -> tuple[float, float, int]:
    from stickslip.procedures.traverse import measure_traverse

    sim = SimulatedMM3A(seed=1, day=DAY)
    sim.set_pose(q2=-math.pi / 2, q3=0.0, theta=0.0, psi=0.0)
    if switch == "audio":
        from stickslip.audio.detector import detector_for
        from stickslip.audio.tuning import tune

        samples, rate, stop_at = sim.labelled_recording(joint, "+")
        detector = detector_for(tune(samples, rate, stop_at, joint=joint))
        mic = sim.microphone()
    else:
        detector = OracleStopDetector(sim, joint, delay_s=0.02)
        mic = sim.microphone(silent=True)
    spec = kin.JOINTS[joint]
    model = sim.true_models()[(joint, "+")]
    sim.set_pose(**{f"q{joint}": spec.lower})
    expected = spec.span / float(model.average_gamma(spec.lower, spec.upper, *sim.pose))
    t = time.perf_counter()
    r = measure_traverse(
        sim,
        joint,
        "+",
        detector=detector,
        audio_blocks=mic,
        pose=sim.pose,
        day=DAY,
        burst_steps=1000,
        listen_after_steps=int(listen_fraction * expected),
    )
    return time.perf_counter() - t, r.elapsed_device_s, r.steps


def main() -> None:
    rows: list[tuple[str, str]] = []
    for joint, bursts in ((3, (1000, 4000)), (2, (1000, 30_000))):
        for burst in bursts:
            sps = _steps_per_second(joint, burst)
            rows.append((f"sim.step joint {joint}, bursts of {burst}", f"{sps / 1e6:.2f} M steps/s"))
    for joint in (3, 2):
        for switch, frac, label in (
            ("audio", 0.0, "audio, listening all along"),
            ("audio", 0.8, "audio, listening after 80 %"),
            ("oracle", 0.0, "oracle switch, silent mic"),
        ):
            wall, device, steps = _traverse(joint, switch, frac)
            rows.append(
                (
                    f"traverse joint {joint} +, {label}",
                    f"{wall:.2f} s wall for {device:.1f} s device ({steps} steps, x{device / wall:.0f} real time)",
                )
            )
    from stickslip.procedures.demo import run_demo

    t = time.perf_counter()
    res = run_demo(seed=0, day=DAY, out=None)
    wall = time.perf_counter() - t
    rows.append(
        (
            "stickslip demo (14 + 16 traverses, audio)",
            f"{wall:.1f} s wall for {res.device_s:.0f} s device ({res.steps_simulated} steps)",
        )
    )
    width = max(len(a) for a, _ in rows)
    print(f"{'benchmark':<{width}}  result")
    print(f"{'-' * width}  {'-' * 60}")
    for a, b in rows:
        print(f"{a:<{width}}  {b}")


if __name__ == "__main__":
    main()
