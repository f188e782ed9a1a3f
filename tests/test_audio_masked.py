"""The stop's signature fitted as it can show over sound added to the stepping (session 29).

The stop changes the stepping's own sound only. Where a second instrument, a fan or a
radio lifted the template above the stepping's level (the floor), the stop moves the
template's level by less than its tuned signature: ``10 log10(1 + w (g - 1))`` dB, with
``w`` the stepping's share of the template's power and ``g`` the stop's gain on it
(:func:`stickslip.audio.change.fit.masked_signature`). Fitted with the tuned signature, the
battery's joint P under a second instrument ringing where the stop's largest drop is was
heard 0.56 s late (by the late path alone); fitted masked, 21 ms after the stop.
"""

from __future__ import annotations

import modal_sound as ms  # noqa: E402
import numpy as np
import pytest
from battery_sound import Scene, render, variant  # noqa: E402
from hypothesis import given
from hypothesis import strategies as st
from scipy.signal import butter, sosfilt
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)  # noqa: E402

from stickslip.audio.change import ChangeParams  # noqa: E402
from stickslip.audio.change.fit import masked_signature  # noqa: E402
from stickslip.audio.change.template import TemplateParams  # noqa: E402
from stickslip.audio.confirm import CONFIRM_S, ConfirmedStopDetector  # noqa: E402
from stickslip.audio.detector import Tuning, detect, detector_for  # noqa: E402

pytestmark = pytest.mark.slow  # make test-fast leaves this file out


def test_nothing_added_leaves_the_signature_as_tuned() -> None:
    delta = np.array([-20.0, -5.1, -0.5, 0.0, 0.2, 15.0, 28.0])
    assert masked_signature(delta, np.zeros(delta.size)) == pytest.approx(delta, abs=1e-12)


def test_values_worked_by_hand() -> None:
    # a 15 dB rise under sound 8 dB over the stepping: w = 10**-0.8, g = 10**1.5
    w, g = 10**-0.8, 10**1.5
    assert masked_signature(np.array([15.0]), np.array([8.0]))[0] == pytest.approx(10 * np.log10(1 + w * (g - 1)))
    assert masked_signature(np.array([15.0]), np.array([8.0]))[0] == pytest.approx(7.674, abs=1e-3)
    # a 5 dB drop under sound 6 dB over it: 1 + 10**-0.6 (10**-0.5 - 1) = 0.8284
    assert masked_signature(np.array([-5.0]), np.array([6.0]))[0] == pytest.approx(-0.8177, abs=1e-3)
    # added sound equal to the stepping (3.01 dB): a doubling of the stepping shows as 10 log10(1.5)
    assert masked_signature(np.array([10 * np.log10(2.0)]), np.array([10 * np.log10(2.0)]))[0] == pytest.approx(
        10 * np.log10(1.5)
    )


def test_the_power_sum_it_stands_for() -> None:
    """The formula is the level change of stepping S (times g) plus added sound B, in linear power."""
    rng = np.random.default_rng(3)
    S, B, g = rng.uniform(0.1, 10, 50), rng.uniform(0.0, 100, 50), rng.uniform(0.01, 100, 50)
    shown = masked_signature(10 * np.log10(g), 10 * np.log10((S + B) / S))
    assert shown == pytest.approx(10 * np.log10((g * S + B) / (S + B)), abs=1e-9)


@given(
    delta=st.floats(-40.0, 40.0),
    added=st.floats(0.0, 60.0),
    more=st.floats(0.0, 30.0),
)
def test_added_sound_only_shrinks_the_change_towards_zero(delta: float, added: float, more: float) -> None:
    shown = masked_signature(np.array([delta]), np.array([added]))[0]
    further = masked_signature(np.array([delta]), np.array([added + more]))[0]
    assert np.isfinite(shown) and np.isfinite(further)
    assert abs(shown) <= abs(delta) + 1e-9  # never larger than the tuned change
    assert shown * delta >= -1e-12  # never the other way
    assert abs(further) <= abs(shown) + 1e-9  # the more added, the less it shows


