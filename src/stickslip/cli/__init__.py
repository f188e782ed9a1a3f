"""The ``stickslip`` command line: a thin shell over the library.

Each area keeps its commands in its own module, which adds them to :data:`app`:

* :mod:`.core`     calibrate, predict, validate, plan, show
* :mod:`.measure`  demo
* :mod:`.audio`    tune, listen
* :mod:`.history`  history, export, import, anova, fit, report
* :mod:`.devices`  move, where
"""

from __future__ import annotations

import inspect

import typer

from ._common import OneLineErrors, drop_warnings, flush_warnings

app = typer.Typer(
    name="stickslip",
    cls=OneLineErrors,
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


def _done(*_args: object, **_kwargs: object) -> None:
    """A command that returned normally prints the warnings it queued (a failed one does not)."""
    flush_warnings()


@app.callback(result_callback=_done)
def _root() -> None:
    """stickslip: calibrate, predict and plan stick-slip steps (see the commands below)."""
    drop_warnings()


from . import audio, core, devices, history, measure  # noqa: E402,F401  (they register their commands)


def _unwrap(doc: str) -> str:
    """Join the hard-wrapped lines of each paragraph, so rich wraps help text to the terminal.

    Paragraphs are separated by blank lines; lines that start a list item or are indented
    keep their breaks.
    """
    out = []
    for para in inspect.cleandoc(doc).split("\n\n"):
        lines = para.splitlines()
        if any(ln.startswith((" ", "-", "*", "$")) for ln in lines[1:]):
            out.append(para)
        else:
            out.append(" ".join(ln.strip() for ln in lines))
    return "\n\n".join(out)


_PANELS = {
    "Measure": ("demo", "traverse", "tune", "listen"),
    "Calibrate and predict": ("calibrate", "fit", "show", "predict", "validate", "plan"),
    "Drive a manipulator": ("move", "where"),
    "Keep and study": ("history", "import", "export", "exclude", "delete", "anova", "report"),
}
_PANEL_OF = {name: panel for panel, names in _PANELS.items() for name in names}
_ORDER = [name for names in _PANELS.values() for name in names]


def _name(info) -> str:
    return info.name or info.callback.__name__.replace("_cmd", "").replace("_", "-")


for _info in app.registered_commands:
    if _info.callback is not None and _info.callback.__doc__ and _info.help is None:
        _info.callback.__doc__ = _unwrap(_info.callback.__doc__)
    _info.rich_help_panel = _PANEL_OF.get(_name(_info), "Other")
app.registered_commands.sort(key=lambda i: _ORDER.index(_name(i)) if _name(i) in _ORDER else len(_ORDER))


def main() -> None:
    """Console entry point."""
    app()
