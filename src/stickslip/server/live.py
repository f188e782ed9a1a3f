"""The live state on a WebSocket: one snapshot per tick to every client, and the messages clients send.

``/api/live`` streams :data:`RATE_HZ` state messages a second; a client sends ``stop``,
``jog`` (a held direction, the dead man's switch), ``release`` or ``ping``. A page that
goes away with a jog key held stops the jog.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import secrets
import time
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from ..records import repeated_key
from .requests import JogBody
from .room import ControlRoom
from .security import Access
from .slot import Refused, one_line

__all__ = ["MAX_MESSAGE", "QUEUE", "RATE_HZ", "Client", "Live", "clean", "command", "is_stop", "live_routes"]

log = logging.getLogger("stickslip.server")

RATE_HZ = 20.0
"""Live-state messages per second on the WebSocket."""

MAX_MESSAGE = 64 * 1024
"""Largest WebSocket message a client may send, bytes (a command is under 100; a larger one closes the socket, 1009)."""

QUEUE = 100
"""State messages a WebSocket client may fall behind (5 s at 20 Hz) before it is closed as too slow."""


class Client:
    """One WebSocket client's queue of state messages, and whether it fell too far behind."""

    def __init__(self) -> None:
        self.queue: asyncio.Queue[str] = asyncio.Queue(maxsize=QUEUE)
        self.overflow = asyncio.Event()


class Live:
    """The WebSocket broadcaster: one snapshot per tick, serialised once, queued for every client in order.

    A client that falls :data:`QUEUE` messages behind is closed with a reason (code 1013),
    never silently skipped: every client sees every message it gets in order, ``seq``
    counting up by one.
    """

    def __init__(self, room: ControlRoom, camera: bool):
        self.room = room
        self.camera = camera
        self.seq = 0
        self.run_id = secrets.token_hex(4)  # this server's run: a page that sees another knows it was restarted
        self.clients: set[Client] = set()
        self._last_event = max(0, room.last_event_id - 20)
        self.sent = 0

    def message(self) -> str:
        """The next state message (JSON): ``seq``, ``run`` (this server's run), ``t`` (UTC epoch s), ``state``,
        the new ``events``."""
        self.seq += 1
        snap = self.room.snapshot()
        snap["camera"] = self.camera
        events = self.room.events_after(self._last_event)
        if events:
            self._last_event = events[-1]["id"]
        return json.dumps(clean({"seq": self.seq, "run": self.run_id, "t": time.time(), "state": snap,
                                 "events": events}),
                          allow_nan=False, default=str)

    def publish(self, text: str) -> None:
        """Queue ``text`` for every client; one whose queue is full is marked to be closed."""
        for c in list(self.clients):
            if c.queue.full():
                self.clients.discard(c)
                c.overflow.set()
                continue
            c.queue.put_nowait(text)
        self.sent += 1

    async def run(self) -> None:
        """Publish :data:`RATE_HZ` messages a second until cancelled."""
        period = 1.0 / RATE_HZ
        next_t = time.monotonic()
        said = ""
        while True:
            next_t += period
            try:
                self.publish(self.message())
            except Exception as e:  # noqa: BLE001 - the stream goes on; the log says what broke, once
                if one_line(e) != said:
                    said = one_line(e)
                    log.error("live state: %s", said)
            await asyncio.sleep(max(0.0, next_t - time.monotonic()))
            if time.monotonic() - next_t > 1.0:  # a stall (a suspended laptop): do not burst to catch up
                next_t = time.monotonic()


