"""The console driver end to end through the project's console emulator (stickslip.sim.console_emulator),
the move loop's handling of StepsUncertain, and the legacy dialect forced on the legacy emulator.

The emulator counts steps from the wall clock; the driver times bursts so that exactly the
commanded steps are made (count x |m| per go, T longer than the burst): exact equality is
the reference. The simulated joint must move by the same steps (SimulatedMM3A.steps_taken
is not used: its position is compared with a second simulator stepped directly).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, cast

import pytest

from stickslip import kinematics as kin
from stickslip.devices.base import Controller, DeviceError, StepsUncertain
from stickslip.devices.nanocontrol import open_url
from stickslip.devices.positions import DeviceState
from stickslip.procedures.move import MoveOutcome, drive
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.console_emulator import POWER_ON_HZ, ConsoleEmulator, steps_by
from stickslip.sim.emulators import NanoControlEmulator

pty_only = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


def _sim() -> SimulatedMM3A:
    sim = SimulatedMM3A(seed=4, day="2026-11-22")
    sim.set_pose(0.0, -1.5707963267948966, 1e-3, 0.0, 0.0)
    return sim


@pty_only
def test_bursts_through_the_emulator_make_exactly_the_steps_and_move_the_arm() -> None:
    sim, twin = _sim(), _sim()
    with ConsoleEmulator(sim) as emu:
        assert emu.hz["C"] == POWER_ON_HZ != 1000
        with open_url(emu.url + "?hz=20000&timeout=0.5") as dev:
            assert dev.info.extra["dialect"] == "console"
            dev.step(3, 1009)
            dev.step(3, -2 * 6400 - 3)
            dev.step(2, 77)
        assert emu.steps == {"A": 0, "B": 77, "C": 1009 - 12803, "D": 0}
        assert emu.fine_steps == dict.fromkeys("ABCD", 0)
        assert emu.driving == []
        assert emu.active == 1  # the power-on profile is active again
        assert emu.hz == dict.fromkeys("ABCD", 20000)
    for j, n in ((3, 1009), (3, -6400), (3, -6400), (3, -3), (2, 77)):
        twin.step(j, n)
    assert sim.position(3) == pytest.approx(twin.position(3), abs=1e-15)
    assert sim.position(2) == pytest.approx(twin.position(2), abs=1e-15)


@pty_only
def test_the_emulator_also_serves_tcp() -> None:
    with ConsoleEmulator(_sim(), transport="tcp") as emu:
        assert emu.url.startswith("mm3a+socket://127.0.0.1:")
        with open_url(emu.url + "?hz=20000&dialect=console") as dev:
            dev.step(1, 64)
        assert emu.steps["A"] == 64


def _power_cycle(emu: ConsoleEmulator) -> None:
    """The controller switched off and on, the serial line (a USB adapter on the PC's side) still open: nothing
    drives, every channel at the power-on frequency, the power-on profiles, profile 1 active."""
    emu._halt()
    with emu._state:
        emu.hz = dict.fromkeys("ABCD", POWER_ON_HZ)
        emu.profiles = {p: ["c16"] * 4 for p in range(1, 7)}
        emu.active = 1
        emu.fine_with_coarse = dict.fromkeys("ABCD", False)


@pty_only
@pytest.mark.parametrize("then", [(3, 1009), (3, 49), (2, 64)])
def test_a_controller_switched_off_and_on_between_two_steps_of_one_session_still_makes_them_exactly(
    then: tuple[int, int],
) -> None:
    """`stickslip serve`, Bluesky and the Python API keep a device open across moves. A NanoControl switched off and
    on between two of them comes back at its power-on frequency and profiles; a burst timed at the URL's frequency
    but made at 700 Hz made a fraction of its steps, counted as all of them (audit57). The driver sets the
    frequency (and writes its profile) again at every step(), as the MCS2 driver sends its settings before every
    burst: a power cycle between two calls changes nothing counted."""
    with ConsoleEmulator(_sim()) as emu:
        with open_url(emu.url + "?hz=20000&timeout=0.5") as dev:
            dev.step(3, 49)  # its scratch profile now holds c49 for channel C
            _power_cycle(emu)
            dev.step(*then)
        made = {"A": 0, "B": 0, "C": 49}
        made["BC"[then[0] - 2]] += then[1]
        assert emu.steps == {**made, "D": 0}
        assert emu.hz == dict.fromkeys("ABCD", 20000)


@pty_only
@pytest.mark.parametrize("fault, match", [("error", "refused 'go"), ("silent", "did not answer 'go"),
                                          ("garbage", "garbage reply")])
def test_a_fault_at_go_stops_the_channel_and_bounds_the_steps(fault: str, match: str) -> None:
    timeout = 0.3
    with ConsoleEmulator(_sim()) as emu:
        dev = open_url(f"{emu.url}?hz=20000&timeout={timeout}")
        dev.step(3, 100)
        emu.inject(fault, after=1)  # the next go works, the one after fails
        t0 = time.monotonic()
        with pytest.raises(StepsUncertain, match=match) as e:
            dev.step(3, 1009)  # 64 x 15, then 49 x 1
        elapsed = time.monotonic() - t0
        dev.close()
        assert emu.driving == []  # stopnack halted it, answered or not
        received = list(emu.received)
    assert e.value.made == 960
    assert e.value.at_most is None  # the faulty emulator refuses or ignores stop too: maybe still driving
    assert received[received.index(next(m for m in reversed(received) if m.startswith("go"))) + 1] == "stopnack"
    # the go's answer (timeout) + the stop's short wait (min(timeout, 0.25 s)) + slack
    assert elapsed < timeout + 0.25 + 1.0


@pty_only
def test_unplugged_mid_run_raises_device_error_quickly() -> None:
    with ConsoleEmulator(_sim()) as emu:
        # 1 s for an answer: 0.3 s once ran out on a starved CI core before the unplug (the first step failed)
        dev = open_url(emu.url + "?timeout=1&hz=20000")
        dev.step(3, 100)
        emu.unplug()
        t0 = time.monotonic()
        with pytest.raises(DeviceError):
            dev.step(3, 100)
        assert time.monotonic() - t0 < 1.0 + 4.0  # a hang guard (the answer's timeout and slack), not a speed test
        dev.close()  # never raises


@pty_only
def test_the_emulator_refuses_malformed_commands() -> None:
    with ConsoleEmulator(_sim()) as emu:
        with open_url(emu.url + "?dialect=console") as dev:
            for cmd, words in [("go 0 0 101 0 10", "out of range"), ("speed 7", "out of range"),
                               ("speed 1 c65 c01 c01 c01", "not c01..c64"), ("frequency 200 1 1 1", "out of range"),
                               ("coarse A +5", "unknown command")]:
                with pytest.raises(DeviceError, match=words):
                    dev.command(cmd)


@pty_only
def test_the_legacy_dialect_forced_sends_exactly_what_it_always_sent() -> None:
    with NanoControlEmulator(_sim()) as emu:
        with open_url(emu.url + "?dialect=legacy") as dev:
            dev.step(3, 25)
            assert dev.info.extra["dialect"] == "legacy"
        assert emu.received == ["version", "coarse C +25"]


@pty_only
def test_detection_on_the_legacy_emulator_ends_in_the_legacy_dialect() -> None:
    with NanoControlEmulator(_sim()) as emu:
        with open_url(emu.url + "?timeout=0.3") as dev:
            assert dev.info.extra["dialect"] == "legacy"
            dev.step(3, 25)
        assert emu.received[-1] == "coarse C +25"
        assert all(m == "version" for m in emu.received[:-1])


def test_steps_by_counts_whole_intervals_and_the_part_of_the_current_one() -> None:
    # 100 steps per 0.5 s interval at 1000 Hz: 0.25 s in -> 100 (interval 1 done at 0.1 s)
    assert steps_by(0.25, 100, 0.5, 1000.0) == 100
    assert steps_by(0.05, 100, 0.5, 1000.0) == 50
    assert steps_by(0.55, 100, 0.5, 1000.0) == 150
    assert steps_by(0.0, 100, 0.5, 1000.0) == 0


# -- the move loop and StepsUncertain -----------------------------------------------------


class Failing:
    """A controller whose second step() raises the given StepsUncertain."""

    def __init__(self, error: StepsUncertain) -> None:
        self.error = error
        self.calls = 0

    def step(self, joint: int, n: int) -> None:
        self.calls += 1
        if self.calls == 2:
            raise self.error


def _drive(error: StepsUncertain) -> tuple[MoveOutcome, DeviceState, list[dict[str, Any]]]:
    state = DeviceState.default("x")
    state.set_position(3, 1e-3, "set")
    saved: list[dict[str, Any]] = []
    step_m = 1e-6  # 1 um per step: reckon(n) = 1 mm + n um

    dev = cast(Controller, Failing(error))
    out = drive(dev, state, 3, 500, 100, lambda n: 1e-3 + n * step_m, lambda s: saved.append(s.to_json()))
    return out, state, saved


def test_drive_keeps_the_certain_steps_of_a_failed_burst() -> None:
    out, state, _ = _drive(StepsUncertain("late", made=40, at_most=40))
    assert out.sent == 140 and out.error == "late"
    assert state.positions[3] == pytest.approx(1e-3 + 140e-6, abs=1e-15) and 3 not in state.uncertain


def test_drive_bounds_a_late_stop_between_made_and_at_most() -> None:
    out, state, _ = _drive(StepsUncertain("late", made=100, at_most=300))
    assert out.sent == 200
    assert state.uncertain[3] == pytest.approx((1e-3 + 200e-6, 1e-3 + 400e-6), abs=1e-15)


def test_drive_bounds_an_unacknowledged_stop_by_the_end_stop() -> None:
    out, state, saved = _drive(StepsUncertain("no stop", made=0, at_most=None))
    assert out.sent == 100
    assert state.uncertain[3] == pytest.approx((1e-3 + 100e-6, kin.JOINTS[3].upper), abs=1e-15)
    assert saved[-1]["uncertain"]["3"] == list(state.uncertain[3])


def test_drive_with_nothing_made_and_nothing_possible_keeps_the_source() -> None:
    state = DeviceState.default("x")
    state.set_position(3, 1e-3, "set")
    dev = cast(Controller, Failing(StepsUncertain("refused", 0, 0)))
    out = drive(dev, state, 3, 50, 100, lambda n: 1e-3 + n * 1e-6, lambda s: None)
    # the first burst is the failing one only if calls == 2; here one burst of 50 succeeds
    assert out.sent == 50 and out.error is None
    failing = Failing(StepsUncertain("refused", 0, 0))
    failing.calls = 1
    state.set_position(3, 1e-3, "set")
    out = drive(cast(Controller, failing), state, 3, 50, 100, lambda n: 1e-3 + n * 1e-6, lambda s: None)
    assert out.sent == 0 and state.sources[3] == "set" and 3 not in state.uncertain


@pty_only
def test_where_reports_dialect_version_frequencies_and_profile(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from stickslip.cli import app

    with ConsoleEmulator(_sim()) as emu:
        r = CliRunner().invoke(app, ["where", "-d", emu.url, "--db", str(tmp_path / "s.db")])
    assert r.exit_code == 0, r.output
    out = " ".join(r.stdout.split())  # the console may wrap long lines
    assert "console dialect; firmware NanoControl console emulator 1.0 (stickslip)" in out
    assert "C 1000 Hz" in out and "sent before this session's first burst" in out
    assert "active speed profile 1 (c16 c16 c16 c16)" in out


@pty_only
def test_stop_from_another_thread_ends_a_burst_early_and_leaves_nothing_driving() -> None:
    import threading

    with ConsoleEmulator(_sim()) as emu:
        with open_url(emu.url + "?timeout=0.5") as dev:  # 1000 Hz: 6400 steps take 6.4 s
            timer = threading.Timer(0.5, dev.stop)
            timer.start()
            t0 = time.monotonic()
            with pytest.raises(StepsUncertain, match="stopped by stop") as e:  # early, and says by how much
                dev.step(3, 6400)
            elapsed = time.monotonic() - t0
            timer.join()
        assert emu.driving == []
        made = emu.steps["C"]
        received = list(emu.received)
    assert elapsed < 3.0
    assert 0 < made < 6400  # about 0.5 s x 1000 Hz
    assert e.value.at_most is not None and e.value.made <= made <= e.value.at_most  # the bound holds what was made
    go = next(i for i, m in enumerate(received) if m.startswith("go"))
    assert received[go + 1 : go + 3] == ["stopnack", "stop"]
