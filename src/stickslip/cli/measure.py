"""Measurement commands: ``demo`` (the whole story on the simulated MM3A)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ..clock import today_label
from ..units import param_scale
from . import app
from ._common import (
    console,
    day_option,
    db_option,
    db_path,
    device_url,
    fail,
    print_json,
    say,
    user_errors,
    validation_table,
    warn,
    warn_later,
)
from ._output import styled


@app.command()
def demo(
    seed: int = typer.Option(0, "--seed", help="Simulator seed: drift of the true parameters, step noise, room sound."),
    day: str | None = typer.Option(
        None,
        "--day",
        help="Session label, e.g. 2026-11-22 (default: today). The truth drifts from day to day.",
        callback=day_option,
    ),
    out: Path = typer.Option(
        Path("stickslip-results"),
        "--output",
        "-o",
        "--out",
        metavar="FOLDER",
        help="Results folder: measurements.csv, calibration.json, tunings, summary.",
    ),
    validation: bool = typer.Option(
        True,
        "--validation/--no-validation",
        help="Also measure the validation sweep of other poses.",
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the summary as one JSON object (SI units)."),
    db: str | None = db_option(" The demo records every traverse and the calibration there."),
    use_db: bool = typer.Option(True, "--db-record/--no-db", help="Record into the database (default) or not."),
    device: str = typer.Option(
        None,
        "--device",
        "-d",
        help="A simulator URL, sim://?seed=3&day=2026-11-22 (same as --seed/--day). The demo compares "
        "with the simulator's truth; on a real manipulator use 'stickslip traverse' and 'calibrate'.",
    ),
    allow_duplicates: bool = typer.Option(
        False,
        "--allow-duplicates",
        help="Record even if this seed and day are already in the database (by default a repeat run is not recorded).",
    ),
    physics: bool = typer.Option(
        False,
        "--physics",
        help="Run on the physics-based arm (sim://?physics=1: stick-slip dynamics, backlash, warm-up; "
        "docs/models.md) instead of the closed-form one. It has no true Eq. 3/8 parameters to compare with, "
        "and its traverses are not recorded in the database.",
    ),
    confirm_s: float | None = typer.Option(
        None,
        "--confirm-s",
        help="Audio switch: take a stop only once it persisted this long while the joint keeps stepping, 0-5 s "
        "(default 0.5; 0: the first fire). Costs this many seconds of stepping into each stop, not accuracy.",
        show_default=False,
    ),
) -> None:
    """Run the whole calibration story on the simulated MM3A (no hardware needed).

    Tunes the audio limit switch for each joint from a simulated recording, runs the paper's 14 calibration traverses (6 prismatic, 8 of joint 2) timed by ear, calibrates, prints the parameters beside the simulator's truth (nm, µrad) with their errors, validates the model against other poses (model vs constant step) and saves measurements (CSV), calibration and tunings (JSON) into --out.

    Example: stickslip demo --seed 3 --day 2026-11-22 --out results/
    """  # noqa: E501
    from ..audio.confirm import CONFIRM_S, check_confirm_s
    from ..calibration import CalibrationError
    from ..procedures.demo import check_outputs, left_from_earlier, run_demo
    from ..procedures.traverse import TraverseError
    from ..storage import Store, StoreError

    try:
        confirm_s = check_confirm_s(CONFIRM_S if confirm_s is None else confirm_s)
    except ValueError as e:
        fail(f"--confirm-s: {e}")
    if device is not None:
        seed, day, physics = _sim_seed_day(device, seed, day, physics)
    try:
        check_outputs(out)
    except ValueError as e:
        fail(str(e))
    with user_errors(CalibrationError, TraverseError, StoreError):
        store = Store.open(db_path(db)) if use_db and not physics else None
        if store is not None and not allow_duplicates and _already_recorded(store, seed, day or today_label()):
            store.close()
            store = None  # the demo still runs; its traverses are not stored a second time
        try:
            result = run_demo(
                seed=seed,
                day=day,
                out=out,
                progress=not json_out,
                validation=validation,
                store=store,
                physics=physics,
                confirm_s=confirm_s,
            )
        finally:
            if store is not None:
                store.close()
    for path in left_from_earlier(result, out):
        warn(f"{path} is from an earlier run, not this one (this run wrote none): delete it or use another --out")
    if json_out:
        print_json(result.to_dict())
        return
    _print_demo(result)


def _print_demo(result: Any) -> None:
    """The demo's summary for a person: the run, the parameters beside the truth, the validation, the files."""
    from rich.table import Table

    console.print(
        styled("stickslip demo", "bold"),
        f": simulated MM3A, seed {result.seed}, day {result.day}: "
        f"{len(result.traverses)} calibration traverses ({result.device_s:.0f} s on the device "
        f"in {result.elapsed_s:.1f} s), method {result.calibration.method}",
        sep="",
    )
    table = Table(title="Calibrated parameters beside the simulator's truth")
    with_se = any(c.parameter.stderr is not None for c in result.parameters)
    cols = ["joint", "dir", "parameter", "q3", "calibrated", "true", "error"]
    if with_se:
        cols.insert(5, "± s.e.")
    for col in cols:
        table.add_column(col, justify="left" if col == "parameter" else "right")
    for c in result.parameters:
        p = c.parameter
        scale, unit = param_scale(p.name, p.joint)
        cells = [
            str(p.joint),
            p.direction,
            f"{p.name} [{unit}]" if unit else p.name,
            "" if p.q3 is None else f"{p.q3 * 1e3:g} mm",
            f"{p.value * scale:.4g}",
            f"{c.true * scale:.4g}",
            c.error_text(),
        ]
        if with_se:
            cells.insert(5, "" if p.stderr is None else f"{p.stderr * scale:.2g}")
        table.add_row(*cells)
    if result.parameters:
        console.print(table)
    else:  # the physics arm has no Eq. 3/8 truth
        console.print("the physics arm has no true Eq. 3/8 parameters to compare with (docs/models.md)")
    if result.validation is not None:
        title = "Validation on other poses: |relative error| of the average step"
        console.print(validation_table(result.validation.rows(), title))
    for what, path in result.files.items():
        say(f"saved {what}: {path}", keep=(path,))


