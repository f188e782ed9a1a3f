"""The piezo's drive sings through the stop: a seventh generator (``tests/support/drive_sound.py``, session 27).

A stick-slip controller's sawtooth makes the piezo and its mount sing at the step rate and
its harmonics, strictly periodic, whether or not the slider moves; only the slider's slips
change at the stop (``blocked``: weaker, and the stop's contact mode rings; ``muted``: all
but gone; ``spectral``: modes moved up and damped, same energy). Never used to tune the
detector. What it found:

* the detector hears the stop under a drive from 10 dB under to 10 dB over the slips, at
  the tuning's rate; ``tune`` refuses three arms where the drive is 10 dB over the slips
  and the stop changes the whole by little (a clear refusal);
* **a false "listening began at the stop"**: slips that jitter less than the tuning's (3-6
  against 15 µs) lose continuum between the clock's lines where they dominate, the shape a
  stop that silences them has; the continuum alone called stepping a stop at 950, 1000 and
  1050 Hz, the confirmed count silently 1.5 s short, while the line levels gave the stop
  b -0.08 to 0.05. The continuum's verdict now needs the levels not to deny it
  (``StartParams.continuum_levels_b``).

Outcomes as a traverse counts them: the confirmed first event's onset within 25 ms is
*right*; flagged ``onset_uncertain`` a refusal (measure again); more than 25 ms off without
the flag *silently wrong*; no event *missed* (the traverse times out: safe).
"""

from __future__ import annotations

from functools import cache

import drive_sound as dv
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.detector import detector_for
from stickslip.audio.tuning import TuningError
from stickslip.audio.tuningfile import Tuning

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = dv.SR
TOL_S = 0.025


def _events(tu: Tuning, y: np.ndarray) -> list[tuple[float, bool]]:
    det = ConfirmedStopDetector(detector_for(tu))
    return [(e.onset_s, e.onset_uncertain) for e in det.feed(np.asarray(y, dtype=np.float32)) + det.finish()]


def _outcome(tu: Tuning, y: np.ndarray, stop_at: float) -> str:
    ev = _events(tu, y)
    if not ev:
        return "missed"
    onset, doubted = ev[0]
    if doubted:
        return "flagged"
    return "early" if onset - stop_at < -TOL_S else "late" if onset - stop_at > TOL_S else "right"


@cache
def _tuning(arm: int, kind: str, drive_db: float) -> Tuning | None:
    try:
        return tune(dv.render(dv.tuning_scene(dv.Arm(arm, kind), drive_db)), SR, 2.0)
    except TuningError:
        return None


