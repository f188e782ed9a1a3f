"""End to end through the protocol emulators: our NanoControl driver on a pseudo-terminal
(and TCP), a calibration traverse over the emulated serial line, and injected faults.

Reference values come from the emulated arm itself: SimulatedMM3A.true_models() gives
the day's true mean-step model, whose exact traverse average (JointModel.average_gamma)
the measured average step must match within the per-step noise and ripple (< 1 %).
"""

from __future__ import annotations

import math
import os
import time

import pytest

from stickslip import kinematics as kin
from stickslip.devices import DeviceError, open_device
from stickslip.procedures.traverse import measure_traverse
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.emulators import NanoControlEmulator
from stickslip.sim.microphone import VirtualMicrophone
from stickslip.sim.oracle import OracleStopDetector

# the emulator serves a pseudo-terminal by default; its TCP tests and the no-pty error run everywhere
pty_only = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals (POSIX)")
SIGTERM_NOTE = "a SIGTERM to a child is TerminateProcess on Windows: no handler runs, the exit code is 1"

POSE = kin.Pose(q1=0.0, q2=-math.pi / 2, q3=0.0, theta=0.0, psi=0.0)


def _sim(seed=5):
    sim = SimulatedMM3A(seed=seed, day="2026-11-22", sample_rate=8000)
    sim.set_pose(*POSE)
    return sim


def _traverse(dev, sim, joint, direction, burst=2000):
    """measure_traverse over the emulated line; the oracle detector stands in for the ear."""
    return measure_traverse(
        dev,
        joint,
        direction,
        detector=OracleStopDetector(sim, joint, t0_s=sim.clock_s),
        audio_blocks=VirtualMicrophone(sim, block=512, silent=True),
        pose=sim.pose,
        day="2026-11-22",
        burst_steps=burst,
        predrive="listen",
        clock=lambda: sim.clock_s,
    )


@pty_only
def test_calibration_traverse_over_pty_measures_the_true_step():
    sim = _sim()
    with NanoControlEmulator(sim) as emu:
        assert emu.url.startswith("mm3a:///dev/pts/")
        dev = open_device(emu.url + "?timeout=2")
        try:
            results = [_traverse(dev, sim, 3, d) for d in ("+", "-")]
        finally:
            dev.close()
        sent = list(emu.received)
    for res, d in zip(results, ("+", "-"), strict=True):
        model = sim.true_models()[(3, d)]
        start, end = (0.0, kin.Q3_MAX) if d == "+" else (kin.Q3_MAX, 0.0)
        true = model.average_gamma(start, end, *POSE)
        assert res.traverse.steps > 5000
        assert res.gamma == pytest.approx(float(true), rel=0.003)  # noise ~0.03 %: 10x room
    # every message on the wire is a well-formed command of the set
    import re

    pattern = re.compile(r"^(version|coarse C [+-]\d+)$")
    assert sent[0] == "version"
    assert all(pattern.match(m) for m in sent), sent
    # the emulator's counter agrees with the steps the traverses commanded
    coarse = sum(int(m.split()[2]) for m in sent if m.startswith("coarse"))
    assert coarse == emu.counters["C"]


def test_rotary_traverse_over_tcp_socket():
    sim = _sim(seed=9)
    with NanoControlEmulator(sim, transport="tcp") as emu:
        assert emu.url.startswith("mm3a+socket://127.0.0.1:")
        with open_device(emu.url) as dev:
            res = _traverse(dev, sim, 2, "-", burst=5000)
    true = sim.true_models()[(2, "-")].average_gamma(
        kin.JOINTS[2].upper, kin.JOINTS[2].lower, *POSE
    )
    assert res.gamma == pytest.approx(float(true), rel=0.003)


@pty_only
def test_settings_reach_the_emulated_device():
    with NanoControlEmulator(_sim()) as emu:
        with open_device(emu.url) as dev:
            dev.set_speed(3, 12)
            dev.set_amplitude(3, positive=60, negative=70)
            dev.step(3, 100)
            assert dev.counters()[3] == 100
        assert emu.speed["C"] == 12 and emu.amplitude["C"] == {"+": 60, "-": 70}
        assert emu.sim.frequency(3) == 2000.0


@pty_only
def test_out_of_range_setting_sends_nothing():
    with NanoControlEmulator(_sim()) as emu:
        with open_device(emu.url) as dev:
            n = len(emu.received)
            with pytest.raises(ValueError, match=r"1\.\.80"):
                dev.set_amplitude(1, positive=200)
            assert len(emu.received) == n


