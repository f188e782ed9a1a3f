"""One rig's day against a shared database, through the command line: the test of several rigs runs one per process.

``python tests/support/shared_rig.py URL DEVICE TABLE CAL`` prints :func:`run_rig`'s
outputs as one JSON object (exit 1 with the failing command's output otherwise).
"""

from __future__ import annotations

import json
import sys
from typing import Any

__all__ = ["run_rig"]


def run_rig(db: str, device: str, table: str, cal: str) -> dict[str, Any]:
    """Import ``table`` as ``device``'s traverses, fit and record a calibration (to ``cal``), move joint 3
    by 30 µm on the simulator, and read the kept position back: ``{command: its --json output}``."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    steps = (
        ("import", ["import", table, "--device", device, "--json"]),
        ("fit", ["fit", "--device", device, "--record", "-o", cal, "--json"]),
        ("move", ["move", "-d", device, "-c", cal, "--joint", "3", "--by", "30um", "--json"]),
        ("where", ["where", "-d", device, "--offline", "--json"]),
    )
    out: dict[str, Any] = {}
    for name, args in steps:
        r = CliRunner().invoke(app, [*args, "--db", db])
        if r.exit_code != 0:
            raise RuntimeError(f"{device}: stickslip {name} failed: {r.output}")
        out[name] = json.loads(r.stdout)
    return out


if __name__ == "__main__":  # pragma: no cover - run as a subprocess by the tests
    try:
        print(json.dumps(run_rig(*sys.argv[1:5])))
    except RuntimeError as e:
        sys.exit(str(e))
