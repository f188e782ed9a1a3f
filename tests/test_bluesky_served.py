"""Bluesky drives a served rig through the client (stickslip.bluesky.ServedAxis): the server plans and moves."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")
pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")

import bluesky.plan_stubs as bps  # noqa: E402
import bluesky.plans as bp  # noqa: E402
from bluesky.utils import FailedStatus  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402
from server_support import room_on, served  # noqa: E402

from stickslip.bluesky import ServedAxis  # noqa: E402
from stickslip.client import Rig  # noqa: E402
from stickslip.server.app import create_app  # noqa: E402
from stickslip.server.room import ControlRoom  # noqa: E402
from stickslip.server.security import Access  # noqa: E402


@pytest.fixture()
def room(tmp_path: Any) -> Iterator[ControlRoom]:
    r = room_on(tmp_path, "sim://?realtime=1&speed=50")
    yield r
    r.close()


@pytest.fixture()
def rig(room: ControlRoom) -> Iterator[Rig]:
    with served(create_app(room, Access(None, True))) as url, Rig(url) as r:
        yield r


def test_a_plan_moves_a_served_joint_and_reads_the_servers_position(RE: Any, rig: Rig, room: ControlRoom) -> None:
    with init_devices():
        q3 = ServedAxis(rig, 3, name="q3")
    RE(bps.mv(q3, 4e-4))
    kept = room.state().positions[3]
    assert kept == pytest.approx(4e-4, abs=0.6e-6)  # the server planned it: within half a step
    location = RE(bps.locate(q3)).plan_result
    assert location["readback"] == kept and location["setpoint"] == 4e-4
    docs: list[tuple[str, Any]] = []
    RE(bp.scan([], q3, 1e-4, 3e-4, 3), lambda name, doc: docs.append((name, doc)))
    readings = [d["data"]["q3"] for n, d in docs if n == "event"]
    assert readings == pytest.approx([1e-4, 2e-4, 3e-4], abs=0.6e-6)


def test_a_refused_move_fails_the_status_with_the_servers_line(RE: Any, rig: Rig) -> None:
    with init_devices():
        q3 = ServedAxis(rig, 3, name="q3")
    with pytest.raises(FailedStatus) as info:
        RE(bps.mv(q3, 0.5))  # 50 cm: outside joint 3's range
    assert "outside joint 3's range" in str(info.value.__cause__ or info.value)


def test_a_served_rig_refuses_a_path_through_a_volume_for_the_client_and_bluesky(RE: Any, tmp_path: Any) -> None:
    import math

    from server_support import rig_room_on

    from stickslip.client import RigError

    room = rig_room_on(tmp_path)
    try:
        with served(create_app(room, Access(None, True))) as url, Rig(url) as rig:
            before = room.owned.dev.steps_simulated
            with pytest.raises(RigError) as err:
                rig.move(2, to="-60deg")
            assert err.value.status == 409 and "'objective'" in str(err.value) and "rig frame" in str(err.value)
            with init_devices():
                q2 = ServedAxis(rig, 2, name="q2")
            with pytest.raises(FailedStatus) as info:
                RE(bps.mv(q2, math.radians(-60)))
            assert "refused by the rig's envelope" in str(info.value.__cause__ or info.value)
            assert room.owned.dev.steps_simulated == before  # nothing sent
    finally:
        room.close()
