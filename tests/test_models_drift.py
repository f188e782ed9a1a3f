"""The step's drift within a session (calibration.drift; docs/models.md §4), on constructed tables."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from analysis_tables import simulated_table

from stickslip.calibration import Calibration, calibrate
from stickslip.calibration.drift import session_drift
from stickslip.calibration.intervals import STEP_NOISE, relative_sd
from stickslip.calibration.selection import NO_REPEAT_NOTE
from stickslip.measurements import Traverse

DAY = "2026-10-05"
STEPS = 12_000


def _row(direction: str, q2: float, gamma: float, day: str = DAY, q3: float = 0.0) -> Traverse:
    """A traverse of joint 3 at (q2, theta = psi = 0) whose average step is exactly ``gamma`` (m)."""
    span = gamma * STEPS
    start, end = (0.0, span) if direction == "+" else (span, 0.0)
    return Traverse(day, 3, direction, 0.0, q2, q3, 0.0, 0.0, start, end, STEPS)


def _session(order: list[int], rate: float, rng: np.random.Generator | None = None, noise: float = 0.0,
             day: str = DAY) -> list[Traverse]:
    """Joint 3 at the poses ``order`` (indices), + then - at each; the k-th traverse steps
    ``exp(rate k)`` times its pose's step (a linear drift of the log per traverse), times ``1 + noise N(0, 1)``."""
    rows = []
    for p in order:
        for d in "+-":
            g0 = (1.0 + 0.1 * p) * (1e-6 if d == "+" else 0.9e-6)
            e = 0.0 if rng is None else noise * float(rng.standard_normal())
            rows.append(_row(d, -0.2 * p, g0 * math.exp(rate * len(rows)) * (1.0 + e), day,
                             q3=0.001 * len(rows)))  # the moving joint's own column differs: ignored
    return rows


def test_one_repeat_gives_the_drift_exactly_with_the_step_scatter_as_its_uncertainty() -> None:
    rate = -1.5e-3  # per traverse: -1.2 % over the 8 traverses between the first pose and its repeat
    rows = _session([0, 1, 2, 3, 0], rate)
    dr = session_drift(rows, 3, "+", STEP_NOISE)
    assert dr is not None and dr.pairs == 1
    assert dr.rate == pytest.approx(rate, rel=1e-9)
    assert dr.span == 8.0 and dr.change == pytest.approx(8 * rate, rel=1e-9)
    # the + traverses are the 1st, 3rd, ... 9th of 10: 9, 7, 5, 3, 1 traverses of the joint after each
    assert dr.bias == pytest.approx(-5 * rate, rel=1e-9)
    sd = math.sqrt(2 * STEP_NOISE**2 / STEPS) / 8
    assert dr.rate_sd == pytest.approx(sd, rel=1e-9)
    assert dr.bias_sd == pytest.approx(5 * sd, rel=1e-9)
    assert dr.term == pytest.approx(math.hypot(dr.bias, dr.bias_sd), rel=1e-12)
    minus = session_drift(rows, 3, "-", STEP_NOISE)
    assert minus is not None and minus.rate == pytest.approx(rate, rel=1e-9) and minus.bias == pytest.approx(-4 * rate)


def test_no_repeat_within_a_day_gives_no_drift() -> None:
    assert session_drift(_session([0, 1, 2, 3], -1e-3), 3, "+") is None
    # the same pose on two days is two sessions, not a repeat; another joint's rows are not this joint's
    two_days = _session([0, 1], -1e-3, day="2026-10-05") + _session([0, 1], -1e-3, day="2026-10-06")
    assert session_drift(two_days, 3, "+") is None
    assert session_drift(_session([0, 1, 0], -1e-3), 2, "+") is None


def test_the_drift_is_recovered_within_its_stated_uncertainty() -> None:
    """400 sessions of 8 poses traversed twice, 0.3 % scatter per traverse: the rate's estimates
    scatter about the true rate as their standard errors say (7 degrees of freedom each)."""
    rate, rng = -5e-4, np.random.default_rng(7)
    est, sds = [], []
    for _ in range(400):
        dr = session_drift(_session(list(range(8)) * 2, rate, rng, 0.003), 3, "+")
        assert dr is not None and dr.pairs == 8
        est.append(dr.rate)
        sds.append(dr.rate_sd)
    est_a, sd_rms = np.array(est), float(np.sqrt(np.mean(np.square(sds))))
    assert abs(est_a.mean() - rate) < 3 * est_a.std() / math.sqrt(len(est_a))  # unbiased
    assert 0.85 < est_a.std() / sd_rms < 1.15  # the stated uncertainty is the actual one
    assert abs(est_a.mean() - rate) < 0.1 * abs(rate)


def test_a_calibration_with_a_repeat_widens_its_intervals_by_the_drift_and_keeps_it() -> None:
    rows = [r for r in simulated_table(3) if r.joint == 3]
    first = rows[0]
    repeat = dataclasses.replace(first, steps=round(first.steps * 1.01))  # 1 % smaller step, warm
    plain = calibrate(rows, model="constant")
    cal = calibrate([*rows, repeat], model="constant")
    assert plain.predictive[(3, "+")].drift == 0.0 and plain.predictive[(3, "+")].drift_sd == 0.0
    dr = session_drift([*rows, repeat], 3, "+", STEP_NOISE)
    assert dr is not None and dr.change == pytest.approx(math.log(first.steps / repeat.steps), rel=1e-12)
    pr = cal.predictive[(3, "+")]
    assert (pr.drift, pr.drift_sd) == (dr.bias, dr.bias_sd) and pr.drift > 0.0
    assert cal.predictive[(3, "-")].drift == 0.0  # no - traverse was repeated
    assert any("traversed again" in n and "3+" in n for n in cal.provenance.notes)
    # without a repeat calibrate says once that the intervals leave the drift out, and how to measure it
    assert plain.provenance.notes.count(NO_REPEAT_NOTE) == 1 and NO_REPEAT_NOTE not in cal.provenance.notes
    # the interval: the error model's sd and the drift in quadrature, at any pose
    q2 = np.linspace(-3.0, 0.0, 7)
    zero = np.zeros_like(q2)
    without = dataclasses.replace(cal, predictive={**cal.predictive, (3, "+"): dataclasses.replace(pr, drift=0.0,
                                                                                                    drift_sd=0.0)})
    sd = relative_sd(cal, 3, "+", zero, q2, zero, zero, zero)
    sd0 = relative_sd(without, 3, "+", zero, q2, zero, zero, zero)
    np.testing.assert_allclose(sd, np.hypot(sd0, math.hypot(pr.drift, pr.drift_sd)), rtol=1e-12)
    back = Calibration.from_dict(cal.to_dict()).predictive[(3, "+")]
    assert (back.drift, back.drift_sd) == (pr.drift, pr.drift_sd)
    assert "drift" not in str(plain.to_dict()["uncertainty"])  # files without a repeat are as before
