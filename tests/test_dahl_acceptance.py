"""Issue 33's acceptance on the Dahl arm (tests/support/dahl_arm.py), which the fitting was not developed on.

The arm (Dahl friction, Hertzian contact compliance, a static anisotropic mount) was written
before the selection, the fallback rule and the intervals of issue 33 were, and nothing was
tuned on it. Per day: the paper's 14 calibration traverses, 32 more at poses spread over the
load space, 32 validation traverses at random poses. A small sample (one seed, three days);
the full numbers, three arms × 3 seeds × 3 days, are in benchmarks/bench_models.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from arm_days import make_day

from stickslip.calibration import calibrate
from stickslip.calibration.intervals import relative_sd

DAYS = ("2026-10-05", "2026-10-06", "2026-10-07")
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("dahl_acceptance")]  # about 5 s, its days fitted once


@pytest.fixture(scope="module")
def days():
    rng = np.random.default_rng(5)
    out = []
    for day in DAYS:
        d = make_day("dahl", 5, day, rng)
        out.append((d, calibrate(d.paper14), calibrate(d.calibration46, model="auto")))
    return out


def _errors(cal, ts):
    return np.array([cal.predict(t) / t.gamma - 1.0 for t in ts])


def test_auto_is_the_model_expected_to_err_less_at_new_poses_and_keeps_its_promise(days):
    # the rule: auto returns the average unless its error expected at new poses (its residuals and its
    # held-out errors, through the intervals' error model) is above the paper's form's; then the paper's
    # form, and it says so
    for _, _, auto in days:
        for (j, d), sel in auto.selection.items():
            if "expected_rms" not in sel:  # nothing compared: the paper's form alone
                assert sel["chosen"].startswith("paper") and not sel["fallback"], (j, d, sel["reason"])
                continue
            avg, paper = sel["expected_rms"]["average"], sel["expected_rms"]["paper"]
            assert sel["fallback"] == (avg > paper), (j, d, sel["reason"])
            if sel["fallback"]:
                assert sel["chosen"].startswith("paper") and "paper's form" in sel["reason"]
    # the promise, at the random validation poses: the model returned erred no more than the paper's form
    # (least squares on the same traverses), and the paper's form erred about as expected. Measured on these
    # days (no fallback): RMS 1.62 against 2.09 % prismatic, 0.55 against 0.57 % rotary; the form's expected
    # error over its actual RMS 1.6 and 1.2
    form = [calibrate(d.calibration46, method="lsq") for d, _, _ in days]
    for j in (3, 2):
        ts = [[t for t in d.validation if t.joint == j] for d, _, _ in days]
        a = np.concatenate([_errors(auto, t) for (_, _, auto), t in zip(days, ts, strict=True)])
        f = np.concatenate([_errors(c, t) for c, t in zip(form, ts, strict=True)])
        assert np.sqrt(np.mean(a**2)) <= np.sqrt(np.mean(f**2)), j
        promised = np.sqrt(np.mean([auto.selection[(j, s)]["expected_rms"]["paper"] ** 2
                                    for _, _, auto in days for s in "+-"]))
        assert 0.5 <= promised / np.sqrt(np.mean(f**2)) <= 2.0, (j, promised)


def test_auto_predicts_new_poses_better_than_the_papers_procedure(days):
    for j in (3, 2):
        a = np.concatenate([_errors(auto, [t for t in d.validation if t.joint == j]) for d, _, auto in days])
        p = np.concatenate([_errors(p14, [t for t in d.validation if t.joint == j]) for d, p14, _ in days])
        assert np.sqrt(np.mean(a**2)) < np.sqrt(np.mean(p**2)), j
        assert np.max(np.abs(a)) <= np.max(np.abs(p)), j  # the worst of these days, not above the paper's
        assert np.max(np.abs(a)) <= (0.075 if j == 3 else 0.035), j


def test_intervals_cover_new_poses_and_the_printed_error_is_honest(days):
    for j in (3, 2):
        inside, z, expected, actual = [], [], [], []
        for d, _, auto in days:
            for s in "+-":
                ts = [t for t in d.validation if t.joint == j and t.direction == s]
                e = _errors(auto, ts)
                sd = relative_sd(auto, j, s, *(np.array([getattr(t, k) for t in ts])
                                               for k in ("q1", "q2", "q3", "theta", "psi")))
                inside += list(np.abs(e) <= 1.96 * sd)
                z += list(e / sd)
                expected.append(auto.sigma_model[(j, s)])
                actual.append(np.sqrt(np.mean(e**2)))
        coverage = np.mean(inside)
        # 48 traverses a joint: the arm held 77-81 %; on these days 97.9 % prismatic, 93.8 % rotary
        assert coverage >= 0.85, (j, coverage)
        # and not wide: standardized errors of a calibrated interval have an RMS near 1 (measured 0.75
        # prismatic, 1.02 rotary on these days with the error growing as the distance squared; 0.79 with
        # joint 3's maximin design; 0.71 and 0.90 when it grew linearly; an interval twice too wide would
        # give 0.5 and still cover everything)
        z_rms = float(np.sqrt(np.mean(np.square(z))))
        assert 0.6 <= z_rms <= 1.4, (j, z_rms)
        ratio = np.sqrt(np.mean(np.square(expected))) / np.sqrt(np.mean(np.square(actual)))
        assert 0.5 <= ratio <= 2.5, (j, ratio)  # the error calibrate prints at new poses, against the truth
