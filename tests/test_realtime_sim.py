"""The simulator in real time (sim://?realtime=1): bursts take the wall clock's time, a stop ends them honestly.

No test times anything: they check step counts, positions and the device clock, which are
exact whatever the machine's load; a burst is made fast with ``speed``.
"""

from __future__ import annotations

import threading

import pytest

from stickslip.devices.base import BurstStopped, DeviceError, StepsUncertain, open_device
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.realtime import RealtimeArm, check_speed
from stickslip.sim.urls import virtual_clock_url


def test_a_burst_in_real_time_moves_the_arm_as_the_virtual_clock_does() -> None:
    # the same seed and day: the same per-step noise, so the same end position to the last bit
    rt = open_device("sim://?seed=4&day=d1&realtime=1&speed=200")
    vc = open_device("sim://?seed=4&day=d1")
    assert isinstance(rt, RealtimeArm) and isinstance(vc, SimulatedMM3A)
    for dev in (rt, vc):
        dev.step(3, 3000)
        dev.step(3, -1200)
    assert rt.position(3) == pytest.approx(vc.position(3), rel=1e-12)
    # device time: 4200 steps at 1 kHz, whatever the wall clock did
    assert rt.clock_s == pytest.approx(4.2, abs=1e-9)
    assert rt.info.model == "simulated MM3A, real time" and rt.info.extra["speed"] == 200.0
    assert rt.info.url == "sim://?seed=4&day=d1&realtime=1&speed=200"


def test_a_stop_ends_the_burst_with_the_exact_steps_made() -> None:
    rt = open_device("sim://?realtime=1&speed=5")  # 100 000 steps would take 20 s
    assert isinstance(rt, RealtimeArm)
    start = rt.position(3)
    before = rt.steps_simulated
    started = threading.Event()
    rt.arm.step = _signal_first(rt.arm.step, started)  # type: ignore[method-assign]
    threading.Thread(target=lambda: (started.wait(10), rt.stop())).start()
    with pytest.raises(BurstStopped) as info:
        rt.step(3, 100_000)
    made = info.value.made
    assert 0 < made < 100_000
    assert info.value.at_most == made  # exactly known: no uncertainty
    assert rt.steps_simulated - before == made  # the arm made exactly what the exception says
    assert rt.position(3) > start
    assert "stopped" in str(info.value)
    # a stop with nothing running changes nothing, and the next burst runs whole
    rt.stop()
    rt.step(3, 10)
    assert rt.steps_simulated - before == made + 10


def _signal_first(step, event):  # noqa: ANN001, ANN202 - a spy on the arm's step
    def spy(joint, n):  # noqa: ANN001, ANN202
        event.set()
        return step(joint, n)

    return spy


def test_a_fault_part_way_says_how_many_steps_were_made() -> None:
    rt = open_device("sim://?realtime=1&speed=50")  # 5000 steps in chunks over 0.1 s
    assert isinstance(rt, RealtimeArm)
    calls = {"n": 0}
    real_step = rt.arm.step

    def failing(joint: int, n: int) -> None:
        calls["n"] += 1
        if calls["n"] == 3:
            raise DeviceError("the arm fell over")
        real_step(joint, n)

    rt.arm.step = failing  # type: ignore[method-assign]
    before = rt.arm.steps_simulated
    with pytest.raises(StepsUncertain) as info:
        rt.step(3, -5000)
    assert info.value.made == -(rt.arm.steps_simulated - before)  # signed: the burst went down
    assert info.value.at_most == info.value.made
    assert "the arm fell over" in str(info.value)


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("sim://?realtime=2", "realtime='2' must be 1 or 0"),
        ("sim://?speed=10", "speed= needs realtime=1"),
        ("sim://?realtime=1&speed=0", "speed must be a number in (0, 1000]"),
        ("sim://?realtime=1&speed=nan", "speed must be a number in (0, 1000]"),
        ("sim://?realtime=1&speed=2000", "speed must be a number in (0, 1000]"),
        ("sim://?realtime=1&bogus=1", "unknown sim:// option 'bogus'"),
    ],
)
def test_bad_realtime_options_are_refused(url: str, message: str) -> None:
    with pytest.raises(ValueError, match=None) as info:
        open_device(url)
    assert message in str(info.value)


def test_realtime_zero_is_the_virtual_clock_and_the_physics_arm_runs_in_real_time_too() -> None:
    assert isinstance(open_device("sim://?realtime=0"), SimulatedMM3A)
    rt = open_device("sim://?physics=1&realtime=1&speed=100")
    assert isinstance(rt, RealtimeArm) and type(rt.arm).__name__ == "PhysicsMM3A"
    assert virtual_clock_url("sim://?physics=1&realtime=1&speed=100&seed=2") == "sim://?physics=1&seed=2"


def test_check_speed() -> None:
    assert check_speed("2.5") == 2.5
    for bad in (True, "fast", -1, float("inf")):
        with pytest.raises(ValueError, match="speed must be"):
            check_speed(bad)


def test_the_realtime_arm_is_what_procedures_expect_of_a_simulator() -> None:
    from stickslip.devices.base import Controller, HasMicrophone, KnowsTruePosition, PoseSettable, VirtualClock

    rt = open_device("sim://?realtime=1")
    for capability in (Controller, HasMicrophone, KnowsTruePosition, PoseSettable, VirtualClock):
        assert isinstance(rt, capability), capability.__name__
    rt.set_pose(q3=0.004)
    assert rt.position(3) == pytest.approx(0.004)
    rt.close()
    with pytest.raises(DeviceError):
        rt.step(3, 1)
