"""The focus step rule reads the last fix's blur, not the copy it was fitted with (docs/vision.md, "Decide").

A fix keeps the last one's blur copy while the fit matches as well as the recent fixes did:
the copies are compared only when it does not. So while the focus drifts slowly the copy a
fix was fitted with lags it, and when the copies are compared at last the copy chosen jumps
by the drift of many frames at once. On the own renderer (``SimScene``, the needle placed
directly): a 10 px bright-field tip learnt blurred by 3 px that sharpens by 0.25 px a frame
is fitted with the sharp copy until the frame is sharper by about 2.3 px, then with the most
sharpening copy (3 px); the rule read from the fitted copy refused the two frames where that
happened (a step of 3 px against the 2 allowed), though their fits lay within 0.4 px of the
tip. A focus that does jump is refused as before.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.track import FOCUS_STEP, Fix, Lost, TipTracker, _View

SIZE = 160
SHAFT = np.array((-1.0, 0.3))  # from the tip back along the shaft


def _scene(look: str, width_px: float) -> SimScene:
    return SimScene(SimCamSettings(look=look, width=SIZE, height=SIZE, photons=200.0, seed=5,
                                   tip_radius_m=0.25e-6 * width_px, pixel_size_m=0.5e-6))


def _track(scene: SimScene, blurs: list[float]) -> tuple[TipTracker, list[tuple[Fix | Lost, np.ndarray]]]:
    """The tip learnt in the first frame (blur ``blurs[0]``, px), then moving 0.8 px a frame."""
    tip = np.array([90.0, 80.0])
    tracker = TipTracker(scene.render(tip, SHAFT, blurs[0]), (90.0, 80.0))
    out = []
    for b in blurs[1:]:
        tip = tip + np.array([0.7, -0.4])
        out.append((tracker.update(scene.render(tip, SHAFT, b)), tip.copy()))
    return tracker, out


@pytest.mark.parametrize("width_px", [10.0])
def test_a_tip_that_sharpens_slowly_is_fixed_in_every_frame(width_px):
    # 3 px to 1 px of blur (sigma) in eight frames: the sharp copy until about frame 5, then the 3 px one
    _, results = _track(_scene("optical", width_px), [3.0 - 0.25 * k for k in range(9)])
    for k, (r, tip) in enumerate(results, start=1):
        assert isinstance(r, Fix), (k, r)
        assert math.hypot(r.x - tip[0], r.y - tip[1]) < 1.2, k
    assert [r.blur for r, _ in results][-1] == -3.0  # the copy did jump, by 3 px, and was taken


def test_a_focus_that_jumps_is_still_refused():
    # sharp, then blurred by 4.5 px at once: the copies at the last fix read it sharp
    _, results = _track(_scene("optical", 10.0), [0.0, 0.2, 0.4, 4.5])
    assert all(isinstance(r, Fix) and r.blur == 0.0 for r, _ in results[:2])
    last = results[-1][0]
    assert isinstance(last, Lost) and last.reason == "lost" and last.detail.startswith(FOCUS_STEP), last


@pytest.mark.parametrize("at", [(80.3, 70.6), (158.7, 1.4)])
def test_the_kept_view_compares_the_copies_as_the_whole_frame_does(at):
    # the blur copies' comparison at a fix on the kept pixels alone equals the one on the frame, bit for bit,
    # in the middle and near a corner (the crop cut by the frame's edges)
    scene = _scene("sem", 8.0)
    tracker = TipTracker(scene.render(np.array([80.0, 80.0]), SHAFT, 0.0), (80.0, 80.0))
    frame = scene.render(np.array(at), SHAFT, 1.3)
    view = _View.keep(frame, at[0], at[1], tracker.template.half)
    assert view.pixels.shape[0] < SIZE and view.pixels.shape[1] < SIZE
    whole = tracker._levels({}, frame, at[0], at[1], 0.01)
    kept = tracker._levels({}, view.frame(), at[0], at[1], 0.01)
    assert kept == whole
    assert len(set(whole)) > 1  # the copies differ
