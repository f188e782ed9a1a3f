"""The example notebooks in docs/notebooks/ run on the simulator, and say what they should.

Each notebook is executed by a fresh Jupyter kernel (nbclient) in a temporary folder, with
the environment pinned: ``HOME``, ``STICKSLIP_DB`` and the Jupyter/IPython folders in the
temporary folder, ``STICKSLIP_TODAY`` fixed (conftest), matplotlib without a display. A cell
that raises fails the test with the cell's traceback. The outputs are then read back and set
against what the notebook claims, from the simulator's own truth (printed by the notebook
beside the model's numbers), not from the model's view of itself.

The notebooks are kept in the repository without outputs (checked here).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

NOTEBOOKS = Path(__file__).resolve().parents[1] / "docs" / "notebooks"
CELL_TIMEOUT_S = 300  # a hang is a failure, not a stuck suite; the notebooks take ~10 s each


def _run(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """Execute notebook ``name`` in ``tmp_path``; its outputs as text (each rich output followed by its kinds)."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    home = tmp_path / "home"
    home.mkdir()
    for key, value in {
        "HOME": home,
        "USERPROFILE": home,
        "IPYTHONDIR": home / ".ipython",
        "JUPYTER_RUNTIME_DIR": home / "jupyter-runtime",
        "JUPYTER_DATA_DIR": home / "jupyter-data",
        "JUPYTER_CONFIG_DIR": home / "jupyter-config",
        "MPLCONFIGDIR": home / "mpl",
        "STICKSLIP_DB": tmp_path / "stickslip.db",
    }.items():
        monkeypatch.setenv(key, str(value))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv("JUPYTER_PLATFORM_DIRS", "1")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=CELL_TIMEOUT_S, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    text = ""
    for cell in nb.cells:
        for out in cell.get("outputs", []):
            if out.get("output_type") == "stream":
                text += out["text"]  # a print may come in pieces
            elif "data" in out:
                kinds = sorted(out["data"])
                text += "\n" + out["data"].get("text/plain", "") + f"\n[{', '.join(kinds)}]\n"
    return text


@pytest.mark.parametrize("path", sorted(NOTEBOOKS.glob("*.ipynb")), ids=lambda p: p.name)
def test_notebooks_are_kept_without_outputs(path: Path) -> None:
    import json

    nb: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [] and cell["execution_count"] is None, f"{path.name}: strip its outputs"
    page = path.with_suffix(".md").read_text(encoding="utf-8")
    assert f"<!-- notebook: {path.name} -->" in page  # the site shows it (docs/hooks.py)


def test_calibration_day_notebook(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = _run("calibration-day.ipynb", tmp_path, monkeypatch)
    # the calibrated parameters against the simulator's true ones: the audio limit switch counts within
    # a few steps of the truth over ~12000 (joint 3) and ~1500 (joint 2) steps, so well under 2 %
    rels = [float(m) for m in re.findall(r"\(([\d.]+)%\)", text)]
    assert len(rels) == 14  # a, b, c of joint 3 and gamma0, d at q3 = 0 and 12 mm of joint 2, in + and -
    (worst,) = re.findall(r"largest relative error: ([\d.]+)%", text)
    assert float(worst) == max(rels) < 2.0
    (steps,) = re.findall(r"(\d+) steps for 30 µm", text)
    # 30 µm at 0.5-1 µm a step (the prismatic step's size, Eq. 2: a ~ 1 µm shrunk by (1 - b |cos q2|) and the load)
    assert 30 <= int(steps) <= 60
    # this run's traverses, and all the database holds (a run of the notebook in a used folder said "kept 28")
    assert "kept 14 traverses and the calibration in calibration-day.db (14 traverses there)" in text
    assert (tmp_path / "calibration-day.db").exists()
    assert "Calibration(" in text and "ValidationResult(" in text
    assert text.count("image/png") == 1  # the figure is shown
    assert text.count("text/html") >= 3  # the traverse table, the calibration, the validation show as tables


def test_bluesky_scan_notebook(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("bluesky")
    pytest.importorskip("ophyd_async")
    text = _run("bluesky-scan.ipynb", tmp_path, monkeypatch)
    rows = [
        tuple(float(v) for v in m)
        for m in re.findall(r"^\s*([\d.]+)\s+([\d.]+)\s+-?\d+\s+([\d.]+)\s+(-?[\d.]+)$", text, re.M)
    ]
    assert len(rows) == 5  # five events
    targets = [r[0] for r in rows]
    assert targets == pytest.approx([1000.0, 1500.0, 2000.0, 2500.0, 3000.0])
    readbacks = [r[1] for r in rows]
    assert all(b > a for a, b in zip(readbacks, readbacks[1:], strict=False))  # rising through the targets
    assert all(abs(rb - t) <= 1.5 for rb, t in zip(readbacks, targets, strict=True))  # within a step (~1 µm)
    truths = [r[2] for r in rows]  # the simulator's true joint: within 1 % of the move from the start (0)
    assert all(abs(tr - t) <= 0.01 * t for tr, t in zip(truths, targets, strict=True))
    (tip,) = re.findall(r"tip \(µm\): ([-\d.]+), ([-\d.]+), ([-\d.]+)", text)
    assert float(tip[1]) == pytest.approx(1000.0, abs=2.0)  # tip.y moved to 1 mm
    assert text.count("UserWarning: joint 1 is not in this calibration") == 1  # the warning its markdown announces
    assert (tmp_path / "bluesky-scan.db").exists()
    assert text.count("image/png") == 1  # the figure is shown
