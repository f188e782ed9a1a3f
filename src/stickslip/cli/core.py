"""Core commands: calibrate, predict, validate, plan, show."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TextIO

import typer
from rich.table import Table

if TYPE_CHECKING:  # numpy and the library load inside the commands, so that --help starts fast
    from ..calibration import Calibration, Conditions
    from ..measurements import Traverse

from ..clock import stale_message
from ..devices.base import device_key
from ..joints import joint_spec
from ..records import atomic_write
from ..units import format_position, format_step, param_scale, step_scale
from . import app
from ._common import (
    angle_option,
    calibration_file,
    console,
    db_option,
    db_path,
    fail,
    fail_table,
    length_option,
    max_age_setting,
    open_store,
    pose_options,
    print_json,
    read_step_table,
    read_table,
    say,
    user_errors,
    validation_table,
    warn,
    warn_later,
)
from ._output import data_stream

CalibrationOpt = Annotated[
    Path | None,
    typer.Option(
        "--calibration",
        "-c",
        help="Calibration JSON written by 'stickslip calibrate' or 'fit' (default: calibration in the config file).",
    ),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print machine-readable JSON instead of a table.")]


def _load_calibration(option: Path | None) -> Calibration:
    """The calibration of ``--calibration``, else the config file's; a stale one queues a warning."""
    from ..calibration import Calibration

    path = calibration_file(option)
    with user_errors():
        cal = Calibration.load(path)
    msg = stale_message(cal.day, max_age_days=max_age_setting(None).value)
    if msg:
        warn_later(msg)
    return cal


def _params_table(cal: Calibration, title: str) -> Table:
    t = Table(title=title, caption=_average_caption(cal))
    for col in ("joint", "dir", "parameter", "q3", "value", "std. error", "unit"):
        t.add_column(col, justify="right" if col in ("value", "std. error") else "left")
    for r in cal.parameters():
        scale, unit = param_scale(r.name, r.joint)
        q3 = f"{r.q3 * 1e3:g} mm" if r.q3 is not None else ""
        se = f"{r.stderr * scale:.3g}" if r.stderr is not None else "—"
        t.add_row(str(r.joint), r.direction, r.name, q3, f"{r.value * scale:.5g}", se, unit or "1")
    return t


def _weights(sel: dict[str, object]) -> dict[str, float]:
    """A selection's family weights in the model average (``{label: weight}``; empty if none recorded)."""
    w = sel.get("weights")
    return {str(k): float(v) for k, v in w.items() if isinstance(v, (int, float))} if isinstance(w, dict) else {}


def _average_caption(cal: Calibration) -> str | None:
    """Under the parameter table: which joints predict with an average of families, not the parameters shown."""
    parts, seen = [], set()
    for (j, _d), sel in sorted(cal.selection.items()):
        w = _weights(sel)
        if j in seen or len(w) < 2:
            continue
        seen.add(j)
        top = max(w, key=w.__getitem__)
        parts.append(f"joint {j}: the parameters of {top} (weight {w[top]:.2f}); it predicts with the "
                     f"weighted average of {len(w)} families")
    return "; ".join(parts) or None


