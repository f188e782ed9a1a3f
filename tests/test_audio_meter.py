"""The record meter shows the stepping band's level in dBFS, labelled with the band."""

from __future__ import annotations

import numpy as np
import pytest
from battery_sound import Scene, render  # noqa: E402

from stickslip.audio.meter import BandMeter, MeterReading  # noqa: E402

SR = 48_000


def _sine(f_hz: float, amp: float, n: int) -> np.ndarray:
    return amp * np.sin(2 * np.pi * f_hz * np.arange(n) / SR)


@pytest.mark.parametrize("block", [128, 1024, 4800])
def test_a_sine_inside_the_band_reads_its_mean_square(block: int) -> None:
    # a sine of amplitude A has mean square A**2 / 2: 0.1 -> 10 log10(0.005) = -23.01 dBFS (Parseval)
    m = BandMeter(SR, band_hz=(2000.0, 6000.0))
    x = _sine(3000.0, 0.1, 48_000)
    r = [m.feed(x[i : i + block]) for i in range(0, x.size, block)][-1]
    assert r.band_hz == (2000.0, 6000.0)
    assert r.level_db == pytest.approx(10 * np.log10(0.1**2 / 2), abs=0.1)


def test_a_sine_outside_the_band_barely_registers() -> None:
    m = BandMeter(SR, band_hz=(2000.0, 6000.0))
    x = _sine(500.0, 0.1, 4800) + _sine(3000.0, 0.001, 4800)  # -63 dBFS in band, -23 dBFS out of it
    assert m.feed(x).level_db == pytest.approx(10 * np.log10(0.001**2 / 2), abs=0.5)


def test_the_band_is_learned_from_stepping_and_labelled() -> None:
    x, sr = render(Scene("P", 1000.0, None, 1.0, seed=3))  # joint P's modes: 1.7, 3.3, 6.1, 9.4 kHz
    m = BandMeter(sr, learn_s=0.5)
    first = m.feed(x[:1024])
    assert first.band_hz is None and "broadband" in first.line()
    readings = [m.feed(x[i : i + 1024]) for i in range(1024, x.size, 1024)]
    lo, hi = readings[-1].band_hz or (0.0, 0.0)
    assert lo < 1700 and hi > 9400
    assert f"in {lo:.0f}-{hi:.0f} Hz" in readings[-1].line()
    # the stepping is -28 dBFS RMS and nearly all inside the band
    assert readings[-1].level_db == pytest.approx(-28.0, abs=1.5)


def test_silence_keeps_learning_and_reads_low() -> None:
    m = BandMeter(SR, learn_s=0.1)
    for _ in range(10):
        r = m.feed(np.zeros(1024))
    assert r.band_hz is None and r.level_db < -150


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="sample_rate"):
        BandMeter(1000)
    with pytest.raises(ValueError, match="learn_s"):
        BandMeter(SR, learn_s=0.0)


def test_the_bar_is_bounded() -> None:
    assert MeterReading(20.0, (1.0, 2.0)).line(width=10).count("#") == 10
    assert MeterReading(-300.0, None).line(width=10).count("#") == 0