def _second_instrument() -> tuple[Tuning, np.ndarray, int]:
    P = Scene("P", 1000.0, 2.0, 3.0, seed=1)
    x, sr = render(P)
    tu = tune(x, sr, 2.0, seed=0)
    y, sr_t = render(variant(P, seed=30, stop_at=1.6, dur=2.2, rate=1080.0, second_rate=730.0, second_from=0.8))
    return tu, y, sr_t


def test_the_template_knows_what_the_second_instrument_added() -> None:
    """Joint P of the battery: the instrument from 0.8 s rings at 2.6, 5.4 and 8.8 kHz.

    Its 2.6 kHz mode lifts the 1.9-2.4 and 2.4-3 kHz sub-bands 3.6 and 8.9 dB over the
    stepping, and the first of them is where the stop's largest drop is (-5.1 dB tuned,
    -8.6 dB predicted at the 1080 Hz heard): under the instrument it can show as about -2 dB
    only, and fitted as tuned it argued against the stop. Its 5.4 kHz mode lifts the stop's
    own 4.8-6 kHz sub-band 4.2 dB, under 2 of this stream's spreads there (2.2 dB): no mask.
    """
    tu, y, _ = _second_instrument()
    det = detector_for(tu)
    st_ = det.state
    assert st_ is not None
    det.feed(y[: int(0.75 * 48_000)])
    assert st_.tpl.added_db is None  # stepping alone so far
    det.feed(y[int(0.75 * 48_000) : int(1.58 * 48_000)])
    assert st_.tpl.added_db is not None
    lifted = np.flatnonzero(st_.tpl.added_db > 0)
    assert {4, 5} <= set(lifted.tolist())  # 1.9-2.4 and 2.4-3 kHz
    assert st_.tpl.added_db[5] > 6.0 and st_.tpl.added_db[4] > 3.0
    biggest_drop = int(np.argmin(st_.delta))
    assert biggest_drop == 4 and st_.delta[4] == pytest.approx(-5.1, abs=0.5)
    assert st_.fits.pred_delta is not None  # the rate heard (1080 Hz) is 8 % off the tuning's: predicted too
    shown = masked_signature(st_.fits.pred_delta, st_.tpl.added_db)
    assert st_.fits.pred_delta[4] < -7.0 and -3.0 < shown[4] < -1.0
    untouched = st_.tpl.added_db == 0
    assert shown[untouched] == pytest.approx(st_.fits.pred_delta[untouched])


def test_a_stop_under_an_instrument_begun_0_8_s_before_it_is_heard_on_time() -> None:
    tu, y, _ = _second_instrument()
    events = detect(y, tu, block=1024, confirm_s=CONFIRM_S)
    assert len(events) == 1
    assert abs(events[0].onset_s - 1.6) <= 0.025 and events[0].detected_at_s - 1.6 <= 0.050
    assert not events[0].onset_uncertain
    # the tuned signature alone (nothing masked) does not hear it within the latency budget
    unmasked = ChangeParams(template=TemplateParams(mask_added=None))
    before = detect(y, tu, block=1024, confirm_s=CONFIRM_S, change=unmasked)
    assert not [e for e in before if abs(e.onset_s - 1.6) <= 0.025 and e.detected_at_s - 1.6 <= 0.050]


def test_a_drifting_step_clock_is_not_taken_for_added_sound() -> None:
    """The battery's clock drifting -10 % to +10 %: the stepping's own lines move off some modes and onto others, so
    the template rises over the floor in some sub-bands (12-15 dB in the lowest here) and falls in others. Added sound
    only lifts: once a sub-band has fallen 2 spreads below its highest template of the floor's window (from 1.15 s
    here), nothing is masked. Before that, for 0.25 s, the slowly lifted 1.9-2.4 kHz sub-band was (3.1 dB); masked
    throughout, this recording was heard 57 ms early, unflagged."""
    P = Scene("P", 1000.0, 2.0, 3.0, seed=1)
    x, sr = render(P)
    tu = tune(x, sr, 2.0, seed=0)
    y = render(variant(P, seed=816465, stop_at=1.4, dur=2.0, rate=1027.5544669906046, drift=-0.1))[0]
    det = detector_for(tu)
    st_ = det.state
    assert st_ is not None
    masked_at = []
    for i in range(0, int(1.38 * sr), 1024):
        det.feed(y[i : i + 1024])
        if st_.tpl.added_db is not None:
            masked_at.append((i + 1024) / sr)
        if (i + 1024) / sr >= 1.15:
            assert st_.tpl.template is not None and st_.tpl.floor is not None
            assert st_.tpl.added_db is None and np.max(st_.tpl.template - st_.tpl.floor) > 6.0
    assert masked_at and max(masked_at) < 1.15
    events = detect(y, tu, block=1024, confirm_s=CONFIRM_S)
    assert events and abs(events[0].onset_s - 1.4) <= 0.025 and not events[0].onset_uncertain