def _already_recorded(store: Any, seed: int, day: str) -> bool:
    """True (and a warning) if this seed and day are in the database: the simulator is deterministic,
    so the same seed and day would store the same traverses again."""
    from ..devices.base import device_key

    key = device_key(f"sim://?seed={seed}")
    n = len(store.traverse_ids(device=key, day=day))
    if n:
        warn_later(
            f"the database {store.path} already holds {n} traverses of {key} on {day} (a demo run before): "
            "this run's traverses were not recorded again (use --allow-duplicates to record a second copy)"
        )
    return n > 0


def _sim_seed_day(device: str, seed: int, day: str | None, physics: bool = False) -> tuple[int, str | None, bool]:
    """Seed, day and physics from a ``sim://`` URL; any other controller is refused with the way to go."""
    from urllib.parse import parse_qs, urlsplit

    parts = urlsplit(device)
    if parts.scheme == "sim+physics":
        physics = True
    elif (parts.scheme or "sim") != "sim":
        fail(
            "the demo runs on the simulator only (it compares the calibration with the simulator's truth); "
            f"on {device} measure each calibration traverse with 'stickslip traverse --device {device} ...' "
            "and calibrate with 'stickslip calibrate' (README: checklist for the first calibration day)"
        )
    query = parse_qs(parts.query)
    unknown = sorted(set(query) - {"seed", "day", "physics"})
    if unknown:
        fail(f"the demo takes seed and day from a sim:// URL, not {', '.join(unknown)}")
    try:
        seed = int(query.get("seed", [seed])[-1])
    except ValueError:
        fail(f"seed must be an integer in {device}")
    day = query.get("day", [day])[-1]
    try:
        day = day_option(day)
    except typer.BadParameter as e:
        fail(f"{e} (day= in {device})")
    return seed, day, physics or query.get("physics", ["0"])[-1] == "1"


