"""The step clock as evidence at confirmation (stickslip.audio.features.stepclock, stickslip.audio.confirm).

Every sound a stepping joint makes is a train of clicks at the step rate, at the stop too;
interference is not synchronous with it. The generators here are the battery's
(tests/support/battery_sound.py: a clean clock, 20 us jitter) and the random arms'
(tests/support/modal_sound.py: 2 % period jitter), not the project's own simulator. The splice
that confirmation by persistence alone takes for a stop is built from another view of the
stop: sound added in the stop's own 5.2 kHz mode that is *not* in step with the clock
(noise through the mode, or a second click train at 730 Hz through it), over a run of
steps 3 dB weaker. Round 7 judges the change line by line over the whole stepping band:
a stop that raises some lines and lowers others no longer cancels, and a run of steps
3 dB weaker is the joint's own sound changing (every line falls 3 dB): the clock no longer
rejects that splice (persistence needs the weaker steps to confirm it at all).
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import modal_sound  # noqa: E402
import numpy as np
import pytest
from battery_sound import MODES, Scene, _bank, _impulses, _res, _train, render, variant  # noqa: E402
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from scipy.signal import butter, lfilter
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)  # noqa: E402

from stickslip.audio.confirm import ConfirmedStopDetector  # noqa: E402
from stickslip.audio.confirm.sync import SYNC, step_clock_verdict  # noqa: E402
from stickslip.audio.detector import StopEvent, Tuning, detector_for  # noqa: E402
from stickslip.audio.events import StopDetector  # noqa: E402
from stickslip.audio.features.stepclock import (  # noqa: E402
    LineChange,
    chi2_as_z,
    line_change,
    line_power,
    line_powers,
    line_z,
    periodogram,
    step_rate_hz,
    synchronous_change_db,
    widen_bands,
)

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
P = Scene("P", 1000.0, 2.0, 3.0, seed=1)
Q = Scene("Q", 1000.0, 2.0, 3.0, seed=2)
STEP_RMS = 10 ** (-28 / 20)  # battery_sound's stepping level


@lru_cache(maxsize=4)
def _tuning(joint: str) -> Tuning:
    x, sr = render(P if joint == "P" else Q)
    return tune(x, sr, 2.0, seed=0)


def _run(det: StopDetector | ConfirmedStopDetector, y: np.ndarray, block: int = 4096) -> list[StopEvent]:
    events = [e for i in range(0, y.size, block) for e in det.feed(y[i : i + block])]
    if isinstance(det, ConfirmedStopDetector):
        events += det.finish()
    return events


# --- the measures ----------------------------------------------------------------------------


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rate=st.floats(700.0, 1400.0), seed=st.integers(0, 10_000), joint=st.sampled_from(["P", "Q"]))
def test_the_step_rate_is_heard_on_the_battery_generator(rate: float, seed: int, joint: str) -> None:
    y, sr = render(Scene(joint, rate, None, 0.5, seed=seed))
    assert step_rate_hz(y, sr) == pytest.approx(rate, rel=0.005)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rate=st.floats(700.0, 1400.0), seed=st.integers(0, 10_000), arm=st.sampled_from([2, 3, 5]))
@example(rate=882.0, seed=1, arm=3)  # its line at the rate stands only 12-13.6 dB clear: HALF_LINE_DB must allow that
@example(rate=1115.0, seed=2000, arm=3)  # a fresh draw: its half 9.8 dB clear, heard at 2229.8 Hz until three halves
@example(rate=1192.0, seed=158, arm=3).xfail(
    raises=AssertionError,
    reason="a fresh draw (session 29): the envelope has no line at the rate (-2.2 dB against the continuum; at half "
    "the rate -1.5 dB), only at two and three times it (11.2, 12.9 dB): heard at 2390 Hz. No rule that hears a missing "
    "fundamental would leave sub-harmonics alone; a traverse knows its commanded rate (listen warns beyond 5 %)",
)
def test_the_step_rate_is_heard_through_a_rough_clock(rate: float, seed: int, arm: int) -> None:
    """The fourth generator's clock jitters by 2 % of every period (a random walk): the rate is still its mean."""
    y = modal_sound.render(modal_sound.Scene(arm, "louder", stop_at=None, dur=0.5, rate=rate, seed=seed))
    assert step_rate_hz(y, SR) == pytest.approx(rate, rel=0.015)


