"""The server's API in-process (httpx through Starlette's TestClient): every verb and every refusal.

The room drives the simulator in real time at 50x (``sim://?realtime=1&speed=50``), so a
move takes wall-clock time (a STOP can land in it) but the tests stay fast. Positions are
checked against the planner (the kept dead reckoning of the steps actually sent) and the
simulator's own count of steps; nothing is timed.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")

from fastapi.testclient import TestClient  # noqa: E402
from server_support import room_on, until  # noqa: E402

from stickslip.joints import JOINTS  # noqa: E402
from stickslip.motion.planning import Planner  # noqa: E402
from stickslip.server.app import create_app  # noqa: E402
from stickslip.server.room import ControlRoom  # noqa: E402
from stickslip.server.security import Access  # noqa: E402

LOCAL = Access(None, True)


@pytest.fixture()
def room(tmp_path: Path) -> Iterator[ControlRoom]:
    r = room_on(tmp_path, jog_idle_end_s=0.3)
    yield r
    r.close()


@pytest.fixture()
def client(room: ControlRoom) -> Iterator[TestClient]:
    with TestClient(create_app(room, LOCAL), base_url="http://127.0.0.1:8765") as c:
        yield c


@pytest.fixture()
def held_room(tmp_path: Path) -> Iterator[ControlRoom]:
    """A room whose dead man waits 30 s: only the release (or the socket) ends a jog, however starved the
    machine is between two keep-alives (with the default hold a slow CI core once let the dead man go first)."""
    r = room_on(tmp_path, jog_idle_end_s=0.3, jog_hold_s=30.0)
    yield r
    r.close()


@pytest.fixture()
def held_client(held_room: ControlRoom) -> Iterator[TestClient]:
    with TestClient(create_app(held_room, LOCAL), base_url="http://127.0.0.1:8765") as c:
        yield c


def wait(client: TestClient, motion: dict[str, Any]) -> dict[str, Any]:
    r = client.get(f"/api/motions/{motion['id']}", params={"wait": 20})
    assert r.status_code == 200, r.text
    m: dict[str, Any] = r.json()
    assert m["status"] not in ("starting", "running"), m
    return m


def refused(r: Any, status: int, *words: str) -> str:
    assert r.status_code == status, r.text
    body = r.json()
    assert set(body) == {"error"}, body
    line = body["error"]
    assert "\n" not in line and "Traceback" not in line
    for w in words:
        assert w in line, (w, line)
    return str(line)


# ---------------------------------------------------------------- state


def test_state_where_and_the_schema(client: TestClient, room: ControlRoom) -> None:
    s = client.get("/api/state").json()
    assert s["device"] == "sim://" and s["model"] == "simulated MM3A, real time"
    assert [r["joint"] for r in s["joints"]] == [1, 2, 3]
    assert s["calibration"]["source"].endswith("true-cal.json")
    # the tip is the kinematics of the kept joints (outstretched: offset 0, length 21 mm along x)
    assert s["tip"] == pytest.approx([0.021, 0.0, 0.0], abs=1e-12)
    assert s["moving"] is False and s["camera"] is False
    w = client.get("/api/where").json()
    assert w["device"] == "sim://" and w["answers"] == "simulated MM3A, real time"
    schema = client.get("/openapi.json").json()
    paths = set(schema["paths"])
    assert {"/api/move", "/api/stop", "/api/jog", "/api/positions", "/api/day", "/api/state"} <= paths
    assert client.get("/docs").status_code == 404  # no page that loads scripts from the internet


def test_a_move_runs_to_its_planned_end(client: TestClient, room: ControlRoom) -> None:
    r = client.post("/api/move", json={"joint": 3, "by": "300um"})
    assert r.status_code in (200, 202), r.text
    m = wait(client, r.json())
    assert m["status"] == "done" and m["error"] is None
    res = m["result"]
    assert res["steps_signed"] == sum(res["bursts"]) > 0
    # the kept position is the plan's dead reckoning of the steps sent, within half a step of the target
    st = room.state()
    assert st.positions[3] == pytest.approx(res["q_end_predicted"], abs=1e-15)
    assert abs(st.positions[3] - 300e-6) < 0.6e-6
    # the simulator made exactly those steps: its truth is within the model's error (true calibration: ~3 %)
    truth = client.get("/api/state").json()["truth"]["q"][2]
    assert truth == pytest.approx(300e-6, rel=0.05)
    # and the path planned for the page runs from the start to the target
    assert m["path"][0] == pytest.approx([0.021, 0.0, 0.0], abs=1e-12)


def test_positions_update_on_the_live_socket_while_a_move_runs(client: TestClient, room: ControlRoom) -> None:
    with client.websocket_connect("ws://127.0.0.1:8765/api/live") as ws:
        first = json.loads(ws.receive_text())
        r = client.post("/api/move", json={"joint": 2, "by": "60deg"})  # ~21 000 steps: 0.4 s at 50x, 3 bursts
        assert r.status_code == 202, r.text
        seqs, q2, truth = [first["seq"]], [first["state"]["joints"][1]["q"]], [first["state"]["truth"]["q"][1]]
        while True:
            msg = json.loads(ws.receive_text())
            seqs.append(msg["seq"])
            q2.append(msg["state"]["joints"][1]["q"])
            truth.append(msg["state"]["truth"]["q"][1])
            motion = msg["state"]["motion"]  # None in a message sent before the move was registered
            if motion is not None and motion["status"] == "done":
                break
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # none lost, in order
    # the kept position moves on after every burst; the simulator's truth as it steps
    assert len(set(q2)) >= 3, sorted(set(q2))
    assert len(set(truth)) >= 4, sorted(set(truth))
    assert q2[-1] - q2[0] == pytest.approx(math.radians(60), abs=1e-4)


def test_one_motion_at_a_time_and_jog_waits_for_a_plan(client: TestClient, room: ControlRoom) -> None:
    r = client.post("/api/move", json={"joint": 2, "to": "min"})  # most of joint 2's range: about 1.5 s at 50x
    assert r.status_code == 202, r.text
    refused(client.post("/api/move", json={"joint": 3, "by": "1um"}), 409, "move of joint 2", "is running",
            "one motion at a time")
    refused(client.post("/api/jog", json={"direction": "+x"}), 409, "jog is disabled while a plan runs")
    refused(client.post("/api/reach", json={"by": ["0um", "0um", "1um"]}), 409, "is running")
    refused(client.post("/api/positions", json={"name": "here"}), 409, "is running")
    refused(client.post("/api/where", json={"set": {"3": "min"}}), 409, "is running")
    refused(client.post("/api/observe", json={"joint": 3, "q": "0um"}), 409, "is running")
    stop = client.post("/api/stop").json()
    assert stop["stopped"].startswith("move of joint 2")
    assert wait(client, r.json())["status"] == "stopped"


def test_stop_ends_a_long_move_and_the_kept_position_is_the_steps_made(client: TestClient, room: ControlRoom) -> None:
    arm = room.owned.dev
    before = arm.steps_simulated
    start = room.state().positions[2]
    r = client.post("/api/move", json={"joint": 2, "to": "min"})
    assert r.status_code == 202, r.text
    until(lambda: arm.steps_simulated - before > 2000, 10, "the move to get going")
    client.post("/api/stop")
    m = wait(client, r.json())
    assert m["status"] == "stopped" and "stopped" in m["error"]
    made = arm.steps_simulated - before
    planned = m["result"]["steps_signed"]
    assert 0 < made < abs(planned)
    assert -sum(m["result"]["bursts"]) == made  # the journal counted every step the arm made, no more
    st = room.state()
    assert 2 not in st.uncertain and st.sources[2] == "dead-reckoned"  # exact where it stopped, not uncertain
    cal = room.calibration
    assert cal is not None
    expected = Planner(cal, 2, st.pose).position_after(start, -made)
    assert st.positions[2] == pytest.approx(expected, abs=1e-12)
    assert room.stops and room.stops[-1][1] is not None


def test_every_bad_request_is_one_line(client: TestClient) -> None:
    refused(client.post("/api/move", json={"joint": 3, "by": "30"}), 422, "by: 30 has no unit", "30um")
    refused(client.post("/api/move", json={"joint": 2, "by": "30um"}), 422, "by:", "angle")
    refused(client.post("/api/move", json={"joint": 4, "by": "30um"}), 422, "joint")
    refused(client.post("/api/move", json={"joint": "3", "by": "30um"}), 422, "joint")
    refused(client.post("/api/move", json={"joint": True, "by": "30um"}), 422, "joint")
    refused(client.post("/api/move", json={"joint": 3}), 422, "exactly one of by and to")
    refused(client.post("/api/move", json={"joint": 3, "by": "1um", "to": "1um"}), 422, "exactly one of by and to")
    refused(client.post("/api/move", json={"joint": 3, "to": "13mm"}), 422, "outside joint 3's range")
    refused(client.post("/api/move", json={"joint": 3, "by": "1um", "speed": 3}), 422, "speed", "Extra inputs")
    refused(client.post("/api/move", content=b"not json", headers={"content-type": "application/json"}), 422,
            "not JSON")
    for raw in (b'{"joint": 3, "by": 1e400}', b'{"joint": 3, "by": NaN}'):
        refused(client.post("/api/move", content=raw, headers={"content-type": "application/json"}), 422)
    refused(client.post("/api/move", json={"joint": 3, "by": "1 parsec"}), 422, "unknown length unit")
    # a finite amount so large that the drawn path's steps overflowed (a 500 once): refused as out of range
    refused(client.post("/api/move", json={"joint": 1, "by": 5.617791046444737e306}), 422, "outside joint 1's range")
    refused(client.post("/api/step", json={"joint": 3, "steps": 0}), 422, "0 steps")
    refused(client.post("/api/step", json={"joint": 3, "steps": 2.5}), 422, "steps")
    refused(client.post("/api/reach", json={"by": ["1um", "2um"]}), 422, "by")
    refused(client.post("/api/reach", json={}), 422, "exactly one of to and by")
    refused(client.post("/api/reach", json={"to": ["1m", "0m", "0m"]}), 422, "reach")
    refused(client.post("/api/jog", json={"direction": "up"}), 422, "direction")
    refused(client.post("/api/jog", json={"direction": "+x", "speed": 9}), 422, "speed")
    refused(client.post("/api/observe", json={"joint": 3, "q": "1um", "sd": "-1um"}), 422, "standard deviation")
    refused(client.post("/api/where", json={"set": {"3": "13mm"}}), 422, "outside joint 3's range")
    refused(client.post("/api/where", json={"set": {"4": "min"}}), 422, "set")
    refused(client.post("/api/positions", json={"name": "../etc"}), 422, "name")
    refused(client.post("/api/positions", json={"name": ""}), 422, "name")
    refused(client.post("/api/positions/nowhere/go"), 404, "no position named 'nowhere'")
    refused(client.delete("/api/positions/nowhere"), 404, "no position named 'nowhere'")
    refused(client.get("/api/motions/12345"), 404, "no motion 12345")
    refused(client.get("/api/motions/0"), 422)
    refused(client.get("/api/motions/1", params={"wait": 99}), 422, "wait")
    refused(client.get("/api/events", params={"after": -1}), 422, "after")
    refused(client.post("/api/day", json={"day": "no/slashes"}), 422, "day")
    refused(client.post("/api/day/pose-set"), 409, "not waiting for a pose")
    refused(client.post("/api/day", json={"resume": True}), 409, "no calibration day to resume")
    refused(client.get("/api/camera"), 404, "no camera")
    refused(client.get("/api/camera/frame"), 404, "no camera")
    refused(client.post("/api/move", content=b"{" + b" " * 70_000 + b"}", headers={"content-type": "application/json"}),
            413, "larger than 64 kB")
    assert client.get("/static/../room.py").status_code == 404
    assert client.get("/static/app.js").status_code == 200


def test_refusals_from_the_kept_state(tmp_path: Path) -> None:
    uncalibrated = room_on(tmp_path, calibrated=False)
    try:
        with TestClient(create_app(uncalibrated, LOCAL), base_url="http://127.0.0.1") as c:
            refused(c.post("/api/move", json={"joint": 3, "by": "1um"}), 409, "no calibration", "calibration day")
            refused(c.post("/api/jog", json={"direction": "+x"}), 409, "no calibration")
            refused(c.post("/api/positions/x/go"), 409, "no calibration")
            # raw steps need none: the joint is then uncertain, and a planned move from it is refused
            m = c.post("/api/step", json={"joint": 3, "steps": 200})
            assert m.status_code in (200, 202)
            assert wait(c, m.json())["status"] == "done"
            state = c.get("/api/state").json()
            assert state["joints"][2]["source"] == "uncertain" and "to" in state["joints"][2]["uncertain_display"]
            refused(c.post("/api/positions", json={"name": "here"}), 409, "uncertain")
    finally:
        uncalibrated.close()


def test_an_uncertain_joint_is_refused_until_referenced(client: TestClient) -> None:
    m = client.post("/api/step", json={"joint": 3, "steps": 100})
    assert wait(client, m.json())["status"] == "done"
    refused(client.post("/api/move", json={"joint": 3, "by": "1um"}), 409, "uncertain", "re-reference")
    ok = client.post("/api/where", json={"set": {"3": "min"}})
    assert ok.status_code == 200, ok.text
    assert ok.json()["joints"][2]["source"] == "set"
    assert wait(client, client.post("/api/move", json={"joint": 3, "by": "1um"}).json())["status"] == "done"


def test_save_a_position_and_return_to_it(client: TestClient, room: ControlRoom) -> None:
    assert wait(client, client.post("/api/move", json={"joint": 3, "to": "2mm"}).json())["status"] == "done"
    assert wait(client, client.post("/api/move", json={"joint": 2, "by": "-10deg"}).json())["status"] == "done"
    saved = client.post("/api/positions", json={"name": "above the cell"})
    assert saved.status_code == 200, saved.text
    here = [room.state().positions[j] for j in (1, 2, 3)]
    assert saved.json()["q"] == here
    assert wait(client, client.post("/api/move", json={"joint": 3, "to": "5mm"}).json())["status"] == "done"
    assert wait(client, client.post("/api/move", json={"joint": 2, "by": "20deg"}).json())["status"] == "done"
    assert [p["name"] for p in client.get("/api/positions").json()["positions"]] == ["above the cell"]
    m = wait(client, client.post("/api/positions/above the cell/go").json())
    assert m["status"] == "done"
    # joint 3 retracted first (5 mm -> 2 mm), then joint 2
    assert [mv["joint"] for mv in m["result"]["moves"]] == [3, 2]
    back = [room.state().positions[j] for j in (1, 2, 3)]
    for j, (a, b) in enumerate(zip(back, here, strict=True), start=1):
        half_step = 0.6e-6 if j == 3 else 30e-6
        assert abs(a - b) < half_step, (j, a, b)
    assert client.delete("/api/positions/above the cell").status_code == 200
    assert client.get("/api/positions").json()["positions"] == []


def test_jog_moves_while_held_and_stops_on_release(held_client: TestClient, held_room: ControlRoom) -> None:
    client, room = held_client, held_room
    arm = room.owned.dev
    start = [arm.position(j) for j in (1, 2, 3)]
    r = client.post("/api/jog", json={"direction": "+z", "speed": 7})
    assert r.status_code == 200 and r.json()["jog"] == "started", r.text
    ident = r.json()["motion"]
    until(lambda: arm.position(2) != start[1], 10, "the arm to move")
    for _ in range(5):  # keep-alives while held
        assert client.post("/api/jog", json={"direction": "+z", "speed": 7}).json()["jog"] == "held"
    client.post("/api/jog/release")
    m = wait(client, {"id": ident})  # the session ends by itself after jog_idle_end_s with nothing held
    assert m["status"] == "done" and m["result"]["deadman"] == 0
    moved = [arm.position(j) - s for j, s in zip((1, 2, 3), start, strict=True)]
    assert moved[1] > 0  # +z from the outstretched pose raises the arm: joint 2 turns up
    # the kept positions are the dead reckoning of what was sent, and follow the arm to the model's error
    sent = m["result"]["sent"]
    assert sent[1] > 0
    kept = room.state().positions[2] - start[1]
    assert kept == pytest.approx(moved[1], rel=0.1)


def test_stop_latches_a_jog_until_its_key_is_let_go(held_client: TestClient, held_room: ControlRoom) -> None:
    """A script that kept sending jog keep-alives started a new jog session 40 ms after STOP and the arm moved on
    (audit34). STOP now latches a jog it ended, as an emergency stop does: refused until the key is let go."""
    client, room = held_client, held_room
    arm = room.owned.dev
    r = client.post("/api/jog", json={"direction": "+z", "speed": 7})
    assert r.status_code == 200 and r.json()["jog"] == "started", r.text
    until(lambda: arm.position(2) != -math.pi / 2, 10, "the arm to move")
    assert client.post("/api/stop").status_code == 200
    assert wait(client, {"id": r.json()["motion"]})["status"] in ("done", "stopped")
    stopped_at = arm.position(2)
    for _ in range(3):  # the key still held: its keep-alives
        refused(client.post("/api/jog", json={"direction": "+z", "speed": 7}), 409, "STOP ended the jog",
                "let go of the jog key")
    assert arm.position(2) == stopped_at and room.current() is None
    assert client.post("/api/jog/release").status_code == 200  # let go: the next press jogs again
    r = client.post("/api/jog", json={"direction": "+z", "speed": 7})
    assert r.status_code == 200 and r.json()["jog"] == "started", r.text
    client.post("/api/jog/release")
    wait(client, {"id": r.json()["motion"]})
    # a STOP with no jog running latches nothing
    assert client.post("/api/stop").status_code == 200
    r = client.post("/api/jog", json={"direction": "-z", "speed": 7})
    assert r.status_code == 200 and r.json()["jog"] == "started", r.text
    client.post("/api/jog/release")
    wait(client, {"id": r.json()["motion"]})


def test_a_jog_whose_client_stops_sending_is_stopped_by_the_dead_man(client: TestClient, room: ControlRoom) -> None:
    r = client.post("/api/jog", json={"direction": "-x", "speed": 6})
    assert r.status_code == 200, r.text
    m = wait(client, {"id": r.json()["motion"]})  # no keep-alive, no release
    assert m["status"] == "done" and m["result"]["deadman"] == 1
    assert m["result"]["message"] == "stopped"


def test_a_jog_whose_socket_closes_stops_at_once(tmp_path: Path) -> None:
    # the dead man given 30 s (not 0.15 s), so only the closing socket can end the jog this soon: on a
    # starved machine the 0.15 s one let go first once (a failure of the test, not of the server)
    room = room_on(tmp_path, jog_idle_end_s=0.3, jog_hold_s=30.0)
    try:
        with TestClient(create_app(room, LOCAL), base_url="http://127.0.0.1:8765") as client:
            _jog_then_close_the_socket(client, room)
    finally:
        room.close()


def _jog_then_close_the_socket(client: TestClient, room: ControlRoom) -> None:
    with client.websocket_connect("ws://127.0.0.1:8765/api/live") as ws:
        ws.receive_text()
        ws.send_text(json.dumps({"type": "jog", "direction": "+y", "speed": 5}))
        until(lambda: room.current() is not None, 10, "the jog to start")
        ident = room.current().id  # type: ignore[union-attr]
        ws.send_text(json.dumps({"type": "jog", "direction": "+y", "speed": 5}))  # held, then the socket closes
    m = wait(client, {"id": ident})
    assert m["result"]["deadman"] == 0  # released by the closing socket, not by the dead man
    texts = [e["text"] for e in client.get("/api/events").json()["events"]]
    assert any("went away with a jog key held" in t for t in texts), texts


def test_stop_on_the_socket_and_bad_messages(client: TestClient, room: ControlRoom) -> None:
    with client.websocket_connect("ws://127.0.0.1:8765/api/live") as ws:
        ws.receive_text()
        ws.send_text("not json")
        ws.send_text(json.dumps({"type": "dance"}))
        ws.send_text(json.dumps({"type": "jog", "direction": "sideways"}))
        ws.send_text(json.dumps({"type": "stop"}))
        replies = []
        while len(replies) < 4:
            msg = json.loads(ws.receive_text())
            if "seq" not in msg:
                replies.append(msg)
    assert "JSON object" in replies[0]["error"]
    assert "unknown message type 'dance'" in replies[1]["error"]
    assert replies[2]["status"] == 422 and "direction" in replies[2]["error"]
    assert replies[3]["reply"] == "stop" and replies[3]["stopped"] is None


def test_one_stop_press_sent_both_ways_is_one_event(
    client: TestClient, room: ControlRoom, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The page sends each STOP press on the socket and as POST /api/stop (belt and braces): one press showed
    'STOP (nothing was moving)' twice (audit26). The press's id makes the second arrival silent; it still halts."""
    def stops() -> list[str]:
        return [e["text"] for e in room.events_after(0) if e["text"].startswith("STOP")]

    before = len(stops())
    with client.websocket_connect("ws://127.0.0.1:8765/api/live") as ws:
        ws.receive_text()
        ws.send_text(json.dumps({"type": "stop", "press": "p-1"}))
        while "seq" in (msg := json.loads(ws.receive_text())):
            pass
    assert msg["reply"] == "stop" and msg["stopped"] is None
    assert client.post("/api/stop?press=p-1").json() == {"stopped": None, "motion": None}
    assert stops()[before:] == ["STOP (nothing was moving)"]
    halt, halts = room.owned.halt, []
    monkeypatch.setattr(room.owned, "halt", lambda: halts.append(1) or halt())
    client.post("/api/stop?press=p-1")  # the same press again: halted again, said once
    client.post("/api/stop?press=p-2")  # another press: said
    client.post("/api/stop")  # no press id (the Python client, curl): said each time
    assert stops()[before:] == ["STOP (nothing was moving)"] * 3
    assert len(halts) == 3  # the controller was told to stop each time, the repeated press too
    long = client.post("/api/stop?press=" + "x" * 5000)  # a STOP is never refused for its id
    assert long.status_code == 200 and stops()[before:] == ["STOP (nothing was moving)"] * 4


