"""One recording, several stops: ``listen`` on a whole session hears every stop, on time.

A lab records a session (or listens live with ``--mic``): traverse after traverse, each
ending in its stop, with or without a pause between them and at slightly different step
rates. The recordings come from two generators the detector was not developed on
(``battery_sound``, ``modal_sound``), tuned on a recording of one traverse.

Found by this test's first version (session 25): the detector stayed latched after a stop
as long as one frame in 0.25 s of the stepping that followed had a stop-likeness above
half the threshold (joint P of the battery: about one stepping frame in 20 does), so the
third stop of a session was not heard; a floor kept from before a stop hid the next
stop's drops (arm 3 of the fourth generator: heard up to 109 ms late); and stepping 4 %
faster after a stop than before it showed drops against the template frozen at the stop,
which held the latch (hypothesis).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import battery_sound as bs  # noqa: E402
import modal_sound as ms  # noqa: E402
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)  # noqa: E402

from stickslip.audio.change.release import RELEASE, Release  # noqa: E402
from stickslip.audio.confirm import CONFIRM_S  # noqa: E402
from stickslip.audio.detector import detect, detector_for  # noqa: E402
from stickslip.audio.tuningfile import Tuning  # noqa: E402

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
TOL_S = 0.025
STOP_S = 1.5  # each traverse's stop, s from its start; each traverse is 2.5 s long
ARMS = ("battery P", "battery Q", "modal 2 duller", "modal 3 louder", "modal 5 spectral")
Traverse = Callable[[int, float], np.ndarray]  # seed, step rate (Hz) -> samples


@cache
def _arm(name: str) -> tuple[Tuning, Traverse]:
    if name.startswith("battery"):
        joint = name[-1]
        base = bs.Scene(joint, 1000.0, 2.0, 3.0, seed=1 if joint == "P" else 2)

        def one(seed: int, rate: float) -> np.ndarray:
            return bs.render(bs.variant(base, seed=seed, stop_at=STOP_S, dur=2.5, rate=rate))[0]

        return tune(*bs.render(base), 2.0, seed=0), one
    _, js, kind = name.split()

    def one_modal(seed: int, rate: float) -> np.ndarray:
        x = ms.render(ms.Scene(int(js), kind, stop_at=STOP_S, dur=2.5, rate=rate, seed=seed))
        return np.asarray(x, np.float32)

    train = ms.render(ms.Scene(int(js), kind, stop_at=3.0, dur=4.5, seed=10))
    return tune(np.asarray(train, np.float32), SR, 3.0, seed=0), one_modal


def _session(arm: str, gaps: list[float], rates: list[float], seed: int) -> tuple[np.ndarray, list[float]]:
    """Traverses one after the other, ``gaps`` s of a quiet room between them; the recording and its stops (s)."""
    _, one = _arm(arm)
    parts: list[np.ndarray] = []
    stops: list[float] = []
    t = 0.0
    room = np.random.default_rng(seed)
    for k, rate in enumerate(rates):
        if k:
            g = (10 ** (-65 / 20) * room.standard_normal(int(gaps[k - 1] * SR))).astype(np.float32)
            parts.append(g)
            t += g.size / SR
        x = one(seed + k, rate)
        parts.append(x)
        stops.append(t + STOP_S)
        t += x.size / SR
    return np.concatenate(parts), stops


def _onsets(arm: str, y: np.ndarray) -> list[float]:
    return [e.onset_s for e in detect(y, _arm(arm)[0], block=1024, confirm_s=CONFIRM_S)]


def _events(arm: str, y: np.ndarray) -> list[tuple[float, bool]]:
    return [(e.onset_s, e.onset_uncertain) for e in detect(y, _arm(arm)[0], block=1024, confirm_s=CONFIRM_S)]


def _never_silently_wrong(got: list[tuple[float, bool]], stops: list[float]) -> bool:
    return len(got) == len(stops) and all(u or abs(o - s) <= TOL_S for (o, u), s in zip(got, stops, strict=True))


@pytest.mark.parametrize("gap", [0.0, 0.05, 0.4])
@pytest.mark.parametrize("arm", ARMS)
def test_every_stop_of_a_session_is_heard_once_and_on_time(arm: str, gap: float) -> None:
    y, stops = _session(arm, [gap, gap], [1000.0, 1010.0, 1020.0], seed=800)
    got = _onsets(arm, y)
    assert len(got) == len(stops), (stops, got)
    assert all(abs(o - s) <= TOL_S for o, s in zip(got, stops, strict=True)), (stops, got)


@settings(max_examples=12, deadline=None)
@example(arm="modal 3 louder", gaps=[0.0, 0.0], rate=977.5, seed=973)
@given(
    arm=st.sampled_from(ARMS),
    gaps=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2),
    rate=st.floats(965.0, 1035.0),
    seed=st.integers(900, 10_000),
)
def test_sessions_at_one_rate_within_the_warning_and_any_pause_hear_every_stop(
    arm: str, gaps: list[float], rate: float, seed: int
) -> None:
    """One controller setting for the session (the usual case): every stop heard once, on time or flagged.

    Not every one on time: a fresh draw (round 9a, ``--hypothesis-seed=13``: arm 3's louder stop at 977.5 Hz, no
    pauses, seed 973) hears the third stop +33 ms late, flagged "a stop heard late" (on this branch's base too).
    """
    y, stops = _session(arm, gaps, [rate, rate, rate], seed)
    got = _events(arm, y)
    assert _never_silently_wrong(got, stops), (stops, got)


def test_a_session_whose_rate_changes_between_traverses_hears_every_stop_on_time_or_flagged() -> None:
    """Arm 3's louder stop, 965 -> 1000 -> 965 Hz, 0.5 s of quiet then none between traverses.

    The second traverse, 3.6 % faster than the stepping the template learned in the first, shows the stop's rise at
    +4 ms but its drops only in flickers (the floor is the slower stepping's: its lines sit elsewhere), so the hold
    broke and the fire came at +55 ms: +31 ms, unflagged in session 25. On this branch's base (a6d72f4) already
    flagged "a stop heard late" (the stop-likeness was at the stop's level from +4 ms): the xfail was strict only
    because it asked for on time; the others are on time. Since round 11a's second fit (the first traverse is 3.5 %
    slower than the tuning) the first is flagged too: measured again, never a wrong count.
    """
    y, stops = _session("modal 3 louder", [0.5, 0.0], [965.0, 1000.0, 965.0], seed=4997)
    got = _events("modal 3 louder", y)
    assert _never_silently_wrong(got, stops), (stops, got)
    assert [u for _, u in got] == [True, True, False], got  # the last on time


@settings(max_examples=6, deadline=None)
@given(
    arm=st.sampled_from(ARMS),
    gaps=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2),
    rates=st.lists(st.floats(965.0, 1035.0), min_size=3, max_size=3),
    seed=st.integers(900, 10_000),
)
def test_sessions_whose_rate_changes_between_traverses_are_never_silently_wrong(
    arm: str, gaps: list[float], rates: list[float], seed: int
) -> None:
    """A rate drawn per traverse within the warning: every stop heard once, each on time or flagged."""
    y, stops = _session(arm, gaps, rates, seed)
    got = _events(arm, y)
    assert _never_silently_wrong(got, stops), (stops, got)


def test_a_session_s_events_do_not_depend_on_block_sizes() -> None:
    y, _ = _session("battery P", [0.05, 0.3], [1000.0, 1010.0, 990.0], seed=820)
    tu = _arm("battery P")[0]
    ref = [(e.detected_at_s, round(e.onset_s, 9)) for e in detector_for(tu).feed(y)]
    assert len(ref) == 3
    for block in (128, 777, 4096):
        det = detector_for(tu)
        ev = [e for i in range(0, y.size, block) for e in det.feed(y[i : i + block])]
        assert [(e.detected_at_s, round(e.onset_s, 9)) for e in ev] == ref


def test_release_needs_a_full_window_mostly_of_stepping() -> None:
    r = Release(20)
    assert not any(r.push(True) for _ in range(19))  # the window is not full yet
    assert r.push(True)
    n_not = round(20 * (1 - RELEASE.share))  # this many frames still like the stop release ...
    r.reset()
    assert [r.push(k >= n_not) for k in range(20)][-1]
    r.reset()  # ... one more does not
    assert not [r.push(k > n_not) for k in range(20)][-1]
    # it is a sliding window: once those frames have left it, it releases
    assert any(r.push(True) for _ in range(n_not + 1))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=200), st.integers(1, 40))
def test_release_agrees_with_counting_the_window_afresh(flags: list[bool], frames: int) -> None:
    r = Release(frames)
    for i, stepping in enumerate(flags):
        w = flags[max(0, i + 1 - frames) : i + 1]
        assert r.push(stepping) == (len(w) >= frames and sum(w) >= RELEASE.share * len(w))
