"""``stickslip serve --rig``: the server drives one arm of a rig, and every motion is checked against the envelope.

The room serves the probe of ``server_support.RIG`` on the simulator in real time at 50x.
Refusals are checked against the independent geometry of ``rig_geometry`` (its own
forward kinematics and point distances), and nothing is sent when a motion is refused
(the simulator's own step count).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")

from fastapi.testclient import TestClient  # noqa: E402
from rig_geometry import links, point_distance  # noqa: E402
from server_support import rig_room_on, until  # noqa: E402
from typer.testing import CliRunner  # noqa: E402

from stickslip.cli import app  # noqa: E402
from stickslip.procedures.arms import position_of  # noqa: E402
from stickslip.procedures.move import PoseUpdate  # noqa: E402
from stickslip.server.app import create_app  # noqa: E402
from stickslip.server.room import ControlRoom  # noqa: E402
from stickslip.server.security import Access  # noqa: E402

LOCAL = Access(None, True)


@pytest.fixture()
def room(tmp_path: Path) -> Iterator[ControlRoom]:
    r = rig_room_on(tmp_path)
    yield r
    r.close()


@pytest.fixture()
def client(room: ControlRoom) -> Iterator[TestClient]:
    with TestClient(create_app(room, LOCAL), base_url="http://127.0.0.1:8765") as c:
        yield c


def wait(client: TestClient, ident: int) -> dict[str, Any]:
    m: dict[str, Any] = client.get(f"/api/motions/{ident}", params={"wait": 20}).json()
    assert m["status"] not in ("starting", "running"), m
    return m


def refused(r: Any, status: int, *words: str) -> str:
    assert r.status_code == status, r.text
    line = str(r.json()["error"])
    assert "\n" not in line and "Traceback" not in line
    for w in words:
        assert w in line, (w, line)
    return line


def clearance(room: ControlRoom, q: list[float], volume: str) -> float:
    """The probe's distance from ``volume`` at ``q`` (independent geometry, points along its links), m."""
    rig = room.options.rig
    assert rig is not None
    arm = rig.arm("probe")
    v = next(v for v in rig.volumes if v.name == volume)
    u = np.linspace(0.0, 1.0, 400)[:, None]
    pts = np.vstack([a + u * (b - a) for a, b in links(arm, np.asarray(q))])
    return float(np.min(point_distance(pts, v)))


def test_every_motion_is_checked_before_a_step_is_sent(client: TestClient, room: ControlRoom) -> None:
    arm = room.owned.dev
    before = arm.steps_simulated
    s = client.get("/api/state").json()
    assert s["rig"]["name"] == "bench" and s["rig"]["arm"] == "probe"
    q0 = [room.state().positions[j] for j in (1, 2, 3)]
    # joint 2 to -60 deg swings the tip up past the objective's lower edge: both ends are clear of its
    # 200 µm margin, the way between is not (the independent geometry says so)
    sweep = [clearance(room, [q0[0], math.radians(a), q0[2]], "objective") for a in np.linspace(-90, -60, 61)]
    assert sweep[0] > 200e-6 and sweep[-1] > 200e-6 and min(sweep) < 200e-6
    refused(client.post("/api/move", json={"joint": 2, "to": "-60deg"}), 409, "refused by the rig's envelope",
            "'objective'", "in the rig frame")
    refused(client.post("/api/reach", json={"by": ["0um", "0um", "8mm"]}), 409, "'objective'")
    refused(client.post("/api/traverse", json={"joint": 2, "direction": "+"}), 409, "traverse", "'objective'")
    refused(client.post("/api/day", json={}), 409, "of the day", "refused by the rig's envelope")
    refused(client.post("/api/step", json={"joint": 3, "steps": 10}), 409, "raw steps are refused with a rig")
    assert arm.steps_simulated == before  # nothing was sent
    events = [e["text"] for e in client.get("/api/events").json()["events"]]
    assert any("refused: refused by the rig's envelope" in t and "objective" in t for t in events), events