@pytest.mark.parametrize("sr", [22_050, 44_100])
def test_the_step_rate_at_other_sample_rates_and_8_bits(sr: int) -> None:
    y, got_sr = render(Scene("P", 1080.0, None, 0.5, seed=3, sr=sr, bits=8))
    assert got_sr == sr and step_rate_hz(y, sr) == pytest.approx(1080.0, rel=0.005)


def test_no_rate_in_silence_or_too_short_a_stretch() -> None:
    assert math.isnan(step_rate_hz(np.zeros(SR), SR))
    assert math.isnan(step_rate_hz(np.ones(100), SR))


def test_a_sine_on_a_harmonic_is_counted_at_its_power_and_one_between_them_not() -> None:
    """Analytic: a sine of amplitude A on a line carries A^2 / 2; half-way between two lines, nothing."""
    t = np.arange(int(0.48 * SR)) / SR
    bands = [(4000.0, 7000.0)]
    on, _, whole = line_power(0.1 * np.sin(2 * np.pi * 5400.0 * t), SR, 1080.0, bands)
    off, _, whole_off = line_power(0.1 * np.sin(2 * np.pi * 5940.0 * t), SR, 1080.0, bands)
    assert on == pytest.approx(0.1**2 / 2, rel=0.02) and whole == pytest.approx(0.1**2 / 2, rel=0.02)
    assert abs(off) < 1e-3 * on and whole_off == pytest.approx(0.1**2 / 2, rel=0.02)


def test_noise_adds_no_line_power_on_average() -> None:
    """Noise through the stop's mode: the line power's mean is 0 and its stated spread is not too small."""
    rng = np.random.default_rng(7)
    n = int(0.48 * SR)
    bands = widen_bands([(4762.0, 6000.0)], 1080.0, SR)
    z = []
    for _ in range(60):
        x = _res(rng.standard_normal(n), 5200, 150, SR)
        p, sd, _ = line_power(x, SR, 1080.0, bands)
        z.append(p / sd)
    assert abs(float(np.mean(z))) < 0.5 and float(np.std(z)) < 1.5


def test_a_louder_stop_raises_the_synchronous_power_and_a_quieter_one_lowers_it() -> None:
    n = int(0.48 * SR)
    for kind, sign in (("louder", 1), ("quieter", -1)):
        y, _ = render(variant(P, seed=5, stop_at=1.0, dur=2.0, rate=1080.0, stop_kind=kind))
        got = synchronous_change_db(y[SR - n - 3000 : SR - 3000], y[SR + 1000 : SR + 1000 + n], SR, [(4762.0, 6000.0)])
        assert got.rate_hz == pytest.approx(1080.0, rel=0.002)
        assert got.share_before >= SYNC.min_share and got.sharpness_before >= SYNC.min_sharpness
        assert sign * got.change_db >= 3.0 and sign * got.change_z >= 10.0, (kind, got)


def test_chi2_as_z_against_scipy() -> None:
    """Wilson-Hilferty: within 0.11 of scipy's exact deviate out to 4 standard deviations, below it beyond."""
    from scipy import stats

    for dof in (3, 5, 9, 15, 30):
        for z in (-2.0, 0.0, 2.0, 4.0):
            assert chi2_as_z(float(stats.chi2.isf(stats.norm.sf(z), dof)), dof) == pytest.approx(z, abs=0.11)
        for z in (5.0, 6.0):
            got = chi2_as_z(float(stats.chi2.isf(stats.norm.sf(z), dof)), dof)
            assert z - 0.36 <= got <= z
    assert math.isnan(chi2_as_z(3.0, 0)) and math.isnan(chi2_as_z(math.inf, 4))


