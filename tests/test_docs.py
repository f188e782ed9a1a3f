"""The documentation in docs/ matches the code: the CLI reference is regenerated and compared."""

from pathlib import Path

from stickslip.cli.reference import render

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_cli_reference_is_up_to_date():
    page = (DOCS / "cli.md").read_text(encoding="utf-8")
    assert page == render(), "docs/cli.md is stale: run  python -m stickslip.cli.reference > docs/cli.md"


def test_cli_reference_covers_every_command():
    page = render()
    for name in ("demo", "calibrate", "predict", "validate", "plan", "tune", "listen", "anova", "report", "move"):
        assert f"## `stickslip {name}`" in page


def test_the_cli_reference_describes_the_code_as_it_is():
    """No help text speaks of an earlier version: the reference says what the commands do now."""
    page = render().lower()
    for history in ("the old behaviour", "as before", "no longer", "previous version", "formerly", "until recently"):
        assert history not in page, f"a help text in docs/cli.md speaks of history: {history!r}"


def _help_texts():
    """Every command's and option's help text, with the command's path."""
    import typer

    from stickslip.cli import app

    def walk(cmd, path):
        yield path, cmd.help or ""
        for p in cmd.params:
            yield f"{path} {p.name}", getattr(p, "help", None) or ""
        for name, sub in (getattr(cmd, "commands", None) or {}).items():
            yield from walk(sub, f"{path} {name}")

    yield from walk(typer.main.get_command(app), "stickslip")


def test_no_help_text_loses_a_bracket_to_the_console_markup():
    """--help reads help texts as rich markup: '[geometry]' or '[[position]]' is a style tag and vanished.

    `stickslip reach --help` said '(default:  in the config file' and `rig go --help` 'a [] of the rig
    file'; only the [bold] ... [/] of the examples is markup.
    """
    from rich.text import Text

    lost = []
    for where, text in _help_texts():
        meant = text.replace("[bold]", "").replace("[/]", "")
        if Text.from_markup(text).plain != meant:
            lost.append(f"{where}: {text[:120]!r}")
    assert not lost, lost
