"""Shared pieces of the command line: consoles, errors, unit options, JSON output.

Every command exits 2 with a one-line reason on bad input (never a traceback),
offers ``--json`` where it prints results, and labels units in what people read.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import re
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, Generic, NoReturn, TypeVar, overload

import typer
from rich.text import Text
from typer.core import TyperGroup

try:  # recent typer vendors click; older ones use the click package
    from typer._click.exceptions import ClickException, UsageError
except ImportError:  # pragma: no cover - depends on the installed typer
    from click.exceptions import ClickException, UsageError  # type: ignore[assignment]  # same names

from ..config import ConfigError, UserConfig, config_path, load_config
from ..devices.base import check_device_url, redact_text, redact_url
from ..units import UnitError, bare_number_problem, parse_angle, parse_length
from ._output import OutputError, console, data_stream, err_console, finish, silence, styled, visible

if TYPE_CHECKING:
    from rich.table import Table

    from ..kinematics import Geometry, Pose
    from ..measurements import StepSize, TableError, Traverse
    from ..storage import Store


def lazy_import(name: str) -> ModuleType:
    """The module ``name``, loaded on first attribute access (so ``--help`` never loads numpy).

    For a command module whose module-level names come from the numpy layers; a module
    already loaded is returned as it is.
    """
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:  # pragma: no cover - a packaging fault
        raise ImportError(f"no module named {name!r}")
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module


__all__ = ["console", "err_console"]  # the consoles of ._output, re-exported: the commands print through them

EXIT_OK = 0
EXIT_ABORTED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
EXIT_CODES = {
    EXIT_OK: "success",
    EXIT_ABORTED: "declined at a confirmation, or the reader of the output went away "
    "(a closed pipe: `| head`; nothing more is printed)",
    EXIT_BAD_INPUT: "bad input, file, URL, device or storage fault, or output that could not be written "
    "(a full device): one `error:` line says which",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C): one `error: interrupted` line says what was interrupted and where "
    "each joint now stands (exact, or uncertain with bounds)",
}
"""The documented exit codes of every command (130 = 128 + SIGINT, the shells' convention for Ctrl-C)."""


class OneLineErrors(TyperGroup):
    """The command group, with click's usage errors as one ``error: ...`` line (exit 2).

    Click prints usage errors (a missing option, ``--joint 4``, a count out of range)
    as a multi-line panel; here they become the same one line as every other error.
    The group also ends every command's output (:func:`._output.finish`) and turns a
    write that failed (:class:`._output.OutputError`) into a quiet exit 1 for a closed
    pipe or one ``error:`` line and exit 2 for anything else.
    """

    def get_params(self, ctx: Any) -> list[Any]:
        """The group's options, each named by what it takes as the commands' are (a flag by nothing, not ``<bool>``)."""
        from ._help import metavar_of

        params = super().get_params(ctx)
        for p in params:
            if p.metavar is None:
                p.metavar = metavar_of(p)
        return params

    def main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        try:
            return self._main(*args, standalone_mode=standalone_mode, **kwargs)
        except OutputError as e:
            if not standalone_mode:
                raise
            silence("stdout")  # what is left in the buffer goes nowhere: no "Exception ignored" at exit
            if e.stream == "standard error":  # nowhere to say it
                silence("stderr")
                sys.exit(EXIT_ABORTED if e.closed else EXIT_BAD_INPUT)
            if e.closed:  # the reader went away (| head): a quiet end
                sys.exit(EXIT_ABORTED)
            try:
                _print_error(f"{e}; the output is incomplete")
                finish()
            except OutputError:
                silence("stderr")
            sys.exit(EXIT_BAD_INPUT)

    def _main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        try:
            try:
                rv = super().main(*args, **{**kwargs, "standalone_mode": False})
            finally:
                finish()
        except UsageError as e:
            hint = f" (see {e.ctx.command_path} --help)" if e.ctx is not None else ""
            message = " ".join(e.format_message().split())
            if not standalone_mode:
                raise
            _print_error(message + hint)
            sys.exit(EXIT_BAD_INPUT)
        except ClickException as e:
            if not standalone_mode:
                raise
            _print_error(e.format_message())
            sys.exit(e.exit_code)
        except (typer.Abort, KeyboardInterrupt):
            if not standalone_mode:
                raise
            err_console.print(Text.assemble(styled("error:", "bold red"), " interrupted (Ctrl-C)"))
            sys.exit(EXIT_INTERRUPTED)
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else EXIT_OK)

    def invoke(self, ctx: Any) -> Any:
        """Run the command; Ctrl-C anywhere in it ends in one line and exit 130 (:func:`interrupted_line`)."""
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as e:
            _print_error(interrupted_line(e, ctx.invoked_subcommand or ""))
            raise typer.Exit(EXIT_INTERRUPTED) from None


