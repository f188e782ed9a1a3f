"""Task-space commands: ``reach`` (a straight tip move) and ``jog`` (teleoperation from the keyboard).

The tip is in the base frame before the base tilt (docs/design.md §9), metres inside;
on the command line coordinates take units (``--by 20um,-10um,5um``). Positions are
kept per device in the database exactly as for ``move`` and ``where``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer

from .. import kinematics as kin
from ..clock import stale_message
from ..devices.base import DeviceError, open_device
from ..devices.positions import DeviceState, device_key, load_state, save_state
from ..units import UnitError, parse_length
from . import app
from ._common import angle_option, console, fail, flush_warnings, length_option, print_json, user_errors, warn_later

_DB_HELP = "SQLite database file (default: $STICKSLIP_DB, else ~/.local/share/stickslip/stickslip.db)."
_DEVICE_HELP = (
    "Controller URL: sim:// (default), mm3a:///dev/ttyUSB0, mm3a+socket://host:port, anc300://host[:7230]?password=..."
)
_GEOMETRY_HELP = (
    "OFFSET,LENGTH of the arm: joint-1 axis to joint-2 axis, joint-2 axis to the tip at q3 = 0 "
    "(default 0mm,21mm; measure yours, see docs/taskspace.md)."
)


def parse_point(text: str, what: str) -> tuple[float, float, float]:
    """``"X,Y,Z"`` lengths with units (``20um,-10um,5um``; bare numbers are metres) to metres."""
    parts = text.split(",")
    if len(parts) != 3:
        fail(f"{what} {text!r}: write three lengths X,Y,Z, e.g. 20um,-10um,5um")
    out = []
    for axis, part in zip("XYZ", parts, strict=True):
        try:
            v = parse_length(part)
        except (UnitError, ArithmeticError, ValueError) as e:
            fail(f"{what} {axis} = {part.strip()!r}: {e}")
        if not math.isfinite(v) or abs(v) > 1.0:
            fail(f"{what} {axis} = {part.strip()!r} is not a length within 1 m")
        out.append(v)
    return (out[0], out[1], out[2])


def parse_geometry(text: str | None) -> kin.Geometry:
    """``--geometry OFFSET,LENGTH`` to a :class:`~stickslip.kinematics.Geometry` (default if ``None``)."""
    if text is None:
        return kin.DEFAULT_GEOMETRY
    try:
        return kin.Geometry.parse(text)
    except ValueError as e:
        fail(f"--geometry: {e}")


def _open_store(db: Path | None) -> Any:
    from ..storage import Store, StoreError

    with user_errors(StoreError):
        return Store.open(db)


def _apply_pose(state: DeviceState, pose_opts: tuple[float | None, ...]) -> None:
    q1, q2, q3, theta, psi = pose_opts
    for j, v in ((1, q1), (2, q2), (3, q3)):
        if v is not None:
            with user_errors():
                state.set_position(j, v, "set")
    with user_errors():
        state.set_tilt(theta, psi)


def _start_state(store: Any, key: str, pose_opts: tuple[float | None, ...]) -> DeviceState:
    with user_errors():
        state = load_state(store, key)
    _apply_pose(state, pose_opts)
    for j in (1, 2, 3):
        problem = state.uncertainty_problem(j)
        if problem:
            fail(problem)
    return state


def _um(v: tuple[float, float, float] | list[float]) -> str:
    return "(" + ", ".join(f"{x * 1e6:.2f}" for x in v) + ") µm"


@app.command()
def reach(
    calibration: Path = typer.Option(..., "--calibration", "-c", help="Calibration JSON (from `stickslip calibrate`)."),
    to: str | None = typer.Option(None, "--to", help="Tip target X,Y,Z in the base frame: 21mm,0,50um."),
    by: str | None = typer.Option(None, "--by", help="Tip displacement DX,DY,DZ: 20um,-10um,5um."),
    device: str = typer.Option("sim://", "--device", "-d", help=_DEVICE_HELP),
    q1: str | None = typer.Option(None, "--q1", callback=angle_option, help="Record q1 (angle) first."),
    q2: str | None = typer.Option(None, "--q2", callback=angle_option, help="Record q2 (angle) first."),
    q3: str | None = typer.Option(None, "--q3", callback=length_option, help="Record q3 (length) first."),
    theta: str | None = typer.Option(None, "--theta", callback=angle_option, help="Record the base tilt theta."),
    psi: str | None = typer.Option(None, "--psi", callback=angle_option, help="Record the base tilt psi."),
    geometry: str | None = typer.Option(None, "--geometry", help=_GEOMETRY_HELP),
    segment: str = typer.Option(
        "10um", "--segment", callback=length_option, help="Longest segment of the line (length; default 10um)."
    ),
    burst: int = typer.Option(1000, "--burst", min=1, max=65535, help="Most steps per burst."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Plan and print; send nothing, keep nothing."),
    db: Path | None = typer.Option(None, "--db", help=_DB_HELP),
    json_out: bool = typer.Option(False, "--json", help="Print the plan as JSON (metres, radians)."),
) -> None:
    """Move the tip in a straight line to a point or by a displacement (task space).

    The tip is in the base frame before the base tilt (x along the outstretched arm at
    q1 = 0, z up the joint-1 axis), from the positions kept for the device (see
    `stickslip where`); --q1 --q2 --q3 --theta --psi record a new pose first.

    The line is cut into segments (at most --segment, and at most 2 % of the move);
    each segment's joint increments come from the inverse kinematics and its steps from
    the calibrated models in the current pose, joints 1, 2, 3 in that order, rounding
    remainders carried to the next segment.

    A target out of reach or a line near joint 1's axis (a singular pose) is refused
    before any step is sent. Without --dry-run the positions are kept after every burst,
    as for `move`.

    Example: stickslip reach -c cal.json -d mm3a:///dev/ttyUSB0 --by 20um,-10um,5um
    """
    if (by is None) == (to is None):
        fail("give exactly one of --by and --to")
    point = parse_point(to if to is not None else str(by), "--to" if to is not None else "--by")
    geom = parse_geometry(geometry)
    seg = float(segment)
    from ..calibration import Calibration
    from ..reach import plan_reach

    with user_errors(KeyError):
        cal = Calibration.load(calibration)
    with user_errors():
        key = device_key(device)
    pose_opts: tuple[float | None, ...] = (q1, q2, q3, theta, psi)  # type: ignore[assignment]  # callbacks made floats

    def plan_from(state: DeviceState) -> Any:
        with user_errors(KeyError):  # OutOfReach and SingularPose are ValueErrors
            if to is not None:
                return plan_reach(cal, state.pose, to=point, geometry=geom, segment=seg)
            return plan_reach(cal, state.pose, by=point, geometry=geom, segment=seg)

    if dry_run:
        with _open_store(db) as store:
            state = _start_state(store, key, pose_opts)
        plan = plan_from(state)
        _print_plan(plan, json_out, None, None)
        return

    from ..procedures.move import DeviceBusy, device_lock
    from ..procedures.reach import ReachOutcome, drive_reach

    with _open_store(db) as store, user_errors(DeviceBusy):
        with device_lock(store, key):
            state = _start_state(store, key, pose_opts)
            plan = plan_from(state)
            with user_errors():
                save_state(store, state)  # the recorded pose, even if nothing moves
            stale = stale_message(cal.day)
            if stale:
                warn_later(stale)
            flush_warnings()
            outcome, sim_true = ReachOutcome(), None
            if any(plan.total_steps):
                try:
                    dev = open_device(device)
                except (DeviceError, ValueError) as e:
                    fail(str(e))
                try:
                    if hasattr(dev, "set_pose"):  # the simulator: start where the positions say
                        dev.set_pose(*state.pose)

                    def save(st: DeviceState) -> None:
                        with user_errors():
                            save_state(store, st)

                    outcome = drive_reach(dev, state, plan, cal, save, burst)
                    if outcome.error is None and hasattr(dev, "position"):
                        sim_true = [float(dev.position(j)) for j in (1, 2, 3)]
                finally:
                    try:
                        dev.close()
                    except DeviceError:
                        pass
    if outcome.error is not None:
        j = outcome.joint or 0
        if j in state.uncertain:
            kept = (
                f"joint {j}'s position is now uncertain; re-reference it (stickslip where --set {j}=min at the "
                f"lower stop) before the next move"
            )
        else:
            kept = "the dead-reckoned positions are kept"
        fail(
            f"{outcome.error}; stopped in segment {outcome.segments_done + 1} of {len(plan.segments)} "
            f"(steps sent per joint: {outcome.sent}); {kept}"
        )
    _print_plan(plan, json_out, key, sim_true)


def _print_plan(plan: Any, json_out: bool, device: str | None, sim_true: list[float] | None) -> None:
    geom = plan.geometry
    true_tip = None if sim_true is None else [float(v) for v in kin.tip(sim_true, geom)]
    if json_out:
        out = plan.as_dict()
        if sim_true is not None:
            out["sim_true"] = {"q": sim_true, "tip": true_tip}
        print_json(out)
        return
    n1, n2, n3 = plan.total_steps
    verb = "moved" if device else "plan"
    console.print(
        f"{verb}: tip {_um(plan.tip_start)} -> {_um(plan.target)} ({plan.length * 1e6:.2f} µm) in "
        f"{len(plan.segments)} segment(s); steps |joint 1| {n1}, |joint 2| {n2}, |joint 3| {n3}",
        highlight=False,
    )
    console.print(
        f"predicted end {_um(plan.tip_end)}, {plan.end_error * 1e9:.0f} nm from the target; joints "
        f"q1 = {math.degrees(plan.q_end[0]):.4f} deg, q2 = {math.degrees(plan.q_end[1]):.4f} deg, "
        f"q3 = {plan.q_end[2] * 1e6:.2f} µm",
        highlight=False,
    )
    if true_tip is not None:
        err = math.dist(true_tip, plan.target)
        console.print(f"simulator's true tip {_um(true_tip)}, {err * 1e9:.0f} nm from the target", highlight=False)
