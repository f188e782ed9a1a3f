"""The page in a real headless browser (Debian's chromium driven by Playwright), as a user would use it.

One browser and one server for the module: the page loads and shows what a user needs,
positions move on the page while a move runs, the keyboard jogs the simulated arm and
the arm stops when the key is let go, STOP (Esc) ends a long move, and screenshots at a
laptop's and a tablet's size show the controls. A simulated camera feeds the camera
panel (the tip marked where the arm's tip is).

Skipped, with the reason, where Playwright or Debian's chromium is missing
(``apt-get install chromium``; ``make test`` installs it in CI). Playwright never
downloads a browser of its own here: it drives ``/usr/bin/chromium``.
"""

from __future__ import annotations

import shutil
import struct
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")
playwright_api = pytest.importorskip("playwright.sync_api", reason="playwright (the dev extra) is not installed")

from server_support import room_on, served, until  # noqa: E402

from stickslip import kinematics as kin  # noqa: E402
from stickslip.server.app import create_app  # noqa: E402
from stickslip.server.camera import FrameFeed  # noqa: E402
from stickslip.server.room import ControlRoom  # noqa: E402
from stickslip.server.security import Access  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("server_browser")]  # one worker starts the browser once

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
if CHROMIUM is None:
    pytest.skip("Debian's chromium is not installed (apt-get install chromium)", allow_module_level=True)

FLAGS = [
    "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync",
]

PX = 2e-6
"""The simulated camera's pixel size, m (a top view: x right, y down in the image = -y of the rig)."""


class TopCamera:
    """A simulated top-view camera of the arm: a dark field with a bright tip where the arm's true tip is."""

    def __init__(self, room: ControlRoom, size: int = 160):
        self.room = room
        self.size = size

    def tip_px(self) -> tuple[float, float]:
        q = [self.room.owned.dev.position(j) for j in (1, 2, 3)]
        p = kin.tip(q)
        return (self.size / 2 + (p[0] - 0.021) / PX, self.size / 2 - p[1] / PX)

    def grab(self) -> Any:
        x, y = self.tip_px()
        yy, xx = np.mgrid[0 : self.size, 0 : self.size]
        image = 0.1 + 0.8 * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / 8.0)
        return type("Frame", (), {"image": image})()

    def close(self) -> None:
        pass


@pytest.fixture(scope="module")
def room(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlRoom]:
    r = room_on(tmp_path_factory.mktemp("browser"), "sim://?realtime=1&speed=5", jog_idle_end_s=0.3)
    yield r
    r.close()


@pytest.fixture(scope="module")
def url(room: ControlRoom) -> Iterator[str]:
    cam = TopCamera(room)

    def project(points: Any) -> list[tuple[float, float]]:
        return [(cam.size / 2 + (p[0] - 0.021) / PX, cam.size / 2 - p[1] / PX) for p in points]

    feed = FrameFeed(cam, tip_of=lambda frame: (*cam.tip_px(), 0.5), project=project)
    with served(create_app(room, Access(None, True), feed)) as base:
        yield base


@pytest.fixture(scope="module")
def page(url: str) -> Iterator[Any]:
    with playwright_api.sync_playwright() as p, tempfile.TemporaryDirectory() as profile:
        context = p.chromium.launch_persistent_context(
            profile, executable_path=CHROMIUM, headless=True, args=FLAGS, viewport={"width": 1366, "height": 768}
        )
        pg = context.pages[0] if context.pages else context.new_page()
        errors: list[str] = []
        pg.on("pageerror", lambda e: errors.append(str(e)))
        pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        pg.goto(url + "/")
        # polled from here: a function waited for in the page would be evaluated there, which its CSP forbids
        until(lambda: pg.evaluate("document.querySelectorAll('#joints .joint').length") == 3, 15, "the joints")
        pg.errors = errors
        yield pg
        context.close()


