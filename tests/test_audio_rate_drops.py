"""The drops' check on the signature predicted at the heard step rate (issue 10, round 12b).

At another step rate than the tuning's, the sub-bands the tuned signature says the stop
lowers may hold their level or rise (the clock's lines sample the arm's narrow modes
elsewhere), and the drops-in-proportion check (``stickslip.audio.change.drops.drops_shown``) withheld stops
the fit heard (round 11b). Since round 12b a frame the predicted signature's fit took, with
its residual within ``PRED_DROPS_RHO`` of ``residual_max``, also passes the check if the
*predicted* signature's drops show in proportion (the tuned drops' verdict otherwise, and
always where no prediction is fitted). ``docs/audio-log.md``, "Round 12b".

The recordings come from generators the detector was not tuned to (the fifth, ``arrival_sound``;
the sixth, ``beam_sound``; the battery's, ``battery_sound``), each tuned by ``tune`` on its
own 1000 Hz tuning recording. "Before" is the same detector with ``PRED_DROPS_RHO`` set to
None, which is main's code path before this round (pinned below against main's outcomes).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.audio.change import ChangeParams, TemplateDetector
from stickslip.audio.change.drops import DROPS, DropParams, drops_shown
from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.detector import StopEvent
from stickslip.audio.tuningfile import Tuning
from test_audio_downstream import _recording, _tuning

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
TOL_S = 0.025


#: the drops' check on the tuned signature alone (the detector before the predicted drops)
TUNED_DROPS_ALONE = ChangeParams(drops=DropParams(pred_drops_rho=None))


def _events(tu: Tuning, y: np.ndarray, params: ChangeParams | None = None) -> tuple[list[StopEvent], TemplateDetector]:
    sd = TemplateDetector(tu, params=params)
    det = ConfirmedStopDetector(sd)
    return det.feed(np.asarray(y, dtype=np.float32)) + det.finish(), sd


def _outcome(events: list[StopEvent], stop: float) -> str:
    if not events:
        return "missed"
    e = events[0]
    if e.onset_uncertain:
        return "flagged"
    return "early" if e.onset_s - stop < -TOL_S else "late" if e.onset_s - stop > TOL_S else "right"


# (generator, arm, stop kind, test rate Hz): main's outcome -> this round's (measured over round 10b's 408 recordings:
# these are all the outcomes that moved, docs/audio-log.md "Round 12b")
CASES = [
    ("sixth", 10, "", 1100.0, "missed", "right"),
    ("fifth", 4, "damped", 950.0, "flagged", "right"),
    ("fifth", 4, "shifted", 1025.0, "flagged", "right"),
    ("fifth", 8, "shifted", 1100.0, "missed", "flagged"),
    ("sixth", 2, "", 1100.0, "missed", "flagged"),
    ("battery", 1, "brighter", 900.0, "missed", "right"),
    ("battery", 1, "brighter", 950.0, "missed", "flagged"),
]


@pytest.mark.parametrize("gen,arm,kind,rate,before,after", CASES)
def test_a_stop_whose_tuned_drops_do_not_show_at_another_rate_is_heard_by_the_predicted_drops(
    gen: str, arm: int, kind: str, rate: float, before: str, after: str
) -> None:
    tu = _tuning(gen, arm, kind)
    y, stop = _recording(gen, arm, kind, rate)
    old, _ = _events(tu, y, TUNED_DROPS_ALONE)
    assert _outcome(old, stop) == before, [(e.onset_s, e.onset_uncertain) for e in old]
    new, sd = _events(tu, y)
    assert _outcome(new, stop) == after, [(e.onset_s, e.onset_uncertain) for e in new]
    assert sd.state.fits.rate_log[0][2]  # the prediction was fitted
    if after == "flagged":
        assert new[0].detected_at_s >= stop  # a flag on the stop, not a fire on stepping


def test_stepping_alone_does_not_fire_with_the_predicted_drops() -> None:
    """The same recordings cut 0.1 s before the stop: no event (round 12b's measurement: none of the 408)."""
    for gen, arm, kind, rate, *_ in CASES:
        y, stop = _recording(gen, arm, kind, rate)
        events, _ = _events(_tuning(gen, arm, kind), y[: int((stop - 0.1) * SR)])
        assert events == [], (gen, arm, kind, rate, [e.onset_s for e in events])


def _trace(
    tu: Tuning, y: np.ndarray, params: ChangeParams | None = None
) -> tuple[list[tuple[float, float, bool]], list[float], list[tuple[int, float, bool]]]:
    sd = TemplateDetector(tu, params=params)
    sd.evidence = []
    det = ConfirmedStopDetector(sd)
    events = det.feed(np.asarray(y, dtype=np.float32)) + det.finish()
    heard = [(e.onset_s, e.detected_at_s, e.onset_uncertain) for e in events]
    return heard, list(sd.evidence or []), sd.state.fits.rate_log


@pytest.mark.parametrize("rate", [1000.0, 1006.0])
def test_at_the_tunings_own_rate_nothing_changes(rate: float) -> None:
    """Within RATE_MIN_CHANGE of the tuning's rate no prediction is fitted: events and the per-frame evidence are
    identical, to the bit, to the tuned drops alone."""
    for gen, arm, kind in (("fifth", 4, "damped"), ("sixth", 10, ""), ("battery", 1, "brighter")):
        tu = _tuning(gen, arm, kind)
        y, _ = _recording(gen, arm, kind, rate)
        got = _trace(tu, y)
        ref = _trace(tu, y, TUNED_DROPS_ALONE)
        assert not got[2][0][2]  # the tuned signature alone
        assert got[0] == ref[0]
        np.testing.assert_array_equal(np.asarray(got[1]), np.asarray(ref[1]))


def test_the_drops_check_is_the_same_function_for_both_signatures() -> None:
    """``drops_shown`` against a direct computation: frames that show exactly the signature's drops pass, frames that
    show none fail, and a frame with half of them passes only where ``a`` asks less than half."""
    rng = np.random.default_rng(1)
    nb = 12
    g = np.minimum(rng.normal(0.0, 3.0, nb), 0.0)
    g[:3] = [-3.0, -2.5, -2.0]  # informative: at least NEG_INFORMATIVE spreads of drops
    gn = np.maximum(g, -DROPS.cap)
    info = float(gn @ gn)
    clear = np.ones((3, nb), dtype=bool)
    zs = np.stack([gn, np.zeros(nb), 0.5 * gn])
    a = np.array([1.0, 1.0, 1.0])
    tail = (np.zeros(0), np.zeros(0))
    # one frame at a time: each averaged with the ones before (NEG_FRAMES)
    shown = []
    for i in range(3):
        s, tail = drops_shown(zs[i : i + 1], clear[i : i + 1], gn, info, a[i : i + 1], tail)
        shown.append(bool(s[0]))
    # the average of 1, 0 and 0.5 of the drops: 1 (pass), 0.5 (pass: need 0.45 less the slack), 0.5 (pass)
    assert shown == [True, True, True]
    s, _ = drops_shown(zs[1:2], clear[1:2], gn, info, a[1:2], (np.zeros(0), np.zeros(0)))
    assert not s[0]  # no drop shown, alone
    # in blocks or frame by frame: the same verdicts
    s_all, _ = drops_shown(zs, clear, gn, info, a, (np.zeros(0), np.zeros(0)))
    assert s_all.tolist() == shown


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    pick=st.integers(0, 10_000),
    rel=st.floats(-0.05, 0.05).filter(lambda r: abs(r) > 0.012),
    seed=st.integers(0, 10_000),
)
def test_the_predicted_drops_never_make_a_stop_silently_wrong(pick: int, rel: float, seed: int) -> None:
    """Any arm of the battery's, the fifth and the sixth generator, tuned at 1000 Hz, at any rate within the 5 %
    warning (and beyond the 1 % where the prediction is fitted) and any seed: the first confirmed event is right,
    flagged or absent, never more than 25 ms off unflagged, unless the tuned drops alone (main) gave the same outcome;
    and stepping alone never fires.

    The exception is measured, not hoped for: the sixth generator's beam 1 at 1027.3 Hz, seed 242, is confirmed 32 ms
    late unflagged on main and here alike (its slow climb: docs/audio-log.md, "Round 12b"); the predicted drops do not
    change it.
    """
    gens = [("battery", 1 + pick % 2, ("louder", "quieter", "duller", "brighter", "spectral")[pick // 2 % 5])]
    gens.append(("fifth", 1 + pick % 8, ("stiff", "damped", "shifted")[pick // 8 % 3]))
    gens.append(("sixth", 1 + pick % 10, ""))
    gen, arm, kind = gens[pick // 7 % 3]
    tu = _tuning(gen, arm, kind)
    y, stop = _recording(gen, arm, kind, 1000.0 * (1 + rel), seed=seed)
    events, _ = _events(tu, y)
    after = _outcome(events, stop)
    if after not in ("right", "flagged", "missed"):
        before = _outcome(_events(tu, y, TUNED_DROPS_ALONE)[0], stop)
        assert after == before, (gen, arm, kind, rel, seed, before, events[:1])
    assert _events(tu, y[: int((stop - 0.1) * SR)])[0] == [], (gen, arm, kind, rel, seed)


def test_a_stop_main_counts_silently_late_is_not_made_worse() -> None:
    """The sixth generator's beam 1 at 1027.3 Hz, seed 242 (found by the property above): 32 ms late, unflagged, on
    main; the same onset with the predicted drops (a case for the confirmation's onset checks, not this round's)."""
    tu = _tuning("sixth", 1, "")
    y, stop = _recording("sixth", 1, "", 1000.0 * (1 + 0.02734375), seed=242)
    before, _ = _events(tu, y, TUNED_DROPS_ALONE)
    after, _ = _events(tu, y)
    assert [(e.onset_s, e.onset_uncertain) for e in after] == [(e.onset_s, e.onset_uncertain) for e in before]
    assert after and after[0].onset_s - stop == pytest.approx(0.0322, abs=5e-4) and not after[0].onset_uncertain