def clean(o: Any) -> Any:
    """``o`` with every non-finite float as ``None`` (JSON has no NaN)."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean(v) for v in o]
    return o

async def _authenticated(ws: WebSocket, access: Access) -> bool:
    """Whether the first message (within 5 s) is ``{"type": "auth", "token": ...}`` with the token; else closed."""
    try:
        first = await asyncio.wait_for(ws.receive_text(), 5.0)
        msg = json.loads(first)
        ok = isinstance(msg, dict) and msg.get("type") == "auth" and isinstance(msg.get("token"), str) \
            and access.accepts(msg["token"])
    except (TimeoutError, ValueError, RecursionError, WebSocketDisconnect, RuntimeError):
        ok = False
    if not ok:
        with contextlib.suppress(Exception):
            await ws.close(4401, "this server needs its token: send {\"type\": \"auth\", \"token\": ...}")
    return ok


BINARY = "a message is a text frame holding JSON, not a binary frame: {\"type\": \"stop\" | \"jog\" | ...}"


async def _text(ws: WebSocket) -> str | None:
    """The next message's text; ``None`` for a binary frame (answered, not taken for a text or let close the
    socket: ``receive_text`` failed on one, and the socket closed without a word)."""
    message = await ws.receive()
    if message["type"] == "websocket.disconnect":
        raise WebSocketDisconnect(message.get("code", 1000), message.get("reason"))
    text = message.get("text")
    return text if isinstance(text, str) else None


def live_routes(live: Live, room: ControlRoom, access: Access) -> APIRouter:
    """The WebSocket ``/api/live``: the token first (a browser's), then the state out and commands in."""
    router = APIRouter()

    @router.websocket("/api/live")
    async def live_socket(ws: WebSocket) -> None:
        await ws.accept()
        if ws.scope.get("state", {}).get("needs_auth_message") and not await _authenticated(ws, access):
            return
        client = Client()
        live.clients.add(client)
        holding = False

        async def sender() -> None:
            while True:
                if client.overflow.is_set() and client.queue.empty():
                    await ws.close(1013, f"too slow: {QUEUE} state messages behind; reconnect")
                    return
                getter = asyncio.ensure_future(client.queue.get())
                flag = asyncio.ensure_future(client.overflow.wait())
                done, _ = await asyncio.wait([getter, flag], return_when=asyncio.FIRST_COMPLETED)
                flag.cancel()
                if getter in done:
                    await ws.send_text(getter.result())
                else:
                    getter.cancel()

        async def receiver() -> None:
            nonlocal holding
            while True:
                text = await _text(ws)
                await asyncio.sleep(0)  # let the loop go: a flood of frames already read never suspends otherwise
                if text is None:
                    await ws.send_text(json.dumps({"error": BINARY, "status": 422}))
                    continue
                if '"jog"' in text:
                    holding = True  # before it is carried out: a socket that closes now lets go
                # a stop is carried out here, on the loop (as POST /api/stop), never queued behind the threads'
                # work: eight GET /api/motions/ID?wait held every worker, and a stop waited for the move's end
                if is_stop(text):
                    reply = command(room, text)
                else:
                    reply = await asyncio.to_thread(command, room, text)
                if reply.get("jog") in ("released", "idle") or "stopped" in reply:
                    holding = False
                if "error" in reply or reply.get("reply"):
                    await ws.send_text(json.dumps(reply))

        tasks = [asyncio.create_task(sender()), asyncio.create_task(receiver())]
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            live.clients.discard(client)
            for t in tasks:
                t.cancel()
            if holding:  # the client went away with a key held: stop now (a session still starting is let go too)
                room.jog_release()
                room.event("warning", "a page went away with a jog key held: stopped")
            with contextlib.suppress(Exception):
                await ws.close()

    return router


def is_stop(text: str) -> bool:
    """Whether the message ``text`` is ``{"type": "stop", ...}``."""
    if '"stop"' not in text:
        return False
    try:
        msg = json.loads(text)
    except (ValueError, RecursionError):
        return False
    return isinstance(msg, dict) and msg.get("type") == "stop"


def command(room: ControlRoom, text: str) -> dict[str, Any]:
    """One message from a WebSocket client: ``stop``, ``jog`` (a held direction), ``release``, ``ping``."""
    try:
        msg = json.loads(text)
    except (ValueError, RecursionError):  # not JSON, or nested thousands deep (the receiver died of it)
        return {"error": "a message is a JSON object: {\"type\": \"stop\" | \"jog\" | \"release\" | \"ping\"}"}
    if not isinstance(msg, dict):
        return {"error": "a message is a JSON object"}
    kind = msg.get("type")
    try:
        if kind == "stop":  # "press": the id of the press, sent as POST /api/stop?press= too: said once
            press = msg.get("press")
            return {**room.stop(press if isinstance(press, str) else None), "reply": "stop"}
        if (twice := repeated_key(text)) is not None:  # json keeps the last: {"joint": 3, "joint": 1}; never a STOP
            return {"error": f"the message gives the key {twice!r:.60} twice (which one is meant?)"}
        if kind == "jog":
            body = JogBody.model_validate({k: v for k, v in msg.items() if k != "type"})
            return room.jog_hold(body.direction, body.speed)
        if kind == "release":
            return room.jog_release()
        if kind == "ping":
            return {"reply": "pong"}
        if kind == "auth":
            return {}
    except Refused as e:
        return {"error": one_line(e), "status": e.status}
    except ValueError as e:  # a pydantic ValidationError
        return {"error": one_line(e).split(" For further information")[0], "status": 422}
    return {"error": one_line(f"unknown message type {kind!r} (stop, jog, release, ping)")}

