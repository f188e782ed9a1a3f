"""Stepping with speech, music and a radio and no stop, on every joint: no stop heard.

The eleventh generator (``tests/support/hour_sound.py``: the tenth generator's joints rendered
as a stream in 1 s blocks, a source-filter talker, a band of harmonic notes and a snare, a
radio's narrow channel) was written before the detector was judged on it and is never used
to tune it. Each joint (arms 1-3 of the tenth generator, as the three joints of an MM3A) is
tuned on its own quiet 1000 Hz recording and heard as a traverse hears it: the confirming
detector, told the commanded 1000 Hz, fed block by block.

The whole hour per joint is ``benchmarks/bench_audio_hour.py`` (minutes per joint: it is a
measurement, not a test). Here, 40 s per joint with spans of 4-12 s, so added sound starts
and stops several times (marked slow), and the stream's own properties.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import soundfile
from fan_sound import SR, Arm
from hour_heard import hear, heard_by, joint_tuning
from hour_sound import KINDS, Hour, spans, stream

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import CLOCKED
from stickslip.audio.confirm.onset import ONSET
from stickslip.audio.detector import detector_for

#: 3.6 s of the hour's joint 1 (its own draw, seed 1) from 2643.0 s, as 16-bit samples (full scale 32767): music at
#: -0.6 dB re the stepping since 2625.0 s, the counted false stop at 2646.01 s (docs/audio-log.md, "Diagnosis of the
#: hour's false stops"). The generator cannot start an hour 44 minutes in (its noises are drawn in order), so the
#: excerpt is kept as samples.
EXCERPT = Path(__file__).parent / "data" / "hour_joint1_music_2643s.flac"  # 16-bit, lossless
EXCERPT_T0_S = 2643.0

#: one worker tunes each joint once for this file and tests/test_audio_blocks.py
pytestmark = pytest.mark.xdist_group("audio_hour")

JOINTS = (1, 2, 3)
#: joint -> what is measured today where it fails. When the test was written, joint 3 gave 2 false stops, none
#: flagged: 0.40 s (a radio from the first sample, +0.4 dB) and 34.5 s (speech over the radio switched on, +0.4 dB),
#: the level's fit to a stop that only rises; the step clock's lines (stickslip.audio.confirm.clocked) removed them
KNOWN: dict[int, str] = {}


def test_a_radio_that_fits_a_stop_that_only_rises_is_off_the_step_clock() -> None:
    """Joint 3's stop only rises (2.5-8.6 dB): a radio as loud as the stepping fits it, and persists.

    The hour's draw 3 begins with a radio at +0.4 dB re the stepping: without the step clock's
    check a false stop at 0.40 s, counted (a wrong count); with it, the fire's window shows
    none of the signature on the lines (``a_L`` under 0.2), and no event.
    """
    h = Hour(Arm(3), dur=3.0, seed=3)
    _, _, kind, level_db = spans(h)[0]
    assert kind == "radio" and level_db == pytest.approx(0.4, abs=0.05)
    tu = joint_tuning(3)
    assert min(tu.signature_db or (0.0,)) > 2.0  # a stop that only rises
    before = hear(h, tu, ConfirmParams(clocked=None))
    assert [(round(e.onset_s, 2), e.onset_uncertain) for e in before] == [(0.40, False)]
    events, det = heard_by(h, tu)
    assert events == []
    judged = [g for _, g in det.log.clocked]
    assert judged and all(abs(g.a) < 0.2 and g.bands == 2 for g in judged)


@pytest.mark.parametrize("rate", [950.0, 1050.0])
def test_at_another_rate_told_a_radio_the_lines_do_not_move_for_is_no_stop(rate: float) -> None:
    """The same radio with the joint stepping 5 % off the tuning's rate, told: the tuned signature is not read for a
    veto there, and the fire was counted (a wrong count); the lines in phase at the commanded rate did not move
    (under ``min_moved_db``: the stepping went on), and that is no stop."""
    h = Hour(Arm(3), rate=rate, dur=3.0, seed=3)
    tu = joint_tuning(3)
    # (the before-case turns ``model_unjudged_early`` off too: with nothing read, it flags this fire as well; and
    # ``onset_short_span``: the fire came before one whole reference of stepping was heard, which flags it too)
    off = replace(CLOCKED, min_moved_db=0.0, model_unjudged_early=False, onset_short_span=False)
    before = hear(h, tu, ConfirmParams(clocked=off))
    assert [e.onset_uncertain for e in before] == [False] and before[0].onset_s < 0.5
    events, det = heard_by(h, tu)
    assert events == []
    judged = [g for _, g in det.log.clocked]
    assert judged and all(g.rate_hz == pytest.approx(rate, rel=0.01) and g.moved_db < 0.5 for g in judged)


def test_the_stream_does_not_depend_on_its_blocks() -> None:
    """Rendered in 1 s or in 0.37 s blocks, the same samples: the filters' states and the events carry over."""
    a = np.concatenate(list(stream(Hour(Arm(2), dur=12.0, seed=5, span_s=(2.0, 4.0)))))
    b = np.concatenate(list(stream(Hour(Arm(2), dur=12.0, seed=5, span_s=(2.0, 4.0), block_s=0.37))))
    assert a.size == b.size == 12 * SR
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_the_levels_are_as_documented() -> None:
    """The stepping at -30 dBFS alone; each span's sound at its level re the stepping (+-2.5 dB: 2-3 voices)."""
    h = Hour(Arm(1), dur=30.0, seed=13, span_s=(4.5, 7.0))
    y = np.concatenate(list(stream(h))).astype(np.float64)
    alone = np.concatenate(list(stream(Hour(Arm(1), dur=30.0, seed=13, span_s=(4.5, 7.0), kinds=("nothing",)))))
    sched = spans(h)
    assert {k for _, _, k, _ in sched} >= set(KINDS[1:])  # every kind of sound plays in the 30 s
    step_db = 20 * np.log10(np.sqrt(np.mean(alone.astype(np.float64) ** 2)))
    assert step_db == pytest.approx(-30.0, abs=0.3)
    for t0, t1, kind, db in sched:
        if t1 - t0 < 4.0:
            continue  # the minute's last span, cut short: a talker may not have begun
        i, j = int((t0 + 0.5) * SR), int((t1 - 0.5) * SR)
        added = y[i:j] - alone[i:j]
        if kind == "nothing":
            assert np.all(added == 0.0)
        else:
            assert 20 * np.log10(np.sqrt(np.mean(added**2))) == pytest.approx(-30.0 + db, abs=2.5), kind


