"""The server's parts on their own: named positions, the owned controller (STOP), the tip's spread, the PNG, the CLI."""

from __future__ import annotations

import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.cli import app
from stickslip.devices.base import BurstStopped, DeviceInfo, StepsUncertain
from stickslip.devices.positions import load_state, save_state
from stickslip.procedures import named
from stickslip.procedures.move import MoveRefused
from stickslip.storage import Store

runner = CliRunner()


# ---------------------------------------------------------------- named positions


def test_named_positions_are_kept_per_device(tmp_path: Path) -> None:
    store = Store.open(tmp_path / "n.db")
    state = load_state(store, "sim://")
    state.set_position(3, 0.002, "set")
    save_state(store, state)
    p = named.save_position(store, "sim://?seed=0&day=x", "above")  # the device's key: options do not matter
    assert p.q == (0.0, -math.pi / 2, 0.002) and p.as_dict()["display"][2] == "2000 µm"
    assert [q.name for q in named.positions(store, "sim://")] == ["above"]
    named.save_position(store, "sim://", "above")  # replaced, not doubled
    assert len(named.positions(store, "sim://")) == 1
    assert named.positions(store, "sim://?seed=5") == []
    named.delete_position(store, "sim://", "above")
    with pytest.raises(KeyError, match="no position named 'above'"):
        named.delete_position(store, "sim://", "above")
    for bad in ("", " lead", "x" * 41, "a/b", "tab\there"):
        with pytest.raises(ValueError, match="position name"):
            named.save_position(store, "sim://", bad)
    state.mark_uncertain(2, -1.0, 0.0, "a move was interrupted")
    save_state(store, state)
    with pytest.raises(MoveRefused, match="uncertain"):
        named.save_position(store, "sim://", "there")
    store.set_state("sim://", "named", {"broken": {"q": "nope"}})
    with pytest.raises(ValueError, match="unreadable"):
        named.positions(store, "sim://")


# ---------------------------------------------------------------- the owned controller


class _Real:
    """A controller that is not a simulator (no true position): a burst returns when done, stop is noted."""

    info = DeviceInfo("fake://", "fake")

    def __init__(self) -> None:
        self.sent: list[int] = []
        self.stops = 0
        self.owner: object = None

    def set_frequency(self, joint: int, hz: float) -> None: ...

    def frequency(self, joint: int) -> float:
        return 1000.0

    def step(self, joint: int, n: int) -> None:
        self.sent.append(n)
        if n == 77:  # STOP arrives while this burst runs
            self.owner.halt()  # type: ignore[attr-defined]

    def stop(self, joint: int | None = None) -> None:
        self.stops += 1

    def settings(self) -> dict[str, object]:
        return {}

    def close(self) -> None:
        raise AssertionError("a procedure must not close the server's controller")


def test_stop_during_a_real_controllers_burst_leaves_that_burst_uncertain() -> None:
    from stickslip.server.owned import OwnedController

    dev = _Real()
    owned = OwnedController(dev)
    dev.owner = owned
    owned.step(3, 10)
    with pytest.raises(StepsUncertain) as info:
        owned.step(3, 77)
    assert (info.value.made, info.value.at_most) == (0, 77)  # anywhere between none and all of it
    with pytest.raises(BurstStopped) as stopped:
        owned.step(3, 5)  # nothing more is sent after STOP
    assert stopped.value.made == 0 and dev.sent == [10, 77]
    assert dev.stops == 1
    owned.resume()
    owned.step(3, 5)
    assert dev.sent[-1] == 5
    owned.close()  # a procedure's close: nothing happens
    assert not hasattr(owned, "set_pose")  # a real controller has no pose to set, and the wrapper claims none


def test_a_drive_stopped_by_stop_keeps_an_honest_position() -> None:
    from stickslip.devices.positions import DeviceState
    from stickslip.procedures.move import drive
    from stickslip.server.owned import OwnedController

    dev = _Real()
    owned = OwnedController(dev)
    dev.owner = owned
    state = DeviceState.default("fake://")
    state.set_position(3, 0.001, "set")
    out = drive(owned, state, 3, 177, 100, lambda n: 0.001 + n * 1e-6, lambda s: None)
    # bursts of 100 then 77: STOP during the second, so it may have gone anywhere from 0 to 77 steps
    assert out.sent == 100 and out.error is not None and "cut short" in out.error
    assert state.uncertain[3] == pytest.approx((0.001 + 100e-6, 0.001 + 177e-6))


# ---------------------------------------------------------------- the tip's spread


def test_tip_sd_is_the_jacobian_propagation() -> None:
    q = np.array([0.3, -1.1, 0.004])
    sd = np.array([2e-5, 5e-5, 1e-6])
    got = kin.tip_sd(q, sd)
    # finite differences of the tip, independent of the closed-form Jacobian
    h = 1e-7
    cols = [(kin.tip(q + h * e) - kin.tip(q - h * e)) / (2 * h) for e in np.eye(3)]
    J = np.stack(cols, axis=1)
    assert got == pytest.approx(np.sqrt((J**2) @ (sd**2)), rel=1e-6)
    assert kin.tip_sd(q, [0, 0, 0]) == pytest.approx([0, 0, 0])
    # joint 3 alone moves the tip along the arm: its sd, split over the arm's direction
    z2 = np.array([-math.sin(q[1]) * math.cos(q[0]), -math.sin(q[1]) * math.sin(q[0]), math.cos(q[1])])
    assert kin.tip_sd(q, [0, 0, 1e-6]) == pytest.approx(1e-6 * np.abs(z2), abs=1e-18)


