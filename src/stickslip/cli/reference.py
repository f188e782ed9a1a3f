"""The command-line reference (``docs/cli.md``), generated from the commands themselves.

Run ``python -m stickslip.cli.reference > docs/cli.md`` after changing a command; a
test fails when the page and the code disagree, so the reference cannot rot.
"""

from __future__ import annotations

import sys
from typing import Any

import typer

from ._help import range_of, shown_default

__all__ = ["render"]


def _param_line(p: Any) -> str:
    if not p.opts or not p.opts[0].startswith("-"):
        name = f"`{(p.name or '').upper()}`"
        what = getattr(p, "help", None) or ""
        return f"| {name} | argument{'' if p.required else ', optional'} | {what} |"
    opts = ", ".join(f"`{o}`" for o in (*p.opts, *p.secondary_opts))
    if p.metavar:  # what --help shows after the option: a unit (<days>) or a form (X,Y, J=FILE)
        opts += " `" + p.metavar.replace("|", "\\|") + "`"
    what = (getattr(p, "help", None) or "").replace("|", "\\|").replace("\n", " ")
    default = shown_default(p)  # as --help shows them: the range checked, the default
    rng = range_of(p)
    shown = (f" (range: {rng})" if rng else "") + ("" if default is None else f" (default: `{default}`)")
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


_OUTPUT_RULES = """\
## Output and exit codes

What every command writes, and how it ends (`stickslip.cli._output`, the one way out of
the command line):

* **Text is shown, never interpreted.** A session label, path, device URL or table cell is
  printed as it stands: console markup (`[bold]`, `[/]`) and emoji codes are not read.
* **Nothing raw reaches the terminal.** A control character (ESC, CR, BEL, the C1
  controls), a bidirectional override or isolate (U+202E) or a line separator in any
  printed text is shown as its escape: `\\x1b[2J`, `\\r`, `\\u202e`.
* **No secret is printed, logged or stored.** Every message, log line (`-v`, `--log-file`)
  and stored note passes through `devices.base.redact_text`: `?password=...` and
  `user:PASSWORD@` in any URL become `***`.
* **Units degrade where the output cannot encode them** (an ASCII locale, a Windows code
  page): `µm` is written `um`, `±` as `+/-`, `°` as `deg`; tables are drawn in ASCII.
  Data is never changed: `--json` is ASCII; a CSV cell the output cannot encode ends the
  command with one line (write it with `-o`).
* **Files:** every output file (`-o`, `--out`, `--append`, `record`) is written to a
  temporary file beside it, flushed and synced, then renamed over it: a full disk or any
  other failed write is one line (`cannot write OUT: No space left on device; the old file
  is kept as it was`) and the old file is unchanged. The files of one command (`report`,
  `demo --out`, `camera calibrate -o ... --jacobian ...`) are renamed together once all are
  written: a disk that fills half-way leaves every earlier file as it was. A file that is
  read-only for you is refused, as a plain write refuses it. A folder, FIFO or device is never
  written to, read from or replaced: it is refused before it is opened.
* **CSV cells a spreadsheet would run are guarded.** A cell beginning with `=`, `+`, `-`,
  `@`, a tab or a carriage return is written with a leading `'`, except a plain decimal
  number (`-1.5707963`, `+3`, `-2.5e-06`: a spreadsheet reads it as a number, so SI values
  round-trip) and a lone `+` or `-` (the direction column). stickslip's own readers take
  the guard off: an exported table reads back exactly.
* **Databases:** stickslip writes only into its own SQLite files (`PRAGMA application_id`
  0x5374536C; a database made before the id is known by its tables and stamped) and
  PostgreSQL schemas (`--db postgresql://...`: an empty schema, or one with its marker
  table `stickslip_marker`; docs/storage.md). Another application's file or tables are
  refused untouched; a damaged one, or a stored value of the wrong type, is one line
  naming the database (and the traverse and column), never a password.
* **JSON** (calibrations, tunings, device state) is read strictly: a key given twice, a
  newer format version, `NaN`, deep nesting or a syntax error is one line naming the file,
  the key or the line and column.
* **Waits end on time.** A device URL's `timeout` bounds how long a fault is waited for:
  once a reply has not come in time, the stops that follow are sent without waiting for
  answers. A FIFO given as a recording or table is refused, never opened (it would block).
* **Lines fit the terminal, and no word is cut.** `--help` is laid out in two columns at the
  terminal's width (80 and up), wrapped at spaces only: a URL, a path or a variable name
  is never broken. Results wrap at spaces with later lines indented. On a terminal a
  warning or an error longer than its width wraps the same way; in a pipe or a log it
  stays one line (grep finds it whole). A `±` always says what it is: `(σ ...)` for a
  standard deviation, `(95 % prediction interval)` for an interval.
* **Options:** a number option of infinite size (`1e999`, `inf`, `nan`), a blank `--day`,
  or a `--device` URL that could never be opened (an unknown scheme, a port beyond 65535,
  a host name longer than DNS allows) is refused naming the option, before anything runs.
  So is a file option given a word that reads as an option (`-o --json`, `--db -v`, `-o --`:
  the file was left out); a file so named is given with its folder (`results/--json`).
  `-o.csv` is a name; an argument that begins with `-` follows `--` (`calibrate -- -o.csv`).
  A file option's leading `~/` is your home folder wherever the command runs (PowerShell and
  cmd pass `~` to a program as it stands).
  A file option's value that ends with `/` names a folder and is refused in one line
  (`show 2 -o out/`, as `curl -o out/`: name the file, `out/cal.json`); a folder option
  (`demo -o`, `report -o`, shown as `FOLDER`) takes it.

| exit code | meaning |
| --- | --- |
"""


def render() -> str:
    """The Markdown reference of every ``stickslip`` command, in the order of ``stickslip --help``."""
    from . import app
    from ._common import EXIT_CODES

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
        *_OUTPUT_RULES.splitlines(),
        *(f"| {code} | {meaning.replace('|', chr(92) + '|')} |" for code, meaning in sorted(EXIT_CODES.items())),
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