def interrupted_line(e: BaseException, command: str) -> str:
    """What Ctrl-C interrupted, and where each joint now stands if a device was being driven.

    A workflow that drives a device raises :class:`stickslip.procedures.move.Interrupted`
    with the kept state (its journal was saved before every burst); anywhere else nothing
    was being sent.
    """
    what = getattr(e, "what", None)
    state = getattr(e, "state", None)
    if what is None:
        return f"interrupted: stickslip {command}".rstrip() + " (Ctrl-C)"
    from ..procedures.move import where_line

    return f"interrupted: {what} (Ctrl-C); " + (where_line(state) if state is not None else "positions unknown")


def fail(message: str, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """Print ``error: message`` to stderr and exit with ``code`` (2 = bad input)."""
    _print_error(message)
    raise typer.Exit(code)


def _print_error(message: object) -> None:
    _print_labelled("error:", "bold red", one_line(message))


def _print_labelled(label: str, style: str, text: str) -> None:
    """``label text`` on stderr: one line for a pipe or a log (grep finds it whole); on a terminal wrapped
    at its width at spaces only, later lines indented (a URL or a path is never broken)."""
    if not err_console.is_terminal:
        err_console.print(Text.assemble(styled(label, style), " ", text), soft_wrap=True)
        return
    from ._help import wrap

    lines = wrap(f"{label} {text}", err_console.width, "  ", first="")
    err_console.print(Text.assemble(styled(label, style), lines[0][len(label) :]), soft_wrap=True)
    for line in lines[1:]:
        err_console.print(line, soft_wrap=True)


def one_line(message: object) -> str:
    """``message`` as one printable line: line breaks become ``; ``, control characters escapes, secrets ``***``."""
    parts = [p.strip() for p in str(message).splitlines() if p.strip()]
    return visible(redact_text("; ".join(parts)))


_KEPT_SPACE = "\ue000"
"""Stands for a space of a path while a line is wrapped (a private-use character no file name holds)."""


def say(text: str, indent: str = "  ", keep: tuple[object, ...] = ()) -> None:
    """Print a result line on stdout, wrapped at the console's width at spaces only, later lines indented.

    A URL, a path or a number with its unit is never broken (rich's own wrapping folds a
    long word), and what belongs together reads as one item. Each of ``keep`` (the paths
    the line names) stays whole even where it holds spaces (``OneDrive - Lab/Messungen 2026``):
    on a line of its own if it is longer than the rest of the line, so it can be copied whole.
    """
    from ._help import wrap

    for k in sorted({str(k) for k in keep}, key=len, reverse=True):  # a name is one line, every control escaped:
        shown = visible(k).replace("\n", "\\n").replace("\t", "\\t")  # wrapping made a \r, \n or tab a space
        text = text.replace(k, shown.replace(" ", _KEPT_SPACE))
    lead = text[: len(text) - len(text.lstrip())]
    for line in wrap(text.strip(), console.width, lead + indent, first=lead):
        console.print(line.replace(_KEPT_SPACE, " "), soft_wrap=True)


def note(message: str) -> None:
    """Print ``note: message`` to stderr: something done that the user should know of, not a problem."""
    _print_labelled("note:", "bold cyan", one_line(message))


def warn(message: str) -> None:
    """Print ``warning: message`` to stderr (wrapped at spaces on a terminal: :func:`_print_labelled`)."""
    _print_labelled("warning:", "bold yellow", one_line(message))


_pending_warnings: list[str] = []


def warn_later(message: str) -> None:
    """Queue a warning that matters only if the command goes on (a stale calibration, say).

    Queued warnings are printed by :func:`flush_warnings`: when the command has checked
    its input and is about to act, or when it ends successfully. A command that fails
    prints only its error, never a warning ahead of it.
    """
    if message not in _pending_warnings:
        _pending_warnings.append(message)


def flush_warnings() -> None:
    """Print the queued warnings (once each) and empty the queue."""
    while _pending_warnings:
        warn(_pending_warnings.pop(0))


def drop_warnings() -> None:
    """Forget the queued warnings (at the start of each command)."""
    _pending_warnings.clear()


@contextmanager
def user_errors(*types: type[BaseException]) -> Iterator[None]:
    """Turn the given exception types (and ValueError, OSError) into ``fail`` with :func:`describe`."""
    catch = types + (ValueError, OSError)
    try:
        yield
    except typer.Exit:
        raise
    except catch as e:  # noqa: B902
        fail(describe(e))


def describe(e: BaseException) -> str:
    """An exception as a person reads it: an ``OSError`` as ``path: reason`` (not ``[Errno 28] ...: 'path'``),
    a ``KeyError`` as its message (not in quotes)."""
    if isinstance(e, OSError) and type(e).__str__ is OSError.__str__ and e.strerror:
        return f"{e.filename}: {e.strerror}" if e.filename else str(e.strerror)
    if isinstance(e, KeyError) and len(e.args) == 1 and isinstance(e.args[0], str):
        return e.args[0]  # str() of a KeyError is the repr of its message: "'...'" in quotes
    return str(e)


def write_failure(path: object, e: OSError) -> str:
    """One line for an output file that could not be written: an atomic write's own (naming the file, the reason,
    and that the old file is kept or that nothing was written), else ``cannot write PATH: reason``."""
    from ..records import WriteError

    return str(e) if isinstance(e, WriteError) else f"cannot write {path}: {e.strerror or e}"


def print_json(obj: object) -> None:
    """Print ``obj`` as JSON on stdout (NaN/inf become null; ASCII, so any stream can take it)."""
    data_stream().write(json.dumps(_clean(obj), indent=2) + "\n")


def _clean(obj: object) -> object:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return _clean(obj.item())
    return obj


def validation_table(rows: list[dict[str, Any]], title: str) -> Table:
    """A rich table of :meth:`ValidationResult.rows` (model vs constant step, per joint)."""
    from rich.table import Table

    t = Table(title=title)
    for col in ("joint", "traverses", "model max", "model mean", "constant max", "constant mean", "better"):
        t.add_column(col, justify="right")
    for r in rows:
        better = "model" if r["model_max_rel_error"] < r["constant_max_rel_error"] else "constant"
        t.add_row(
            str(r["joint"]),
            str(r["n"]),
            f"{r['model_max_rel_error']:.2%}",
            f"{r['model_mean_rel_error']:.2%}",
            f"{r['constant_max_rel_error']:.2%}",
            f"{r['constant_mean_rel_error']:.2%}",
            better,
        )
    return t


def _parse_unit(parse: Callable[[str], float], what: str, value: str) -> float:
    """SI value of an option given with units; ``typer.BadParameter`` (one ``error:`` line) with the reason.

    A bare number other than 0 is refused with a did-you-mean (:func:`~stickslip.units.bare_number_problem`):
    on the command line every length and angle carries its unit.
    """
    bare = bare_number_problem(value, "angle" if parse is parse_angle else "length")
    if bare is not None:
        raise typer.BadParameter(bare)
    try:
        v = parse(value)
    except UnitError as e:
        raise typer.BadParameter(f"{e} ({what})") from None
    except (ArithmeticError, ValueError, TypeError) as e:  # pi/0, 1e999: never a traceback
        raise typer.BadParameter(f"{value!r} is not a usable value ({e}; {what})") from None
    if not math.isfinite(v):
        raise typer.BadParameter(f"{value!r} is not a finite value ({what})")
    return v


@overload
def angle_option(value: str) -> float: ...
@overload
def angle_option(value: None) -> None: ...
def angle_option(value: str | None) -> float | None:
    """An angle option in rad (``-90deg``, ``-pi/2``, ``500urad``); ``None`` if not given (typer parser or callback)."""
    return None if value is None else _parse_unit(parse_angle, "an angle: deg, rad, mrad, urad, or -pi/2", value)


@overload
def length_option(value: str) -> float: ...
@overload
def length_option(value: None) -> None: ...
def length_option(value: str | None) -> float | None:
    """A length option in m (``2mm``, ``30um``, ``850nm``); ``None`` if not given (typer parser or callback)."""
    return None if value is None else _parse_unit(parse_length, "a length: m, mm, um or nm", value)


def pose_options(q1: str, q2: str, q3: str, theta: str, psi: str) -> Pose:
    """The pose of ``--q1 --q2 --q3 --theta --psi`` given as text (units allowed); an ``error:`` naming the option."""
    from ..kinematics import Pose

    values = []
    for flag, text, parse in (
        ("--q1", q1, angle_option), ("--q2", q2, angle_option), ("--q3", q3, length_option),
        ("--theta", theta, angle_option), ("--psi", psi, angle_option),
    ):  # fmt: skip
        try:
            values.append(parse(text))
        except typer.BadParameter as e:
            fail(f"{flag}: {e.message}")
    try:
        return Pose(*values)
    except ValueError as e:  # no arm's pose (-90rad: degrees?); an arm's own stops are its planner's to check
        fail(str(e))


def day_option(value: str | None) -> str | None:
    """A session label option (``--day``): stripped, or ``typer.BadParameter`` saying why it cannot be one."""
    if value is None:
        return None
    from ..clock import check_day_label

    try:
        return check_day_label(value)
    except ValueError as e:
        raise typer.BadParameter(str(e)) from None


def _finite_option(value: float | None) -> float | None:
    """A float option's value, or ``typer.BadParameter`` for ``inf`` (``1e999``) or ``nan``."""
    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"not a finite number (got {value!r})")
    return value


