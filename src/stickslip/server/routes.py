"""The API's routes, grouped by area: the page, the state, the motions, the named positions, the
calibration day, the camera. Each endpoint parses its input and calls one verb of the room."""

from __future__ import annotations

import asyncio
import time
from importlib import resources
from typing import Annotated

from fastapi import APIRouter, Path, Query
from fastapi.responses import HTMLResponse, JSONResponse, Response

from ..joints import JOINTS
from ..procedures.named import NAME_PATTERN
from .camera import CameraFeed
from .live import clean
from .requests import (
    DayBody,
    JogBody,
    MoveBody,
    ObserveBody,
    PositionBody,
    ReachBody,
    StepBody,
    TraverseBody,
    WhereBody,
    accepted,
    joint_value,
    pose,
    vector,
)
from .room import ControlRoom
from .slot import NotFound, Refused, Unavailable, one_line

__all__ = ["WAIT_POLL_S", "routers"]

WAIT_POLL_S = 0.02
"""How often ``GET /api/motions/{id}?wait=S`` looks whether the motion ended, s (the answer is at most this late)."""


def routers(room: ControlRoom, camera: CameraFeed | None) -> list[APIRouter]:
    """The routers of the API, in the order their paths are listed in the schema."""
    return [page_routes(), state_routes(room, camera), drive_routes(room), motion_routes(room),
            position_routes(room), calibration_routes(room), camera_routes(room, camera)]


def page_routes() -> APIRouter:
    """The page and its files (no token: they hold nothing)."""
    router = APIRouter()
    static = resources.files("stickslip.server") / "static"

    @router.get("/", include_in_schema=False)
    def page() -> HTMLResponse:
        return HTMLResponse(static.joinpath("index.html").read_text(encoding="utf-8"),
                            headers={"Cache-Control": "no-store", "X-Frame-Options": "DENY",
                                     "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; "
                                     "connect-src 'self' ws: wss:; frame-ancestors 'none'"})

    types = {".js": "text/javascript", ".css": "text/css", ".txt": "text/plain", ".svg": "image/svg+xml"}

    @router.get("/static/{name}", include_in_schema=False)
    def static_file(name: Annotated[str, Path(pattern=r"^[a-z0-9_-]+\.(js|css|txt|svg)$")]) -> Response:
        f = static.joinpath(name)
        if not f.is_file():
            raise NotFound(f"no file {name}")
        return Response(f.read_bytes(), media_type=types["." + name.rsplit(".", 1)[1]],
                        headers={"Cache-Control": "no-cache"})

    return router


def state_routes(room: ControlRoom, camera: CameraFeed | None) -> APIRouter:
    """The state: live once, the kept positions (read and recorded), the events."""
    router = APIRouter()

    @router.get("/api/state", tags=["state"])
    def state() -> JSONResponse:
        """The live state once: joints ± sd, tip ± sd, the motion, jog, the calibration day, the audio level."""
        snap = room.snapshot()
        snap["camera"] = camera is not None
        return JSONResponse(clean(snap))

    @router.get("/api/where", tags=["state"])
    def where_get() -> JSONResponse:
        """The kept positions (``stickslip where --json``)."""
        return JSONResponse(clean(room.where()))

    @router.post("/api/where", tags=["state"])
    def where_post(body: WhereBody) -> JSONResponse:
        """Record references (``{"set": {"3": "min"}}``: joint 3 is at its lower stop) or a pose."""
        refs = [(int(j), joint_value(int(j), v, f"set {j}", stops=True)) for j, v in sorted((body.set or {}).items())]
        for j, q in refs:
            problem = JOINTS[j].range_problem(f"q{j}", q)
            if problem:
                raise Refused(problem)
        return JSONResponse(clean(room.where(refs, pose(body))))

    @router.get("/api/events", tags=["state"])
    def events(after: Annotated[int, Query(ge=0, le=2**62)] = 0) -> JSONResponse:
        """Events (motions started and ended, refusals, STOP, warnings) with an id above ``after``."""
        return JSONResponse({"events": room.events_after(after)})

    return router


