"""Confirming a stop by its persistence (stickslip.audio.confirm), on the battery's independent generator.

The interference here is the strongest there is: 80 ms of the joint's *own stop sound*
spliced into the stepping (what a detector must take for the stop, and does), rendered
by tests/support/battery_sound.py (not the simulator the tuning code grew up with). A real stop
lasts as long as the joint steps into it; the splice does not.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from battery_sound import Scene, render, variant  # noqa: E402
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.audio.confirm import (  # noqa: E402
    CONFIRM_S,
    ConfirmedStopDetector,
    PersistenceParams,
    check_confirm_s,
    confirming,
)
from stickslip.audio.events import StopDetector  # noqa: E402

AFTER_REJECT_S = PersistenceParams().after_reject_s
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)  # noqa: E402

from stickslip.audio.detector import StopEvent, Tuning, detector_for  # noqa: E402

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
P = Scene("P", 1000.0, 2.0, 3.0, seed=1)
SPLICE_AT, SPLICE_S = 1.0, 0.08


@lru_cache(maxsize=1)
def _tuning() -> Tuning:
    x, sr = render(P)
    return tune(x, sr, 2.0, seed=0)


@lru_cache(maxsize=1)
def _stop_sound() -> np.ndarray:
    z, _ = render(variant(P, seed=12, stop_at=0.0, dur=1.0, rate=1080.0))
    return z[SR // 2 :]


@lru_cache(maxsize=8)
def _recording(stop_at: float, after_s: float = 1.0, splice_at: float | None = SPLICE_AT) -> np.ndarray:
    """Stepping at 1080 Hz, the stop from ``stop_at``, ``after_s`` of it; the stop's sound spliced in for 80 ms."""
    y, _ = render(variant(P, seed=11, stop_at=stop_at, dur=stop_at + after_s, rate=1080.0))
    y = y.copy()
    if splice_at is not None:
        i0, n = int(splice_at * SR), int(SPLICE_S * SR)
        y[i0 : i0 + n] = _stop_sound()[:n]
    return y


def _run(det: StopDetector | ConfirmedStopDetector, y: np.ndarray, block: int) -> list[StopEvent]:
    events = [e for i in range(0, y.size, block) for e in det.feed(y[i : i + block])]
    if isinstance(det, ConfirmedStopDetector):
        events += det.finish()
    return events


def test_the_splice_fools_the_detector_and_confirmation_passes_it_by() -> None:
    y = _recording(4.0)
    plain = _run(detector_for(_tuning()), y, 1024)
    assert [round(e.onset_s, 1) for e in plain] == [1.0, 4.0]  # without confirmation the splice is a stop
    det = ConfirmedStopDetector(detector_for(_tuning()))
    (ev,) = _run(det, y, 1024)
    assert ev.onset_s == pytest.approx(4.0, abs=0.025) and not ev.onset_uncertain
    assert (ev.onset_s, ev.detected_at_s) == (plain[1].onset_s, plain[1].detected_at_s)
    # the plain detector re-armed after the splice by itself and learned its template anew; the confirming one was
    # un-latched when the splice was rejected and its template went on following: the same stop, nearly the same a
    assert ev.level_db == pytest.approx(plain[1].level_db, abs=0.01)
    hop = _tuning().hop / SR
    assert ev.confirmed_s is not None and ev.confirmed_s == pytest.approx(CONFIRM_S, abs=hop)
    assert ev.confirmed_at_s == pytest.approx(ev.detected_at_s + ev.confirmed_s, abs=1e-9)
    assert [round(e.onset_s, 2) for e in det.log.rejected] == [round(plain[0].onset_s, 2)]
    assert ev.to_dict()["confirmed_at_s"] == ev.confirmed_at_s
    assert plain[0].to_dict()["confirmed_at_s"] is None and plain[0].confirmed_s is None


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(block=st.integers(128, 65536))
def test_events_do_not_depend_on_the_block_size(block: int) -> None:
    y = _recording(1.3)  # the stop starts inside the splice's window: rejected, then heard at once
    det = ConfirmedStopDetector(detector_for(_tuning()))
    events = _run(det, y, block)
    ref = ConfirmedStopDetector(detector_for(_tuning()))
    ref_events = _run(ref, y, 4096)

    def times(evs: list[StopEvent]) -> list[tuple[float, float, float | None, float | None]]:
        return [(e.detected_at_s, e.onset_s, e.confirmed_at_s, e.confirmed_s) for e in evs]

    # the times exactly (frame boundaries); the level to float32 FFT rounding
    assert times(events) == times(ref_events) and len(events) == 1
    assert times(det.log.rejected) == times(ref.log.rejected) and len(det.log.rejected) == 1
    levels = [e.level_db for e in ref_events + ref.log.rejected]
    assert [e.level_db for e in events + det.log.rejected] == pytest.approx(levels)