@app.command("calibrate")
def calibrate_cmd(
    measurements: Annotated[
        Path | None,
        typer.Argument(
            help="Measurement table (CSV, header day,joint,direction,q1,q2,q3,theta,psi,start,end,steps; SI units). "
            "May be left out with --step-sizes and --prior."
        ),
    ] = None,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the calibration JSON here.")] = None,
    step_sizes: Annotated[
        Path | None,
        typer.Option(
            "--step-sizes",
            help="Step sizes measured at poses (CSV from 'stickslip camera calibrate -o'): fitted beside the "
            "traverses, each weighted by its uncertainty. Each joint needs a model: with --prior the prior's "
            "(an MM3A's has joints 2 and 3: measure with camera calibrate --joints 3,2), else traverses of it.",
        ),
    ] = None,
    check: Annotated[
        Path | None,
        typer.Option(
            "--check",
            help="Check traverses (a measurement table): at random poses (none of the calibration's), measured "
            "after the table's and not fitted; how they erred scales each joint's intervals (docs/models.md §4). "
            "The table needs more traverses than the paper's 14 poses: the paper's procedure alone has no "
            "intervals to scale (refused).",
        ),
    ] = None,
    method: Annotated[
        str,
        typer.Option(
            help="auto | paper | paper-quadratic | lsq (the old names seed, seed-quadratic still work). "
            "'auto' uses the paper's procedure when the table "
            "has its calibration poses, least squares otherwise."
        ),
    ] = "auto",
    day: Annotated[
        str | None, typer.Option(help="Session label to record (default: the latest day in the table).")
    ] = None,
    device: Annotated[
        str | None,
        typer.Option(
            "--device", "-d",
            help="Device URL the traverses were measured on (recorded without options or secrets; default: the "
            "one device the database holds them all under, if any). A calibration without its device, or from "
            "the simulator, is refused on a real controller unless --trust-calibration.",
        ),
    ] = None,
    db: str | None = db_option(),
    frequency: Annotated[  # the ranges are calibration.result's _CONDITION_RANGES (a test holds them equal)
        float | None,
        typer.Option(
            help="Stepping frequency of the traverses, Hz (recorded; move warns on a change).", min=0.001, max=1e6
        ),
    ] = None,
    amplitude: Annotated[
        float | None,
        typer.Option(help="Drive amplitude of the traverses, V (recorded; move warns on a change).", min=0, max=1000),
    ] = None,
    temperature: Annotated[
        float | None, typer.Option(help="Temperature during the traverses, °C (recorded).", min=-273.15, max=500)
    ] = None,
    model: Annotated[
        str,
        typer.Option(
            "--model",
            help="auto | paper | a family name (docs/models.md). 'auto': the paper's procedure where a joint's "
            "traverses are exactly the paper's poses, else every model family the data identify, averaged "
            "with weights from cross-validation on held-out poses (pseudo-BMA+, leaning to the paper's form), "
            "or the paper's form where the average is expected to err more at new poses. 'paper': the paper's "
            "models "
            "only (also what 'auto' means "
            "with a --method other than auto).",
        ),
    ] = "auto",
    prior: Annotated[
        Path | None,
        typer.Option(
            "--prior",
            help="An earlier calibration to bring up to date with these (few) traverses: the step scale of "
            "each joint and direction measured is updated (Bayesian), the rest kept.",
        ),
    ] = None,
    drift: Annotated[
        float | None,
        typer.Option(
            help="With --prior: prior standard deviation of a day's change of step scale (relative, above 0; "
            "default 0.15).",
            show_default=False,
        ),
    ] = None,
    max_table_mb: Annotated[
        float,
        typer.Option(
            "--max-table-mb",
            help="Largest measurement table read, MB: calibrate holds every row in memory (about ten times "
            "the file), so a table beyond this is refused rather than filling the memory.",
        ),
    ] = 64.0,
    json_out: JsonOpt = False,
    rig_file: Annotated[
        Path | None,
        typer.Option(
            "--rig",
            help="Rig file (docs/rig.md): calibrate its stage arm (--arm) from the table, each joint and "
            "direction's mean step, checked against the arm's joints; an MM3A arm is calibrated without --rig.",
        ),
    ] = None,
    arm: Annotated[str | None, typer.Option("--arm", help="Arm of the rig (default: its first arm).")] = None,
) -> None:
    """Calibrate the step-size models from measured traverses.

    The paper's procedure needs, for the prismatic joint, traverses in + and - at
    (q2, theta, psi) = (-90deg, 0, 0), (0, -90deg, 0), (0, 0, 0) (Eqs. 4-6), and for
    joint 2 full-range traverses at (q3, theta, psi) = (0, 0, 0), (12mm, 0, 0),
    (12mm, -90deg, 0), (0, -90deg, 0); d is found by inverting the exact average-step
    integral. Any other set of traverses is fitted by least squares, with standard errors.

    With more traverses than the paper's poses, every model family the data can
    identify is fitted and cross-validated on held-out poses (folds as far from the rest
    as new poses of the workspace are from the calibration's), and the prediction averages
    them, each weighted by how well it predicted the poses held out (pseudo-BMA+, half the
    prior on the paper's form); where that average is expected to err more at new poses
    than the paper's form, the paper's form is used and the note says so. The table gives each
    family's parameter count (+ and - together), CV error and weight, and ◀ marks the one
    whose parameters are shown; below it, the error to expect at new poses (what
    predict --interval and plan use). With --prior, an earlier calibration is brought up to
    date with as few as one traverse per joint and direction.

    With --step-sizes, step sizes a camera measured at poses (stickslip camera calibrate)
    join the traverses: each joint and direction that has some is fitted by least squares
    on the paper's model, each step size weighted by its uncertainty; with --prior they
    bring the calibration up to date at the poses where you work.

    When the database holds every row of the table under one device (measured with
    traverse or demo, or imported with --device), the calibration records that device and
    is kept in the database beside them (history lists it; show N gets it back). One
    without a device, or from the simulator, is refused on a real controller unless
    --trust-calibration.

    A stage (a rig file's xyz arm, --rig RIG --arm NAME) is planned with a constant step
    per joint and direction: each is the mean of its traverses' average steps (length over
    steps counted, weighted by length), with its standard error and count; every joint
    needs a traverse each way. The table's rows are checked against the arm's joints
    (their numbers and ranges, positions in m); the calibration records the arm's
    controller as its device unless --device.

    With --check, traverses at random poses measured after the table's (not fitted) show
    how far the intervals are from the errors at new poses, and each joint's intervals are
    scaled part of the way (a note says by how much).

    Example: stickslip calibrate day1.csv -o cal.json

    Example: stickslip calibrate today4.csv --prior yesterday.json -o today.json

    Example: stickslip calibrate --prior yesterday.json --step-sizes camera.csv -o today.json

    Example: stickslip calibrate day1-and-sweep.csv --check check1.csv -o cal.json

    Example: stickslip calibrate stack.csv --rig lab.toml --arm gripper -o cal/gripper.json
    """
    from ..calibration import CalibrationError, Conditions, calibrate
    from ..measurements import StepSize
    from ..models import NonPhysicalError

    if measurements is None and (step_sizes is None or prior is None):
        fail("give a measurement table (MEASUREMENTS.csv); it may be left out only with --step-sizes and --prior")
    if not (math.isfinite(max_table_mb) and max_table_mb > 0):
        fail(f"--max-table-mb must be a positive number of MB, got {max_table_mb!r}")
    _check_drift(drift, prior)
    if check is not None and (prior is not None or step_sizes is not None):
        fail("--check scales the intervals of a calibration made from the table: not with --prior or --step-sizes")
    if rig_file is not None:
        mm3a_only = (prior is not None or step_sizes is not None or method != "auto" or model != "auto"
                     or check is not None)
        measurements = _stage_table(measurements, mm3a_only, db)
        _calibrate_stage(measurements, rig_file, arm, output, day, device, frequency, amplitude, temperature,
                         int(max_table_mb * 1024 * 1024), json_out)
        return
    if arm is not None:
        fail("--arm names an arm of a rig: give --rig FILE too")
    traverses = _whole_table(measurements, int(max_table_mb * 1024 * 1024)) if measurements is not None else []
    checks = _whole_table(check, int(max_table_mb * 1024 * 1024)) if check is not None else []
    steps: list[StepSize] = read_step_table(step_sizes) if step_sizes is not None else []
    source = str(measurements) if measurements is not None else str(step_sizes)
    stored = _stored_device(traverses, db) if device is None and traverses else None
    if stored is not None:
        device = stored[0]
    try:
        conditions = Conditions(device_key(device) if device else None, frequency, amplitude, temperature)
        if prior is not None:
            cal = _updated(prior, traverses, drift, day, source, steps, conditions)
        else:
            with _progress_bar("calibrating") as progress:  # shown once it has taken a second
                cal = calibrate(traverses, method=method, day=day, source=source, model=model, step_sizes=steps,
                                progress=progress, check=checks)
    except (CalibrationError, NonPhysicalError, ValueError, KeyError) as e:
        fail(str(e.args[0]) if isinstance(e, KeyError) else str(e))
    cal = dataclasses.replace(cal, conditions=conditions)
    _warn_if_pooled(traverses, cal.day)
    if output is not None:
        with user_errors():
            cal.save(output)
    kept = _keep(cal, stored, db)
    if json_out:
        print_json(cal.to_dict())
        return
    with_steps = f" and {len(steps)} step sizes" if steps else ""
    console.print(
        _params_table(cal, f"calibration — day {cal.day}, method {cal.method}, {len(traverses)} traverses{with_steps}")
    )
    if cal.selection:
        console.print(_selection_table(cal))
    for n in cal.provenance.notes:
        say(f"note: {n}")  # wrapped at spaces, later lines indented: a path or a number is never cut
    if output is not None:
        say(f"saved to {output}", keep=(output,))
    if kept is not None:
        say(f"kept in the database as calibration #{kept} of {stored[0] if stored else ''}".rstrip())


