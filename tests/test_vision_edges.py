"""The edge stage (vision/edges.py): the needle's two edges followed back from a candidate tip.

Frames of the simulated microscope's renderer (``SimScene``) with the needle placed
directly; each check is made at a known place against the truth.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.edges import check_edges, learn_edges
from stickslip.vision.sampling import patch
from stickslip.vision.template import TipTemplate, TrackerParams
from stickslip.vision.track import Fix, Lost, TipTracker

TIP = np.array([60.3, 62.7])
SHAFT = np.array([1.0, 0.35]) / math.hypot(1.0, 0.35)  # from the tip back along the needle


def _scene(look: str, seed: int = 3) -> SimScene:
    return SimScene(SimCamSettings(look=look, width=128, height=128, photons=200.0, seed=seed,
                                   tip_radius_m=2e-6, pixel_size_m=0.5e-6))


def _check(template: TipTemplate, image: np.ndarray, at: np.ndarray):  # type: ignore[no-untyped-def]
    ep = learn_edges(template.bank, template.apex, template.mask, template.shaft)
    noise = template.noise / (2.0 * math.sqrt(math.pi))  # a sample of the frame smoothed by 1 px
    return check_edges(ep, 0, patch(image, float(at[0]), float(at[1]), 40.0, 1.0), float(at[0]), float(at[1]),
                       0.0, noise)


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_the_edges_behind_the_true_tip_hold(look):
    scene = _scene(look)
    first = scene.render(TIP, SHAFT, 0.5)
    t = TipTemplate.learn(first, (float(TIP[0]), float(TIP[1])))
    ec = _check(t, scene.render(TIP, SHAFT, 0.5), TIP)
    assert ec is not None
    p = TrackerParams()
    assert 0.8 <= ec.far <= 1.2  # the needle as in the first frame: its contrast again
    assert ec.near >= p.edge_near * ec.far and ec.shape >= p.edge_shape
    assert abs(ec.shift) <= 0.5


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_a_fit_ahead_of_the_tip_finds_the_edges_fading_behind_it(look):
    """5 px ahead of the tip the first stations see ground: the edges stop short of the candidate."""
    scene = _scene(look)
    first = scene.render(TIP, SHAFT, 0.5)
    t = TipTemplate.learn(first, (float(TIP[0]), float(TIP[1])))
    ec = _check(t, scene.render(TIP, SHAFT, 0.5), TIP - 5.0 * SHAFT)
    assert ec is not None
    assert ec.near < TrackerParams().edge_near * ec.far


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_plain_ground_has_no_edges(look):
    """Where the needle is not, the profiles' contrast against the template's is far below 0.6."""
    scene = _scene(look)
    first = scene.render(TIP, SHAFT, 0.5)
    t = TipTemplate.learn(first, (float(TIP[0]), float(TIP[1])))
    away = np.array([400.0, 400.0])  # the needle far out of the field
    ec = _check(t, scene.render(away, SHAFT, 0.5), TIP)
    assert ec is not None
    assert ec.far < TrackerParams().edge_contrast


def test_a_needle_gone_from_the_field_is_never_fixed():
    """The tracker on frames with no needle at all: every one refused (the ground fitted through the
    brightness planes correlates well with a blurred copy; its edges are missing)."""
    scene = _scene("sem", seed=5)
    tracker = TipTracker(scene.render(TIP, SHAFT, 0.5), (float(TIP[0]), float(TIP[1])))
    assert isinstance(tracker.update(scene.render(TIP, SHAFT, 0.5)), Fix)
    for k in range(4):
        r = tracker.update(scene.render(np.array([400.0, 400.0 + k]), SHAFT, 0.5 + 0.5 * k))
        assert isinstance(r, Lost), r
    r = tracker.update(scene.render(TIP + 2.0, SHAFT, 0.5))  # and found again when it comes back
    assert isinstance(r, Fix) and math.hypot(r.x - TIP[0] - 2.0, r.y - TIP[1] - 2.0) <= 1.0


def test_a_tip_that_left_the_field_is_not_fixed_on_the_ground():
    """An own sequence with many events, where the second round's tracker gave 8 of these frames a fix
    3 to 139 px off, most on the ground while the tip was out of the field (its fit correlated by
    0.89 there); the edges refuse them."""
    from vision_own import own_sequence

    seq = own_sequence(4003, 24, 256, 12.0, "sem", event_rate=0.3)
    tracker = TipTracker(seq.frames[0].image, seq.frames[0].tip)
    out = fixes = 0
    for f in seq.frames[1:]:
        r = tracker.update(f.image)
        out += f.kind == "out"
        if isinstance(r, Fix):
            fixes += 1
            assert f.kind != "out" and math.hypot(r.x - f.tip[0], r.y - f.tip[1]) <= 3.0, (f.kind, r)
    assert out >= 5 and fixes >= 8
