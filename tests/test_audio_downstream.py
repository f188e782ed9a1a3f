"""Stops the fit hears but the detector loses, at another step rate than the tuning's (issue 10, round 11b).

Round 10b found that of the recordings at 900-1100 Hz (tuned at 1000 Hz) that the confirmed
detector did not get right, many show the stop-likeness ``a`` of the line fit above the
threshold at the stop: the fit hears the stop, something downstream loses it. Round 11b traced
each to the stage that loses it (docs/audio-log.md, "Round 11b"). Two stages lose most of them, and
neither is the confirmation's to change:

* **the drops in proportion** (``TemplateState``'s check that the sub-bands the stop lowers are
  lower, at least 0.45 x ``a``): at another rate the click train's lines sample the narrow
  modes elsewhere, and the sub-bands the tuned signature says the stop lowers are not lower
  at the stop (they hold their level, or rise). That is what a voice over stepping looks like
  too, which is why the check exists; the stop is missed (safe: a traverse times out). The
  lever is a signature predicted at the heard rate (round 10b), not a looser check;
* **a fire on stepping before the stop**: a template that departs in one sub-band (the fifth
  generator's arm 1, shifted stop) fires on stepping at another rate; the window (2 s after a
  rejected fire) spans the stop, and the event is flagged ``onset_uncertain``. The flag is right:
  every one of those onsets is 53-851 ms off.

The checks here are made from another view than the detector's own: the stop-likeness and the
drops are computed offline from the public level and fit functions against a fixed template
(the low quantile of the last second of stepping), not read from the detector's state.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import arrival_sound as ar
import battery_sound as bs
import beam_sound as bm
import modal_sound as md
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.change import ChangeParams, TemplateDetector
from stickslip.audio.change.drops import DROPS, DropParams
from stickslip.audio.change.fit import fit_departure
from stickslip.audio.change.template import TEMPLATE
from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.confirm.onset import ONSET
from stickslip.audio.confirm.persistence import PERSISTENCE
from stickslip.audio.detector import StopEvent, detector_for
from stickslip.audio.features.spectra import subband_levels_db
from stickslip.audio.tuningfile import Tuning
from test_audio_rate_signature import tuned_alone

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
TOL_S = 0.025


@cache
def _tuning(gen: str, arm: int, kind: str) -> Tuning:
    """The generator's arm tuned by ``tune`` on its 1000 Hz tuning recording (as round 10b's scan)."""
    if gen == "battery":
        x, sr = bs.render(bs.Scene("PQ"[arm - 1], 1000.0, 2.0, 3.0, seed=arm, stop_kind=kind))
        return tune(x, sr, 2.0, seed=0)
    if gen == "fifth":
        return tune(ar.render(ar.tuning_scene(ar.Arm(arm, kind))), SR, 2.0, seed=0)
    if gen == "fourth":
        return tune(md.render(md.Scene(arm, kind, stop_at=3.0, dur=4.5, seed=10)), SR, 3.0, seed=0)
    return tune(bm.render(bm.tuning_scene(bm.Beam(arm))), SR, 2.0, seed=0)


def _recording(gen: str, arm: int, kind: str, rate: float, seed: int | None = None) -> tuple[np.ndarray, float]:
    """A test recording at ``rate`` (round 10b's: the generator's own room, the seed the rate), and its stop, s."""
    sd = int(rate) if seed is None else seed
    if gen == "battery":
        x, _ = bs.render(bs.Scene("PQ"[arm - 1], float(rate), 1.6, 2.2, seed=sd, stop_kind=kind))
        return np.asarray(x, dtype=np.float64), 1.6
    if gen == "fifth":
        return np.asarray(ar.render(ar.Scene(arm=ar.Arm(arm, kind), rate=float(rate), seed=sd)), dtype=np.float64), 2.0
    if gen == "fourth":
        y = md.render(md.Scene(arm, kind, stop_at=2.0, dur=3.0, rate=float(rate), seed=sd))
        return np.asarray(y, dtype=np.float64), 2.0
    return np.asarray(bm.render(bm.Scene(beam=bm.Beam(arm), rate=float(rate), seed=sd)), dtype=np.float64), 2.0


def _events(
    tu: Tuning, y: np.ndarray, params: ChangeParams | None = None, rate_hz: float | None = None
) -> list[StopEvent]:
    """The confirmed detector's events on ``y``; ``rate_hz``: the commanded rate told, Hz (as a traverse tells it)."""
    det = ConfirmedStopDetector(TemplateDetector(tu, params=params))
    det.reset(0.0, step_rate_hz=rate_hz)
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish()


