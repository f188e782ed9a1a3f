"""Measurement commands: ``demo`` (the whole story on the simulated MM3A)."""

from __future__ import annotations

from pathlib import Path

import typer

from . import app
from ._common import console, print_json, user_errors, validation_table


def _scale(name: str, joint: int) -> tuple[float, str]:
    if name == "b":
        return 1.0, ""
    return (1e9, "nm") if joint == 3 else (1e6, "µrad")


@app.command()
def demo(
    seed: int = typer.Option(
        0, "--seed", help="Simulator seed: drift of the true parameters, step noise, room sound."
    ),
    day: str = typer.Option(
        None,
        "--day",
        help="Session label, e.g. 2026-11-22 (default: today). The truth drifts from day to day.",
    ),
    out: Path = typer.Option(
        Path("stickslip-results"),
        "--out",
        help="Results folder: measurements.csv, calibration.json, tunings, summary.",
    ),
    validation: bool = typer.Option(
        True,
        "--validation/--no-validation",
        help="Also measure the validation sweep of other poses.",
    ),
    json_out: bool = typer.Option(
        False, "--json", help="Print the summary as one JSON object (SI units)."
    ),
    db: Path = typer.Option(
        None,
        "--db",
        help="Record every traverse and the calibration in this SQLite file "
        "(default: $STICKSLIP_DB, else the user's data folder).",
    ),
    use_db: bool = typer.Option(True, "--db-record/--no-db", help="Record into the database (default) or not."),
) -> None:
    """Run the whole calibration story on the simulated MM3A (no hardware needed).

    Tunes the audio limit switch for each joint from a simulated recording, runs the seed's 14 calibration traverses (6 prismatic, 8 of joint 2) timed by ear, calibrates, prints the parameters beside the simulator's truth (nm, µrad) with their errors, validates the model against other poses (model vs constant step) and saves measurements (CSV), calibration and tunings (JSON) into --out.

    Example: stickslip demo --seed 3 --day 2026-11-22 --out results/
    """  # noqa: E501
    from ..calibration import CalibrationError
    from ..demo import run_demo
    from ..storage import Store, StoreError
    from ..traverse import TraverseError

    with user_errors(CalibrationError, TraverseError, StoreError):
        store = Store.open(db) if use_db else None
        try:
            result = run_demo(
                seed=seed, day=day, out=out, progress=not json_out, validation=validation, store=store
            )
        finally:
            if store is not None:
                store.close()
    if json_out:
        print_json(result.to_dict())
        return

    from rich.table import Table

    console.print(
        f"[bold]stickslip demo[/]: simulated MM3A, seed {result.seed}, day {result.day}: "
        f"{len(result.traverses)} calibration traverses ({result.device_s:.0f} s on the device "
        f"in {result.elapsed_s:.1f} s), method {result.calibration.method}"
    )
    table = Table(title="Calibrated parameters beside the simulator's truth")
    with_se = any(p.get("stderr") is not None for p in result.parameters)
    cols = ["joint", "dir", "parameter", "q3", "calibrated", "true", "error"]
    if with_se:
        cols.insert(5, "± s.e.")
    for col in cols:
        table.add_column(col, justify="left" if col == "parameter" else "right")
    for p in result.parameters:
        scale, unit = _scale(p["name"], p["joint"])
        se = p.get("stderr")
        error = f"{p['error']:+.4f}" if p["name"] == "b" else f"{p['rel_error']:+.2%}"
        cells = [
            str(p["joint"]),
            p["direction"],
            f"{p['name']} [{unit}]" if unit else p["name"],
            "" if p["q3"] is None else f"{p['q3'] * 1e3:g} mm",
            f"{p['value'] * scale:.4g}",
            f"{p['true'] * scale:.4g}",
            error,
        ]
        if with_se:
            cells.insert(5, "" if se is None else f"{se * scale:.2g}")
        table.add_row(*cells)
    console.print(table)
    if result.validation is not None:
        title = "Validation on other poses: |relative error| of the average step"
        console.print(validation_table(result.validation.rows(), title))
    for what, path in result.files.items():
        console.print(f"saved {what}: {path}", highlight=False)
