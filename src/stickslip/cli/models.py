"""Model commands: suggest (which traverses next)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from ..records import atomic_write_text
from . import app
from ._common import calibration_file, console, fail, print_json, user_errors


@app.command("suggest")
def suggest_cmd(
    calibration: Annotated[
        Path | None,
        typer.Option(
            "--calibration",
            "-c",
            help="Calibration JSON written by 'stickslip calibrate' (default: calibration in the config file).",
        ),
    ] = None,
    joint: Annotated[
        list[int] | None, typer.Option("--joint", "-j", help="Joint(s) to plan for (default: all calibrated).")
    ] = None,
    n: Annotated[int, typer.Option("--n", help="Poses to suggest per joint (1-20).")] = 4,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the poses as a pose table (CSV, SI units).")
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print machine-readable JSON instead of a table.")] = False,
) -> None:
    """Suggest the poses whose traverses would most reduce the prediction uncertainty.

    For each joint, the calibration's model is linearised in its parameters and poses are
    chosen greedily from random workspace poses (tilts within ±90° and ±60°) so as to
    minimise the average variance of the predicted step over the workspace (I-optimal
    design), traversing each pose in both directions. The table shows how the RMS
    relative uncertainty of a prediction falls with each pose.

    Example: stickslip suggest -c cal.json --n 4 -o next.csv
    """
    if not 1 <= n <= 20:
        fail(f"--n {n} is outside 1..20")
    from numpy.linalg import LinAlgError

    from ..calibration import Calibration
    from ..calibration.design import suggest_poses

    path = calibration_file(calibration)
    with user_errors():
        cal = Calibration.load(path)
    joints = sorted(set(joint or cal.joints))
    rows = []
    for j in joints:
        if j not in cal.joints:
            fail(f"joint {j} is not in this calibration (it has: {', '.join(map(str, cal.joints))})")
        try:
            rows.extend(suggest_poses(cal, j, n))
        except (ValueError, TypeError, LinAlgError) as e:
            fail(f"joint {j}: {e}")
    if output is not None:
        lines = ["joint,direction,q1,q2,q3,theta,psi"]
        for s in rows:
            for d in sorted(dd for jj, dd in cal.models if jj == s.joint):
                lines.append(",".join([str(s.joint), d, *(repr(float(v)) for v in s.pose)]))
        with user_errors():
            atomic_write_text(output, "\n".join(lines) + "\n")
    if json_out:
        print_json([s.as_dict() for s in rows])
        return
    t = Table(title="suggested traverses (both directions at each pose), greedy I-optimal design")
    for col in ("joint", "q1", "q2", "q3", "theta", "psi", "RMS sd before", "after"):
        t.add_column(col, justify="right")
    for s in rows:
        p = s.pose
        t.add_row(
            str(s.joint), f"{math.degrees(p.q1):.1f}°", f"{math.degrees(p.q2):.1f}°", f"{p.q3 * 1e3:.2f} mm",
            f"{math.degrees(p.theta):.1f}°", f"{math.degrees(p.psi):.1f}°",
            f"{s.rms_sd_before * 100:.2f} %", f"{s.rms_sd_after * 100:.2f} %",
        )
    console.print(t)
    if output is not None:
        console.print(f"wrote {output}")