def drive_routes(room: ControlRoom) -> APIRouter:
    """What drives: a move, raw steps, a tip move, a jog held and let go, STOP."""
    router = APIRouter()

    @router.post("/api/move", status_code=202, tags=["motion"])
    def move(body: MoveBody) -> JSONResponse:
        """Move one joint by or to an amount (``stickslip move``): 202 with the motion once it drives."""
        if (body.by is None) == (body.to is None):
            raise Refused("give exactly one of by and to")
        by = None if body.by is None else joint_value(body.joint, body.by, "by")
        to = None if body.to is None else joint_value(body.joint, body.to, "to", stops=True)
        return accepted(room.move(body.joint, by, to))

    @router.post("/api/step", status_code=202, tags=["motion"])
    def step(body: StepBody) -> JSONResponse:
        """Raw steps without a calibration (``stickslip move --steps``): the joint is uncertain until referenced."""
        return accepted(room.step(body.joint, body.steps))

    @router.post("/api/reach", status_code=202, tags=["motion"])
    def reach(body: ReachBody) -> JSONResponse:
        """Move the tip in a straight line (``stickslip reach``)."""
        if (body.to is None) == (body.by is None):
            raise Refused("give exactly one of to and by")
        to = None if body.to is None else vector(body.to, "to")
        by = None if body.by is None else vector(body.by, "by")
        return accepted(room.reach(to, by))

    @router.post("/api/jog", tags=["motion"])
    def jog_hold(body: JogBody) -> JSONResponse:
        """Hold a jog direction; repeat at least every 50 ms while held. The tip stops within 0.3 s of the last."""
        return JSONResponse(room.jog_hold(body.direction, body.speed))

    @router.post("/api/jog/release", tags=["motion"])
    def jog_release(end: bool = False) -> JSONResponse:
        """Let go of the jog direction: the tip stops at once; ``end`` ends the session too (else 2 s later)."""
        return JSONResponse(room.jog_release(end))

    @router.post("/api/stop", tags=["motion"])
    async def stop(press: str | None = None) -> JSONResponse:
        """STOP: every axis, now (with a rig, every arm's server before its next burst). Nothing further is sent; a
        jog or the calibration day ends. ``press``: the id of the press (a page sends each on its socket too): the
        event is said once per press."""
        return JSONResponse(room.stop(press))

    return router


def motion_routes(room: ControlRoom) -> APIRouter:
    """An observation, a traverse, and the motions run."""
    router = APIRouter()

    @router.post("/api/observe", tags=["motion"])
    def observe(body: ObserveBody) -> JSONResponse:
        """A measured position into the joint's track (``stickslip observe``)."""
        q = joint_value(body.joint, body.q, "q", stops=True)
        sd = None if body.sd is None else joint_value(body.joint, body.sd, "sd")  # Observation judges it, as the CLI's
        return JSONResponse(clean(room.observe(body.joint, q, sd, body.at_stop, body.force)))

    @router.post("/api/traverse", status_code=202, tags=["motion"])
    def traverse(body: TraverseBody) -> JSONResponse:
        """One traverse from stop to stop, timed by the limit switch (``stickslip traverse``), stored."""
        return accepted(room.traverse(body.joint, body.direction))

    @router.get("/api/motions/{ident}", tags=["motion"])
    async def motion(
        ident: Annotated[int, Path(ge=1, le=2**62)], wait: Annotated[float, Query(ge=0, le=30)] = 0.0
    ) -> JSONResponse:
        """A motion's state and result; ``wait`` (s) waits for it to end first."""
        m = room.motion(ident)
        end = time.monotonic() + wait
        while m.active and time.monotonic() < end:  # polled: a thread per waiter filled the executor that
            await asyncio.sleep(WAIT_POLL_S)  # the WebSocket's commands run in
        return JSONResponse(clean(m.as_dict()))

    @router.get("/api/motion", tags=["motion"])
    def current_motion() -> JSONResponse:
        """The motion running now (``{"motion": null}`` if none)."""
        m = room.current()
        return JSONResponse({"motion": clean(m.as_dict()) if m is not None else None})

    return router