def joint_text(page: Any, joint: int) -> str:
    return str(page.inner_text(f"#joints .joint:nth-child({joint}) .value"))


def idle(room: ControlRoom) -> None:
    until(lambda: room.current() is None, 30, "the motion to end")


def test_the_page_loads_with_what_a_user_needs(page: Any, room: ControlRoom) -> None:
    assert "simulated MM3A, real time" in page.inner_text("#device")
    assert page.is_visible("#stop")
    for sel in ("#joints", "#pad", "#move-form", "#save-form", "#day-start", "#plot", "#events"):
        assert page.is_visible(sel), sel
    assert joint_text(page, 2).startswith("-90 deg")
    page.wait_for_selector("#camera-panel:not(.hidden)", timeout=10_000)
    until(lambda: page.evaluate("document.getElementById('frame').naturalWidth") == 160, 10, "a camera frame")
    # the page shows a frame first and then asks /api/camera for the tip: the text follows the frame
    until(lambda: page.inner_text("#camera-tip") != "", 10, "the tip's text after the frame")
    assert "tip at (80.0, 80.0) px" in page.inner_text("#camera-tip")
    assert page.errors == []


def test_positions_update_while_a_move_runs(page: Any, room: ControlRoom) -> None:
    page.select_option("#move-joint", "2")
    page.select_option("#move-mode", "by")
    page.fill("#move-amount", "20deg")  # ~7000 steps: 1.4 s at 5x
    before = joint_text(page, 2)
    page.click("#move-form button[type=submit]")
    seen = {before}
    until(lambda: room.current() is not None, 10, "the move to start")
    while room.current() is not None:
        seen.add(joint_text(page, 2))
    seen.add(joint_text(page, 2))
    assert len(seen) >= 4, seen  # the start, positions along the way, the end
    until(lambda: abs(float(joint_text(page, 2).split(" deg")[0]) + 70.0) < 0.01, 5, "the page to show the end")
    until(lambda: "done" in page.inner_text("#motion"), 5, "the page to say the move is done")


def test_keyboard_jog_moves_the_arm_and_stops_on_release(page: Any, room: ControlRoom) -> None:
    idle(room)
    arm = room.owned.dev
    page.click("h2#h-joints")  # the page has the focus, no input field
    start = arm.steps_simulated
    page.keyboard.down("ArrowUp")
    until(lambda: arm.steps_simulated > start + 5, 10, "the arm to step")
    assert page.eval_on_selector('#pad button[data-dir="+y"]', "b => b.classList.contains('held')")
    page.keyboard.up("ArrowUp")
    until(lambda: room._pad is None or room._pad.held is None, 5, "the pad to let go")  # noqa: SLF001
    stopped_at = arm.steps_simulated
    idle(room)  # the session ends by itself (nothing held); no step after the release
    assert arm.steps_simulated == stopped_at
    assert not page.eval_on_selector('#pad button[data-dir="+y"]', "b => b.classList.contains('held')")
    m = room.motion(max(room._motions))  # noqa: SLF001
    # it ended without a failure; the dead man may have let go once in between on a starved machine
    # (a keep-alive over 0.15 s late: the safe outcome, measured on a clean run at twice the CPU time)
    assert m.kind == "jog" and m.result is not None and m.result["failure"] is None, m.result
    assert m.result["message"] == "stopped" and sum(m.result["sent"]) > 0, m.result


def test_stop_ends_a_long_move(page: Any, room: ControlRoom) -> None:
    idle(room)
    arm = room.owned.dev
    page.select_option("#move-joint", "2")
    page.select_option("#move-mode", "to")
    page.fill("#move-amount", "min")  # ~60 000 steps: 12 s at 5x
    page.click("#move-form button[type=submit]")
    until(lambda: room.current() is not None and room.current().status == "running", 10, "the move")  # type: ignore[union-attr]
    start = arm.steps_simulated
    until(lambda: arm.steps_simulated > start + 500, 10, "the move to get going")
    page.click("h2#h-joints")
    page.keyboard.press("Escape")
    idle(room)
    m = room.motion(max(room._motions))  # noqa: SLF001
    assert m.status == "stopped"
    after = arm.steps_simulated
    assert after - start < 30_000  # stopped long before its end
    until(lambda: "stopped" in page.inner_text("#motion"), 5, "the page to say so")
    assert "STOP" in page.inner_text("#events")


