"""The tip's x, y, z as bluesky pseudo-axes, run by a RunEngine on the simulator.

Independent views, not the device's own:
* where the tip really is: the simulator's true joint positions (``KnowsTruePosition``) put through
  the test's own forward kinematics (``hidden_arm.tip_of``: composed scipy rotations, not
  ``stickslip.kinematics.tip``), with the calibration equal to the simulator's true models and no
  per-step noise;
* what bluesky saw: the documents a collecting callback received;
* what was kept: the database read back with ``load_state`` (what ``stickslip where`` shows).

"Within one step" at the tip is the sum over the joints of the lever of each joint at the tip times
its step there (the columns of the Jacobian are orthogonal, docs/taskspace.md: the levers are rho,
length + q3 and 1), with the simulator's position ripple (0.5 % of each joint's travel) on top for the truth.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")

import bluesky.plan_stubs as bps  # noqa: E402
import bluesky.plans as bp  # noqa: E402
from bluesky.utils import FailedStatus  # noqa: E402
from bluesky_support import DAY, true_calibration  # noqa: E402  (RE, the RunEngine fixture, is in conftest.py)
from hidden_arm import tip_of  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

from stickslip import kinematics as kin  # noqa: E402
from stickslip.bluesky import MoveError, StickSlipManipulator  # noqa: E402
from stickslip.calibration import Calibration  # noqa: E402
from stickslip.devices.base import KnowsTruePosition  # noqa: E402
from stickslip.devices.positions import load_state  # noqa: E402
from stickslip.motion.planning import Planner  # noqa: E402
from stickslip.sim.arm import SimulatedMM3A  # noqa: E402
from stickslip.storage import Store  # noqa: E402

GEOMETRY = kin.Geometry(offset=1e-3, length=0.021)


@pytest.fixture()
def sim() -> SimulatedMM3A:
    return SimulatedMM3A(seed=4, day=DAY, step_noise=0.0)


def true_tip(dev: KnowsTruePosition) -> np.ndarray:
    return np.asarray(tip_of([dev.position(j) for j in (1, 2, 3)], GEOMETRY.offset, GEOMETRY.length))


def kept_q() -> tuple[float, float, float]:
    with Store.open() as store:
        state = load_state(store, "sim://")
    assert not state.uncertain
    return state.positions[1], state.positions[2], state.positions[3]


def tip_step(cal: Calibration, q: tuple[float, float, float]) -> float:
    """One step of each joint, as a distance at the tip, summed (m)."""
    pose = kin.Pose(*q)
    rho = math.hypot(*tip_of(q, GEOMETRY.offset, GEOMETRY.length)[:2])
    levers = {1: rho, 2: GEOMETRY.length + q[2], 3: 1.0}
    total = 0.0
    for j, lever in levers.items():
        p = Planner(cal, j, pose)
        total += lever * max(p.gamma(q[j - 1], "+"), p.gamma(q[j - 1], "-"))
    return total


def ripple(start: tuple[float, float, float], end: tuple[float, float, float]) -> float:
    """The simulator's dead-reckoning ripple at the tip: 0.5 % of each joint's travel, times its lever (m)."""
    rho = GEOMETRY.length + 0.012 + abs(GEOMETRY.offset)
    return 0.005 * (rho * abs(end[0] - start[0]) + rho * abs(end[1] - start[1]) + abs(end[2] - start[2]))


@pytest.mark.slow
@pytest.mark.parametrize("coordinate, delta", [("y", 1.5e-3), ("z", -2e-3), ("x", 3e-3)])
def test_mv_of_one_coordinate_reaches_it_and_keeps_the_others(
    RE: Any, sim: SimulatedMM3A, coordinate: str, delta: float
) -> None:
    cal = true_calibration(sim)
    with init_devices():
        arm = StickSlipManipulator(sim, cal, geometry=GEOMETRY)
    q0 = kept_q()
    start = true_tip(sim)
    assert np.allclose(start, [GEOMETRY.offset + GEOMETRY.length, 0.0, 0.0], atol=1e-12)  # outstretched along x
    axis = getattr(arm.tip, coordinate)
    i = "xyz".index(coordinate)
    target = float(start[i] + delta)
    RE(bps.mv(axis, target))
    where = RE(bps.locate(axis)).plan_result
    q = kept_q()
    step = tip_step(cal, q)
    assert where["setpoint"] == target
    assert abs(where["readback"] - target) <= step
    want = start.copy()
    want[i] = target
    assert np.max(np.abs(true_tip(sim) - want)) <= step + ripple(q0, q)
    # the readback is the forward kinematics of the kept joints (the test's own kinematics)
    assert where["readback"] == pytest.approx(tip_of(q, GEOMETRY.offset, GEOMETRY.length)[i], abs=1e-12)
    others = [RE(bps.locate(getattr(arm.tip, c))).plan_result for c in "xyz" if c != coordinate]
    for w, v in zip(others, [start[k] for k in range(3) if k != i], strict=True):
        assert w["setpoint"] == pytest.approx(v, abs=1e-12) and abs(w["readback"] - v) <= step


@pytest.mark.slow
def test_scan_of_the_tip_emits_five_events_rising_through_the_targets(RE: Any, sim: SimulatedMM3A) -> None:
    cal = true_calibration(sim)
    with init_devices():
        arm = StickSlipManipulator(sim, cal, geometry=GEOMETRY)
    docs: list[tuple[str, dict[str, Any]]] = []
    RE.subscribe(lambda name, doc: docs.append((name, doc)))
    a, b = -1e-3, 1e-3
    RE(bp.scan([], arm.tip.y, a, b, 5))
    events = [d for n, d in docs if n == "event"]
    assert len(events) == 5
    ys = np.array([e["data"]["arm-tip-y"] for e in events])
    assert np.all(np.diff(ys) > 0)
    step = tip_step(cal, kept_q())
    assert np.max(np.abs(ys - np.linspace(a, b, 5))) <= step
    (descriptor,) = [d for n, d in docs if n == "descriptor"]
    assert descriptor["data_keys"]["arm-tip-y"]["units"] == "m"
    # x and z stayed on the line: the targets of the other coordinates, not the drifting readbacks
    x0 = GEOMETRY.offset + GEOMETRY.length
    x, _, z = tip_of(kept_q(), GEOMETRY.offset, GEOMETRY.length)
    assert abs(x - x0) <= step and abs(z) <= step
    assert abs(true_tip(sim)[0] - x0) <= step + ripple((0.0, -math.pi / 2, 0.0), kept_q())


@pytest.mark.parametrize(
    "coordinate, value, message",
    [
        ("x", 0.040, "joint 3"),  # 40 mm out: past joint 3's 12 mm
        ("z", 0.0, ""),  # fine: no message (control row)
        ("x", 0.0, "joint 1's axis"),  # the tip onto joint 1's axis: singular
        ("y", math.nan, "not a position"),
        ("y", 5.0, "not a position"),  # 5 m: a unit slip
    ],
)
def test_a_bad_tip_target_fails_the_status_and_sends_no_step(
    RE: Any, sim: SimulatedMM3A, coordinate: str, value: float, message: str
) -> None:
    with init_devices():
        arm = StickSlipManipulator(sim, true_calibration(sim), geometry=GEOMETRY)
    axis = getattr(arm.tip, coordinate)
    if not message:
        RE(bps.mv(axis, value))  # z = 0 is where the tip already is: nothing to do
        assert sim.steps_simulated == 0
        return
    with pytest.raises(FailedStatus) as e:
        RE(bps.mv(axis, value))
    err = e.value.__cause__
    assert isinstance(err, ValueError)
    assert message in str(err)
    assert sim.steps_simulated == 0
    assert kept_q() == (0.0, -math.pi / 2, 0.0)


def test_a_tip_target_past_joint_1s_stop_is_refused_naming_it(RE: Any, sim: SimulatedMM3A) -> None:
    with init_devices():
        arm = StickSlipManipulator(sim, true_calibration(sim), geometry=GEOMETRY)
    RE(bps.mv(arm.q1, 2.0))  # joint 1 near its +120 deg stop: the tip at about (-9, 20, 0) mm
    before = sim.steps_simulated
    with pytest.raises(FailedStatus) as e:
        RE(bps.mv(arm.tip.y, -0.010))  # y = -10 mm at that x needs joint 1 at about 227 deg
    assert isinstance(e.value.__cause__, ValueError)
    assert "joint 1 would be at" in str(e.value.__cause__) and "upper limit 120 deg" in str(e.value.__cause__)
    assert sim.steps_simulated == before


@pytest.mark.slow
def test_tip_readback_follows_joint_moves(RE: Any, sim: SimulatedMM3A) -> None:
    cal = true_calibration(sim)
    with init_devices():
        arm = StickSlipManipulator(sim, cal, geometry=GEOMETRY)
    RE(bps.mv(arm.q3, 4e-3))
    RE(bps.mv(arm.q2, -1.2))
    q = kept_q()
    want = tip_of(q, GEOMETRY.offset, GEOMETRY.length)
    got = [RE(bps.rd(getattr(arm.tip, c))).plan_result for c in "xyz"]
    assert np.allclose(got, want, atol=1e-12)
    # a tip move now keeps the others at the readback (the joints moved since the last tip target)
    RE(bps.mv(arm.tip.y, 1e-3))
    where = tip_of(kept_q(), GEOMETRY.offset, GEOMETRY.length)
    step = tip_step(cal, kept_q())
    assert abs(where[0] - want[0]) <= step and abs(where[2] - want[2]) <= step and abs(where[1] - 1e-3) <= step
    # and the joints' readbacks followed the tip move
    assert RE(bps.rd(arm.q2)).plan_result == pytest.approx(kept_q()[1], abs=1e-15)


def test_no_calibration_refuses_a_tip_move(RE: Any, sim: SimulatedMM3A) -> None:
    with init_devices():
        arm = StickSlipManipulator(sim, geometry=GEOMETRY)
    with pytest.raises(FailedStatus) as e:
        RE(bps.mv(arm.tip.y, 1e-3))
    assert isinstance(e.value.__cause__, MoveError) and "no calibration" in str(e.value.__cause__)
    assert sim.steps_simulated == 0


def test_stop_of_a_tip_move_between_bursts_keeps_exact_joints(sim: SimulatedMM3A) -> None:
    """On the simulator a burst completes at once: a stop lands between bursts and every joint stays exact."""
    import asyncio

    cal = true_calibration(sim)

    async def scenario() -> StickSlipManipulator:
        arm = StickSlipManipulator(sim, cal, geometry=GEOMETRY, burst=20, name="arm")
        await arm.connect()
        status = arm.tip.y.set(3e-3)
        while await arm.tip.y.readback.get_value() < 0.5e-3:
            await asyncio.sleep(0.001)
        await arm.tip.y.stop(success=True)
        await status
        return arm

    asyncio.run(scenario())
    q = kept_q()  # asserts nothing is uncertain
    y = tip_of(q, GEOMETRY.offset, GEOMETRY.length)[1]
    assert 0.5e-3 <= y < 3e-3 - 1e-4
    assert np.max(np.abs(true_tip(sim) - tip_of(q, GEOMETRY.offset, GEOMETRY.length))) <= ripple(
        (0.0, -math.pi / 2, 0.0), q
    ) + 1e-12


@settings(max_examples=40, deadline=None)
@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(), st.text(max_size=3), st.none()))
def test_target_problem_refuses_every_non_position(value: Any) -> None:
    arm = StickSlipManipulator(SimulatedMM3A(), None, geometry=GEOMETRY)
    problem = arm.tip.x.target_problem(value)
    ok = (
        isinstance(value, (int, float))
        and not isinstance(value, bool)
        and math.isfinite(float(value))
        and abs(float(value)) <= 1.0
    )
    assert (problem is None) == ok
