"""Every command's ``--help``, laid out to fit the terminal (80 columns and up) without cutting a word.

Typer's rich panels give the option descriptions what is left of the width after five
other columns, and cut what does not fit there (``$STICKSLIP_ANC300_PASSWO…``). Here a
command's help is two columns, the option with what it takes, then its description,
wrapped at spaces only: a URL, a path or a variable name is never broken. What an option
takes is named by its kind: ``<length>``, ``<angle>``, ``<steps>``, ``<path>``, ``<int>``
(with its range), never a bare ``<float>``.
"""

from __future__ import annotations

import shutil
import textwrap
from typing import Any

from typer.core import TyperCommand

__all__ = ["HelpCommand", "help_width", "metavar_of", "range_of", "shown_default", "wrap"]

MAX_WIDTH = 100
"""Help is laid out for the terminal's width, at most this many columns (long lines read badly)."""

NAME_COLUMN = 30
"""The widest the option column gets; a longer option puts its description on the next line."""


def help_width() -> int:
    """The width to lay help out for: the terminal's (``$COLUMNS`` when set), at least 40, at most :data:`MAX_WIDTH`."""
    return max(40, min(MAX_WIDTH, shutil.get_terminal_size((80, 24)).columns))


def wrap(text: str, width: int, indent: str = "", first: str | None = None) -> list[str]:
    """``text`` wrapped at spaces to ``width`` columns; words longer than a line stay whole."""
    return textwrap.wrap(
        text, width=width, initial_indent=indent if first is None else first, subsequent_indent=indent,
        break_long_words=False, break_on_hyphens=False,
    ) or [indent if first is None else first]


def _plain(text: str) -> str:
    """``text`` without rich markup (``[bold]...[/]``)."""
    from rich.text import Text

    try:
        return Text.from_markup(text).plain
    except Exception:  # noqa: BLE001 - markup that rich cannot read is shown as written
        return text


_PARSERS = {"angle_option": "<angle>", "length_option": "<length>"}

_BY_NAME = {
    "device": "<url>", "day": "<label>", "audio_input": "<sound card>", "serial_port": "<port>", "serial": "<port>",
    "q1": "<angle>", "q2": "<angle>", "q3": "<length>", "theta": "<angle>", "psi": "<angle>",
    "q_from": "<length|angle>", "q_to": "<length|angle>", "at": "<length|angle|min|max>", "sigma": "<length|angle>",
    "geometry": "<length,length>", "set_": "<J=position>", "confirm_s": "<seconds>", "stop_at": "<seconds>",
    "before": "<seconds>", "after": "<seconds>", "hold": "<seconds>", "sample_rate": "<Hz>", "frequency": "<Hz>",
    "max_rate": "<steps/s>", "min_band": "<Hz>", "amplitude": "<volts>", "temperature": "<celsius>",
}
"""What an option takes, by its name, where its type says too little (a string, a float)."""


def metavar_of(param: Any) -> str:
    """What an option takes, by kind: ``<angle>``, ``<length>``, ``<int>``, ``<number>``, ``<path>``, ``<text>``."""
    if getattr(param, "is_flag", False) or getattr(param, "count", False):
        return ""
    explicit = getattr(param, "metavar", None)
    if explicit:
        return str(explicit)
    td = getattr(param, "type_descriptor", None)
    parser = getattr(getattr(td, "parameter_info", None), "parser", None)
    if parser is not None and getattr(parser, "__name__", "") in _PARSERS:
        return _PARSERS[parser.__name__]
    choices = getattr(td, "choices", None)
    if choices:
        return "<" + "|".join(str(getattr(c, "value", c)) for c in choices) + ">"
    kind = getattr(td, "annotation", str)
    if kind is bool:
        return ""
    if param.name in _BY_NAME and (kind in (str, float, int) or getattr(td, "is_list", False)):
        return _BY_NAME[param.name]
    if kind is int:
        return "<int>"
    if kind is float:
        return "<number>"
    if getattr(td, "is_path", False):
        return "<path>"
    return "<text>"


def range_of(param: Any) -> str:
    """The range --help shows for a number option (its typer min and max): ``1 to 65535``, ``>= 0``, or ""."""
    lo, hi = getattr(param, "min", None), getattr(param, "max", None)
    if lo is None and hi is None:
        return ""
    if lo is not None and hi is not None:
        return f"{lo:g} to {hi:g}"
    return f">= {lo:g}" if lo is not None else f"<= {hi:g}"


