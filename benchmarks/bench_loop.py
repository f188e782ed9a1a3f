"""The closed loop on the simulator: ``reach``/``move`` with the camera against the open-loop move.

The arm is ``sim://?seed=4&day=2026-11-22``; the calibration is its true models (as in
tests/test_reach.py) with every step divided by ``OFF`` and dated the day before: the
day's steps are ``OFF`` times the calibrated ones (1.2 and 0.8: 20 % off either way).
Each scenario runs twice from the same start, each in its own database: open loop
(:func:`stickslip.procedures.reach.reach` / ``move``) and closed loop with a camera
(:func:`stickslip.procedures.closed_loop.reach_seen` / ``move_seen``), the tip given
as the user would (the simulator's true tip in the first frame). Printed per scenario:
the true tip's miss of the open-loop move (µm and % of the move), and for the closed
loop whether it reached the tolerance, the corrections (legs after the dead reckoning
had reached the target), the legs looked at, the true tip's miss (µm) and the time
per leg (a rendered 512 x 512 frame, the tracker, the journal writes).

Cameras: ``simcam://`` (the simulated microscope, optical and SEM, several substrate
seeds) and ``peercam://`` (tests/support/loop_peer.py: another renderer through
another projection).

The tilted rows (``tilt=30``: the peer microscope leaning 30 deg about the world's y
axis) run the loop twice: with the kinematic straight-down Jacobian (``kin``) and with
the image Jacobian ``camera calibrate`` measured at the start pose (``jac``: joints 3
and 1, up to 200 steps each way, scaled by the day's true steps), side by side.

Run: ``.venv/bin/python benchmarks/bench_loop.py`` (about a minute and a half on 2 cores).
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import tempfile
import textwrap
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "support"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import loop_peer  # noqa: E402

from stickslip import kinematics as kin  # noqa: E402
from stickslip.calibration import Calibration  # noqa: E402
from stickslip.devices.base import open_device  # noqa: E402
from stickslip.motion.tracking import scaled_calibration  # noqa: E402
from stickslip.procedures.camera import calibrate_camera  # noqa: E402
from stickslip.procedures.closed_loop import CameraLoop, move_seen, reach_seen  # noqa: E402
from stickslip.procedures.move import MoveRequest, move  # noqa: E402
from stickslip.procedures.reach import ReachRequest, reach  # noqa: E402
from stickslip.sim.arm import SimulatedMM3A  # noqa: E402
from stickslip.storage import Store  # noqa: E402
from stickslip.vision.camera import open_camera  # noqa: E402
from stickslip.vision.jacobian import MeasuredJacobian, measured_jacobian  # noqa: E402

DAY = "2026-11-22"
DEV = f"sim://?seed=4&day={DAY}"

SCENARIOS: list[tuple[str, float, str, tuple[float, float, float] | float]] = [
    # (camera, OFF, kind, by): reach by (x, y, z) m, or move joint 3 by m
    ("simcam://?pixel=1um", 1.2, "reach", (0.0, -200e-6, 0.0)),
    ("simcam://?pixel=1um", 0.8, "reach", (0.0, -200e-6, 0.0)),
    ("simcam://?pixel=1um&seed=1", 1.2, "reach", (0.0, 200e-6, 0.0)),
    ("simcam://?pixel=1um&seed=2&look=sem", 1.2, "reach", (0.0, -200e-6, 0.0)),
    ("simcam://?pixel=1um", 1.2, "reach", (0.0, 200e-6, 0.0)),
    ("simcam://?pixel=1um", 1.2, "move", 150e-6),
    ("simcam://?pixel=0.5um", 0.8, "move", 80e-6),
    ("peercam://?pixel=1um&size=512x512", 1.2, "reach", (0.0, -200e-6, 0.0)),
    ("peercam://?pixel=1um&size=512x512&look=sem", 0.8, "move", 150e-6),
]

TILTED: list[tuple[str, float, str, tuple[float, float, float] | float]] = [
    ("peercam://?pixel=1um&size=512x512&tilt=30", 1.2, "move", 150e-6),
    ("peercam://?pixel=1um&size=512x512&tilt=30", 1.2, "reach", (0.0, -200e-6, 0.0)),
]


STOPS: list[str] = []
"""Why the loops that stopped short stopped (printed under the table)."""


def _full(joint: int, direction: str) -> tuple[float, float]:
    spec = kin.JOINTS[joint]
    return (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)


def calibration(off: float) -> Calibration:
    """The simulator's true models, steps divided by ``off``, dated the day before."""
    models = SimulatedMM3A(seed=4, day=DAY).true_models()
    cal = Calibration(
        models=models, stderr=dict.fromkeys(models),
        constant_steps={k: float(m.average_gamma(*_full(*k), *kin.Pose())) for k, m in models.items()},
        day=DAY, method="paper",
    )
    for j in (1, 2, 3):
        cal = scaled_calibration(cal, j, 1.0 / off)
    return dataclasses.replace(cal, day="2026-11-21")


