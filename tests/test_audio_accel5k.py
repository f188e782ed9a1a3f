"""An accelerometer bridge that samples at 5 kHz: tuned, heard, and a pause before the stop is not the stop.

Accelerometer bridges commonly send 5 kHz (``tests/support/mount_sound.py``: an accelerometer on a
two-mass mount read through a 2 kHz anti-alias filter, written for this before the detector was
changed and never tuned to). Stepping is below 1 kHz there, so the envelope's lines at the rate and
its first multiples are under the Nyquist frequency. Before: ``tune`` refused the CSV ("sample rate
5000 Hz is outside 8000-192000 Hz"), and on an accelerometer recording a short pause in the
stepping a few seconds before the stop was reported as the stop.
"""

from __future__ import annotations

import json
from dataclasses import replace

import mount_sound as mt
import numpy as np
import pytest
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)
from typer.testing import CliRunner

from stickslip.audio.detector import detect
from stickslip.audio.events import StopEvent
from stickslip.audio.sources.vibration import read_vibration
from stickslip.audio.tuningfile import Tuning
from stickslip.cli import app

pytestmark = pytest.mark.slow  # tunes a recording: make test-fast leaves this file out

TOL_S = 0.025


def _train(seed: int = 1) -> mt.Scene:
    return mt.Scene(mount=mt.Mount(seed), rate=700.0, stop_at=5.0, dur=6.5, seed=10)


def test_the_generator_steps_below_1_khz_at_5_khz_and_its_stop_changes_the_mount() -> None:
    x = mt.render(_train())
    assert x.size == int(6.5 * mt.FS_OUT)
    sr = mt.FS_OUT
    before, after = x[int(3.5 * sr) : int(4.5 * sr)], x[int(5.2 * sr) : int(6.2 * sr)]
    # the envelope's line at the step rate: the slips, 700 Hz, below a quarter of the sample rate
    f = np.fft.rfftfreq(2 * sr, 1 / sr)
    env = np.abs(np.fft.rfft((np.diff(before, prepend=before[0]) ** 2 - np.mean(np.diff(before) ** 2)), 2 * sr)) ** 2
    band = (f > 500) & (f < 1000)
    assert abs(f[band][int(np.argmax(env[band]))] - 700.0) <= 1.0
    change_db = 20 * np.log10(float(np.std(before)) / float(np.std(after)))
    assert change_db > 1.0  # the blocked slider slips weaker: the stop is quieter, and its upper mode moves


def test_tune_takes_a_5_khz_csv_of_the_bridge(tmp_path: object) -> None:
    mt.write_csv(f"{tmp_path}/train.csv", mt.render(_train()))
    r = CliRunner().invoke(app, ["tune", f"{tmp_path}/train.csv", "--stop-at", "5.0", "-o", f"{tmp_path}/t.json"])
    assert r.exit_code == 0, r.output
    tu = Tuning.load(f"{tmp_path}/t.json")
    assert tu.sample_rate == 5000 and tu.step_rate_hz == pytest.approx(700.0, rel=0.01)


@pytest.fixture(scope="module")
def tuning() -> Tuning:
    return tune(mt.render(_train()), mt.FS_OUT, 5.0)


@pytest.mark.parametrize("seed", [3, 4])
def test_listen_hears_the_stop_once_on_another_recording(tuning: Tuning, seed: int, tmp_path: object) -> None:
    mt.write_csv(f"{tmp_path}/test.csv", mt.render(mt.Scene(rate=690.0, stop_at=4.0, dur=5.0, seed=seed)))
    y, sr = read_vibration(f"{tmp_path}/test.csv")
    events = detect(y, tuning.for_sample_rate(sr), block=1024, confirm_s=0.5)
    assert len(events) == 1 and abs(events[0].onset_s - 4.0) <= TOL_S, [(e.onset_s, e.detected_at_s) for e in events]


@pytest.mark.parametrize("rate", [560.0, 840.0])
def test_stepping_20_percent_slower_or_faster_than_the_tuning_is_heard_on_time(tuning: Tuning, rate: float) -> None:
    # the mount's modes are broad: a rate 20 % off the tuning moves no narrow line across a sub-band
    y = mt.render(mt.Scene(rate=rate, stop_at=3.0, dur=4.0, seed=11))
    events = detect(y.astype(np.float32), tuning, block=1024, confirm_s=0.5)
    assert len(events) == 1 and abs(events[0].onset_s - 3.0) <= TOL_S, [(e.onset_s, e.detected_at_s) for e in events]


