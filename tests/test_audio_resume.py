"""After a pause the detector listens afresh where the stepping comes back (``stickslip.audio.confirm.resume``).

The sounds are made here: white noise through the detector's band stands for the
stepping (its level is all the resumption reads), the room is white noise 35 dB under
it, and a knock is a 15 ms burst. The generators' pauses are heard through the whole
detector in ``tests/test_audio_fan.py`` and ``tests/test_audio_stopped.py``.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.audio.confirm.pause import PAUSE, band_filter, band_power
from stickslip.audio.confirm.resume import Resumption

SR = 48_000
SOS = band_filter((300.0, 16_000.0), SR)
PIECE = int(PAUSE.piece_s * SR)


def _noise(seconds: float, db: float, seed: int) -> np.ndarray:
    return (10 ** (db / 20) * np.random.default_rng(seed).standard_normal(int(round(seconds * SR)))).astype(np.float32)


@cache
def _before() -> float:
    """The stepping's in-band power before the pause, as the pause check measures it."""
    return band_power(_noise(0.5, -30.0, 1).astype(np.float64), SOS, SR, PAUSE.before_quantile)


def _hear(x: np.ndarray, cuts: list[int], before: float) -> tuple[int, np.ndarray] | None:
    r = Resumption(SOS, SR)
    r.start(before)
    for a, b in zip([0, *cuts], [*cuts, x.size], strict=True):
        got = r.push(x[a:b])
        if got is not None:
            at, rest = got
            assert not r.waiting
            return at, np.concatenate([rest, x[b:]])
    assert r.waiting
    return None


@settings(max_examples=12, deadline=None)
@given(
    quiet_s=st.floats(0.05, 0.8),
    back_db=st.sampled_from([-30.0, -38.0, -48.0]),
    cuts=st.lists(st.integers(1, 60_000), max_size=6),
)
def test_the_restart_is_where_the_stepping_came_back_however_the_stream_is_cut(
    quiet_s: float, back_db: float, cuts: list[int]
) -> None:
    """The room for ``quiet_s``, then the stepping again at its level (-30 dB), 8 dB under it (within ``back_db``) or
    18 dB under it (another gain: 17 dB over the room, the rise): the restart is the piece the stepping came back
    in (or the next, where the stepping filled too little of it to rise), the samples from there on handed back
    whole, for any cuts of the stream."""
    x = np.concatenate([_noise(quiet_s, -65.0, 2), _noise(0.1, back_db, 3)])
    got = _hear(x, sorted(set(c for c in cuts if c < x.size)), _before())
    assert got is not None
    at, rest = got
    back = int(round(quiet_s * SR))
    assert at % PIECE == 0 and back - PIECE < at < back + PIECE
    np.testing.assert_array_equal(rest, x[at:])
    assert rest.dtype == np.float32  # the detector hears the samples as they came
    assert got[0] == _hear(x, [], _before())[0]  # type: ignore[index]


def test_stepping_already_back_restarts_at_once_and_a_knock_does_not_restart() -> None:
    """A pause shorter than the window: the restart is where it was judged. A 15 ms knock (under
    ``resume_pieces`` pieces) in the room is not the stepping: still waiting after it."""
    before = _before()
    got = _hear(_noise(0.2, -30.0, 4), [1000, 1000], before)  # an empty block between
    assert got is not None and got[0] == 0
    knock = np.concatenate([_noise(0.3, -65.0, 5), _noise(0.015, -25.0, 6), _noise(0.3, -65.0, 7)])
    assert _hear(knock, [7000], before) is None
    assert PAUSE.resume_pieces * PAUSE.piece_s > 0.015


def test_an_unknown_stepping_level_leaves_the_rise_to_decide() -> None:
    """Without the stepping's level (too little heard before the fire) only a rise over the room restarts."""
    x = np.concatenate([_noise(0.3, -65.0, 8), _noise(0.3, -60.0, 9), _noise(0.3, -40.0, 10)])
    got = _hear(x, [], float("nan"))
    assert got is not None
    assert int(0.6 * SR) - PIECE < got[0] <= int(0.6 * SR)
    assert _hear(x[: int(0.6 * SR)], [], float("nan")) is None  # 5 dB over the room is not the stepping


@pytest.mark.parametrize("before", [0.0, float("inf")])
def test_a_meaningless_stepping_level_is_not_used(before: float) -> None:
    x = np.concatenate([_noise(0.2, -65.0, 11), _noise(0.2, -30.0, 12)])
    got = _hear(x, [], before)
    assert got is not None and int(0.2 * SR) - PIECE < got[0] <= int(0.2 * SR)
