"""Core commands: calibrate, predict, validate, plan, show."""

from __future__ import annotations

import csv
import io
import math
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from ..calibration import Calibration, CalibrationError, calibrate, validate
from ..clock import stale_message
from ..kinematics import JOINTS, Pose
from ..measurements import TableError, read_measurements, read_pose_table
from ..models import NonPhysicalError
from ..units import format_position, format_step
from . import app
from ._common import angle_option, console, fail, length_option, print_json, user_errors, validation_table, warn_later

CalibrationOpt = Annotated[
    Path, typer.Option("--calibration", "-c", help="Calibration JSON written by 'stickslip calibrate' or 'fit'.")
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print machine-readable JSON instead of a table.")]


def _fail_table(e: TableError) -> None:
    fail("\n".join(e.problems))


def _load_calibration(path: Path) -> Calibration:
    with user_errors():
        cal = Calibration.load(path)
    msg = stale_message(cal.day)
    if msg:
        warn_later(msg)
    return cal


def _read_table(path: Path):
    try:
        return read_measurements(path)
    except TableError as e:
        _fail_table(e)


def _step_unit(joint: int) -> tuple[float, str]:
    return (1e9, "nm") if joint == 3 else (1e6, "µrad")


def _params_table(cal: Calibration, title: str) -> Table:
    t = Table(title=title)
    for col in ("joint", "dir", "parameter", "q3", "value", "std. error", "unit"):
        t.add_column(col, justify="right" if col in ("value", "std. error") else "left")
    for r in cal.parameters():
        if r["name"] in ("b", "b2", "k"):
            scale, unit = 1.0, "1"
        else:
            scale, unit = _step_unit(int(r["joint"]))
        q3 = f"{r['q3'] * 1e3:g} mm" if r["q3"] is not None else ""
        se = f"{r['stderr'] * scale:.3g}" if r["stderr"] is not None else "—"
        t.add_row(str(r["joint"]), str(r["direction"]), str(r["name"]), q3, f"{r['value'] * scale:.5g}", se, unit)
    return t


@app.command("calibrate")
def calibrate_cmd(
    measurements: Annotated[
        Path,
        typer.Argument(
            help="Measurement table (CSV, header day,joint,direction,q1,q2,q3,theta,psi,start,end,steps; SI units)."
        ),
    ],
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the calibration JSON here.")] = None,
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
    model: Annotated[
        str,
        typer.Option(
            "--model",
            help="auto | paper | a family name (docs/models.md). 'auto': the paper's procedure where a joint's "
            "traverses are exactly the paper's poses, else every model family the data identify, chosen by "
            "leave-one-pose-out cross-validation. 'paper': the paper's models only (also what 'auto' means "
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
        float, typer.Option(help="With --prior: prior standard deviation of a day's change of step scale (relative).")
    ] = 0.15,
    json_out: JsonOpt = False,
) -> None:
    """Calibrate the step-size models from measured traverses.

    The paper's procedure needs, for the prismatic joint, traverses in + and - at
    (q2, theta, psi) = (-90deg, 0, 0), (0, -90deg, 0), (0, 0, 0) (Eqs. 4-6), and for
    joint 2 full-range traverses at (q3, theta, psi) = (0, 0, 0), (12mm, 0, 0),
    (12mm, -90deg, 0), (0, -90deg, 0); d is found by inverting the exact average-step
    integral. Any other set of traverses is fitted by least squares, with standard errors.

    With more traverses than the paper's poses, every model family the data can
    identify is fitted and one is chosen by leave-one-pose-out cross-validation; the
    table says which, why, and the CV error of each. With --prior, an earlier
    calibration is brought up to date with as few as one traverse per joint and direction.

    Example: stickslip calibrate day1.csv -o cal.json
    Example: stickslip calibrate today4.csv --prior yesterday.json -o today.json
    """
    traverses = _read_table(measurements)
    try:
        if prior is not None:
            from ..calibration.update import update_calibration

            with user_errors():
                old = Calibration.load(prior)
            cal, _ = update_calibration(old, traverses, drift=drift, day=day, source=str(measurements))
        else:
            cal = calibrate(traverses, method=method, day=day, source=str(measurements), model=model)
    except (CalibrationError, NonPhysicalError, ValueError, KeyError) as e:
        fail(str(e.args[0]) if isinstance(e, KeyError) else str(e))
    if output is not None:
        with user_errors():
            cal.save(output)
    if json_out:
        print_json(cal.to_dict())
        return
    console.print(_params_table(cal, f"calibration — day {cal.day}, method {cal.method}, {len(traverses)} traverses"))
    if cal.selection:
        console.print(_selection_table(cal))
    for n in cal.provenance.get("notes", []) or []:
        console.print(f"[dim]note:[/] {n}", highlight=False)
    if output is not None:
        console.print(f"saved to {output}")


def _selection_table(cal: Calibration) -> Table:
    t = Table(title="model families: leave-one-pose-out cross-validation (relative error of the average step)")
    for col in ("joint", "family", "params (+ and -)", "CV RMS", "CV max", "fit RMS", "status"):
        t.add_column(col, justify="right" if col.startswith(("CV", "fit", "params")) else "left")
    seen: set[int] = set()
    for (j, _d), sel in sorted(cal.selection.items()):
        if j in seen:  # one selection per joint (both directions are fitted together)
            continue
        seen.add(j)
        chosen = sel.get("chosen")
        for sc in sel.get("scores", []) or []:  # type: ignore[union-attr]

            def pct(x: object) -> str:
                return f"{float(x) * 100:.2f} %" if isinstance(x, (int, float)) else "—"

            mark = " ◀ chosen" if sc["family"] == chosen else ""
            t.add_row(str(j), f"{sc['family']}{mark}", str(sc["n_params"]), pct(sc["cv_rms"]), pct(sc["cv_max"]),
                      pct(sc["fit_rms"]), str(sc["status"]))
    return t


@app.command("show")
def show_cmd(
    calibration: Annotated[Path, typer.Argument(help="Calibration JSON.")],
    json_out: JsonOpt = False,
) -> None:
    """Show a calibration's parameters (nm for the prismatic joint, µrad for rotary joints)."""
    with user_errors():
        cal = Calibration.load(calibration)
    if json_out:
        print_json(cal.to_dict())
        return
    console.print(_params_table(cal, f"{calibration} — day {cal.day}, method {cal.method}"))
    for (j, d), v in sorted(cal.constant_steps.items()):
        s, u = _step_unit(j)
        console.print(f"constant-step comparator, joint {j}{d}: {v * s:.5g} {u}", highlight=False)


@app.command("predict")
def predict_cmd(
    poses: Annotated[
        Path,
        typer.Argument(
            help="Pose table (CSV): joint,direction,q1,q2,q3,theta,psi[,start,end], SI units; "
            "direction may be left out on rows with start,end; other columns are passed through."
        ),
    ],
    calibration: CalibrationOpt,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the CSV here instead of stdout.")] = None,
    json_out: JsonOpt = False,
) -> None:
    """Predict step sizes: adds gamma_pred and gamma_pi95 columns (m for joint 3, rad for joints 1, 2).

    gamma_pi95 is the half-width of a 95 % prediction interval: 1.96 times the
    calibration's relative model error (its leave-one-pose-out error; an assumed one
    for the paper's exactly determined procedure) times gamma_pred.

    A row with start,end gets the average step over that traverse (exact integral);
    a row without them gets the step size at its pose (the moving joint at q1/q2/q3).

    Example: stickslip predict -c cal.json poses.csv -o predicted.csv
    """
    cal = _load_calibration(calibration)
    try:
        header, rows, queries = read_pose_table(poses)
    except TableError as e:
        _fail_table(e)
    from ..calibration.update import prediction_sd

    preds = []
    sds = []
    for i, q in enumerate(queries, start=1):
        try:
            m = cal.model(q.joint, q.direction)
            if q.is_traverse:
                g = float(m.average_gamma(q.start, q.end, q.q1, q.q2, q.q3, q.theta, q.psi))
            else:
                g = float(m.gamma(q.q1, q.q2, q.q3, q.theta, q.psi))
        except KeyError as e:
            fail(f"{poses}: row {i}: {e.args[0]}")
        except NonPhysicalError as e:
            fail(f"{poses}: row {i}: {e}")
        preds.append(g)
        sds.append(prediction_sd(cal, q.joint, q.direction)[0])
    extra = [c for c in ("gamma_pi95", "gamma_pred") if c not in header]  # gamma_pred stays last
    out_header = header + extra
    records = []
    for row, g, sd in zip(rows, preds, sds, strict=True):
        rec = dict(row)
        rec["gamma_pred"] = repr(g)
        rec["gamma_pi95"] = repr(1.96 * sd * g)
        records.append(rec)
    if json_out:
        out = []
        for rec, g, sd in zip(records, preds, sds, strict=True):
            r = {k: _maybe_number(v) for k, v in rec.items()}
            r["gamma_pred"] = g
            r["gamma_pi95"] = 1.96 * sd * g
            out.append(r)
        print_json(out)
        return
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=out_header, lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    w.writerows(records)
    if output is None:
        sys.stdout.write(buf.getvalue())
    else:
        with user_errors():
            output.write_text(buf.getvalue(), encoding="utf-8")
        console.print(f"wrote {len(records)} rows to {output}")


def _maybe_number(v: str) -> object:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return v
    if x.is_integer() and v.strip().lstrip("+-").isdigit():
        return int(x)
    return x


@app.command("validate")
def validate_cmd(
    measurements: Annotated[Path, typer.Argument(help="Measurement table (CSV) to compare with.")],
    calibration: CalibrationOpt,
    json_out: JsonOpt = False,
) -> None:
    """Compare the model with measured traverses, against the paper's constant-step model.

    For each joint: the maximum and mean relative error of the calibrated model's
    average step, and of a constant step (the paper's comparator: the unloaded
    prismatic step a_i; for joint 2 the full-range average at q3 = 0, theta = 0).

    Example: stickslip validate -c cal.json day1-sweep.csv
    """
    cal = _load_calibration(calibration)
    traverses = _read_table(measurements)
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
    calibration: CalibrationOpt,
    joint: Annotated[int, typer.Option("--joint", "-j", help="Joint to move: 1, 2 (rotary) or 3 (prismatic).")],
    q_from: Annotated[str, typer.Option("--from", help="Start position: rad / m, or with units (-30deg, 2mm).")],
    q_to: Annotated[str, typer.Option("--to", help="Target position: rad / m, or with units (-60deg, 2.03mm).")],
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
    if joint not in JOINTS:
        fail(f"unknown joint {joint} (joints are 1, 2 and 3)")
    from ..planning import plan_move

    pos = length_option if joint == 3 else angle_option
    try:
        qa, qb = pos(q_from), pos(q_to)
        pose = Pose(angle_option(q1), angle_option(q2), length_option(q3), angle_option(theta), angle_option(psi))
    except typer.BadParameter as e:
        fail(str(e))
    cal = _load_calibration(calibration)
    try:
        plan = plan_move(cal, joint, qa, qb, pose)  # type: ignore[arg-type]
    except KeyError as e:
        fail(str(e.args[0]))
    except (ValueError, NonPhysicalError) as e:
        fail(str(e))
    from ..calibration.update import prediction_sd

    sd, assumed = prediction_sd(cal, joint, plan.direction, max(plan.steps, 1))
    half = 1.96 * sd * abs(plan.q_end_predicted - plan.q_from)
    if json_out:
        d = plan.as_dict()
        d["pi95"] = half
        d["pi95_assumed"] = assumed
        print_json(d)
        return
    err = plan.q_end_predicted - plan.q_to
    console.print(
        f"joint {joint}: {plan.steps} steps in direction {plan.direction} "
        f"from {format_position(plan.q_from, joint)} to {format_position(plan.q_to, joint)}",
        highlight=False,
    )
    console.print(
        f"  predicted end {format_position(plan.q_end_predicted, joint)} "
        f"(off by {format_position(err, joint, 3)}; step {format_step(plan.gamma_start, joint)} at the start, "
        f"{format_step(plan.gamma_end, joint)} at the target)",
        highlight=False,
    )
    console.print(
        f"  95 % prediction interval of the move: {format_position(abs(plan.q_end_predicted - plan.q_from), joint)} "
        f"± {format_position(half, joint, 3)}"
        + (" (model error assumed: the calibration has none)" if assumed else ""),
        highlight=False,
    )
    if math.isclose(plan.q_from, plan.q_to):
        console.print("  nothing to do: start and target are the same")
