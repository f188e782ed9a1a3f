"""With the rate told, once the stepping's clock was heard at the told rate, the lines are read there.

The twelfth generator's joint 3 (``tests/support/crystal_sound.py``: a divided crystal's step clock in bursts,
music placed on and beside the lines, 0 to +6 dB) steps at 1100 Hz, told (the tuning's rate: 1000 Hz), into its
stop at 12 s. Music near the lines pulled the line found near the told rate 0.7-0.8 % off it over the first two
seconds (1107-1109 Hz), so the stepping's lines model was built at 1108.17 Hz and read every span there; the
stop's own fire, 0.25 s into the stop, was read against a reference holding the stop's beginning, its clock found
at 1064.4 Hz, and the model (z 12.4) let it through: counted 253 ms late. With ``ClockedParams.told_held_tol``
the span ending at 5.28 s, heard 0.05 % off 1100 Hz with 0.90 of its lines' power in phase there, holds the clock
at the told rate: the model is built again at 1100 Hz (not ready by 12.25 s) and the fire read at 1100 Hz gives
no verdict, so the stop is flagged (``model_unjudged``). The false stop counted at 4.032 s (read at 1099.95 Hz,
the lines moved 1.40 dB) comes before the clock is held: it is flagged by ``ClockedParams.model_confirmed_early``
(held past its window, its lines read back within ``model_max_z`` of the spans before it), either way.
"""

from __future__ import annotations

import crystal_sound as cs
import numpy as np
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.confirm.clocked import ClockedCheck, ClockedParams
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent
from stickslip.audio.tuningfile import Tuning

RATE = 1100.0
SR = cs.SR


def _tuned() -> Tuning:
    return tune(cs.render(cs.tuning_session(cs.Joint(3))), SR, 2.0)


def _heard(tols: tuple[float, ...]) -> list[list[StopEvent]]:
    """The run's events with each ``told_held_tol`` of ``tols`` (the same samples)."""
    tu = _tuned()
    s = cs.Session(
        cs.Joint(3), cs.Clock(rate=RATE), dur=14, stop_at=12, seed=1, kinds=("music",), span_s=(30, 40), music_db=(0, 6)
    )
    x = np.asarray(cs.render(s), dtype=np.float32)
    out = []
    for tol in tols:
        det = ConfirmedStopDetector(detector_for(tu), params=ConfirmParams(clocked=ClockedParams(told_held_tol=tol)))
        det.reset(0.0, step_rate_hz=RATE)
        out.append(det.feed(x) + det.finish())
    return out


def test_a_stop_read_at_a_clock_pulled_off_the_told_rate_is_flagged() -> None:
    before, after = _heard((0.0, ClockedParams().told_held_tol))
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in before] == [
        (1.978, True),
        (4.032, True),  # a false stop, 8 s before the stop: flagged (model_confirmed_early), not the clock
        (12.253, False),  # counted: the stop 253 ms late
    ]
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in after] == [(1.978, True), (4.032, True), (12.253, True)]
    assert after[2].detected_at_s == before[2].detected_at_s  # the same fire, flagged


def _stepping(rate_hz: float, n: int, jitter: float = 0.0) -> np.ndarray:
    """Clicks at ``rate_hz`` (a decaying 3 kHz burst each) over ``n`` samples: stepping alone; each interval drawn
    with ``jitter`` (share, one standard deviation; 0: a clean clock)."""
    x = np.zeros(n)
    k = np.arange(int(0.004 * SR)) / SR
    click = np.sin(2 * np.pi * 3000.0 * k) * np.exp(-k / 0.001)
    steps = int(n / SR * rate_hz) + 1
    dt = (1.0 + jitter * np.random.default_rng(5).standard_normal(steps)) / rate_hz
    times = np.cumsum(dt) - dt[0]
    for t0 in times[times < n / SR - 0.005]:
        i = int(round(t0 * SR))
        x[i : i + click.size] += click
    return x


def test_the_clock_is_held_at_the_told_rate_only_once_heard_there_in_phase() -> None:
    tu = _tuned()
    c = ClockedCheck(tu, ClockedParams())
    c.reset(RATE)
    assert c.models_lines() and not c.held
    n = int(0.48 * SR)
    rough = _stepping(RATE, n, jitter=0.03)  # a rough clock heard near the told rate, its lines smeared: not held
    assert abs(c.hear_held(rough) / RATE - 1.0) <= c.p.told_held_tol and not c.held
    off = c.hear_held(_stepping(RATE * 1.008, n))  # a line 0.8 % off: not the told rate, not held
    assert abs(off / RATE - 1.008) < 0.002 and not c.held
    assert c.hear_held(_stepping(RATE, n)) == RATE and c.held  # heard at the told rate, in phase there: held
    assert c.hear_held(_stepping(RATE * 1.008, n)) == RATE  # a line found off it later: the told rate read
    never = ClockedCheck(tu, ClockedParams(told_held_tol=0.0))
    never.reset(RATE)
    assert abs(never.hear_held(_stepping(RATE, n)) / RATE - 1.0) < 0.002 and not never.held  # (0: not)