def test_the_drive_is_the_same_before_and_after_the_stop_and_sings_at_the_exact_rate() -> None:
    """The generator's premise: the stop changes only the slips; the drive is a line spectrum at the exact rate."""
    arm = dv.Arm(3, "muted")
    # both levelled on their first 1.5 s, all stepping
    with_stop = dv.render(dv.Scene(arm=arm, rate=1015.0, stop_at=1.5, dur=2.5, drive_db=6.0, seed=5))
    without = dv.render(dv.Scene(arm=arm, rate=1015.0, stop_at=None, dur=2.5, drive_db=6.0, seed=5))
    k0 = int(1.5 * SR)
    assert np.max(np.abs(with_stop[:k0] - without[:k0])) <= 1e-12 * np.max(np.abs(without))
    late = slice(k0 + SR // 10, int(2.5 * SR))
    assert np.sqrt(np.mean((with_stop[late] - without[late]) ** 2)) > 0.3 * np.sqrt(np.mean(without[late] ** 2))
    # 1 s at 1015 Hz is 1015 whole periods: every bit of the drive's power sits on a multiple of 1015 Hz
    drive = dv._drive(dv.Scene(rate=1015.0), dv._draws(arm), SR, SR)
    p = np.abs(np.fft.rfft(drive)) ** 2
    assert p[1015::1015].sum() / p.sum() > 1 - 1e-9


@pytest.mark.parametrize("jitter_us", [3.0, 5.0])
@pytest.mark.parametrize("rate", [950.0, 1000.0, 1050.0])
def test_slips_that_jitter_less_than_the_tunings_are_not_a_stop_at_the_start(rate: float, jitter_us: float) -> None:
    """Arm 2, muted stop, the drive 6 dB under the slips, tuned with 15 us of jitter: today's stop, on time (main before
    session 27: a stop at the start of listening, 1.5 s early and unflagged, in five of the six)."""
    tu = _tuning(2, "muted", -6.0)
    assert tu is not None
    y = dv.render(
        dv.Scene(arm=dv.Arm(2, "muted"), rate=rate, stop_at=1.5, dur=2.4, drive_db=-6.0, jitter_us=jitter_us, seed=60)
    )
    assert _outcome(tu, y, 1.5) == "right"


# measured at 1000 Hz with this file's draws (session 27): right in all but these (kind, drive dB): flagged
FLAGGED_AT_THE_RATE = {("spectral", -10.0): 1}


@pytest.mark.parametrize("kind", dv.KINDS)
def test_every_stop_under_the_drive_at_the_tunings_rate_is_right_and_stepping_never_fires(kind: str) -> None:
    """Arms 1-3, the drive -10 to +10 dB re the slips, two recordings each at 1000 Hz (stop 1.5-2.5 s, jitter 5-30 us,
    SNR 25-40 dB) and 4 s of stepping: no silent error, no confirmed event on stepping, and every stop right but those
    measured flagged (refused tunings are clear refusals: counted, at most the 3 of 36 measured)."""
    counts: dict[str, int] = {}
    refused = 0
    for drive_db in (-10.0, 0.0, 6.0, 10.0):
        for arm in (1, 2, 3):
            tu = _tuning(arm, kind, drive_db)
            if tu is None:
                refused += 1
                continue
            rng = np.random.default_rng(1000 * arm + int(drive_db) + 50)
            for j in range(2):
                stop = float(rng.uniform(1.5, 2.5))
                scene = dv.Scene(
                    arm=dv.Arm(arm, kind),
                    stop_at=stop,
                    dur=stop + 0.9,
                    drive_db=drive_db,
                    jitter_us=float(rng.uniform(5.0, 30.0)),
                    snr_db=float(rng.uniform(25.0, 40.0)),
                    seed=100 * arm + j,
                )
                o = _outcome(tu, dv.render(scene), stop)
                counts[o] = counts.get(o, 0) + 1
            stepping = dv.Scene(arm=dv.Arm(arm, kind), stop_at=None, dur=4.0, drive_db=drive_db, seed=arm + 55)
            assert _events(tu, dv.render(stepping)) == [], (kind, drive_db, arm)
    flagged = sum(n for (k, _), n in FLAGGED_AT_THE_RATE.items() if k == kind)
    assert counts.get("early", 0) == counts.get("late", 0) == 0, counts
    assert counts.get("flagged", 0) <= flagged and counts.get("missed", 0) == 0, counts
    assert refused <= 1, refused


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    arm=st.integers(1, 10_000),
    kind=st.sampled_from(dv.KINDS),
    drive_db=st.floats(-10.0, 10.0),
    jitter_us=st.floats(2.0, 40.0),
    rate=st.floats(950.0, 1050.0),
    seed=st.integers(0, 10_000),
)
def test_under_any_drive_a_stop_is_never_counted_silently_wrong(
    arm: int, kind: str, drive_db: float, jitter_us: float, rate: float, seed: int
) -> None:
    """Any arm, stop, drive level, jitter and rate within the tuning's +-5 %: the first confirmed event is right,
    flagged or missing (a refusal or a timeout), never silently early or late."""
    try:
        tu = tune(dv.render(dv.tuning_scene(dv.Arm(arm, kind), drive_db)), SR, 2.0)
    except TuningError:
        return  # a clear refusal
    scene = dv.Scene(
        arm=dv.Arm(arm, kind), rate=rate, stop_at=1.6, dur=2.5, drive_db=drive_db, jitter_us=jitter_us, seed=seed
    )
    assert _outcome(tu, dv.render(scene), 1.6) in ("right", "flagged", "missed")
