"""Step sizes measured at poses (method camera) beside traverses: the paper's calibration unchanged without them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synth import PAPER_PRISMATIC, PINNED_TODAY, paper_table, random_poses, traverse_from_model

from stickslip.calibration import calibrate, calibrate_lsq
from stickslip.calibration.auto import ASSUMED_MODEL_ERROR, step_size_weight
from stickslip.calibration.update import update_calibration
from stickslip.measurements import StepSize, TableError, parse_step_sizes, step_sizes_to_csv
from stickslip.models import JointModel

OUT = -math.pi / 2


def _row(joint: int, d: str, gamma: float, sigma: float, q2: float = OUT, q3: float = 0.0, theta: float = 0.0):
    return StepSize(PINNED_TODAY, joint, d, 0.0, q2, q3, theta, 0.0, gamma, sigma, 150, "camera")


def test_the_paper_calibration_is_exactly_as_before_without_step_sizes():
    ts = paper_table()
    a = calibrate(ts, model="auto")
    b = calibrate(ts, model="auto", step_sizes=())
    assert a.method == b.method == "paper"
    assert a.parameters() == b.parameters() and a.provenance == b.provenance


def test_unit_weights_change_nothing_in_least_squares():
    rng = np.random.default_rng(4)
    m = JointModel(3, "+", PAPER_PRISMATIC["+"])
    ts = [traverse_from_model(m, p, PINNED_TODAY, rng, 0.01) for p in random_poses(rng, 3, 8)]
    a, b = calibrate_lsq(ts), calibrate_lsq(ts, weights=[1.0] * len(ts))
    assert a.parameters() == b.parameters()
    with pytest.raises(ValueError, match="weights for"):
        calibrate_lsq(ts, weights=[1.0])


def test_step_sizes_join_their_joint_and_leave_the_others_alone():
    ts = paper_table()
    a = PAPER_PRISMATIC["+"].a
    rows = [_row(3, "+", a * 1.01, a * 0.005), _row(3, "-", PAPER_PRISMATIC["-"].a * 1.01, 5e-9)]
    cal = calibrate(ts, model="auto", step_sizes=rows)
    base = calibrate(ts, model="auto")
    assert cal.models[(2, "+")].params == base.models[(2, "+")].params  # joint 2: the paper's, untouched
    assert "lsq with step sizes (3+ 3-)" in cal.method
    g = float(cal.models[(3, "+")].gamma(0.0, OUT, 0.0, 0.0, 0.0))
    assert a < g < 1.01 * a  # pulled towards the camera's step at that pose
    assert len(cal.provenance.extra["step_sizes"]) == 2  # type: ignore[arg-type]


def test_a_step_size_weighs_by_its_uncertainty():
    sm = ASSUMED_MODEL_ERROR[3]
    assert step_size_weight(_row(3, "+", 1e-6, 1e-12)) == pytest.approx(1.0, abs=1e-9)
    assert step_size_weight(_row(3, "+", 1e-6, sm * 1e-6)) == pytest.approx(1 / math.sqrt(2))
    assert step_size_weight(_row(2, "+", 50e-6, 5e-6)) < step_size_weight(_row(2, "+", 50e-6, 0.5e-6))


def test_as_traverse_is_the_same_step_size():
    r = _row(1, "-", 48e-6, 0.3e-6)
    t = r.as_traverse()
    assert t.gamma == pytest.approx(r.gamma, rel=1e-12) and t.steps == r.steps and t.end < t.start
    assert (t.start + t.end) / 2 == pytest.approx(r.q1)


def test_a_prior_is_brought_up_to_date_by_camera_rows():
    """A day 8 % stronger on joint 3: two camera rows move the scale most of the way (their sigma 0.5 %)."""
    prior = calibrate(paper_table())
    rows = [_row(3, d, float(prior.models[(3, d)].gamma(0.0, OUT, 0.0, 0.0, 0.0)) * 1.08, 5e-9) for d in "+-"]
    cal, ups = update_calibration(prior, [], step_sizes=rows)
    assert [u.joint for u in ups] == [3, 3]
    assert all(1.04 < u.scale < 1.08 for u in ups)


def test_the_table_round_trips_and_bad_rows_are_named():
    rows = [_row(3, "+", 9.7e-7, 5e-9), _row(1, "-", 4.8e-5, 3e-7, q3=0.002)]
    assert parse_step_sizes(step_sizes_to_csv(rows)) == rows
    text = step_sizes_to_csv(rows).replace("camera", "ruler", 1).replace("4.8e-05", "48", 1)
    with pytest.raises(TableError) as e:
        parse_step_sizes(text, "s.csv")
    assert e.value.problems[0].startswith("s.csv:2: method must be camera")
    assert "s.csv:3: gamma = 48 rad is not a step size of joint 1" in e.value.problems[1]
    with pytest.raises(TableError, match="header must be exactly"):
        parse_step_sizes("day,joint\n", "h.csv")