_OPTION_LIKE = re.compile(r"--|--?[A-Za-z][A-Za-z0-9-]*")
"""A value that reads as an option (``-j``, ``--json``) or the end of options (``--``), not as a file's name."""


def path_option(value: str | Path | None) -> str | Path | None:
    """A file option's value (``-o``, ``--db``, ``--log-file``), or ``typer.BadParameter`` if it reads as an option;
    a leading ``~/`` is the home folder (a POSIX shell expands it; PowerShell and cmd pass it as it stands).

    ``show 2 -o --json`` wrote the calibration to a file named ``--json`` and printed no JSON:
    click takes the next word as the value whatever it looks like. A file of such a name is
    still written, given with its folder (``results/--json``, the full path: pathlib reads ``./--json``
    as ``--json``); ``-o.csv`` and ``--help.csv`` are names, taken as they are.
    """
    text = None if value is None else os.fspath(value)
    if text is not None and _OPTION_LIKE.fullmatch(text):
        try:
            whole = os.path.join(os.getcwd(), text)  # ./--json reaches here as --json (pathlib drops ./)
        except OSError:  # the working folder was removed
            whole = os.path.join("FOLDER", text)
        raise typer.BadParameter(
            f"{text!r} reads as an option, not a file: was the file left out? (a file of that name: {whole})"
        )
    if isinstance(value, str) and "://" not in value:  # --db FILE (not a URL), --log-file: as a Path option's text
        folder_problem(value)
    if text is not None and (text == "~" or text.startswith(("~/", "~" + os.sep))):
        # the home folder, as a POSIX shell would give it: PowerShell and cmd pass ~ to a program as it stands
        return type(value)(os.path.expanduser(text)) if isinstance(value, Path) else os.path.expanduser(text)
    return value


