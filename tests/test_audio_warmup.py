"""The detector's first half second: a recording that starts at the stop, at any step rate.

At the end of its warm-up the detector asks whether it began listening at the stop. The
sub-band levels cannot say so at another step rate than the tuning's: the lines of a
click train fall elsewhere on narrow modes and move a sub-band by many dB. The power
*between* the lines (the continuum the steps' irregularity makes) is shaped by the same
modes at every rate, and is what the judgement uses (``template.continuum_levels_db``).

The recordings come from the battery's generator (``battery_sound``: modal resonators
driven by a jittered click train), not the project's simulator; the knocks at the start
are made here.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from functools import cache
from typing import Any

import numpy as np
import pytest
from battery_sound import Scene, espeak_speech, render, variant
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.detector import StopEvent, detect, detector_for
from stickslip.audio.features.spectra import SPECTRA, continuum_levels_db
from stickslip.audio.tuningfile import Tuning

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
JOINTS = {"P": Scene("P", 1000.0, 2.0, 3.0, seed=1), "Q": Scene("Q", 1000.0, 2.0, 3.0, seed=2)}


@cache
def _tuning(joint: str) -> Tuning:
    x, sr = render(JOINTS[joint])
    return tune(x, sr, 2.0, seed=0)


def _at_once(events: list[StopEvent], within_s: float = 0.3) -> list[StopEvent]:
    return [e for e in events if e.detected_at_s <= within_s]


@settings(max_examples=16, deadline=None)
@given(joint=st.sampled_from(["P", "Q"]), rate=st.floats(700.0, 1400.0), seed=st.integers(1, 10**6))
def test_a_recording_that_starts_at_the_stop_fires_at_once_at_any_step_rate(joint: str, rate: float, seed: int) -> None:
    x, _ = render(variant(JOINTS[joint], seed=seed, stop_at=0.0, dur=0.9, rate=rate))
    events = detect(x, _tuning(joint), block=2048, confirm_s=0.5)  # as listen reports them
    assert len(events) == 1, [(e.onset_s, e.detected_at_s) for e in events]
    assert abs(events[0].onset_s) <= 0.025 and events[0].detected_at_s <= 0.25


@settings(max_examples=16, deadline=None)
@given(joint=st.sampled_from(["P", "Q"]), rate=st.floats(700.0, 1400.0), seed=st.integers(1, 10**6))
def test_stepping_at_another_rate_than_the_tunings_does_not_fire_at_once(joint: str, rate: float, seed: int) -> None:
    x, _ = render(variant(JOINTS[joint], seed=seed, stop_at=None, dur=0.6, rate=rate))
    assert detect(x, _tuning(joint), block=4096) == []


def _knocks_from_the_start(x: np.ndarray, seed: int) -> np.ndarray:
    """Two table knocks (a 40-150 Hz mode and a contact burst, 20 dB over the stepping) at 10 and 90 ms."""
    rng = np.random.default_rng(seed)
    n = int(0.25 * SR)
    t = np.arange(n) / SR
    y = np.asarray(x, dtype=np.float64).copy()
    for t0 in (0.01, 0.09):
        knock = np.sin(2 * np.pi * rng.uniform(40, 150) * t) * np.exp(-t / 0.06)
        burst = rng.standard_normal(n) * np.exp(-t / 0.003)
        knock += 0.6 * (burst - lfilter([0.2], [1, -0.8], burst))
        knock *= 10 ** (-28 / 20) * 10.0 / np.max(np.abs(knock))
        i0 = int(t0 * SR)
        y[i0 : i0 + n] += knock[: y.size - i0]
    return y


ROOMS: dict[str, dict[str, Any]] = {
    "knocks from the first sample": {},
    "formant babble from the first sample, +6 dB": {"speech": "babble", "speech_db": 6.0},
    "a second talker (espeak-ng) from the first sample, +3 dB": {"speech": "espeak2", "speech_db": 3.0},
    "a door slam at 50 ms": {"door_at": 0.05},
    "a fan with a motor whine": {"fan": True},
    "a radio, +6 dB": {"music": True, "music_db": 6.0},
}


@pytest.mark.parametrize("room", list(ROOMS))
@pytest.mark.parametrize("joint", ["P", "Q"])
def test_a_recording_that_starts_stepping_with_a_knock_or_a_voice_does_not_fire_at_once(joint: str, room: str) -> None:
    kw = ROOMS[room]
    if str(kw.get("speech", "")).startswith("espeak") and espeak_speech(SR, "espeak2") is None:
        pytest.skip("espeak-ng is not installed (apt-get install espeak-ng)")
    for rate, seed in ((750.0, 300), (1080.0, 301), (1300.0, 302)):
        x, _ = render(variant(JOINTS[joint], seed=seed, stop_at=None, dur=0.6, rate=rate, **kw))
        if room.startswith("knocks"):
            x = _knocks_from_the_start(x, seed)
        assert _at_once(detect(x, _tuning(joint), block=1024)) == [], (rate, seed)


@pytest.mark.parametrize("block", [128, 1000, 4096, 65536])
def test_the_start_at_the_stop_does_not_depend_on_the_block_size(block: int) -> None:
    x, _ = render(variant(JOINTS["P"], seed=78, stop_at=0.0, dur=0.6, rate=1080.0))
    ref = [(e.onset_s, e.detected_at_s) for e in detect(x, _tuning("P"), block=1 << 16)]
    assert len(ref) == 1
    assert [(e.onset_s, e.detected_at_s) for e in detect(x, _tuning("P"), block=block)] == ref


def test_a_tuning_without_the_continuum_behaves_as_before() -> None:
    """Files made before the step rate was recorded load, and judge the start on the levels alone."""
    tu = _tuning("P")
    assert tu.step_rate_hz is not None and abs(tu.step_rate_hz - 1000.0) < 2.0
    d = tu.to_dict()
    for k in ("step_rate_hz", "continuum_levels_db", "continuum_signature_db", "continuum_spread_db"):
        d.pop(k)
    old = Tuning.from_dict(json.loads(json.dumps(d)))
    assert old.step_rate_hz is None and old.continuum_levels_db is None
    x, _ = render(variant(JOINTS["P"], seed=78, stop_at=0.0, dur=0.6, rate=1080.0))
    assert detect(x, old) == []  # the levels alone do not show it at 1080 Hz (the battery's old known failure)
    assert len(detect(x, tu)) == 1


def test_the_continuum_round_trips_through_the_file_with_nulls() -> None:
    tu = _tuning("Q")
    assert tu.continuum_levels_db is not None
    sig = list(tu.continuum_signature_db or ())
    sig[0] = math.nan  # a sub-band without a bin off the lines
    tu2 = replace(tu, continuum_signature_db=tuple(sig))
    text = json.dumps(tu2.to_dict(), allow_nan=False)  # strict JSON: NaN is written as null
    back = Tuning.from_dict(json.loads(text))
    assert back.continuum_signature_db is not None and math.isnan(back.continuum_signature_db[0])
    assert list(back.continuum_signature_db[1:]) == sig[1:] == list(tu2.continuum_signature_db or ())[1:]
    assert back.step_rate_hz == tu2.step_rate_hz
    with pytest.raises(ValueError, match="come together"):
        replace(tu, continuum_spread_db=None)
    with pytest.raises(ValueError, match="at least 0.001 dB"):
        replace(tu, continuum_spread_db=(0.0,) + tuple(tu.continuum_spread_db or ())[1:])


@settings(max_examples=20, deadline=None)
@given(
    period=st.integers(32, 80),
    rms_db=st.floats(-60.0, -10.0),
    line_db=st.floats(10.0, 40.0),
    seed=st.integers(0, 2**31),
)
def test_the_continuum_is_the_noise_between_the_lines(period: int, rms_db: float, line_db: float, seed: int) -> None:
    """White noise of variance s^2 has a one-sided power of 2 s^2 / N per bin of an N-point frame; a perfectly
    periodic click train (lines only, up to ``line_db`` louder than the noise; a whole number of samples per
    period, 600-1500 Hz, so that no click lands off its time) added to it changes nothing."""
    rate = SR / period
    rng = np.random.default_rng(seed)
    n = int(0.5 * SR)
    s = 10 ** (rms_db / 20)
    noise = s * rng.standard_normal(n)
    clicks = np.zeros(n)
    clicks[::period] = 1.0
    clicks *= s * 10 ** (line_db / 20) / np.std(clicks)
    frame = SPECTRA.continuum_frame * 512
    edges = (2000.0, 4000.0, 8000.0, 16000.0)
    expect = 10 * np.log10(2 * s**2 / frame)
    for x in (noise, noise + clicks):
        c = continuum_levels_db(x, SR, frame, 512, edges, rate)
        level = 10 * np.log10(np.mean(10 ** (c / 10), axis=0))
        assert np.all(np.abs(level - expect) < 0.6), (level - expect, rate)


def test_the_detector_keeps_only_the_warm_ups_samples() -> None:
    det = detector_for(_tuning("P"))
    x, _ = render(variant(JOINTS["P"], seed=5, stop_at=None, dur=1.0))
    for i in range(0, x.size, 700):
        det.feed(x[i : i + 700])
    st_ = det.state
    assert st_ is not None and st_.head is not None and st_.head.size == st_.head_samples
    assert det._head is not None and det._head._parts == []  # the pieces are let go once joined


@settings(max_examples=10, deadline=None)
@given(
    joint=st.sampled_from(["P", "Q"]),
    rate=st.floats(700.0, 1400.0),
    drift=st.sampled_from([0.1, -0.1]),
    seed=st.integers(1, 10**6),
)
def test_a_drifting_step_rate_without_a_stop_gives_no_event(joint: str, rate: float, drift: float, seed: int) -> None:
    """The step clock drifts 10 % over 2 s (from -10 % to +10 % of ``rate``, or back), no stop: no stop reported.

    Counted as ``listen`` reports them (confirmed over 0.5 s), except a fire in the recording's last 0.5 s,
    which ``finish`` reports if what was heard of it persisted (its ``confirmed_s`` says so; a traverse's stream
    does not end there): the stale-template check needs 0.3 s after a fire.
    """
    x, _ = render(variant(JOINTS[joint], seed=seed, stop_at=None, dur=2.0, rate=rate, drift=drift))
    events = detect(x, _tuning(joint), block=1024, confirm_s=0.5)
    heard = [e for e in events if (e.confirmed_s or 0.0) >= 0.5 - 1e-9]
    assert heard == [], [(e.onset_s, e.detected_at_s) for e in heard]


def test_the_stale_template_check_does_not_depend_on_the_block_size() -> None:
    x, _ = render(variant(JOINTS["P"], seed=72, stop_at=1.6, dur=2.2, rate=1080.0, drift=0.1))
    ref = [(e.onset_s, e.detected_at_s) for e in detect(x, _tuning("P"), block=1 << 16, confirm_s=0.5)]
    assert len(ref) == 1 and abs(ref[0][0] - 1.6) <= 0.025
    for block in (128, 777, 4096):
        assert [(e.onset_s, e.detected_at_s) for e in detect(x, _tuning("P"), block=block, confirm_s=0.5)] == ref
        det = detector_for(_tuning("P"))
        for i in range(0, x.size, block):
            det.feed(x[i : i + block])
        assert det.state is not None and any(s for *_, s in det.state.stale.log)  # the false fire, judged


@pytest.mark.xfail(
    strict=True,
    reason="measured on the under-talk bench (round 7b): formant babble over the whole warm-up with its third "
    "formant in joint Q's stop sub-band (3.0-3.75 kHz) lifts that sub-band's continuum by 12 spreads and the low ones "
    "by 3-6: b 0.74, 0.37 of the gain-only residual left, inside the start rule (b >= 0.7, <= 0.4); confirmation "
    "drops the fire (no confirmed event before the stop on the bench)",
)
def test_babble_over_the_whole_warm_up_in_joint_qs_stop_band_does_not_fire_at_once() -> None:
    x, sr = render(Scene("Q", 1000.0, 2.0, 3.0, seed=1))
    tu = tune(x, sr, 2.0, seed=0)
    y, _ = render(Scene("Q", 1080.0, 20.0, 22.5, seed=300, speech="babble"))  # the bench's recording
    assert _at_once(detect(y[:SR], tu)) == []