def _known(j: int) -> list[pytest.MarkDecorator]:
    return [pytest.mark.xfail(strict=True, reason=KNOWN[j])] if j in KNOWN else []


@pytest.mark.slow
@pytest.mark.parametrize("joint", [pytest.param(j, marks=_known(j)) for j in JOINTS])
def test_stepping_under_speech_music_and_a_radio_raises_no_stop(joint: int) -> None:
    h = Hour(Arm(joint), dur=40.0, seed=joint, span_s=(4.0, 12.0))
    events = hear(h, joint_tuning(joint))
    where = [(round(e.onset_s, 2), next(k for t0, t1, k, _ in spans(h) if t0 <= e.onset_s < t1)) for e in events]
    assert events == [], f"{len(events)} false stops: {where}"


@pytest.mark.slow  # joint 1's tuning (seconds) is shared with the slow test above; hearing the excerpt takes 0.1 s
def test_music_that_smears_the_only_judged_lines_raises_no_stop() -> None:
    """The hour's counted false stop on joint 1 (music at -0.6 dB), heard from 3.0 s before it.

    A music note 25 dB over the stepping in 1488-1875 Hz decays; the fast path fires (0.46
    against 0.43) and the fire persists 0.5 s. Joint 1's stop moves one sub-band (3750-4219 Hz,
    +12.2 dB), whose one line (4 kHz) the music's partials beside it left not sharp on a comb
    of 0.4 % of its frequency (0.79 < 0.85 of one four times wider): no verdict, and a counted
    false stop. Read on the comb the window resolves (3 bins), the line is sharp (0.92) and did
    not move (a_L 0.02): the fire is vetoed. A fresh detector started 1, 2 or 4-7 s before
    learns another template and hears nothing there; the hour is the check
    (``benchmarks/bench_audio_hour.py``). The target: no unflagged event.
    """
    raw, rate = soundfile.read(EXCERPT, dtype="int16")
    assert rate == SR
    samples = raw.astype(np.float32) / np.float32(32767.0)
    assert samples.shape == (int(3.6 * SR),)
    det = ConfirmedStopDetector(detector_for(joint_tuning(1)))
    det.reset(EXCERPT_T0_S, step_rate_hz=1000.0)
    events = [e for i in range(0, samples.size, SR) for e in det.feed(samples[i : i + SR])] + det.finish()
    counted = [round(e.onset_s, 3) for e in events if not e.onset_uncertain]
    assert counted == [], f"counted false stops at {counted} s; the clocked check: {det.log.clocked}"
    first = det.log.clocked[0][1]  # the fire at 2646.00 s, judged on the one sub-band, vetoed
    assert first.bands == 1 and abs(first.a) < 0.1


def test_20_percent_off_told_music_the_comb_cannot_judge_and_the_lines_do_not_move_for_is_no_stop() -> None:
    """Joint 2 stepping at 1200 Hz (20 % off the tuning's rate, told) under music from the first sample: its tuned
    stop's sub-bands hold no sharp line there, so the comb gives no verdict and nothing vetoed the fires (with
    ``min_pred_moved_db`` 0 and ``model_unjudged`` off: four flagged and one counted in 16 s; with ``model_unjudged``,
    the model never ready under the music, all five flagged). The signature predicted at 1200 Hz moves the
    locked lines 3 dB RMS or more; they moved under 1 dB (the stepping went on), or, once the stepping's lines are
    modelled (``lines_model``), sat within ``model_max_z`` of the model: no stop."""
    h = Hour(Arm(2), rate=1200.0, dur=16.0, seed=2)
    assert spans(h)[0][2] == "music"
    tu = joint_tuning(2)
    no_break = replace(ONSET, break_check=False)  # (the break before the fire flags the counted one too)
    before = hear(
        h, tu, ConfirmParams(clocked=replace(CLOCKED, min_pred_moved_db=0.0, model_unjudged=False), onset=no_break)
    )
    assert [e.onset_uncertain for e in before] == [True, True, True, True, False]
    unjudged = hear(h, tu, ConfirmParams(clocked=replace(CLOCKED, min_pred_moved_db=0.0), onset=no_break))
    assert [(e.onset_s, e.onset_uncertain) for e in unjudged] == [(e.onset_s, True) for e in before]
    events, det = heard_by(h, tu)
    assert events == []
    judged = [g for _, g in det.log.clocked]
    assert judged and all(g.rate_hz == pytest.approx(1200.0, rel=0.01) for g in judged)
    vetoed = [g for g in judged if np.isnan(g.a)]
    assert vetoed and all(g.moved_db < CLOCKED.min_moved_db or g.still_z < CLOCKED.model_max_z for g in vetoed)
    assert any(g.moved_db < CLOCKED.min_moved_db for g in vetoed)  # the per-fire veto before the model is ready
