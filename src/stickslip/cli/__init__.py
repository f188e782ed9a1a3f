"""The ``stickslip`` command line: a thin shell over the library.

Each area keeps its commands in its own module, which adds them to :data:`app`:

* :mod:`.core`     calibrate, predict, validate, plan, show
* :mod:`.measure`  demo
* :mod:`.audio`    tune, listen
* :mod:`.history`  history, export, import, anova, fit, report
* :mod:`.devices`  move, where
"""

from __future__ import annotations

import typer

app = typer.Typer(
    name="stickslip",
    help=(
        "Make piezoelectric stick-slip micromanipulators predictable without joint sensors.\n\n"
        "Measure a joint's average step size between its end stops, calibrate the load-aware "
        "step-size model, and turn 'move 30 um' into the right number of steps in any pose.\n\n"
        "Files are SI (metres, radians); on the command line lengths and angles also take "
        "units: 12mm, 850nm, -90deg, 40urad, -pi/2."
    ),
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode="rich",
    pretty_exceptions_enable=False,
)



@app.callback()
def _root() -> None:
    """stickslip: calibrate, predict and plan stick-slip steps (see the commands below)."""


from . import audio, core, devices, history, measure  # noqa: E402,F401  (they register their commands)


def main() -> None:
    """Console entry point."""
    app()
