"""The web layer: HTTP for commands, a WebSocket for the live state, the page, the OpenAPI schema.

Every endpoint parses its input (units as on the command line: a JSON number is SI, a
string carries its unit, ``"30um"``, ``"2deg"``), calls one verb of the
:class:`~.room.ControlRoom` (which calls one library procedure) and reports. Errors are
one line, ``{"error": "..."}``: 422 for a value that cannot be used, 409 when the
manipulator's state refuses it (another motion runs, a joint is uncertain, no
calibration), 404 for an unknown motion or position, 401/403 for the token, the host or
the origin (:mod:`.security`), 503 when the device does not answer. No response and no
log line carries the token or a device password.

A motion (move, reach, step, traverse, go to, the calibration day) answers ``202`` with
its id once its procedure has checked the input and the first burst is about to go out;
``GET /api/motions/{id}?wait=S`` waits for it to end. ``POST /api/stop`` (and a
``{"type": "stop"}`` message on the WebSocket) stops everything.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import AsyncIterator, MutableMapping
from importlib import resources
from typing import Annotated, Any, Literal

from fastapi import FastAPI, Path, Query, Request, WebSocket, WebSocketDisconnect
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.types import ASGIApp, Receive, Scope, Send

from .. import __version__
from ..devices.base import redact_url
from ..joints import JOINTS, joint_spec
from ..procedures.move import PoseUpdate
from ..procedures.named import NAME_PATTERN
from ..units import UnitError, bare_number_problem, parse_angle, parse_length
from .camera import CameraFeed
from .room import ControlRoom, Motion, NotFound, Refused, one_line
from .security import Access, origin_problem

__all__ = ["RATE_HZ", "create_app"]

log = logging.getLogger("stickslip.server")

RATE_HZ = 20.0
"""Live-state messages per second on the WebSocket."""

QUEUE = 100
"""State messages a WebSocket client may fall behind (5 s at 20 Hz) before it is closed as too slow."""

MAX_BODY = 64 * 1024
"""Largest request body, bytes."""

Amount = Annotated[
    float | str,
    Field(description="SI (m or rad) as a JSON number, or a string with its unit: '30um', '2deg', '-pi/2'"),
]


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid")


class MoveBody(_Body):
    """A planned move of one joint: ``by`` or ``to`` (exactly one)."""

    joint: int = Field(ge=1, le=3, strict=True, description="1, 2 (rotary) or 3 (prismatic)")
    by: Amount | None = None
    to: Amount | None = Field(None, description="a position, or 'min'/'max' for an end stop")


class StepBody(_Body):
    """Raw steps, no calibration (the joint is then uncertain until referenced)."""

    joint: int = Field(ge=1, le=3, strict=True)
    steps: int = Field(ge=-10_000_000, le=10_000_000, strict=True, description="signed steps, not 0")


class ReachBody(_Body):
    """A straight tip move, base frame before the tilt: ``to`` or ``by`` (exactly one), three lengths each."""

    to: list[Amount] | None = Field(None, min_length=3, max_length=3)
    by: list[Amount] | None = Field(None, min_length=3, max_length=3)


class JogBody(_Body):
    """A jog direction held (send it again at least every 50 ms while held: the dead man's switch)."""

    direction: Literal["+x", "-x", "+y", "-y", "+z", "-z"]
    speed: int | None = Field(None, ge=1, le=7, strict=True, description="preset 1-7: 0.1, 0.3, 1, 3, 10, 30, 100 µm/s")


class WhereBody(_Body):
    """Record references (a joint put at a known point) or a pose; ``set`` maps a joint to a position or min/max."""

    set: dict[Literal["1", "2", "3"], Amount] | None = None
    q1: Amount | None = None
    q2: Amount | None = None
    q3: Amount | None = None
    theta: Amount | None = None
    psi: Amount | None = None


class ObserveBody(_Body):
    """A measured position of one joint (a microscope reading, an end stop reached)."""

    joint: int = Field(ge=1, le=3, strict=True)
    q: Amount
    sd: Amount | None = None
    at_stop: bool = False
    force: bool = False


class TraverseBody(_Body):
    """One traverse of a joint from stop to stop, timed by the limit switch."""

    joint: int = Field(ge=1, le=3, strict=True)
    direction: Literal["+", "-"]


class PositionBody(_Body):
    """Save the current positions under a name."""

    name: str = Field(pattern=NAME_PATTERN)


class DayBody(_Body):
    """Start the calibration day (or resume a stopped one)."""

    day: str | None = Field(None, pattern=r"^[0-9A-Za-z][0-9A-Za-z_.:+-]{0,39}$", description="session label")
    resume: bool = False


# ------------------------------------------------------------------------------ parsing with units


def _value(text: Amount, kind: str, what: str, span: float | None = None) -> float:
    """An amount: a JSON number is SI; a string needs its unit (a bare number other than 0 is refused)."""
    if isinstance(text, (int, float)):
        v = float(text)
    else:
        bare = bare_number_problem(text, kind, span)
        if bare is not None:
            raise Refused(f"{what}: {bare}")
        try:
            v = parse_angle(text) if kind == "angle" else parse_length(text)
        except (UnitError, ValueError, ArithmeticError) as e:
            raise Refused(f"{what}: {one_line(e)}") from None
    if not math.isfinite(v):
        raise Refused(f"{what}: {text!r} is not a finite value")
    return v


def _joint_value(joint: int, text: Amount, what: str, stops: bool = False) -> float:
    """A position or displacement of ``joint``: a length (joint 3) or an angle (1, 2); ``min``/``max`` if ``stops``."""
    spec = joint_spec(joint)
    if stops and isinstance(text, str) and text.strip().lower() in ("min", "lower", "max", "upper"):
        return spec.lower if text.strip().lower() in ("min", "lower") else spec.upper
    return _value(text, "angle" if spec.rotary else "length", what, spec.span)


def _pose(body: WhereBody) -> PoseUpdate:
    def q(j: int, v: Amount | None) -> float | None:
        return None if v is None else _joint_value(j, v, f"q{j}")

    def a(name: str, v: Amount | None) -> float | None:
        return None if v is None else _value(v, "angle", name)

    return PoseUpdate(q(1, body.q1), q(2, body.q2), q(3, body.q3), a("theta", body.theta), a("psi", body.psi))


def _vector(values: list[Amount], what: str) -> tuple[float, float, float]:
    out = [_value(v, "length", f"{what}[{i}]") for i, v in enumerate(values)]
    return (out[0], out[1], out[2])


def _accepted(m: Motion) -> JSONResponse:
    status = 202 if m.active else 200
    return JSONResponse(m.as_dict(full=not m.active), status_code=status)


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status)


