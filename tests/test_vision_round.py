"""A round bead over a blunt needle's end (the own renderer's round mode), and the tracker near the edge.

The second renderer's two worst fixes (docs/vision-log.md, "Diagnosis of the two worst
fixes", "Eighth round") are blunt tips under a round opaque particle: its chord is as wide
as the blunt end over about its radius, so the needle's width behind the fit passes, or
fewer than three of the width's stations lie in the frame and nothing is checked. The
round mode (``tests/support/vision_own.py``: a paraboloid-ended needle,
``SimCamSettings(end="paraboloid")``, with beads stuck on it and tips held near the edge
their shaft leaves by) is that case written from our own view; these tests check the
paraboloid it paints and that a fix nothing vouches for is refused.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from vision_own import own_sequence

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.frame import as_image
from stickslip.vision.template import TrackerParams
from stickslip.vision.track import Fix, Lost, TipTracker


def test_the_blunt_end_is_a_paraboloid_joining_the_cone() -> None:
    # an apex of radius R = 8 px pointing left along x at (20, 64): r(s) = sqrt(2 R s) while its slope R / r is above
    # the cone's tan 20 deg, i.e. up to s_t = R / (2 tan² 20°) = 30.2 px; then the cone, tangent to it
    s = SimCamSettings(look="optical", width=128, height=128, tip_radius_m=4e-6, pixel_size_m=0.5e-6,
                       taper=math.radians(20.0), end="paraboloid")
    scene = SimScene(s)
    cover, _ = scene._needle(np.array([20.0, 64.0]), np.array([1.0, 0.0]), 1.0)
    slope = math.tan(math.radians(20.0))
    s_t, r_t = 8.0 / (2.0 * slope**2), 8.0 / slope
    for col in (24, 30, 40, 60, 80):
        along = col - 20.0
        r = math.sqrt(2.0 * 8.0 * along) if along < s_t else r_t + (along - s_t) * slope
        assert cover[:, col].sum() == pytest.approx(2.0 * r, abs=0.6)  # the column's width, anti-aliased
    assert cover[64, 19] < 0.5 < cover[64, 21]  # the apex at x = 20
    assert cover[:, :19].sum() == 0.0  # nothing ahead of it


def test_an_unknown_end_is_refused() -> None:
    with pytest.raises(ValueError, match="end='spike'"):
        SimScene(SimCamSettings(end="spike"))


@lru_cache(maxsize=1)
def _bead_near_the_edge() -> tuple[list[tuple[str, str, tuple[float, float]]], list[Fix | Lost], list[Fix | Lost]]:
    """A 16 px blunt bright-field tip, a bead stuck on it from frame 6 (128 px, seed 44): the answers of the
    eighth round's rule (an unchecked fix trusted) and of the default (refused)."""
    seq = own_sequence(44, 8, 128, 16.0, "optical", round_rate=0.4)
    first = as_image(seq.frames[0].image)
    trusting = TipTracker(first, seq.frames[0].tip, TrackerParams(trust_unchecked=True))
    default = TipTracker(first, seq.frames[0].tip)
    before, after = [], []
    for f in seq.frames[1:]:
        image = as_image(f.image)
        before.append(trusting.update(image))
        after.append(default.update(image))
    return [(f.kind, f.cause, f.tip) for f in seq.frames[1:]], before, after


def test_a_bead_over_a_blunt_tip_whose_shaft_leaves_the_field_is_refused() -> None:
    truth, before, after = _bead_near_the_edge()
    kind, cause, tip = truth[5]  # frame 6
    assert (kind, cause) == ("occluded", "bead")
    # trusted, the fit takes the bead's far rim for the tip, 11.2 px off: behind it the shaft leaves the field
    # before three of the width's stations, so nothing checked it
    fix = before[5]
    assert isinstance(fix, Fix) and math.hypot(fix.x - tip[0], fix.y - tip[1]) > 10.0
    refused = after[5]
    assert isinstance(refused, Lost) and refused.reason == "lost"
    assert "nothing vouches that the end seen is the tip" in refused.detail


def test_no_fix_near_the_edge_is_more_than_3_px_off() -> None:
    truth, _, after = _bead_near_the_edge()
    for (_, _, tip), answer in zip(truth, after, strict=True):
        if isinstance(answer, Fix):
            assert math.hypot(answer.x - tip[0], answer.y - tip[1]) <= 3.0
