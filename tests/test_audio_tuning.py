"""Tuning from a labelled recording, then detection on recordings it has not seen.

The acceptance targets of issue 3 (item 3): every stop found within +-25 ms, median
latency (detected_at - true stop) <= 30 ms and 95th percentile <= 50 ms at 48 kHz, no
false alarm in two minutes of stepping with interference. Tuned on one recording (seed
11, 1000 Hz, 0 dB, no babble); checked on others with different seeds, step rates
800-1300 Hz, microphone gain +-3 dB, knocks and speech-like babble.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from stickslip.audio.detector import detect
from stickslip.audio.tuning import TuningError, candidate_bands, tune, tune_band
from stickslip.sim.sound import render_traverse_recording

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("audio_tuning")]  # slow; its tunings made once

TUNE_STOP_S = 2.0


@pytest.fixture(scope="module")
def tunings():
    out = {}
    for joint in (1, 2, 3):
        x, sr = render_traverse_recording(joint, 1000.0, TUNE_STOP_S, 3.5, seed=11)
        out[joint] = tune(x, sr, TUNE_STOP_S, joint=joint)
    return out


RATES = [800.0, 870.0, 950.0, 1030.0, 1110.0, 1180.0, 1250.0, 1300.0]
GAINS = [-3.0, 3.0, -1.5, 2.0, 0.5, -2.5, 3.0, -3.0]


def test_tuning_learns_the_joints_own_stop(tunings):
    """The signature peaks in the sub-band holding the joint's rattle, the template stays below 0.42 fs."""
    from stickslip.sim.sound import JOINT_SOUNDS

    for joint, t in tunings.items():
        assert t.method == "template" and t.edges_hz is not None and t.signature_db is not None
        k = int(np.argmax(t.signature_db))
        assert t.edges_hz[k] <= JOINT_SOUNDS[joint].stop_hz <= t.edges_hz[k + 1], (joint, t.edges_hz, t.signature_db)
        assert max(t.signature_db) > 12.0  # the rattle adds >12 dB in its sub-band
        assert t.edges_hz[-1] <= 0.42 * t.sample_rate
        assert t.stepping_db < t.threshold_db < t.stopped_db  # worst stepping frame < threshold < stop's low
        # the self-check ran and found the stop in every variant (knocks, babble, second train, +-20 dB)
        assert t.checks["stops_found"] == t.checks["stops"] == 5 and t.checks["false_alarms"] <= 1
        assert t.checks["false_alarms_per_hour"] == pytest.approx(
            t.checks["false_alarms"] / t.checks["checked_s"] * 3600, abs=0.1
        )


def test_version_1_band_tuning_still_loads_and_runs(tmp_path):
    """A tuning file of the band detector (version 1) loads and is run by the band detector."""
    x, sr = render_traverse_recording(2, 1000.0, 2.0, 3.0, seed=12)
    old = tune_band(x, sr, 2.0, joint=2)
    d = old.to_dict()
    assert d["version"] == 1 and "method" not in d and "signature_db" not in d
    p = tmp_path / "old.json"
    old.save(p)
    from stickslip.audio.detector import Tuning

    back = Tuning.load(p)
    assert back.method == "band" and back == old
    y, _ = render_traverse_recording(2, 1100.0, 1.2, 1.8, seed=13)
    (ev,) = detect(y, back)
    assert abs(ev.onset_s - 1.2) < 0.025


def test_template_tuning_round_trips(tunings, tmp_path):
    from stickslip.audio.detector import Tuning

    t = tunings[1]
    p = tmp_path / "t.json"
    t.save(p)
    back = Tuning.load(p)
    assert back == t and back.to_dict()["version"] == 2


def test_a_late_label_is_corrected_and_named():
    """A stop label 0.1 s late: a warning names where the sound changes; the onset stays unbiased."""
    x, sr = render_traverse_recording(3, 1000.0, 2.0, 3.0, seed=14)
    t = tune(x, sr, 2.1, joint=3)
    (w,) = [w for w in t.checks["warnings"] if "disagrees" in w]
    assert re.search(r"labelled stop \(2\.100 s\) disagrees with the sound, which changes at (1\.99|2\.00)\d s", w), w
    assert t.checks["stop_at_sound_s"] == pytest.approx(2.0, abs=0.01)
    y, _ = render_traverse_recording(3, 1000.0, 1.3, 2.0, seed=15)
    (ev,) = detect(y, t)
    assert abs(ev.onset_s - 1.3) < 0.01


def test_refuses_when_nothing_changes_near_the_label():
    x, sr = render_traverse_recording(1, 1000.0, 2.5, 3.5, seed=16)
    with pytest.raises(TuningError, match="nothing changes near the labelled stop at 1.2 s"):
        tune(x, sr, 1.2)


def test_listening_that_begins_at_the_stop_fires_at_once(tunings):
    """The detector learns its template from the first 0.17 s; if that is already the stop, it says so."""
    x, sr = render_traverse_recording(2, 1000.0, 0.0, 1.0, seed=17)  # at the stop throughout
    (ev,) = detect(x, tunings[2])
    assert ev.onset_s == 0.0 and ev.detected_at_s < 0.2
    y, _ = render_traverse_recording(2, 1000.0, 1e9, 1.0, seed=18)  # stepping throughout
    assert detect(y, tunings[2]) == []


