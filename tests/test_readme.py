"""The README's tour and Python example run as written (docs/style.md: examples run)."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from synth import paper_table
from typer.testing import CliRunner

from stickslip.measurements import measurements_to_csv

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

README = (Path(__file__).resolve().parents[1] / "README.md").read_text()
runner = CliRunner()


def _block(after: str, lang: str) -> str:
    start = README.index(after)
    m = re.search(rf"```{lang}\n(.*?)```", README[start:], re.S)
    assert m, f"no {lang} block after {after!r}"
    return m.group(1)


def test_readme_opens_with_the_two_commands():
    first = _block("# stickslip", "console")
    assert "make demo" in first and "make test" in first


@pytest.fixture(scope="module")
def tour_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("tour")


def _tour_lines() -> list[str]:
    return [ln[2:] for ln in _block("## A tour", "console").splitlines() if ln.startswith("$ ")]


@pytest.mark.skipif(sys.platform == "win32", reason="the tour is a POSIX shell session (bash)")
def test_tour_runs_literally_in_a_shell(tour_dir):
    """The README's tour, every line as written, in bash: a folder holding the project's .venv, as after `make`."""
    venv = Path(sys.prefix)
    if not (venv / "bin" / "activate").exists() or not (venv / "bin" / "stickslip").exists():
        pytest.skip("not running inside the project's virtual environment (make test builds it)")
    (tour_dir / ".venv").symlink_to(venv, target_is_directory=True)
    lines = _tour_lines()
    assert lines[0].startswith(". .venv/bin/activate") and len(lines) >= 10
    script = "set -euo pipefail\n" + "\n".join(lines) + "\n"
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV",)}
    env["PATH"] = "/usr/bin:/bin"  # nothing of the project's on the PATH until the tour activates it
    env["STICKSLIP_DB"] = str(tour_dir / "tour.db")
    r = subprocess.run(["bash", "-c", script], cwd=tour_dir, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    assert "Traceback" not in r.stderr
    out = tour_dir / "stickslip-results"
    assert (out / "cal.json").exists() and (out / "report" / "index.html").exists()
    predicted = (out / "predicted.csv").read_text().splitlines()
    assert predicted[0].endswith("gamma_pred") and len(predicted) == 2
    assert len((out / "today.csv").read_text().splitlines()) == 2  # header + the traverse measured by ear


@pytest.mark.skipif(sys.platform == "win32", reason="the tour is a POSIX shell session (bash)")
def test_camera_block_runs_after_the_tour(tour_dir):
    """The README's camera block, as written, in the tour's folder (after the tour, or on the paper's table), in a
    fresh database; its lines from the second on are docs/vision.md's block (test_docs_examples checks they match)."""
    venv = Path(sys.prefix)
    if not (venv / "bin" / "stickslip").exists():
        pytest.skip("not running inside the project's virtual environment (make test builds it)")
    pytest.importorskip("PIL")
    results = tour_dir / "stickslip-results"
    if not (results / "measurements.csv").exists():  # run alone: the paper's 14 traverses stand in
        results.mkdir(exist_ok=True)
        (results / "measurements.csv").write_text(measurements_to_csv(paper_table()))
    lines = [ln[2:] for ln in _block("### Seeing the tip", "console").splitlines() if ln.startswith("$ ")]
    assert any("camera calibrate" in ln for ln in lines) and any("--step-sizes" in ln for ln in lines)
    script = "set -euo pipefail\n" + "\n".join(lines) + "\n"
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV",)}
    env["PATH"] = f"{venv / 'bin'}:/usr/bin:/bin"
    env["STICKSLIP_DB"] = str(tour_dir / "camera.db")
    r = subprocess.run(["bash", "-c", script], cwd=results, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    located = json.loads(r.stdout[r.stdout.index("[") : r.stdout.index("]") + 1])
    assert located[0]["x"] == 307.2 and abs(located[1]["x"] - 323.2) < 0.5  # 8 µm at 0.5 µm a pixel
    assert (results / "camera-steps.csv").read_text().count(",camera") == 2
    assert "step sizes" in json.loads((results / "cal-camera.json").read_text())["method"]
    assert "reached: the seen tip" in r.stdout  # the closed loop ended within its tolerance


def test_python_example_runs(tour_dir, monkeypatch):
    meas = tour_dir / "stickslip-results" / "measurements.csv"
    if not meas.exists():  # run alone: the paper's 14 traverses stand in for the demo's
        meas.parent.mkdir(exist_ok=True)
        meas.write_text(measurements_to_csv(paper_table()))
    monkeypatch.chdir(tour_dir)
    ns: dict = {}
    exec(compile(_block("## In Python", "python"), "README.md", "exec"), ns)
    assert ns["n"] > 0 and abs(ns["where"] - 0.00203) < ns["planner"].gamma(0.002, "+")


def test_emulator_example_runs():
    ns: dict = {}
    exec(compile(_block("No controller at hand?", "python"), "README.md", "exec"), ns)
    assert ns["emu"].url.startswith("mm3a://")