# ---------------------------------------------------------------- the camera's PNG


def test_the_png_encoder_round_trips_through_zlib() -> None:
    from stickslip.server.camera import png_grey

    img = np.linspace(0, 1, 12 * 7).reshape(7, 12)
    data = png_grey(img)
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    w, h, depth, kind = struct.unpack(">IIBB", data[16:26])
    assert (w, h, depth, kind) == (12, 7, 8, 0)
    idat_len = struct.unpack(">I", data[33:37])[0]
    raw = zlib.decompress(data[41 : 41 + idat_len])
    rows = np.frombuffer(raw, dtype=np.uint8).reshape(7, 13)
    assert (rows[:, 0] == 0).all()  # filter byte 0 on every row
    assert rows[:, 1:] == pytest.approx(np.round(img * 255), abs=0.5)
    with pytest.raises(ValueError, match="2-D"):
        png_grey(np.zeros((2, 2, 3)))


# ---------------------------------------------------------------- the command


def test_serve_help_teaches() -> None:
    r = runner.invoke(app, ["serve", "--help"], terminal_width=80)
    assert r.exit_code == 0
    text = " ".join(r.output.split())
    for words in ("--device", "--camera", "--host", "--port", "realtime=1", "--rig", "--arm", "envelope", "token"):
        assert words in text, words


def test_serve_refuses_bad_input_in_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    r = runner.invoke(app, ["serve", "-d", "/dev/ttyUSB0"])
    assert r.exit_code == 2 and "no scheme" in r.output
    r = runner.invoke(app, ["serve", "--tuning", "3"])
    assert r.exit_code == 2 and "write J=FILE" in r.output
    r = runner.invoke(app, ["serve", "-c", str(tmp_path / "none.json")])
    assert r.exit_code == 2 and "does not exist" in r.output
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        r = runner.invoke(app, ["serve", "--port", str(port), "--db", str(tmp_path / "x.db")])
    assert r.exit_code == 2 and f"port {port} on 127.0.0.1 is in use" in r.output
    assert "Traceback" not in r.output


def test_serve_without_the_extra_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "fastapi" else real(name, *a))
    r = runner.invoke(app, ["serve"])
    assert r.exit_code == 2 and "pip install 'stickslip[serve]'" in r.output


def test_a_sim_url_runs_in_real_time_unless_it_says_otherwise() -> None:
    from stickslip.cli.serve import with_realtime

    assert with_realtime("sim://") == "sim://?realtime=1"
    assert with_realtime("sim://?seed=2") == "sim://?seed=2&realtime=1"
    assert with_realtime("sim+physics://?seed=2") == "sim+physics://?seed=2&realtime=1"
    assert with_realtime("sim://?realtime=0&seed=1") == "sim://?realtime=0&seed=1"
    assert with_realtime("anc300://10.0.0.2") == "anc300://10.0.0.2"


def test_the_camera_panel_tracks_the_simulated_microscopes_tip(tmp_path: Path) -> None:
    pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")
    from server_support import room_on

    from stickslip.server.run import ServeError, open_camera_feed
    from stickslip.sim.camera import SimCamera

    room = room_on(tmp_path, "sim://?realtime=1&speed=50")
    try:
        probe = open_camera_feed("simcam://?seed=1&size=160x120", room.owned)
        assert isinstance(probe.camera, SimCamera)  # type: ignore[attr-defined]
        (x0, y0), _ = probe.camera.true_tip()  # type: ignore[attr-defined]
        feed = open_camera_feed("simcam://?seed=1&size=160x120", room.owned, (float(x0), float(y0)))
        data, media, size = feed.frame()
        assert media == "image/png" and data[:4] == b"\x89PNG" and size == (160, 120)
        room.reach(None, (0.0, 3e-6, 0.0)).finished.wait(20)
        feed.frame()
        tip = feed.tip()
        (x1, y1), _ = feed.camera.true_tip()  # type: ignore[attr-defined]
        # tracked to the true tip: 0.74 px; 1.39 before the first move confirmed the template's mask (a dust grain)
        assert tip is not None and math.hypot(tip[0] - x1, tip[1] - y1) < 1.0
        assert math.hypot(x1 - x0, y1 - y0) > 2  # and the tip did move in the image
        assert feed.to_pixels([[0.0, 0.0, 0.0]]) is None  # no projection without a camera calibration
        with pytest.raises(ServeError, match="--camera"):
            open_camera_feed("nocam://x", room.owned)
    finally:
        room.close()


def test_a_clients_message_hides_the_secret_and_keeps_the_rest_of_the_line() -> None:
    from stickslip.server.slot import one_line

    text = one_line(ValueError("cannot open 'anc300://H:7230?password=hunter2' (timed out after 2 s)"))
    assert text == "cannot open 'anc300://H:7230?password=***' (timed out after 2 s)"
