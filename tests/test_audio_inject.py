"""The self-check's interference (stickslip.audio.tuning.inject) at any sample rate a sound card offers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.tuning.inject import babble, click_train, knocks
from stickslip.sim.sound import render_traverse_recording

RATES = [4000, 8000, 11_025, 16_000, 22_050, 44_100, 48_000, 96_000, 192_000]


@settings(max_examples=40, deadline=None)
@given(rate=st.sampled_from(RATES), seed=st.integers(0, 99))
def test_interference_is_finite_at_its_level_at_every_sample_rate(rate, seed):
    # an 8 kHz file made tune fail inside the injection (a fricative band drawn from 3.5 kHz up to 0.4 fs)
    n = int(0.6 * rate)
    rng = np.random.default_rng(seed)
    for make in (
        lambda: babble(n, rate, 0.1, rng),
        lambda: click_train(n, rate, 0.1, rng),
        lambda: knocks(n, rate, 0.1, rng, every_s=0.2),
    ):
        x = make()
        assert x.shape == (n,) and np.all(np.isfinite(x))
    y = click_train(n, rate, 0.1, rng, level_db=0.0)
    assert np.sqrt(np.mean(y**2)) == pytest.approx(0.1, rel=1e-9)  # at the level asked for


def test_tune_on_an_8_khz_recording_finishes_and_reports_its_self_check():
    x, sr = render_traverse_recording(3, 1000.0, 2.0, 3.0, seed=31)
    y = x[::6].copy()  # 8 kHz: joint 3's rattle is gone, what is left below 4 kHz must do
    tu = tune(y, 8000, 2.0, seed=0)
    assert tu.sample_rate == 8000 and "false_alarms_per_hour" in str(tu.checks)