def _tip(camera: str) -> tuple[float, float]:
    """The tip's pixel in the first frame, as the user would click it (the camera's true tip)."""
    dev = open_device(DEV)
    try:
        cam = open_camera(camera, dev)
        found = cam.true_tip()  # type: ignore[attr-defined]
        cam.close()
    finally:
        dev.close()
    xy = found if isinstance(found[0], float) else found[0]  # simcam's is (pixel, depth)
    return (float(xy[0]), float(xy[1]))


def measure(camera: str) -> MeasuredJacobian:
    """``camera calibrate`` at the start pose (joints 3 and 1), scaled by the day's true steps."""
    dev = open_device(DEV)
    try:
        cam = open_camera(camera, dev)
        pose = kin.Pose(*(float(dev.position(j)) for j in (1, 2, 3)))  # type: ignore[attr-defined]
        res = calibrate_camera(dev, cam, pose, (3, 1), tip=_tip(camera))
        cam.close()
    finally:
        dev.close()
    fits = [f for jr in res.joints if jr.refused is None for f in jr.fits]
    return measured_jacobian(fits, res.pose, res.tip, calibration(1.0), camera, float(res.pixel_size_m or 0.0))


def run(camera: str, off: float, kind: str, by: tuple[float, float, float] | float, folder: Path,
        jacobian: MeasuredJacobian | None = None, label: str = "") -> list[str]:
    cal = calibration(off)
    with Store.open(folder / f"open-{abs(hash((camera, off, kind, str(by), label)))}.db") as st:
        if kind == "reach":
            assert isinstance(by, tuple)
            r = reach(st, ReachRequest(DEV, by=by), cal)
            assert r.sim_true is not None
            miss = math.dist(kin.tip(r.sim_true), r.plan.target)
            length = math.hypot(*by)
        else:
            assert isinstance(by, float)
            m = move(st, MoveRequest(DEV, 3, by=by), cal)
            assert m.sim_true_end is not None
            miss, length = abs(m.sim_true_end - by), by
    loop = CameraLoop(camera, tip=_tip(camera), jacobian=jacobian)
    with Store.open(folder / f"seen-{abs(hash((camera, off, kind, str(by), label)))}.db") as st:
        t = time.perf_counter()
        try:
            if kind == "reach":
                assert isinstance(by, tuple)
                res = reach_seen(st, ReachRequest(DEV, by=by), cal, loop)
            else:
                assert isinstance(by, float)
                res = move_seen(st, MoveRequest(DEV, 3, by=by), cal, loop)
        except ValueError as e:  # refused before anything moved (the tip not seen at the start)
            STOPS.append(f"{camera}, {kind}: refused before moving: {e}")
            return [camera[:30] + label, f"{off:.1f}", kind, f"{miss * 1e6:5.1f}", f"no ({len(STOPS)})", "-", "0",
                    "-", "-"]
        dt = time.perf_counter() - t
    true_miss = res.sim_true_error if res.sim_true_error is not None else math.nan
    what = f"{kind} {length * 1e6:.0f}"
    short = camera.replace("simcam://?", "sim ").replace("peercam://?", "peer ").replace("pixel=", "")
    short = short.replace("&size=512x512", "").replace("&", " ") + label
    if not res.reached:
        STOPS.append(f"{short}, {what} µm: {res.reason}")
    return [
        short, f"{off:.1f}", what, f"{miss * 1e6:5.1f} ({100 * miss / length:4.1f} %)",
        "yes" if res.reached else f"no ({len(STOPS)})", str(res.corrections), str(len(res.looks)),
        f"{true_miss * 1e6:.2f}", f"{1e3 * dt / max(len(res.looks), 1):.0f}",
    ]


def main() -> None:
    os.environ.setdefault("STICKSLIP_TODAY", DAY)
    loop_peer.register()
    head = ["camera", "off", "µm", "open: miss µm", "reached", "corr", "legs", "miss µm", "ms/leg"]
    rows = [head]
    with tempfile.TemporaryDirectory() as d:
        for camera, off, kind, by in SCENARIOS:
            rows.append(run(camera, off, kind, by, Path(d)))
        measured: dict[str, MeasuredJacobian] = {}
        for camera, off, kind, by in TILTED:
            if camera not in measured:
                measured[camera] = measure(camera)
            rows.append(run(camera, off, kind, by, Path(d), None, " kin"))
            rows.append(run(camera, off, kind, by, Path(d), measured[camera], " jac"))
    widths = [max(len(r[k]) for r in rows) for k in range(len(head))]
    for r in rows:
        print("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)))
    for k, why in enumerate(STOPS, 1):
        print(textwrap.fill(f"({k}) {why}", 79, subsequent_indent="    "))
    print("tolerance: 1 px or 0.5 µm, the larger; at most 4 corrections;")
    print("miss: the true tip's distance from the target; off: the day's steps over")
    print("the calibrated ones")


if __name__ == "__main__":
    main()
