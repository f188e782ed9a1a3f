"""The shaft followed back from a candidate tip (stickslip.vision.shaft), on the simulated microscope's needle.

The needle runs from its tip at x = 60 px to the field's left edge: the first frame shows
it for 60 px, and the stations are learnt that far and no further. At the true tip the
shaft behind is where the first frame had it (contrast and correlation near 1); a
candidate 5 px to the side of the needle's axis (a lobe beside the tip) finds its edges
elsewhere.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.shaft import BACK_FROM, BACK_STEP, check_shaft, learn_shaft
from stickslip.vision.template import TipTemplate, TrackerParams

SHAFT = np.array([-1.0, 0.15])
TIP = (60.0, 80.0)


def _profiles(look: str):  # type: ignore[no-untyped-def]
    scene = SimScene(SimCamSettings(look=look, width=160, height=160, photons=200.0, seed=5,
                                    tip_radius_m=0.25e-6 * 10.0, pixel_size_m=0.5e-6))
    first = scene.render(np.array(TIP), SHAFT, 1.0)
    p = TrackerParams()
    t = TipTemplate.learn(first, TIP, p)
    smooth = [(math.hypot(p.template_blur, b), p.template_blur) for b in p.blur_bank]
    sp = learn_shaft(first, TIP, t.shaft, t.ground[0], t.ground[1], p.contrast, smooth)
    return scene, sp


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_the_shaft_is_learnt_as_far_as_the_first_frame_shows_it(look):
    _, sp = _profiles(look)
    # the needle leaves the field 60 px behind the tip: the stations from 18 px every 6 px up to it
    assert sp.s[0] == BACK_FROM
    np.testing.assert_allclose(np.diff(sp.s), BACK_STEP)
    assert 48.0 <= sp.s[-1] <= 58.0


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_the_shaft_holds_behind_the_tip_and_not_beside_it(look):
    scene, sp = _profiles(look)
    frame = scene.render(np.array(TIP), SHAFT, 1.0)
    at = check_shaft(sp, 0, frame, *TIP, 0.0)
    assert at is not None and at.n == sp.s.size
    assert 0.85 <= at.back <= 1.15 and at.shape >= 0.97, at
    u = SHAFT / np.hypot(*SHAFT)
    side = (TIP[0] - 5.0 * u[1], TIP[1] + 5.0 * u[0])  # 5 px across the shaft
    off = check_shaft(sp, 0, frame, *side, 0.0)
    assert off is not None and off.shape < 0.9, off


@pytest.mark.parametrize("look", ["optical", "sem"])
def test_the_taper_says_how_far_along_the_axis_a_candidate_lies_from_the_tip(look):
    """The needle widens away from its tip: the shaft behind a candidate displaced along the axis is the
    first frame's taper shifted. At the tip the taper shows no displacement; 5 px ahead of the tip or behind
    it, a displacement of the right sign, at 60 to 95 % of its size (the taper's first-order model)."""
    scene, sp = _profiles(look)
    frame = scene.render(np.array(TIP), SHAFT, 1.0)
    u = SHAFT / np.hypot(*SHAFT)  # from the tip back along the needle
    at = check_shaft(sp, 0, frame, *TIP, 0.0)
    assert at is not None and abs(at.along) <= 0.6 and at.along_sd < 0.25, at
    ahead = check_shaft(sp, 0, frame, TIP[0] - 5.0 * u[0], TIP[1] - 5.0 * u[1], 0.0)
    behind = check_shaft(sp, 0, frame, TIP[0] + 5.0 * u[0], TIP[1] + 5.0 * u[1], 0.0)
    assert ahead is not None and -4.75 <= ahead.along <= -3.0, ahead  # the tip behind the candidate
    assert behind is not None and 3.0 <= behind.along <= 4.75, behind
    # the candidate behind the tip is refused (along_limit + along_sigmas standard deviations); at the tip it is not
    p = TrackerParams()
    assert abs(behind.along) > p.along_limit + p.along_sigmas * behind.along_sd
    assert abs(at.along) < p.along_limit + p.along_sigmas * at.along_sd


def test_the_taper_reads_a_frame_sharper_than_the_first_at_a_sharpen_copy_in_full():
    """A frame 3 px sharper than the first (blur 0.5 px against 3 px), fitted at the sharpest copy (the frame
    smoothed by hypot(1, 3) px across the shaft). The taper's basis is smoothed as the frame is: 5 px behind the
    tip reads 5.5 to 6.8 px (with the basis at the first frame's 1 px it read 3.6 +- 0.2, under the limit of
    3.6), 5 px ahead -5.3 to -6.8 (it read -3.2); at the tip within 1 px (+0.35 with that basis, -0.69 now)."""
    scene = SimScene(SimCamSettings(look="optical", width=160, height=160, photons=200.0, seed=5,
                                    tip_radius_m=0.25e-6 * 10.0, pixel_size_m=0.5e-6))
    first = scene.render(np.array(TIP), SHAFT, 3.0)
    p = TrackerParams()
    t = TipTemplate.learn(first, TIP, p)
    s0 = p.template_blur
    smooth = ([(math.hypot(s0, b), s0) for b in p.blur_bank]
              + [(s0, math.hypot(s0, f)) for f in p.sharpen_bank])  # as the tracker's copies are
    sp = learn_shaft(first, TIP, t.shaft, t.ground[0], t.ground[1], p.contrast, smooth)
    frame = scene.render(np.array(TIP), SHAFT, 0.5)
    copy = len(p.blur_bank) + p.sharpen_bank.index(3.0)
    u = SHAFT / np.hypot(*SHAFT)
    at = check_shaft(sp, copy, frame, *TIP, 0.0)
    behind = check_shaft(sp, copy, frame, TIP[0] + 5.0 * u[0], TIP[1] + 5.0 * u[1], 0.0)
    ahead = check_shaft(sp, copy, frame, TIP[0] - 5.0 * u[0], TIP[1] - 5.0 * u[1], 0.0)
    assert at is not None and abs(at.along) <= 1.0, at
    assert behind is not None and 5.5 <= behind.along <= 6.8, behind
    assert ahead is not None and -6.8 <= ahead.along <= -5.3, ahead
    assert abs(behind.along) > p.along_limit + p.along_sigmas * behind.along_sd
    assert abs(ahead.along) > p.along_limit + p.along_sigmas * ahead.along_sd
    assert abs(at.along) < p.along_limit + p.along_sigmas * at.along_sd
