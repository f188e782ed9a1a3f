"""A pause is not an end stop: when the stepping itself stops, no stop is counted.

At an end stop the controller goes on stepping and the joint still sounds. When the
stepping stops (a pause in a recording, a controller that halted), the sound falls to the
room's, every sub-band drops far more than any stop's signature, and the level detector
fired on it: ``listen`` reported the pause as an unflagged stop, and a traverse whose
controller halted mid-way counted its steps to that moment (``stickslip.audio.confirm.pause``).

The pauses are spliced here from room noise, not rendered by any generator; the stops
come from the battery's generator (``tests/support/battery_sound.py``), the fifth
(``tests/support/arrival_sound.py``) and the seventh (``tests/support/drive_sound.py``: a stop that mutes
the slips while the piezo's drive tone sings on, which falls by more than 20 dB and must
still be heard as a stop).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import arrival_sound as ar  # noqa: E402
import battery_sound as bs  # noqa: E402
import beam_sound as bm  # noqa: E402
import drive_sound as dv  # noqa: E402
import numpy as np
import pytest
import soundfile as sf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)  # noqa: E402
from typer.testing import CliRunner

from stickslip.audio.confirm import CONFIRM_S, ConfirmedStopDetector  # noqa: E402
from stickslip.audio.confirm.pause import PAUSE, step_lines_db, tuned_change_db  # noqa: E402
from stickslip.audio.detector import Tuning, detect, detector_for  # noqa: E402
from stickslip.cli import app  # noqa: E402
from stickslip.procedures.traverse import TraverseError, TraverseResult, measure_traverse  # noqa: E402
from stickslip.sim.arm import SimulatedMM3A  # noqa: E402
from test_audio_onset import whole_and_in_blocks  # noqa: E402

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
TOL_S = 0.025


def _room(seconds: float, seed: int, db: float = -65.0) -> np.ndarray:
    return 10 ** (db / 20) * np.random.default_rng(seed).standard_normal(int(seconds * SR))


_TUNINGS: dict[str, Tuning] = {}


def _battery_tuning(joint: str) -> Tuning:
    if joint not in _TUNINGS:
        x, _ = bs.render(bs.Scene(joint, 1000.0, 2.0, 3.0, seed=1 if joint == "P" else 2))
        _TUNINGS[joint] = tune(x, SR, 2.0, seed=0)
    return _TUNINGS[joint]


def _arrival_tuning() -> Tuning:
    if "arrival" not in _TUNINGS:
        _TUNINGS["arrival"] = tune(ar.render(ar.tuning_scene(ar.Arm(2, "stiff"))), SR, 2.0, seed=0)
    return _TUNINGS["arrival"]


def _beam_tuning() -> Tuning:
    if "beam" not in _TUNINGS:
        _TUNINGS["beam"] = tune(bm.render(bm.tuning_scene(bm.Beam(3))), SR, 2.0, seed=0)
    return _TUNINGS["beam"]


def _stepping(joint: str, seconds: float, seed: int) -> np.ndarray:
    return bs.render(bs.Scene(joint, 1000.0, None, seconds, seed=seed))[0]


@pytest.mark.parametrize("joint", ["P", "Q"])
@pytest.mark.parametrize("pause_s", [0.8, 2.0])
def test_a_pause_in_the_stepping_is_not_a_stop(joint: str, pause_s: float) -> None:
    """Stepping 2 s, the room alone for a while (-65 dB), stepping again: no stop. Before: one at the pause."""
    x = np.concatenate([_stepping(joint, 2.0, 301), _room(pause_s, 7), _stepping(joint, 2.0, 302)])
    det = ConfirmedStopDetector(detector_for(_battery_tuning(joint)))
    assert det.feed(x.astype(np.float32)) + det.finish() == []
    assert det.log.stopped, "the pause fired and was judged the stepping stopping"
    t, why = det.log.stopped[0]
    assert abs(t - 2.0) < 0.05 and why.drop_db < -PAUSE.drop_db and why.line_db < PAUSE.lines_db


def test_traverses_with_pauses_between_them_each_stop_once_on_time() -> None:
    """Four traverses in one file, pauses of 0-1 s between them: every stop that is heard is on time, none at a
    pause. Three generators; the sixth's beam misses its stops at 1020 and 990 Hz, and before, the pause after the
    second of them was confirmed as a stop 0.69 s after it (unflagged)."""
    for tu, make in (
        (
            _battery_tuning("P"),
            lambda r, stop_s, s: bs.render(bs.Scene("P", r, stop_s, stop_s + 0.7, seed=s))[0],
        ),
        (
            _arrival_tuning(),
            lambda r, stop_s, s: ar.render(
                ar.Scene(arm=ar.Arm(2, "stiff"), rate=r, seed=s, stop_at=stop_s, dur=stop_s + 0.7)
            ),
        ),
        (
            _beam_tuning(),
            lambda r, stop_s, s: bm.render(bm.Scene(beam=bm.Beam(3), rate=r, seed=s, stop_at=stop_s, dur=stop_s + 0.7)),
        ),
    ):
        parts, stops, t = [], [], 0.0
        plan = [(1000.0, 1.7, 0.5), (1020.0, 2.3, 0.0), (990.0, 1.2, 1.0), (1000.0, 2.0, 0.3)]
        for k, (rate, stop_s, gap) in enumerate(plan):
            y = np.asarray(make(rate, stop_s, 100 + k), dtype=float)
            parts.append(y)
            stops.append(t + stop_s)
            t += y.size / SR
            if gap:
                parts.append(_room(gap, k, -70.0))
                t += gap
        events = detect(np.concatenate(parts).astype(np.float32), tu, block=1024, confirm_s=CONFIRM_S)  # as listen
        for e in events:
            assert min(abs(e.onset_s - s) for s in stops) <= TOL_S, (e.onset_s, stops)
        assert len(events) >= 2, events  # some may be missed (another rate), never replaced by a pause


def test_a_stop_that_mutes_the_slips_while_the_drive_sings_is_still_a_stop() -> None:
    """Tuned where the muted stop falls 10 dB, tested where it falls 25 dB (the drive 25 dB under the slips): more
    than 20 dB quieter, but the drive's lines stand at the step rate, so it is a stop, on time."""
    arm = dv.Arm(5, "muted")
    tu = tune(dv.render(dv.tuning_scene(arm, -10.0)), SR, 2.0)
    y = dv.render(dv.Scene(arm=arm, rate=1000.0, stop_at=1.6, dur=2.5, drive_db=-25.0, seed=3))
    det = ConfirmedStopDetector(detector_for(tu))
    events = det.feed(y.astype(np.float32)) + det.finish()
    assert len(events) == 1 and abs(events[0].onset_s - 1.6) <= TOL_S and not events[0].onset_uncertain, events
    assert det.log.stopped == []


