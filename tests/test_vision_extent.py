"""The needle's extent across the shaft behind a candidate tip (stickslip.vision.width's ``short``), and the
third generator's occlusions (tests/support/occlusion_scenes.py).

A blunt needle (half-width ``a sqrt(s)``, a paraboloid end 16 px wide 4 px behind it) in
transmitted light. An opaque bead over its end, its far rim 10 px ahead of the tip, has a
chord about as wide as the end over its radius: taken for the tip, the width's stations
within the bead agree with the first frame's (the blunt chord). Past the bead the needle
is its own, 10 px further back: narrower than the first frame showed it there by the taper
over 10 px, beyond what 3 px along the axis allow.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest
from occlusion_scenes import SUB, _down, _grid, _needle, scene_sequence
from width_learnt import learnt_width

from stickslip.vision.template import TrackerParams
from stickslip.vision.track import _width_refusal
from stickslip.vision.width import WidthStations, check_width, runs

SIZE = 160
ANGLE = math.radians(200.0)  # from the tip up the shaft: to the left, a little up
U = (math.cos(ANGLE), math.sin(ANGLE))
TIP = (112.0, 90.0)
A = 8.0 / 2.0  # half-width a sqrt(s): 16 px wide 4 px behind the end


def _render(tip: tuple[float, float], bead: tuple[float, float, float] | None, seed: int) -> np.ndarray:
    """The needle (transmission 0.1) with its end at ``tip``, an opaque bead (x, y, radius) over it, light 0.7,
    blurred by 1 px, read noise 0.01."""
    gx, gy = _grid(SIZE)
    t = np.where(_needle(gx, gy, tip, ANGLE, "power", A, 0.5, 0.0), 0.1, 1.0)
    if bead is not None:
        t = np.where(np.hypot(gx - bead[0], gy - bead[1]) <= bead[2], 0.05, t)
    from scipy import ndimage

    light = ndimage.gaussian_filter(0.7 * _down(t), 1.0)
    return light + np.random.default_rng(seed).normal(0.0, 0.01, light.shape)


@lru_cache(maxsize=1)
def _learnt() -> tuple[WidthStations, TrackerParams]:
    p = TrackerParams()
    return learnt_width(_render(TIP, None, 1), TIP, p), p


def test_a_clean_tip_is_as_wide_as_first_seen_at_every_station() -> None:
    ws, p = _learnt()
    assert ws.runs[0].min() > 10.0  # a solid silhouette: every station's extent compared
    for seed in (2, 3):
        frame = _render(TIP, None, seed)
        got = check_width(ws, 0, frame, *TIP, 0.0, p.along_limit, p.along_sigmas)
        assert got is not None and len(got.short) == got.n >= 5
        assert max(got.short) < -1.0, got  # within 1 px of the first frame's, less the 3 px the taper allows
        assert _width_refusal(got, slack=p.extent_slack) is None


@pytest.mark.parametrize("d", [10.0, 14.0])
def test_a_bead_s_far_rim_taken_for_the_tip_is_refused(d: float) -> None:
    """The needle's end ``d`` px behind ``TIP``, a bead of radius ``d`` px centred on it: its far rim at ``TIP``."""
    ws, p = _learnt()
    true_tip = (TIP[0] + d * U[0], TIP[1] + d * U[1])
    frame = _render(true_tip, (true_tip[0], true_tip[1], d), 4)
    got = check_width(ws, 0, frame, *TIP, 0.0, p.along_limit, p.along_sigmas)
    assert got is not None
    # past the bead (2 d behind its rim) the needle is its own, d px further back: 2 a (sqrt(s) - sqrt(s - d))
    # narrower, less the 3 px along the axis allow (2 a 3 / (2 sqrt(s))): 5 px or more at 24 px for d = 10
    past = [sh for s, sh in zip(got.s, got.short, strict=True) if s > 2.0 * d + 2.0]
    assert past and max(past) > p.extent_slack, got
    assert all(sh > 2.0 for sh in past), got
    refusal = _width_refusal(got, slack=p.extent_slack)
    assert refusal is not None and refusal.reason == "occluded"
    # the extent alone refuses it, whatever the stations' median width says
    alone = _width_refusal(replace(got, dw=tuple(0.0 for _ in got.dw)), slack=p.extent_slack)
    assert alone is not None and alone.reason == "occluded" and "narrower" in alone.detail
    # and the truth sits where the needle is: at the true tip, no station is short
    at = check_width(ws, 0, _render(true_tip, None, 5), *true_tip, 0.0, p.along_limit, p.along_sigmas)
    assert at is not None and max(at.short) < 0.0