def test_the_rig_files_positions_and_the_saved_ones_are_one_set(client: TestClient, room: ControlRoom) -> None:
    r = client.post("/api/move", json={"joint": 3, "by": "200um"})  # a clear move runs
    assert wait(client, r.json()["id"])["status"] == "done"
    assert abs(room.state().positions[3] - 200e-6) < 0.6e-6
    assert client.post("/api/positions", json={"name": "here"}).status_code == 200
    listed = client.get("/api/positions").json()["positions"]
    assert [(p["name"], p["source"], p["order"]) for p in listed] == [("park", "rig", [3, 2]), ("here", "saved", None)]
    assert listed[0]["q"] == [None, pytest.approx(math.radians(-120)), 0.0]
    refused(client.post("/api/positions", json={"name": "park"}), 409, "rig file", "choose another name")
    refused(client.delete("/api/positions/park"), 409, "rig file")
    # park: joint 3 retracted first, then joint 2; the rig file's order
    r = client.post("/api/positions/park/go")
    m = wait(client, r.json()["id"])
    assert m["status"] == "done", m
    assert [x["joint"] for x in m["result"]["moves"]] == [3, 2]
    st = room.state()
    assert st.positions[2] == pytest.approx(math.radians(-120), abs=1e-4) and 0.0 <= st.positions[3] <= 0.5e-6
    # back to the saved one: joint 3 extends, so it moves last
    m = wait(client, client.post("/api/positions/here/go").json()["id"])
    assert m["status"] == "done" and [x["joint"] for x in m["result"]["moves"]] == [2, 3], m
    # a saved position inside the objective (recorded by hand) is refused, nothing sent
    room.where(pose=PoseUpdate(q2=math.radians(-60)))
    client.post("/api/positions", json={"name": "inside"})
    room.where(pose=PoseUpdate(q2=math.radians(-90)))
    before = room.owned.dev.steps_simulated
    refused(client.post("/api/positions/inside/go"), 409, "going to 'inside'", "'objective'")
    assert room.owned.dev.steps_simulated == before
    # the command line's `rig go` finds the saved ones too, with their safe order from the kept pose
    rig = room.options.rig
    assert rig is not None
    here = position_of(room.store, rig, "probe", "here")
    retracts = here.q[2] < room.state().positions[3]
    assert here.q[2] == pytest.approx(200e-6, abs=0.6e-6) and here.order == ((3, 1, 2) if retracts else (1, 2, 3))
    with pytest.raises(KeyError, match="no named position 'nowhere'.*saved for it: here, inside"):
        position_of(room.store, rig, "probe", "nowhere")


@pytest.mark.slow
def test_a_jog_stops_at_the_envelope_with_its_margin(tmp_path: Path) -> None:
    room = rig_room_on(tmp_path, lid="0.2mm", jog_idle_end_s=0.3)
    try:
        with TestClient(create_app(room, LOCAL), base_url="http://127.0.0.1:8765") as client:
            r = client.post("/api/jog", json={"direction": "+z", "speed": 7})
            assert r.status_code == 200, r.text
            ident = r.json()["motion"]

            seen: list[str] = []

            def stopped() -> bool:
                client.post("/api/jog", json={"direction": "+z", "speed": 7})  # the key stays held
                jog = client.get("/api/state").json()["jog"]
                seen.append(str(jog["message"]) if jog else "")
                return "envelope" in seen[-1]

            until(stopped, 20, "the jog to stop at the lid")
            assert seen[-1] == "stopped at the rig's envelope (lid): move another way"
            client.post("/api/jog/release", params={"end": True})
            assert wait(client, ident)["status"] == "done"
            q = [room.state().positions[j] for j in (1, 2, 3)]
            # the lid is 200 µm above the tip's start; the tip stopped outside its margin (10 µm and 3 σ), and
            # within one tick of it (the σ after 100-odd steps of joint 2 is a few µm at most)
            gap = clearance(room, q, "lid")
            assert 10e-6 < gap < 60e-6, gap
    finally:
        room.close()


