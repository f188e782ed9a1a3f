"""The streaming detector: level calibration, hold/hysteresis, streaming, Tuning files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.audio.detector import (
    Tuning,
    TuningFileError,
    band_levels_db,
    detect,
    detector_for,
)

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
BAND = (5000.0, 7000.0)


def tone(duration_s: float, amp: float, f_hz: float = 6000.0) -> np.ndarray:
    t = np.arange(int(round(duration_s * SR))) / SR
    return (amp * np.sin(2 * np.pi * f_hz * t)).astype(np.float32)


def test_sine_level_is_its_mean_square():
    """A sine of amplitude A inside the band reads 10 log10(A^2/2) dBFS (Parseval), +-0.05 dB."""
    levels = band_levels_db(tone(0.2, 0.1), SR, 512, 128, BAND)
    assert np.allclose(levels, 10 * np.log10(0.1**2 / 2), atol=0.05)


def test_white_noise_band_level_is_its_share_of_the_variance():
    """White noise of variance s^2: a band of width W reads s^2 * W / (SR/2), +-0.3 dB."""
    x = np.random.default_rng(0).normal(0, 0.01, SR * 4)
    levels = band_levels_db(x, SR, 512, 128, BAND)
    expected = 10 * np.log10(1e-4 * (BAND[1] - BAND[0]) / (SR / 2))
    assert 10 * np.log10(np.mean(10 ** (levels / 10))) == pytest.approx(expected, abs=0.3)


def test_tone_outside_the_band_is_ignored():
    levels = band_levels_db(tone(0.2, 0.1, f_hz=2000.0), SR, 512, 128, BAND)
    assert levels.max() < 10 * np.log10(0.1**2 / 2) - 60


def _quiet_then(*segments: tuple[float, float]) -> np.ndarray:
    """Concatenate (duration_s, amplitude) tone segments (amplitude 0 = silence)."""
    return np.concatenate([tone(d, a) for d, a in segments])


TUNING = Tuning(band_hz=BAND, threshold_db=-40.0, hold_s=0.016, release_s=0.25)


def test_short_burst_does_not_fire_long_one_fires_once():
    short = _quiet_then((0.5, 0.0), (0.004, 0.1), (0.5, 0.0))  # a knock-like 4 ms burst
    assert detect(short, TUNING) == []
    long = _quiet_then((0.5, 0.0), (0.4, 0.1), (0.3, 0.0))
    (ev,) = detect(long, TUNING)
    # fires after the hold: the frame that completes 6 above-threshold frames
    assert 0.5 + 0.016 <= ev.detected_at_s <= 0.5 + 0.016 + 512 / SR
    assert ev.level_db == pytest.approx(10 * np.log10(0.1**2 / 2), abs=0.1)


def test_one_stop_fires_once_through_dropouts_and_rearms_after_release():
    """Gaps shorter than release_s keep the event latched; a second stop after a long
    quiet fires again."""
    x = _quiet_then(
        (0.3, 0.0),
        (0.2, 0.1),
        (0.05, 0.0),
        (0.2, 0.1),
        (0.1, 0.0),
        (0.2, 0.1),  # one stop
        (0.6, 0.0),
        (0.2, 0.1),
        (0.2, 0.0),  # a second one
    )
    events = detect(x, TUNING)
    assert len(events) == 2
    assert events[0].detected_at_s == pytest.approx(0.3 + 0.02, abs=0.012)
    assert events[1].detected_at_s == pytest.approx(1.65 + 0.02, abs=0.012)


def test_onset_interpolates_the_crossing():
    """A step from silence to a loud tone at t=0.5 s: onset (with onset_lag_s=0) is the
    threshold crossing, a few ms after 0.5 s, never before it."""
    x = _quiet_then((0.5, 0.0), (0.3, 0.1))
    (ev,) = detect(x, Tuning(band_hz=BAND, threshold_db=-40.0, onset_lag_s=0.0))
    assert 0.5 <= ev.onset_s <= 0.5 + 512 / SR
    lagged = detect(x, Tuning(band_hz=BAND, threshold_db=-40.0, onset_lag_s=0.004))[0]
    assert lagged.onset_s == pytest.approx(ev.onset_s - 0.004, abs=1e-12)


def test_stream_time_offset():
    x = _quiet_then((0.5, 0.0), (0.3, 0.1))
    a = detect(x, TUNING)[0]
    b = detect(x, TUNING, t0_s=100.0)[0]
    assert b.detected_at_s == pytest.approx(a.detected_at_s + 100.0, abs=1e-9)
    assert b.onset_s == pytest.approx(a.onset_s + 100.0, abs=1e-9)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(1, 3000), min_size=1, max_size=40))
def test_block_sizes_do_not_change_the_events(sizes):
    x = _quiet_then((0.3, 0.0), (0.2, 0.1), (0.4, 0.0), (0.2, 0.1), (0.1, 0.0))
    reference = detect(x, TUNING, block=x.size)
    det, events, i, k = detector_for(TUNING), [], 0, 0
    while i < x.size:
        n = sizes[k % len(sizes)]
        events += det.feed(x[i : i + n])
        i, k = i + n, k + 1
    assert events == reference and len(reference) == 2


def test_reset_forgets_state():
    x = _quiet_then((0.3, 0.0), (0.3, 0.1))
    det = detector_for(TUNING)
    assert len(det.feed(x)) == 1 and det.latched
    det.reset(10.0)
    assert not det.latched
    (ev,) = det.feed(x)
    assert ev.detected_at_s > 10.3


def test_latency_estimate_without_measurement():
    """Untuned: onset lag + hold (6 hops of 128 samples at 48 kHz = 16 ms)."""
    t = Tuning(band_hz=BAND, threshold_db=-40.0, onset_lag_s=0.003)
    assert t.hold_frames == 6
    assert detector_for(t).latency_s == pytest.approx(0.003 + 6 * 128 / SR)


def test_tuning_round_trip(tmp_path):
    t = Tuning(
        band_hz=BAND,
        threshold_db=-41.5,
        joint=2,
        contrast_db=20.0,
        margin_db=10.0,
        stepping_db=-51.5,
        stopped_db=-31.5,
        latency_measured_s=0.019,
    )
    d = t.to_dict()
    assert d["band_hz"] == [5000.0, 7000.0] and d["threshold_db"] == -41.5
    assert {"frame", "hop", "sample_rate", "hold_s", "latency_s"} <= set(d)
    assert Tuning.from_dict(json.loads(json.dumps(d))) == t
    assert Tuning.load(t.save(tmp_path / "t.json")) == t


@pytest.mark.parametrize(
    "d, match",
    [
        ({"threshold_db": -40}, "band_hz"),
        ({"band_hz": [5000, 7000]}, "threshold_db"),
        ({"band_hz": 5000, "threshold_db": -40}, r"\[low_Hz, high_Hz\]"),
        ({"band_hz": [5000, 30000], "threshold_db": -40}, "24000"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "frame": 500}, "power of two"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "hop": 1.5}, "integer"),
        ({"band_hz": [5000, 7000], "threshold_db": "loud"}, "threshold_db must be a finite number, got 'loud'"),
        ({"band_hz": [5000, 7000], "threshold_db": "-40"}, "threshold_db must be a finite number"),
        ({"band_hz": [5000, True], "threshold_db": -40}, r"band_hz\[1\] must be a finite number"),
        (
            {"band_hz": [5000, 7000], "threshold_db": -40, "latency_measured_s": "x"},
            "latency_measured_s must be a finite number",
        ),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "latency_measured_s": 1e30}, r"within 0\.\.1"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "latency_measured_s": -0.02}, r"within 0\.\.1"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "contrast_db": [3]}, "contrast_db must be a finite number"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "joint": 7}, "joint 7 must be 1, 2 or 3"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "joint": "x"}, "joint must be an integer"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "version": True}, "version True is not a version stickslip"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "version": 0}, r"version 0 is not a version stickslip writes "
         r"\(the whole numbers 1 or 2\): re-tune"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "version": "2"}, "version '2' is not a version stickslip"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "version": 2.5}, "version 2.5 is not a version stickslip"),
        ({"band_hz": [5000, 7000], "threshold_db": -40, "version": 3}, "version 3 is newer than this stickslip"),
        ({"kind": "calibration", "band_hz": [1, 2], "threshold_db": 0}, "not a stop-detector"),
        ([1, 2], "JSON object"),
    ],
)
def test_bad_tuning_dicts_say_why(d, match):
    with pytest.raises(TuningFileError, match=match):
        Tuning.from_dict(d)


def test_load_rejects_non_json(tmp_path):
    p = tmp_path / "t.json"
    p.write_text("not json")
    with pytest.raises(TuningFileError, match="not JSON"):
        Tuning.load(p)


def test_for_sample_rate_keeps_durations():
    t = Tuning(band_hz=BAND, threshold_db=-40.0).for_sample_rate(96_000)
    assert (t.frame, t.hop, t.sample_rate) == (1024, 256, 96_000)
    with pytest.raises(ValueError, match="band_hz"):
        Tuning(band_hz=(9000.0, 12000.0), threshold_db=-40.0).for_sample_rate(16_000)


def test_feed_rejects_stereo():
    with pytest.raises(ValueError, match="mono"):
        detector_for(TUNING).feed(np.zeros((100, 2)))


def test_plot_levels_draws_threshold_and_event():
    from figures import inside_figure  # tests/support

    from stickslip.audio.detector import plot_levels

    x = _quiet_then((0.3, 0.0), (0.3, 0.1))
    ax = plot_levels(x, TUNING, stop_at_s=0.3)
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert {"threshold", "detected", "true stop"} <= set(labels)
    assert ax.get_ylabel() == "band level (dBFS)"
    assert ax.get_title() == "end-stop detector: 1 stop detected"
    assert inside_figure(ax.xaxis.label) and inside_figure(ax.yaxis.label)  # "time (s)" was cut at the bottom


def test_plot_levels_of_a_template_tuning_labels_its_level_inside_the_figure():
    from figures import inside_figure  # tests/support

    from stickslip.audio.detector import plot_levels

    tuning, x = _template_case()
    ax = plot_levels(x[: tuning.sample_rate], tuning)
    assert ax.get_ylabel() == "stop-likeness\n(0 stepping, 1 the tuned stop)"
    lo, hi = tuning.band_hz
    assert ax.get_lines()[0].get_label() == f"stop-likeness over band {lo:.0f}-{hi:.0f} Hz"  # not "band ..." alone
    assert inside_figure(ax.yaxis.label)  # "band level ((stop-likeness: ...))" ran off both ends


_TEMPLATE: dict[str, object] = {}


def _template_case():
    """A template tuning (simulator, joint 1) and a test recording with two stops, 0.6 s apart."""
    if not _TEMPLATE:
        from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

        from stickslip.sim.sound import render_traverse_recording

        x, sr = render_traverse_recording(1, 1000.0, 1.0, 1.6, seed=31)
        t = tune(x, sr, 1.0, self_check=False)
        a, _ = render_traverse_recording(1, 1100.0, 0.6, 1.0, seed=32)
        b, _ = render_traverse_recording(1, 1100.0, 0.5, 0.9, seed=33)
        _TEMPLATE.update(tuning=t, x=np.concatenate((a, b)))
    return _TEMPLATE["tuning"], _TEMPLATE["x"]


@settings(max_examples=15, deadline=None)
@given(st.lists(st.integers(1, 5000), min_size=1, max_size=30))
def test_template_detector_events_do_not_depend_on_block_sizes(sizes):
    tuning, x = _template_case()
    reference = detect(x, tuning)
    det, events, i, k = detector_for(tuning), [], 0, 0
    while i < x.size:
        n = sizes[k % len(sizes)]
        events += det.feed(x[i : i + n])
        i, k = i + n, k + 1
    assert [e.detected_at_s for e in events] == [e.detected_at_s for e in reference]
    for e, r in zip(events, reference, strict=True):  # the same to float rounding (BLAS sums in another order)
        assert e.onset_s == pytest.approx(r.onset_s, abs=1e-9) and e.level_db == pytest.approx(r.level_db, abs=1e-9)
    assert [round(e.onset_s, 2) for e in reference] == [0.6, 1.5]  # re-armed in the stepping between the stops


@settings(max_examples=30, deadline=None)
@given(
    st.sampled_from(["zeros", "constant", "noise", "full-scale square", "huge", "nan"]),
    st.integers(100, 40_000),
)
def test_template_detector_never_crashes_and_never_fires_on_dead_input(kind, n):
    tuning, _ = _template_case()
    rng = np.random.default_rng(n)
    x = {
        "zeros": np.zeros(n),
        "constant": np.full(n, 0.3),
        "noise": 1e-4 * rng.standard_normal(n),
        "full-scale square": np.sign(np.sin(np.arange(n) / 7.0)),
        "huge": 1e30 * rng.standard_normal(n),
        "nan": np.where(rng.random(n) < 0.1, np.nan, 1e-3 * rng.standard_normal(n)),
    }[kind].astype(np.float32)
    events = detect(x, tuning)
    assert all(np.isfinite([e.onset_s, e.detected_at_s, e.level_db]).all() for e in events)
    if kind in ("zeros", "constant"):
        assert events == []
