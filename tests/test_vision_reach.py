"""The whole-frame search reaches a tip near the field's edge (docs/vision.md, "Find again").

A tip the tracker lost and that comes back close to the field's edge, far from its last
fix, can only be found by the search over the whole frame. On the own renderer
(``SimScene``, the needle placed directly), after a frame with the tip out of the field:
the tip 4 to 12 px inside the edge ahead of it (the needle's shaft runs back into the
field, so all it needs to be vouched for is in the frame) is fixed within a pixel. The
correlation under it (:func:`~stickslip.vision.template.inside_ncc`) is
checked against the weighted correlation summed pixel by pixel over the part of the
template inside the frame.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.template import inside_ncc, masked_ncc
from stickslip.vision.track import Fix, Lost, TipTracker, _by_rank, _ranked

SIZE = 160


def _brute_ncc(region: np.ndarray, inside: np.ndarray, t: np.ndarray, w: np.ndarray, i: int, j: int) -> float:
    """The weighted correlation of ``t`` with ``region[i:i+n, j:j+n]`` over the pixels inside, summed directly."""
    n = t.shape[0]
    ww = w * inside[i : i + n, j : j + n]
    im = region[i : i + n, j : j + n]
    sw = ww.sum()
    dt = t - (ww * t).sum() / sw
    di = im - (ww * im).sum() / sw
    return float((ww * dt * di).sum() / math.sqrt((ww * dt * dt).sum() * (ww * di * di).sum()))


def test_the_masked_correlation_counts_only_the_pixels_inside():
    rng = np.random.default_rng(4)
    n = 7
    t = rng.normal(size=(n, n))
    w = rng.uniform(0.2, 1.0, (n, n))
    region = rng.normal(size=(30, 26))
    inside = np.ones_like(region)
    inside[:5] = 0.0  # the frame's top rows and left columns lie outside
    inside[:, :4] = 0.0
    out, cover = inside_ncc(region * inside, inside, t, w)
    assert out.shape == cover.shape == (30 - n + 1, 26 - n + 1)
    for i, j in ((0, 0), (2, 1), (3, 9), (10, 2), (15, 15), (23, 19)):
        assert cover[i, j] == pytest.approx((w * inside[i : i + n, j : j + n]).sum() / w.sum(), abs=1e-12)
        if cover[i, j] > 0.3:
            assert out[i, j] == pytest.approx(_brute_ncc(region, inside, t, w, i, j), abs=1e-9)
    # all inside: the correlation without a mask, to rounding
    full = masked_ncc(region, t, w)
    inner, _ = inside_ncc(region, np.ones_like(region), t, w)
    np.testing.assert_allclose(inner, full, atol=1e-9)


def _found_again(look: str, width_px: float, shaft: tuple[float, float], at: tuple[float, float],
                 gone: tuple[float, float]) -> Fix | Lost:
    """The tip learnt at the field's middle, out of the field in the next frame, then at ``at``."""
    scene = SimScene(SimCamSettings(look=look, width=SIZE, height=SIZE, photons=200.0, seed=5,
                                    tip_radius_m=0.25e-6 * width_px, pixel_size_m=0.5e-6))
    d = np.array(shaft)
    tracker = TipTracker(scene.render(np.array([80.0, 80.0]), d, 0.0), (80.0, 80.0))
    assert isinstance(tracker.update(scene.render(np.array(gone), d, 0.0)), Lost)
    return tracker.update(scene.render(np.array(at), d, 0.0))


@pytest.mark.parametrize("inside", [6.0, 12.0])
def test_a_tip_back_near_the_edge_ahead_of_it_is_found_again(inside):
    # the needle enters from the left; the tip comes back near the right edge, 75 px from its last fix
    at = (SIZE - 1 - inside, 70.0)
    r = _found_again("optical", 16.0, (-1.0, 0.15), at, (SIZE + 20.0, 70.0))
    assert isinstance(r, Fix), r
    assert math.hypot(r.x - at[0], r.y - at[1]) < 1.0


def test_a_tip_back_4_px_inside_the_top_edge_is_found_again_in_an_sem():
    at = (70.0, 4.0)
    r = _found_again("sem", 6.0, (0.15, 1.0), at, (70.0, -20.0))
    assert isinstance(r, Fix), r
    assert math.hypot(r.x - at[0], r.y - at[1]) < 1.0


def test_a_peak_over_part_of_the_template_ranks_by_its_significance():
    ncc = np.zeros((20, 20))
    cover = np.ones((20, 20))
    ncc[5, 5], ncc[14, 14], ncc[5, 14] = 0.84, 0.87, 0.80  # the tip in the middle; junk at the border
    cover[14, 14], cover[5, 14] = 0.80, 1.0
    ranked = list(_by_rank([_ranked(ncc, cover, 2)]))
    assert [(i, j) for _, i, j, _ in ranked] == [(5, 5), (14, 14), (5, 14)]
    assert ranked[0][0] == pytest.approx(math.atanh(0.84))
    assert ranked[1][0] == pytest.approx(math.atanh(0.87) * math.sqrt(0.80))
    assert all(k == 2 for *_, k in ranked)


def test_a_tip_the_whole_frame_search_finds_and_a_rule_refuses_is_not_called_nowhere(monkeypatch):
    """The refusal names what refused the frame's best candidate (here: too near the edge to vouch for)."""
    scene = SimScene(SimCamSettings(look="optical", width=SIZE, height=SIZE, photons=200.0, seed=5,
                                    tip_radius_m=0.25e-6 * 16.0, pixel_size_m=0.5e-6))
    d = np.array((-1.0, 0.15))
    tracker = TipTracker(scene.render(np.array([80.0, 80.0]), d, 0.0), (80.0, 80.0))
    monkeypatch.setattr(tracker, "_local", lambda image: None)  # nothing near the last fix: only the whole frame
    r = tracker.update(scene.render(np.array([SIZE - 2.0, 70.0]), d, 0.0))
    assert isinstance(r, Lost) and r.reason == "lost"
    assert "the best candidate was refused (out of the field): the tip would be 1." in r.detail  # 1.0-1.1 px
    blank = np.full((SIZE, SIZE), float(np.median(scene.render(np.array([80.0, 80.0]), d, 0.0))))
    assert tracker.update(blank) == Lost("lost", "not found near the last fix nor anywhere in the frame")