def test_the_extent_spans_a_split_needle_and_a_faint_one_is_not_compared() -> None:
    q = 41
    ts = np.arange(q) - 20.0
    prof = np.zeros((3, q))
    prof[0, np.abs(ts) <= 6] = -1.0  # a solid needle 13 px wide
    prof[1, (np.abs(ts) <= 6) & (np.abs(ts) >= 4)] = 1.0  # bright edges, a middle at the ground's level
    got = runs(prof, 0.0, 0.5, np.full(3, 14.0))
    assert got.tolist() == [13.0, 13.0, 0.0]
    from stickslip.vision.width import _solid

    # the first needle stands twice the threshold from the ground: compared; the split one (its middle
    # at the ground) is not
    assert _solid(prof * 1.2, 0.0, 0.5, np.full(3, 14.0), got, 2.0).tolist() == [13.0, 0.0, 0.0]


def test_the_scenes_truth() -> None:
    seq = scene_sequence(7, n=12, size=96, width_px=14.0, occlusion_rate=0.6)
    assert seq.frames[0].kind == "visible" and seq.frames[0].cause == ""
    causes = {f.cause for f in seq.frames}
    assert causes - {""}, "an occluder within 12 frames at a rate of 0.6"
    for f in seq.frames:
        assert f.image.shape == (96, 96) and 0.0 <= f.image.min() and f.image.max() <= 1.0
        assert 20.0 <= f.tip[0] <= 75.0 and 20.0 <= f.tip[1] <= 75.0
        assert f.kind in ("visible", "occluded") and (f.kind == "visible" or f.cause in ("fibre", "particle"))


def test_the_needle_s_end_is_the_tip() -> None:
    """The silhouette's extreme point along the axis is the tip given, within a sub-pixel."""
    gx, gy = _grid(64)
    for shape, a, p, corner in (("power", 2.0, 0.5, 0.0), ("truncated", 5.0, 0.2, 2.0)):
        m = _needle(gx, gy, (30.0, 32.0), 0.3, shape, a, p, corner)
        s = (gx - 30.0) * math.cos(0.3) + (gy - 32.0) * math.sin(0.3)
        assert abs(float(s[m].min())) <= 1.0 / SUB


@pytest.mark.parametrize(("gain", "offset"), [(1.3, 0.0), (0.75, 0.05), (1.0, -0.03)])
def test_the_extent_reads_through_a_change_of_lamp(gain: float, offset: float) -> None:
    """A lamp brighter or dimmer: the frame's ground beside the needle, against the first frame's, moves the
    frame's grey levels back; the clean tip is as wide as first seen (the ground does not stand beyond the
    threshold) and the bead's rim still refused."""
    ws, p = _learnt()
    clean = gain * _render(TIP, None, 2) + offset
    got = check_width(ws, 0, clean, *TIP, 0.0, p.along_limit, p.along_sigmas)
    assert got is not None and -6.0 < max(got.short) < 2.0, got  # a dimmer needle's blurred edges: 0.14 px at most
    assert _width_refusal(got, slack=p.extent_slack) is None
    true_tip = (TIP[0] + 14.0 * U[0], TIP[1] + 14.0 * U[1])
    bead = gain * _render(true_tip, (true_tip[0], true_tip[1], 14.0), 4) + offset
    rim = check_width(ws, 0, bead, *TIP, 0.0, p.along_limit, p.along_sigmas)
    assert rim is not None and max(rim.short) > p.extent_slack, rim
