"""The twelfth generator (``tests/support/crystal_sound.py``): a crystal's step clock, bursts, music on the lines.

Written before the step clock's check was changed for it, and never used to tune the detector.
These tests hold the generator to what it claims (the divided crystal's step times, the bursts'
restarted phase, notes placed on and beside the lines, the level, the same samples in any
blocks) and check that the detector hears its joints' stops at all. What the detector does
over minutes of it is measured in ``benchmarks/bench_audio_hour.py --crystal`` (a
measurement, not a test; ``docs/audio-log.md``).
"""

from __future__ import annotations

import numpy as np
import pytest
from crystal_sound import (
    OFFSETS,
    SR,
    XTAL_HZ,
    Clock,
    Joint,
    Session,
    Stream,
    _note_samples,
    render,
    step_times,
    stream,
    tuning_session,
)
from tuned import tune

from stickslip.audio.detector import detect


def test_steps_keep_the_crystal_s_clock() -> None:
    """In one burst each step is an integer number of the drifting crystal's ticks from the first: what is left
    after the drift (a quadratic over 20 s) is the edges' jitter alone, 20 ns, and it does not accumulate."""
    c = Clock(burst_steps=None)
    t, starts = step_times(c, 20.0, np.random.default_rng(3))
    assert starts.tolist() == [0]
    k = np.arange(t.size, dtype=np.float64)
    left = t - np.polyval(np.polyfit(k, t, 2), k)
    assert 15e-9 < float(np.std(left)) < 25e-9
    # the realised rate: the divider's (16 000 ticks) from the crystal 30 ppm fast, within the 5 ppm drift
    rate = 1.0 / float(np.mean(np.diff(t)))
    assert c.divider() == 16_000
    assert abs(rate / (XTAL_HZ * 1.00003 / 16_000) - 1.0) < 5.5e-6
    # against the random walk of the tenth generator (0.4 % a step): 1000 steps wander 0.13 ms there, 20 ns here
    assert float(np.max(np.abs(left))) < 1e-7


def test_bursts_restart_the_clock_s_phase() -> None:
    """Bursts of 2000 steps, 2-15 ms apart; each starts at its own phase of the clock."""
    c = Clock()
    t, starts = step_times(c, 30.0, np.random.default_rng(4))
    assert np.all(np.diff(starts) == 2000)
    period = c.divider() / XTAL_HZ
    gaps = t[starts[1:]] - t[starts[1:] - 1] - period
    assert np.all((gaps >= 0.002 - 1e-6) & (gaps <= 0.015 + 1e-6))
    phase = np.mod((t[starts] - t[0]) / period, 1.0)  # each burst's start on the first burst's clock, cycles
    assert float(np.std(phase)) > 0.2


def test_notes_are_placed_on_and_beside_the_lines() -> None:
    """A placed note's loudest partial lies on a line k x the realised rate, off by one of ``OFFSETS``; rendered
    alone, a steady one peaks there (to the spectrum's 0.5 Hz bins)."""
    s = Session(Joint(2), dur=60.0, seed=5, kinds=("music on the lines",))
    st = Stream(s)
    rate = s.clock.realised_hz()
    placed = [n for n in st.notes if max(n.amps) > 1.5 * n.amps[0] or n.amps[0] > 2 * n.amps[1]]
    assert len(placed) > 20
    offs = set()
    for n in placed:
        m = int(np.argmax(n.amps)) + 1
        k = round(m * n.f0 / rate)
        off = m * n.f0 / (k * rate) - 1.0
        assert 1500.0 <= k * rate <= 12_000.0 + rate
        near = min(OFFSETS, key=lambda o: abs(abs(off) - o))
        assert abs(abs(off) - near) < 1e-9
        offs.add(near)
    assert offs == set(OFFSETS)
    steady = next(n for n in placed if n.vib == 0.0 and n.dur > 1.0 and int(np.argmax(n.amps)) == 0)
    i0 = int(steady.t0 * SR)
    z = _note_samples(steady, i0, 2 * SR)
    spec = np.abs(np.fft.rfft(z * np.hanning(z.size)))
    f = np.fft.rfftfreq(z.size, 1 / SR)
    assert abs(f[int(np.argmax(spec))] - steady.f0) <= 0.5


def test_same_samples_in_any_blocks_and_the_level() -> None:
    """The stream is the same in 1 s and 0.37 s blocks; the stepping is -30 dBFS RMS (one joint, no music)."""
    s = Session(Joint(1), dur=4.0, seed=2)
    a = np.concatenate(list(stream(s, 1.0)))
    b = np.concatenate(list(stream(s, 0.37)))
    assert a.size == b.size == 4 * SR
    assert float(np.max(np.abs(a - b))) < 1e-9
    quiet = render(Session(Joint(3), dur=3.0, seed=2, kinds=("nothing",)))
    assert abs(20 * np.log10(float(np.sqrt(np.mean(quiet**2)))) + 30.0) < 0.5


@pytest.mark.parametrize("joint", [3])
def test_the_joint_s_stop_is_heard(joint: int) -> None:
    """Tuned on its own quiet recording, the detector hears the joint's stop there within 10 ms (the stop at 2 s)."""
    x = render(tuning_session(Joint(joint)))
    tu = tune(x, SR, 2.0)
    ev = detect(x, tu)
    assert len(ev) == 1
    assert abs(ev[0].onset_s - 2.0) < 0.01
    assert not ev[0].onset_uncertain
