"""Recordings that earlier rounds pinned a mechanism on, heard with round 11a's second fit (the signature predicted at
the heard step rate, ``stickslip.audio.features.fine``).

The tests that pin those mechanisms (round 9a's onset taken back, a slow climb flagged) run on the tuned signature
alone (``tuned_alone``); here the same recordings with the tuning as ``tune`` makes it now: on time, unflagged, without
the mechanism. And the second fit's events do not depend on how the stream is cut into blocks.
"""

from __future__ import annotations

import arrival_sound as ar
import beam_sound as bm
import numpy as np
import pytest

import test_audio_onset as on
import test_audio_shifted as sh

TOL_S = 0.025


def test_the_strongest_reverberation_is_on_time_without_being_taken_back() -> None:
    """Arm 2's damped stop at 950 Hz in the domain's strongest room: +37 ms taken back to +14 ms on the tuned signature
    alone (``test_audio_onset``); with the second fit on time as fired."""
    tu = on._arrival_tuning(2, "damped")
    ev, det = on._first(tu, ar.render(on._strongest_room()))
    assert ev is not None and not ev.onset_uncertain and abs(ev.onset_s - 2.375) <= TOL_S, ev
    assert det.log.retime == [] and det.log.onset == []
    assert det.inner.state is not None and det.inner.state.fits.rate_log[0][2]  # the prediction was fitted


@pytest.mark.slow
def test_arm_8s_shifted_stop_is_on_time_without_being_taken_back() -> None:
    s = sh._arrival_draws(8)[10]
    assert s.stop_at is not None
    ev, det = on._first(sh._arrival_tuning(8), ar.render(s))
    assert ev is not None and not ev.onset_uncertain and abs(ev.onset_s - s.stop_at) <= TOL_S, ev
    assert det.log.retime == []


def test_beam_1s_slow_climb_is_heard_on_time() -> None:
    """Flagged ``onset_uncertain`` 32 ms after the pinning on the tuned signature alone; 8 ms with the second fit."""
    s = sh._beam_draws(1, 3)[2]
    assert s.stop_at is not None
    kind, onsets = sh._outcome(sh._beam_tuning(1), bm.render(s), s.stop_at)
    assert kind == "right" and abs(onsets[0]) < 0.015, (kind, onsets)


@pytest.mark.slow
@pytest.mark.parametrize("block", [128, 777, 4096])
def test_the_second_fit_does_not_depend_on_the_block_size(block: int) -> None:
    """The rate heard at the warm-up and after a relearned template, in blocks of 128 to 4096 samples: the same
    events and the same hearings as in one piece."""
    for tu, x in (
        (on._arrival_tuning(2, "damped"), ar.render(on._strongest_room())),
        (sh._beam_tuning(1), bm.render(sh._beam_draws(1, 3)[2])),
    ):
        ref, det = on.whole_and_in_blocks(tu, np.asarray(x, dtype=np.float32), block)
        assert ref.inner.state is not None and det.inner.state is not None
        assert det.inner.state.fits.rate_log == ref.inner.state.fits.rate_log and ref.inner.state.fits.rate_log[0][2]
