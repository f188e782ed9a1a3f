"""Tip tracking: on the simulated microscope it was designed on, and on the second renderer it was not.

Correctness on small samples (seconds); the full numbers (500 frames, 512 x 512) and the
speed are measured by ``benchmarks/bench_vision.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage
from vision_peer import peer_sequence

from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.camera import SimCamera, SimCamSettings, SimScene
from stickslip.vision.frame import as_image
from stickslip.vision.refine import refine, steepest
from stickslip.vision.sampling import patch
from stickslip.vision.track import REASONS, Fix, Lost, TemplateError, TipTracker, track


def _simcam(look: str, seed: int, photons: float = 150.0, size: int = 256) -> tuple[SimulatedMM3A, SimCamera]:
    sim = SimulatedMM3A(seed=seed)
    cam = SimCamera(sim, SimCamSettings(look=look, width=size, height=size, photons=photons, seed=seed,
                                        pixel_size_m=0.4e-6, tip_radius_m=1.2e-6))
    return sim, cam


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_simcam_moves_are_followed_to_a_fraction_of_a_pixel(look):
    sim, cam = _simcam(look, 3)
    tip, _ = cam.true_tip()
    tracker = TipTracker(cam.grab(), tuple(tip))
    rng = np.random.default_rng(3)
    errors = []
    for _ in range(14):
        sim.step(int(rng.choice([1, 3])), int(rng.integers(-6, 7)))
        truth, _ = cam.true_tip()
        r = tracker.update(cam.grab())
        assert isinstance(r, Fix), r
        errors.append(math.hypot(r.x - truth[0], r.y - truth[1]))
        assert 0.0 < r.score <= 1.0 and 0.0 < r.sigma <= 1.0
    assert np.median(errors) <= 0.4 and max(errors) <= 1.5, np.round(errors, 2)


def test_a_tip_out_of_the_field_is_refused_and_found_again():
    sim, cam = _simcam("optical", 4)
    tip, _ = cam.true_tip()
    tracker = TipTracker(cam.grab(), tuple(tip))
    sim.step(3, 90)  # ~225 px out: beyond the 256 px field
    assert cam.true_tip()[0][0] > 256
    r = tracker.update(cam.grab())
    assert isinstance(r, Lost) and r.reason in REASONS
    sim.step(3, -90)
    truth, _ = cam.true_tip()
    back = tracker.update(cam.grab())
    assert isinstance(back, Fix) and math.hypot(back.x - truth[0], back.y - truth[1]) < 1.0


def test_a_tip_under_a_particle_is_refused_or_within_3_px():
    sim, cam = _simcam("optical", 5)
    tip, _ = cam.true_tip()
    tracker = TipTracker(cam.grab(), tuple(tip))
    sim.step(3, 4)
    truth, _ = cam.true_tip()
    img = cam.grab().image.copy()
    yy, xx = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    disc = np.hypot(xx - truth[0] - 2, yy - truth[1]) <= 9
    img[disc] = 0.08  # an opaque particle over the tip
    r = tracker.update(img)
    assert isinstance(r, Lost) or math.hypot(r.x - truth[0], r.y - truth[1]) <= 3.0


def test_nothing_at_the_tip_given_is_refused():
    flat = np.random.default_rng(0).normal(0.5, 0.01, (64, 64))
    with pytest.raises(TemplateError, match="nothing stands out"):
        TipTracker(flat, (30.0, 30.0))
    with pytest.raises(TemplateError, match="outside the 64 x 64 frame"):
        TipTracker(flat, (70.0, 3.0))
    with pytest.raises(TemplateError, match="within 4 px of the frame's edge"):
        TipTracker(flat, (2.0, 30.0))


def test_track_yields_the_tip_given_first():
    sim, cam = _simcam("sem", 6)
    tip, _ = cam.true_tip()
    out = list(track([cam.grab(), cam.grab()], tuple(tip)))
    assert out[0] == Fix(float(tip[0]), float(tip[1]), 1.0, 0.0) and isinstance(out[1], Fix)


# ------------------------------------------------------------------------- the second renderer


@pytest.fixture(scope="module")
def peer_results() -> dict[str, object]:
    """Three sequences of the peer renderer (tip widths 3, 10, 17 px; 12 frames of 256 px each)."""
    errors, any_err, refused, visible, out_fixed, out_total = [], [], 0, 0, 0, 0
    for i, w in enumerate((3.0, 10.0, 17.0)):
        seq = peer_sequence(500 + i, 12, 256, 256, w)
        images = [as_image(f.image) for f in seq.frames]
        tracker = TipTracker(images[0], seq.frames[0].tip)
        for f, img in zip(seq.frames[1:], images[1:], strict=True):
            r = tracker.update(img)
            visible += f.kind == "visible"
            out_total += f.kind == "out"
            if isinstance(r, Fix):
                e = math.hypot(r.x - f.tip[0], r.y - f.tip[1])
                any_err.append(e)
                if f.kind == "visible":
                    errors.append(e)
                out_fixed += f.kind == "out"
            elif f.kind == "visible":
                refused += 1
    return {"errors": np.array(errors), "any": np.array(any_err), "refused": refused, "visible": visible,
            "out_fixed": out_fixed, "out_total": out_total}


@pytest.mark.slow
def test_peer_frames_what_the_tracker_reaches(peer_results):
    """Guards at what the tracker reaches on frames it was not designed on (measured: see docs/vision.md)."""
    e = peer_results["errors"]
    assert peer_results["out_total"] > 0 and peer_results["out_fixed"] == 0  # every tip out of the field refused
    assert np.median(e) <= 0.8 and np.percentile(e, 95) <= 2.5
    # ninth round: 7 of 29 (a 3 px tip near the 256 px field's edge, its shaft leaving the field: fixes nothing
    # vouches for are refused, TrackerParams.trust_unchecked; 0 of 29 with them trusted)
    assert peer_results["refused"] <= 0.25 * peer_results["visible"]
    assert np.max(peer_results["any"]) <= 3.0  # on these 33 frames (measured 1.34 px); not on the benchmark's 500


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="not met yet on the peer renderer (bench_vision, 500 frames, after one width station too narrow "
    "refuses: median 0.58 px, p95 1.17 px, largest 2.30 px, 7.9 % of visible tips refused); "
    "docs/vision-log.md",
)
def test_peer_frames_meet_the_issues_numbers(peer_results):
    e = peer_results["errors"]
    assert np.median(e) <= 0.3 and np.percentile(e, 95) <= 1.0
    assert np.max(peer_results["any"]) <= 3.0
    assert peer_results["refused"] <= 0.02 * peer_results["visible"]


# ------------------------------------------------------------------------- the blur term and the focus


def _capsule(n: int, tip: tuple[float, float], sigma: float, width: float = 6.0, up: int = 8) -> np.ndarray:
    """A dark needle along +x ending in a half disc at ``tip`` (its extreme point), blurred by ``sigma`` px."""
    yy, xx = (np.mgrid[0 : n * up, 0 : n * up] + 0.5) / up - 0.5
    r = width / 2
    dx, dy = xx - tip[0], yy - tip[1]
    inside = np.where(dx > r, np.abs(dy) - r, np.hypot(dx - r, dy) - r) < 0
    cover = inside.astype(float).reshape(n, up, n, up).mean(axis=(1, 3))
    return 1.0 - 0.7 * ndimage.gaussian_filter(cover, sigma)


@pytest.mark.parametrize("extra", [1.5, 2.0])
@pytest.mark.parametrize("ty", [31.0, 31.25, 31.5])
def test_a_focus_between_two_blur_copies_does_not_move_the_tip(extra, ty):
    """The fit's blur term (the template's Laplacian) takes up a blur the copy lacks: the tip stays put.

    Without it the end of a needle blurred by 1.5 to 2 px more than its template is found
    0.2 to 0.8 px behind its tip (measured: the heat equation's term set to zero).
    """
    template = ndimage.gaussian_filter(_capsule(41, (20.0, 20.0), 1.0), 1.0)
    st = steepest(template, (20.0, 20.0), np.ones((41, 41)))
    truth = (30.3, ty)
    frame = _capsule(64, truth, math.hypot(1.0, extra))
    fit = refine(patch(frame, 30.0, 31.0, 40.0, 1.0), st, (30.0, 31.0))
    assert fit.converged
    assert math.hypot(fit.x - truth[0], fit.y - truth[1]) <= 0.1
    # half the blur variance the frame has beyond the template's: extra² (the copy's smoothing applied to both)
    assert 0.5 * extra**2 <= fit.dvar <= 1.5 * extra**2


def test_a_sudden_change_of_focus_is_refused_and_a_slow_one_followed():
    scene = SimScene(SimCamSettings(look="optical", width=128, height=128, photons=300.0, seed=2,
                                    tip_radius_m=2e-6, pixel_size_m=0.5e-6))
    shaft, tip = np.array([1.0, 0.4]), np.array([50.3, 60.7])
    slow = TipTracker(scene.render(tip, shaft, 0.5), (50.3, 60.7))
    for sigma in (0.5, 1.0, 1.5, 2.0, 2.5):  # half a pixel of blur a frame: followed
        r = slow.update(scene.render(tip, shaft, sigma))
        assert isinstance(r, Fix) and math.hypot(r.x - tip[0], r.y - tip[1]) <= 1.0, (sigma, r)
    jump = TipTracker(scene.render(tip, shaft, 0.5), (50.3, 60.7))
    assert isinstance(jump.update(scene.render(tip, shaft, 0.5)), Fix)
    r = jump.update(scene.render(tip, shaft, 4.0))  # 3.5 px of blur in one frame: not the same thing
    assert isinstance(r, Lost) and r.reason == "lost" and "focus would have changed" in r.detail


def _noise_free_needle(tx: float, ty: float, size: int = 128) -> np.ndarray:
    """A dark tapered needle pointing left with its apex at (tx, ty), rendered 8 x over and averaged: no noise."""
    k = 8
    yy, xx = np.mgrid[0 : size * k, 0 : size * k].astype(float)
    along = (xx + 0.5) / k - 0.5 - tx
    across = (yy + 0.5) / k - 0.5 - ty
    inside = (along >= 0) & (np.abs(across) <= 1.0 + 0.15 * along)
    img = np.where(inside, 0.2, 0.8).reshape(size, k, size, k).mean(axis=(1, 3))
    return ndimage.gaussian_filter(img, 1.2)


def test_a_noise_free_frame_is_tracked_without_dividing_by_its_zero_noise():
    """A rendered frame has no pixel noise (its neighbour MAD is 0): the noise is floored at a 16-bit
    camera's rounding over the frame's range, and the edge check no longer divides by zero (pytest turns
    stickslip's RuntimeWarnings into errors); the moved tip is fixed within a pixel."""
    from stickslip.vision.template import noise_sigma

    first = _noise_free_needle(40.0, 64.0)
    assert noise_sigma(first) == pytest.approx(0.6 / 65535 / math.sqrt(12), rel=0.05)  # the span: 0.8 - 0.2
    tracker = TipTracker(first, (40.0, 64.0))
    for k in range(1, 6):
        truth = (40.0 + 0.7 * k, 64.0 + 0.3 * k)
        fix = tracker.update(_noise_free_needle(*truth))
        assert isinstance(fix, Fix), fix
        assert math.hypot(fix.x - truth[0], fix.y - truth[1]) < 1.0
