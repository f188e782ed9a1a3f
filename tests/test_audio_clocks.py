"""Another instrument stepping in bursts in the tuning recording: two step clocks (issue 35 item 6).

The tuning hears the step rate again in pieces of the stepping part
(:func:`stickslip.audio.tuning.tune.other_clock`); a second clock heard in some of them, off the
first and its harmonics, is another instrument's. Untold which is the joint's, the tuning refuses
the recording rather than learn that clock and its bursts' coming and going as the stop (the
tenth generator's early stops); told the commanded rate, it leaves out the pieces the other clock
holds and learns from the rest (:mod:`stickslip.audio.tuning.clocks`), refusing where neither
clock is the told one or too little is left. Checked on the simulator's traverse recordings
(another generator than the tenth's, where the rules were found) and on the tenth generator's own
draws.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.detector import detector_for
from stickslip.audio.features.stepclock import clear_rates_hz
from stickslip.audio.tuning import TuningError, tune
from stickslip.audio.tuning.clocks import joint_clock_only, two_clocks
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


@pytest.mark.parametrize(("joint", "other", "rate_hz"), [(1, 2, 730.0), (2, 3, 1250.0), (3, 1, 820.0)])
def test_told_the_commanded_rate_the_other_clock_is_left_out_and_the_stop_heard(
    joint: int, other: int, rate_hz: float
) -> None:
    """Told 1000 Hz, the tuning keeps the joint's clock, learns from the pieces without the other, and hears a
    traverse's stop as the tuning on the recording without the other instrument does (within 5 ms, not flagged).
    Told a rate neither clock has, or the other instrument's (the joint's clock in every piece: nothing left):
    refused."""
    _, both, sr = _with_bursts(joint, other, rate_hz)
    tu = tune(both, sr, STOP_S, joint=joint, step_rate_hz=1000.0)
    assert tu.step_rate_hz == pytest.approx(1000.0, abs=1.0)
    y, _ = render_traverse_recording(joint, 1000.0, 2.5, 3.5, seed=21)
    det = ConfirmedStopDetector(detector_for(tu))
    det.reset(0.0, step_rate_hz=1000.0)
    events = det.feed(y.astype(np.float32)) + det.finish()
    assert len(events) == 1 and not events[0].onset_uncertain and abs(events[0].onset_s - 2.5) <= 0.005
    with pytest.raises(TuningError, match="neither"):
        tune(both, sr, STOP_S, joint=joint, step_rate_hz=1150.0)
    if joint != 1:  # joint 1 told 730 Hz is refused too, by the template's own checks (its stepping fires it)
        with pytest.raises(TuningError, match="left out"):
            tune(both, sr, STOP_S, joint=joint, step_rate_hz=rate_hz)


def test_the_pieces_the_other_clock_holds_are_left_out_from_the_stop_outwards() -> None:
    """The simulator's joint 2 with joint 3 at 1250 Hz for 0.45 s of every 0.9 s: the stepping kept is the joint
    alone (one clock, 1000 Hz), the bursts' share of it gone; the stop at the join of the stepping and the stop kept."""
    x, both, sr = _with_bursts(2, 3, 1250.0)
    clocks = two_clocks(both[: int((STOP_S - 0.15) * sr)], sr)
    assert clocks is not None and sorted(clocks) == [pytest.approx(1000.0, abs=2.0), pytest.approx(1250.0, abs=2.0)]
    y, stop_s = joint_clock_only(both, sr, STOP_S, clocks, 1000.0)
    assert 0.5 <= stop_s <= 0.55 * STOP_S  # the gaps, 0.45 s of each 0.9 s, less the pieces a burst's edge spoils
    assert y.size - stop_s * sr >= 0.25 * sr  # the stop part: the joint's stop masks the other's line here, kept
    assert other_clock(y[: int(stop_s * sr)], sr) is None
    assert max(abs(r - 1000.0) for r in clear_rates_hz(y[: int(stop_s * sr)], sr, sr // 4, 10.0)) < 2.0
    with pytest.raises(TuningError, match="left out"):
        joint_clock_only(both[: int(2.2 * sr)], sr, 0.8, clocks, 1000.0)  # 0.8 s of stepping, under 0.5 s kept


def test_the_command_line_tells_the_tuning_the_commanded_rate(tmp_path: Path) -> None:
    """``stickslip tune --rate``: the recording with another instrument refused without it, tuned with it; a rate that
    is not one refused before tuning."""
    from typer.testing import CliRunner

    from stickslip.audio.sources import write_wav
    from stickslip.cli import app

    _, both, sr = _with_bursts(2, 3, 1250.0)
    wav = tmp_path / "both.wav"
    write_wav(wav, both, sr)
    args = ["tune", str(wav), "--stop-at", str(STOP_S), "-o", str(tmp_path / "t.json"), "--no-self-check"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2 and "two step clocks" in r.output
    r = CliRunner().invoke(app, [*args, "--rate", "1000"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "t.json").exists()
    r = CliRunner().invoke(app, [*args, "--rate", "0"])
    assert r.exit_code == 2 and "--rate must be a step rate" in r.output
