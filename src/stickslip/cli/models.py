"""Model commands: suggest (which traverses next)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from ..records import atomic_write_text
from . import app
from ._common import calibration_file, console, fail, print_json, say, user_errors

if TYPE_CHECKING:
    from ..calibration.design import Suggestion


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
    check: Annotated[
        int | None,
        typer.Option(
            "--check",
            metavar="<N>",
            help="Instead: N random workspace poses per joint (1-20) for check traverses, measured after the "
            "calibration's and given to 'calibrate --check' (docs/models.md §4).",
            show_default=False,
        ),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="With --check: the random poses' seed (another seed, "
                                      "other poses; the same seed, the same poses).", min=0)] = 0,
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

    With --check N the poses are random instead (N a joint, each in both directions): check
    traverses, which show how far the calibration's intervals are from its errors between the
    calibrated poses ('calibrate TABLE --check CHECK.csv' scales the intervals by them).

    Example: stickslip suggest -c cal.json --n 4 -o next.csv

    Example: stickslip suggest -c cal.json --check 2 --seed 7 -o check-poses.csv
    """
    if not 1 <= n <= 20:
        fail(f"--n {n} is outside 1..20")
    if check is not None and not 1 <= check <= 20:
        fail(f"--check {check} is outside 1..20")
    if check is None and seed != 0:
        fail("--seed draws the random poses of --check: give --check N too (the designed poses have no seed)")
    from numpy.linalg import LinAlgError

    from ..calibration import Calibration
    from ..calibration.design import Suggestion, check_poses, suggest_poses

    path = calibration_file(calibration)
    with user_errors():
        cal = Calibration.load(path)
    joints = sorted(set(joint or cal.joints))
    rows: list[Suggestion] = []
    for j in joints:
        if j not in cal.joints:
            fail(f"joint {j} is not in this calibration (it has: {', '.join(map(str, cal.joints))})")
        if check is not None:
            rows.extend(Suggestion(j, pose, math.nan, math.nan) for pose in check_poses(j, check, seed))
            continue
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
        print_json([_check_dict(s) if check is not None else s.as_dict() for s in rows])
        return
    title = ("check traverses (both directions at each pose): random workspace poses, measured after the "
             "calibration's, not fitted" if check is not None else
             "suggested traverses (both directions at each pose), greedy I-optimal design")
    t = Table(title=title)
    for col in ("joint", "q1", "q2", "q3", "theta", "psi", *(("RMS sd before", "after") if check is None else ())):
        t.add_column(col, justify="right")
    for s in rows:
        p = s.pose
        sd = () if check is not None else (f"{s.rms_sd_before * 100:.2f} %", f"{s.rms_sd_after * 100:.2f} %")
        t.add_row(
            str(s.joint), f"{math.degrees(p.q1):.1f}°", f"{math.degrees(p.q2):.1f}°", f"{p.q3 * 1e3:.2f} mm",
            f"{math.degrees(p.theta):.1f}°", f"{math.degrees(p.psi):.1f}°", *sd,
        )
    console.print(t)
    if output is not None:
        say(f"wrote {output}", keep=(output,))



def _check_dict(s: Suggestion) -> dict[str, object]:
    """A check pose as JSON (SI units): its joint and pose, no uncertainty (it is random, not designed)."""
    return {"joint": s.joint, **{k: float(v) for k, v in s.pose._asdict().items()}}
