"""Vouching near the field's edge: a tip found again there stands on the rules for a tip found again.

Behind a fit whose shaft leaves the field, fewer than three of the needle's width stations
lie in the frame, and nothing checks that the end seen is the tip: a round bead stuck on a
blunt end looks like the end (docs/vision-log.md, "Ninth round"). A fit near the last fix
is taken only under the stricter rules for a tip found again (its correlation, its mismatch
against the recent fixes', a standard deviation of at most 0.5 px), which stand in for the
stations; one that fails them is refused and the whole frame's search is run instead
(docs/vision.md, "Decision rules"; measured in docs/vision-log.md, "Twelfth round"). On
the own renderer: a blunt tip found again near the edge its shaft leaves by is fixed; a
bead over it there stays refused.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from vision_own import own_sequence

from stickslip.sim.camera import SimCamSettings, SimScene
from stickslip.vision.frame import as_image
from stickslip.vision.track import Fix, Lost, TipTracker

SIZE = 160
NOTHING_VOUCHES = "nothing vouches that the end seen is the tip"


def _watched(tracker: TipTracker, truth: list[tuple[float, float]]) -> list[list[tuple[bool, float, Fix | Lost, bool]]]:
    """Record, frame by frame, every candidate ``tracker`` judges: found again or not, its distance from the
    frame's tip in ``truth`` (px, set before each update), the verdict, and whether no width station checked it."""
    judge = tracker._judge
    seen: list[list[tuple[bool, float, Fix | Lost, bool]]] = []

    def watched(cand, image, reacquire=False):  # type: ignore[no-untyped-def]
        res, out = judge(cand, image, reacquire)
        x, y = truth[-1]
        seen[-1].append((reacquire, math.hypot(cand.ref.x - x, cand.ref.y - y), res, out.width is None))
        return res, out

    tracker._judge = watched  # type: ignore[method-assign]
    return seen


@pytest.mark.parametrize(("look", "width_px", "inside"), [("optical", 16.0, 12.0), ("sem", 8.0, 16.0)])
def test_a_blunt_tip_found_again_near_the_edge_its_shaft_leaves_by_is_fixed(look, width_px, inside):
    # learnt in the middle, gone beyond the top edge, back 12 or 16 px inside it: 94 px from the last fix, its
    # shaft leaving the field by the same edge (no width station behind it in the frame)
    scene = SimScene(SimCamSettings(look=look, width=SIZE, height=SIZE, photons=200.0, seed=5,
                                    tip_radius_m=0.25e-6 * width_px, pixel_size_m=0.5e-6, end="paraboloid"))
    d = np.array((0.1, -1.0))
    tracker = TipTracker(scene.render(np.array([80.0, 110.0]), d, 0.0), (80.0, 110.0))
    truth = [(80.0, -30.0)]
    seen = _watched(tracker, truth)
    seen.append([])
    assert isinstance(tracker.update(scene.render(np.array(truth[-1]), d, 0.0)), Lost)
    truth.append((80.0, inside))
    seen.append([])
    r = tracker.update(scene.render(np.array(truth[-1]), d, 0.0))
    assert isinstance(r, Fix), r
    assert math.hypot(r.x - 80.0, r.y - inside) < 1.0
    taken = [s for s in seen[-1] if isinstance(s[2], Fix)]
    assert len(taken) == 1 and taken[0][0]  # found again by the whole frame's search
    assert taken[0][3] and tracker._width is not None  # the first frame showed the stations; none checked the fit


@lru_cache(maxsize=1)
def _bead_at_the_edge() -> tuple[list[tuple[str, str, tuple[float, float]]], list[Fix | Lost],
                                 list[list[tuple[bool, float, Fix | Lost, bool]]]]:
    """A 16 px blunt bright-field tip near the bottom edge its shaft leaves by, a bead stuck on it from frame 6
    (the own round mode, 128 px, seed 44): the truth, the answers and the candidates judged, frame by frame."""
    seq = own_sequence(44, 8, 128, 16.0, "optical", round_rate=0.4)
    tracker = TipTracker(as_image(seq.frames[0].image), seq.frames[0].tip)
    truth: list[tuple[float, float]] = []
    seen = _watched(tracker, truth)
    answers = []
    for f in seq.frames[1:]:
        truth.append(f.tip)
        seen.append([])
        answers.append(tracker.update(as_image(f.image)))
    return [(f.kind, f.cause, f.tip) for f in seq.frames[1:]], answers, seen


@pytest.mark.parametrize("frame", [3, 5])
def test_a_tip_near_the_edge_nothing_vouches_for_is_fixed_under_the_rules_for_a_tip_found_again(frame):
    """Near the last fix, with no width station in the frame behind it, the fit passes the rules a tip found
    again must pass (a correlation of 0.8, the mismatch, a standard deviation of at most 0.5 px): they vouch
    for it there as they would in the whole frame's search, which is not run (it found the same tip again,
    0.27 and 0.44 px off, before the rules were applied near the last fix too)."""
    truth, answers, seen = _bead_at_the_edge()
    kind, _, tip = truth[frame - 1]
    assert kind == "visible" and 128 - 1 - tip[1] < 27.0  # 26 and 20 px from the bottom edge
    [(again, dist, verdict, unchecked)] = seen[frame - 1]
    assert not again and unchecked and isinstance(verdict, Fix) and dist < 1.0
    r = answers[frame - 1]
    assert isinstance(r, Fix) and r.score >= 0.8 and r.sigma <= 0.5
    assert math.hypot(r.x - tip[0], r.y - tip[1]) < 0.6  # 0.28 and 0.54 px


def test_a_bead_over_the_tip_near_the_edge_stays_refused():
    truth, answers, seen = _bead_at_the_edge()
    assert truth[5][:2] == ("occluded", "bead")  # frame 6
    # near the last fix the bead's rim is refused (nothing vouches); the whole frame's search finds the rim again,
    # 11 px from the tip, where the fit's position is less determined than a tip found again may be
    local, again = seen[5]
    assert not local[0] and local[1] > 10.0 and NOTHING_VOUCHES in local[2].detail
    assert again[0] and again[1] > 10.0
    assert isinstance(again[2], Lost) and "position undetermined (sigma 0.7" in again[2].detail
    assert isinstance(answers[5], Lost) and NOTHING_VOUCHES in answers[5].detail
    for (_, _, tip), answer in zip(truth, answers, strict=True):
        if isinstance(answer, Fix):
            assert math.hypot(answer.x - tip[0], answer.y - tip[1]) <= 3.0
