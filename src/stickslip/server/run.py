"""Start the server: the access rules, the room, the camera, uvicorn (what ``stickslip serve`` calls)."""

from __future__ import annotations

import errno
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..devices.base import redact_url
from .app import create_app
from .camera import CameraFeed, FrameFeed
from .live import MAX_MESSAGE
from .room import ControlRoom, RoomOptions
from .security import Access, default_token_path, is_loopback, load_or_create_token

__all__ = ["ServeError", "access_for", "envelope_problem", "open_camera_feed", "port_problem", "serve", "server_config"]


class ServeError(RuntimeError):
    """The server cannot start (a port in use, a camera that cannot be opened, a token file); one line says why."""


def access_for(host: str, token_path: Path | None, echo: Callable[[str], None]) -> Access:
    """The rules for ``host``: no token on a loopback address; else the token (made and printed once)."""
    if is_loopback(host):
        return Access(None, True)
    path = token_path or default_token_path()
    try:
        token, new = load_or_create_token(path)
    except (OSError, ValueError) as e:
        raise ServeError(f"the token file {path}: {e}") from None
    if new:
        echo(f"new token (shown this once): {token}")
        echo(f"kept in {path}, readable by you only;")
        # (written without 'token=': the console shows any 'token=...' as a secret, '#token=***')
        echo("the page asks for it (or add it to the page's address after '#token' and an equals sign);")
        echo("scripts send 'Authorization: Bearer TOKEN'")
    else:
        echo(f"this address needs the token kept in {path}")
    return Access(token, False)


def port_problem(host: str, port: int) -> str | None:
    """Why ``host:port`` cannot be served (in use, no such address), or ``None``."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except OSError as e:
        return f"cannot serve on {host}: {e.strerror or e}"
    family, kind, proto, _, addr = infos[0]
    with socket.socket(family, kind, proto) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(addr)
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                return f"port {port} on {host} is in use (another server?): choose another with --port"
            return f"cannot serve on {host}:{port}: {e.strerror or e}"
    return None


def open_camera_feed(url: str, device: Any, tip: tuple[float, float] | None = None) -> CameraFeed:
    """The camera panel's feed of the camera ``url`` names (:func:`stickslip.vision.open_camera`).

    With ``tip`` (px, where the tip is in the first frame) the tip is tracked
    (:class:`stickslip.vision.track.TipTracker`) and marked on the page; without it the
    frames are shown alone. ``ServeError`` for a camera that cannot be opened or a tip
    that cannot be tracked.
    """
    from ..vision import CameraError, open_camera
    from ..vision.template import TemplateError
    from ..vision.track import Fix, TipTracker

    try:
        cam = open_camera(url, device)
    except (CameraError, ValueError) as e:
        raise ServeError(f"--camera {redact_url(url)}: {e}") from None
    if tip is None:
        return FrameFeed(cam)
    try:
        tracker = TipTracker(cam.grab(), tip)
    except (CameraError, TemplateError, ValueError) as e:
        cam.close()
        raise ServeError(f"--camera-tip {tip[0]:g},{tip[1]:g}: {e}") from None

    def tip_of(frame: Any) -> tuple[float, float, float | None] | None:
        found = tracker.update(frame)
        return (found.x, found.y, found.sigma) if isinstance(found, Fix) else None

    return FrameFeed(cam, tip_of=tip_of)


def server_config(app: Any, host: str, port: int) -> Any:
    """uvicorn's settings for ``app``: no access log, and a WebSocket message at most :data:`~.live.MAX_MESSAGE`
    bytes (uvicorn's default, 16 MiB, let ten clients each send one and hold 420 MB of the server's memory)."""
    import uvicorn

    return uvicorn.Config(app, host=host, port=port, log_level="warning", access_log=False, lifespan="on",
                          ws_max_size=MAX_MESSAGE)


def envelope_problem(room: ControlRoom) -> str | None:
    """Why the served arm, where its position is kept, breaks the rig's envelope (as ``rig check`` says), for a
    line at start; ``None``: it does not, or no rig. Every motion says it again when refused."""
    from ..procedures.arms import guard_for
    from ..rig import EnvelopeViolation

    rig = room.options.rig
    if rig is None:
        return None
    st = room.state()
    try:
        guard_for(room.store, rig, room.options.arm).check([[st.positions[j] for j in (1, 2, 3)]])
    except EnvelopeViolation as e:
        return (f"where its position is kept, {e}: a planned move must take it out (docs/rig.md, "
                "\"Starting inside a margin\"), or none is planned from there")
    return None


def serve(
    options: RoomOptions,
    host: str = "127.0.0.1",
    port: int = 8765,
    *,
    camera_url: str | None = None,
    camera_tip: tuple[float, float] | None = None,
    token_path: Path | None = None,
    echo: Callable[[str], None] = print,
) -> None:
    """Serve ``options``' device on ``host:port`` until Ctrl-C (or SIGTERM); then stop the arm and close everything."""
    import uvicorn

    problem = port_problem(host, port)
    if problem:
        raise ServeError(problem)
    access = access_for(host, token_path, echo)
    room = ControlRoom(options)
    camera: CameraFeed | None = None
    try:
        if camera_url is not None:
            camera = open_camera_feed(camera_url, room.owned, camera_tip)
        app = create_app(room, access, camera)
        shown = f"[{host}]" if ":" in host else host
        echo(f"serving {redact_url(options.device)} ({room.info.model})")
        if options.rig is not None:
            echo(f"arm {options.rig.arm(options.arm).name!r} of the rig {options.rig.name!r}: every move is "
                 "checked against its envelope")
            stuck = envelope_problem(room)
            if stuck:
                echo(f"warning: {stuck}")
        if host in ("0.0.0.0", "::"):  # every address of this computer: not one a browser can open
            echo(f"open http://<this computer's name or address>:{port}/ in a browser; Ctrl-C stops")
        else:
            echo(f"open http://{shown}:{port}/ in a browser; Ctrl-C stops")
        if room.calibration is None:
            echo("no calibration yet: run the calibration day on the page")
        uvicorn.Server(server_config(app, host, port)).run()
    finally:
        if camera is not None:
            camera.close()
        room.close()
