"""The first frame's focus read on the needle's shaft edges (vision/focus.py), and ``camera locate``'s warning."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.focus import first_frame_focus
from stickslip.vision.frame import Frame
from stickslip.vision.locate import locate_frames
from stickslip.vision.track import TipTracker

PIL = pytest.importorskip("PIL.Image")
TIP = (70.3, 80.6)
PHI = 0.5  # the shaft's direction from the tip, rad


def _frame(blur: float, tip: tuple[float, float] = TIP, defocus: str = "gaussian", seed: int = 1) -> np.ndarray:
    """A bright-field needle 8 px wide at 150 photons, its shaft along :data:`PHI`, blurred ``blur`` px."""
    scene = SimScene(SimCamSettings(look="optical", width=160, height=160, photons=150.0, seed=seed,
                                    tip_radius_m=2e-6, taper=math.radians(8.0), pixel_size_m=0.5e-6,
                                    defocus=defocus))
    return scene.render(np.array(tip), np.array([math.cos(PHI), math.sin(PHI)]), blur)


@pytest.mark.parametrize("blur, defocus", [(0.5, "gaussian"), (1.2, "gaussian"), (2.5, "gaussian"), (2.5, "disc")])
def test_the_edges_read_the_first_frames_blur(blur: float, defocus: str) -> None:
    img = _frame(blur, defocus=defocus)
    got = first_frame_focus(img, TIP, TipTracker(img, TIP).template.shaft)
    assert got is not None
    # own bright-field first frames (track73): Gaussian bias within 0.1 px, spread 0.06-0.12 px; the disc reads
    # +0.2 to +0.4 px high over 1.6 px (its edge profile's tails)
    lo, hi = (blur - 0.3, blur + 0.3) if defocus == "gaussian" else (blur, blur + 0.8)
    assert lo < got.sigma < hi, got
    assert 0 < got.se < 0.2


def test_no_edges_no_reading_and_locate_carries_it_on_the_first_frame_only() -> None:
    assert first_frame_focus(np.full((160, 160), 0.7), TIP, (math.cos(PHI), math.sin(PHI))) is None
    found = locate_frames([Frame(_frame(2.5, seed=s), source=f"f{s}") for s in (1, 2)], TIP)
    assert found[0].focus is not None and found[0].focus.sigma > 2.0 and found[1].focus is None
    assert set(found[0].as_dict()) == {"frame", "x", "y", "score"}


def _save(folder, blur: float) -> str:
    for k in range(3):
        tip = (TIP[0] + 1.5 * k, TIP[1] - 0.8 * k)
        PIL.fromarray((_frame(blur, tip, seed=k + 1) * 65535).astype(np.uint16)).save(folder / f"f{k}.png")
    return str(folder / "f*.png")


def test_locate_warns_in_one_line_on_a_blurred_first_frame_and_tracks_as_before(tmp_path) -> None:
    runner = CliRunner()
    blurred, sharp = tmp_path / "blurred", tmp_path / "sharp"
    blurred.mkdir()
    sharp.mkdir()
    args = ["camera", "locate", _save(blurred, 2.5), "--tip", f"{TIP[0]},{TIP[1]}", "--json"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: the first frame looks out of focus"), r.stderr
    assert "blurred by about 2." in lines[0]
    out = json.loads(r.stdout)  # stdout: the JSON only, as without the warning
    assert len(out) == 3 and all(set(o) == {"frame", "x", "y", "score"} for o in out)
    r = runner.invoke(app, ["camera", "locate", _save(sharp, 0.5), "--tip", f"{TIP[0]},{TIP[1]}", "--json"])
    assert r.exit_code == 0 and r.stderr == "", r.stderr
    assert len(json.loads(r.stdout)) == 3