@pytest.mark.parametrize(("name", "width", "height"), [("laptop", 1366, 768), ("tablet", 768, 1024)])
def test_screenshots_show_the_controls(page: Any, tmp_path: Path, name: str, width: int, height: int) -> None:
    page.set_viewport_size({"width": width, "height": height})
    page.wait_for_timeout(300)  # a frame or two of the live state at the new size
    shot = tmp_path / f"serve-{name}.png"
    page.screenshot(path=str(shot), full_page=True)
    w, h = struct.unpack(">II", shot.read_bytes()[16:24])  # the PNG's IHDR
    assert w == width and h >= height
    stop = page.query_selector("#stop").bounding_box()
    assert stop["y"] + stop["height"] <= 90 and stop["x"] + stop["width"] <= width  # always in view, at the top
    assert stop["height"] >= 44 and stop["width"] >= 88  # big enough to hit
    for b in page.query_selector_all("#pad button"):
        box = b.bounding_box()
        assert box["height"] >= 44 and box["width"] >= 44 and box["x"] + box["width"] <= width
    for sel in ("#joints", "#pad", "#move-form", "#save-form", "#day-start", "#plot"):
        box = page.query_selector(sel).bounding_box()
        assert box is not None and box["width"] > 0 and box["x"] >= 0 and box["x"] + box["width"] <= width, sel
    page.set_viewport_size({"width": 1366, "height": 768})


def test_a_lost_camera_is_said_and_its_last_frame_greyed(page: Any, room: ControlRoom) -> None:
    """The camera panel kept the last frame and its 'tip at (x, y) px' as if live when the camera stopped
    delivering (a 503 from /api/camera/frame was ignored): now it says why, greys the frame and marks no tip."""

    class TwoFrames:
        grabs = 0

        def grab(self) -> Any:
            self.grabs += 1
            if self.grabs > 2:
                from stickslip.vision.camera import CameraEnded

                raise CameraEnded("the 2 frames of files://f/*.png are used up")
            return type("Frame", (), {"image": np.full((40, 60), 0.5)})()

        def close(self) -> None:
            pass

    feed = FrameFeed(TwoFrames(), tip_of=lambda frame: (30.0, 20.0, 0.5))
    with served(create_app(room, Access(None, True), feed)) as base:
        pg = page.context.new_page()
        try:
            pg.goto(base + "/")
            until(lambda: pg.inner_text("#camera-tip").startswith("no new frame"), 15, "the camera's loss shown")
            assert pg.inner_text("#camera-tip") == (
                "no new frame: camera: the 2 frames of files://f/*.png are used up "
                "(the frame shown is the last one received)")
            assert pg.evaluate("document.getElementById('frame').classList.contains('stale')")
        finally:
            pg.close()


