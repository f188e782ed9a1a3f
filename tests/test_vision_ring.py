"""A needle the window's ring hides: the first frame's background level and spread read on the ring.

A plain dark needle beside a large bright cell, the cell and the shaft over more than half the ring: the
ring's spread (its median absolute deviation) is raised until the needle does not stand 3 spreads out, and
the tip is not learnt ("nothing stands out"; issue 30, docs/vision-log.md, "The first frames' mismatch
limit, and a needle beside a bright cell").
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from scipy import ndimage
from vision_own import own_sequence

from stickslip.vision.frame import as_image
from stickslip.vision.template import TemplateError, TipTemplate, TrackerParams


@lru_cache(maxsize=1)
def _beside_a_cell() -> tuple[list[np.ndarray], list[tuple[float, float]], np.ndarray, float]:
    """A 12.4 px bright-field tip (278 photons) moving over 12 frames beside a still bright cell (radius 26 px,
    60 % over the ground, its rim 2 px ahead of the first frame's tip and to the side): the frames, the tips,
    the cell's footprint and the clean first frame's contrast."""
    seq = own_sequence(5, 12, 128, 12.4, "optical", photons=278, events=False)
    first = as_image(seq.frames[0].image)
    x, y = seq.frames[0].tip
    clean = TipTemplate.learn(first, (x, y))
    sx, sy = clean.shaft
    a = math.atan2(-sy, -sx) + 0.9
    cx, cy = x + 28.0 * math.cos(a), y + 28.0 * math.sin(a)
    yy, xx = np.mgrid[: first.shape[0], : first.shape[1]]
    cell = ndimage.gaussian_filter(np.clip(1.0 - (np.hypot(xx - cx, yy - cy) / 26.0) ** 4, 0.0, None), 1.5)
    bright = 0.6 * float(np.median(first)) * cell
    frames = [as_image(f.image) + bright for f in seq.frames]
    return frames, [f.tip for f in seq.frames], cell > 0.1, clean.contrast


def test_a_needle_beside_a_bright_cell_is_not_learnt() -> None:
    # the ring: a third cell, a quarter shaft; its median sits on the ground (0.82) but its spread is 0.25 where
    # the ground's own is 0.05, and the tip, 0.33 below the ground, stands 1.3 spreads out (docs/vision-log.md)
    frames, tips, _, _ = _beside_a_cell()
    with pytest.raises(TemplateError, match="nothing stands out"):
        TipTemplate.learn(frames[0], tips[0])


@pytest.mark.xfail(strict=True, reason="no reading of the ring learns it without taking in the cell or wrong SEM "
                                       "tips (docs/vision-log.md)", raises=TemplateError)
def test_a_needle_beside_a_bright_cell_is_learnt_without_the_cell() -> None:
    frames, tips, cell, contrast = _beside_a_cell()
    t = TipTemplate.learn(frames[0], tips[0])
    assert t.contrast == pytest.approx(contrast, rel=0.05)  # the needle's own contrast, not the cell's
    h = TrackerParams().half_window
    cx, cy = round(tips[0][0]), round(tips[0][1])
    assert not (t.mask & cell[cy - h : cy + h + 1, cx - h : cx + h + 1]).any()  # no pixel of the cell is needle