FOLDER_METAVAR = "FOLDER"
"""The metavar of a path option that names a folder (``demo -o``, ``report -o``): a trailing ``/`` is welcome there."""


def folder_problem(text: str) -> None:
    """``typer.BadParameter`` if a file option's text ends with a separator: it names a folder, not a file.

    ``show 2 -o neu/`` wrote a *file* named ``neu``: pathlib drops the ``/`` before a callback sees it. As
    ``curl -o neu/`` (which writes a file) it is refused, in one line; ``cp``'s "into that folder" would need a
    name each command does not have (``show -o`` has no default file).
    """
    seps = tuple(s for s in (os.sep, os.altsep) if s)
    if text.endswith(seps):
        raise typer.BadParameter(
            f"{text!r} ends with {text[-1]!r}, so it names a folder, and this option takes a file: "
            f"give the file's name ({text}NAME)"
        )


def path_text(folder: bool = False) -> Callable[[str | Path], Path]:
    """The parser of a path option: its text as typed (a trailing ``/`` kept, which pathlib drops) becomes a ``Path``.

    A file option's text ending with a separator is refused (:func:`folder_problem`); a folder
    option (metavar :data:`FOLDER_METAVAR`) takes it. A default (already a ``Path``) is taken as it is.
    """

    def parse(value: str | Path) -> Path:
        if isinstance(value, str) and not folder:
            folder_problem(value)
        return Path(value)

    return parse


