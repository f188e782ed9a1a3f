"""stickslip.client.Rig against a served room (uvicorn on a loopback port): the verbs, the errors, the live state."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")

from server_support import room_on, served, until  # noqa: E402

from stickslip.client import MotionFailed, Rig, RigError  # noqa: E402
from stickslip.server.app import create_app  # noqa: E402
from stickslip.server.room import ControlRoom  # noqa: E402
from stickslip.server.security import Access  # noqa: E402

TOKEN = "t" * 43


@pytest.fixture(scope="module")
def room(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlRoom]:
    r = room_on(tmp_path_factory.mktemp("client"), "sim://?realtime=1&speed=50", jog_idle_end_s=0.2)
    yield r
    r.close()


@pytest.fixture(scope="module")
def url(room: ControlRoom) -> Iterator[str]:
    with served(create_app(room, Access(TOKEN, False))) as base:
        yield base


@pytest.fixture()
def rig(url: str, room: ControlRoom) -> Iterator[Rig]:
    with Rig(url, token=TOKEN) as r:
        yield r
    until(lambda: room.current() is None, 20, "the motion to end")


def test_the_verbs_from_python(rig: Rig, room: ControlRoom) -> None:
    assert rig.where()["device"] == "sim://"
    m = rig.move(3, by="200um")
    assert m["status"] == "done" and m["result"]["joint"] == 3
    assert room.state().positions[3] == pytest.approx(200e-6, abs=0.6e-6)
    rig.save_position("p1")
    rig.move(3, to=0.0005)  # a number is SI: 500 µm
    assert room.state().positions[3] == pytest.approx(500e-6, abs=0.6e-6)
    rig.reach(by=("0um", "0um", "5um"))
    assert rig.go_to("p1")["status"] == "done"
    assert [p["name"] for p in rig.positions()] == ["p1"]
    rig.delete_position("p1")
    assert rig.positions() == []
    assert rig.state()["calibration"]["method"] == "paper"
    assert "joint 3" in rig.calibration()["report"]
    out = rig.jog("+x", 0.3, speed=6)
    assert out["kind"] == "jog" and out["status"] == "done" and any(out["result"]["sent"])
    o = rig.observe(3, room.state().positions[3], sd="1um")
    assert o["joint"] == 3


def test_refusals_and_failures_are_exceptions(rig: Rig, url: str, room: ControlRoom) -> None:
    with pytest.raises(RigError) as info:
        rig.move(3, by="30")
    assert info.value.status == 422 and "did you mean 30um" in str(info.value)
    with Rig(url) as anonymous, pytest.raises(RigError) as info:
        anonymous.where()
    assert info.value.status == 401
    m = rig.move(2, to="min", wait=False)
    assert m["status"] == "running"
    with pytest.raises(RigError) as busy:
        rig.move(3, by="1um")
    assert busy.value.status == 409
    threading.Timer(0.2, rig.stop).start()
    with pytest.raises(MotionFailed) as failed:
        rig.wait(m["id"])
    assert failed.value.motion["status"] == "stopped"
    with Rig("http://127.0.0.1:9") as nowhere, pytest.raises(RigError, match="127.0.0.1:9"):
        nowhere.state()


def test_the_live_state_in_order(rig: Rig) -> None:
    messages = list(rig.live(messages=5))
    seqs = [m["seq"] for m in messages]
    assert seqs == list(range(seqs[0], seqs[0] + 5))
    assert messages[-1]["state"]["device"] == "sim://"


@pytest.mark.slow
def test_a_day_over_the_api_stops_and_resumes(rig: Rig, room: ControlRoom, tmp_path: Path) -> None:
    start = rig.calibration_day()
    assert start["kind"] == "day" and start["status"] == "running"
    day = rig.day()["day"]
    assert day["total"] == 14 and len(day["plan"]) == 14
    until(lambda: (rig.day()["day"]["done"] or 0) >= 1, 60, "the first traverse of the day")
    rig.stop()
    with pytest.raises(MotionFailed) as stopped:
        rig.wait(start["id"])
    assert stopped.value.motion["status"] == "stopped"
    done = rig.day()["day"]["done"]
    assert done >= 1
    again = rig.calibration_day(resume=True)
    assert again["progress"]["index"] == done  # goes on from the next traverse
    rig.stop()
    with pytest.raises(MotionFailed):
        rig.wait(again["id"])
    assert rig.day()["day"]["result"] is None


@pytest.mark.slow  # a documentation example run whole (make test runs it; make test-fast leaves it)
def test_the_example_of_docs_serve_runs(url: str, room: ControlRoom) -> None:
    import re

    page = (Path(__file__).resolve().parents[1] / "docs" / "serve.md").read_text(encoding="utf-8")
    block = re.search(r"## From Python\n\n```python\n(.*?)```", page, re.S)
    assert block is not None
    code = block.group(1).replace('Rig("http://127.0.0.1:8765")', f'Rig("{url}", token="{TOKEN}")')
    until(lambda: room.current() is None, 20, "the room to be idle")
    room.where([(3, 2e-3)])  # joint 3 at 2 mm (an earlier test left it at a stop): room for the example's moves
    exec(compile(code, "docs/serve.md", "exec"), {"print": lambda *a: None})
    with Rig(url, token=TOKEN) as rig:
        assert "above the cell" in [p["name"] for p in rig.positions()]


def test_a_bad_argument_is_refused_by_name_before_anything_is_sent() -> None:
    """NaN, inf, a negative jog and numpy values: NaN said 'Out of range float values are not JSON compliant'
    (no argument named), jog(seconds=nan or -1) held the direction once and returned 'done', numpy.int64 and
    a 0-d array were 'not JSON serializable'. Port 9 (discard) has no server: nothing may be sent."""
    import numpy as np

    from stickslip.client import _plain

    with Rig("http://127.0.0.1:9") as rig:
        for call, line in [
            (lambda: rig.move(3, by=float("nan")), "by: nan is not a finite number"),
            (lambda: rig.move(3, to=float("-inf")), "to: -inf is not a finite number"),
            (lambda: rig.reach(by=(0.0, float("nan"), 0.0)), "by[1]: nan is not a finite number"),
            (lambda: rig.observe(3, 1e-4, sd=np.float64("inf")), "sd: inf is not a finite number"),
            (lambda: rig.jog("+z", seconds=float("nan")), "seconds: nan is not a finite number"),
            (lambda: rig.jog("+z", seconds=-1), "seconds: how long to hold the direction, 0 s or more, got -1"),
            (lambda: list(rig.live(messages=-1)), "messages: how many messages to take, 0 or more"),
        ]:
            with pytest.raises(ValueError) as e:
                call()
            assert str(e.value).startswith(line)
        with pytest.raises(TypeError, match=r"^by: a number or a string with its unit, got object"):
            rig.move(3, by=object())  # type: ignore[arg-type]
    body = {"joint": np.int64(3), "by": np.array(2e-6), "to": [np.float32(0.5), "1um"]}
    assert _plain("", body) == {"joint": 3, "by": 2e-6, "to": [0.5, "1um"]}
    assert type(_plain("", body)["joint"]) is int