def _whine(n: int, sr: int, fc: float, start_s: float, rng: np.random.Generator, rms: float) -> np.ndarray:
    """A pump's whine: noise in +-6 % around ``fc``, its level swaying 30 % at 0.7 Hz, from ``start_s`` (5 ms ramp).

    Continuous narrowband noise, where the battery's second instrument is a click train:
    another view of "a sound that begins shortly before the stop in its sub-bands".
    """
    sos = butter(2, [fc / 1.06 / (sr / 2), fc * 1.06 / (sr / 2)], "band", output="sos")
    w = sosfilt(sos, rng.standard_normal(n))
    t = np.arange(n) / sr
    w *= (1 + 0.3 * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6))) * np.clip((t - start_s) / 0.05, 0, 1)
    return np.asarray(w / np.std(w[int(start_s * sr) :]) * rms)


@pytest.mark.parametrize("arm", [1, 3, 5, 7, 9, 11])
def test_a_whine_begun_before_the_stop_in_its_band_never_makes_a_count_silently_wrong(arm: int) -> None:
    """The fourth generator's random arms (not tuned to), louder stops; a whine as loud as the stepping on the stop's
    strongest rising sub-band from 0.8 s before the stop. Measured (session 29, arms 1-12, seeds 1-3, whine -12 to
    +6 dB: 288 recordings): none silently wrong, before or after the masked fit; here arms 1, 3, 9 and 11 on time and
    unflagged, 5 and 7 flagged (a refusal: measure again). The whine is masked on arms 1, 3 and 5 only: on the others it
    lifts the stop's sub-band by less than 2 spreads."""
    sr = ms.SR
    tu = tune(ms.render(ms.Scene(arm, "louder", stop_at=3.0, dur=4.5, seed=10)), sr, 3.0)
    assert tu.signature_db is not None and tu.edges_hz is not None
    b = int(np.argmax(tu.signature_db))
    fc = float(np.sqrt(tu.edges_hz[b] * tu.edges_hz[b + 1]))
    stop = 2.1
    x = ms.render(ms.Scene(arm, "louder", stop_at=stop, dur=stop + 0.8, seed=1))
    rms = float(np.sqrt(np.mean(x[: int(stop * sr)] ** 2)))
    y = (x + _whine(x.size, sr, fc, stop - 0.8, np.random.default_rng(1000 * arm + 1), rms)).astype(np.float32)
    sd = detector_for(tu)
    det = ConfirmedStopDetector(sd)
    ev = det.feed(y[: int((stop - 0.02) * sr)])
    assert sd.state is not None
    added = sd.state.tpl.added_db
    if arm in (1, 3, 5):  # the whine lifts the stop's sub-band 4.5-13 spreads over the floor: taken for added sound
        assert added is not None and added[b] > 0.0
    else:  # under 2 spreads on these arms: nothing masked, the tuned fit as before
        assert added is None
    ev += det.feed(y[int((stop - 0.02) * sr) :]) + det.finish()
    assert ev, "the stop was missed"
    first = ev[0]
    on_time = abs(first.onset_s - stop) <= 0.025
    assert on_time or first.onset_uncertain, (first.onset_s, first.detected_at_s)  # never silently wrong
    if arm in (1, 3, 9, 11):
        assert on_time and not first.onset_uncertain and first.detected_at_s - stop <= 0.050
