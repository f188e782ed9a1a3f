"""With the rate told, once the stepping's clock was heard at the told rate, the lines are read there.

The twelfth generator's joint 3 (``tests/support/crystal_sound.py``: a divided crystal's step clock in bursts,
music placed on and beside the lines, 0 to +6 dB) steps at 1100 Hz, told (the tuning's rate: 1000 Hz), into its
stop at 12 s. Music near the lines pulls the line found near the told rate 0.7-0.8 % off it over the first two
seconds (1107-1109 Hz), so the stepping's lines model was built at 1108.17 Hz and the fire at 1.98 s was read at
1108.89 Hz (no verdict: flagged). The stop's own fire, 0.25 s late, was read against a reference holding the
stop's beginning, its clock found at 1064.4 Hz. Without ``ClockedParams.told_held_tol`` this run counted a false
stop at 4.032 s and the stop 253 ms late; with it (the clock heard within 0.2 % of 1100 Hz in the span ending at
2.40 s) the fire at 1.98 s is read at 1100 Hz and vetoed (its lines moved 0.78 dB, ``min_moved_db`` 1), and the
stop is found inside a vetoed window at 12.004 s, flagged.
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


def test_the_lines_read_at_the_told_rate_mend_a_false_stop_and_a_late_stop() -> None:
    before, after = _heard((0.0, ClockedParams().told_held_tol))
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in before] == [
        (1.978, True),
        (4.032, False),  # counted: a false stop, 8 s before the stop
        (12.253, False),  # counted: the stop 253 ms late
    ]
    assert [(round(e.onset_s, 3), e.onset_uncertain) for e in after] == [(12.004, True)]
    assert after[0].found_late


def _stepping(rate_hz: float, n: int) -> np.ndarray:
    """Clicks at ``rate_hz`` (a decaying 3 kHz burst each) over ``n`` samples: stepping alone."""
    t = np.arange(n) / SR
    x = np.zeros(n)
    k = np.arange(int(0.004 * SR)) / SR
    click = np.sin(2 * np.pi * 3000.0 * k) * np.exp(-k / 0.001)
    for t0 in np.arange(0.0, t[-1] - 0.005, 1.0 / rate_hz):
        i = int(round(t0 * SR))
        x[i : i + click.size] += click
    return x


def test_the_clock_is_held_at_the_told_rate_only_once_heard_there() -> None:
    tu = _tuned()
    c = ClockedCheck(tu, ClockedParams())
    c.reset(RATE)
    assert c.models_lines() and not c.held
    n = int(0.48 * SR)
    off = c.hear_held(_stepping(RATE * 1.008, n))  # a line 0.8 % off: not the told rate, not held
    assert abs(off / RATE - 1.008) < 0.002 and not c.held
    assert c.hear_held(_stepping(RATE, n)) == RATE and c.held  # heard at the told rate: held
    assert c.hear_held(_stepping(RATE * 1.008, n)) == RATE  # a line found off it later: the told rate read
    never = ClockedCheck(tu, ClockedParams(told_held_tol=0.0))
    never.reset(RATE)
    assert abs(never.hear_held(_stepping(RATE, n)) / RATE - 1.0) < 0.002 and not never.held  # (0: not)
