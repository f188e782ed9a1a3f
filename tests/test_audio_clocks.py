"""Another instrument stepping in bursts in the tuning recording: two step clocks, refused (issue 35 item 6).

The tuning hears the step rate again in pieces of the stepping part
(:func:`stickslip.audio.tuning.tune.other_clock`); a second clock heard in some of them, off the
first and its harmonics, is another instrument's: the tuning refuses the recording rather than
learn that clock and its bursts' coming and going as the stop (the tenth generator's early stops).
Checked on the simulator's traverse recordings (another generator than the tenth's, where the
rule was found) and on the tenth generator's own draws.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from stickslip.audio.features.stepclock import clear_rates_hz
from stickslip.audio.tuning import TuningError, tune
from stickslip.audio.tuning.tune import other_clock
from stickslip.sim.sound import render_traverse_recording

sys.path.insert(0, str(Path(__file__).resolve().parent / "support"))
from fan_sound import SR, Arm, Scene, render, tuning_scene  # noqa: E402

STOP_S = 2.0


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(v, dtype=np.float64))))


def _with_bursts(joint: int, other: int, rate_hz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The simulator's ``joint`` at 1000 Hz, alone and with ``other`` stepping at ``rate_hz`` 0.45 s in each 0.9 s."""
    x, sr = render_traverse_recording(joint, 1000.0, STOP_S, 3.5, seed=11)
    y, _ = render_traverse_recording(other, rate_hz, 9.0, 3.5, seed=12)
    y = y * ((np.arange(x.size) / sr) % 0.9 < 0.45)
    return x, (x + y * (_rms(x) / _rms(y))).astype(np.float32), sr


@pytest.mark.parametrize(("joint", "other", "rate_hz"), [(1, 2, 730.0), (2, 3, 1250.0), (3, 1, 820.0)])
def test_a_second_clock_in_bursts_is_named_and_the_tuning_refused(joint: int, other: int, rate_hz: float) -> None:
    x, both, sr = _with_bursts(joint, other, rate_hz)
    part = int((STOP_S - 0.15) * sr)
    assert other_clock(x[:part], sr) is None
    said = other_clock(both[:part], sr)
    assert said is not None
    low, high = (float(v) for v in re.findall(r"(\d+) Hz", said))
    assert low == pytest.approx(min(rate_hz, 1000.0), abs=2.0) and high == pytest.approx(max(rate_hz, 1000.0), abs=2.0)
    with pytest.raises(TuningError, match="two step clocks"):
        tune(both, sr, STOP_S, joint=joint)


def test_one_clock_throughout_gives_one_rate() -> None:
    """The tenth generator's tuning recordings (every arm): each piece at the joint's 1000 Hz, none refused."""
    for arm in range(1, 9):
        x = render(tuning_scene(Arm(arm)))[: int((STOP_S - 0.15) * SR)]
        rates = clear_rates_hz(x, SR, SR // 4, 10.0)
        assert len(rates) == 7 and max(abs(r - 1000.0) for r in rates) < 2.0, (arm, rates)
        assert other_clock(x, SR) is None


def test_pieces_unheard_are_left_out() -> None:
    """Silence and white noise give no clear rate; a lone clear piece is one clock."""
    assert clear_rates_hz(np.zeros(SR), SR, SR // 4, 10.0) == []
    noise = np.random.default_rng(1).standard_normal(SR)
    assert clear_rates_hz(noise, SR, SR // 4, 10.0) == []
    steps = render(Scene(Arm(2), stop_at=None, dur=0.3, seed=5))
    x = np.concatenate([steps[: SR // 4], 1e-3 * noise]).astype(np.float32)
    assert other_clock(x, SR) is None
