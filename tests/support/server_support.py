"""What the server's tests share: a room on the simulator with its true calibration, a running server, waiting.

``room_on(tmp_path, url)`` builds a :class:`~stickslip.server.room.ControlRoom` on a
fresh database with the simulated arm's own models as its calibration (exact by
construction, joint 1 included); ``served(app)`` runs an app under uvicorn on a free
loopback port in a thread (for the client, the browser and the benchmark), and stops it.
``until(predicate)`` polls a condition (never a fixed sleep standing in for a measurement).
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from stickslip.calibration import Calibration
from stickslip.devices.base import open_device
from stickslip.server.room import ControlRoom, RoomOptions
from stickslip.sim.arm import SimulatedMM3A
from stickslip.sim.urls import virtual_clock_url

DAY = "2026-11-22"


def true_calibration(url: str) -> Calibration:
    """The models of the arm ``url`` opens (its seed and day), as a calibration: exact by construction."""
    sim = open_device(virtual_clock_url(url))
    assert isinstance(sim, SimulatedMM3A)
    models = sim.true_models()
    return Calibration(
        models=models, stderr=dict.fromkeys(models), constant_steps=dict.fromkeys(models, 1e-6), day=DAY,
        method="paper",
    )


def room_on(
    tmp_path: Path, url: str = "sim://?realtime=1&speed=50", calibrated: bool = True, **options: Any
) -> ControlRoom:
    """A control room on ``url`` with a fresh database (and the arm's true calibration unless not ``calibrated``)."""
    cal_path = None
    if calibrated:
        cal_path = tmp_path / "true-cal.json"
        true_calibration(url).save(cal_path)
    return ControlRoom(RoomOptions(device=url, db=tmp_path / "serve.db", calibration=cal_path, **options))


def free_port() -> int:
    """A TCP port free on the loopback address now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def served(app: Any, port: int | None = None) -> Iterator[str]:
    """Serve ``app`` with uvicorn on 127.0.0.1 in a thread; yields ``http://127.0.0.1:PORT``; stops it after."""
    import uvicorn

    port = port or free_port()
    config = uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning", access_log=False, lifespan="on")
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, name="uvicorn", daemon=True)
    thread.start()
    until(lambda: server.started, 20.0, "the server to start")
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(10.0)


def until(predicate: Callable[[], object], timeout: float = 20.0, what: str = "the condition") -> None:
    """Wait until ``predicate()`` is true (polled every 10 ms); ``AssertionError`` naming ``what`` after ``timeout``."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.01)


RIG = """\
name = "bench"
arm_distance = "1mm"

[[arm]]
name = "probe"
controller = "sim://"
mount = { origin = ["-30mm", "0mm", "0mm"] }

[[arm]]
name = "other"
controller = "sim://?seed=2"
mount = { origin = ["30mm", "0mm", "0mm"], rotation = ["0deg", "0deg", "180deg"] }

[[volume]]
name = "objective"
shape = "cylinder"
base = ["-7mm", "0mm", "6mm"]
axis = [0, 0, 1]
radius = "3mm"
height = "20mm"
margin = "200um"

[[volume]]
name = "lid"
shape = "half-space"
point = ["0mm", "0mm", "{lid}"]
normal = [0, 0, 1]
margin = "10um"

[[position]]
name = "park"
arm = "probe"
q2 = "-120deg"
q3 = "0mm"
order = [3, 2]
"""
"""A rig for the server's tests: the probe (served; its tip at (-9, 0, 0) mm outstretched), another arm
kept 60 mm away, an objective above the probe's tip, a lid (a half-space above, at ``lid``) and a named
position ``park``."""


def rig_room_on(
    tmp_path: Path, lid: str = "30mm", arm: str = "probe", url: str = "sim://?realtime=1&speed=50", **options: Any
) -> ControlRoom:
    """A control room serving the rig :data:`RIG`'s ``arm`` (its simulator in real time at 50x: the probe's
    ``sim://``, the other's ``sim://?seed=2``); two rooms of one ``tmp_path`` share its database."""
    from stickslip.rig import load_rig

    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", lid), encoding="utf-8")
    cal_path = tmp_path / f"true-cal-{arm}.json"
    true_calibration(url).save(cal_path)
    return ControlRoom(RoomOptions(device=url, db=tmp_path / "serve.db", calibration=cal_path, rig=load_rig(path),
                                   arm=arm, **options))
