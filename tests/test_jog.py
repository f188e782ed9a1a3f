"""Teleoperation: the pure resolved-rate law (keys -> velocity -> step rates, capped) and `stickslip jog`
driven through a pseudo-terminal with scripted key presses.

References: at the outstretched pose the Jacobian's columns are the base axes
(+x along the arm: joint 3; +y: joint 1 at lever rho; +z: joint 2 at lever r), so each
direction key must step exactly one joint at ``v / (lever * gamma)`` steps/s, with
gamma from ``Calibration.gamma`` (the model's point value, not the planner's
integrals); single-step moves are checked against ``stickslip.motion.planning.plan_move``.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.cli import app
from stickslip.devices.positions import DeviceState
from stickslip.motion.planning import plan_move
from stickslip.procedures.jog import SPEEDS, JogController, parse_keys, run_jog
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.emulators import NanoControlEmulator
from test_reach import CAL

OUT = kin.Pose(0.0, -math.pi / 2, 0.002, 0.0, 0.0)  # outstretched, level
G = kin.DEFAULT_GEOMETRY


def ctl(pose: kin.Pose = OUT, **kw) -> JogController:
    return JogController(CAL, list(pose[:3]), pose.theta, pose.psi, **kw)


def test_parse_keys():
    assert parse_keys(b"\x1b[A\x1b[B\x1b[C\x1b[D\x1b[5~\x1b[6~") == ["up", "down", "right", "left", "pgup", "pgdn"]
    assert parse_keys(b"WaSdRf q\x03") == ["w", "a", "s", "d", "r", "f", "space", "q", "q"]
    assert parse_keys(b"1 7+-=mb[]") == ["1", "space", "7", "+", "-", "+", "m", "b", "[", "]"]
    assert parse_keys(b"\xe0H\xe0P\x00I\x00Q") == ["up", "down", "pgup", "pgdn"]  # Windows (msvcrt)
    assert parse_keys(b"\x1b\x1b[Zxyz9") == []  # unknown escapes and keys are dropped


@pytest.mark.parametrize(
    "key, joint, lever",
    [
        ("d", 3, 1.0),
        ("right", 3, 1.0),
        ("w", 1, G.length + OUT.q3),
        ("pgup", 2, G.length + OUT.q3),
        ("a", 3, 1.0),
        ("s", 1, G.length + OUT.q3),
        ("f", 2, G.length + OUT.q3),
    ],
)
def test_each_axis_steps_one_joint_at_the_outstretched_pose(key, joint, lever):
    c = ctl(speed_index=4)  # 10 µm/s
    c.press(key, 0.0)
    sign = 1 if key in ("d", "right", "w", "pgup") else -1
    rates, scale = c.rates(tuple(c.speed * x for x in c.direction))
    assert scale == 1.0
    gamma = CAL.gamma(joint, "+" if sign > 0 else "-", OUT)
    expected = sign * 10e-6 / lever / gamma
    assert rates[joint - 1] == pytest.approx(expected, rel=1e-3)  # gamma over one step vs at a point
    assert [r for j, r in enumerate(rates, 1) if j != joint] == pytest.approx([0.0, 0.0], abs=1e-9)


@settings(max_examples=80, deadline=None)
@given(
    st.tuples(st.floats(-1.5, 1.5), st.floats(-3.0, -0.3), st.floats(0.0, 0.012)),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 0.1),
    st.floats(5.0, 5000.0),
)
def test_rates_keep_the_direction_and_respect_the_cap(q, v, cap):
    c = ctl(kin.Pose(*q, -0.4, 0.2), max_rate=(cap, cap * 1.5, cap / 2))
    v = tuple(100e-6 * x / np.linalg.norm(v) for x in v)
    rates, scale = c.rates(v)
    assert all(abs(r) <= m * (1 + 1e-12) for r, m in zip(rates, c.max_rate, strict=True))
    # back to a tip velocity through the model's step sizes and the Jacobian: parallel to v, |.| = scale |v|
    pose = kin.Pose(*c.q, c.theta, c.psi)
    dq = [r * CAL.gamma(j, "+" if r > 0 else "-", pose) for j, r in enumerate(rates, 1)]
    tip_v = kin.jacobian(c.q) @ dq
    np.testing.assert_allclose(tip_v, np.multiply(v, scale), rtol=0, atol=2e-3 * 100e-6 * scale)


def test_cap_scales_every_joint_together():
    c = ctl(kin.Pose(0.3, -1.2, 0.005), max_rate=(10.0, 10.0, 10.0), speed_index=6)
    c.press("d", 0.0)
    rates, scale = c.rates(tuple(c.speed * x for x in c.direction))
    assert scale < 1 and max(abs(r) for r in rates) == pytest.approx(10.0)


def test_fractions_of_a_step_are_carried_between_ticks():
    """0.1 µm/s along the arm is ~0.1 steps/s: rounding each 50 ms tick would never step."""
    c = ctl(speed_index=0, hold=0.0)
    c.press("d", 0.0)
    total = 0
    for k in range(1, 2001):  # 100 s
        n = c.tick(k * 0.05, 0.05)
        assert n[0] == n[1] == 0
        c.sent_steps(3, n[2])
        total += n[2]
    gamma = CAL.gamma(3, "+", OUT)
    assert abs(total - 100 * 0.1e-6 / gamma) <= 1.0


def test_space_stops_at_once_and_the_hold_times_out():
    c = ctl(speed_index=6, hold=0.5)
    c.press("d", 0.0)
    assert c.tick(0.1, 0.1)[2] > 0
    c.press("space", 0.15)
    assert c.tick(0.2, 0.05) == (0, 0, 0) and c.direction is None
    c.press("d", 1.0)
    assert c.tick(1.2, 0.2)[2] > 0
    assert c.tick(1.6, 0.4) == (0, 0, 0)  # 0.6 s since the last key: released
    assert c.direction is None


def test_limits_and_singular_poses_stop_with_a_message():
    c = ctl(kin.Pose(0.0, -math.pi / 2, 0.012 - 5e-6), speed_index=6)
    c.press("d", 0.0)
    assert c.tick(0.5, 0.5) == (0, 0, 0)
    assert "joint 3 is at its upper limit" in c.message
    c = ctl(kin.Pose(0.0, -math.pi / 2, 0.0), speed_index=6)  # on the lower stop: outwards is allowed
    c.press("d", 0.0)
    assert c.tick(0.5, 0.5)[2] > 0 and c.message == ""
    c = ctl(kin.Pose(0.0, 0.0, 0.005), speed_index=6)
    c.press("w", 0.0)
    assert c.tick(0.1, 0.1) == (0, 0, 0) and "singular" in c.message


def test_speed_keys_and_image_frame():
    c = ctl()
    for key, speed in (("1", 0.1e-6), ("7", 100e-6), ("-", 30e-6), ("+", 100e-6), ("+", 100e-6)):
        c.press(key, 0.0)
        assert c.speed == pytest.approx(speed)
    assert SPEEDS[0] == 0.1e-6 and SPEEDS[-1] == 100e-6
    c = ctl(image_angle=math.radians(90))
    c.press("b", 0.0)
    c.press("d", 0.0)  # +x of the image is +y of the base: joint 1
    np.testing.assert_allclose(c.direction, (0.0, 1.0, 0.0), atol=1e-15)
    c.press("[", 0.0)  # turned back by 15 degrees
    assert math.degrees(c.image_angle) == pytest.approx(75.0)


def test_single_step_mode_moves_by_the_preset_distance():
    c = ctl()
    for key in ("m", "5", "d"):  # single-step, 10 µm, +x (along the arm: joint 3 only)
        c.press(key, 0.0)
    steps = []
    while (n := c.tick(0.0, 0.05)) != (0, 0, 0):
        steps.append(n)
        for j in (1, 2, 3):
            c.sent_steps(j, n[j - 1])
    plan = plan_move(CAL, 3, OUT.q3, OUT.q3 + 10e-6, OUT)
    assert sum(s[2] for s in steps) == plan.steps and all(s[:2] == (0, 0) for s in steps)


def test_run_jog_on_the_simulator_with_scripted_keys():
    sim = SimulatedMM3A(seed=4, day="2026-11-22", pose=OUT)
    state = DeviceState("sim://", {1: OUT.q1, 2: OUT.q2, 3: OUT.q3}, dict.fromkeys((1, 2, 3), "set"))
    c = ctl(speed_index=6, hold=0.0)
    clock = iter(np.arange(0.0, 100.0, 0.05))
    script = [["w"]] + [[]] * 20 + [["space"]] + [[]] * 3 + [["q"]]
    saved = []
    shown = []
    err = run_jog(sim, state, c, lambda t: script.pop(0), shown.append, saved.append, lambda: float(next(clock)))
    assert err is None and c.quit
    assert c.sent[0] > 0 and c.sent[1:] == [0, 0]  # +y at the outstretched pose: joint 1 only
    assert [state.positions[j] for j in (1, 2, 3)] == pytest.approx(c.q, abs=0)
    assert sim.position(1) == pytest.approx(c.q[0], rel=0.05)  # the true arm followed (3 % noise)
    assert saved and shown[-1].sent == c.sent


def test_a_late_tick_moves_as_two_ticks_at_most_not_by_the_stall():
    """A machine that stalls 3 s in the middle of a held key: the tick after it moves the arm as two ticks would."""

    def sent_with(times: list[float]) -> int:
        sim = SimulatedMM3A(seed=4, day="2026-11-22", pose=OUT)
        state = DeviceState("sim://", {1: OUT.q1, 2: OUT.q2, 3: OUT.q3}, dict.fromkeys((1, 2, 3), "set"))
        c = ctl(speed_index=6, hold=0.0)
        clock = iter(times)
        script = [["w"]] + [[]] * 20 + [["q"]]
        assert run_jog(sim, state, c, lambda t: script.pop(0), lambda s: None, lambda s: None,
                       lambda: float(next(clock))) is None
        return c.sent[0]

    steady = list(np.arange(0.0, 100.0, 0.05))
    stalled = steady[:20] + [t + 3.0 for t in steady[20:]]  # 3 s between two readings of the clock
    per_tick = sent_with(steady) / 20  # about 20 ticks of motion
    assert per_tick > 2
    assert abs(sent_with(stalled) - sent_with(steady)) <= 1.5 * per_tick  # at most one tick more (3 s: 60 ticks)


# ---------------------------------------------------------------- through a pseudo-terminal


class Terminal:
    """`stickslip jog` in a subprocess on a pseudo-terminal; keys written, output drained."""

    def __init__(self, args: list[str], env: dict[str, str]):
        self.master, slave = os.openpty()  # its tests skip where there is none
        code = "import sys; from stickslip.cli import app; sys.argv[0] = 'stickslip'; app()"
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code, *args], stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True
        )
        os.close(slave)
        self.output = b""
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()

    def _drain(self) -> None:
        while True:
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            if not data:
                return
            self.output += data

    def wait_for(self, text: bytes, timeout: float = 30.0) -> None:
        end = time.monotonic() + timeout
        while text not in self.output:
            if time.monotonic() > end or self.proc.poll() is not None:
                raise AssertionError(f"{text!r} not seen; output: {self.output.decode(errors='replace')[-2000:]}")
            time.sleep(0.02)

    def keys(self, data: bytes, pause: float = 0.3) -> None:
        os.write(self.master, data)
        time.sleep(pause)

    def finish(self, timeout: float = 30.0) -> int:
        try:
            return self.proc.wait(timeout)
        finally:
            self._reader.join(5)
            os.close(self.master)


def _quiet(emu, settle: float = 0.5, timeout: float = 30.0) -> None:
    """Wait until the emulator has received a step and then nothing for ``settle`` seconds."""
    end = time.monotonic() + timeout
    n, since = -1, time.monotonic()
    while time.monotonic() < end:
        k = len(emu.received)
        if k != n:
            n, since = k, time.monotonic()
        elif any(m.startswith("coarse") for m in emu.received) and time.monotonic() - since > settle:
            return
        time.sleep(0.02)
    raise AssertionError("the emulator did not settle")


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals (POSIX)")
def test_jog_in_a_terminal_steps_the_emulated_nanocontrol(tmp_path):
    cal_path = tmp_path / "cal.json"
    CAL.save(cal_path)
    db = tmp_path / "s.db"
    env = {**os.environ, "STICKSLIP_DB": str(db), "STICKSLIP_TODAY": "2026-11-22"}
    with NanoControlEmulator() as emu:
        term = Terminal(["jog", "-c", str(cal_path), "-d", emu.url, "--q1", "0", "--q2", "-90deg", "--q3", "2mm",
                         "--hold", "0", "--trust-calibration"], env)  # fmt: skip
        term.wait_for(b"keys:")
        term.keys(b"m5d\x1b[A", pause=0.0)  # single-step, 10 µm per press: +x (along the arm), then +y
        _quiet(emu)
        single = list(emu.received)
        term.keys(b"m7")  # continuous, 100 µm/s
        term.keys(b"\x1b[6~", pause=0.5)  # PgDn: -z
        term.keys(b" ", pause=0.3)  # space: stop at once
        after_stop = len(emu.received)
        term.keys(b"", pause=0.4)
        assert len(emu.received) == after_stop  # nothing more after the stop
        term.keys(b"q")
        code = term.finish()
        received = list(emu.received)
    assert code == 0, term.output.decode(errors="replace")
    pat = re.compile(r"^(version|stop|coarse [ABC] [+-][1-9]\d*|speed [ABC] \d+|\w+.*)$")
    assert all(pat.match(m) for m in received), received
    coarse = [(m.split()[1], int(m.split()[2])) for m in received if m.startswith("coarse")]
    first = [(c, n) for c, n in coarse[: len([m for m in single if m.startswith("coarse")])]]
    # the 10 µm press along the arm: joint 3 (channel C) only, as many steps as plan_move gives
    plan3 = plan_move(CAL, 3, 0.002, 0.002 + 10e-6, OUT)
    c_steps = sum(n for c, n in first if c == "C")
    assert abs(c_steps - plan3.steps) <= 1  # the second press may change q3 by a step (the circle)
    # the 10 µm press sideways: joint 1 (channel A), atan(10 µm / 23 mm) of turn
    plan1 = plan_move(CAL, 1, 0.0, math.atan2(10e-6, 0.023), OUT)
    assert sum(n for c, n in first if c == "A") == plan1.steps
    assert not any(c == "B" for c, _ in first)
    # continuous -z at the outstretched pose: joint 2 only, negative
    rest = coarse[len(first) :]
    assert rest and all(c == "B" and n < 0 for c, n in rest)
    # the positions kept are the dead-reckoned end, and the session ended cleanly
    r = CliRunner().invoke(app, ["where", "-d", emu.url, "--db", str(db), "--offline", "--json"])
    w = json.loads(r.stdout)
    assert [j["source"] for j in w["joints"]] == ["dead-reckoned"] * 3
    assert b"jog ended" in term.output


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals (POSIX)")
def test_jog_refuses_without_a_terminal(tmp_path):
    cal_path = tmp_path / "cal.json"
    CAL.save(cal_path)
    env = {**os.environ, "STICKSLIP_DB": str(tmp_path / "s.db"), "STICKSLIP_TODAY": "2026-11-22"}
    code = "import sys; from stickslip.cli import app; sys.argv[0] = 'stickslip'; app()"
    r = subprocess.run(
        [sys.executable, "-c", code, "jog", "-c", str(cal_path)],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        env=env,
        timeout=60,
    )
    assert r.returncode == 2 and b"needs a terminal" in r.stderr and r.stderr.count(b"error:") == 1


def test_run_jog_over_the_emulated_anc300():
    """The same law over the ANC300's protocol: +z at the outstretched pose is joint 2 (axis 2) only, upwards."""
    pytest.importorskip("pymeasure")
    from stickslip.devices.base import open_device
    from stickslip.sim.emulators import ANC300Emulator

    with ANC300Emulator() as emu:
        dev = open_device(emu.url + "&delay=0.002")
        try:
            state = DeviceState("anc", {1: OUT.q1, 2: OUT.q2, 3: OUT.q3}, dict.fromkeys((1, 2, 3), "set"))
            c = ctl(speed_index=6, hold=0.0)
            clock = iter(np.arange(0.0, 100.0, 0.05))
            script = [["r"]] + [[]] * 10 + [["q"]]
            err = run_jog(dev, state, c, lambda t: script.pop(0), lambda s: None, lambda s: None,
                          lambda: float(next(clock)))  # fmt: skip
        finally:
            dev.close()
        sent = list(emu.received)
    assert err is None and c.sent[1] > 0 and c.sent[0] == c.sent[2] == 0
    ups = [int(m.split()[2]) for m in sent if m.startswith("stepu 2 ")]
    assert sum(ups) == c.sent[1]
    assert not any(m.startswith(("stepu 1", "stepu 3", "stepd")) for m in sent), sent