def _names(param: Any) -> str:
    """``-j, --joint <int>``: short names first, then long, then what it takes."""
    names = sorted(param.opts, key=lambda o: (o.startswith("--"), o))
    for secondary in param.secondary_opts:  # --db-record/--no-db
        names[-1] = f"{names[-1]}/{secondary}"
    label = ", ".join(names)
    meta = metavar_of(param)
    return f"{label} {meta}".rstrip()


def shown_default(param: Any) -> object | None:
    """The default ``--help`` (and docs/cli.md) shows for ``param``, or ``None``: none for a flag, a computed
    default, ``show_default=False`` (its help says it), or an empty one; a default of 0 is shown (0 == False)."""
    default: object = param.default
    if getattr(param, "show_default", True) is False or getattr(param, "is_flag", False) or callable(default):
        return None
    if default is None or default is False or (isinstance(default, (str, tuple, list)) and not default):
        return None
    return default


def _description(param: Any) -> str:
    text = _plain(getattr(param, "help", None) or "")
    extras = []
    rng = range_of(param)
    if rng:
        extras.append(rng)
    default = shown_default(param)
    if default is not None:
        extras.append(f"default: {default}")
    if param.required:
        extras.append("required")
    return (text + (" [" + "; ".join(extras) + "]" if extras else "")).strip()


def _rows(rows: list[tuple[str, str]], width: int) -> list[str]:
    """Two columns: a name, then its description wrapped beside it (or below it when the name is long)."""
    if not rows:
        return []
    col = min(max(len(n) for n, _ in rows), NAME_COLUMN) + 4
    out = []
    for name, desc in rows:
        head = "  " + name
        if len(head) + 2 > col:
            out.append(head)
            out += wrap(desc, width, " " * col) if desc else []
        else:
            out += wrap(desc, width, " " * col, first=head.ljust(col))
    return out


def _body(doc: str, width: int) -> list[str]:
    """A command's docstring as paragraphs wrapped to ``width``; indented or list lines keep their breaks."""
    out: list[str] = []
    for para in _plain(doc).strip().split("\n\n"):
        lines = para.splitlines()
        keep = any(ln.startswith((" ", "- ", "* ", "$")) for ln in lines[1:])
        if keep:
            for ln in lines:
                lead = ln[: len(ln) - len(ln.lstrip())]
                out += wrap(ln.strip(), width, lead + "  ", first=lead)
        else:
            out += wrap(" ".join(ln.strip() for ln in lines), width)
        out.append("")
    return out


def _argument_name(p: Any) -> str:
    """An argument as the help names it: its metavar, else its name in capitals (``POSES``)."""
    return str(p.metavar or (p.name or "").upper())


def _usage(ctx: Any, params: list[Any], dashed: list[Any]) -> str:
    """The usage line, in the same names as the arguments' rows: ``POSES``, ``[MEASUREMENTS]``, ``FRAMES...``."""
    pieces = [ctx.command_path] + (["[OPTIONS]"] if dashed else [])
    for p in params:
        if p in dashed:
            continue
        name = _argument_name(p)
        if not p.required and not name.startswith("["):
            name = f"[{name}]"
        pieces.append(name + ("..." if p.nargs != 1 else ""))
    return " ".join(pieces)


class HelpCommand(TyperCommand):
    """A typer command whose ``--help`` fits the terminal (:func:`help_width`) without cutting a word."""

    def format_help(self, ctx: Any, formatter: Any) -> None:
        width = help_width()
        params = [p for p in self.get_params(ctx) if not getattr(p, "hidden", False)]
        dashed = [p for p in params if p.opts and p.opts[0].startswith("-")]
        lines = wrap(_usage(ctx, params, dashed), width, "    ", first="Usage: ") + [""]
        if self.help:
            lines += _body(self.help, width)
        arguments = [(_argument_name(p), _description(p)) for p in params if p not in dashed]
        options = [(_names(p), _description(p)) for p in dashed]
        for title, rows in (("Arguments:", arguments), ("Options:", options)):
            if rows:
                lines += [title, *_rows(rows, width), ""]
        formatter.write("\n".join(lines).rstrip() + "\n")
