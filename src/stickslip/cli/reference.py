"""The command-line reference (``docs/cli.md``), generated from the commands themselves.

Run ``python -m stickslip.cli.reference > docs/cli.md`` after changing a command; a
test fails when the page and the code disagree, so the reference cannot rot.
"""

from __future__ import annotations

import sys
from typing import Any

import typer

__all__ = ["render"]


def _param_line(p: Any) -> str:
    if not p.opts or not p.opts[0].startswith("-"):
        name = f"`{(p.name or '').upper()}`"
        what = getattr(p, "help", None) or ""
        return f"| {name} | argument{'' if p.required else ', optional'} | {what} |"
    opts = ", ".join(f"`{o}`" for o in (*p.opts, *p.secondary_opts))
    what = (getattr(p, "help", None) or "").replace("|", "\\|").replace("\n", " ")
    default = p.default if not callable(p.default) else None
    shown = "" if default in (None, False, ()) or getattr(p, "is_flag", False) else f" (default: `{default}`)"
    return f"| {opts} | option | {what}{shown} |"


def _section(name: str, cmd: Any) -> list[str]:
    out = [f"## `stickslip {name}`", ""]
    doc = (cmd.help or "").strip()
    out += [doc.replace("[bold]", "").replace("[/]", ""), ""]
    params = [p for p in cmd.params if p.name != "help"]
    if params:
        out += ["| name | kind | meaning |", "| --- | --- | --- |"]
        out += [_param_line(p) for p in params]
        out.append("")
    return out


def render() -> str:
    """The Markdown reference of every ``stickslip`` command, in the order of ``stickslip --help``."""
    from . import app

    group: Any = typer.main.get_command(app)
    ctx = group.make_context("stickslip", ["--help"], resilient_parsing=True)
    lines = [
        "# Command-line reference",
        "",
        "Generated from the code by `python -m stickslip.cli.reference`; do not edit by hand.",
        "Every length and angle on the command line takes its unit (`12mm`, `850nm`, `-90deg`, `40urad`,",
        "`-pi/2`; a bare number other than 0 is refused); files are SI. Every command exits 2 with a",
        "one-line `error:` on bad input, and 130 with one `error: interrupted` line on Ctrl-C.",
        "",
    ]
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        if cmd is not None and not cmd.hidden:
            lines += _section(name, cmd)
            if hasattr(cmd, "list_commands"):  # a group of commands (config): each one below it
                sub_ctx = cmd.make_context(name, ["--help"], parent=ctx, resilient_parsing=True)
                for sub_name in cmd.list_commands(sub_ctx):
                    sub = cmd.get_command(sub_ctx, sub_name)
                    if sub is not None and not sub.hidden:
                        lines += _section(f"{name} {sub_name}", sub)
    return "\n".join(lines).rstrip() + "\n"


if __name__ == "__main__":  # pragma: no cover - exercised through the test of docs/cli.md
    sys.stdout.write(render())
