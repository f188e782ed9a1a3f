"""The API as a careless script or a hostile client uses it: a body sent without a length, a binary frame."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

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
    import asyncio
    import threading

    import uvicorn
    import websockets

    from stickslip.server.live import MAX_MESSAGE
    from stickslip.server.run import server_config

    room = room_on(tmp_path, "sim://?realtime=0")
    config = server_config(create_app(room, Access(None, True)), "127.0.0.1", 0)
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        while not server.started:
            thread.join(0.02)
        port = server.servers[0].sockets[0].getsockname()[1]

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
    finally:
        server.should_exit = True
        thread.join(10)
        room.close()
