"""Who may talk to the server: the token (made once, owner-only, never echoed), the host, the origin."""

from __future__ import annotations

import json
import logging
import os
import stat
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")

from fastapi.testclient import TestClient  # noqa: E402
from server_support import room_on  # noqa: E402
from starlette.websockets import WebSocketDisconnect  # noqa: E402

from stickslip.server.app import create_app  # noqa: E402
from stickslip.server.room import ControlRoom  # noqa: E402
from stickslip.server.run import access_for  # noqa: E402
from stickslip.server.security import Access, is_loopback, load_or_create_token, origin_problem  # noqa: E402

TOKEN = "k" * 43


@pytest.fixture()
def room(tmp_path: Path) -> Iterator[ControlRoom]:
    r = room_on(tmp_path, "sim://?realtime=0")
    yield r
    r.close()


def test_the_token_is_made_once_with_owner_only_permissions(tmp_path: Path) -> None:
    path = tmp_path / "cfg" / "serve-token"
    token, new = load_or_create_token(path)
    assert new and len(token) >= 43
    assert path.read_text().strip() == token
    if os.name == "posix":
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
    again, new_again = load_or_create_token(path)
    assert (again, new_again) == (token, False)
    path.write_text("short\n")
    with pytest.raises(ValueError, match="does not hold a usable token"):
        load_or_create_token(path)


def test_the_token_is_printed_once_and_never_again(tmp_path: Path) -> None:
    lines: list[str] = []
    path = tmp_path / "t"
    access = access_for("0.0.0.0", path, lines.append)
    assert access.token is not None and not access.loopback
    assert any(access.token in line for line in lines)
    from stickslip.devices.base import redact_text

    hint = next(line for line in lines if "#token" in line)
    assert redact_text(hint) == hint  # the instruction is not shown as '#token=***' (audit34)
    lines.clear()
    assert access_for("0.0.0.0", path, lines.append).token == access.token
    assert lines and not any(access.token in line for line in lines)
    assert access_for("127.0.0.1", path, lines.append) == Access(None, True)


@pytest.mark.parametrize(
    ("host", "loop"),
    [("127.0.0.1", True), ("localhost", True), ("::1", True), ("[::1]", True), ("127.3.2.1", True),
     ("0.0.0.0", False), ("192.168.1.5", False), ("example.org", False), ("", False)],
)
def test_is_loopback(host: str, loop: bool) -> None:
    assert is_loopback(host) is loop


@pytest.mark.parametrize(
    ("origin", "host", "ok"),
    [(None, "127.0.0.1:8765", True), ("http://127.0.0.1:8765", "127.0.0.1:8765", True),
     ("http://localhost:8765", "127.0.0.1:8765", False), ("https://evil.example", "127.0.0.1:8765", False),
     ("null", "127.0.0.1:8765", False), ("http://127.0.0.1:8766", "127.0.0.1:8765", False)],
)
def test_origin_problem(origin: str | None, host: str, ok: bool) -> None:
    assert (origin_problem(origin, host) is None) is ok


def test_a_loopback_server_refuses_other_host_names_and_cross_origin_requests(room: ControlRoom) -> None:
    with TestClient(create_app(room, Access(None, True)), base_url="http://127.0.0.1:8765") as c:
        assert c.get("/api/state").status_code == 200
        r = c.get("/api/state", headers={"host": "evil.example:8765"})  # DNS rebinding
        assert r.status_code == 403 and "loopback host name" in r.json()["error"]
        r = c.post("/api/stop", headers={"origin": "https://evil.example"})
        assert r.status_code == 403 and "cross-origin" in r.json()["error"]
        r = c.post("/api/stop", headers={"sec-fetch-site": "cross-site"})
        assert r.status_code == 403
        r = c.post("/api/stop", headers={"origin": "http://127.0.0.1:8765"})
        assert r.status_code == 200
        with pytest.raises(WebSocketDisconnect) as info, c.websocket_connect(
            "ws://127.0.0.1:8765/api/live", headers={"origin": "https://evil.example"}
        ) as ws:
            ws.receive_text()
        assert info.value.code == 4403


def test_elsewhere_every_request_needs_the_token(room: ControlRoom, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    app = create_app(room, Access(TOKEN, False))
    with TestClient(app, base_url="http://192.0.2.10:8765") as c:
        for method, path in (("GET", "/api/state"), ("POST", "/api/stop"), ("GET", "/openapi.json"),
                             ("POST", "/api/move"), ("GET", "/api/motions/1")):
            r = c.request(method, path)
            assert r.status_code == 401 and "needs its token" in r.json()["error"], (path, r.text)
        r = c.get("/api/state", headers={"authorization": "Bearer wrong"})
        assert r.status_code == 401 and "wrong token" in r.json()["error"]
        r = c.get("/api/state", headers={"authorization": f"Basic {TOKEN}"})
        assert r.status_code == 401
        ok = c.get("/api/state", headers={"authorization": f"Bearer {TOKEN}"})
        assert ok.status_code == 200
        assert c.get("/").status_code == 200  # the page holds nothing: it asks for the token
        # a browser's WebSocket sends the token as its first message
        with c.websocket_connect("ws://192.0.2.10:8765/api/live") as ws:
            ws.send_text(json.dumps({"type": "auth", "token": TOKEN}))
            assert "seq" in json.loads(ws.receive_text())
        with pytest.raises(WebSocketDisconnect) as info, c.websocket_connect("ws://192.0.2.10:8765/api/live") as ws:
            ws.send_text(json.dumps({"type": "auth", "token": "nope"}))
            ws.receive_text()
        assert info.value.code == 4401
        with c.websocket_connect(
            "ws://192.0.2.10:8765/api/live", headers={"authorization": f"Bearer {TOKEN}"}
        ) as ws:
            assert "seq" in json.loads(ws.receive_text())
        texts = [ok.text, c.get("/api/events", headers={"authorization": f"Bearer {TOKEN}"}).text]
    for text in texts + [rec.getMessage() for rec in caplog.records]:
        assert TOKEN not in text


def test_a_device_password_never_leaves_the_server(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from stickslip.devices.base import register_backend
    from stickslip.server.room import ControlRoom, RoomOptions
    from stickslip.sim.arm import SimulatedMM3A

    caplog.set_level(logging.DEBUG)
    register_backend("pwtest", lambda url: SimulatedMM3A(url=url))
    try:
        room = ControlRoom(RoomOptions(device="pwtest://admin:hunter2@10.0.0.2?password=hunter2",
                                       db=tmp_path / "x.db"))
        try:
            with TestClient(create_app(room, Access(None, True)), base_url="http://127.0.0.1") as c:
                texts = [c.get(p).text for p in ("/api/state", "/api/where", "/api/events", "/openapi.json")]
                texts.append(c.post("/api/move", json={"joint": 3, "by": "1um"}).text)
        finally:
            room.close()
    finally:
        from stickslip.devices.base import BACKENDS

        BACKENDS.pop("pwtest", None)
    for text in texts + [rec.getMessage() for rec in caplog.records]:
        assert "hunter2" not in text, text


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX permissions")
def test_the_token_file_is_never_readable_by_others_even_when_the_umask_is_open(tmp_path: Path) -> None:
    old = os.umask(0)
    try:
        _, new = load_or_create_token(tmp_path / "open-umask-token")
    finally:
        os.umask(old)
    assert new
    assert stat.S_IMODE((tmp_path / "open-umask-token").stat().st_mode) == 0o600