def test_targets_on_unseen_recordings(tunings):
    latencies, onset_errors = [], []
    for joint, tuning in tunings.items():
        for k, (rate, gain) in enumerate(zip(RATES, GAINS, strict=True)):
            stop_at = 1.0 + 0.07 * k
            x, _ = render_traverse_recording(
                joint,
                rate,
                stop_at,
                stop_at + 0.6,
                seed=200 + 10 * joint + k,
                gain_db=gain,
                babble=True,
                knocks_per_min=30.0,
            )
            events = detect(x, tuning, block=1024)
            assert len(events) == 1, (joint, rate, gain, events)
            onset_errors.append(events[0].onset_s - stop_at)
            latencies.append(events[0].detected_at_s - stop_at)
    onset_errors, latencies = np.array(onset_errors), np.array(latencies)
    assert np.all(np.abs(onset_errors) <= 0.025), onset_errors
    assert np.all(latencies > 0)
    assert np.median(latencies) <= 0.030
    assert np.percentile(latencies, 95) <= 0.050
    # the latency the traverse corrects with is what actually happens, +-3 ms
    assert np.median(latencies) == pytest.approx(np.median([t.latency_s for t in tunings.values()]), abs=0.003)


@pytest.mark.parametrize("joint, rate", [(1, 1300.0), (2, 800.0), (3, 1050.0)])
def test_no_false_alarm_in_two_minutes_of_stepping(tunings, joint, rate):
    x, _ = render_traverse_recording(
        joint, rate, 1e9, 120.0, seed=900 + joint, gain_db=3.0, babble=True, knocks_per_min=12.0
    )
    assert detect(x, tunings[joint], block=2048) == []


def test_tuning_at_44k1():
    x, sr = render_traverse_recording(2, 1000.0, 1.5, 2.5, seed=3, sample_rate=44_100)
    t = tune(x, sr, 1.5, joint=2)
    assert t.sample_rate == 44_100 and t.frame == 512
    y, _ = render_traverse_recording(2, 1200.0, 1.2, 2.0, seed=4, sample_rate=44_100, gain_db=-3.0, babble=True)
    (ev,) = detect(y, t)
    assert abs(ev.onset_s - 1.2) < 0.025 and ev.detected_at_s - 1.2 < 0.05


def test_refuses_a_recording_whose_halves_sound_alike():
    x, sr = render_traverse_recording(1, 1000.0, 1e9, 3.0, seed=5)
    with pytest.raises(TuningError, match="sound alike"):
        tune(x, sr, 1.5)


def test_refuses_a_wrong_stop_time():
    x, sr = render_traverse_recording(1, 1000.0, 2.0, 3.0, seed=5)
    with pytest.raises(TuningError, match=r"within 0\.280\.\.2\.720 s"):
        tune(x, sr, 2.8)
    # a stop time far off: the parts are mixed, the detector would fire elsewhere
    with pytest.raises(TuningError):
        tune(x, sr, 0.8)


def test_refuses_a_too_short_recording():
    x, sr = render_traverse_recording(1, 1000.0, 0.25, 0.5, seed=5)
    with pytest.raises(TuningError, match="at least"):
        tune(x, sr, 0.25)


def test_tunes_on_a_short_stop():
    """0.3 s of stop after the event is enough (the simulator's labelled recordings)."""
    x, sr = render_traverse_recording(1, 1000.0, 1.0, 1.3, seed=5, babble=True)
    t = tune(x, sr, 1.0, joint=1)
    (ev,) = detect(render_traverse_recording(1, 1200.0, 0.8, 1.2, seed=6)[0], t)
    assert abs(ev.onset_s - 0.8) < 0.025


def test_candidate_bands_respect_width_and_nyquist():
    bands = candidate_bands(48_000, 512, min_band_hz=1400.0)
    assert bands and all(hi - lo >= 1400.0 and hi <= 0.98 * 24_000 for lo, hi in bands)


def test_refusal_names_the_spans_that_spoil_the_recording():
    """A stretch of stop sound pasted into the stepping part (a second stop heard): tune names where."""
    x, sr = render_traverse_recording(2, 1000.0, 2.0, 3.0, seed=19)
    x = x.copy()
    x[int(0.9 * sr) : int(1.3 * sr)] = x[int(2.2 * sr) : int(2.6 * sr)]  # the stop, heard at 0.9-1.3 s
    with pytest.raises(TuningError, match=r"sounds like the stop at 0\.9\d-1\.[23]\d s") as e:
        tune(x, sr, 2.0)
    assert "cut those spans out" in str(e.value)


def test_a_label_far_off_is_refused_naming_where_the_sound_changes():
    x, sr = render_traverse_recording(1, 1000.0, 2.0, 3.5, seed=20)
    with pytest.raises(
        TuningError, match=r"nothing changes near the labelled stop at 2\.7 s .*changes at (1\.99|2\.00)\d s"
    ):
        tune(x, sr, 2.7)
