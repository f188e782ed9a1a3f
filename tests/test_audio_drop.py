"""The drop channel's statistics, a tuning's drop_threshold, and a tuning at another sample rate."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.audio.change.drops import DropMeter, DropParams
from stickslip.audio.detector import Tuning, TuningFileError

DROP_FRAMES = DropParams().frames


def test_the_average_follows_a_step_after_drop_frames() -> None:
    z = np.zeros((30, 5))
    z[10:] = -2.0  # every sub-band drops by 2 spreads at frame 10
    m = DropMeter(5)(z)
    np.testing.assert_allclose(m[:10], 0.0)
    # frame 10 + k averages k + 1 dropped frames of DROP_FRAMES
    for k in range(DROP_FRAMES):
        np.testing.assert_allclose(m[10 + k], -2.0 * (k + 1) / DROP_FRAMES)
    np.testing.assert_allclose(m[10 + DROP_FRAMES :], -2.0)


def test_broad_and_local_drops_by_hand() -> None:
    m = np.array(
        [
            [-2.0, -2.0, -2.0, -2.0, -2.0],  # quieter: median -2, RMS of negatives 2
            [0.0, 0.0, -5.0, 0.0, 0.0],  # one sub-band gone: median 0, RMS sqrt(25/5)
            [3.0, 3.0, 3.0, -1.0, 3.0],  # louder in four: no broad drop, local sqrt(1/5)
        ]
    )
    broad, local = DropMeter.drops(m)
    np.testing.assert_allclose(broad, [2.0, 0.0, 0.0])
    np.testing.assert_allclose(local, [2.0, np.sqrt(5.0), np.sqrt(0.2)])
    # an even number of sub-bands: the median is the mean of the middle two
    broad4, _ = DropMeter.drops(np.array([[-4.0, -2.0, 0.0, 1.0]]))
    np.testing.assert_allclose(broad4, [1.0])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 13), min_size=1, max_size=12), st.integers(0, 2**31 - 1))
def test_the_average_does_not_depend_on_how_frames_are_cut(cuts: list[int], seed: int) -> None:
    z = np.random.default_rng(seed).normal(size=(60, 7))
    whole = DropMeter(7)(z)
    meter, parts, i, k = DropMeter(7), [], 0, 0
    while i < z.shape[0]:
        n = cuts[k % len(cuts)]
        parts.append(meter(z[i : i + n]))
        i, k = i + n, k + 1
    np.testing.assert_allclose(np.concatenate(parts), whole, atol=1e-12)


def _template_tuning(**kw: object) -> Tuning:
    edges = (1000.0, 2000.0, 4000.0, 8000.0, 12000.0)
    base: dict[str, object] = dict(
        band_hz=(edges[0], edges[-1]),
        threshold_db=0.5,
        method="template",
        edges_hz=edges,
        signature_db=(-3.0, 12.0, -2.0, -1.0),
        spread_db=(1.0, 1.0, 1.0, 1.0),
        stepping_levels_db=(-40.0, -42.0, -45.0, -50.0),
        trim=1,
        drop_threshold=(0.6, 1.5),
    )
    base.update(kw)
    return Tuning(**base)  # type: ignore[arg-type]  # test helper: fields by name


def test_drop_threshold_round_trips_and_is_checked() -> None:
    t = _template_tuning()
    assert Tuning.from_dict(t.to_dict()).drop_threshold == (0.6, 1.5)
    d = t.to_dict()
    d.pop("drop_threshold")  # a version-2 file from before the drop channel: no drop channel
    assert Tuning.from_dict(d).drop_threshold is None
    for bad in ([0.6], [0.0, 1.0], [1.0, float("nan")], [1.0, 500.0]):
        with pytest.raises(TuningFileError, match="drop_threshold"):
            Tuning.from_dict({**t.to_dict(), "drop_threshold": bad})


@pytest.mark.parametrize(
    "field, bad, match",
    [
        ("signature_db", [-3.0, 1e30, -2.0, -1.0], "signature_db must be within -400..400 dB"),
        ("signature_db", [-3.0, "12", -2.0, -1.0], r"signature_db\[1\] must be a finite number, got '12'"),
        ("spread_db", [1.0, 1e-300, 1.0, 1.0], "spread_db must be within 0.001..400 dB"),
        ("spread_db", [1.0, None, 1.0, 1.0], r"spread_db\[1\] must be a finite number, got None"),
        ("stepping_levels_db", [-40.0, -1e30, -45.0, -50.0], "stepping_levels_db must hold 4 levels within"),
        ("edges_hz", [1000.0, 2000.0, float("inf"), 8000.0, 12000.0], r"edges_hz\[2\] must be a finite number"),
    ],
)
def test_a_template_tuning_with_impossible_values_is_refused_naming_them(field: str, bad: object, match: str) -> None:
    with pytest.raises(TuningFileError, match=match):
        Tuning.from_dict({**_template_tuning().to_dict(), field: bad})


def test_a_48k_tuning_at_22k_keeps_the_sub_bands_that_fit() -> None:
    t = _template_tuning().for_sample_rate(22_050)  # 0.45 * 22050 = 9922 Hz: the 8-12 kHz sub-band goes
    assert t.edges_hz == (1000.0, 2000.0, 4000.0, 8000.0)
    assert t.signature_db == (-3.0, 12.0, -2.0) and t.spread_db == (1.0, 1.0, 1.0)
    assert t.stepping_levels_db == (-40.0, -42.0, -45.0) and t.band_hz == (1000.0, 8000.0)
    assert t.sample_rate == 22_050 and t.frame == 256 and t.hop == 64


def test_a_tuning_whose_stop_is_heard_above_the_new_nyquist_is_refused() -> None:
    t = _template_tuning(signature_db=(0.5, 0.5, 1.0, 15.0))
    with pytest.raises(ValueError, match="mostly above 9922 Hz"):
        t.for_sample_rate(22_050)


def test_the_step_rate_check_needs_the_tuning_s_rate_and_allows_five_per_cent() -> None:
    assert _template_tuning().step_rate_problem(1500.0) is None  # a file from before the rate was recorded
    t = replace(_template_tuning(), step_rate_hz=1000.0)
    assert t.step_rate_problem(1050.0) is None and t.step_rate_problem(950.0) is None
    assert t.step_rate_problem(float("nan")) is None  # no rate heard: nothing to compare
    why = t.step_rate_problem(1051.0)
    assert why is not None and "+5 % from the 1000 Hz" in why
    why = t.step_rate_problem(949.0)
    assert why is not None and "-5 % from the 1000 Hz" in why