DEVICE_FILTERS = frozenset({"history", "export", "anova", "report", "delete"})
"""Commands whose ``--device`` only picks stored rows: any text may match a device stored by an older release."""


def guard_options(callback: Callable[..., Any], device_is_filter: bool = False) -> None:
    """Give the options of one command the checks every command shares (one place for the whole CLI).

    * a ``float`` option (without a parser of its own) refuses ``inf``, ``1e999`` and
      ``nan``, naming the option (click's float type takes them);
    * a ``--day`` option (a session label, or a filter by one) is checked by
      :func:`day_option`: a blank or whitespace label is refused, naming ``--day``;
    * a ``--device`` option is checked by :func:`device_option`: a URL that could never
      be opened (no scheme, an unknown one, a bad port, a host name DNS cannot carry) is
      refused before any command uses it, records it or stores anything with it (not
      where it only filters stored rows, ``device_is_filter``: :data:`DEVICE_FILTERS`).
    * a path option (and ``--db``) is checked by :func:`path_option` (a value that reads as an
      option, a leading ``~``), and a ``Path`` option's text is read by :func:`path_text` before
      pathlib drops a trailing ``/``: a file option given a folder (``-o out/``) is refused.

    The check is set as the option's typer callback where it has none (an option with a
    callback of its own checks itself). Called on every command when the CLI is built.
    """
    import inspect
    import typing

    from typer.models import OptionInfo, ParameterInfo

    for p in inspect.signature(callback, eval_str=True).parameters.values():
        annotation, info = p.annotation, p.default
        if typing.get_origin(annotation) is typing.Annotated:
            annotation, *meta = typing.get_args(annotation)
            info = next((m for m in meta if isinstance(m, ParameterInfo)), info)
            # a string annotation (from __future__ import annotations) is evaluated afresh, with a new
            # OptionInfo, each time it is read: keep the evaluated one, whose OptionInfo is set below
            callback.__annotations__[p.name] = p.annotation
        if not isinstance(info, ParameterInfo) or info.callback is not None or getattr(info, "parser", None):
            continue
        kinds = {a for a in (typing.get_args(annotation) or (annotation,)) if a is not type(None)}
        if kinds == {float}:
            info.callback = _finite_option
        elif kinds == {str} and p.name == "day":
            info.callback = day_option
        elif kinds == {str} and p.name == "device" and not device_is_filter:
            info.callback = device_option
        elif isinstance(info, OptionInfo) and (kinds == {Path} or (kinds == {str} and p.name == "db")):
            info.callback = path_option
            if kinds == {Path}:  # typer's Path drops a trailing /: the parser sees the text as typed
                info.parser = path_text(folder=info.metavar == FOLDER_METAVAR)


def device_option(value: str | None) -> str | None:
    """A ``--device`` option: the URL if a device could be opened with it, else ``typer.BadParameter`` saying why."""
    if value is None:
        return None
    from ..devices.base import check_device_url

    try:
        return check_device_url(value)
    except ValueError as e:
        raise typer.BadParameter(str(e)) from None


# ---------------------------------------------------------------- the user's configuration file
# Each default a command takes from the configuration file (docs/config.md) is resolved here,
# in one order: the command-line option, then the environment variable where one exists,
# then the file, then the built-in default. ``config show`` prints the same resolution.

T = TypeVar("T")


@dataclass(frozen=True)
class Setting(Generic[T]):
    """A value a command uses and where it came from.

    ``source`` is ``"option"``, ``"env"``, ``"file"`` or ``"default"``; ``where`` names
    it: the option (``--db``), the variable (``$STICKSLIP_DB``), the file's path, or ``""``.
    """

    value: T
    source: str
    where: str = ""


def user_config() -> UserConfig:
    """The configuration file's settings (:func:`stickslip.config.load_config`), or one ``error:`` line."""
    try:
        return load_config()
    except ConfigError as e:
        fail(str(e))


DEFAULT_DEVICE_URL = "sim://"
"""The controller without --device and without ``device`` in the configuration file: the simulated MM3A."""


