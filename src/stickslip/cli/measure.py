"""Measurement commands: demo, tune, listen."""

from __future__ import annotations

import typer

from . import app
from ._common import console


@app.command()
def demo(json_out: bool = typer.Option(False, "--json", help="Print the summary as one JSON object.")) -> None:
    """Run the whole calibration story on the simulated MM3A (no hardware needed)."""
    console.print("stickslip demo: the simulated MM3A is coming with the measurement issue.")