def _at_the_stop(tu: Tuning, y: np.ndarray, stop: float) -> tuple[float, float, float]:
    """Offline, against a fixed template (the low quantile of the last second of stepping): over 30-500 ms after the
    stop, the share of frames whose fitted stop-likeness reaches the threshold, the median ``a`` in thresholds, and the
    median share of the signature's drops the frames show (each sub-band's expected drop capped at NEG_CAP spreads)."""
    assert tu.edges_hz is not None and tu.signature_db is not None and tu.spread_db is not None
    v = subband_levels_db(y, SR, tu.frame, tu.hop, tu.edges_hz)
    t = (np.arange(v.shape[0]) * tu.hop + tu.frame) / SR
    stepping = (t > stop - 1.0) & (t < stop - 0.05)
    after = (t >= stop + 0.03) & (t < stop + 0.5)
    d = v - np.percentile(v[stepping], 100 * TEMPLATE.quantile, axis=0)
    delta, sigma = np.asarray(tu.signature_db), np.asarray(tu.spread_db)
    a, _ = fit_departure(d[after], delta, sigma, tu.trim)
    g = np.maximum(np.minimum(delta, 0.0) / sigma, -DROPS.cap)
    shown = (np.maximum(d[after] / sigma, -DROPS.cap) @ g) / float(g @ g)
    thr = float(tu.threshold_db)
    return float(np.mean(a >= thr)), float(np.median(a)) / thr, float(np.median(shown))


# (generator, arm, stop kind, test rate Hz): missed by the detector, the fit's a at the stop 1.8-5.4 thresholds
WITHHELD = [
    ("battery", 1, "brighter", 900.0),
    ("battery", 1, "brighter", 950.0),
    ("fifth", 1, "stiff", 1025.0),
    ("fifth", 7, "stiff", 950.0),
    ("fifth", 7, "stiff", 1050.0),
    ("fifth", 7, "shifted", 950.0),
    ("sixth", 3, "", 1025.0),
]


@pytest.mark.parametrize(("gen", "arm", "kind", "rate"), WITHHELD)
def test_the_fit_hears_the_stop_whose_drops_do_not_show_at_another_rate(
    gen: str, arm: int, kind: str, rate: float
) -> None:
    """The stage that loses these stops: the fit hears the stop (a at or over the threshold in nearly every frame,
    1.6 thresholds or more), but the sub-bands the tuned signature lowers are not lower at this rate: the share of the
    drops shown is under half the NEG_RATIO x a (a capped at 1) the check asks (measured -2.9 to 0.21), where at the
    tuning's own rate the same arm's stop shows them (0.91-1.0). The detector misses the stop, safely."""
    tu = _tuning(gen, arm, kind)
    y, stop = _recording(gen, arm, kind, rate)
    share, a_thr, shown = _at_the_stop(tu, y, stop)
    assert share >= 0.9 and a_thr >= 1.6, (share, a_thr)
    assert shown < DROPS.ratio / 2, shown
    y0, stop0 = _recording(gen, arm, kind, 1000.0)
    share0, _, shown0 = _at_the_stop(tu, y0, stop0)
    assert share0 >= 0.9 and shown0 >= 0.9, (share0, shown0)
    # missed on the tuned signature's drops (a traverse times out); since round 12b the predicted signature's drops
    # hear the battery's two (tests/test_audio_rate_drops.py)
    assert _events(tu, y, ChangeParams(drops=DropParams(pred_drops_rho=None))) == []
    ev0 = _events(tu, y0)
    assert ev0 and not ev0[0].onset_uncertain and abs(ev0[0].onset_s - stop0) <= TOL_S