def test_a_controller_that_halts_mid_traverse_records_nothing() -> None:
    """The simulator steps, then, 3 s into the measured stepping, its sound falls to a live room's (the
    controller halted, the microphone still on): before, the pause was confirmed as the stop and the steps up to
    it counted; now the guard's "no stepping sound" ends the traverse and nothing is recorded."""
    day = "2026-11-22"
    sim = SimulatedMM3A(seed=5, day=day)
    samples, rate, stop_at = sim.labelled_recording(3, "+", before_s=2.0, after_s=1.0)
    tu = tune(samples, rate, stop_at, joint=3)

    def traverse(halt_s: float) -> TraverseResult:
        sim = SimulatedMM3A(seed=5, day=day)
        mic = sim.microphone(block=1024)
        rng = np.random.default_rng(4)

        def blocks() -> Iterator[np.ndarray]:
            while True:
                for b in mic():
                    yield b if sim.clock_s < halt_s else (3e-5 * rng.standard_normal(len(b))).astype(np.float32)

        return measure_traverse(
            sim, 3, "+", detector=detector_for(tu), audio_blocks=blocks(), pose=sim.pose, day=day, burst_steps=1000,
        )  # fmt: skip

    whole = traverse(float("inf"))  # 12338 steps
    first_burst_s = whole.bursts[0][0]
    with pytest.raises(TraverseError, match=r"no stepping sound at \d+ Hz") as e:
        traverse(first_burst_s + 3.0)  # before: 1969 steps recorded, of 12338
    assert "nothing was recorded" in str(e.value)


