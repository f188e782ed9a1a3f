"""The calibration day as a guided run (procedures.day): the paper's 14 traverses, resumed, then calibrated.

A whole day listens to an hour of simulated stepping (about 100 s of CPU): too long for
the suite. The test resumes a day at its last two traverses, the rows before them
computed from the simulator's true models (the exact average step over each traverse, an
integral the simulator does not use: it steps one noisy step at a time), and measures the
last two by ear. The calibration made from the 14 rows must find the simulator's true
prismatic ``a`` (Eq. 4: read straight from the two measured traverses) within 1 %.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from stickslip import kinematics as kin
from stickslip.devices.base import open_device
from stickslip.measurements import Traverse
from stickslip.procedures.day import DAY_PLAN, DayProgress, DayRequest, calibration_day, simulator_tunings
from stickslip.sim.arm import SimulatedMM3A
from stickslip.storage import Store

URL = "sim://?seed=2&day=2026-11-22"
DAY = "2026-11-22"


def test_the_plan_is_the_papers_fourteen_traverses() -> None:
    assert len(DAY_PLAN) == 14
    assert [(t.joint, t.direction) for t in DAY_PLAN[:6]] == [(3, "+"), (3, "-")] * 3
    assert {t.joint for t in DAY_PLAN[6:]} == {2}
    first = DAY_PLAN[0]
    assert first.pose.q3 == 0.0 and first.pose.q2 == pytest.approx(-math.pi / 2)
    assert DAY_PLAN[1].pose.q3 == kin.Q3_MAX  # a - traverse starts at the upper stop
    assert first.describe() == (
        "joint 3 + (lower stop to upper) with q1 = 0 deg, q2 = -90 deg, theta = 0 deg, psi = 0 deg"
    )


def _exact_row(sim: SimulatedMM3A, joint: int, direction: str, fixed: dict[str, float]) -> Traverse:
    spec = kin.joint_spec(joint)
    start, end = (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)
    pose = {"q1": 0.0, "q2": 0.0, "q3": 0.0, "theta": 0.0, "psi": 0.0, **fixed, f"q{joint}": start}
    model = sim.true_models()[(joint, direction)]
    gamma = float(model.average_gamma(start, end, pose["q1"], pose["q2"], pose["q3"], pose["theta"], pose["psi"]))
    return Traverse(DAY, joint, direction, pose["q1"], pose["q2"], pose["q3"], pose["theta"], pose["psi"], start,
                    end, round(spec.span / gamma))


@pytest.mark.slow
def test_a_resumed_day_measures_the_rest_and_calibrates_from_all_fourteen(tmp_path: Path) -> None:
    sim = open_device(URL)
    assert isinstance(sim, SimulatedMM3A)
    plan = DAY_PLAN[2:] + DAY_PLAN[:2]  # the two traverses at q2 = -90 deg (the shortest) measured last
    store = Store.open(tmp_path / "day.db")
    done = []
    for t in plan[:12]:
        row = _exact_row(sim, t.joint, t.direction, dict(t.fixed))
        done.append((row, store.add_traverse(row, device="sim://?seed=2", how="exact")))
    stages: list[tuple[int, str]] = []

    def progress(p: DayProgress) -> None:
        if not stages or stages[-1] != (p.index, p.stage):
            stages.append((p.index, p.stage))
        if p.stage == "traversing" and p.steps:
            assert p.band_hz is not None and p.level_db is not None and -120 < p.level_db < 0

    poses: list[int] = []
    result = calibration_day(
        store, DayRequest(URL, DAY, simulator_tunings(URL, (3,)), start_at=12, plan=plan), done=done,
        set_pose=lambda i, t: poses.append(i), progress=progress,
    )
    assert poses == [12, 13]
    assert stages == [(12, "pose"), (12, "traversing"), (12, "measured"), (13, "pose"), (13, "traversing"),
                      (13, "measured"), (13, "calibrating")]
    assert len(result.rows) == 14 and len(result.traverse_ids) == 14
    assert store.calibration_traverses(result.calibration_id) and len(store.calibration_traverses(
        result.calibration_id)) == 14
    cal = store.latest_calibration("sim://?seed=2")
    assert cal is not None and cal.day == DAY
    truth = {(p.joint, p.direction, p.name, p.q3): p.value for p in sim.true_parameters()}
    found = {(p.joint, p.direction, p.name, p.q3): p.value for p in result.calibration.parameters()}
    for direction in "+-":
        key = (3, direction, "a", None)
        assert found[key] == pytest.approx(truth[key], rel=0.01), (key, found[key], truth[key])
    # the measured joint ends referenced at the stop it reached
    state = store.get_state("sim://?seed=2", "positions")
    assert state["sources"]["3"] == "set" and state["positions"]["3"] == 0.0


def test_bad_requests_are_refused_before_anything_moves(tmp_path: Path) -> None:
    store = Store.open(tmp_path / "x.db")
    with pytest.raises(ValueError, match=r"tuning of joint\(s\) \[2\]"):
        calibration_day(store, DayRequest(URL, DAY, {3: object()}))  # type: ignore[dict-item]
    tun = {2: object(), 3: object()}
    with pytest.raises(ValueError, match="start_at = 14 is outside 0..13"):
        calibration_day(store, DayRequest(URL, DAY, tun, start_at=14))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="needs the 3 rows before it"):
        calibration_day(store, DayRequest(URL, DAY, tun, start_at=3))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="2026-13-45"):
        calibration_day(store, DayRequest(URL, "2026-13-45", tun))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="is not a simulator"):
        simulator_tunings("mm3a:///dev/ttyUSB0")