def _warn_if_pooled(traverses: list[Traverse], day: str) -> None:
    """Queue a warning when ``traverses`` span several sessions: one fit pools them, dated ``day``."""
    days = sorted({t.day for t in traverses})
    if len(days) > 1:
        shown = ", ".join(days) if len(days) <= 4 else f"{days[0]} ... {days[-1]}"
        warn_later(f"the table holds traverses of {len(days)} sessions ({shown}), fitted as one and dated {day}: "
                   "a day's change of step size is taken for model error (the paper found it significant); "
                   "calibrate each session from its own traverses, or today's with --prior yesterday's calibration")


def _check_drift(drift: float | None, prior: Path | None) -> None:
    """``--drift``: with --prior only (else it would be taken and not used), and above 0."""
    if drift is not None and prior is None:
        fail("--drift is the prior's day-to-day change of step scale: it goes with --prior (else unused)")
    if drift is not None and not (math.isfinite(drift) and drift > 0):
        fail(f"--drift must be above 0 (a relative standard deviation, 0.15 = 15 %), got {drift:g}")


def _updated(prior: Path, traverses: list[Traverse], drift: float | None, day: str | None, source: str,
             steps: list[Any], conditions: Conditions) -> Calibration:
    """``calibrate --prior``: the calibration in ``prior`` brought up to date (:mod:`stickslip.calibration.update`),
    with a warning queued for each :func:`_prior_problems`."""
    from ..calibration import Calibration
    from ..calibration.update import DRIFT_PRIOR, update_calibration

    with user_errors():
        old = Calibration.load(prior)
    cal, _ = update_calibration(
        old, traverses, drift=DRIFT_PRIOR if drift is None else drift, day=day, source=source, step_sizes=steps
    )
    for w in _prior_problems(old, conditions, cal.day):
        warn_later(w)
    return cal