def test_a_restarted_server_s_events_are_shown(page: Any, tmp_path: Path) -> None:
    """A page left open while its server restarted hid the new server's events: their ids count from 1 again
    and the page skipped every id it had already shown (here 'STOP (nothing was moving)' of the new server)."""
    from server_support import free_port

    port = free_port()
    first, second = room_on(tmp_path / "a", calibrated=False), None
    (tmp_path / "b").mkdir()
    pg = page.context.new_page()
    try:
        with served(create_app(first, Access(None, True)), port) as base:
            pg.goto(base + "/")
            until(lambda: pg.evaluate("document.querySelectorAll('#joints .joint').length") == 3, 15, "the joints")
            for _ in range(3):
                first.event("info", "an event of the first server")
            until(lambda: pg.inner_text("#events").count("first server") == 3, 15, "the first server's events")
        first.close()
        until(lambda: pg.inner_text("#status").startswith("offline since "), 15, "the page to see the server gone")
        second = room_on(tmp_path / "b", calibrated=False)
        with served(create_app(second, Access(None, True)), port):
            until(lambda: pg.inner_text("#status") == "idle", 15, "the page to reconnect")
            second.event("warning", "an event of the second server")
            until(lambda: "second server" in pg.inner_text("#events"), 15, "the second server's event")
            lines = [ln[9:] if ln[:2].isdigit() else ln for ln in pg.inner_text("#events").splitlines()]  # newest first
            cut = lines.index("the server was restarted; its events follow")
            assert "an event of the second server" in lines[:cut]
            assert lines[cut + 1:cut + 4] == ["an event of the first server"] * 3
    finally:
        pg.close()
        if second is not None:
            second.close()


def test_the_tip_boxes_take_a_bare_number_in_um_or_an_amount_as_typed(page: Any, room: ControlRoom) -> None:
    """The 'tip by (µm)' boxes appended 'um' to whatever was typed: '2um' was refused as "unknown length unit
    'umum' in '2umum'", 'abc' as "cannot read 'abcum'" (text the user never typed)."""
    idle(room)
    page.evaluate("document.getElementById('move-msg').textContent = ''")
    for box, value in (("#reach-x", "abc"), ("#reach-y", "0"), ("#reach-z", "0")):
        page.fill(box, value)
    page.click("#reach-form button")
    until(lambda: page.inner_text("#move-msg") != "", 10, "the refusal")
    assert page.inner_text("#move-msg") == "by[0]: cannot read 'abc' as a number with an optional unit"
    page.fill("#reach-x", "2um")
    page.fill("#reach-z", "0.001mm")
    page.click("#reach-form button")
    until(lambda: page.inner_text("#move-msg").startswith("tip move"), 10, "the tip move")
    assert page.inner_text("#move-msg").startswith("tip move by (+2.0, +0.0, +1.0) µm")
    idle(room)
    for box, value in (("#reach-x", "0"), ("#reach-y", "0"), ("#reach-z", "10")):
        page.fill(box, value)


def test_the_move_message_follows_the_motion_to_its_end(page: Any, room: ControlRoom) -> None:
    """'#move-msg' kept "...: running" (the POST's answer) after the move had ended (audit26); it follows the live
    state of that motion now: done, stopped (STOP), and a refusal's reason."""
    idle(room)
    page.select_option("#move-joint", "1")
    page.select_option("#move-mode", "by")
    page.fill("#move-amount", "2deg")
    page.click("#move-form button[type=submit]")
    until(lambda: page.inner_text("#move-msg").startswith("move"), 10, "the move's message")
    idle(room)
    until(lambda: page.inner_text("#move-msg").endswith(": done"), 5, "the message to say the move is done")
    assert page.eval_on_selector("#move-msg", "e => e.className") == "msg ok"
    page.select_option("#move-mode", "to")
    page.fill("#move-amount", "min")
    page.click("#move-form button[type=submit]")
    until(lambda: room.current() is not None and room.current().status == "running", 10, "the move")  # type: ignore[union-attr]
    page.click("h2#h-joints")
    page.keyboard.press("Escape")
    idle(room)
    until(lambda: ": running" not in page.inner_text("#move-msg"), 5, "the message to say the move ended")
    said = page.inner_text("#move-msg")
    assert said.startswith("move of joint 1 to -120 deg: stopped — stopped: joint 1 made "), said
    assert page.eval_on_selector("#move-msg", "e => e.className") == "msg ok"  # a STOP asked for is no failure


