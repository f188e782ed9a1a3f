"""A few of the golden comparison's recordings, pinned: the events the detector gave when it was one module.

``benchmarks/golden_audio.py`` compares every tuning, event and log over 175 recordings
before and after a change to :mod:`stickslip.audio` that means to change nothing (minutes).
These four take seconds and cross the paths a refactoring is most likely to break: a clean
stop, a stop under a second instrument (the masked signature), a drifting clock that fires
twice before the stop (rejections, then a flagged onset) and a session whose stepping pauses
before the first stop (the pause, the restart, two stops). The numbers are the detector's
own, recorded from the code before it was split into stages (the session's since the restart after a pause
waits for the stepping to come back); the battery's generator
(``tests/support/battery_sound.py``) makes the sound.
"""

from __future__ import annotations

from functools import cache

import battery_sound as bs  # noqa: E402
import numpy as np
import pytest
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)  # noqa: E402

from stickslip.audio.confirm import ConfirmedStopDetector, confirming  # noqa: E402
from stickslip.audio.detector import detector_for  # noqa: E402
from stickslip.audio.events import StopEvent  # noqa: E402
from stickslip.audio.tuningfile import Tuning  # noqa: E402

SR = 48_000
P = bs.Scene("P", 1000.0, 2.0, 3.0, seed=1)
Q = bs.Scene("Q", 1000.0, 2.0, 3.0, seed=2)


@cache
def _tuning(joint: str) -> Tuning:
    return tune(*bs.render(P if joint == "P" else Q), 2.0, seed=0)


def _hear(tu: Tuning, y: np.ndarray) -> tuple[list[StopEvent], list[StopEvent], ConfirmedStopDetector]:
    """The fast path's fires and the confirmed events (late path on), in blocks of 1024."""
    fast = detector_for(tu)
    fires = [e for i in range(0, y.size, 1024) for e in fast.feed(y[i : i + 1024])]
    det = confirming(detector_for(tu), 0.5, late=True)
    assert isinstance(det, ConfirmedStopDetector)
    events = [e for i in range(0, y.size, 1024) for e in det.feed(y[i : i + 1024])] + det.finish()
    return fires, events, det


def _same(events: list[StopEvent], want: list[tuple[float, float, bool]]) -> bool:
    """The events are ``want`` (detected_at_s, onset_s, onset_uncertain), to 1 ns."""
    got = [(e.detected_at_s, e.onset_s, e.onset_uncertain) for e in events]
    return len(got) == len(want) and all(
        abs(g[0] - w[0]) <= 1e-9 and abs(g[1] - w[1]) <= 1e-9 and g[2] is w[2] for g, w in zip(got, want, strict=True)
    )


def _test(s: bs.Scene, seed: int, **kw: object) -> np.ndarray:
    y = bs.render(bs.variant(s, seed=seed, stop_at=1.6, dur=2.2, rate=1080.0, **kw))[0]
    return np.asarray(y, dtype=np.float32)


@pytest.mark.slow  # three tunings: several seconds
def test_the_tunings_are_the_ones_recorded() -> None:
    p, q = _tuning("P"), _tuning("Q")
    assert (p.threshold_db, p.onset_lag_s, p.step_rate_hz) == (0.4178, 0.01065, 999.994)
    assert p.edges_hz == (750.0, 944.9, 1190.6, 1500.0, 1889.9, 2381.1, 3000.0, 3779.8, 4762.2, 6000.0, 7559.5,
                          9524.4, 11718.8)  # fmt: skip
    assert (q.threshold_db, q.onset_lag_s, q.step_rate_hz) == (0.4, 0.01065, 1000.002)


def test_a_clean_stop() -> None:
    fires, events, _ = _hear(_tuning("P"), _test(P, 11))
    assert _same(fires, [(1.6239791666666668, 1.5999958333333333, False)])
    assert _same(events, [(1.6239791666666668, 1.5999958333333333, False)])
    assert events[0].confirmed_s == pytest.approx(0.5013333333333333, abs=1e-12)


def test_a_stop_under_a_second_instrument_is_fitted_as_masked() -> None:
    _, events, _ = _hear(_tuning("P"), _test(P, 30, second_rate=730.0, second_from=0.8))
    assert _same(events, [(1.6213125, 1.5956966719164538, False)])


def test_a_drifting_clock_fires_twice_before_the_stop_and_the_stop_is_flagged() -> None:
    fires, events, det = _hear(_tuning("P"), _test(P, 72, drift=0.1))
    fired = [0.5439791666666667, 1.2106458333333334, 1.6239791666666668]
    assert [e.detected_at_s for e in fires] == pytest.approx(fired)
    assert [e.detected_at_s for e in det.log.rejected] == pytest.approx([0.5439791666666667, 1.2106458333333334])
    assert _same(events, [(1.6239791666666668, 1.5999958333333333, True)])
    assert events[0].confirmed_s == pytest.approx(0.576, abs=1e-12)


def test_a_pause_in_the_stepping_is_not_a_stop_and_the_next_two_are() -> None:
    base = Q
    room = np.random.default_rng(5)
    parts: list[np.ndarray] = []
    for k, rate in enumerate((1000.0, 1030.0)):
        if k:
            parts.append((10 ** (-65 / 20) * room.standard_normal(int(0.8 * SR))).astype(np.float32))
        y = bs.render(bs.variant(base, seed=40 + k, stop_at=1.5, dur=2.5, rate=rate))[0]
        if k == 0:  # the stepping stops 1.0 s in for 0.6 s, then resumes
            y = np.concatenate((y[:SR], 10 ** (-65 / 20) * room.standard_normal(int(0.6 * SR)), y[SR:]))
        parts.append(np.asarray(y, np.float32))
    _, events, det = _hear(_tuning("Q"), np.concatenate(parts).astype(np.float32))
    assert [t for t, _ in det.log.stopped] == pytest.approx([1.0239791666666667])
    assert det.log.stopped[0][1].drop_db == pytest.approx(-39.76116169088548, abs=1e-9)
    # the detector restarts where the stepping came back (at 1.600 s: the piece from 1.595 s), not where the pause was
    # judged (1.525 s, in the room's silence): the stops heard 2 ms earlier and 6 ms later than before, their onsets
    # within 1 ms of 2.1 and 5.4 s as before
    assert det.log.restarts == [(pytest.approx(1.5253333333333334), pytest.approx(1.5953333333333335))]
    # the first stop's fire came 0.53 s after the restart: its reference (0.48 s ending 0.06 s before the fire) was
    # cut by the restart (0.47 s heard): flagged (``ClockedParams.onset_short_span``, its price), never counted
    assert _same(events, [(2.1233125, 2.0993291666666667, True), (5.4299791666666675, 5.4006625, False)])