def test_observe_and_where(client: TestClient, room: ControlRoom) -> None:
    assert wait(client, client.post("/api/move", json={"joint": 3, "by": "100um"}).json())["status"] == "done"
    kept = room.state().positions[3]
    r = client.post("/api/observe", json={"joint": 3, "q": kept + 0.2e-6, "sd": "0.5um"})
    assert r.status_code == 200, r.text
    assert r.json()["q_measured"] == pytest.approx(kept + 0.2e-6)
    refused(client.post("/api/observe", json={"joint": 3, "q": "3mm", "sd": "0.1um"}), 422, "standard deviations")
    r = client.post("/api/where", json={"q2": "-60deg", "theta": "10deg"})
    assert r.json()["theta"] == pytest.approx(math.radians(10))
    assert room.state().positions[2] == pytest.approx(math.radians(-60))


def test_events_and_motion_listing(client: TestClient) -> None:
    m = client.post("/api/move", json={"joint": 3, "by": "2um"}).json()
    wait(client, m)
    texts = [e["text"] for e in client.get("/api/events").json()["events"]]
    assert any("move of joint 3 by 2 µm: done" in t for t in texts), texts
    after = client.get("/api/events", params={"after": 10**6}).json()["events"]
    assert after == []
    assert client.get("/api/motion").json() == {"motion": None}