def _validation_line(exc: RequestValidationError) -> str:
    """The first validation error as one line: where (``body.joint``) and why."""
    errors = exc.errors()
    if not errors:
        return "invalid request"
    e = errors[0]
    if e.get("type") == "json_invalid":
        ctx = e.get("ctx") or {}
        return f"the body is not JSON ({ctx.get('error', 'invalid')})"
    where = ".".join(str(p) for p in e.get("loc", ()) if p not in ("body",)) or "body"
    msg = str(e.get("msg", "invalid"))
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return redact_url(" ".join(f"{where}: {msg}{more}".split()))


# ------------------------------------------------------------------------------ the guard (ASGI middleware)


class Guard:
    """Every HTTP request and WebSocket passes here: host, origin, token, body size (see :mod:`.security`).

    The page and its files (``/``, ``/static/...``) need no token (they hold nothing);
    everything under ``/api`` and the schema do. A WebSocket from a browser may instead
    send the token as its first message (the endpoint checks that).
    """

    def __init__(self, app: ASGIApp, access: Access):
        self.app = app
        self.access = access

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        path = str(scope.get("path", ""))
        problem = self.access.host_problem(headers.get("host"))
        status = 403
        if problem is None:
            problem = origin_problem(headers.get("origin"), headers.get("host"))
        if problem is None and headers.get("sec-fetch-site") == "cross-site":
            problem = "cross-origin requests are refused: open the page from this server itself"
        if problem is None and (path.startswith("/api") or path == "/openapi.json"):
            if scope["type"] == "websocket" and not headers.get("authorization"):
                scope.setdefault("state", {})["needs_auth_message"] = self.access.token is not None
            else:
                problem = self.access.token_problem(headers.get("authorization"))
                status = 401
        if problem is None and scope["type"] == "http":
            length = headers.get("content-length")
            if length is not None and (not length.isdigit() or int(length) > MAX_BODY):
                problem, status = f"the request body is larger than {MAX_BODY // 1024} kB", 413
        if problem is None:
            await self.app(scope, receive if scope["type"] != "http" else _limited(receive), send)
            return
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 4401 if status == 401 else 4403, "reason": problem})
            return
        body = json.dumps({"error": problem}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})


def _limited(receive: Receive) -> Receive:
    """``receive`` that stops a body (sent without a length) at :data:`MAX_BODY` bytes."""
    seen = 0

    async def inner() -> MutableMapping[str, Any]:
        nonlocal seen
        message = await receive()
        if message["type"] == "http.request":
            seen += len(message.get("body", b""))
            if seen > MAX_BODY:
                raise _TooLarge()
        return message

    return inner