@pytest.mark.parametrize(("gen", "arm", "kind", "rate"), WITHHELD[3:5])
def test_a_stop_the_fit_hears_at_another_rate_is_heard_on_time(gen: str, arm: int, kind: str, rate: float) -> None:
    """The fifth generator's arm 7, stiff stop, at 950 and 1050 Hz (told, as a traverse tells it): the signature
    predicted at the rate lowers nothing worth checking (its drops' information 0.7 and 0.2 spreads squared, under
    the 4 the drops' check needs), so the tuned drops cannot be asked of the stop there. The frames are *unasked*:
    the hold fires on them, on time, but they are not hot, and the confirmation asks the joint's lines, which affirm
    the stop (both readings at min_affirm, on the tuned signature: measured 0.68 / 0.54 at 950 Hz, 0.61 / 0.62 at
    1050 Hz). Before (unasked frames held back as the tuned drops said, the lines read within 1 % of the tuning's
    rate only): no fire, or one rejected; missed."""
    tu = _tuning(gen, arm, kind)
    y, stop = _recording(gen, arm, kind, rate)
    det = ConfirmedStopDetector(TemplateDetector(tu))
    det.reset(0.0, step_rate_hz=rate)  # the traverse knows the rate it commands
    ev = det.feed(np.asarray(y, dtype=np.float32)) + det.finish()
    assert ev and not ev[0].onset_uncertain and abs(ev[0].onset_s - stop) <= TOL_S, ev
    # confirmed by the lines, at the rate told (5 % from the tuning's), not by the hot frames
    (_, got), *_ = det.log.clocked
    assert abs(got.rate_hz / rate - 1.0) < 0.01 and got.a >= CLOCKED.min_affirm and got.locked >= CLOCKED.min_affirm
    # the levels alone did not confirm it: under the persistence's hot share, and missed where unasked frames wait
    fp = TemplateDetector(tu)
    fp.reset(0.0, step_rate_hz=rate)
    fp.evidence, fp.hot_evidence = [], []
    fp.feed(np.asarray(y, dtype=np.float32))
    after = slice(int((stop + 0.03) * SR - tu.frame) // tu.hop, int((stop + 0.5) * SR - tu.frame) // tu.hop)
    assert np.mean(np.asarray(fp.evidence[after]) >= 0.0) >= 0.95
    assert np.mean(fp.hot_evidence[after]) < PERSISTENCE.min_hot
    old = ConfirmedStopDetector(
        TemplateDetector(tu, params=ChangeParams(drops=DropParams(pred_unasked=False))),
        params=ConfirmParams(clocked=replace(CLOCKED, affirm_window=0.0)),
    )
    old.reset(0.0, step_rate_hz=rate)
    assert old.feed(np.asarray(y, dtype=np.float32)) + old.finish() == []


@pytest.mark.xfail(
    strict=True,
    reason="the fifth generator's arm 1, stiff stop, at 1025 Hz: the fast path fires on time on unasked frames (the "
    "predicted signature lowers nothing worth checking), but the joint's lines give no verdict (2 sub-bands, lines "
    "1-2: under min_covered) and cannot affirm it: rejected, missed (safely). Strict: when it is heard, update this",
)
def test_a_stop_whose_lines_cannot_be_read_at_another_rate_is_heard_on_time() -> None:
    tu = _tuning("fifth", 1, "stiff")
    y, stop = _recording("fifth", 1, "stiff", 1025.0)
    ev = _events(tu, y, rate_hz=1025.0)
    assert ev and not ev[0].onset_uncertain and abs(ev[0].onset_s - stop) <= TOL_S


@pytest.mark.parametrize("rate", [900.0, 950.0, 975.0, 1025.0, 1050.0, 1100.0])
def test_a_fire_on_stepping_that_runs_into_the_stop_is_flagged_and_the_flag_is_right(rate: float) -> None:
    """The fifth generator's arm 1, shifted stop: its template departs in one sub-band, and stepping at another rate
    fires it before the stop (the first fire 0.4-1.8 s early, rejected; the next, within 2 s of it, has a 2 s window
    that the stop then fills). The event is flagged, a traverse measures again: and rightly, as the onset it carries
    is 53-851 ms from the stop's (counted to it, the count would be silently wrong)."""
    tu = _tuning("fifth", 1, "shifted")
    y, stop = _recording("fifth", 1, "shifted", rate)
    ev = _events(tu, y)
    assert ev, rate
    assert ev[0].onset_uncertain, (rate, ev[0])
    assert abs(ev[0].onset_s - stop) > 2 * TOL_S, (rate, ev[0].onset_s - stop)


# (generator, arm, stop kind, test rate Hz, the onset's error ms): flagged "a slow rise" of 21-53 ms on main, the climb
# measured from a stepping that flickers to 0.5-1.4 thresholds at this rate
FLICKER = [
    ("fourth", 6, "spectral", 1050.0, 0.0),
    ("fifth", 7, "stiff", 900.0, 3.2),
    ("sixth", 3, "", 1100.0, 5.0),
]


@pytest.mark.parametrize(("gen", "arm", "kind", "rate", "err_ms"), FLICKER)
def test_a_stepping_that_flickers_at_another_rate_is_not_taken_for_the_stop_s_climb(
    gen: str, arm: int, kind: str, rate: float, err_ms: float
) -> None:
    """The onset check's cost (round 11b): the slow-rise check walked back from the crossing over every frame a quarter
    of the way from the stepping's level to the stop's; at another rate the stepping flickers past that (its 95th
    percentile 0.46-1.38 thresholds on the detector's own template, 0.40-0.77 offline), and the walk measured the
    flicker as the climb. The climb is now measured from where the stop-likeness left the stepping's own range: these
    stops, on time, are no longer flagged (a traverse is not measured again for nothing)."""
    tu = _tuning(gen, arm, kind)
    y, stop = _recording(gen, arm, kind, rate)
    # offline, the premise: the stepping before the stop sits low (its median under ONSET_QUIET thresholds: not "a
    # stepping near the threshold") but flickers high (its 95th percentile 0.40-0.77 thresholds here)
    assert tu.edges_hz is not None and tu.signature_db is not None and tu.spread_db is not None
    v = subband_levels_db(y, SR, tu.frame, tu.hop, tu.edges_hz)
    t = (np.arange(v.shape[0]) * tu.hop + tu.frame) / SR
    stepping = (t > stop - 1.0) & (t < stop - 0.05)
    d = v - np.percentile(v[stepping], 100 * TEMPLATE.quantile, axis=0)
    a, _ = fit_departure(d[stepping], np.asarray(tu.signature_db), np.asarray(tu.spread_db), tu.trim)
    assert float(np.median(a)) < ONSET.quiet * tu.threshold_db <= float(np.percentile(a, 95))
    # the mechanism, on the tuned signature alone (as measured in round 11b); then as a user's detector hears it, with
    # round 11a's second fit (the fifth generator's arm 7 then comes 8.0 ms late: on time too)
    for tuning, want_ms in ((tuned_alone(tu), err_ms), (tu, None)):
        det = ConfirmedStopDetector(detector_for(tuning))
        ev = det.feed(np.asarray(y, dtype=np.float32)) + det.finish()
        assert ev and not ev[0].onset_uncertain, (ev, det.log.onset)
        if want_ms is None:
            assert abs(ev[0].onset_s - stop) <= TOL_S, ev[0].onset_s - stop
        else:
            assert 1e3 * (ev[0].onset_s - stop) == pytest.approx(want_ms, abs=0.5)
    assert det.log.rise and det.log.rise[0][1] <= ONSET.slow_s


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    gen=st.sampled_from(["battery", "fourth", "fifth", "sixth"]),
    arm=st.integers(1, 10),
    kind_i=st.integers(0, 4),
    rate=st.floats(950.0, 1050.0),
    seed=st.integers(1, 10**6),
)
def test_a_stop_heard_at_another_rate_within_the_warning_is_never_silently_wrong(
    gen: str, arm: int, kind_i: int, rate: float, seed: int
) -> None:
    """Whatever stage loses a stop at a rate within the tuning's 5 % warning (the drops in proportion, a fire on
    stepping, an onset check), it loses it safely: the confirmed first event is on time, flagged or absent, never
    more than 25 ms off without the flag (the battery's generator, the fourth's arms 1-6, the fifth's arms 1-8 and the
    sixth's beams 1-10, each tuned at 1000 Hz; the test recording in the generator's own room at any rate and seed)."""
    if gen == "battery":
        arm, kind = 1 + arm % 2, ("louder", "quieter", "duller", "brighter", "spectral")[kind_i]
    elif gen == "fourth":
        arm, kind = 1 + arm % 6, md.KINDS[kind_i % 4]
    elif gen == "fifth":
        arm, kind = 1 + arm % 8, ar.STOP_KINDS[kind_i % 3]
    else:
        kind = ""
    tu = _tuning(gen, arm, kind)
    y, stop = _recording(gen, arm, kind, rate, seed)
    ev = _events(tu, y)
    assert not (ev and not ev[0].onset_uncertain and abs(ev[0].onset_s - stop) > TOL_S), (
        gen,
        arm,
        kind,
        rate,
        seed,
        ev[0].onset_s - stop,
    )