def test_calibration_history_and_anova(client: TestClient) -> None:
    cal = client.get("/api/calibration").json()
    assert {p["name"] for p in cal["parameters"]} >= {"a", "b", "c", "gamma0", "d"}
    assert "joint 3" in cal["report"]
    assert client.get("/api/history").json()["sessions"] == []
    anova = client.get("/api/anova").json()
    assert anova["traverses"] == 0 and "no traverses stored for sim:// yet" in anova["report"]


def test_the_page_is_served_with_its_files(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200 and "STOP" in page.text
    assert "frame-ancestors 'none'" in page.headers["content-security-policy"]
    for name in ("app.js", "style.css"):
        assert client.get(f"/static/{name}").status_code == 200
    # nothing on the page comes from elsewhere
    for text in (page.text, client.get("/static/app.js").text, client.get("/static/style.css").text):
        assert "http://" not in text.replace("http://" + "", "") or "https://" not in text
        assert "//cdn" not in text and "googleapis" not in text


def test_jog_limit_and_speed_preset_checks() -> None:
    from stickslip.server.pad import DIRECTIONS, PadKeys

    clock = [0.0]
    pad = PadKeys(hold_s=0.15, idle_end_s=2.0, clock=lambda: clock[0])
    pad.hold("+x", 3)
    clock[0] = 0.05  # the session reads for the first time: the hold counts from here
    assert pad.read(0.0) == ["3", "right"]
    clock[0] = 0.1
    pad.hold("+x")
    assert pad.read(0.0) == ["right"]
    clock[0] = 0.26  # 0.16 s since the last keep-alive: the dead man lets go
    assert pad.read(0.0) == ["space"] and pad.deadman == 1 and pad.held is None
    clock[0] = 2.2
    assert pad.read(0.0) == []
    clock[0] = 2.27  # 2.01 s with nothing held: the session ends
    assert pad.read(0.0) == ["q"]
    assert pad.read(0.0) == []  # once
    with pytest.raises(ValueError, match="unknown direction"):
        pad.hold("up")
    with pytest.raises(ValueError, match="speed must be a preset 1-7"):
        pad.hold("+x", 8)
    from stickslip.procedures.jog import DIRECTION_KEYS

    assert set(DIRECTIONS.values()) <= set(DIRECTION_KEYS)
    assert JOINTS[3].upper == 0.012


def test_a_lost_camera_is_503_and_its_tip_is_forgotten(room: ControlRoom) -> None:
    """A camera that stops delivering (files:// used up, a camera unplugged) was a 500 'internal error: ...' with a
    traceback in the server's log, and /api/camera kept the tip of the last frame as if it were current."""
    import numpy as np

    from stickslip.server.camera import FrameFeed
    from stickslip.vision.camera import CameraEnded

    class OneFrame:
        grabs = 0

        def grab(self) -> Any:
            self.grabs += 1
            if self.grabs > 1:
                raise CameraEnded("the 1 frames of files://f/*.png are used up")
            return type("Frame", (), {"image": np.full((4, 6), 0.5)})()

        def close(self) -> None:
            pass

    feed = FrameFeed(OneFrame(), tip_of=lambda frame: (3.0, 2.0, 0.5))
    with TestClient(create_app(room, LOCAL, feed), base_url="http://127.0.0.1:8765") as c:
        ok = c.get("/api/camera/frame")
        assert ok.status_code == 200 and ok.headers["X-Frame-Width"] == "6"
        assert c.get("/api/camera").json()["tip"] == {"x": 3.0, "y": 2.0, "sd": 0.5}
        lost = c.get("/api/camera/frame")
        assert lost.status_code == 503
        assert lost.json()["error"] == "camera: the 1 frames of files://f/*.png are used up"
        assert c.get("/api/camera").json()["tip"] is None
