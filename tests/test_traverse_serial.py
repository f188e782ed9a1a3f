"""A traverse timed by a vibration sensor on a serial port (`traverse --serial`): a vacuum chamber's limit switch.

The controller is the simulated arm seen as a real one (its own clock, but no microphone of
its own), and the "sensor bridge" sends what the arm's structure carries as ASCII samples,
one per line, the way an Arduino reading an accelerometer would; the detector is tuned on
the same stream. The traverse must count the simulator's true steps between the stops.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip import kinematics as kin
from stickslip.audio.sources import vibration
from stickslip.procedures.session import traverse_on_device
from stickslip.sim.arm import SimulatedMM3A

DAY = "2026-11-22"


class _ArmWithoutEars:
    """The simulated arm as a controller with a clock of its own but no microphone: a real controller's path."""

    def __init__(self, arm: SimulatedMM3A) -> None:
        self.arm = arm

    @property
    def clock_s(self) -> float:
        return float(self.arm.clock_s)

    info = property(lambda self: self.arm.info)

    def set_pose(self, **kw: float) -> None:
        self.arm.set_pose(**kw)

    def set_frequency(self, joint: int, hz: float) -> None:
        self.arm.set_frequency(joint, hz)

    def frequency(self, joint: int) -> float:
        return float(self.arm.frequency(joint))

    def step(self, joint: int, n: int) -> None:
        self.arm.step(joint, n)

    def stop(self, joint: int | None = None) -> None:
        self.arm.stop(joint)

    def settings(self) -> Any:
        return self.arm.settings()

    def close(self) -> None:
        pass


class _Bridge:
    """A sensor bridge on a serial line: each sample the arm's structure carried, as one ASCII line (pyserial-like)."""

    def __init__(self, arm: SimulatedMM3A, block: int) -> None:
        self.mic = arm.microphone(block=block)
        self.lines: list[bytes] = []
        self.sent = 0

    def readline(self) -> bytes:
        if not self.lines:
            for b in self.mic():  # what has been carried up to the arm's clock
                self.lines += [f"{v:.6f}\r\n".encode() for v in np.asarray(b, dtype=np.float64)]
            self.lines.reverse()
        if not self.lines:
            return b""  # nothing more: the bridge fell silent (pyserial's timeout)
        self.sent += 1
        return self.lines.pop()

    def close(self) -> None:
        pass


@pytest.mark.slow
def test_a_traverse_timed_by_a_serial_vibration_sensor_counts_the_true_steps(monkeypatch: pytest.MonkeyPatch) -> None:
    arm = SimulatedMM3A(seed=12, day=DAY)
    samples, rate, stop_at = SimulatedMM3A(seed=12, day=DAY).labelled_recording(3, "+")
    tuning = tune(samples, rate, stop_at, joint=3)
    bridges: list[_Bridge] = []
    real = vibration.SerialSamples

    def serial_samples(port: str, sample_rate: int, **kw: Any) -> vibration.SerialSamples:
        assert port == "/dev/ttyACM0" and sample_rate == rate
        bridges.append(_Bridge(arm, block=1024))
        return real(sample_rate=sample_rate, block=1024, serial=bridges[-1])

    monkeypatch.setattr(vibration, "SerialSamples", serial_samples)
    pose = kin.Pose(q1=0.0, q2=-math.pi / 2, q3=0.0, theta=0.0, psi=0.0)
    ctrl = _ArmWithoutEars(arm)
    result = traverse_on_device(
        ctrl, 3, "+", pose, DAY, tuning, serial_port="/dev/ttyACM0", progress=False
    )
    truth = arm.true_models()[(3, "+")]
    g_true = float(truth.average_gamma(0.0, 0.012, 0.0, -math.pi / 2, 0.0, 0.0, 0.0))
    assert bridges and bridges[0].sent > 0.5 * rate  # the stream did come through the serial line
    # per-step noise 3 % over ~12 000 steps: ~0.03 %; the onset is good to a few steps
    assert result.traverse.gamma == pytest.approx(g_true, rel=3e-3)


def test_traverse_takes_a_sound_card_or_a_serial_sensor_not_both(tmp_path: Any) -> None:
    from typer.testing import CliRunner

    from stickslip.cli import app

    args = ["traverse", "--joint", "3", "--direction", "+", "--tuning", str(tmp_path / "t.json"), "--no-db"]
    r = CliRunner().invoke(app, [*args, "--serial", "/dev/ttyACM0", "--input", "2"])
    assert r.exit_code == 2 and "not both" in r.output