def device_setting(option: str | None, flag: str = "--device") -> Setting[str]:
    """The controller URL: ``option``, else the file's ``device``, else ``sim://``."""
    if option is not None:
        try:
            check_device_url(option)
        except ValueError as e:
            fail(f"{flag}: {e}")
        return Setting(option, "option", flag)
    cfg = user_config()
    if cfg.device is not None:
        return Setting(cfg.device, "file", str(cfg.path))
    return Setting(DEFAULT_DEVICE_URL, "default")


def device_url(option: str | None) -> str:
    """The controller URL a command drives (:func:`device_setting`).

    When it comes from the configuration file, a line on stderr says so (the URL with any
    secret hidden), so an arm is never driven without the user seeing which.
    """
    setting = device_setting(option)
    if setting.source == "file":
        err_console.print(
            f"device {redact_url(setting.value)} (from {setting.where})", highlight=False, markup=False, soft_wrap=True
        )
    return setting.value


def calibration_setting(option: Path | None, flag: str = "--calibration") -> Setting[Path | None]:
    """The calibration file: ``option``, else the file's ``calibration``, else none."""
    if option is not None:
        return Setting(option, "option", flag)
    cfg = user_config()
    if cfg.calibration is not None:
        return Setting(cfg.calibration, "file", str(cfg.path))
    return Setting(None, "default")


def calibration_file(option: Path | None, flag: str = "--calibration") -> Path:
    """The calibration a command needs: ``option``, else the file's ``calibration``; else ``error:``.

    A file the configuration names but that is not there is refused naming the
    configuration file (so a stale entry is found where it was written).
    """
    s = calibration_setting(option, flag)
    if s.value is None:
        what = f"{flag} CAL.json" if flag.startswith("-") else flag
        fail(f"no calibration: give {what}, or set calibration in the config file {config_path()} (docs/config.md)")
    if s.source == "file" and not s.value.exists():
        fail(f"{s.where}: calibration: {s.value} does not exist (give {flag}, or fix the config file)")
    return s.value


#: ``--db``'s help, for every command that reads or records the database (:func:`database_setting`)
DB_HELP = (
    "Database: an SQLite file, or a shared PostgreSQL database as postgresql://USER@HOST/DBNAME "
    "(password from $PGPASSWORD or ~/.pgpass; docs/storage.md). Default: $STICKSLIP_DB, else database in the "
    "config file, else stickslip.db in your data folder: ~/.local/share/stickslip on Linux, "
    "%LOCALAPPDATA%\\stickslip on Windows; `stickslip config show` says which."
)


def db_option(help_extra: str = "") -> Any:
    """The ``--db`` option: a file path or a ``postgresql://`` URL, kept as text (a ``Path`` would fold ``//``)."""
    return typer.Option(None, "--db", help=DB_HELP + help_extra, metavar="FILE|URL")


def database_setting(option: str | os.PathLike[str] | None, flag: str = "--db") -> Setting[Path | str]:
    """The database: ``option``, else ``$STICKSLIP_DB``, else the file's ``database``, else the data folder.

    An empty ``option`` is refused, not taken for "not given".

    A file is a ``Path``; a PostgreSQL database is its URL (``str``, shown only through
    :func:`stickslip.storage.describe_database`). Another ``scheme://`` is one ``error:`` line.
    """
    from ..storage import StoreError, default_db_path, resolve_database
    from ..storage.schema import ENV_VAR

    if option is not None and not str(option).strip():
        # An empty --db (often an unset shell variable, --db "$LABDB") would otherwise
        # fall through to $STICKSLIP_DB or the default and record into the wrong database.
        fail(f"{flag} is empty: give a database file or a postgresql:// URL, or leave {flag} out for the default")
    if option is not None:
        with user_errors(StoreError):
            return Setting(resolve_database(option), "option", flag)
    env = os.environ.get(ENV_VAR)
    if env:
        with user_errors(StoreError):
            return Setting(resolve_database(env), "env", f"${ENV_VAR}")
    cfg = user_config()
    if cfg.database is not None:
        with user_errors(StoreError):
            return Setting(resolve_database(cfg.database), "file", str(cfg.path))
    return Setting(default_db_path(), "default")


def db_path(option: str | os.PathLike[str] | None) -> Path | str:
    """The database a command uses (:func:`database_setting`): a file, or a PostgreSQL URL."""
    return database_setting(option).value


