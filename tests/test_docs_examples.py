"""Every shell and Python example in the README and in docs/ runs (docs/style.md: examples run).

* Console blocks (lines starting with ``$ ``) of docs/*.md run as written in bash, from a
  fresh folder that holds only the project's ``.venv`` (as after the README's two set-up
  commands), one block after another so later blocks see what earlier ones made.
* The README's blocks for hardware run against stand-ins the tests make: a recording from
  the simulator's sound for ``tune``/``listen``, the NanoControl protocol emulator on a
  pseudo-terminal for ``where``/``move`` (its URL in place of ``mm3a:///dev/ttyUSB0``).
  The live-microphone line needs a sound card and is the one line not run.
* A block marked ```text (a picture, a file format) is not code and is not run.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
POSIX = pytest.mark.skipif(sys.platform == "win32", reason="the examples are POSIX shell sessions (bash)")


def console_lines(text: str) -> list[list[str]]:
    """The ``$ `` lines of every console block, block by block."""
    blocks = re.findall(r"```console\n(.*?)```", text, re.S)
    return [[ln[2:] for ln in b.splitlines() if ln.startswith("$ ")] for b in blocks]


def _venv_folder(tmp: Path) -> dict[str, str]:
    venv = Path(sys.prefix)
    if not (venv / "bin" / "activate").exists() or not (venv / "bin" / "stickslip").exists():
        pytest.skip("not running inside the project's virtual environment (make test builds it)")
    (tmp / ".venv").symlink_to(venv, target_is_directory=True)
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["PATH"] = "/usr/bin:/bin"  # nothing of the project's on the PATH until the example activates it
    env["COLUMNS"] = "120"
    return env


def _bash(lines: list[str], cwd: Path, env: dict[str, str], timeout: float = 600) -> subprocess.CompletedProcess[str]:
    script = "set -euo pipefail\n" + "\n".join(lines) + "\n"
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def test_every_docs_page_with_console_blocks_is_listed_here():
    """A new page with shell examples must be run by a test: this list names the pages that have them.

    Every folder of docs/ counts (docs/howto/ too: a guide there is what a newcomer copies first)."""
    pages = sorted(
        p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md") if console_lines(p.read_text(encoding="utf-8"))
    )
    listed = sorted([*RUN_PAGES, *RUN_IN_README, *RUN_ELSEWHERE])
    assert pages == listed, f"pages with console blocks: {pages}; run them in this module"
    for page, test in RUN_ELSEWHERE.items():  # the test named runs that page's file
        assert page in (ROOT / "tests" / test).read_text(encoding="utf-8").replace('" / "', "/"), (page, test)


RUN_PAGES = ["tutorial.md", "config.md", "rig.md"]  # config.md names its own $STICKSLIP_CONFIG
RUN_IN_README = ["vision.md"]  # its one block is the README's camera block, which tests/test_readme.py runs
RUN_ELSEWHERE = {
    "howto/day-one.md": "test_day_one.py",  # against the NanoControl console emulator
    "taskspace.md": "test_docs_examples.py",  # its joint-1 loop: test_the_taskspace_joint_1_loop_runs_as_written
}


def test_the_vision_page_runs_as_the_readme_camera_block(tmp_path):
    """docs/vision.md's block is the README's camera block from a fresh folder: the README's first line only states
    the simulator's default pose (the arm outstretched), so running the README's block runs the page's lines as
    written (tests/test_readme.py, in a fresh database) instead of a second time here."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    page = console_lines((DOCS / "vision.md").read_text(encoding="utf-8"))
    readme = _readme_block_after("### Seeing the tip")
    assert len(page) == 1 and page[0][0].startswith(". .venv/bin/activate")

    def command(line: str) -> str:  # the line without its comment (the two pages comment it differently)
        return line.split("  #")[0].rstrip()

    first, rest = command(readme[0]).split(), [command(ln) for ln in readme[1:]]
    assert first[:4] == ["stickslip", "where", "-d", "sim://"]
    assert [command(ln) for ln in page[0][1:]] == rest[: len(page[0]) - 1]
    fresh = CliRunner().invoke(app, ["where", "-d", "sim://", "--db", str(tmp_path / "fresh.db"), "--json"])
    assert fresh.exit_code == 0, fresh.output
    default = {j["joint"]: j["q"] for j in json.loads(fresh.stdout)["joints"]}
    assert first[4:] == ["--set", "1=0", "--set", "2=-90deg", "--set", "3=0", "--theta", "0", "--psi", "0"]
    assert default == {1: 0.0, 2: -math.pi / 2, 3: 0.0}


@POSIX
@pytest.mark.parametrize("page", RUN_PAGES)
def test_docs_page_runs_as_written(page, tmp_path):
    env = _venv_folder(tmp_path)
    blocks = console_lines((DOCS / page).read_text(encoding="utf-8"))
    assert blocks and blocks[0][0].startswith(". .venv/bin/activate")
    if page == "tutorial.md":  # where the tutorial's move ended, asked right after its third block
        blocks = [*blocks[:3], [TUTORIAL_WHERE], *blocks[3:]]
    r = _bash([ln for b in blocks for ln in b], tmp_path, env)
    assert r.returncode == 0, f"{page}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    assert "Traceback" not in r.stderr
    if page == "config.md":
        _check_config_page(tmp_path, env)
    if page == "tutorial.md":
        # the tutorial's move: 2.03 mm, dead reckoning lands within half a step
        q3 = json.loads((tmp_path / "where.json").read_text())["joints"][2]["q"]
        assert abs(q3 - 0.00203) < 1e-6, q3


