"""The SmarAct drivers end to end through the project's emulators (stickslip.sim.smaract_emulator).

References: the emulator moves a simulated MM3A with every burst; a second simulator
stepped directly by the same signed counts (the twin) must end at exactly the same
position, and the measured average step of a traverse must match the day's true model
(SimulatedMM3A.true_models(), exact traverse average) within the per-step noise. The
CLI's `move` must make exactly the steps `stickslip plan` gives.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from synth import paper_table
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.cli import app
from stickslip.devices import open_device
from stickslip.devices.base import DeviceError, StepsUncertain
from stickslip.measurements import measurements_to_csv
from stickslip.procedures.traverse import measure_traverse
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.microphone import VirtualMicrophone
from stickslip.sim.oracle import OracleStopDetector
from stickslip.sim.smaract_emulator import MCS2Emulator, MCSEmulator

POSE = kin.Pose(q1=0.0, q2=-math.pi / 2, q3=1e-3, theta=0.0, psi=0.0)
pty_only = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")
runner = CliRunner()


def _sim(seed: int = 4) -> SimulatedMM3A:
    sim = SimulatedMM3A(seed=seed, day="2026-11-22", sample_rate=8000)
    sim.set_pose(*POSE)
    return sim


def _no_waiting(dev: object) -> None:
    """Let the driver's clock jump over each burst's duration (the emulator ends bursts at once)."""
    box = [0.0]

    def sleep(s: float) -> None:
        box[0] += s

    dev._clock, dev._sleep = (lambda: box[0]), sleep  # type: ignore[attr-defined]


def _emulators() -> list[tuple[type, str]]:
    kinds: list[tuple[type, str]] = [(MCSEmulator, "tcp"), (MCS2Emulator, "tcp")]
    if hasattr(os, "openpty"):
        kinds.append((MCSEmulator, "pty"))
    return kinds


@pytest.mark.parametrize("emulator, transport", _emulators())
def test_bursts_move_the_arm_exactly_as_the_steps_say(emulator: type, transport: str) -> None:
    sim, twin = _sim(), _sim()
    hz = 18500 if emulator is MCSEmulator else 20000
    with emulator(sim, transport=transport, channels="0,-1,2") as emu:
        with open_device(f"{emu.url}?hz={hz}&channels=0,-1,2&timeout=0.5") as dev:
            _no_waiting(dev)
            dev.step(3, 1009)
            dev.step(2, -40000)  # more than one MCS burst
            dev.step(1, 77)
            dev.step(3, -9)
        assert emu.steps[0] == 77 and emu.steps[1] == 40000 and emu.steps[2] == 1000
        assert emu.driving == []
    first = -29999 if emulator is MCSEmulator else -40000  # the MCS's bursts are at most 29999 steps
    for j, n in ((3, 1009), (2, first), (2, -40000 - first), (1, 77), (3, -9)):
        if n:
            twin.step(j, n)
    for j in (1, 2, 3):
        assert sim.position(j) == pytest.approx(twin.position(j), abs=1e-15)


def test_a_calibration_traverse_through_the_mcs2_measures_the_true_step() -> None:
    sim = _sim(seed=5)
    sim.set_pose(q3=0.0)
    with MCS2Emulator(sim) as emu:
        with open_device(emu.url + "?hz=5000") as dev:  # the simulated arm steps at most at 5 kHz
            _no_waiting(dev)
            res = measure_traverse(
                dev, 3, "+", detector=OracleStopDetector(sim, 3, t0_s=sim.clock_s),
                audio_blocks=VirtualMicrophone(sim, block=512, silent=True), pose=sim.pose,
                day="2026-11-22", burst_steps=4000, predrive="listen", clock=lambda: sim.clock_s,
            )
    true = sim.true_models()[(3, "+")].average_gamma(0.0, kin.Q3_MAX, 0.0, -math.pi / 2, 0.0, 0.0, 0.0)
    assert res.traverse.steps > 5000
    assert res.gamma == pytest.approx(float(true), rel=0.003)  # per-step noise ~0.03 %: 10x room


@pytest.mark.parametrize("emulator", [MCSEmulator, MCS2Emulator])
@pytest.mark.parametrize("fault, words", [("silent", "did not answer"), ("garbage", "garbage reply"),
                                          ("error", "refused"), ("stuck", "still stepping")])
def test_a_fault_mid_move_is_bounded_stopped_and_leaves_nothing_stepping(
    emulator: type, fault: str, words: str
) -> None:
    timeout = 0.2
    with emulator(_sim(), transport="tcp") as emu:
        dev = open_device(f"{emu.url}?timeout={timeout}&hz=10000")
        dev.step(3, 100)
        emu.inject(fault, after=1)  # the next burst works, the one after fails
        dev.step(3, 100)
        t0 = time.monotonic()
        with pytest.raises(StepsUncertain, match=words) as e:
            dev.step(3, 250)
        elapsed = time.monotonic() - t0
        emu.inject(None)
        dev.close()
        assert emu.driving == [] or fault == "silent"  # a silent device carried out the stop too
        made = emu.steps[2]
    assert e.value.made == 0
    assert e.value.at_most == (0 if fault == "error" else 250)
    assert 200 <= made <= 450
    # each failing answer waits the timeout at most: the burst's, its stop's, and the stop's error count
    assert elapsed < 1.5 * 250 / 10000 + 3 * timeout + 1.0


def test_stop_from_another_thread_ends_a_burst_early_and_the_steps_stay_uncertain() -> None:
    with MCS2Emulator(_sim(), realtime=1.0) as emu:
        with open_device(emu.url + "?timeout=0.5&hz=1000") as dev:  # 3000 steps take 3 s
            timer = threading.Timer(0.4, dev.stop)
            timer.start()
            t0 = time.monotonic()
            with pytest.raises(StepsUncertain, match="stopped part-way") as e:
                dev.step(3, 3000)
            elapsed = time.monotonic() - t0
            timer.join()
        made = emu.steps[2]
        assert emu.driving == []
    assert (e.value.made, e.value.at_most) == (0, 3000)
    assert 0 < made < 3000 and elapsed < 2.0


def test_unplugged_mid_run_is_a_device_error_within_the_timeout() -> None:
    with MCS2Emulator(_sim()) as emu:
        dev = open_device(emu.url + "?timeout=0.3&hz=20000")
        dev.step(3, 100)
        emu.unplug()
        t0 = time.monotonic()
        with pytest.raises(DeviceError):
            dev.step(3, 100)
        assert time.monotonic() - t0 < 2.0
        dev.close()  # never raises


def test_the_emulators_refuse_what_the_manual_forbids() -> None:
    with MCSEmulator(_sim(), transport="tcp") as emu:
        with open_device(emu.url) as dev:
            for cmd, code in [("MST0,30001,4095,1000", "7"), ("MST0,10,4096,1000", "7"), ("MST9,10,1,1", "7"),
                              ("FOO", "2"), ("MST0,1", "5")]:
                with pytest.raises(DeviceError, match=f"error {code} "):
                    dev.command(cmd)
            dev.command("MST0,5,0,1000")  # 0 V: steps counted, nothing moves
            assert emu.sim.position(1) == 0.0
    with MCS2Emulator(_sim()) as emu:
        with open_device(emu.url) as dev:
            with pytest.raises(DeviceError, match="error 259 "):
                dev.command(":MOVE0 10")  # not in step mode: no sensor for a closed-loop move
            with pytest.raises(DeviceError, match="error -222 "):
                dev.command(":CHAN0:STEP:FREQ 20001")
            with pytest.raises(DeviceError, match="error -113 "):
                dev.command(":CHAN0:SPEED 3")


@pytest.fixture(scope="module")
def cal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("cal")
    (tmp / "meas.csv").write_text(measurements_to_csv(paper_table()))
    r = runner.invoke(app, ["calibrate", str(tmp / "meas.csv"), "-o", str(tmp / "cal.json")])
    assert r.exit_code == 0, r.output
    return tmp / "cal.json"


@pytest.mark.parametrize("emulator", [MCSEmulator, MCS2Emulator])
def test_the_command_line_moves_and_reports_through_the_emulator(emulator: type, cal: Path, tmp_path: Path) -> None:
    db = str(tmp_path / "s.db")
    r = runner.invoke(app, ["plan", "-c", str(cal), "--joint", "3", "--from", "1mm", "--to", "1.5mm", "--q2", "-90deg",
                            "--json"])
    steps = json.loads(r.stdout)["steps"]
    with emulator(_sim(), transport="tcp") as emu:
        url = emu.url + "?hz=5000"
        assert runner.invoke(app, ["where", "-d", url, "--offline", "--set", "3=1mm", "--db", db]).exit_code == 0
        r = runner.invoke(app, ["move", "-d", url, "-c", str(cal), "--joint", "3", "--by", "500um", "--q2", "-90deg",
                                "--trust-calibration",  # the calibration records no device
                                "--db", db])
        assert r.exit_code == 0, r.output
        w = runner.invoke(app, ["where", "-d", url, "--db", db])
        assert w.exit_code == 0, w.output
        assert emu.steps[2] == steps and emu.steps[0] == emu.steps[1] == 0
    text = " ".join(w.stdout.split())
    model = "SmarAct MCS (system id 1234567890)" if emulator is MCSEmulator else "SmarAct MCS2 (serial MCS2-00004711)"
    assert f"(answers: {model})" in text and "stepping ch0 5000 Hz, ch1 5000 Hz, ch2 5000 Hz" in text
    assert "joint 3:" in text and "(dead-reckoned" in text


@pytest.mark.skipif(os.name != "posix", reason="SIGTERM to a child is TerminateProcess on Windows: no handler, exit 1")
@pytest.mark.parametrize("kind", ["mcs", "mcs2"])
def test_an_emulator_served_from_the_command_line_stops_cleanly_on_sigterm(kind: str) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "stickslip.sim.smaract_emulator", kind, "--tcp"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        url = proc.stdout.readline().strip()
        assert "://127.0.0.1:" in url, url
        with open_device(url + "?hz=10000") as dev:
            dev.step(2, 10)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "commands received; steps {0: 0, 1: 10, 2: 0" in out


class _StopOnEnter:
    """The step lock, with a stop() from 'another thread' arriving just after step() has taken it: the moment the
    halt flag used to be cleared (thread62's note 3), made deterministic by calling stop() from inside."""

    def __init__(self, dev: object) -> None:
        self._lock, self._dev = threading.Lock(), dev

    def locked(self) -> bool:
        return self._lock.locked()

    def __enter__(self) -> None:
        self._lock.acquire()
        self._dev.stop()  # type: ignore[attr-defined]

    def __exit__(self, *exc: object) -> None:
        self._lock.release()


@pytest.mark.parametrize("emulator", [MCSEmulator, MCS2Emulator])
def test_a_stop_just_after_a_step_took_its_lock_stops_that_step(emulator: type) -> None:
    """step() cleared the halt flag after taking its lock, so a stop() that came in between was erased and the
    burst ran in full (the channel's stop had gone out before the burst started). Now the halt is set for any
    step() begun and cleared only before one begins: the step sends no burst and says so, no step made."""
    sim = _sim(seed=5)
    with emulator(sim) as emu:
        with open_device(emu.url + "?hz=5000") as dev:
            _no_waiting(dev)
            before = sim.position(3)
            dev._step_lock = _StopOnEnter(dev)  # type: ignore[attr-defined]
            with pytest.raises(StepsUncertain) as e:
                dev.step(3, 200)
            assert (e.value.made, e.value.at_most) == (0, 0) and "stop() was called" in str(e.value)
            assert sim.position(3) == before  # was: 200 steps made
            dev._step_lock = threading.Lock()  # type: ignore[attr-defined]
            dev.step(3, 10)  # a stop before a step began does not stop the next one
    assert sim.position(3) != before