def position_routes(room: ControlRoom) -> APIRouter:
    """The named positions: list, save, forget, go to."""
    router = APIRouter()

    @router.get("/api/positions", tags=["positions"])
    def positions() -> JSONResponse:
        """The named positions."""
        return JSONResponse({"positions": clean(room.positions())})

    @router.post("/api/positions", tags=["positions"])
    def save_position(body: PositionBody) -> JSONResponse:
        """Save the current positions under a name."""
        return JSONResponse(clean(room.save_position(body.name)))

    @router.delete("/api/positions/{name}", tags=["positions"])
    def delete_position(name: Annotated[str, Path(pattern=NAME_PATTERN)]) -> JSONResponse:
        """Forget a named position."""
        return JSONResponse(room.delete_position(name))

    @router.post("/api/positions/{name}/go", status_code=202, tags=["positions"])
    def go(name: Annotated[str, Path(pattern=NAME_PATTERN)]) -> JSONResponse:
        """Drive back to a named position, joint by joint."""
        return accepted(room.go_to(name))

    return router


def calibration_routes(room: ControlRoom) -> APIRouter:
    """The calibration day, the calibration in use, the history, the ANOVA."""
    router = APIRouter()

    @router.post("/api/day", status_code=202, tags=["calibration"])
    def day_start(body: DayBody) -> JSONResponse:
        """Start (or resume) the guided calibration day: the paper's 14 traverses, then the calibration."""
        return accepted(room.day_start(body.day, body.resume))

    @router.get("/api/day", tags=["calibration"])
    def day() -> JSONResponse:
        """The day's plan, progress (the traverse, steps, the end-stop meter) and result."""
        return JSONResponse(clean(room.day()))

    @router.post("/api/day/pose-set", tags=["calibration"])
    def day_pose() -> JSONResponse:
        """The operator has set the pose the day waits for (a real arm)."""
        return JSONResponse(room.day_pose_set())

    @router.get("/api/calibration", tags=["calibration"])
    def calibration() -> JSONResponse:
        """The calibration in use: its parameters with standard errors, and its report."""
        return JSONResponse(clean(room.calibration_detail()))

    @router.get("/api/history", tags=["calibration"])
    def history() -> JSONResponse:
        """The device's sessions (traverses per day) and calibrations, oldest first."""
        return JSONResponse(clean(room.history()))

    @router.get("/api/anova", tags=["calibration"])
    def anova() -> JSONResponse:
        """The ANOVA of the stored traverses (``stickslip anova``): day to day, and + against -."""
        return JSONResponse(clean(room.anova()))

    return router


def camera_routes(room: ControlRoom, camera: CameraFeed | None) -> APIRouter:
    """The camera: the tip in pixels, the planned path, the newest frame."""
    router = APIRouter()

    @router.get("/api/camera", tags=["camera"])
    def camera_info() -> JSONResponse:
        """The tip's pixel position in the last frame, and the planned path in pixels (when calibrated)."""
        if camera is None:
            raise NotFound("no camera (start the server with --camera URL)")
        cur = room.current()
        path = cur.path if cur is not None else None
        px = camera.to_pixels(path) if path else None
        tip = camera.tip()
        return JSONResponse(clean({
            "tip": None if tip is None else {"x": tip[0], "y": tip[1], "sd": tip[2]},
            "path_px": None if px is None else [list(p) for p in px],
        }))

    @router.get("/api/camera/frame", tags=["camera"])
    def camera_frame() -> Response:
        """The newest frame (PNG)."""
        if camera is None:
            raise NotFound("no camera (start the server with --camera URL)")
        from ..vision.camera import CameraError  # the vision layer only where a camera is served

        try:
            data, media, size = camera.frame()
        except (CameraError, OSError) as e:  # the camera lost or used up: the device's condition, not a bug
            raise Unavailable(f"camera: {one_line(e)}") from None
        return Response(data, media_type=media, headers={
            "Cache-Control": "no-store", "X-Frame-Width": str(size[0]), "X-Frame-Height": str(size[1])})

    return router