def test_one_stop_press_shows_one_event(page: Any, room: ControlRoom, monkeypatch: pytest.MonkeyPatch) -> None:
    """The STOP button sends the press on the socket and as POST /api/stop (the socket is the quicker path; the
    POST also gets through on a socket that is closed or dead, and its failure is said): one press showed
    'STOP (nothing was moving)' twice in the events (audit26). Both still reach the room; one event is shown."""
    idle(room)
    calls: list[int] = []
    stop = room.stop
    monkeypatch.setattr(room, "stop", lambda *a, **k: calls.append(1) or stop(*a, **k))
    said = "STOP (nothing was moving)"
    before = page.inner_text("#events").count(said)
    page.click("#stop")
    until(lambda: len(calls) == 2, 10, "the press on both paths")
    room.event("info", "after the one press")  # the page has shown every event before this one once it shows it
    until(lambda: "after the one press" in page.inner_text("#events"), 10, "the events to reach the page")
    assert page.inner_text("#events").count(said) == before + 1


def _greyed(pg: Any) -> dict[str, str]:
    """Each live value's computed opacity and filter, by its selector."""
    return dict(pg.evaluate("""() => Object.fromEntries(
        ["#joints", ".tip", "#motion", "#plot", "#day-now", ".meter", "#device"].map((s) => {
            const c = getComputedStyle(document.querySelector(s));
            return [s, c.opacity + " " + c.filter];
        }))"""))


def test_an_offline_page_greys_every_live_value_until_fresh_state_comes(page: Any, tmp_path: Path) -> None:
    """While the server was down the page said 'offline' in the status pill only: the joints, the tip and the
    motion stayed as last received, not greyed, as if live (audit26). Now every live value is greyed with the time
    of the last update, as a lost camera's last frame is, and is live again only once a fresh state comes: a
    reconnected socket whose server sends no state yet leaves them greyed."""
    from server_support import free_port

    port = free_port()
    first, second = room_on(tmp_path / "a", calibrated=False), None
    (tmp_path / "b").mkdir()
    pg = page.context.new_page()
    try:
        with served(create_app(first, Access(None, True)), port) as base:
            pg.goto(base + "/")
            until(lambda: pg.inner_text("#status") == "idle", 15, "the page's first state")
            assert set(_greyed(pg).values()) == {"1 none"}
            assert not pg.is_visible("#stale-note")
            shown = joint_text(pg, 3)
        first.close()
        until(lambda: pg.inner_text("#status").startswith("offline since "), 15, "the page to see the server gone")
        assert set(_greyed(pg).values()) == {"0.35 grayscale(1)"}  # as img.stale, the lost camera's frame
        note = pg.inner_text("#stale-note")
        assert note.startswith("offline since ") and " UTC: the greyed values are the last received, at " in note
        assert note.endswith(" UTC, and may no longer be true; they are live again when the server sends fresh ones")
        assert joint_text(pg, 3) == shown  # the last value stays, to be read as the last one
        pg.click("#stop")  # said 'STOP: Failed to fetch' (the browser's words)
        until(lambda: pg.inner_text("#move-msg").startswith("STOP"), 10, "the STOP's failure said")
        assert pg.inner_text("#move-msg") == "STOP: the server does not answer: this STOP did not reach it"
        pg.click("h2#h-joints")
        pg.keyboard.down("ArrowUp")  # a jog key held while offline: let go at once, and nothing was said
        until(lambda: pg.inner_text("#jog-note") != "", 5, "the jog's refusal said")
        pg.keyboard.up("ArrowUp")
        assert pg.inner_text("#jog-note") == "jog: the server does not answer; nothing was sent"
        assert not pg.eval_on_selector('#pad button[data-dir="+y"]', "b => b.classList.contains('held')")
        second = room_on(tmp_path / "b", calibrated=False)
        held = True
        snapshot = second.snapshot

        def no_state_yet() -> dict[str, Any]:
            if held:
                raise RuntimeError("no state yet")  # the live stream sends nothing while this holds
            return snapshot()

        second.snapshot = no_state_yet  # type: ignore[method-assign]
        app = create_app(second, Access(None, True))
        with served(app, port):
            until(lambda: pg.inner_text("#status") == "reconnected; waiting for the state", 15, "the reconnection")
            until(lambda: app.state.live.clients, 5, "the socket among the live clients")  # open, and no state
            assert set(_greyed(pg).values()) == {"0.35 grayscale(1)"} and pg.is_visible("#stale-note")
            held = False
            until(lambda: pg.inner_text("#status") == "idle", 15, "the fresh state")
            assert set(_greyed(pg).values()) == {"1 none"}
            assert not pg.is_visible("#stale-note")
            assert pg.inner_text("#jog-note") == ""  # live again: the jog may be tried again
    finally:
        pg.close()
        if second is not None:
            second.close()