@pytest.mark.parametrize("stop_at", [1.3, 1.45])
def test_a_stop_that_begins_inside_a_rejected_window_is_flagged_uncertain(stop_at: float) -> None:
    """Splice at 1.0 s, its window to 1.52 s; the stop at 1.3-1.45 s: heard on un-latching, its onset flagged.

    When the stop began inside the window is not known (a voice over a stop can hide it for 90 ms as well);
    the event says so, and a traverse refuses it, rather than count to a guess.
    """
    det = ConfirmedStopDetector(detector_for(_tuning()))
    (ev,) = _run(det, _recording(stop_at, after_s=2.5), 1024)
    assert ev.onset_uncertain and ev.to_dict()["onset_uncertain"] is True
    assert SPLICE_AT + CONFIRM_S < ev.onset_s < SPLICE_AT + CONFIRM_S + 0.05  # the un-latching, not the stop
    assert len(det.log.rejected) == 1 and det.log.rejected[0].onset_s == pytest.approx(SPLICE_AT, abs=0.025)


def test_a_fire_soon_after_a_rejected_one_must_persist_longer() -> None:
    """The stop 0.5 s after the splice's window: a fire within RECENT_S of a rejection is confirmed over 2 s."""
    det = ConfirmedStopDetector(detector_for(_tuning()))
    (ev,) = _run(det, _recording(2.0, after_s=2.5), 1024)
    assert ev.onset_s == pytest.approx(2.0, abs=0.025) and not ev.onset_uncertain
    assert ev.confirmed_s == pytest.approx(AFTER_REJECT_S, abs=_tuning().hop / SR)


@pytest.mark.parametrize("stop_at", [1.12, 1.2])
def test_interference_that_runs_into_the_stop_keeps_its_onset(stop_at: float) -> None:
    """The documented limit: the stop 40-120 ms after the splice ends (less than GAP_S) is one event from 1.0 s."""
    det = ConfirmedStopDetector(detector_for(_tuning()))
    (ev,) = _run(det, _recording(stop_at), 1024)
    assert ev.onset_s == pytest.approx(SPLICE_AT, abs=0.025) and det.log.rejected == []


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(confirm_s=st.floats(0.03, 1.2))
def test_a_lasting_stop_is_confirmed_after_the_window_with_the_detectors_onset(confirm_s: float) -> None:
    y = _recording(1.0, after_s=1.5, splice_at=None)
    (fire,) = _run(detector_for(_tuning()), y, 2048)
    (ev,) = _run(ConfirmedStopDetector(detector_for(_tuning()), confirm_s), y, 2048)
    assert (ev.onset_s, ev.detected_at_s) == (fire.onset_s, fire.detected_at_s)
    hop = _tuning().hop / SR
    assert ev.confirmed_s == pytest.approx(confirm_s, abs=hop / 2 + 1e-9)
    assert ev.confirmed_at_s is not None and ev.confirmed_at_s - ev.detected_at_s == pytest.approx(ev.confirmed_s)


