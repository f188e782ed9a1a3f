"""The soundscape: determinism in absolute time, levels, joint-specific stop sounds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.sim.sound import JOINT_SOUNDS, Soundscape, render_traverse_recording

SR = 48_000


def _events(duration_s: float, rate_hz: float = 1000.0, stop_at_s: float = 0.1):
    t = np.arange(0.0, duration_s, 1 / rate_hz) + 3.3e-4
    return t, np.full(t.shape, 2), t >= stop_at_s


def _render_split(scape: Soundscape, times, joints, stops, cuts: list[int], n: int):
    parts = []
    bounds = [0, *cuts, n]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        t0 = a / SR
        sel = (times >= t0 - scape.tail_s) & (times < b / SR)
        parts.append(scape.render(t0, b - a, times[sel], joints[sel], stops[sel]))
    return np.concatenate(parts)


@settings(max_examples=12, deadline=None)
@given(st.lists(st.integers(1, 9_599), min_size=1, max_size=5, unique=True))
def test_render_is_a_function_of_absolute_time(cuts):
    """Rendering 0.2 s in one call equals rendering it in pieces (to float32 rounding)."""
    scape = Soundscape(seed=5, babble=True, knocks_per_min=600)
    times, joints, stops = _events(0.2)
    n = 9_600
    whole = scape.render(0.0, n, times, joints, stops)
    split = _render_split(scape, times, joints, stops, sorted(cuts), n)
    np.testing.assert_allclose(split, whole, atol=1e-6)


def test_events_outside_the_block_and_tail_do_not_matter():
    scape = Soundscape(seed=1)
    times, joints, stops = _events(2.0)
    t0, n = 1.0, 4_800
    sel = (times >= t0 - scape.tail_s) & (times < t0 + n / SR)
    a = scape.render(t0, n, times, joints, stops)
    b = scape.render(t0, n, times[sel], joints[sel], stops[sel])
    np.testing.assert_array_equal(a, b)


def test_silent_room_without_steps_is_exactly_zero():
    scape = Soundscape(noise_db=-400.0, hum=False, knocks_per_min=0.0)
    x = scape.render(3.0, 1000)
    assert x.dtype == np.float32 and x.shape == (1000,)
    assert np.max(np.abs(x)) < 1e-18


def test_gain_scales_everything():
    """gain_db is a preamplifier: +6 dB multiplies every sample by 10**(6/20)."""
    times, joints, stops = _events(0.1)
    a = Soundscape(seed=2, babble=True).render(0.0, 4800, times, joints, stops)
    b = Soundscape(seed=2, babble=True, gain_db=6.0).render(0.0, 4800, times, joints, stops)
    np.testing.assert_allclose(b, a * 10 ** (6 / 20), rtol=1e-5, atol=1e-7)


def test_room_noise_level_matches_noise_db():
    """Room noise alone has mean square 10**(noise_db/10) (tables normalised), +-0.5 dB."""
    x = Soundscape(seed=3, noise_db=-50.0, hum=False, knocks_per_min=0).render(0.0, SR)
    assert 10 * np.log10(np.mean(x.astype(np.float64) ** 2)) == pytest.approx(-50.0, abs=0.5)


@pytest.mark.parametrize("joint", [1, 2, 3])
def test_stop_sound_is_joint_specific(joint):
    """Against the stop the spectrum rises most near the joint's own rattle frequency."""
    from scipy.signal import welch

    x, sr = render_traverse_recording(joint, 1000.0, 1.0, 2.0, seed=4, knocks_per_min=0)
    f, p_step = welch(x[: sr - 2400], sr, nperseg=1024)
    _, p_stop = welch(x[sr + 2400 :], sr, nperseg=1024)
    rise = 10 * np.log10(p_stop / p_step)
    peak = f[np.argmax(rise)]
    assert peak == pytest.approx(JOINT_SOUNDS[joint].stop_hz, abs=300.0)
    assert rise.max() > 25.0
    others = [JOINT_SOUNDS[j].stop_hz for j in JOINT_SOUNDS if j != joint]
    assert all(abs(peak - o) > 1000.0 for o in others)


def test_recording_is_labelled_and_reproducible():
    a, sr = render_traverse_recording(3, 900.0, 0.5, 1.0, seed=8)
    b, _ = render_traverse_recording(3, 900.0, 0.5, 1.0, seed=8)
    c, _ = render_traverse_recording(3, 900.0, 0.5, 1.0, seed=9)
    assert sr == SR and a.shape == (SR,)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(joint=4, step_hz=1000.0, stop_at_s=1.0, duration_s=2.0), "joint"),
        (dict(joint=1, step_hz=0.0, stop_at_s=1.0, duration_s=2.0), "step_hz"),
        (dict(joint=1, step_hz=1e3, stop_at_s=1.0, duration_s=2.0, sample_rate=1000), "8000"),
    ],
)
def test_bad_settings_name_the_allowed_range(kwargs, match):
    with pytest.raises(ValueError, match=match):
        render_traverse_recording(**kwargs)


def test_bad_joint_in_events():
    with pytest.raises(ValueError, match="1, 2 or 3"):
        Soundscape().render(0.0, 100, [0.001], [7], [False])
