"""Bluesky drives a served rig through the client (stickslip.bluesky.ServedAxis): the server plans and moves."""

from __future__ import annotations

import math
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


def _answering(answers: dict[str, Any]) -> Rig:
    """A client whose server answers each path with a fixed body (bytes: as is; else JSON), status 200."""
    import httpx

    def handle(request: httpx.Request) -> httpx.Response:
        body = answers[request.url.path]
        if isinstance(body, Exception):  # the server gone
            raise body
        if isinstance(body, bytes):
            return httpx.Response(200, content=body)
        return httpx.Response(200, json=body)

    rig = Rig("http://garbage.invalid")
    rig._http = httpx.Client(base_url=rig.url, transport=httpx.MockTransport(handle))
    return rig


def _row(joint: int, **kw: Any) -> dict[str, Any]:
    return {"joint": joint, "q": 1e-3, "unit": "m", "sd": None, "uncertain": None, **kw}


def test_the_served_axis_says_when_the_server_keeps_the_position_uncertain() -> None:
    """An axis reports its position as uncertain when the server does (a cut burst, raw steps): as StickSlipAxis."""
    import asyncio

    where = {"joints": [_row(1), _row(2), _row(3, q=2e-3, uncertain=[1.5e-3, 2e-3])]}
    axis = ServedAxis(_answering({"/api/where": where}), 3, name="q3")

    async def read() -> tuple[float, bool]:
        await axis.connect()
        await axis.refresh()
        return await axis.readback.get_value(), await axis.uncertain.get_value()

    assert asyncio.run(read()) == (2e-3, True)
    assert "q3-uncertain" in asyncio.run(axis.read())
    where["joints"][2]["uncertain"] = None
    assert asyncio.run(read()) == (2e-3, False)


@pytest.mark.parametrize(
    "where",
    [
        b"<html>502 Bad Gateway</html>",
        {},
        {"joints": "none"},
        {"joints": [_row(1), _row(2)]},
        {"joints": [_row(1), _row(2), _row(3, q=None)]},
        {"joints": [_row(1), _row(2), _row(3, q="1e-3")]},
        b'{"joints": [{"joint": 1, "q": 0}, {"joint": 2, "q": 0}, {"joint": 3, "q": NaN}]}',
        {"joints": [_row(1), _row(2), _row(2)]},
    ],
)
def test_a_garbage_answer_is_one_line_not_a_position(where: Any) -> None:
    """A server (or proxy) answering garbage fails the read with a MoveError, never a KeyError or a made-up position."""
    import asyncio

    from stickslip.bluesky import MoveError

    axis = ServedAxis(_answering({"/api/where": where}), 3, name="q3")
    with pytest.raises(MoveError, match="not a stickslip server"):
        asyncio.run(axis.refresh())
    assert math.isnan(asyncio.run(axis.readback.get_value()))


@pytest.mark.parametrize("motion", [b"OK", {}, {"id": "7", "status": "running"}, {"id": 7}])
def test_a_garbage_motion_record_fails_the_move_with_one_line(motion: Any) -> None:
    import asyncio

    from stickslip.bluesky import MoveError

    where = {"joints": [_row(1), _row(2), _row(3)]}
    axis = ServedAxis(_answering({"/api/where": where, "/api/move": motion}), 3, name="q3")

    async def move() -> None:
        await axis.connect()
        await axis.set(2e-3)

    with pytest.raises(MoveError, match="not a stickslip server"):
        asyncio.run(move())


def test_a_read_before_any_move_gives_the_servers_position_not_nan() -> None:
    """bp.count of a served axis before any move recorded NaN (the readback was read in only by set and locate)."""
    import asyncio

    where = {"joints": [_row(1), _row(2), _row(3, q=2e-3)]}
    axis = ServedAxis(_answering({"/api/where": where}), 3, name="q3")

    async def read() -> float:
        await axis.connect()
        return float((await axis.read())["q3"]["value"])

    assert asyncio.run(read()) == 2e-3
    where["joints"][2]["q"] = 3e-3  # the page moved it
    assert asyncio.run(read()) == 3e-3


def test_a_served_axis_that_lost_its_server_mid_move_says_its_position_is_uncertain() -> None:
    """The server gone during a move failed the status, but the axis kept its last readback with uncertain False
    (audit28's question 8): a subscriber to the signals read a position the move may have left. Now uncertain."""
    import asyncio

    import httpx

    from stickslip.bluesky import MoveError

    answers: dict[str, Any] = {"/api/where": {"joints": [_row(1), _row(2), _row(3, q=2e-3)]}}
    axis = ServedAxis(_answering(answers), 3, name="q3")

    async def move() -> None:
        await axis.connect()
        await axis.refresh()
        gone = httpx.ConnectError("connection refused")
        answers["/api/move"] = answers["/api/where"] = gone
        await axis.set(3e-3)

    with pytest.raises(MoveError):
        asyncio.run(move())
    assert asyncio.run(axis.uncertain.get_value()) is True
    assert asyncio.run(axis.readback.get_value()) == 2e-3  # the last the server said, flagged
    answers["/api/where"] = {"joints": [_row(1), _row(2), _row(3, q=2.5e-3)]}  # back: the server's word again
    asyncio.run(axis.refresh())
    assert (asyncio.run(axis.readback.get_value()), asyncio.run(axis.uncertain.get_value())) == (2.5e-3, False)
