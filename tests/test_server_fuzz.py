"""The API fuzzed from its own OpenAPI schema (schemathesis): no request makes a 500 or a traceback.

Schemathesis draws requests from every operation's schema (valid ones, and ones that
break it: wrong types, missing fields, strings where numbers go) with hypothesis,
derandomized like every property test here. Each answer must be below 500 and, when it
refuses, be one line of JSON ``{"error": ...}``. The room drives the simulator on its
virtual clock (moves end at once), with its true calibration, so valid moves, jogs and
positions really run.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.xdist_group("server_fuzz")  # one worker starts the fuzzed room once

pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")
schemathesis = pytest.importorskip("schemathesis", reason="schemathesis (the dev extra) is not installed")

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from server_support import room_on  # noqa: E402

from stickslip.server.app import create_app  # noqa: E402
from stickslip.server.live import command  # noqa: E402
from stickslip.server.room import ControlRoom  # noqa: E402
from stickslip.server.security import Access  # noqa: E402


@pytest.fixture(scope="module")
def fuzz_room(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlRoom]:
    room = room_on(tmp_path_factory.mktemp("fuzz"), "sim://?realtime=0", jog_idle_end_s=0.05)
    yield room
    room.close()


@pytest.fixture(scope="module")
def api_schema(fuzz_room: ControlRoom) -> Any:
    app = create_app(fuzz_room, Access(None, False))  # no host check: the fuzzer's client names no loopback host
    return schemathesis.openapi.from_asgi("/openapi.json", app)


OPERATIONS = [
    ("GET", "/api/state"), ("GET", "/api/where"), ("POST", "/api/where"), ("GET", "/api/events"),
    ("POST", "/api/move"), ("POST", "/api/step"), ("POST", "/api/reach"), ("POST", "/api/jog"),
    ("POST", "/api/jog/release"), ("POST", "/api/stop"), ("POST", "/api/observe"), ("POST", "/api/traverse"),
    ("GET", "/api/motions/{ident}"), ("GET", "/api/motion"), ("GET", "/api/positions"), ("POST", "/api/positions"),
    ("DELETE", "/api/positions/{name}"), ("POST", "/api/positions/{name}/go"), ("POST", "/api/day"),
    ("GET", "/api/day"), ("POST", "/api/day/pose-set"), ("GET", "/api/calibration"), ("GET", "/api/history"),
    ("GET", "/api/anova"), ("GET", "/api/camera"), ("GET", "/api/camera/frame"),
]
"""Every operation of the API (the schema must list exactly these: the last test)."""

EXAMPLES = 25
"""Requests drawn per operation (positive and negative together): 26 x 25 = 650 requests, about 15 s."""


@pytest.mark.parametrize(("method", "path"), OPERATIONS)
def test_no_request_makes_a_server_error(api_schema: Any, fuzz_room: ControlRoom, method: str, path: str) -> None:
    operation = api_schema[path][method]

    @given(operation.as_strategy())
    @settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
    def run(case: Any) -> None:
        response = case.call()
        assert response.status_code < 500, (case.method, case.formatted_path, case.body, response.text)
        if response.status_code >= 400:
            body = response.json()
            assert set(body) == {"error"}, body
            assert "\n" not in body["error"] and "Traceback" not in body["error"]
        fuzz_room.stop()  # whatever a request started ends before the next: every operation is tried idle

    run()


def test_the_schema_names_every_operation(api_schema: Any, tmp_path: Path) -> None:
    listed = {(m.upper(), p) for p, ops in api_schema.raw_schema["paths"].items() for m in ops}
    assert listed == set(OPERATIONS)


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)


@given(
    st.one_of(
        st.text(max_size=40),
        _JSON.map(json.dumps),
        st.fixed_dictionaries(
            {"type": st.sampled_from(["stop", "jog", "release", "ping", "auth", "x"])}, optional={
                "direction": st.sampled_from(["+x", "-z", "up", ""]) | st.text(max_size=4),
                "speed": st.integers(-3, 12) | st.text(max_size=3), "token": st.text(max_size=5),
            },
        ).map(json.dumps),
    )
)
@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
def test_no_socket_message_raises(fuzz_room: ControlRoom, text: str) -> None:
    reply = command(fuzz_room, text)
    assert isinstance(reply, dict)
    if "error" in reply:
        assert "\n" not in reply["error"] and "Traceback" not in reply["error"]
    json.dumps(reply)
    fuzz_room.stop()
