"""The API as a careless script or a hostile client uses it: a body sent without a length, a binary frame."""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")

from fastapi.testclient import TestClient  # noqa: E402
from server_support import room_on  # noqa: E402

from stickslip.server.app import MAX_BODY, create_app  # noqa: E402
from stickslip.server.security import Access  # noqa: E402


@pytest.fixture()
def client(tmp_path: Path) -> Iterator[TestClient]:
    room = room_on(tmp_path, "sim://?realtime=0")
    try:
        with TestClient(create_app(room, Access(None, True)), base_url="http://127.0.0.1:8765",
                        raise_server_exceptions=False) as c:
            yield c
    finally:
        room.close()


def test_a_body_too_large_sent_without_a_length_is_413_not_unreadable_json(client: TestClient) -> None:
    """Before: 100 MB sent chunked (no Content-Length) to /api/move was stopped at 64 kB but answered 422 "the body
    cannot be read as JSON (There was an error parsing the body)": FastAPI wrapped the guard's refusal."""
    def chunks() -> Iterator[bytes]:
        for _ in range(100):  # 1.6 MB in 16 kB chunks (uvicorn stops reading after the fifth; the test client
            yield b" " * 16384  # sends them all)

    r = client.post("/api/move", content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413, r.text
    assert r.json() == {"error": f"the request body is larger than {MAX_BODY // 1024} kB"}
    small = client.post("/api/move", content=iter([b'{"joint": 3, ', b'"by": "1e300mm"}']),
                        headers={"content-type": "application/json"})
    assert small.status_code == 422 and "outside joint 3's range" in small.json()["error"], small.text


def test_a_binary_frame_on_the_websocket_is_answered_and_the_socket_stays(client: TestClient) -> None:
    """Before: a binary frame (even one holding a JSON stop) closed the socket with 1000 and no word."""
    with client.websocket_connect("ws://127.0.0.1:8765/api/live") as ws:
        assert "seq" in json.loads(ws.receive_text())
        ws.send_bytes(b'{"type": "stop"}')
        replies = [json.loads(ws.receive_text()) for _ in range(3)]
        errors = [r for r in replies if "error" in r]
        assert errors and "text frame" in errors[0]["error"], replies
        ws.send_text('{"type": "ping"}')
        for _ in range(200):
            reply = json.loads(ws.receive_text())
            if "reply" in reply:
                break
        assert reply == {"reply": "pong"}


def test_a_websocket_message_larger_than_64_kb_closes_the_socket_on_a_real_server(tmp_path: Path) -> None:
    """Before: uvicorn took messages up to 16 MiB; ten clients each sending one held 420 MB of the server (RSS
    226 -> 646 MB, 307 MB after). Now a message over :data:`MAX_MESSAGE` closes its socket (1009), a command fits."""
    import websockets

    from stickslip.server.live import MAX_MESSAGE
    from stickslip.server.run import server_config

    room = room_on(tmp_path, "sim://?realtime=0")
    config = server_config(create_app(room, Access(None, True)), "127.0.0.1", 0)
    with _uvicorn(config) as (_, port):

        async def talk(size: int) -> str:
            async with websockets.connect(f"ws://127.0.0.1:{port}/api/live", max_size=None) as ws:
                await ws.send(json.dumps({"type": "ping", "pad": "a" * size}))
                try:
                    while "reply" not in (text := str(await ws.recv())):
                        pass
                except websockets.ConnectionClosed as e:
                    return f"closed {e.rcvd.code if e.rcvd else None}"
                return text

        assert asyncio.run(talk(MAX_MESSAGE - 100)) == '{"reply": "pong"}'
        assert asyncio.run(talk(MAX_MESSAGE + 1)) == "closed 1009"
        assert config.ws_max_size == MAX_MESSAGE == 65536
    room.close()


@contextlib.contextmanager
def _uvicorn(config: Any) -> Iterator[tuple[asyncio.AbstractEventLoop, int]]:
    """A real uvicorn server in a thread: its loop and port."""
    import uvicorn

    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        while not server.started:
            thread.join(0.02)
        yield server.servers[0].get_loop(), server.servers[0].sockets[0].getsockname()[1]
    finally:
        server.should_exit = True
        thread.join(10)


def test_a_stop_on_the_websocket_is_not_queued_behind_work_that_holds_every_thread(tmp_path: Path) -> None:
    """Before: a WebSocket message was carried out in the loop's default executor (6 threads on 2 cores), which
    eight ``GET /api/motions/ID?wait=30`` filled: a stop sent during a 12 mm move was answered after the move ended
    by itself (8.8 s, "stopped": null). Now a stop is carried out on the loop, and ``?wait`` holds no thread."""
    import httpx
    import websockets

    from stickslip.server.run import server_config

    room = room_on(tmp_path, "sim://?realtime=1")
    held = threading.Event()
    with _uvicorn(server_config(create_app(room, Access(None, True)), "127.0.0.1", 0)) as (loop, port):
        async def fill() -> None:  # every worker of the default executor busy until the test ends
            for _ in range(64):
                loop.run_in_executor(None, held.wait)

        asyncio.run_coroutine_threadsafe(fill(), loop).result(5)

        async def talk() -> tuple[dict[str, Any], dict[str, Any]]:
            async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=5) as c:
                started = (await c.post("/api/step", json={"joint": 3, "steps": 20000})).json()
                waited = (await c.get(f"/api/motions/{started['id']}?wait=0.05")).json()
                async with websockets.connect(f"ws://127.0.0.1:{port}/api/live", close_timeout=1) as ws:
                    await ws.send(json.dumps({"type": "stop"}))
                    async def answer() -> dict[str, Any]:  # the state messages (20 a second) passed over
                        while "reply" not in (reply := json.loads(await ws.recv())):
                            pass
                        return reply

                    try:
                        reply = await asyncio.wait_for(answer(), 5)
                    except TimeoutError:
                        held.set()  # the stop waits for a thread: let them go, so that the server can end
                        raise
                return waited, reply

        try:
            waited, reply = asyncio.run(talk())
        finally:
            held.set()
    room.close()
    assert waited["status"] == "running", waited
    assert reply["reply"] == "stop" and reply["motion"] == waited["id"] and reply["stopped"] == waited["what"], reply


