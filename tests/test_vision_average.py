"""The template averaged over the first fitted frames (stickslip.vision.average): round trips and identities."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.average import TemplateAverage, anchor
from stickslip.vision.refine import steepest
from stickslip.vision.sampling import patch
from stickslip.vision.template import TipTemplate, TrackerParams
from stickslip.vision.track import Fix, TipTracker

TIP = (60.3, 58.6)
DIRECTION = np.array([0.8, 0.6])


def _scene(photons: float = 1e9, look: str = "optical", flat: bool = False) -> SimScene:
    scene = SimScene(SimCamSettings(look=look, width=128, height=128, photons=photons, seed=5, tip_radius_m=2.0e-6,
                                    pixel_size_m=0.5e-6))
    if flat:  # no texture and no dust: the ground the needle moves over is the same everywhere
        scene.substrate = np.full_like(scene.substrate, float(np.median(scene.substrate)))
    return scene


def test_the_first_frame_and_whole_pixel_moves_of_it_average_to_its_own_window() -> None:
    frame = _scene().render(np.array(TIP), DIRECTION, 1.0)
    t = TipTemplate.learn(frame, TIP)
    avg = TemplateAverage(frame, TIP, t, 3)
    win0 = avg._win0
    assert win0 is not None
    shifts = [(3, -2), (-5, 4), (0, 0)]
    out = None
    for k, (dx, dy) in enumerate(shifts):
        moved = np.roll(frame, (dy, dx), axis=(0, 1))
        # darker and with less contrast too: brought back to the first frame's by the weighted fit
        out = avg.add(0.6 * moved + 0.1, TIP[0] + dx, TIP[1] + dy, 0.0)
        assert (out is None) == (k < len(shifts) - 1)
    assert avg.count == 3 and not avg.open
    assert out is not None
    np.testing.assert_allclose(out, win0, atol=1e-9)


def test_a_window_past_the_frame_is_not_taken() -> None:
    frame = _scene().render(np.array(TIP), DIRECTION, 1.0)
    avg = TemplateAverage(frame, TIP, TipTemplate.learn(frame, TIP), 2)
    assert avg.add(frame, 5.0, 60.0, 0.0) is None
    assert avg.count == 0 and avg.open


def test_the_anchor_moves_the_apex_to_the_tip_given() -> None:
    """Fitted to the frame it was cut from, the template says where its apex is against the tip given: the move
    is the tip's offset, to a hundredth of a pixel; beyond the limit, no move."""
    frame = _scene().render(np.array(TIP), DIRECTION, 1.0)
    p = TrackerParams()
    t = TipTemplate.learn(frame, TIP, p)
    st = steepest(t.bank[0], t.apex, t.level_weights[0])
    off = (0.3, -0.2)
    given = (TIP[0] + off[0], TIP[1] + off[1])
    first = patch(frame, given[0], given[1], t.half * math.sqrt(2.0) + 12.0, p.template_blur)
    move = anchor(first, st, given, p.sigma_factor, 1.0)
    assert move is not None
    assert move == pytest.approx(off, abs=0.01)
    far = (TIP[0] + 1.5, TIP[1])
    first = patch(frame, far[0], far[1], t.half * math.sqrt(2.0) + 12.0, p.template_blur)
    assert anchor(first, st, far, p.sigma_factor, 1.0) is None


def _track(params: TrackerParams, photons: float, steps: int, whole: bool = False) -> tuple[TipTracker, list[float]]:
    """A tracker through ``steps`` frames of an SEM needle on flat ground moved by up to 6 px (whole pixels with
    ``whole``), and its fixes' distances from the truth, px."""
    scene = _scene(photons, "sem", flat=True)
    rng = np.random.default_rng(7)
    moves = rng.uniform(-6.0, 6.0, (steps, 2))
    tips = [np.array(TIP) + (np.round(m) if whole else m) for m in moves]
    tracker = TipTracker(scene.render(np.array(TIP), DIRECTION, 1.0), TIP, params)
    errors = []
    for tip in tips:
        r = tracker.update(scene.render(tip, DIRECTION, 1.0))
        assert isinstance(r, Fix)
        errors.append(math.hypot(r.x - tip[0], r.y - tip[1]))
    return tracker, errors


def test_without_noise_the_averaged_template_keeps_the_fixes_where_they_were() -> None:
    """Noise-free frames of one needle moved by fractions of a pixel: the average is the first window smoothed a
    little by the interpolation, the anchor moves the apex by a few hundredths of a pixel, and the fixes after
    it lie as close to the truth as before it."""
    plain, before = _track(TrackerParams(average_frames=0), 1e9, 8)
    avg, after = _track(TrackerParams(average_frames=3), 1e9, 8)
    assert avg._average is None  # averaged, once
    assert avg._bank_noise2[0] == pytest.approx(plain._bank_noise2[0] / 4.0)
    assert 0.0 < math.dist(avg.template.apex, plain.template.apex) < 0.05
    assert max(before) < 0.1 and max(after) < 0.1
    assert float(np.mean(after)) < float(np.mean(before)) + 0.01


def test_three_noisy_frames_averaged_with_the_first_leave_half_the_noise() -> None:
    """With shot noise (100 photons), three frames placed at the truth (whole pixels) averaged with the first:
    the window's difference from the noise-free one has half the spread (a quarter of the variance)."""
    clean = _scene(1e9, "sem", flat=True).render(np.array(TIP), DIRECTION, 1.0)
    scene = _scene(100.0, "sem", flat=True)
    first = scene.render(np.array(TIP), DIRECTION, 1.0)
    avg = TemplateAverage(first, TIP, TipTemplate.learn(first, TIP), 3)
    out = None
    for dx, dy in ((4, -3), (-2, 5), (6, 1)):
        out = avg.add(scene.render(np.array([TIP[0] + dx, TIP[1] + dy]), DIRECTION, 1.0), TIP[0] + dx, TIP[1] + dy,
                      0.0)
    assert out is not None and avg._win0 is not None
    ref = TemplateAverage(clean, TIP, TipTemplate.learn(clean, TIP), 1)._win0
    assert ref is not None
    ratio = float(np.std(out - ref)) / float(np.std(avg._win0 - ref))
    assert 0.4 < ratio < 0.6
