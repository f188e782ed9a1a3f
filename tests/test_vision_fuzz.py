"""The tracker's public API on frames nobody would design for: one answer per frame, never a traceback.

A first frame gives a tracker or one :class:`TemplateError` / :class:`ImageError`; every later frame a
:class:`Fix` inside the frame with finite numbers, or a :class:`Lost` with a known reason. The package's
RuntimeWarnings are errors under pytest, so an overflow or an empty median fails here too.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.vision.frame import MAX_VALUE, ImageError, as_image
from stickslip.vision.template import TemplateError
from stickslip.vision.track import REASONS, Fix, TipTracker


def _needle(h: int, w: int, x: float, y: float, angle: float, width: float, contrast: float) -> np.ndarray:
    """A wedge with its apex at (x, y), px, pointing away from ``angle`` (rad), on a 0.3 background."""
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    ux, uy = math.cos(angle), math.sin(angle)
    along = (xx - x) * ux + (yy - y) * uy
    across = np.abs(-(xx - x) * uy + (yy - y) * ux)
    return 0.3 + contrast * ((along >= 0) & (across <= width / 2 + 0.15 * along))


def _frame(kind: int, h: int, w: int, x: float, y: float, rng: np.random.Generator) -> np.ndarray:
    if kind == 0:
        return rng.normal(0.5, 0.1, (h, w))
    if kind == 1:
        return np.full((h, w), rng.uniform(0.0, 1e4))
    if kind == 2:  # a checkerboard of any scale
        return (np.indices((h, w)).sum(0) % 2).astype(float) * rng.uniform(1e-9, 1e9)
    if kind == 3:  # a needle of any width, contrast (either sign) and noise
        noisy = rng.normal(0.0, rng.uniform(0.0, 0.3), (h, w))
        return _needle(h, w, x, y, rng.uniform(0, 2 * math.pi), rng.uniform(1, 20), rng.uniform(-1, 1)) + noisy
    if kind == 4:  # salt and pepper at a 16-bit camera's extremes
        return rng.choice([0.0, 65535.0], (h, w))
    return _needle(h, w, x, y, 0.3, 8.0, 0.6)  # noise-free


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(h=st.integers(16, 110), w=st.integers(16, 110), fx=st.floats(0.05, 0.95), fy=st.floats(0.05, 0.95),
       first=st.sampled_from([3, 3, 5, 0]), later=st.lists(st.integers(0, 5), min_size=3, max_size=3),
       seed=st.integers(0, 2**32 - 1))
def test_any_frames_give_a_fix_inside_the_frame_or_a_reason(h, w, fx, fy, first, later, seed):
    rng = np.random.default_rng(seed)
    x, y = fx * (w - 1), fy * (h - 1)
    try:
        tracker = TipTracker(_frame(first, h, w, x, y, rng), (x, y))
    except (TemplateError, ImageError) as e:
        assert str(e)  # one line that says why
        return
    for kind in later:
        dx, dy = rng.normal(0.0, 5.0, 2)
        r = tracker.update(_frame(kind, h, w, x + dx, y + dy, rng))
        if isinstance(r, Fix):
            assert math.isfinite(r.x) and math.isfinite(r.y) and math.isfinite(r.sigma)
            assert -0.5 <= r.x <= w - 0.5 and -0.5 <= r.y <= h - 0.5
        else:
            assert r.reason in REASONS


def test_a_frame_smaller_than_the_window_is_refused_with_its_reason():
    """Found by the fuzz above: a 25 x 22 frame left the background ring empty (a median of nothing)."""
    image = np.random.default_rng(0).normal(0.5, 0.1, (22, 25))
    with pytest.raises(TemplateError, match=r"no background around the tip \(11.5, 14.9\).*wholly outside the frame"):
        TipTracker(image, (11.5, 14.9))


def test_values_no_camera_records_are_refused_before_they_overflow_the_sums():
    """A float TIFF of 1e300s made `camera locate` end in an OverflowError traceback."""
    image = _needle(64, 64, 30.0, 32.0, 0.0, 6.0, 0.6)
    with pytest.raises(ImageError, match=r"a pixel of 9e\+299 \(at x=\d+, y=\d+\) is beyond the ±1e\+100"):
        as_image(image * 1e300)
    with pytest.raises(ImageError, match=r"the first frame: a pixel of -2e\+200"):
        TipTracker(np.where(image > 0.5, -2e200, image), (30.0, 32.0))
    with pytest.raises(ImageError, match=r"a pixel of 1.0000001e\+100 .* beyond the ±1e\+100"):
        as_image(np.full((20, 20), 1.0000001e100))  # just over the limit: said as it is, not rounded onto it
    assert as_image(image * MAX_VALUE).max() == pytest.approx(0.9 * MAX_VALUE)  # up to the limit: kept as it is
    tracker = TipTracker(image * 1e6, (30.0, 32.0))  # a float image in large units is tracked all the same
    r = tracker.update(image * 1e6)
    assert isinstance(r, Fix) and math.hypot(r.x - 30.0, r.y - 32.0) < 0.05