def test_a_socket_open_with_nothing_coming_greys_the_values(page: Any, tmp_path: Path) -> None:
    """A server whose live stream stops while its socket stays open (the browser cannot tell a dead link from a
    quiet one): after 3 s with no state the values are greyed with 'no update since', and live again with the
    next state."""
    room = room_on(tmp_path, calibrated=False)
    quiet = False
    snapshot = room.snapshot

    def stream() -> dict[str, Any]:
        if quiet:
            raise RuntimeError("the stream stalls")
        return snapshot()

    room.snapshot = stream  # type: ignore[method-assign]
    pg = page.context.new_page()
    try:
        with served(create_app(room, Access(None, True))) as base:
            pg.goto(base + "/")
            until(lambda: pg.inner_text("#status") == "idle", 15, "the page's first state")
            quiet = True
            until(lambda: pg.inner_text("#status").startswith("no update since "), 15, "the page to see no update")
            assert set(_greyed(pg).values()) == {"0.35 grayscale(1)"}
            assert pg.inner_text("#stale-note").startswith("no update since ")
            quiet = False
            until(lambda: pg.inner_text("#status") == "idle", 15, "the next state")
            assert set(_greyed(pg).values()) == {"1 none"} and not pg.is_visible("#stale-note")
    finally:
        pg.close()
        room.close()


def test_a_move_followed_across_a_restart_is_not_left_running(page: Any, tmp_path: Path) -> None:
    """The move's message box follows its motion to the end; a server gone mid-move left it saying '...: running'
    for good after the restart (the new server has no such motion, and its motion ids count from 1 again, so
    its first motion could have been taken for it). It says now that the end was not seen."""
    from server_support import free_port

    port = free_port()
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first, second = room_on(tmp_path / "a", "sim://?realtime=1&speed=1"), None
    pg = page.context.new_page()
    try:
        with served(create_app(first, Access(None, True)), port) as base:
            pg.goto(base + "/")
            until(lambda: pg.inner_text("#status") == "idle", 15, "the page's first state")
            pg.select_option("#move-joint", "2")
            pg.select_option("#move-mode", "to")
            pg.fill("#move-amount", "min")
            pg.click("#move-form button[type=submit]")
            until(lambda: pg.inner_text("#move-msg").endswith(": running"), 10, "the move running")
        until(lambda: pg.inner_text("#status").startswith("offline since "), 15, "the page to see the server gone")
        first.close()
        assert pg.inner_text("#move-msg").endswith(": running")  # the last it heard, greyed with the values
        assert pg.eval_on_selector("#move-msg", "e => getComputedStyle(e).opacity") == "0.35"
        second = room_on(tmp_path / "b", calibrated=False)
        with served(create_app(second, Access(None, True)), port):
            until(lambda: pg.inner_text("#status") == "idle", 15, "the page to reconnect")
            until(lambda: not pg.inner_text("#move-msg").endswith(": running"), 5, "the message to change")
            said = pg.inner_text("#move-msg")
            assert said.startswith("move of joint 2 to ")
            assert said.endswith(": the server was restarted while it ran; its end was not seen (the joints say "
                                 "what is kept)"), said
    finally:
        pg.close()
        if second is not None:
            second.close()