def _prior_problems(old: Calibration, now: Conditions, day: str) -> list[str]:
    """Why ``calibrate --prior`` may be bringing the wrong calibration up to date, one line each: the prior was made
    on another device or setting than the new traverses (``now``, :class:`~stickslip.calibration.Conditions`), or on
    a later session than theirs (``day``). The update keeps the prior's shape, which is that arm's."""
    from ..clock import age_days

    out: list[str] = []
    then = old.conditions
    if then.device:
        with contextlib.suppress(ValueError):  # a malformed key compares as written
            then = dataclasses.replace(then, device=device_key(then.device))
    diffs = then.differences(now)
    if diffs:
        out.append("the prior calibration was made under other conditions (" + "; ".join(diffs) + "): the update "
                   "keeps its model's shape, which is that arm's and setting's; calibrate this one from scratch")
    age = age_days(old.day, day)
    if age is not None and age < 0:
        out.append(f"the prior calibration is of {old.day}, {-age} day{'s' if age != -1 else ''} after these "
                   f"traverses' {day}: an update brings an earlier calibration forward; check which file is the "
                   "prior (and --day)")
    return out


def _stage_table(measurements: Path | None, mm3a_only: bool, db: str | None) -> Path:
    """The stage's table (``calibrate --rig``), refusing what only an MM3A's calibration uses."""
    if mm3a_only:
        fail("a stage (--rig) is calibrated from its traverses alone: --prior, --step-sizes, --check, --method "
             "and --model are for an MM3A")
    if measurements is None:
        fail("give the stage's measurement table (MEASUREMENTS.csv)")
    if db is not None:
        fail("a stage's calibration is kept in its file (-o), not in a database: leave out --db")
    return measurements