@pty_only
def test_device_error_reply_is_reported():
    with NanoControlEmulator(_sim(), channels="AB") as emu:  # channel C not connected
        with open_device(emu.url) as dev:
            with pytest.raises(DeviceError, match="channel C not connected"):
                dev.step(3, 10)
            assert emu.received[-1] == "stop"


@pty_only
@pytest.mark.slow
@pytest.mark.parametrize("fault, match", [("silent", "did not answer"), ("garbage", "garbage")])
def test_fault_mid_traverse_keeps_earlier_traverses_stops_and_does_not_hang(fault, match):
    sim = _sim()
    timeout = 0.3
    kept = []
    with NanoControlEmulator(sim) as emu:
        dev = open_device(f"{emu.url}?timeout={timeout}")
        kept.append(_traverse(dev, sim, 3, "+").traverse)
        emu.inject(fault, after=3)  # three more bursts go through, then the device fails
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match=match):
            for d in ("-", "+"):
                kept.append(_traverse(dev, sim, 3, d).traverse)
        elapsed = time.monotonic() - t0
        dev.close()
        stops = [m for m in emu.received if m == "stop"]
    assert len(kept) == 1 and kept[0].steps > 5000  # the finished traverse is kept
    assert stops  # the driver told the device to stop
    # bursts answered at once; the failing one waits timeout + its own duration (2 s at 1 kHz)
    assert elapsed < timeout + 1.5 * 2000 / 1000 + 1.0


@pty_only
def test_unplugged_mid_run_raises_device_error_quickly():
    with NanoControlEmulator(_sim()) as emu:
        dev = open_device(emu.url + "?timeout=0.3")
        dev.step(3, 100)
        emu.unplug()
        t0 = time.monotonic()
        with pytest.raises(DeviceError):
            dev.step(3, 100)
        assert time.monotonic() - t0 < 2.0
        dev.close()  # never raises


@pty_only
def test_unplugged_at_open_names_the_port():
    with NanoControlEmulator(_sim()) as emu:
        url = emu.url
    with pytest.raises(DeviceError, match=url.removeprefix("mm3a://")):
        open_device(url + "?timeout=0.2")


@pty_only
def test_emulator_rejects_malformed_commands():
    with NanoControlEmulator(_sim()) as emu:
        with open_device(emu.url) as dev:
            with pytest.raises(DeviceError, match="out of range"):
                dev.command("coarse A +70000")
            with pytest.raises(DeviceError, match="unknown command"):
                dev.command("jump A 3")


@pty_only
def test_a_port_in_use_is_refused_with_a_clear_reason():
    with NanoControlEmulator(_sim()) as emu:
        with open_device(emu.url):
            with pytest.raises(DeviceError, match="another program"):
                open_device(emu.url + "?timeout=0.2")


@pty_only
def test_late_reply_from_a_timed_out_command_is_discarded():
    """A reply that arrives after its timeout must not be taken for the next command's."""
    with NanoControlEmulator(_sim(), realtime=1.0) as emu:
        with open_device(emu.url + "?timeout=0.05&hz=1000000") as dev:
            with pytest.raises(DeviceError, match="did not answer"):
                dev.step(3, 300)  # the emulator needs 0.3 s; we wait 0.05 + a few us
            time.sleep(1.0)  # the late "o" (and the stop's answer) arrive meanwhile
            assert dev.counters()[3] == 300  # the counters answer, not a stale "o\t"


@pytest.mark.skipif(os.name != "posix", reason=SIGTERM_NOTE)
@pytest.mark.slow
@pytest.mark.parametrize("module", ["stickslip.sim.emulators", "stickslip.sim.console_emulator"])
def test_an_emulator_served_from_the_command_line_stops_cleanly_on_sigterm(module):
    # python -m <emulator> --tcp prints its URL, serves until SIGTERM, then prints what it received and exits 0
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", module, "--tcp", "--seed", "3"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        url = proc.stdout.readline().strip()
        assert "://127.0.0.1:" in url, url  # loopback only
        dev = open_device(url)
        dev.close()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "commands received" in out


def test_a_pseudo_terminal_on_a_system_without_one_is_a_clear_error(monkeypatch):
    # Windows has no pty: the emulator says to use TCP instead of failing inside tty/termios
    monkeypatch.setattr(os, "name", "nt")
    with pytest.raises(OSError, match="transport='tcp'"):
        NanoControlEmulator(transport="pty").start()
