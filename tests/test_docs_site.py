"""The documentation site builds without a warning (``mkdocs build --strict``), from the pages and the docstrings.

Skipped, with the reason, when the ``docs`` extra (mkdocs-material, mkdocstrings) is not
installed; ``make test`` installs it. What the build is checked for beyond "no warning":
every page under docs/ is in the navigation (mkdocs' ``omitted_files`` validation, strict),
the API pages hold the public names of the modules they document, and the notebook pages
show the notebooks' cells (docs/hooks.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

# make test-fast leaves this file out; one worker builds the site once for all its tests (--dist loadgroup)
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("docs_site")]

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")  # one build per run: the group keeps its tests on one worker
def site(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(module, reason="the docs extra is not installed: pip install -e '.[docs]'")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
    )
    log = run.stdout + run.stderr
    assert run.returncode == 0, log
    return out, log


def test_the_site_builds_without_warnings(site: tuple[Path, str]) -> None:
    _, log = site
    assert "WARNING" not in log, log


@pytest.mark.parametrize(
    "page, names",
    [
        ("api/calibration", ["stickslip.calibration.calibrate", "Calibration", "validate"]),
        ("api/models", ["JointModel", "PrismaticParams", "RotaryParams"]),
        ("api/motion", ["Planner", "plan_reach", "ReachPlan", "JointTrack"]),
        ("api/procedures", ["MoveRequest", "plan_tracked", "ObserveResult", "ReachRequest", "JogRequest",
                            "listen_blocks"]),
        ("api/bluesky", ["StickSlipAxis", "StickSlipManipulator", "TipAxis", "calibration_day", "STOP_RETURN_S"]),
        ("api/devices", ["Controller", "KnowsTruePosition", "NanoControl"]),
        ("howto/anc300", ["STICKSLIP_ANC300_PASSWORD", "stepu"]),
        ("howto/day-one", ["Day one on hardware", "18000", "126000", "backup", "Ctrl-C"]),
    ],
)
def test_api_pages_document_the_public_names(site: tuple[Path, str], page: str, names: list[str]) -> None:
    html = (site[0] / page / "index.html").read_text(encoding="utf-8")
    for name in names:
        assert name in html, f"{page} does not mention {name}"


@pytest.mark.parametrize("name", ["calibration-day", "bluesky-scan"])
def test_notebook_pages_show_every_cell_and_link_the_notebook(site: tuple[Path, str], name: str) -> None:
    import html as html_lib
    import re

    out = site[0]
    raw = (out / "notebooks" / name / "index.html").read_text(encoding="utf-8")
    text = " ".join(html_lib.unescape(re.sub(r"<[^>]+>", "", raw)).split())  # the page's text, tags dropped
    nb = json.loads((ROOT / "docs" / "notebooks" / f"{name}.ipynb").read_text(encoding="utf-8"))
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert len(code) >= 5
    for cell in code:  # the longest line of every code cell is on the page, as written
        line = max("".join(cell["source"]).splitlines(), key=len)
        assert " ".join(line.split()) in text
    title = "".join(nb["cells"][0]["source"]).splitlines()[0].lstrip("# ")
    assert title in text
    page = raw
    assert f"{name}.ipynb" in page
    assert (out / "notebooks" / f"{name}.ipynb").exists()  # the download link's target