def _calibrate_stage(measurements: Path, rig_file: Path, arm: str | None, output: Path | None, day: str | None,
                     device: str | None, frequency: float | None, amplitude: float | None,
                     temperature: float | None, max_bytes: int, json_out: bool) -> None:
    """``calibrate TABLE --rig RIG --arm NAME``: a stage arm's mean steps (:mod:`stickslip.calibration.stage`)."""
    from ..calibration import CalibrationError, Conditions
    from ..calibration.stage import calibrate_stage, check_stage
    from .rig import load

    with user_errors(KeyError):
        a = load(rig_file).arm(arm)
    joints = a.joint_specs()
    try:
        check_stage(joints, a.name)
        traverses = _whole_table(measurements, max_bytes, joints)
        conditions = Conditions(device_key(device or a.controller), frequency, amplitude, temperature)
        cal = calibrate_stage(traverses, joints, arm=a.name, day=day, source=str(measurements))
    except (CalibrationError, ValueError) as e:
        fail(str(e))
    cal = dataclasses.replace(cal, conditions=conditions)
    if output is not None:
        with user_errors():
            cal.save(output)
    if json_out:
        print_json(cal.to_dict())
        return
    t = Table(title=f"arm {a.name!r}: mean steps — day {cal.day}, {len(traverses)} traverses")
    for col in ("joint", "dir", "mean step", "std. error", "traverses", "unit"):
        t.add_column(col, justify="left" if col in ("joint", "dir", "unit") else "right")
    for (j, d), v in sorted(cal.constant_steps.items()):
        scale, unit = step_scale(joints[j])
        se = cal.constant_stderr.get((j, d))
        t.add_row(str(j), d, f"{v * scale:.5g}", "—" if se is None else f"{se * scale:.3g}",
                  str(cal.constant_traverses.get((j, d), "")), unit)
    console.print(t)
    for n in cal.provenance.notes:
        say(f"note: {n}")  # wrapped at spaces, later lines indented: a path or a number is never cut
    if output is not None:
        say(f"saved to {output}", keep=(output,))


def _stored_device(traverses: list[Any], db: str | None) -> tuple[str, list[int]] | None:
    """The device the database holds every one of ``traverses`` under, and their ids (``None``: not so)."""
    from ..storage import Store, StoreError

    path = db_path(db)
    if isinstance(path, Path) and not path.is_file():
        return None  # a calibration never creates a database
    try:
        with Store.open(path, create=False) as store:
            return store.device_holding(traverses)
    except (StoreError, ValueError):
        return None  # the device stays unknown; the database's own problem is for the commands that use it


def _keep(cal: Calibration, stored: tuple[str, list[int]] | None, db: str | None) -> int | None:
    """Keep ``cal`` in the database beside the traverses it was made from (its id), if the database holds them."""
    if stored is None:
        return None
    from ..storage import Store, StoreError

    with user_errors(StoreError), Store.open(db_path(db)) as store:
        return store.add_calibration(cal, stored[0], stored[1])


def _whole_table(path: Path, max_bytes: int, joints: Any = None) -> list[Traverse]:
    """A measurement table read whole (calibrate holds every row), or every problem and exit 2; over the size
    limit, the message says how to raise it. ``joints``: an arm's own joints to check the rows against
    (:func:`~stickslip.measurements.read_measurements`; default the MM3A's)."""
    from ..measurements import TableError, read_measurements

    try:
        return read_measurements(path, max_bytes, joints)
    except TableError as e:
        fail("\n".join(p + ("; --max-table-mb raises the limit" if "limit for a CSV" in p else "")
                       for p in e.problems))


