"""The first frame's width stations as a test reads them: learnt from a template of the frame, smoothed as each blur
copy of the bank is (the tracker's own call, `track._learn_shaft`, takes the sharpening copies too)."""

from __future__ import annotations

import math

import numpy as np

from stickslip.vision.template import TipTemplate, TrackerParams
from stickslip.vision.width import WidthStations, learn_width


def learnt_width(first: np.ndarray, tip: tuple[float, float], p: TrackerParams | None = None,
                 extent: bool = True) -> WidthStations:
    """``first``'s width stations behind ``tip`` (x, y px) with the tracker's constants ``p``; ``extent`` False: the
    needle's extent across the shaft not learnt (``depth`` inf)."""
    p = TrackerParams() if p is None else p
    t = TipTemplate.learn(first, tip, p)
    smooth = [(math.hypot(p.template_blur, b), p.template_blur) for b in p.blur_bank]
    ws = learn_width(first, tip, t.shaft, t.ground[0], t.ground[1], p.contrast, t.noise, smooth, p.width_shift,
                     p.width_slack, p.extent_depth if extent else math.inf)
    assert ws is not None, "fewer than three width stations in the first frame"
    return ws