def max_age_setting(option: int | None, flag: str = "--max-age") -> Setting[int]:
    """Largest calibration age (days) without a warning: ``option``, ``$STICKSLIP_MAX_AGE_DAYS``, the file, 0."""
    from ..clock import ENV_MAX_AGE, max_age_days

    if option is not None:
        with user_errors():
            return Setting(max_age_days(option), "option", flag)
    if os.environ.get(ENV_MAX_AGE, "").strip():
        with user_errors():
            return Setting(max_age_days(None), "env", f"${ENV_MAX_AGE}")
    cfg = user_config()
    if cfg.max_age_days is not None:
        return Setting(cfg.max_age_days, "file", str(cfg.path))
    return Setting(0, "default")


def geometry_setting(option: str | None, flag: str = "--geometry") -> Setting[Geometry]:
    """The arm's geometry: ``option`` (OFFSET,LENGTH), else the file's ``[geometry]``, else 0mm,21mm.

    A ``[geometry]`` table that gives only one length takes the other from the default.
    """
    from ..kinematics import DEFAULT_GEOMETRY, Geometry

    if option is not None:
        for part in option.split(","):
            bare = bare_number_problem(part, "length")
            if bare is not None:
                fail(f"{flag}: {bare}")
        try:
            return Setting(Geometry.parse(option), "option", flag)
        except ValueError as e:
            fail(f"{flag}: {e}")
    cfg = user_config()
    given = {k: v for k, v in (("offset", cfg.geometry_offset), ("length", cfg.geometry_length)) if v is not None}
    if given:
        try:
            return Setting(Geometry(**given), "file", str(cfg.path))
        except ValueError as e:
            fail(f"{cfg.path}: [geometry]: {e}")
    return Setting(DEFAULT_GEOMETRY, "default")


@contextmanager
def open_store(db: str | os.PathLike[str] | None, must_exist: bool = False) -> Iterator[Store]:
    """The database at ``db`` (``--db``, else ``$STICKSLIP_DB``, else the config file's, else the data folder).

    A context manager (``with open_store(db) as st:``), the one way commands open the
    database: a file, or a shared PostgreSQL database (``postgresql://``). A command that
    only reads passes ``must_exist=True`` and refuses a database that is not there yet
    instead of creating an empty one. Every storage fault, when opening (another
    application's file or tables, a FIFO, a newer schema, a server that does not answer)
    or inside the block (a damaged page, a stored value of the wrong type, a full disk),
    is one ``error:`` line naming the database, never a password; the store is closed
    either way.
    """
    from ..storage import NoDatabase, Store, StoreError, describe_database

    target = db_path(db)
    with user_errors(StoreError):
        try:
            store = Store.open(target, create=not must_exist)
        except NoDatabase:
            fail(
                f"no database at {describe_database(target)} (nothing recorded yet: run stickslip demo, "
                "or stickslip import MEAS.csv -d URL)"
            )
    if store.upgraded_from is not None:
        kept = (f"the file as it was is kept as {store.upgrade_copy}, which an older stickslip still reads"
                if store.upgrade_copy is not None else "a server's database is not copied (pg_dump keeps one)")
        note(f"upgraded the database {describe_database(target)} from schema version {store.upgraded_from} to "
             f"{store.schema_version} (docs/storage.md); {kept}; an older stickslip refuses the upgraded one as newer")
        for line in store.upgrade_notes:  # two spellings of one device merged: said, never silently
            note(line)
    try:
        with store:
            yield store
    except StoreError as e:
        fail(describe(e))


def fail_table(e: TableError) -> NoReturn:
    """Every problem of a bad table, one line each (``file:line: reason``), then exit 2."""
    fail("\n".join(e.problems))


def read_table(path: Path, max_bytes: int | None = None) -> list[Traverse]:
    """The traverses of a measurement table, or every bad row's reason and exit 2 (nothing is read)."""
    from ..measurements import TableError, read_measurements

    try:
        return read_measurements(path, max_bytes)
    except TableError as e:
        fail_table(e)


def read_step_table(path: Path) -> list[StepSize]:
    """The step sizes of a step-size table (``camera calibrate -o``), or every bad row's reason and exit 2."""
    from ..measurements import TableError, read_step_sizes

    try:
        return read_step_sizes(path)
    except TableError as e:
        fail_table(e)