@contextlib.contextmanager
def _progress_bar(what: str, after_s: float = 1.0) -> Iterator[Callable[[float, str], None]]:
    """A ``progress(fraction, text)`` callback that shows a bar on stderr once ``after_s`` have passed
    (a calibration of a few hundred traverses ends before it would flicker), removed when done."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    start = time.monotonic()
    bar: Progress | None = None
    task = None

    def update(fraction: float, text: str) -> None:
        nonlocal bar, task
        if bar is None and time.monotonic() - start < after_s:
            return
        if bar is None:
            console = Console(stderr=True)  # in a pipe or a log no bar: its close would leave a blank line
            bar = Progress(TextColumn(what), BarColumn(), TextColumn("{task.percentage:>3.0f} %"),
                           TextColumn("{task.description}"), TimeElapsedColumn(),
                           console=console, transient=True, disable=not console.is_terminal)
            bar.start()
            task = bar.add_task(text, total=1.0)
        assert task is not None
        bar.update(task, completed=min(max(fraction, 0.0), 1.0), description=text)

    try:
        yield update
    finally:
        if bar is not None:
            bar.stop()


def _selection_table(cal: Calibration) -> Table:
    """Each scored family's CV errors and weight; the families the data could not score, in the caption."""
    t = Table(title="model families: cross-validation on held-out poses (relative error of the average step)")
    for col in ("joint", "family", "params", "CV RMS", "CV max", "fit RMS", "weight"):
        t.add_column(
            col, justify="left" if col in ("joint", "family") else "right", no_wrap=col != "family", overflow="fold"
        )
    seen: set[int] = set()
    unscored: list[str] = []
    for (j, _d), sel in sorted(cal.selection.items()):
        if j in seen:  # one selection per joint (both directions are fitted together)
            continue
        seen.add(j)
        chosen = sel.get("chosen")
        weights = _weights(sel)
        scores = sel.get("scores") or []
        for sc in scores if isinstance(scores, list) else []:

            def pct(x: object) -> str:
                return f"{float(x) * 100:.2f} %" if isinstance(x, (int, float)) else "—"

            if sc["status"] != "ok":
                unscored.append(f"joint {j} {sc['family']}: {sc['status']}")
                continue
            mark = " ◀" if sc["family"] == chosen else ""  # the family whose parameters are shown
            w = weights.get(str(sc["family"]))
            t.add_row(str(j), str(sc["family"]), str(sc["n_params"]), pct(sc["cv_rms"]), pct(sc["cv_max"]),
                      pct(sc["fit_rms"]), (f"{w:.2f}" if w else "") + mark)
    captions = []
    expected = [f"{j}{d} {cal.sigma_model[(j, d)] * 100:.1f} %" for (j, d) in sorted(cal.predictive)
                if (j, d) in cal.sigma_model]
    if expected:
        captions.append("expected RMS error at new poses of the workspace: " + ", ".join(expected))
    if unscored:
        captions.append("not scored: " + "; ".join(unscored))
    t.caption = "\n".join(captions) or None
    return t