@pytest.mark.parametrize("pause_at", [1.5, 2.0])
def test_a_short_pause_a_few_seconds_before_the_stop_is_not_the_stop(tuning: Tuning, pause_at: float) -> None:
    y = mt.render(mt.Scene(rate=700.0, stop_at=4.5, dur=5.5, pause_at=pause_at, pause_s=0.4, seed=7))
    events = detect(y.astype(np.float32), tuning, block=1024, confirm_s=0.5)
    wrong = [e for e in events if abs(e.onset_s - 4.5) > TOL_S and not e.onset_uncertain]
    assert not wrong, [(e.onset_s, e.detected_at_s) for e in events]
    assert any(abs(e.onset_s - 4.5) <= TOL_S for e in events), [(e.onset_s, e.detected_at_s) for e in events]


def test_listen_json_on_the_bridges_csv(tuning: Tuning, tmp_path: object) -> None:
    tuning.save(f"{tmp_path}/t.json")
    mt.write_csv(f"{tmp_path}/test.csv", mt.render(mt.Scene(rate=700.0, stop_at=3.0, dur=4.0, seed=5)))
    r = CliRunner().invoke(app, ["listen", f"{tmp_path}/test.csv", "--tuning", f"{tmp_path}/t.json", "--json"])
    assert r.exit_code == 0, r.output
    events = json.loads(r.stdout)
    assert len(events) == 1 and abs(events[0]["onset_s"] - 3.0) <= TOL_S


def _first_is_right_or_flagged(events: list[StopEvent], stop: float) -> bool:
    """A traverse counts to the first event: it must be on time, or flagged (a refusal), never silently off."""
    return bool(events) and (abs(events[0].onset_s - stop) <= TOL_S or events[0].onset_uncertain)


@pytest.mark.parametrize("seed", [30, 31, 32, 33, 34])
def test_another_instrument_stepping_in_bursts_nearby_in_the_test_only(tuning: Tuning, seed: int) -> None:
    # a second slider on the same table, 910 Hz in 0.3 s bursts, 6 dB under the arm's stepping
    y = mt.render(mt.Scene(rate=700.0, stop_at=4.0, dur=5.0, seed=seed, other_rate=910.0, other_db=-6.0))
    events = detect(y.astype(np.float32), tuning, block=1024, confirm_s=0.5)
    assert _first_is_right_or_flagged(events, 4.0), [(e.onset_s, e.onset_uncertain) for e in events]


@pytest.fixture(scope="module")
def tuning_with_other() -> Tuning:
    return tune(mt.render(replace(_train(), other_rate=910.0)), mt.FS_OUT, 5.0)


@pytest.mark.parametrize("seed", [30, 32, 34])
def test_another_instrument_stepping_in_bursts_in_training_and_test(tuning_with_other: Tuning, seed: int) -> None:
    tu = tuning_with_other
    y = mt.render(mt.Scene(rate=700.0, stop_at=4.0, dur=5.0, seed=seed, other_rate=910.0, other_db=0.0))
    events = detect(y.astype(np.float32), tu, block=1024, confirm_s=0.5)
    assert len(events) == 1 and abs(events[0].onset_s - 4.0) <= TOL_S, [(e.onset_s, e.onset_uncertain) for e in events]


@pytest.mark.xfail(
    strict=True,
    reason="measured: the other instrument as loud as the arm's stepping, heard in the test only: on seed 34 the "
    "first event is unflagged at 3.929 s, 71 ms before the stop at 4.0 (seeds 30, 32, 33 are flagged, 31 right); "
    "tuned with it in training all five are right",
)
def test_another_instrument_as_loud_as_the_stepping_in_the_test_only(tuning: Tuning) -> None:
    y = mt.render(mt.Scene(rate=700.0, stop_at=4.0, dur=5.0, seed=34, other_rate=910.0, other_db=0.0))
    events = detect(y.astype(np.float32), tuning, block=1024, confirm_s=0.5)
    assert _first_is_right_or_flagged(events, 4.0), [(e.onset_s, e.onset_uncertain) for e in events]
