"""The needle's outline read one edge at a time (stickslip.vision.width.check_outline): what vouches for a fit
behind which the needle leaves the field.

A blunt (paraboloid-ended) bright-field needle 14 px wide is learnt in the middle of a 160 px field, its shaft
running up and to the left; later it is held with its tip 10 to 16 px below the top edge, its shaft leaving the
field by that edge, so that fewer than three of the width stations lie in the frame behind it. The outline's
stations, every 2 px from 4 to 40 px behind the tip, are read on the one edge whose registration lies in the frame.
At the tip that edge lies where the first frame had it; a sideways offset of the fit moves it alike at every
station (its median shift, not its closing); a dark bead over the tip, its far rim taken for the tip, has the
outline close behind the rim by several px (docs/vision-log.md, "Vouching near the edge from one edge of the
outline").
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest
from scipy import ndimage

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.track import Fix, Lost, TipTracker, TrackerParams
from stickslip.vision.width import OutlineStations, check_outline, check_width

SIZE = 160
D = np.array((-1.0, -0.25))  # from the tip back along the shaft
U = D / np.hypot(*D)
N = np.array((-U[1], U[0]))
P = TrackerParams()


@lru_cache(maxsize=1)
def _scene() -> tuple[SimScene, np.ndarray]:
    scene = SimScene(SimCamSettings(look="optical", width=SIZE, height=SIZE, photons=200.0, seed=5,
                                    tip_radius_m=0.25e-6 * 14.0, pixel_size_m=0.5e-6, end="paraboloid"))
    return scene, scene.render(np.array((100.0, 90.0)), D, 0.0)


@lru_cache(maxsize=1)
def _outline() -> OutlineStations:
    scene, first = _scene()
    t = TipTracker(first, (100.0, 90.0))
    assert t._outline is not None
    return t._outline


def _near_the_top(y: float) -> tuple[tuple[float, float], np.ndarray]:
    scene, _ = _scene()
    tip = (110.0, y)
    return tip, scene.render(np.array(tip), D, 0.0)


def _with_a_bead(frame: np.ndarray, tip: tuple[float, float], radius: float, ahead: float
                 ) -> tuple[np.ndarray, tuple[float, float]]:
    """``frame`` with a disc as dark as the needle's middle over the tip, its middle ``ahead`` px ahead of the
    tip (its outline softened by 0.7 px), and the disc's far rim."""
    core = float(np.median(frame[int(tip[1]) - 1 : int(tip[1]) + 2, int(tip[0]) + 3 : int(tip[0]) + 7]))
    c = np.array(tip) - ahead * U
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    m = ndimage.gaussian_filter(((xx - c[0]) ** 2 + (yy - c[1]) ** 2 <= radius * radius).astype(float), 0.7)
    rim = c - radius * U
    return frame * (1.0 - m) + core * m, (float(rim[0]), float(rim[1]))


def test_the_outline_s_stations_are_learnt_every_2_px() -> None:
    o = _outline()
    assert o.s[0] == 4.0 and o.s[-1] == 40.0 and np.allclose(np.diff(o.s), 2.0)


@pytest.mark.parametrize("y", [10.0, 16.0])
def test_at_the_tip_one_edge_lies_where_the_first_frame_had_it(y: float) -> None:
    tip, frame = _near_the_top(y)
    ws = _outline()
    reach, closing, offset = check_outline(ws, 0, frame, *tip, 0.0)
    assert reach >= P.outline_reach and closing < 1.0 and offset < 0.2


@pytest.mark.parametrize("side", [1.0, 3.0])
def test_a_sideways_offset_moves_the_edge_alike_at_every_station(side: float) -> None:
    tip, frame = _near_the_top(12.0)
    reach, closing, offset = check_outline(_outline(), 0, frame, tip[0] + side * N[0], tip[1] + side * N[1], 0.0)
    _, closing0, _ = check_outline(_outline(), 0, frame, *tip, 0.0)
    assert closing == pytest.approx(closing0, abs=0.1)  # the closing does not see it
    assert offset == pytest.approx(side, abs=0.3)  # the median shift does


@pytest.mark.parametrize("y", [10.0, 16.0])
def test_behind_a_bead_s_rim_taken_for_the_tip_the_outline_closes(y: float) -> None:
    tip, frame = _near_the_top(y)
    img, rim = _with_a_bead(frame, tip, 9.0, 3.0)  # the rim 12 px ahead of the tip
    reach, closing, offset = check_outline(_outline(), 0, img, *rim, 0.0)
    assert reach >= P.outline_reach and closing > 3.0 * P.outline_slack and offset > P.outline_slack


def test_a_tip_near_the_edge_its_shaft_leaves_by_is_vouched_for_by_its_outline() -> None:
    """With the found-again rules' vouching made impossible (``unvouched_sigma`` 0.01 px), only the outline
    vouches: fixed 40 px below the top edge (width stations checked), then 12 px below it (none in the frame),
    the fit near the last fix is taken with the outline, refused without (and the whole frame's search too)."""
    scene, first = _scene()
    before, frame_before = _near_the_top(40.0)
    tip, frame = _near_the_top(12.0)
    strict = replace(P, unvouched_sigma=0.01)
    answers = []
    for params in (strict, replace(strict, outline_reach=math.inf)):
        t = TipTracker(first, (100.0, 90.0), params)
        r0 = t.update(frame_before)
        assert isinstance(r0, Fix) and math.hypot(r0.x - before[0], r0.y - before[1]) < 0.5
        assert t._width is not None and check_width(t._width, 0, frame, *tip, 0.0, P.along_limit,
                                                    P.along_sigmas) is None
        answers.append(t.update(frame))
    r, refused = answers
    assert isinstance(r, Fix) and math.hypot(r.x - tip[0], r.y - tip[1]) < 0.5
    assert isinstance(refused, Lost) and "nothing vouches" in refused.detail