class _TooLarge(Exception):
    pass


# ------------------------------------------------------------------------------ the live state


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
        self.clients: set[Client] = set()
        self._last_event = max(0, room.last_event_id - 20)
        self.sent = 0

    def message(self) -> str:
        """The next state message (JSON): ``seq``, ``t`` (UTC epoch s), ``state``, the new ``events``."""
        self.seq += 1
        snap = self.room.snapshot()
        snap["camera"] = self.camera
        events = self.room.events_after(self._last_event)
        if events:
            self._last_event = events[-1]["id"]
        return json.dumps(_clean({"seq": self.seq, "t": time.time(), "state": snap, "events": events}),
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


def _clean(o: Any) -> Any:
    """``o`` with every non-finite float as ``None`` (JSON has no NaN)."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    return o


# ------------------------------------------------------------------------------ the app


def create_app(room: ControlRoom, access: Access, camera: CameraFeed | None = None) -> FastAPI:
    """The ASGI app of ``room``: the API, the WebSocket, the page; guarded by ``access``.

    The room belongs to the caller, who closes it after the app stops.
    """
    live = Live(room, camera is not None)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        task = asyncio.create_task(live.run())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task

    app = FastAPI(
        title="stickslip serve",
        version=__version__,
        description=(
            "Drive a stick-slip micromanipulator: the same procedures as the stickslip command line. "
            "Amounts: a JSON number is SI (m, rad); a string carries its unit ('30um', '2deg'). "
            "Errors: {\"error\": one line}."
        ),
        docs_url=None,
        redoc_url=None,
        lifespan=lifespan,
    )
    app.state.room = room
    app.state.live = live
    app.add_middleware(Guard, access=access)

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return _error(422, _validation_line(exc))

    @app.exception_handler(Refused)
    async def refused(request: Request, exc: Refused) -> JSONResponse:
        return _error(exc.status, one_line(exc))

    @app.exception_handler(_TooLarge)
    async def too_large(request: Request, exc: _TooLarge) -> JSONResponse:
        return _error(413, f"the request body is larger than {MAX_BODY // 1024} kB")

    @app.exception_handler(json.JSONDecodeError)
    async def bad_json(request: Request, exc: json.JSONDecodeError) -> JSONResponse:
        return _error(422, f"the body is not JSON: {exc.msg} at character {exc.pos}")

    @app.exception_handler(Exception)
    async def internal(request: Request, exc: Exception) -> JSONResponse:
        log.error("internal error on %s: %s", request.url.path, one_line(exc), exc_info=exc)
        return _error(500, f"internal error: {one_line(exc)}")

    # -- the page ------------------------------------------------------------------------

    static = resources.files("stickslip.server") / "static"

    @app.get("/", include_in_schema=False)
    def page() -> HTMLResponse:
        return HTMLResponse(static.joinpath("index.html").read_text(encoding="utf-8"),
                            headers={"Cache-Control": "no-store", "X-Frame-Options": "DENY",
                                     "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; "
                                     "connect-src 'self' ws: wss:; frame-ancestors 'none'"})

    types = {".js": "text/javascript", ".css": "text/css", ".txt": "text/plain", ".svg": "image/svg+xml"}

    @app.get("/static/{name}", include_in_schema=False)
    def static_file(name: Annotated[str, Path(pattern=r"^[a-z0-9_-]+\.(js|css|txt|svg)$")]) -> Response:
        f = static.joinpath(name)
        if not f.is_file():
            raise NotFound(f"no file {name}")
        return Response(f.read_bytes(), media_type=types["." + name.rsplit(".", 1)[1]],
                        headers={"Cache-Control": "no-cache"})

    # -- state ---------------------------------------------------------------------------

    @app.get("/api/state", tags=["state"])
    def state() -> JSONResponse:
        """The live state once: joints ± sd, tip ± sd, the motion, jog, the calibration day, the audio level."""
        snap = room.snapshot()
        snap["camera"] = camera is not None
        return JSONResponse(_clean(snap))

    @app.get("/api/where", tags=["state"])
    def where_get() -> JSONResponse:
        """The kept positions (``stickslip where --json``)."""
        return JSONResponse(_clean(room.where()))

    @app.post("/api/where", tags=["state"])
    def where_post(body: WhereBody) -> JSONResponse:
        """Record references (``{"set": {"3": "min"}}``: joint 3 is at its lower stop) or a pose."""
        refs = [(int(j), _joint_value(int(j), v, f"set {j}", stops=True)) for j, v in sorted((body.set or {}).items())]
        for j, q in refs:
            problem = JOINTS[j].range_problem(f"q{j}", q)
            if problem:
                raise Refused(problem)
        return JSONResponse(_clean(room.where(refs, _pose(body))))

    @app.get("/api/events", tags=["state"])
    def events(after: Annotated[int, Query(ge=0, le=2**62)] = 0) -> JSONResponse:
        """Events (motions started and ended, refusals, STOP, warnings) with an id above ``after``."""
        return JSONResponse({"events": room.events_after(after)})

    # -- motions -------------------------------------------------------------------------

    @app.post("/api/move", status_code=202, tags=["motion"])
    def move(body: MoveBody) -> JSONResponse:
        """Move one joint by or to an amount (``stickslip move``): 202 with the motion once it drives."""
        if (body.by is None) == (body.to is None):
            raise Refused("give exactly one of by and to")
        by = None if body.by is None else _joint_value(body.joint, body.by, "by")
        to = None if body.to is None else _joint_value(body.joint, body.to, "to", stops=True)
        return _accepted(room.move(body.joint, by, to))

    @app.post("/api/step", status_code=202, tags=["motion"])
    def step(body: StepBody) -> JSONResponse:
        """Raw steps without a calibration (``stickslip move --steps``): the joint is uncertain until referenced."""
        return _accepted(room.step(body.joint, body.steps))

    @app.post("/api/reach", status_code=202, tags=["motion"])
    def reach(body: ReachBody) -> JSONResponse:
        """Move the tip in a straight line (``stickslip reach``)."""
        if (body.to is None) == (body.by is None):
            raise Refused("give exactly one of to and by")
        to = None if body.to is None else _vector(body.to, "to")
        by = None if body.by is None else _vector(body.by, "by")
        return _accepted(room.reach(to, by))

    @app.post("/api/jog", tags=["motion"])
    def jog_hold(body: JogBody) -> JSONResponse:
        """Hold a jog direction; repeat at least every 50 ms while held. The tip stops within 0.3 s of the last."""
        return JSONResponse(room.jog_hold(body.direction, body.speed))

    @app.post("/api/jog/release", tags=["motion"])
    def jog_release(end: bool = False) -> JSONResponse:
        """Let go of the jog direction: the tip stops at once; ``end`` ends the session too (else 2 s later)."""
        return JSONResponse(room.jog_release(end))

    @app.post("/api/stop", tags=["motion"])
    async def stop() -> JSONResponse:
        """STOP: every axis, now. Nothing further is sent; a jog or the calibration day ends."""
        return JSONResponse(room.stop())

    @app.post("/api/observe", tags=["motion"])
    def observe(body: ObserveBody) -> JSONResponse:
        """A measured position into the joint's track (``stickslip observe``)."""
        q = _joint_value(body.joint, body.q, "q", stops=True)
        sd = None if body.sd is None else _joint_value(body.joint, body.sd, "sd")
        if sd is not None and not sd > 0:
            raise Refused("sd must be > 0")
        return JSONResponse(_clean(room.observe(body.joint, q, sd, body.at_stop, body.force)))

    @app.post("/api/traverse", status_code=202, tags=["motion"])
    def traverse(body: TraverseBody) -> JSONResponse:
        """One traverse from stop to stop, timed by the limit switch (``stickslip traverse``), stored."""
        return _accepted(room.traverse(body.joint, body.direction))

    @app.get("/api/motions/{ident}", tags=["motion"])
    async def motion(
        ident: Annotated[int, Path(ge=1, le=2**62)], wait: Annotated[float, Query(ge=0, le=30)] = 0.0
    ) -> JSONResponse:
        """A motion's state and result; ``wait`` (s) waits for it to end first."""
        m = room.motion(ident)
        if wait > 0 and m.active:
            await asyncio.to_thread(m.finished.wait, wait)
        return JSONResponse(_clean(m.as_dict()))

    @app.get("/api/motion", tags=["motion"])
    def current_motion() -> JSONResponse:
        """The motion running now (``{"motion": null}`` if none)."""
        m = room.current()
        return JSONResponse({"motion": _clean(m.as_dict()) if m is not None else None})

    # -- named positions -----------------------------------------------------------------

    @app.get("/api/positions", tags=["positions"])
    def positions() -> JSONResponse:
        """The named positions."""
        return JSONResponse({"positions": _clean(room.positions())})

    @app.post("/api/positions", tags=["positions"])
    def save_position(body: PositionBody) -> JSONResponse:
        """Save the current positions under a name."""
        return JSONResponse(_clean(room.save_position(body.name)))

    @app.delete("/api/positions/{name}", tags=["positions"])
    def delete_position(name: Annotated[str, Path(pattern=NAME_PATTERN)]) -> JSONResponse:
        """Forget a named position."""
        return JSONResponse(room.delete_position(name))

    @app.post("/api/positions/{name}/go", status_code=202, tags=["positions"])
    def go(name: Annotated[str, Path(pattern=NAME_PATTERN)]) -> JSONResponse:
        """Drive back to a named position, joint by joint."""
        return _accepted(room.go_to(name))

    # -- the calibration day -------------------------------------------------------------

    @app.post("/api/day", status_code=202, tags=["calibration"])
    def day_start(body: DayBody) -> JSONResponse:
        """Start (or resume) the guided calibration day: the paper's 14 traverses, then the calibration."""
        return _accepted(room.day_start(body.day, body.resume))

    @app.get("/api/day", tags=["calibration"])
    def day() -> JSONResponse:
        """The day's plan, progress (the traverse, steps, the end-stop meter) and result."""
        return JSONResponse(_clean(room.day()))

    @app.post("/api/day/pose-set", tags=["calibration"])
    def day_pose() -> JSONResponse:
        """The operator has set the pose the day waits for (a real arm)."""
        return JSONResponse(room.day_pose_set())

    @app.get("/api/calibration", tags=["calibration"])
    def calibration() -> JSONResponse:
        """The calibration in use: its parameters with standard errors, and its report."""
        return JSONResponse(_clean(room.calibration_detail()))

    @app.get("/api/history", tags=["calibration"])
    def history() -> JSONResponse:
        """The device's sessions (traverses per day) and calibrations, oldest first."""
        return JSONResponse(_clean(room.history()))

    @app.get("/api/anova", tags=["calibration"])
    def anova() -> JSONResponse:
        """The ANOVA of the stored traverses (``stickslip anova``): day to day, and + against -."""
        return JSONResponse(_clean(room.anova()))

    # -- the camera ----------------------------------------------------------------------

    @app.get("/api/camera", tags=["camera"])
    def camera_info() -> JSONResponse:
        """The tip's pixel position in the last frame, and the planned path in pixels (when calibrated)."""
        if camera is None:
            raise NotFound("no camera (start the server with --camera URL)")
        cur = room.current()
        path = cur.path if cur is not None else None
        px = camera.to_pixels(path) if path else None
        tip = camera.tip()
        return JSONResponse(_clean({
            "tip": None if tip is None else {"x": tip[0], "y": tip[1], "sd": tip[2]},
            "path_px": None if px is None else [list(p) for p in px],
        }))

    @app.get("/api/camera/frame", tags=["camera"])
    def camera_frame() -> Response:
        """The newest frame (PNG)."""
        if camera is None:
            raise NotFound("no camera (start the server with --camera URL)")
        data, media, size = camera.frame()
        return Response(data, media_type=media, headers={
            "Cache-Control": "no-store", "X-Frame-Width": str(size[0]), "X-Frame-Height": str(size[1])})

    # -- the live WebSocket --------------------------------------------------------------

    @app.websocket("/api/live")
    async def live_socket(ws: WebSocket) -> None:
        await ws.accept()
        if ws.scope.get("state", {}).get("needs_auth_message"):
            try:
                first = await asyncio.wait_for(ws.receive_text(), 5.0)
                msg = json.loads(first)
                ok = isinstance(msg, dict) and msg.get("type") == "auth" and isinstance(msg.get("token"), str) \
                    and access.accepts(msg["token"])
            except (TimeoutError, ValueError, WebSocketDisconnect, RuntimeError):
                ok = False
            if not ok:
                with contextlib.suppress(Exception):
                    await ws.close(4401, "this server needs its token: send {\"type\": \"auth\", \"token\": ...}")
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
                text = await ws.receive_text()
                if '"jog"' in text:
                    holding = True  # before it is carried out: a socket that closes now lets go
                reply = await asyncio.to_thread(_command, room, text)
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

    return app


def _command(room: ControlRoom, text: str) -> dict[str, Any]:
    """One message from a WebSocket client: ``stop``, ``jog`` (a held direction), ``release``, ``ping``."""
    try:
        msg = json.loads(text)
    except ValueError:
        return {"error": "a message is a JSON object: {\"type\": \"stop\" | \"jog\" | \"release\" | \"ping\"}"}
    if not isinstance(msg, dict):
        return {"error": "a message is a JSON object"}
    kind = msg.get("type")
    try:
        if kind == "stop":
            return {**room.stop(), "reply": "stop"}
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
    return {"error": f"unknown message type {kind!r} (stop, jog, release, ping)"}