@app.command("show")
def show_cmd(
    calibration: Annotated[
        str | None,
        typer.Argument(
            help="Calibration JSON, or the number of a stored calibration (`stickslip history` lists them: #1 "
            "is 1) (default: calibration in the config file).",
            metavar="[CAL.json|N]",
            show_default=False,
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Also write the calibration to this JSON file (use it with -c)."),
    ] = None,
    db: str | None = db_option(),
    json_out: JsonOpt = False,
) -> None:
    """Show a calibration's parameters (nm for the prismatic joint, µrad for rotary joints).

    A calibration that averages model families (calibrate --model auto) also shows each
    family's cross-validation error and weight; ◀ marks the family whose parameters are
    listed. --json gives every family's parameters. A number (or #N) that is not a file
    names a calibration kept in the database; -o writes it out for -c.

    Example: stickslip show 1 -o cal.json
    """
    cal, name = _calibration_to_show(calibration, db)
    if output is not None:
        with user_errors():
            cal.save(output)
    if json_out:
        print_json(cal.to_dict())
        return
    console.print(_params_table(cal, f"{name} — day {cal.day}, method {cal.method}"))
    if cal.selection:  # an averaged model: which families, with what weight (◀: the one whose parameters are shown)
        console.print(_selection_table(cal))
    for (j, d), v in sorted(cal.constant_steps.items()):
        s, u = (1e9, "nm") if cal.kind(j) == "prismatic" else step_scale(j)
        say(f"{'constant-step comparator' if cal.models else 'mean step'}, joint {j}{d}: {v * s:.5g} {u}")
    if output is not None:
        say(f"saved to {output}", keep=(output,))


def _calibration_to_show(text: str | None, db: str | None) -> tuple[Calibration, str]:
    """The calibration ``show`` names: a file, or ``N`` / ``#N`` kept in the database; and what to call it."""
    from ..calibration import Calibration
    from ..storage import StoreError

    number = (text or "").strip().lstrip("#")
    if text is not None and number.isdigit() and not Path(text).exists():
        with open_store(db, must_exist=True) as store, user_errors(StoreError):
            try:
                return store.calibration(int(number)), f"calibration #{number} of {store.path}"
            except KeyError as e:
                fail(f"{e.args[0]} in {store.path} (stickslip history lists them)")
    path = calibration_file(None if text is None else Path(text), "CAL.json")
    with user_errors():
        return Calibration.load(path), str(path)


@app.command("predict")
def predict_cmd(
    poses: Annotated[
        Path,
        typer.Argument(
            help="Pose table (CSV): joint,direction,q1,q2,q3,theta,psi[,start,end], SI units; "
            "direction may be left out on rows with start,end; other columns are passed through."
        ),
    ],
    calibration: CalibrationOpt = None,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the CSV here instead of stdout.")] = None,
    interval: Annotated[
        bool, typer.Option("--interval", help="Also add gamma_pi95, the 95 % prediction interval's half-width.")
    ] = False,
    json_out: JsonOpt = False,
) -> None:
    """Predict step sizes: adds a gamma_pred column (m for joint 3, rad for joints 1, 2).

    With --interval also gamma_pi95, the half-width of a 95 % prediction interval: 1.96
    times the relative error the calibration expects in that pose (it grows with the pose's
    distance from the calibrated poses; an assumed one for the paper's exactly determined
    procedure) times gamma_pred. A calibration from another day adds a day's change of step
    (15 %), as plan and move do; a line on standard error says so.

    A row with start,end gets the average step over that traverse (exact integral);
    a row without them gets the step size at its pose (the moving joint at q1/q2/q3).

    Example: stickslip predict -c cal.json poses.csv -o predicted.csv
    """
    from ..calibration.update import day_drift
    from ..measurements import TableError
    from ..procedures.predict import PredictionError, check_pose_file, predict_pose_file, write_csv, write_json

    cal = _load_calibration(calibration)
    drift = day_drift(cal) if interval else 0.0
    rows = [0]

    def emit(f: TextIO) -> None:  # the table streams through, a chunk at a time (any length, bounded memory)
        header, chunks = predict_pose_file(cal, poses, interval, drift)
        rows[0] = write_json(header, chunks, f) if json_out else write_csv(header, chunks, f, interval)

    try:
        if output is None:
            check_pose_file(poses)  # a table that fails further on must not leave half of it on the screen
            emit(data_stream())
        else:
            with user_errors():
                atomic_write(output, emit)  # a failed write or a bad row leaves no half file
    except TableError as e:
        fail_table(e)
    except PredictionError as e:
        fail(str(e))
    if drift:
        warn(f"gamma_pi95 includes a day's change of step, {drift:.0%}: the calibration is from "
             f"{cal.day or 'an unknown day'}, not today")  # on stderr: stdout may be the table
    if output is not None:
        say(f"wrote {rows[0]} rows to {output}", keep=(output,))


@app.command("validate")
def validate_cmd(
    measurements: Annotated[Path, typer.Argument(help="Measurement table (CSV) to compare with.")],
    calibration: CalibrationOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Compare the model with measured traverses, against the paper's constant-step model.

    For each joint: the maximum and mean relative error of the calibrated model's
    average step, and of a constant step (the paper's comparator: the unloaded
    prismatic step a_i; for joint 2 the full-range average at q3 = 0, theta = 0).

    Example: stickslip validate -c cal.json day1-sweep.csv
    """
    from ..calibration import validate
    from ..models import NonPhysicalError

    cal = _load_calibration(calibration)
    traverses = read_table(measurements)
    try:
        res = validate(cal, traverses)
    except KeyError as e:
        fail(str(e.args[0]))
    except NonPhysicalError as e:
        fail(str(e))
    rows = res.rows()
    if json_out:
        print_json(rows)
        return
    title = f"model vs constant step on {len(traverses)} traverses (relative error of the average step)"
    console.print(validation_table(rows, title))


@app.command("plan")
def plan_cmd(
    joint: Annotated[int, typer.Option("--joint", "-j", help="Joint to move: 1, 2 (rotary) or 3 (prismatic).")],
    q_from: Annotated[str, typer.Option("--from", help=(
        "Start position with its unit: -30deg (joints 1, 2), 2mm (joint 3); a bare number other than 0 is "
        "refused."))],
    q_to: Annotated[str, typer.Option("--to", help=(
        "Target position with its unit: -60deg, 2.03mm (a bare number other than 0 is refused)."))],
    calibration: CalibrationOpt = None,
    q1: Annotated[str, typer.Option(help="Joint 1 angle (ignored when moving joint 1).")] = "0",
    q2: Annotated[
        str, typer.Option(help="Joint 2 angle; -90deg holds the arm out (ignored when moving joint 2).")
    ] = "-90deg",
    q3: Annotated[str, typer.Option(help="Joint 3 extension (ignored when moving joint 3).")] = "0",
    theta: Annotated[str, typer.Option(help="Base tilt about x0.")] = "0",
    psi: Annotated[str, typer.Option(help="Base tilt about the new y0.")] = "0",
    json_out: JsonOpt = False,
) -> None:
    """Plan a move: how many steps take a joint from one position to another in a pose.

    Rotary joints integrate the step size along the way (it changes with the gravity
    torque); the predicted end point is where those whole steps land.

    Example: stickslip plan -c cal.json --joint 3 --from 2mm --to 2.03mm --q2 -60deg
    """
    from ..kinematics import JOINTS
    from ..models import NonPhysicalError

    if joint not in JOINTS:
        fail(f"unknown joint {joint} (joints are 1, 2 and 3)")
    from ..motion.planning import plan_move

    pos = angle_option if joint_spec(joint).rotary else length_option
    try:
        qa = pos(q_from)
    except typer.BadParameter as e:
        fail(f"--from: {e.message}")
    try:
        qb = pos(q_to)
    except typer.BadParameter as e:
        fail(f"--to: {e.message}")
    pose = pose_options(q1, q2, q3, theta, psi)
    cal = _load_calibration(calibration)
    try:
        plan = plan_move(cal, joint, qa, qb, pose)
    except KeyError as e:
        fail(str(e.args[0]))
    except (ValueError, NonPhysicalError) as e:
        fail(str(e))
    from ..calibration.intervals import prediction_sd

    sd, assumed = prediction_sd(cal, joint, plan.direction, max(plan.steps, 1), pose=tuple(pose),
                                span=(plan.q_from, plan.q_end_predicted))
    from ..calibration.update import day_drift

    drift = day_drift(cal)
    sd = math.hypot(sd, drift)
    half = 1.96 * sd * abs(plan.q_end_predicted - plan.q_from)
    if json_out:
        d = plan.as_dict()
        d["pi95"] = half
        d["pi95_assumed"] = assumed
        d["pi95_day_drift"] = drift
        print_json(d)
        return
    err = plan.q_end_predicted - plan.q_to
    say(
        f"joint {joint}: {plan.steps} steps in direction {plan.direction} "
        f"from {format_position(plan.q_from, joint)} to {format_position(plan.q_to, joint)}"
    )
    say(
        f"  predicted end {format_position(plan.q_end_predicted, joint)} "
        f"(off by {format_position(err, joint, 3)}; step {format_step(plan.gamma_start, joint)} at the start, "
        f"{format_step(plan.gamma_end, joint)} at the target)",
        indent="    ",
    )
    say(
        f"  the move: {format_position(abs(plan.q_end_predicted - plan.q_from), joint)} "
        f"± {format_position(half, joint, 3)} (95 % prediction interval)"
        + (" (model error assumed: the calibration has none)" if assumed else "")
        + (f" (with a day's change of step, {drift:.0%}: the calibration is from another day)" if drift else ""),
        indent="    ",
    )
    if math.isclose(plan.q_from, plan.q_to):
        say("  nothing to do: start and target are the same")
