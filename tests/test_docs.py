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
