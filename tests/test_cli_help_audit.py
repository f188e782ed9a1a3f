"""Every command's --help read as a user who trusts it: what it names exists, what it takes is used (audit40)."""

import json

from synth import paper_table
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.measurements import measurements_to_csv

runner = CliRunner()


def _bad(result, *words, code=2):
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output and "Traceback" not in result.stderr
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for w in words:
        assert w in result.stderr, result.stderr


def test_fit_with_an_unknown_model_family_is_one_line_naming_the_known_ones(tmp_path):
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    _bad(runner.invoke(app, ["fit", str(meas), "--model", "foo", "--json"]), "no model family 'foo'", "torque2")
