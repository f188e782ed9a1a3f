"""The needle's width behind a candidate tip (stickslip.vision.width), on the simulated microscope's needle.

The needle (a cone of half-angle 8 deg, so its width grows by 2 tan 8 deg = 0.281 px a px
away from the tip) runs from its tip at x = 60 px to the field's left edge. At the true
tip every station has the first frame's width; a candidate displaced by ``d`` px along the
axis finds the needle ``0.281 d`` px narrower (ahead of the tip) or wider (behind it) at
each station, read in full (the shaft's first-order taper reads 5 px as 3.0 to 4.6 px).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from width_learnt import learnt_width

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.template import TrackerParams
from stickslip.vision.width import FROM, WidthStations, _on_the_taper, check_width

SHAFT = np.array([-1.0, 0.15])
TIP = (60.0, 80.0)
GROWTH = 2.0 * math.tan(math.radians(8.0))  # the cone's full width, px per px along it


@lru_cache(maxsize=2)
def _learnt(look: str) -> tuple[np.ndarray, WidthStations]:
    scene = SimScene(SimCamSettings(look=look, width=160, height=160, photons=200.0, seed=5,
                                    tip_radius_m=0.25e-6 * 10.0, pixel_size_m=0.5e-6, taper=math.radians(8.0)))
    ws = learnt_width(scene.render(np.array(TIP), SHAFT, 1.0), TIP, extent=False)
    return scene.render(np.array(TIP), SHAFT, 1.0), ws


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_the_taper_is_learnt_from_the_first_frame(look: str) -> None:
    _, ws = _learnt(look)
    assert ws.s[-1] >= 42.0 and np.all(np.diff(ws.s) > 0) and ws.s[0] >= FROM
    # beyond the rounded apex (radius 5 px) the width grows as the cone's
    cone = ws.taper[ws.s >= 12.0]
    assert np.median(cone) == pytest.approx(GROWTH, rel=0.2)


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_at_the_tip_the_needle_is_as_wide_as_first_seen(look: str) -> None:
    frame, ws = _learnt(look)
    p = TrackerParams()
    at = check_width(ws, 0, frame, *TIP, 0.0, p.along_limit, p.along_sigmas)
    assert at is not None and at.n == ws.s.size
    assert max(abs(d) for d in at.dw) < 1.0 and at.disagree == 0 and at.excess < 0.0, at


@pytest.mark.parametrize("look", ["optical", "sem"])
@pytest.mark.parametrize("d", [-12.0, 12.0])
def test_a_candidate_displaced_along_the_axis_reads_the_whole_displacement(look: str, d: float) -> None:
    """``d`` > 0: the candidate ``d`` px ahead of the tip (the needle narrower behind it), < 0: behind it."""
    frame, ws = _learnt(look)
    p = TrackerParams()
    u = SHAFT / np.hypot(*SHAFT)  # from the tip back along the needle
    got = check_width(ws, 0, frame, TIP[0] - d * u[0], TIP[1] - d * u[1], 0.0, p.along_limit, p.along_sigmas)
    assert got is not None
    on_cone = [w for w, s in zip(got.dw, got.s, strict=True) if s - max(d, 0.0) >= 12.0]
    assert len(on_cone) >= 3
    assert float(np.median(on_cone)) == pytest.approx(-d * GROWTH, rel=0.25), got
    assert got.excess > 0.0  # refused: 12 px is beyond 3 px plus 3 standard deviations


def test_stations_off_the_needle_s_straight_taper_are_not_used() -> None:
    s = np.arange(6.0, 55.0, 6.0)
    # an SEM needle whose dark middle split the run found from 48 px on (one bright edge's width)
    assert _on_the_taper(s, np.array([11.0, 15, 19, 21, 25, 27, 30, 13, 11]), 2.0) == [0, 1, 2, 3, 4, 5, 6]
    # a dust grain beside the needle merged into its run at the first two stations
    assert _on_the_taper(s[:8] + 12.0, np.array([29.0, 27, 17, 18, 19, 21, 22, 22]), 2.0) == [2, 3, 4, 5, 6, 7]
    assert _on_the_taper(s[:2], np.array([10.0, 12.0]), 2.0) == []
