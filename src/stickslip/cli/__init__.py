"""The ``stickslip`` command line: a thin shell over the library.

Each area keeps its commands in its own module, which adds them to :data:`app`:

* :mod:`.core`     calibrate, predict, validate, plan, show
* :mod:`.measure`  demo
* :mod:`.audio`    tune, listen
* :mod:`.history`  history, export, import, backup, anova, fit, report
* :mod:`.models`   suggest
* :mod:`.devices`  move, where
* :mod:`.observe`  observe (a measured position into the dead reckoning)
* :mod:`.taskspace` reach, jog
* :mod:`.serve`    serve (the control room: a web page and an API)
* :mod:`.config`   config path, config show, config init (the user's configuration file)
* :mod:`.camera`   camera locate, camera calibrate, camera grab (see the tip)
"""

from __future__ import annotations

import inspect
from pathlib import Path

import typer
from typer.models import CommandInfo

from ._common import DEVICE_FILTERS, OneLineErrors, describe, drop_warnings, flush_warnings, guard_options
from ._help import HelpCommand

app = typer.Typer(
    name="stickslip",
    cls=OneLineErrors,
    help=(
        "Make piezoelectric stick-slip micromanipulators predictable without joint sensors.\n\n"
        "Measure a joint's average step size between its end stops, calibrate the load-aware "
        "step-size model, and turn 'move 30 um' into the right number of steps in any pose.\n\n"
        "Files are SI (metres, radians); on the command line every length and angle takes its "
        "unit: 12mm, 850nm, -90deg, 40urad, -pi/2 (a bare number other than 0 is refused). A file option "
        "(-o, -c, --db) takes a file's name: one that ends with / names a folder and is refused, as curl -o "
        "refuses it; an option shown as FOLDER (demo -o, report -o) takes a folder."
    ),
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode="rich",
    pretty_exceptions_enable=False,
)


def _done(*_args: object, **_kwargs: object) -> None:
    """A command that returned normally prints the warnings it queued (a failed one does not)."""
    flush_warnings()


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"stickslip {__version__}")
        raise typer.Exit()


def _logging(verbose: int, log_file: Path | None) -> None:
    """-v: INFO to stderr, -vv: DEBUG (every message to and from a controller); --log-file: DEBUG to a file."""
    import logging

    from ..devices.base import RedactText

    log = logging.getLogger("stickslip")
    for old in [h for h in log.handlers if getattr(h, "_stickslip_cli", False)]:
        log.removeHandler(old)
        old.close()
    from ._output import visible

    class Visible(logging.Formatter):  # a log line on the terminal follows the output rules (docs/cli.md)
        def format(self, record: logging.LogRecord) -> str:
            return visible(super().format(record))

    fmt = logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
    handlers: list[logging.Handler] = []
    if verbose:
        h: logging.Handler = logging.StreamHandler()
        h.setLevel(logging.INFO if verbose == 1 else logging.DEBUG)
        h.setFormatter(Visible(fmt._fmt))
        handlers.append(h)
    if log_file is not None:
        from ..records import writable_target
        from ._common import path_option
        from ._logfile import LogFile

        try:
            path_option(log_file)  # --log-file -v: a value left out, not a log named '-v'
        except typer.BadParameter as e:
            raise typer.BadParameter(e.message, param_hint="--log-file") from None
        try:
            h = LogFile(writable_target(log_file, "log"), encoding="utf-8")  # never a FIFO: it would hang
        except (OSError, ValueError) as e:
            raise typer.BadParameter(f"cannot write the log file: {describe(e)}", param_hint="--log-file") from None
        h.setLevel(logging.DEBUG)
        handlers.append(h)
    for h in handlers:
        if h.formatter is None:
            h.setFormatter(fmt)
        h.addFilter(RedactText())  # every log line through the one redaction
        h._stickslip_cli = True  # type: ignore[attr-defined]  # to find ours again on the next call
        log.addHandler(h)
    log.setLevel(logging.DEBUG if handlers else logging.NOTSET)


def _log_file_text(value: str | Path) -> Path:
    """``--log-file`` as typed: ``lg/`` names a folder (pathlib would drop the ``/`` and write a file ``lg``)."""
    from ._common import path_text

    return path_text()(value)


@app.callback(result_callback=_done)
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
    verbose: int = typer.Option(
        0, "--verbose", "-v", count=True, help="-v: progress messages; -vv: also every message to and from a device."
    ),
    log_file: Path | None = typer.Option(
        None, "--log-file", help="Also write a DEBUG log (device traffic, passwords redacted) to this file.",
        parser=_log_file_text,
    ),
) -> None:
    """stickslip: calibrate, predict and plan stick-slip steps (see the commands below)."""
    drop_warnings()
    _logging(verbose, log_file)


from . import audio, camera, config, core, devices, history, measure, models, observe, rig, serve, taskspace  # noqa: E402,F401  (they register their commands)


def _unwrap(doc: str) -> str:
    """Join the hard-wrapped lines of each paragraph, so rich wraps help text to the terminal.

    Paragraphs are separated by blank lines; lines that start a list item or are indented
    keep their breaks.
    """
    out = []
    for para in inspect.cleandoc(doc).split("\n\n"):
        lines = para.splitlines()
        if any(ln.startswith((" ", "- ", "* ", "$")) for ln in lines[1:]):
            out.append(para)
        else:
            out.append(" ".join(ln.strip() for ln in lines))
    return "\n\n".join(out)


_PANELS = {
    "Measure": ("demo", "traverse", "record", "tune", "listen"),
    "Calibrate and predict": ("calibrate", "fit", "show", "predict", "validate", "plan", "suggest"),
    "Drive a manipulator": ("move", "observe", "where", "reach", "jog", "serve"),
    "Keep and study": ("history", "import", "export", "backup", "exclude", "delete", "anova", "report"),
}
_PANEL_OF = {name: panel for panel, names in _PANELS.items() for name in names}
_ORDER = [name for names in _PANELS.values() for name in names]


def _name(info: CommandInfo) -> str:
    if info.name:
        return info.name
    callback = info.callback
    return "" if callback is None else callback.__name__.replace("_cmd", "").replace("_", "-")


for _info in app.registered_commands:
    if _info.callback is not None:
        # finite floats, non-blank --day, a --device that can be opened: the checks every command shares
        guard_options(_info.callback, device_is_filter=_name(_info) in DEVICE_FILTERS)
    if _info.callback is not None and _info.callback.__doc__ and _info.help is None:
        _info.callback.__doc__ = _unwrap(_info.callback.__doc__)
    _info.rich_help_panel = _PANEL_OF.get(_name(_info), "Other")
    _info.cls = HelpCommand  # --help fits the terminal without cutting a word (._help)
for _group in app.registered_groups:  # the commands of a group (config path, show, init)
    for _sub in _group.typer_instance.registered_commands if _group.typer_instance else []:
        if _sub.callback is not None:
            guard_options(_sub.callback)
        if _sub.callback is not None and _sub.callback.__doc__ and _sub.help is None:
            _sub.callback.__doc__ = _unwrap(_sub.callback.__doc__)
        _sub.cls = HelpCommand
app.registered_commands.sort(key=lambda i: _ORDER.index(_name(i)) if _name(i) in _ORDER else len(_ORDER))


def main() -> None:
    """Console entry point."""
    app()
