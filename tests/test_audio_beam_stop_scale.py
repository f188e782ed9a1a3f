"""The beam generator's two stop loudnesses (``beam_sound.Scene.stop_scale``; audio49, audio50).

``"recording"`` scales each recording's stop to that recording's stepping RMS; ``"arm"`` fixes the factor per arm
(the tuning recording's). At the tuning recording the two render the same samples; at another step rate the
per-recording stop is as loud as the stepping whatever the modes, while the per-arm stop's loudness against the
stepping follows the two sets of modes at the rate's lines: the arm's factor times the ratio of the stop's to the
stepping's kernel power summed over the harmonics ``k r``.
"""

from __future__ import annotations

import dataclasses

import beam_sound as bm
import numpy as np
import pytest

SR = bm.SR


def _stop_re_step_db(s: bm.Scene) -> float:
    """The rendered stop's RMS against the stepping's (0.2-1.95 s against 2.1 s to the end), dB."""
    y = np.asarray(bm.render(s), dtype=np.float64)
    assert s.stop_at == 2.0
    return float(10 * np.log10(np.mean(y[int(2.1 * SR) :] ** 2) / np.mean(y[int(0.2 * SR) : int(1.95 * SR)] ** 2)))


def _line_power_ratio_db(beam: bm.Beam, rate: float) -> float:
    """The stop's kernel power over the stepping's, summed at the harmonics ``k rate`` up to 0.45 fs, dB."""
    m = bm.beam_modes(beam, SR)
    f = np.arange(1, int(0.45 * SR / rate) + 1) * rate
    power = []
    for name in ("step", "stop"):
        k = bm._kernel(m[f"{name}_f"], m[f"{name}_g"], float(m["q"]), SR)
        spectrum = np.exp(-2j * np.pi * np.outer(f, np.arange(k.size)) / SR) @ k
        power.append(float(np.sum(np.abs(spectrum) ** 2)))
    return float(10 * np.log10(power[1] / power[0]))


@pytest.mark.parametrize("beam", [1, 5])
def test_at_the_tuning_recording_both_stop_scales_render_the_same_samples(beam: int) -> None:
    s = bm.tuning_scene(bm.Beam(beam))
    assert np.array_equal(bm.render(s), bm.render(dataclasses.replace(s, stop_scale="arm")))
    quiet = bm.Scene(beam=bm.Beam(beam), rate=950.0, stop_at=None, seed=3)  # no stop: nothing to scale
    assert np.array_equal(bm.render(quiet), bm.render(dataclasses.replace(quiet, stop_scale="arm")))


@pytest.mark.parametrize(
    ("beam", "rate", "arm_db"),
    [(1, 800.0, -6.6), (3, 900.0, 3.4), (5, 800.0, -11.4), (8, 1200.0, -9.7), (2, 1200.0, 7.0)],
)
def test_off_the_tuning_rate_the_per_arm_stop_follows_the_modes(beam: int, rate: float, arm_db: float) -> None:
    s = bm.Scene(beam=bm.Beam(beam), rate=rate, seed=int(rate))
    assert abs(_stop_re_step_db(s)) < 0.05  # per recording: as loud as the stepping, whatever the modes
    measured = _stop_re_step_db(dataclasses.replace(s, stop_scale="arm"))
    assert measured == pytest.approx(arm_db, abs=0.1)
    predicted = 20 * np.log10(bm.arm_stop_scale(bm.Beam(beam))) + _line_power_ratio_db(bm.Beam(beam), rate)
    assert measured == pytest.approx(predicted, abs=1.0)  # 0.04-0.8 dB off (jitter, slip strengths, rounding)


def test_an_unknown_stop_scale_is_refused() -> None:
    with pytest.raises(ValueError, match="stop_scale"):
        bm.render(bm.Scene(beam=bm.Beam(1), rate=1000.0, stop_scale="stepping"))
