"""A tip given on the needle's shaft, not at its end, is refused when the template is learnt (audit40's question).

Before, a pixel on the shaft learnt a patch of two parallel edges; the tip moving 4 px a frame along the needle
was tracked as 0.4 px, each fix with the score of a good one (about 1.0): positions silently wrong. The needles
here are drawn by this file (a dark or bright wedge with a round end, blurred, with noise), not by the project's
renderers.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import ndimage
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.vision.template import TemplateError, TipTemplate


def _needle(angle: float, width: float, blur: float, sign: float, seed: int) -> tuple[np.ndarray, tuple[float, float]]:
    """A 128 x 128 frame of a needle whose end is at the centre, its shaft leaving at ``angle`` (rad)."""
    n = 128
    end = (64.3, 63.8)
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    bx, by = math.cos(angle), math.sin(angle)
    s = (xx - end[0]) * bx + (yy - end[1]) * by  # along the shaft, from the end
    d = np.abs(-(xx - end[0]) * by + (yy - end[1]) * bx)  # across
    half = 0.5 + 0.5 * width * np.clip(s / 20.0, 0.0, 1.0) + 0.02 * np.clip(s - 20.0, 0.0, None)
    inside = ((s >= 0) & (d <= half)) | (np.hypot(xx - end[0], yy - end[1]) <= 0.5)
    img = 0.5 + sign * 0.3 * inside.astype(float)
    img = ndimage.gaussian_filter(img, blur)
    rng = np.random.default_rng(seed)
    return img + rng.normal(0.0, 0.01, img.shape), end


@pytest.mark.parametrize("width", [3.0, 10.0, 20.0])
@pytest.mark.parametrize("blur", [0.7, 3.0])
@pytest.mark.parametrize("angle_deg", [0.0, 37.0, 200.0])
def test_the_end_is_learnt_and_a_pixel_on_the_shaft_is_refused(width: float, blur: float, angle_deg: float) -> None:
    a = math.radians(angle_deg)
    img, (ex, ey) = _needle(a, width, blur, -1.0 if width != 10.0 else 1.0, seed=int(width * 10 + blur))
    TipTemplate.learn(img, (ex, ey))  # its end: learnt
    TipTemplate.learn(img, (ex + 2 * math.cos(a), ey + 2 * math.sin(a)))  # 2 px behind it: still its end's region
    said = []
    for back in (24.0, 40.0):
        with pytest.raises(TemplateError, match="put the tip on the needle's very end") as e:
            TipTemplate.learn(img, (ex + back * math.cos(a), ey + back * math.sin(a)))
        said.append("is on the needle's shaft, not at its end" in str(e.value))
    # a shaft as wide as 20 px fills the background ring on both sides: at 40 px it may stand out of nothing
    assert said[0] and (said[1] or width == 20.0)


def test_camera_locate_refuses_a_tip_given_on_the_shaft(tmp_path, monkeypatch) -> None:
    pytest.importorskip("PIL.Image")
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    cam = "simcam://?pixel=1um"
    tips = []
    for k in range(2):
        assert runner.invoke(app, ["where", "-d", "sim://", "--set", f"3={4 * k}um"]).exit_code == 0
        r = runner.invoke(app, ["camera", "grab", "-d", "sim://", "--camera", cam, "-o", f"f{k}.png", "--json"])
        assert r.exit_code == 0, r.output
        tips.append(json.loads(r.stdout)["sim_true_tip"])
    (x, y), (x1, _) = tips
    assert x1 - x == pytest.approx(4.0, abs=0.2)  # the needle points along +x: its shaft lies towards -x
    r = runner.invoke(app, ["camera", "locate", "f0.png", "f1.png", "--tip", f"{x - 25},{y}", "--json"])
    assert r.exit_code == 2 and r.stdout == ""
    assert r.stderr.startswith("error: ") and "is on the needle's shaft, not at its end" in r.stderr
    r = runner.invoke(app, ["camera", "locate", "f0.png", "f1.png", "--tip", f"{x},{y}", "--json"])
    assert r.exit_code == 0 and json.loads(r.stdout)[1]["x"] == pytest.approx(x1, abs=0.5)