class _Keys:
    def __init__(self, ticks: list[list[str]]) -> None:
        self.ticks = ticks

    def read(self, timeout: float) -> list[str]:
        return self.ticks.pop(0) if self.ticks else ["q"]

    def close(self) -> None:
        pass


def test_a_jog_steps_and_dead_reckons_with_the_tracked_step_scale(tmp_path):
    """A jog dead-reckoned with the bare calibration after `observe` had taught a joint's step scale, so its kept
    position was off by the scale (audit28: reach and tip moves too). A calibration whose joint-1 steps are 25 %
    long, with a track that learnt 0.8, must keep joint 1 where the simulator (whose truth is CAL) put it; the
    track is kept, not restarted at scale 1."""
    from stickslip.devices.base import device_key, open_device
    from stickslip.devices.positions import load_state, save_state
    from stickslip.motion.tracking import JointTrack, scaled_calibration
    from stickslip.procedures.jog import JogRequest, jog
    from stickslip.storage import Store
    from test_reach import DAY

    dev = f"sim://?seed=4&day={DAY}"
    wrong = scaled_calibration(CAL, 1, 1.25)
    clock = iter(np.arange(0.0, 1000.0, 0.05))
    keys = _Keys([["6", "s"]] + [[]] * 40 + [["space"]] + [[]] * 3 + [["q"]])  # -y at 30 µm/s for 2 s: joint 1
    sim = open_device(dev)
    with Store.open(tmp_path / "s.db") as store:
        state = load_state(store, device_key(dev))
        track = JointTrack.fresh(wrong, 1)
        track.log_scale[:] = math.log(0.8)
        state.track[1] = track.to_json()
        save_state(store, state)
        result = jog(store, JogRequest(dev, speed=6, hold=0.0), wrong, keys=lambda: keys, show=lambda s: None,
                     clock=lambda: float(next(clock)), opener=lambda _url: sim)
        kept = load_state(store, device_key(dev))
    true_q1 = float(sim.position(1))
    assert result.error is None and true_q1 < -1e-3
    assert abs(kept.positions[1] - true_q1) < 0.02 * abs(true_q1)  # bare calibration: about 20 % off
    assert JointTrack.from_json(kept.track[1]).scale_of("-") == pytest.approx(0.8, rel=1e-9)
