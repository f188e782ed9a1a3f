"""``stickslip config``: where the user's configuration file is, what it sets, and a template to start from.

The file (docs/config.md) gives the defaults of --device, --calibration, --db,
--geometry and --max-age; every option still wins, and so do ``$STICKSLIP_DB`` and
``$STICKSLIP_MAX_AGE_DAYS``. The resolution itself lives in :mod:`._common`
(:func:`~._common.device_setting` and its siblings), so ``config show`` prints exactly
what the commands use.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import typer

from ..config import ENV_CONFIG, config_path, write_template
from ..devices.base import redact_url
from . import app
from ._common import (
    OneLineErrors,
    Setting,
    calibration_setting,
    console,
    database_setting,
    device_setting,
    fail,
    geometry_setting,
    max_age_setting,
    print_json,
    say,
    user_config,
    write_failure,
)
from ._output import data_stream

config_app = typer.Typer(
    name="config",
    cls=OneLineErrors,
    no_args_is_help=True,
    rich_markup_mode="rich",
    help=(
        "The user configuration file: default device, calibration, database, geometry and calibration age.\n\n"
        "A TOML file in your configuration folder (or at $STICKSLIP_CONFIG) gives the defaults of "
        "--device, --calibration, --db, --geometry and --max-age. Every option wins over it, and so do "
        "$STICKSLIP_DB and $STICKSLIP_MAX_AGE_DAYS. It never holds a password. See docs/config.md."
    ),
)
app.add_typer(config_app, name="config", rich_help_panel="Set up")


@config_app.command("path")
def path_cmd(
    json_out: bool = typer.Option(False, "--json", help="Print the path, whether it exists and why there, as JSON."),
) -> None:
    """Print where the configuration file is looked for ($STICKSLIP_CONFIG, else the platform's folder).

    Only the path is printed, so it can be used in a shell: $EDITOR "$(stickslip config path)".

    Example: stickslip config path
    """
    p = config_path()
    from_env = bool(os.environ.get(ENV_CONFIG, "").strip())
    if json_out:
        print_json(
            {
                "path": str(p),
                "exists": os.path.isfile(p),
                "source": "env" if from_env else "default",
                "where": f"${ENV_CONFIG}" if from_env else "",
            }
        )
        return
    data_stream().write(f"{p}\n")  # for a shell: the path as it is


@config_app.command("init")
def init_cmd(
    force: bool = typer.Option(False, "--force", help="Overwrite a configuration file that exists."),
) -> None:
    """Write a commented template of every key to the configuration file (nothing set yet).

    Refuses to overwrite a file that exists unless --force; the write is atomic (a
    temporary file, then a rename), so a failed write leaves the old file as it was.
    Edit the file, then check it with stickslip config show.

    Example: stickslip config init
    """
    try:
        written = write_template(None, force=force)
    except OSError as e:  # FileExistsError without --force; a read-only folder
        fail(str(e) if isinstance(e, FileExistsError) else write_failure(config_path(), e))
    console.print(
        f"wrote {written}: every key is commented out; edit it, then check it with stickslip config show",
        highlight=False,
        soft_wrap=True,
    )


def _row(s: Setting[Any]) -> dict[str, Any]:
    return {"value": s.value, "source": s.source, "where": s.where}


@config_app.command("show")
def show_cmd(
    device: str | None = typer.Option(None, "--device", "-d", help="As a command's --device (shows it winning)."),
    calibration: Path | None = typer.Option(None, "--calibration", "-c", help="As a command's --calibration."),
    db: str | None = typer.Option(None, "--db", metavar="FILE|URL", help="As a command's --db."),
    geometry: str | None = typer.Option(None, "--geometry", help="As a command's --geometry (OFFSET,LENGTH)."),
    max_age: int | None = typer.Option(None, "--max-age", min=0, max=36500, help="As a command's --max-age (days)."),
    json_out: bool = typer.Option(False, "--json", help="Print the settings as JSON (paths, metres, days)."),
) -> None:
    """Show the values the commands use and where each comes from: option, env, file or default.

    The order is always: a command-line option, then an environment variable
    ($STICKSLIP_DB, $STICKSLIP_MAX_AGE_DAYS), then the configuration file, then the
    built-in default. Give a command's options here to see them win. A configuration
    file that cannot be used (not TOML, an unknown key, a password in the device URL)
    is one error line naming the file, the line and the key (exit 2); so is a
    calibration it names that is not there, after the settings are shown.

    Example: stickslip config show --json
    """
    from ..storage import describe_database

    cfg = user_config()
    dev = device_setting(device)
    cal = calibration_setting(calibration)
    base = database_setting(db)
    age = max_age_setting(max_age)
    geom = geometry_setting(geometry)
    dev = Setting(redact_url(dev.value), dev.source, dev.where)  # an option may hold a password; never print it
    if json_out:
        print_json(
            {
                "config": {"path": str(cfg.path), "found": cfg.found, "sets": cfg.values()},
                "settings": {
                    "device": _row(dev),
                    "calibration": {
                        **_row(cal),
                        "value": None if cal.value is None else str(cal.value),
                        "exists": None if cal.value is None else os.path.isfile(cal.value),
                    },
                    "database": {
                        **_row(base),
                        "value": describe_database(base.value),
                        "exists": os.path.isfile(base.value) if isinstance(base.value, Path) else None,
                    },
                    "max_age_days": _row(age),
                    "geometry": {**_row(geom), "value": geom.value.as_dict()},
                },
            }
        )
        _check_named_files(cal)
        return
    state = "found" if cfg.found else "not there: built-in defaults (stickslip config init writes a template)"
    say(f"config file: {cfg.path} ({state})", keep=(cfg.path,))

    def origin(s: Setting[Any]) -> str:
        return s.source + (f" {s.where}" if s.where else "")

    def path_text(p: Path | None) -> str:
        if p is None:
            return "none: give --calibration"
        return str(p) + ("" if os.path.isfile(p) else " (not there)")  # never raises (a name too long)

    g = geom.value
    for name, value, setting in (
        ("device", dev.value, dev),
        ("calibration", path_text(cal.value), cal),
        ("database", _database_text(base.value), base),
        ("max_age_days", f"{age.value} day{'s' if age.value != 1 else ''}", age),
        ("geometry", f"offset {g.offset * 1e3:g} mm, length {g.length * 1e3:g} mm", geom),
    ):
        say(f"  {name}: {value} (from {origin(setting)})", indent="      ", keep=(setting.value, setting.where))
    _check_named_files(cal)


def _check_named_files(cal: Setting[Path | None]) -> None:
    """Exit 2 naming the configuration file when the calibration it names is not there (every command would fail)."""
    if cal.source == "file" and cal.value is not None and not os.path.isfile(cal.value):
        fail(f"{cal.where}: calibration: {cal.value} does not exist (fix the config file, or give --calibration)")


def _database_text(where: Path | str) -> str:
    """The database as ``config show`` names it: a file (and whether it is there yet), or a server (never asked)."""
    from ..storage import describe_database

    if isinstance(where, Path):
        return str(where) + ("" if os.path.isfile(where) else " (not there yet)")
    return f"{describe_database(where)} (PostgreSQL)"
