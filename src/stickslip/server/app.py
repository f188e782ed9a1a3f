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
from collections.abc import AsyncIterator, MutableMapping
from typing import Any

from fastapi import Depends, FastAPI, Request
from fastapi.dependencies.models import Dependant
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Receive, Scope, Send

from .. import __version__
from ..devices.base import redact_text
from ..records import repeated_key
from .camera import CameraFeed
from .live import RATE_HZ, Live, live_routes
from .room import ControlRoom, Refused, one_line
from .routes import routers
from .security import Access, origin_problem

__all__ = ["RATE_HZ", "create_app"]

log = logging.getLogger("stickslip.server")

MAX_BODY = 64 * 1024
"""Largest request body, bytes."""

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
    return redact_text(" ".join(f"{where}: {msg}{more}".split()))


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
            limited = _limited(receive, keys=scope.get("path") != "/api/stop")  # a STOP is never refused for its body
            await self.app(scope, receive if scope["type"] != "http" else limited, send)
            return
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 4401 if status == 401 else 4403, "reason": problem})
            return
        body = json.dumps({"error": problem}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})


def _limited(receive: Receive, keys: bool = True) -> Receive:
    """``receive`` that stops a body (sent without a length) at :data:`MAX_BODY` bytes, and (``keys``) one that
    gives a key twice in one object (:func:`~stickslip.records.repeated_key`)."""
    seen = 0
    chunks: list[bytes] = []

    async def inner() -> MutableMapping[str, Any]:
        nonlocal seen
        message = await receive()
        if message["type"] == "http.request":
            body = message.get("body", b"")
            seen += len(body)
            if seen > MAX_BODY:
                raise _TooLarge()
            chunks.append(body)
            if keys and not message.get("more_body", False) and (key := repeated_key(b"".join(chunks))) is not None:
                raise _KeyTwice(key)
        return message

    return inner


class _TooLarge(Exception):
    pass


class _KeyTwice(Exception):
    """A body giving one key twice (``{"joint": 3, "joint": 1}``): JSON readers keep the last silently."""

    def line(self) -> str:
        return f"the body gives the key {self.args[0]!r:.60} twice in one object (which one is meant?)"


# ------------------------------------------------------------------------------ the app


def _query_names(dependant: Dependant) -> set[str]:
    """The query parameters a route takes (its own and its dependencies')."""
    names = {str(p.alias) for p in dependant.query_params}
    for d in dependant.dependencies:
        names |= _query_names(d)
    return names


def _known_query(request: Request) -> None:
    """Refuse (422) an API request with a query parameter its route does not take, as a body's unknown key is.

    ``POST /api/move?arm=gripper`` sent to the probe's server moved the probe: a server serves one arm, and a
    request naming another (or anything else it would ignore) must not be carried out as if it named none.
    """
    route = request.scope.get("route")
    if not request.query_params or not isinstance(route, APIRoute) or not route.path.startswith("/api/"):
        return
    known = _query_names(route.dependant)
    unknown = sorted(set(request.query_params) - known)
    if not unknown:
        return
    line = f"{unknown[0]}: this request takes no query parameter {unknown[0]!r}"
    line += f" (it takes {', '.join(sorted(known))})" if known else ""
    if unknown[0].casefold() == "arm":
        options = request.app.state.room.options
        served = f"one arm, {options.arm or options.rig.arms[0].name!r}" if options.rig is not None else "one arm"
        line += f"; this server serves {served}: another arm has a server of its own"
    raise Refused(line)


async def _http_error(request: Request, exc: Exception) -> JSONResponse:
    """An unknown path or method in the documented shape; FastAPI's 400 for a body it could not parse (JSON
    nested thousands deep) as a value that cannot be used, and for a body the guard cut (:class:`_TooLarge`,
    which FastAPI wraps) as 413."""
    if not isinstance(exc, StarletteHTTPException):  # registered for it alone
        raise exc
    if exc.status_code == 400 and isinstance(exc.__cause__, _TooLarge):  # sent without a length, cut by the guard
        return _error(413, f"the request body is larger than {MAX_BODY // 1024} kB")
    if exc.status_code == 400 and isinstance(exc.__cause__, _KeyTwice):
        return _error(422, exc.__cause__.line())
    if exc.status_code == 400:
        why = "nested too deeply" if isinstance(exc.__cause__, RecursionError) else one_line(str(exc.detail))
        return _error(422, f"the body cannot be read as JSON ({why})")
    return _error(exc.status_code, one_line(str(exc.detail)))


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

    app.add_exception_handler(StarletteHTTPException, _http_error)
    @app.exception_handler(Refused)
    async def refused(request: Request, exc: Refused) -> JSONResponse:
        return _error(exc.status, one_line(exc))

    @app.exception_handler(_TooLarge)
    async def too_large(request: Request, exc: _TooLarge) -> JSONResponse:
        return _error(413, f"the request body is larger than {MAX_BODY // 1024} kB")

    @app.exception_handler(_KeyTwice)
    async def key_twice(request: Request, exc: _KeyTwice) -> JSONResponse:
        return _error(422, exc.line())

    @app.exception_handler(json.JSONDecodeError)
    async def bad_json(request: Request, exc: json.JSONDecodeError) -> JSONResponse:
        return _error(422, f"the body is not JSON: {exc.msg} at character {exc.pos}")

    @app.exception_handler(Exception)
    async def internal(request: Request, exc: Exception) -> JSONResponse:
        log.error("internal error on %s: %s", request.url.path, one_line(exc), exc_info=exc)
        return _error(500, f"internal error: {one_line(exc)}")

    for router in routers(room, camera):
        app.include_router(router, dependencies=[Depends(_known_query)])
    app.include_router(live_routes(live, room, access))
    return app