def test_listen_says_where_the_stepping_stopped(tmp_path: Path) -> None:
    """``listen`` on a recording with a pause reports no stop and says, in one line on stderr, where the stepping
    stopped and how far the sound fell; ``--json`` stays a clean list on stdout."""
    x = np.concatenate([_stepping("P", 2.0, 301), _room(1.0, 7), _stepping("P", 1.0, 302)])
    sf.write(tmp_path / "pause.wav", x, SR, subtype="PCM_16")
    _battery_tuning("P").save(tmp_path / "t.json")
    r = CliRunner().invoke(app, ["listen", str(tmp_path / "pause.wav"), "--tuning", str(tmp_path / "t.json"), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout) == []
    notes = [line for line in r.stderr.splitlines() if "the stepping stopped" in line]
    assert len(notes) == 1 and "at 2.0" in notes[0] and "not an end stop" in notes[0], r.stderr


def test_a_live_listener_says_where_the_stepping_stopped(capsys: pytest.CaptureFixture[str]) -> None:
    """The live path (``listen --mic`` / ``--serial``) prints the same note as the stepping stops, block by block."""
    from stickslip.cli.audio import _report_live

    tu = _battery_tuning("Q")
    x = np.concatenate([_stepping("Q", 2.0, 21), _room(1.2, 8), _stepping("Q", 1.0, 22)]).astype(np.float32)
    det = ConfirmedStopDetector(detector_for(tu))
    closed = []
    _report_live(det, iter(np.array_split(x, 200)), lambda: closed.append(1), tu, True, 0.5, "")
    out, err = capsys.readouterr()
    assert out == "" and closed == [1]
    assert err.count("the stepping stopped at 2.0") == 1, err


@pytest.mark.parametrize("block", [128, 1000, 4096, 65536])
def test_the_pause_judgement_does_not_depend_on_the_block_size(block: int) -> None:
    x = np.concatenate([_stepping("Q", 1.5, 11), _room(1.0, 3), bs.render(bs.Scene("Q", 1000.0, 1.4, 2.0, seed=12))[0]])
    ref, det = whole_and_in_blocks(_battery_tuning("Q"), x.astype(np.float32), block)
    assert [t for t, _ in det.log.stopped] == [t for t, _ in ref.log.stopped] and len(ref.log.stopped) >= 1
    assert det.log.restarts == ref.log.restarts and len(ref.log.restarts) == 1  # where the stepping came back
    assert 2.5 - 0.01 <= ref.log.restarts[0][1] <= 2.5 + 0.01


def test_the_step_lines_read_low_on_noise_and_high_on_stepping() -> None:
    """600 windows of white noise at random rates: 8.8 dB at most (the threshold is 10); stepping: tens of dB."""
    rng = np.random.default_rng(0)
    noise = [step_lines_db(rng.standard_normal(SR // 2), SR, float(rng.uniform(700.0, 1300.0))) for _ in range(600)]
    assert max(noise) < PAUSE.lines_db and 4.0 < float(np.median(noise)) < 7.0
    assert step_lines_db(_stepping("P", 0.6, 5)[: SR // 2], SR, 1000.0) > 20.0
    assert step_lines_db(np.zeros(100), SR, 1000.0) == float("inf")  # too short to judge


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    levels=st.lists(st.floats(-80.0, 0.0), min_size=1, max_size=20),
    shift=st.floats(-30.0, 30.0),
    spread=st.floats(0.0, 20.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_the_tuned_change_lies_within_the_signature_and_is_exact_for_a_flat_one(
    levels: list[float], shift: float, spread: float, seed: int
) -> None:
    """The in-band change is a power-weighted mean of the sub-bands' changes: between their least and greatest,
    and exactly the shift when every sub-band moves alike."""
    sig = shift + spread * np.random.default_rng(seed).uniform(-1.0, 1.0, len(levels))
    got = tuned_change_db(tuple(levels), tuple(float(v) for v in sig))
    assert float(sig.min()) - 1e-9 <= got <= float(sig.max()) + 1e-9
    assert tuned_change_db(tuple(levels), (shift,) * len(levels)) == pytest.approx(shift, abs=1e-9)
    assert tuned_change_db(None, (shift,)) == 0.0 and tuned_change_db((1.0, 2.0), (shift,)) == 0.0