def test_a_value_quoted_back_in_an_error_is_cut(client: TestClient) -> None:
    """Before: ``{"by": "x" * 60000}`` was answered with a 60 kB error line quoting it whole (the page shows it);
    on the WebSocket an unknown type of 60 000 characters too."""
    from stickslip.server.live import command

    max_line = 600  # slot.MAX_LINE
    r = client.post("/api/move", json={"joint": 3, "by": "x" * 60000})
    line = r.json()["error"]
    assert r.status_code == 422 and line.startswith("by: cannot read 'xxx") and len(line) <= max_line, len(line)
    assert " ...[59488 characters cut]... " in line and line.endswith("xxx' as a number with an optional unit"), line
    reply = command(client.app.state.room, json.dumps({"type": "y" * 60000}))  # type: ignore[attr-defined]
    assert reply["error"].startswith("unknown message type 'yyy") and len(reply["error"]) <= max_line


def test_a_body_or_message_giving_a_key_twice_is_refused_not_read_with_the_last(tmp_path: Path) -> None:
    """{"joint": 1, "joint": 3, "by": "10um"} moved joint 3 (JSON readers keep the last key; audit34's question 2).
    Now 422 naming the key; a WebSocket message alike; a STOP is never refused for its body or message."""
    from stickslip.server.live import command

    room = room_on(tmp_path)
    try:
        with TestClient(create_app(room, Access(None, True)), base_url="http://127.0.0.1:8765") as c:
            before = room.state().positions[3]
            r = c.post("/api/move", content=b'{"joint": 1, "joint": 3, "by": "10um"}',
                       headers={"content-type": "application/json"})
            assert r.status_code == 422 and "the key 'joint' twice" in r.json()["error"], r.text
            assert room.current() is None and room.state().positions[3] == before
            r = c.post("/api/stop", content=b'{"a": 1, "a": 2}', headers={"content-type": "application/json"})
            assert r.status_code == 200, r.text
        reply = command(room, '{"type": "jog", "direction": "+x", "direction": "-x"}')
        assert "the key 'direction' twice" in reply["error"] and room.current() is None
        assert command(room, '{"type": "jog", "type": "stop"}')["reply"] == "stop"
    finally:
        room.close()