@POSIX
def test_the_taskspace_joint_1_loop_runs_as_written(tmp_path):
    """docs/taskspace.md's joint-1 traverses on `sim://?seed=3` (the config file's device), appended to a day's table
    of joints 2 and 3, calibrate joint 1 near the simulator's own model (the page: within 2.5 % for γ0)."""
    from server_support import true_calibration
    from synth import paper_table
    from tuned import tune

    from stickslip.calibration import Calibration
    from stickslip.measurements import measurements_to_csv
    from stickslip.sim.arm import SimulatedMM3A

    env = _venv_folder(tmp_path)
    url = "sim://?seed=3"
    samples, rate, stop_at = SimulatedMM3A(seed=3).labelled_recording(1, "+")
    tune(samples, rate, stop_at, joint=1).save(tmp_path / "tuning-joint1.json")
    (tmp_path / "day1.csv").write_text(measurements_to_csv(paper_table()))  # the day's joints 2 and 3
    (tmp_path / "config.toml").write_text(f'device = "{url}"\n')
    env.update(STICKSLIP_CONFIG=str(tmp_path / "config.toml"), STICKSLIP_DB=str(tmp_path / "s.db"))
    lines = console_lines((DOCS / "taskspace.md").read_text(encoding="utf-8"))
    assert len(lines) == 1 and lines[0][0].startswith("for th in 0 -90deg")
    r = _bash([". .venv/bin/activate", *lines[0]], tmp_path, env)
    assert r.returncode == 0, f"{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    cal, truth = Calibration.load(tmp_path / "cal.json"), true_calibration(url)
    assert cal.joints == [1, 2, 3]
    for d in "+-":  # gamma0 at q3 = 0 and 12 mm (Eq. 8), rad
        for gamma0, true_gamma0 in zip(cal.model(1, d).params.gamma0, truth.model(1, d).params.gamma0, strict=True):
            assert abs(gamma0 / true_gamma0 - 1) < 0.05, (d, gamma0, true_gamma0)


TUTORIAL_WHERE = "stickslip where -d 'sim://?seed=3' --offline --json > where.json"


def _check_config_page(tmp: Path, env: dict[str, str]) -> None:
    """What docs/config.md says each level did: file, env and option, by what the commands kept."""
    assert json.loads((tmp / "env.json").read_text())["settings"]["database"]["source"] == "env"
    options = (tmp / "options.txt").read_text()
    assert "option --db" in options and "option --device" in options
    env = {**env, "STICKSLIP_CONFIG": str(tmp / "lab" / "config.toml")}
    env.pop("STICKSLIP_DB", None)
    r = _bash([". .venv/bin/activate", "stickslip where --offline --json"], tmp, env)
    kept = json.loads(r.stdout)
    assert kept["device"] == "sim://?seed=3"  # the file's device, its positions in the file's database
    assert abs(kept["joints"][2]["q"] - 30e-6) < 1.5e-6  # the move of 30 um, dead-reckoned (within a step)
    assert (tmp / "lab" / "lab.db").is_file() and not (tmp / "other.db").exists()


README = (ROOT / "README.md").read_text(encoding="utf-8")


def _readme_block_after(heading: str) -> list[str]:
    start = README.index(heading)
    return console_lines(README[start:])[0]


@POSIX
def test_readme_audio_example_runs_on_a_recording(tmp_path):
    """`record`, `listen` and `tune` as the README writes them (record makes the recording on sim://)."""
    env = _venv_folder(tmp_path)
    env["STICKSLIP_DB"] = str(tmp_path / "audio.db")
    lines = [ln for ln in _readme_block_after("## The audio limit switch") if "--mic" not in ln]
    assert len(lines) == 3 and lines[0].startswith("stickslip record")
    r = _bash([". .venv/bin/activate", *lines], tmp_path, env, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    stop = float(re.search(r"stop at ([0-9.]+) s", r.stdout).group(1))  # record says where it put the stop
    out = r.stdout.splitlines()
    first = next(i for i, ln in enumerate(out) if ln.startswith(("[", "{")))  # listen --json
    last = next(i for i in range(first, len(out)) if out[i].startswith(("]", "}")))
    found = json.loads("\n".join(out[first : last + 1]))
    assert len(found) == 1 and abs(found[0]["onset_s"] - stop) < 0.025
    assert (tmp_path / "joint3-tuning.json").exists()


@POSIX
def test_readme_hardware_moves_run_against_the_emulator(tmp_path):
    """`where`/`move` on mm3a:///dev/ttyUSB0 as written, the emulator's pseudo-terminal standing in for the port."""
    from synth import paper_table

    from stickslip.measurements import measurements_to_csv
    from stickslip.sim.emulators import NanoControlEmulator

    env = _venv_folder(tmp_path)
    env["STICKSLIP_DB"] = str(tmp_path / "hw.db")
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    lines = _readme_block_after("### Moving with the model")
    with NanoControlEmulator() as emu:
        lines = [ln.replace("mm3a:///dev/ttyUSB0", emu.url) for ln in lines]
        # the calibration records the device its traverses came from (the one the moves then drive)
        calibrate = f"stickslip calibrate meas.csv -o cal.json --device {emu.url}"
        r = _bash([". .venv/bin/activate", calibrate, *lines], tmp_path, env)
    assert r.returncode == 0, f"{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    assert "Traceback" not in r.stderr