def test_the_per_line_changes_of_sines_in_noise_have_unit_spread() -> None:
    """Independent of any generator: ten sines on the harmonics of a rate, white noise drawn afresh on each side.

    The per-line changes, each in its stated standard deviation (:func:`line_z`), scatter with a mean of 0 and a
    standard deviation of 1 (382 lines): the variance, noise alone plus the line's own scatter under it, is right.
    """
    rng = np.random.default_rng(1)
    t = np.arange(int(0.48 * SR)) / SR
    zs: list[float] = []
    for k in range(40):
        rate = 1000.0 + 7 * k
        sig = sum(0.01 * np.sin(2 * np.pi * h * rate * t + h) for h in range(2, 12))
        a, b = (sig + 0.01 * rng.standard_normal(t.size) for _ in range(2))
        bands = [(1500.0, 12500.0)]
        zs += list(line_z(line_powers(a, SR, rate, bands)[0], line_powers(b, SR, rate, bands)[0]))
    assert len(zs) >= 380  # the last harmonic falls off the band's top for the higher rates
    assert abs(float(np.mean(zs))) < 0.15 and 0.85 < float(np.std(zs)) < 1.15


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    rate=st.floats(700.0, 1400.0),
    seed=st.integers(0, 10_000),
    joint=st.sampled_from(["P", "Q"]),
    snr_db=st.sampled_from([None, 20.0, 10.0]),
)
def test_steady_stepping_never_changes_the_lines(rate: float, seed: int, joint: str, snr_db: float | None) -> None:
    """Two stretches of the same stepping, 0.8 s apart: never a verdict of "changed" (the null of the statistic)."""
    y, _ = render(Scene(joint, rate, None, 2.2, seed=seed, snr_db=snr_db))
    n = int(0.48 * SR)
    got = line_change(y[SR // 2 : SR // 2 + n], y[int(1.3 * SR) : int(1.3 * SR) + n], SR, [(600.0, 0.45 * SR)])
    # the rate, or in noise a harmonic of it (twice, or three times: joint Q at 715 Hz and 10 dB SNR, found on CI's
    # fresh draws); the check's null is what this test is about
    assert min(abs(got.rate_hz / (k * rate) - 1) for k in (1, 2, 3)) < 0.005, got
    assert step_clock_verdict(got) is not True, got


def _comb(kind: str, rate: float, seed: int, t: float) -> LineChange:
    """The line change of joint Q's recording with a ``kind`` stop at 2.0 s: 0.24 s from ``t`` against the 0.48 s of
    stepping that end 0.06 s before it."""
    y, _ = render(variant(Q, seed=seed, stop_at=2.0, dur=2.6, rate=rate, stop_kind=kind))
    n, g, m = int(0.48 * SR), int(0.06 * SR), int(0.24 * SR)
    i = int(t * SR)
    got = line_change(y[i - g - n : i - g], y[i : i + m], SR, [(600.0, 0.42 * SR)])
    assert got.rate_hz == pytest.approx(rate, rel=0.005)
    return got


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    kind=st.sampled_from(["brighter", "louder", "duller", "quieter"]),
    rate=st.floats(800.0, 1300.0),
    seed=st.integers(0, 10_000),
)
@example(kind="brighter", rate=1000.0, seed=516)  # the rate heard at half: a chance line at 500 Hz (CI's fresh draw)
def test_the_comb_sees_a_stop_in_any_direction(kind: str, rate: float, seed: int) -> None:
    """The stops of the battery's cross conditions (joint Q), which the level template misses when it was tuned on
    another kind: 0.24 s of the stop against the 0.48 s of stepping before it changes the lines by a deviate of 8 or
    more, a verdict of "changed" (docs/audio-log.md, "A synchronous departure as a source of fires")."""
    got = _comb(kind, rate, seed, 2.0)
    assert got.change_z >= 8.0 and step_clock_verdict(got) is True, got


def test_stepping_before_the_stop_is_rarely_called_changed() -> None:
    """The null of the same check: 0.24 s of stepping 0.3 s before the stop, against the stepping before it.

    It is a statistic, and it errs by chance: fresh draws of the property above (which asked it of every draw until
    session 26) found joint Q's stepping at 1165 Hz (seed 748) called "changed" (deviate 4.85, a line 2.6 dB), and at
    1052 Hz (seed 391) a deviate of 4.18 that only the rule's second half (a line moved SYNC.min_change_db) kept out.
    Over 80 fixed draws (800-1300 Hz, the four kinds of stop) none is called "changed"; both draws are kept as found.
    """
    rng = np.random.default_rng(26)
    changed = []
    for k in range(80):
        kind = ("brighter", "louder", "duller", "quieter")[k % 4]
        rate, seed = float(rng.uniform(800, 1300)), int(rng.integers(10_000))
        got = _comb(kind, rate, seed, 1.7)
        if step_clock_verdict(got) is True:
            changed.append((kind, rate, seed, got))
    assert changed == [], changed
    near = _comb("brighter", 1051.9453125, 391, 1.7)
    assert near.change_z >= SYNC.min_z and abs(near.change_db) < SYNC.min_change_db
    assert step_clock_verdict(near) is not True
    chance = _comb("brighter", 1165.375, 748, 1.7)
    assert chance.change_z == pytest.approx(4.85, abs=0.01) and step_clock_verdict(chance) is True


# --- confirmation ----------------------------------------------------------------------------


def _splice(
    kind: str, dur: float, level_db: float, seed: int = 21, rate: float = 1080.0, weaker: float = 0.3
) -> np.ndarray:
    """Stepping; from 1.5 s, for ``dur``, unsynchronised sound in the stop's mode over weaker steps; 1.5 s more.

    ``weaker``: the steps' amplitude falls by this share in the splice (0.3: 3 dB).
    """
    y, _ = render(variant(P, seed=seed, stop_at=None, dur=dur + 3.0, rate=rate))
    y = y.astype(np.float64)
    rng = np.random.default_rng(seed + 1)
    i0, n = int(1.5 * SR), int(dur * SR)
    if kind == "noise":
        z = _res(rng.standard_normal(n), 5200, 150, SR)
    else:  # a second instrument at 730 Hz ringing the stop's own mode
        t, a = _impulses(n, SR, 730.0, rng)
        z = _bank(_train(n, SR, t, a), (MODES["P"][1],), SR)
    z = z / np.std(z) * STEP_RMS * 10 ** (level_db / 20)
    ramp = np.minimum(1.0, np.minimum(np.arange(n), n - np.arange(n)) / (0.005 * SR))
    y[i0 : i0 + n] *= 1 - weaker * ramp
    y[i0 : i0 + n] += z * ramp
    return y.astype(np.float32)


@pytest.mark.parametrize(("kind", "dur"), [("noise", 1.0), ("noise", 3.0), ("train730", 2.0)])
@pytest.mark.parametrize("level_db", [-6.0, 0.0, 6.0])
def test_unsynchronised_sound_over_steady_steps_is_not_a_stop(kind: str, dur: float, level_db: float) -> None:
    """Sound in the stop's band, not in step with the clock, over steps that stay as they were: no event.

    Persistence alone passes it by too; the step clock's lines do not move (a fire that persisted would be judged
    unchanged), and the sound never becomes a stop with the clock on.
    """
    y = _splice(kind, dur, level_db, weaker=0.0)
    assert _run(ConfirmedStopDetector(detector_for(_tuning("P"))), y) == []
    det = ConfirmedStopDetector(detector_for(_tuning("P")), step_clock=True)
    assert _run(det, y) == []
    n = int(0.48 * SR)
    i0 = int(1.5 * SR)
    for off in (0.1, 0.4 * dur):  # the lines before the splice against those inside it
        got = line_change(
            y[i0 - n - 3000 : i0 - 3000], y[i0 + int(off * SR) : i0 + int(off * SR) + n], SR, det.sync_bands
        )
        assert got.rate_hz == pytest.approx(1080.0, rel=0.005)
        assert step_clock_verdict(got) is False, got


@pytest.mark.parametrize(("kind", "dur"), [("noise", 1.0), ("train730", 2.0)])
def test_a_run_of_weaker_steps_is_the_joints_own_sound_changing(kind: str, dur: float) -> None:
    """The same sound over steps 3 dB weaker: persistence confirms it (main's round 6 rejected it on the stop's
    sub-bands); every line of the clock falls about 3 dB, a change of the joint's own sound the step clock cannot
    tell from a quieter stop, and it says so by confirming it."""
    y = _splice(kind, dur, 0.0)
    (plain,) = _run(ConfirmedStopDetector(detector_for(_tuning("P"))), y)
    det = ConfirmedStopDetector(detector_for(_tuning("P")), step_clock=True)
    (ev,) = _run(det, y)
    assert ev.onset_s == plain.onset_s == pytest.approx(1.5, abs=0.06)
    (_, got), *_ = det.log.step_clock
    assert step_clock_verdict(got) is True and got.change_z >= 10.0
    assert -8.0 <= got.change_db <= -2.0  # lines 3 dB down; a weak one more or less, within its noise


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(block=st.integers(128, 65536))
def test_the_step_clocks_verdict_does_not_depend_on_the_block_size(block: int) -> None:
    y = _handover_with_stop()
    det = ConfirmedStopDetector(detector_for(_tuning("P")), step_clock=True)
    ref = ConfirmedStopDetector(detector_for(_tuning("P")), step_clock=True)
    got, want = _run(det, y, block), _run(ref, y, 4096)
    assert [(e.onset_s, e.detected_at_s, e.confirmed_at_s) for e in got] == [
        (e.onset_s, e.detected_at_s, e.confirmed_at_s) for e in want
    ]
    # the handover's fires, each persisting and each rejected by the clock (the template, frozen in every window,
    # does not get over the handover), then the stop, heard on un-latching inside the last window: uncertain
    assert len(got) == 1 and got[0].onset_uncertain and 10.0 < got[0].onset_s < 12.0
    assert [t for t, _ in det.log.step_clock] == [t for t, _ in ref.log.step_clock]
    assert [step_clock_verdict(g) for _, g in det.log.step_clock] == [False] * 5 + [True]
    flat = [x for _, g in det.log.step_clock for x in g]
    assert flat == pytest.approx([x for _, g in ref.log.step_clock for x in g], abs=1e-6)


def _handover(broad_db: float, mode_db: float, t1: float = 3.0, dur: float = 1.5, total: float = 6.0) -> np.ndarray:
    """Steady stepping; broadband noise (0.9-12 kHz) until ``t1``, then noise through the stop's 5.2 kHz mode.

    Another view of a false stop than the weaker steps': a sound that fills the whole band ends as one in the stop's
    own band begins. The template and the floor learned the band with the first in it, so the bands it leaves look
    lowered and the stop's band raised: the tuned stop's shape, without the steps changing at all.
    """
    y, _ = render(variant(P, seed=21, stop_at=None, dur=total, rate=1080.0))
    y = y.astype(np.float64)
    rng = np.random.default_rng(23)
    n1, n2 = int(t1 * SR), int(dur * SR)
    b, a = butter(2, [900 / (SR / 2), 12000 / (SR / 2)], "band")
    broad = lfilter(b, a, rng.standard_normal(n1))
    y[:n1] += broad * STEP_RMS * 10 ** (broad_db / 20) / np.std(broad)
    z = _res(rng.standard_normal(n2), 5200, 150, SR)
    y[n1 : n1 + n2] += z * STEP_RMS * 10 ** (mode_db / 20) / np.std(z)
    return y.astype(np.float32)


@pytest.mark.parametrize(("broad_db", "mode_db"), [(-6.0, -3.0), (-6.0, 0.0), (0.0, -3.0), (0.0, 0.0), (0.0, 6.0)])
def test_a_handover_of_unsynchronised_sounds_is_not_a_stop(broad_db: float, mode_db: float) -> None:
    """Persistence confirms the handover (a false stop at 3.0 s); the clock's lines did not move: it rejects it.

    Fails on main in all five: round 6 judged only the stop's sub-bands, where the lines held 1-4 % of the power
    (under the 5 % it asks), so it gave no verdict and the handover stood on persistence.
    """
    y = _handover(broad_db, mode_db)
    (plain,) = _run(ConfirmedStopDetector(detector_for(_tuning("P"))), y)
    assert plain.onset_s == pytest.approx(3.0, abs=0.025)
    det = ConfirmedStopDetector(detector_for(_tuning("P")), step_clock=True)
    assert _run(det, y) == []
    assert det.log.step_clock
    for _, got in det.log.step_clock:
        assert got.rate_hz == pytest.approx(1080.0, rel=0.005)
        assert step_clock_verdict(got) is False and got.change_z < 0.0 and got.change_db == 0.0, got


@lru_cache(maxsize=1)
def _handover_with_stop() -> np.ndarray:
    """The handover at 0 / 0 dB (3.0-4.5 s), then the real stop at 10.0 s (the stop's sound of the same seed)."""
    y = _handover(0.0, 0.0, total=13.0).astype(np.float64)
    s, _ = render(variant(P, seed=21, stop_at=10.0, dur=13.0, rate=1080.0))
    y[int(10.0 * SR) :] = s[int(10.0 * SR) :]
    return y.astype(np.float32)


@settings(max_examples=16, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    joint=st.sampled_from(["P", "Q"]),
    rate=st.floats(700.0, 1400.0),
    seed=st.integers(0, 10_000),
    talk=st.sampled_from([None, "babble"]),
)
def test_a_true_stop_is_confirmed_with_the_step_clock_as_without(
    joint: str, rate: float, seed: int, talk: str | None
) -> None:
    """With the step clock on, a true stop of the battery's generator heard on time is confirmed as without it.

    On main (round 6's sum over the stop's sub-bands) joint Q's stop changed its comb by -0.05 dB at 1362.5 Hz
    and 0.27 dB at 1125 Hz, and joint P's by 1.0 dB at 1196 Hz: the fire rejected, and no event or an
    ``onset_uncertain`` one instead (:func:`test_a_stop_whose_rise_and_fall_cancel_on_the_comb`). A fire that
    comes late (joint P at 1387.5 Hz, seed 258: 0.56 s after the stop, which persistence confirms, a wrong count)
    has the stop in its reference as well as in its window: the clock sees no change and rejects it; anything
    the clock emits that persistence did not is flagged ``onset_uncertain``.
    """
    s = variant(P if joint == "P" else Q, seed=seed, stop_at=2.0, dur=3.0, rate=rate, speech=talk)
    y, _ = render(s)
    plain = _run(ConfirmedStopDetector(detector_for(_tuning(joint))), y)
    det = ConfirmedStopDetector(detector_for(_tuning(joint)), step_clock=True)
    events = _run(det, y)
    key = [(e.onset_s, e.detected_at_s, e.onset_uncertain) for e in events]
    on_time = [(e.onset_s, e.detected_at_s, e.onset_uncertain) for e in plain if abs(e.onset_s - 2.0) <= 0.025]
    assert all(k in key for k in on_time)
    before = {(e.onset_s, e.detected_at_s) for e in plain}
    assert all(e.onset_uncertain for e in events if (e.onset_s, e.detected_at_s) not in before)
    for t, got in det.log.step_clock:
        if abs(t - 2.0) < 0.06:  # the stop's own fire, on time
            assert step_clock_verdict(got) is not False, (t, got)


@pytest.mark.parametrize(("joint", "rate", "seed"), [("Q", 1362.5, 77), ("Q", 1125.0, 77), ("P", 1196.0, 5380)])
def test_a_stop_whose_rise_and_fall_cancel_on_the_comb(joint: str, rate: float, seed: int) -> None:
    """Round 6's blind spot (fails on main): summed, the lines hardly move; line by line they move both ways."""
    y, _ = render(variant(Q if joint == "Q" else P, seed=seed, stop_at=2.0, dur=3.0, rate=rate))
    plain = _run(ConfirmedStopDetector(detector_for(_tuning(joint))), y)
    det = ConfirmedStopDetector(detector_for(_tuning(joint)), step_clock=True)
    events = _run(det, y)
    assert [(e.onset_s, e.onset_uncertain) for e in events] == [(e.onset_s, e.onset_uncertain) for e in plain]
    assert len(events) == 1 and not events[0].onset_uncertain
    (_, got), *_ = det.log.step_clock
    assert step_clock_verdict(got) is True and got.change_z >= 6.0, got


def test_a_stop_heard_mainly_as_a_drop_is_judged_too() -> None:
    """The clock is judged over the whole stepping band: a quieter stop lowers every line (round 6 left it alone)."""
    x, sr = render(variant(P, stop_kind="quieter"))
    tu = tune(x, sr, 2.0, seed=0)
    det = ConfirmedStopDetector(detector_for(tu), step_clock=True)
    assert det.sync_bands == [(tu.edges_hz[0], tu.edges_hz[-1])]  # type: ignore[index]  # a template tuning
    assert ConfirmedStopDetector(detector_for(_tuning("P"))).sync_bands == []  # off by default
    y, _ = render(variant(P, seed=41, stop_at=1.6, dur=2.2, rate=1080.0, stop_kind="quieter"))
    (ev,) = _run(det, y)
    assert ev.onset_s == pytest.approx(1.6, abs=0.025)
    (_, got), *_ = det.log.step_clock
    assert step_clock_verdict(got) is True and -10.0 <= got.change_db <= -6.0  # the steps 8 dB quieter


def test_the_simulators_stop_is_seen_line_by_line() -> None:
    """The project's simulator rattles its stop 0-0.5 ms late at every step: off the clock's comb at kHz.

    Round 6's sum over the stop's sub-bands saw less than 2 standard deviations there and would have passed the
    stop by (why the clock is opt-in); over the whole band, line by line, the stepping's own lines change at the
    stop by many standard deviations, and the stop is confirmed with the clock on as without it.
    """
    from stickslip.sim.arm import SimulatedMM3A

    sim = SimulatedMM3A(seed=5, day="2026-11-22")
    x, rate, stop_at = sim.labelled_recording(3, "+", before_s=2.0, after_s=1.0)
    tu = tune(x, rate, stop_at, joint=3)
    y, _, stop2 = SimulatedMM3A(seed=105, day="2026-11-22").labelled_recording(3, "+", before_s=3.0, after_s=1.5)
    (ev,) = _run(ConfirmedStopDetector(detector_for(tu)), y)
    assert abs(ev.onset_s - stop2) <= 0.025
    det = ConfirmedStopDetector(detector_for(tu), step_clock=True)
    assert _run(det, y) == [ev]
    (_, got), *_ = det.log.step_clock
    assert got.sharpness_before >= SYNC.min_sharpness and got.share_before >= SYNC.min_share  # a clean clock, judged
    assert step_clock_verdict(got) is True and got.change_z >= 20.0
    # what round 6 measured: the sum over the stop's sub-bands, widened, moves by less than 2 standard deviations
    sig = np.asarray(tu.signature_db)
    e = tu.edges_hz
    assert e is not None
    bands = [(e[k], e[k + 1]) for k in np.flatnonzero(sig >= 0.5 * sig.max())]
    n = int(0.48 * rate)
    fire = int(ev.detected_at_s * rate)
    old = synchronous_change_db(y[fire - 2900 - n : fire - 2900], y[fire + 1 : fire + 1 + n], rate, bands)
    assert abs(old.change_z) < 2.5, old


def test_listen_step_clock_on_the_command_line(tmp_path: Path) -> None:
    """``listen --step-clock`` passes the handover by; without it the handover is reported as a stop."""
    import json

    from typer.testing import CliRunner

    from stickslip.audio.sources import write_wav
    from stickslip.cli import app

    runner = CliRunner()
    _tuning("P").save(tmp_path / "p.json")
    write_wav(tmp_path / "rec.wav", _handover(0.0, 0.0), SR)
    base = ["listen", str(tmp_path / "rec.wav"), "--tuning", str(tmp_path / "p.json"), "--json"]
    r = runner.invoke(app, base)
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)[0]["onset_s"] == pytest.approx(3.0, abs=0.05)  # persistence alone: the handover
    r = runner.invoke(app, [*base, "--step-clock"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout) == []
    r = runner.invoke(app, [*base, "--step-clock", "--confirm-s", "0"])
    assert r.exit_code == 2 and "--confirm-s > 0" in r.output


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**16), n=st.integers(0, 6000), width=st.sampled_from([1.0, 4.0]))
def test_lines_read_from_a_periodogram_are_those_read_from_the_samples(seed: int, n: int, width: float) -> None:
    # one spectrum read on several combs (the clocked check, the late path) gives each reading's values bit for bit
    rng = np.random.default_rng(seed)
    t = np.arange(n) / SR
    x = rng.standard_normal(n) + np.sign(np.sin(2 * np.pi * 1000.0 * t))
    bands = [(2000.0, 4000.0), (3500.0, 8000.0)]
    want, whole = line_powers(x, SR, 1000.0, bands, width)
    got, whole2 = line_powers(periodogram(x), SR, 1000.0, bands, width)
    assert len(got.power) == len(want.power)
    assert (len(want.power) > 0) == (n >= 20 * SR / 1000.0)  # lines from 20 step periods on
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a, b)
    assert whole2 == whole or (math.isnan(whole) and math.isnan(whole2))
