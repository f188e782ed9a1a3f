"""The step's drift within a session (calibration.drift; docs/models.md §4), on constructed tables."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from analysis_tables import simulated_table

from stickslip.calibration import Calibration, calibrate
from stickslip.calibration.drift import EndBias, end_bias, session_drift
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
    assert dr.late == (rows[8],)  # the session's end: the first pose's + traversed again
    sd = math.sqrt(2 * STEP_NOISE**2 / STEPS) / 8
    assert dr.rate_sd == pytest.approx(sd, rel=1e-9)
    minus = session_drift(rows, 3, "-", STEP_NOISE)
    assert minus is not None and minus.rate == pytest.approx(rate, rel=1e-9) and minus.late == (rows[9],)


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


def test_the_end_bias_is_the_residual_beyond_the_models_own_misfit() -> None:
    """Empirical Bayes (calibration.drift): the posterior mean and sd of the bias, whose squares sum to
    ``max(0, mean(e)^2 - floor^2 / k)``."""
    b = end_bias([0.02, 0.03, np.nan], 0.01)  # the non-finite residual is left out
    s2, tau2 = 0.01**2 / 2, 0.025**2 - 0.01**2 / 2
    assert (b.residual, b.repeats) == (pytest.approx(0.025), 2) and b.misfit == pytest.approx(math.sqrt(s2))
    assert b.bias == pytest.approx(0.025 * tau2 / (tau2 + s2), rel=1e-12)
    assert b.bias_sd == pytest.approx(math.sqrt(s2 * tau2 / (tau2 + s2)), rel=1e-12)
    assert b.term**2 == pytest.approx(tau2, rel=1e-12)
    # within the misfit a calibrated pose has anyway: no term; no residual: none
    assert end_bias([-0.009], 0.01).term == 0.0 and end_bias([-0.009], 0.01).residual == pytest.approx(-0.009)
    assert end_bias([], 0.01) == end_bias([np.inf], 0.01) == EndBias(0.0, 0.0, 0.0, 0.0, 0)


def _with_repeat(scale_first: float, scale_rest: float) -> tuple[list[Traverse], Traverse]:
    """Joint 3 at 12 poses, + then - at each, steps of a constant size per direction with 0.3 % scatter
    (the constant family fits them but for it); the first traverse's step times ``scale_first``, the
    others' times ``scale_rest``, and the first pose's + traversed again at the end at its true step."""
    rng = np.random.default_rng(5)
    truth = [_row(d, -0.25 * p, (1e-6 if d == "+" else 0.9e-6) * (1.0 + 0.003 * float(rng.standard_normal())))
             for p in range(12) for d in "+-"]
    rows = [_row(r.direction, r.q2, r.gamma * (scale_first if k == 0 else scale_rest)) for k, r in enumerate(truth)]
    return [*rows, truth[0]], truth[0]


def test_a_drift_the_fit_absorbs_adds_nothing_and_one_it_cannot_is_recovered() -> None:
    # a cold first traverse (3 % further) among warm ones: the drift is there, the fit hardly keeps it
    rows, first = _with_repeat(1.03, 1.0)
    cal = calibrate(rows, model="constant")
    dr = session_drift(rows, 3, "+", STEP_NOISE)
    assert dr is not None and dr.change == pytest.approx(-math.log(1.03), abs=1e-4) and dr.late == (rows[-1],)
    pr = cal.predictive[(3, "+")]
    assert (pr.drift, pr.drift_sd) == (0.0, 0.0)
    assert any("traversed again" in n and "3+" in n and "add the bias beyond it, 0.00 %" in n
               for n in cal.provenance.notes)
    # the whole calibration 2 % further than the step at the session's end: the fit keeps it all
    rows, first = _with_repeat(1.02, 1.02)
    cal = calibrate(rows, model="constant")
    pr = cal.predictive[(3, "+")]
    resid = float(cal.predict_many([first])[0] / first.gamma - 1.0)
    assert (pr.drift, pr.drift_sd) == pytest.approx(
        (end_bias([resid], pr.floor).bias, end_bias([resid], pr.floor).bias_sd), rel=1e-12)
    # the fit's actual bias at the session's end, over the calibrated poses
    plus = [r for r in rows[:-1] if r.direction == "+"]
    truth = float(np.mean(cal.predict_many(plus) / np.array([r.gamma / 1.02 for r in plus]) - 1.0))
    assert truth == pytest.approx(0.02 * 12 / 13, abs=0.002)  # the fit keeps 12 of its 13 traverses' drift
    assert abs(pr.drift - truth) < 2.0 * pr.drift_sd and 0.001 < pr.drift_sd < 0.006
    assert cal.predictive[(3, "-")].drift == 0.0  # no - traverse repeated
    # the interval: the error model's sd and the bias in quadrature, at any pose; kept in the file
    q2 = np.linspace(-3.0, 0.0, 7)
    zero = np.zeros_like(q2)
    without = dataclasses.replace(cal, predictive={**cal.predictive, (3, "+"): dataclasses.replace(pr, drift=0.0,
                                                                                                    drift_sd=0.0)})
    sd = relative_sd(cal, 3, "+", zero, q2, zero, zero, zero)
    sd0 = relative_sd(without, 3, "+", zero, q2, zero, zero, zero)
    np.testing.assert_allclose(sd, np.hypot(sd0, math.hypot(pr.drift, pr.drift_sd)), rtol=1e-12)
    back = Calibration.from_dict(cal.to_dict()).predictive[(3, "+")]
    assert (back.drift, back.drift_sd) == (pr.drift, pr.drift_sd)


def test_without_a_repeat_there_is_no_term_and_calibrate_says_how_to_measure_it() -> None:
    rows = [r for r in simulated_table(3) if r.joint == 3]
    plain = calibrate(rows, model="constant")
    cal = calibrate([*rows, rows[0]], model="constant")
    assert plain.predictive[(3, "+")].drift == 0.0 and plain.predictive[(3, "+")].drift_sd == 0.0
    assert plain.provenance.notes.count(NO_REPEAT_NOTE) == 1 and NO_REPEAT_NOTE not in cal.provenance.notes
    assert "drift" not in str(plain.to_dict()["uncertainty"])  # files without a repeat are as before