@app.command("traverse")
def traverse_cmd(
    ctx: typer.Context,
    joint: int = typer.Option(..., "--joint", "-j", help="Joint to traverse: 1, 2 (rotary) or 3 (prismatic)."),
    direction: str = typer.Option(
        ..., "--direction", metavar="<+|->", help="'+' (lower stop to upper) or '-'. (-d is the device.)"
    ),
    tuning: Path = typer.Option(..., "--tuning", help="This joint's limit-switch tuning (stickslip tune, or demo)."),
    device: str | None = typer.Option(
        None,
        "--device",
        "-d",
        help="Controller URL: sim://, mm3a:///dev/ttyUSB0, anc300://host (default: device in the config file, "
        "else sim://).",
    ),
    audio_input: str = typer.Option(None, "--input", help="Audio input device for a real controller (index or name)."),
    serial_port: str = typer.Option(
        None,
        "--serial",
        help="Listen to a vibration sensor on this serial port instead of a sound card (a vacuum chamber, no air "
        "to carry the sound): one ASCII sample per line at the tuning's sample rate; tune from the same sensor "
        "(docs/audio.md, 'Other sensors').",
    ),
    q1: str = typer.Option("0", help="Joint 1 angle (ignored when traversing joint 1)."),
    q2: str = typer.Option("-90deg", help="Joint 2 angle (ignored when traversing joint 2)."),
    q3: str = typer.Option("0", help="Joint 3 extension (ignored when traversing joint 3)."),
    theta: str = typer.Option("0", help="Base tilt about x0."),
    psi: str = typer.Option("0", help="Base tilt about the new y0."),
    day: str = typer.Option(None, "--day", help="Session label (default: today's ISO date).", callback=day_option),
    append: Path = typer.Option(None, "--append", "-a", help="Append the row to this measurement table (CSV)."),
    db: str | None = db_option(),
    use_db: bool = typer.Option(True, "--db-record/--no-db", help="Record the traverse into the database."),
    burst: int = typer.Option(
        2000, "--burst", min=1, max=1_000_000, help="Steps per burst between checks of the limit switch."
    ),
    confirm_s: float | None = typer.Option(
        None,
        "--confirm-s",
        help="Take the stop only once it persisted this long while the joint keeps stepping, 0-5 s (default 0.5: "
        "interference that mimics the stop for a moment is passed by). Costs this many seconds x the step rate "
        "extra steps against the stop (2 s just after a fire that did not persist; harmless: the slider slips) and "
        "that much time, not accuracy: the count runs to the stop's onset. 0: the first fire is the stop.",
        show_default=False,
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the measured row as JSON (SI units)."),
) -> None:
    """Measure one traverse: count the steps between a joint's end stops, timed by ear.

    Drives the joint to its start stop, then steps in bursts in the measured direction
    while the tuned audio limit switch listens; stops at the end stop and counts the
    steps that moved the joint (latency corrected). The pose options say how the arm
    and base are set (on a real manipulator you set them; the simulator is placed there).
    The row goes to the database and, with --append, to a measurement table. The joint
    ends referenced at its stop, and the pose options you give are kept as the arm's pose
    (stickslip where shows them, the next move plans from them); an option left at its
    default is recorded in the row but does not change the kept pose, and a warning says so
    before the joint moves when that default is more than 0.5 deg (10 µm for q3, or 3 σ of
    a tracked position) from where the arm is kept.

    Example: stickslip traverse --joint 3 --direction + --tuning tuning-joint3.json --q2 0 --theta -90deg -a day.csv
    """
    from ..audio.confirm import CONFIRM_S, check_confirm_s
    from ..audio.detector import Tuning
    from ..clock import today_label
    from ..devices import DeviceError
    from ..kinematics import JOINTS
    from ..measurements import HEADER
    from ..models import direction_label
    from ..procedures.move import DeviceBusy
    from ..procedures.session import POSE_NAMES, TraverseRequest, check_append_target, traverse
    from ..procedures.traverse import TraverseError
    from ..storage import Store, StoreError
    from ..units import format_step
    from ._common import pose_options

    if joint not in JOINTS:
        fail(f"unknown joint {joint} (joints are 1, 2 and 3)")
    try:
        confirm_s = check_confirm_s(CONFIRM_S if confirm_s is None else confirm_s)
    except ValueError as e:
        fail(f"--confirm-s: {e}")
    if serial_port is not None and audio_input is not None:
        fail("give --input (a sound card) or --serial (a vibration sensor), not both")
    device = device_url(device)
    try:
        label = direction_label(direction)
    except ValueError as e:
        fail(f"--direction: {e}")
    pose = pose_options(q1, q2, q3, theta, psi)
    with user_errors(DeviceError, TraverseError, StoreError, DeviceBusy):
        if append is not None:
            check_append_target(append)  # before anything else: a traverse takes a while
        tun = Tuning.load(tuning)
        if getattr(tun, "joint", None) not in (None, joint):
            fail(f"{tuning} is tuned for joint {tun.joint}, not joint {joint}")
        given = _given(ctx, POSE_NAMES)
        request = TraverseRequest(
            device, joint, label, pose, day or today_label(), tun, audio_input=audio_input, serial_port=serial_port,
            burst=burst, confirm_s=confirm_s, append=append, keep_pose=given,
            defaulted=tuple(n for n in POSE_NAMES if n not in given),
        )
        store = Store.open(db_path(db)) if use_db else None
        try:
            result = traverse(store, request, progress=not json_out, on_warning=warn)
        finally:
            if store is not None:
                store.close()
    row = result.traverse
    if json_out:
        print_json({**row.as_row(), "gamma": row.gamma, "header": list(HEADER)})
        return
    console.print(
        f"joint {joint}{label}: {row.steps} steps from {row.start:.6g} to {row.end:.6g} "
        f"{JOINTS[joint].unit}: average step {format_step(row.gamma, joint)}",
        highlight=False,
    )


def _given(ctx: typer.Context, names: tuple[str, ...]) -> tuple[str, ...]:
    """Which of the options ``names`` the user gave (on the command line or from the environment), not defaults."""
    sources = {n: ctx.get_parameter_source(n) for n in names}
    return tuple(n for n, src in sources.items() if src is not None and src.name != "DEFAULT")