def test_serve_takes_a_rig_and_checks_its_options(tmp_path: Path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text("[[arm]]\nname = 'a'\ncontroller = 'sim://'\n", encoding="utf-8")
    runner = CliRunner()
    r = runner.invoke(app, ["serve", "--rig", str(rig), "--arm", "nobody"])
    assert r.exit_code == 2 and "no arm named 'nobody'" in r.output
    r = runner.invoke(app, ["serve", "--rig", str(rig), "-d", "sim://"])
    assert r.exit_code == 2 and "not both" in r.output
    r = runner.invoke(app, ["serve", "--arm", "a"])
    assert r.exit_code == 2 and "--rig" in r.output
    stage = tmp_path / "stage.toml"
    stage.write_text("[[arm]]\nname = 's'\nkind = 'xyz'\ncontroller = 'sim://'\n"
                     + "[[arm.joint]]\nrange = ['-1mm', '1mm']\n" * 3, encoding="utf-8")
    r = runner.invoke(app, ["serve", "--rig", str(stage)])
    assert r.exit_code == 2 and "arm 's' is a stage (xyz)" in r.output, r.output


@pytest.mark.parametrize("lid, words", [("30mm", None), ("-1mm", "enters 'lid'"), ("5um", "'lid'")])
def test_serve_says_at_start_that_the_arm_stands_outside_its_envelope(tmp_path: Path, lid: str,
                                                                     words: str | None) -> None:
    """The arm inside a volume (the lid below the tip) or a margin (the lid 5 µm above it, 10 µm kept): the server
    started with no word of it, every motion then refused; now a line at start says so, as rig check does."""
    from stickslip.server.run import envelope_problem

    room = rig_room_on(tmp_path, lid=lid)
    try:
        problem = envelope_problem(room)
        if words is None:
            assert problem is None
        else:
            assert problem is not None and words in problem and "arm 'probe'" in problem and "\n" not in problem
    finally:
        room.close()


def test_a_move_is_refused_while_another_arm_of_the_rig_is_in_flight(client: TestClient, room: ControlRoom) -> None:
    # audit46: two servers of one rig each checked their move against the other arm's confirmed pose while
    # that arm moved, and both tips ended at (0, 0, 0). The other arm's journal says where it may be.
    from stickslip.devices.positions import load_state, save_state

    rig = room.options.rig
    assert rig is not None
    key, specs = rig.state_key("other"), rig.arm("other").joint_specs()
    arm = room.owned.dev
    before = arm.steps_simulated
    other = load_state(room.store, key, specs)
    assert other.positions[3] == 0.0  # its tip at (+9, 0, 0) mm: 18 mm from the probe's, 10 mm after the move
    other.intend(3, 9e-3)  # its server's write-ahead mark: joint 3 in flight toward 9 mm (its tip to (0, 0, 0))
    save_state(room.store, other)
    refused(client.post("/api/move", json={"joint": 3, "by": "8mm"}), 409, "refused by the rig's envelope",
            "arm 'other' may be anywhere", "between 0 µm and 9000 µm")
    assert arm.steps_simulated == before  # nothing was sent
    other.set_position(3, 9e-3, "dead-reckoned")  # its move ended there: the probe's move is checked against it
    save_state(room.store, other)
    refused(client.post("/api/move", json={"joint": 3, "by": "8mm"}), 409, "kept around 'arm other'")
    other.set_position(3, 0.0, "dead-reckoned")  # back: 10 mm apart after the move, accepted
    save_state(room.store, other)
    r = client.post("/api/move", json={"joint": 3, "by": "8mm"})
    assert r.status_code == 202, r.text
    assert wait(client, r.json()["id"])["status"] == "done"


def test_a_request_naming_an_arm_in_its_query_is_refused(client: TestClient, room: ControlRoom) -> None:
    # audit46: POST /api/move?arm=gripper to the probe's server moved the probe (the query was ignored)
    arm = room.owned.dev
    before = arm.steps_simulated
    refused(client.post("/api/move", params={"arm": "other"}, json={"joint": 3, "by": "1um"}), 422,
            "arm: this request takes no query parameter 'arm'", "serves one arm, 'probe'")
    refused(client.get("/api/where", params={"arm": "Probe"}), 422, "'arm'")
    refused(client.get("/api/motions/1", params={"wait": 0, "arm": "other"}), 422, "(it takes wait)")
    assert arm.steps_simulated == before  # nothing was sent
    assert client.post("/api/stop", params={"press": "p1"}).status_code == 200  # the declared ones still work
    assert client.get("/api/events", params={"after": 0}).status_code == 200
    assert client.get("/", params={"x": 1}).status_code == 200  # the page is not the API


def test_stop_on_one_arms_server_stops_every_arm_of_the_rig(tmp_path: Path) -> None:
    # audit46 (design question 3): STOP on the probe's page left the other arm's move running to its end. The
    # two servers of one rig share only the store: a STOP on either is read by the other before its next burst.
    from stickslip.devices.positions import load_state

    room = rig_room_on(tmp_path, url="sim://?realtime=1&speed=2")  # moves of a few mm take seconds at 2x
    other = rig_room_on(tmp_path, arm="other", url="sim://?seed=2&realtime=1&speed=2")
    try:
        with TestClient(create_app(other, LOCAL), base_url="http://127.0.0.1:8766") as theirs, \
                TestClient(create_app(room, LOCAL), base_url="http://127.0.0.1:8765") as mine:
            sim = other.owned.dev
            r = theirs.post("/api/move", json={"joint": 3, "by": "3mm"})  # tips 15 mm apart after it
            assert r.status_code == 202, r.text
            until(lambda: sim.steps_simulated > 0, what="the other arm moving")
            assert mine.post("/api/stop", params={"press": "p1"}).json()["stopped"] is None  # the probe was idle
            m = wait(theirs, r.json()["id"])
            assert m["status"] == "stopped", m
            assert "stopped by the rig's STOP (pressed for arm 'probe'" in m["error"] and "\n" not in m["error"]
            made = sim.steps_simulated
            kept = load_state(room.store, room.options.rig.state_key("other"))  # type: ignore[union-attr]
            assert not kept.uncertain and not kept.claim and 0.0 < kept.positions[3] < 3e-3  # exact, part-way
            assert abs(kept.positions[3] - sim.position(3)) < 2e-6
            texts = [e["text"] for e in theirs.get("/api/events").json()["events"]]
            assert any("stopped by the rig's STOP" in t for t in texts), texts
            texts = [e["text"] for e in mine.get("/api/events").json()["events"]]
            assert "STOP sent to every arm of rig 'bench'" in texts, texts
            # a move begun after the press is not stopped by it; the same press said again is not sent again
            assert mine.post("/api/stop", params={"press": "p1"}).status_code == 200
            r = theirs.post("/api/move", json={"joint": 3, "by": "10um"})
            assert r.status_code == 202, r.text
            assert wait(theirs, r.json()["id"])["status"] == "done"
            assert sim.steps_simulated > made
            # and the other way round: the other arm's STOP ends the probe's move
            before = room.owned.dev.steps_simulated
            r = mine.post("/api/move", json={"joint": 3, "by": "3mm"})
            assert r.status_code == 202, r.text
            until(lambda: room.owned.dev.steps_simulated > before, what="the probe moving")
            theirs.post("/api/stop")
            m = wait(mine, r.json()["id"])
            assert m["status"] == "stopped" and "pressed for arm 'other'" in m["error"], m
        other.close()  # closing a server stops its own arm only: no rig STOP pressed
        from stickslip.procedures.rigstop import pressed

        assert pressed(room.store, room.options.rig)["count"] == 2  # type: ignore[arg-type]
    finally:
        other.close()
        room.close()