def test_a_recording_that_ends_while_confirming() -> None:
    """A stop 0.2 s before the end: emitted by finish(), flagged by confirmed_s < the window; a splice is not."""
    y = _recording(2.0, after_s=0.2, splice_at=None)
    det = ConfirmedStopDetector(detector_for(_tuning()))
    assert [e for i in range(0, y.size, 1024) for e in det.feed(y[i : i + 1024])] == []
    assert det.pending is not None
    (ev,) = det.finish()
    assert ev.onset_s == pytest.approx(2.0, abs=0.025)
    assert ev.confirmed_s is not None and 0.1 < ev.confirmed_s < 0.2
    assert ev.confirmed_at_s == pytest.approx(y.size / SR, abs=_tuning().frame / SR)
    assert det.finish() == [] and det.pending is None
    # the splice 0.2 s before the end of a stepping recording: what was heard of its window did not persist
    y = _recording(9.0, after_s=0.0, splice_at=None)[: int(1.2 * SR)].copy()
    y[SR : SR + int(SPLICE_S * SR)] = _stop_sound()[: int(SPLICE_S * SR)]
    det = ConfirmedStopDetector(detector_for(_tuning()))
    assert _run(det, y, 1024) == [] and len(det.log.rejected) == 1


def test_a_band_tuning_is_confirmed_too() -> None:
    """The version-1 band-power detector: a 60 ms tone burst is passed by, a lasting tone is the stop."""
    rng = np.random.default_rng(0)
    x = 0.01 * rng.standard_normal(3 * SR)
    t = np.arange(x.size) / SR
    tone = 0.05 * np.sin(2 * np.pi * 6000 * t)
    burst = (t >= 0.8) & (t < 0.86)
    x = x + tone * (burst | (t >= 2.0))
    tu = Tuning(band_hz=(5600, 7100), threshold_db=-40.0)
    plain = _run(detector_for(tu), x, 1000)
    assert [round(e.onset_s, 1) for e in plain] == [0.8, 2.0]
    det = ConfirmedStopDetector(detector_for(tu), 0.3)
    (ev,) = _run(det, x, 1000)
    assert (ev.onset_s, ev.detected_at_s) == (plain[1].onset_s, plain[1].detected_at_s)
    assert [e.onset_s for e in det.log.rejected] == [plain[0].onset_s]


def test_confirming_wraps_only_what_it_can_and_refuses_bad_windows() -> None:
    inner = detector_for(_tuning())
    assert confirming(inner, 0.0) is inner
    wrapped = confirming(inner)
    assert isinstance(wrapped, ConfirmedStopDetector) and wrapped.inner is not inner and inner.evidence is None
    assert confirming(wrapped) is wrapped
    oracle = object()
    assert confirming(oracle, 0.5) is oracle
    for bad in (-0.1, math.nan, math.inf, 5.01, "x"):
        with pytest.raises(ValueError, match="confirm_s"):
            check_confirm_s(bad)  # type: ignore[arg-type]  # a str on purpose
    with pytest.raises(ValueError, match="> 0"):
        ConfirmedStopDetector(inner, 0.0)
    with pytest.raises(ValueError, match="min_share"):
        PersistenceParams(min_share=0.0)
    det = ConfirmedStopDetector(detector_for(_tuning(), t0_s=7.0))
    assert (det.latency_s, det.tuning, det.ready, det.latched) == (inner.latency_s, inner.tuning, False, False)
    with pytest.raises(ValueError, match="1-D"):
        det.feed(np.zeros((4, 2)))


def test_reset_forgets_a_provisional_stop() -> None:
    y = _recording(2.0, after_s=0.2, splice_at=None)
    det = ConfirmedStopDetector(detector_for(_tuning()))
    det.feed(y)
    assert det.pending is not None
    det.reset(5.0)
    assert det.pending is None and det.finish() == [] and det.log.rejected == []
    (ev,) = _run(det, _recording(2.0), 4096)  # and hears the next stream in its own time
    assert ev.onset_s == pytest.approx(7.0, abs=0.025)
