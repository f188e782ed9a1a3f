"""NanoControl driver against exact command transcripts (no hardware, no emulator).

The transcripts follow the command set in stickslip.devices.nanocontrol's docstring:
`;`-terminated commands, one `<status>\\t<message>\\r` answer each.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.devices.base import DeviceError, open_device
from stickslip.devices.nanocontrol import MAX_COARSE, NanoControl
from stickslip.devices.transport import FakeTransport, TranscriptError

VERSION = ("version;", "o\tNanoControl 3.1\r")


def nc(
    transcript: list[tuple[str | bytes | None, str | bytes | None]], **kw: Any
) -> tuple[FakeTransport, NanoControl]:
    t = FakeTransport([VERSION, *transcript], name="/dev/fake")
    return t, NanoControl(t, timeout=kw.pop("timeout", 0.05), **kw)


def test_open_asks_version_and_reports_it() -> None:
    t, dev = nc([])
    with t:
        assert dev.version == "NanoControl 3.1"
        assert dev.info.model == "Kleindiek NanoControl (NanoControl 3.1)"
        assert dev.info.joints == (1, 2, 3)


def test_step_sends_signed_coarse_on_mapped_channel() -> None:
    t, dev = nc([("coarse C +1200;", "o\t\r"), ("coarse A -35;", "o\t\r")])
    with t:
        dev.step(3, 1200)
        dev.step(1, -35)


def test_custom_channel_map() -> None:
    t, dev = nc([("coarse A +5;", "o\t\r")], channels={1: "C", 2: "B", 3: "A"})
    with t:
        dev.step(3, 5)


def test_long_burst_is_split_at_max_coarse() -> None:
    n = MAX_COARSE + 10
    t, dev = nc([(f"coarse B -{MAX_COARSE};", "o\t\r"), ("coarse B -10;", "o\t\r")], nominal_hz=1e7)
    with t:
        dev.step(2, -n)


def test_zero_steps_sends_nothing() -> None:
    t, dev = nc([])
    with t:
        dev.step(1, 0)


def test_settings_commands_and_ranges() -> None:
    t, dev = nc(
        [
            ("speed A 13;", "o\t\r"),
            ("amplitudepos B 80;", "o\t\r"),
            ("amplitudeneg B 1;", "o\t\r"),
            ("pause 250;", "o\t\r"),
            ("counterreset;", "o\t\r"),
            ("counterread;", "o\t120 -3 7 0\r"),
        ]
    )
    with t:
        dev.set_speed(1, 13)
        assert dev.frequency(1) == 3000.0  # SPEED_HZ[13]
        dev.set_amplitude(2, positive=80, negative=1)
        dev.pause(250)
        dev.reset_counters()
        assert dev.counters() == {1: 120, 2: -3, 3: 7}
        s: dict[str, Any] = dev.settings()
        assert s["speed_level"]["1"] == 13 and s["amplitude_neg"]["2"] == 1


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda d: d.set_amplitude(1, positive=81), r"1\.\.80"),
        (lambda d: d.set_amplitude(1, negative=0), r"1\.\.80"),
        (lambda d: d.set_amplitude(1, positive=40.5), r"integer"),
        (lambda d: d.set_speed(1, 16), r"1\.\.15"),
        (lambda d: d.set_speed(1, 0), r"1\.\.15"),
        (lambda d: d.set_frequency(1, 1234.0), r"one of .*1000.* Hz"),
        (lambda d: d.pause(0), r"1\.\.65535"),
        (lambda d: d.step(4, 10), r"joint must be one of \[1, 2, 3\]"),
        (lambda d: d.step(1, 2.5), r"integer"),
    ],
)
def test_out_of_range_settings_raise_and_send_nothing(call: Callable[[NanoControl], None], match: str) -> None:
    t, dev = nc([])
    with t:  # FakeTransport fails on any message: nothing may be sent
        with pytest.raises(ValueError, match=match):
            call(dev)


def test_set_frequency_picks_the_speed_level() -> None:
    t, dev = nc([("speed C 10;", "o\t\r")])
    with t:
        dev.set_frequency(3, 1000.0)
        levels: Any = dev.settings()["speed_level"]
        assert levels["3"] == 10


def test_info_lines_are_logged_and_skipped(caplog: pytest.LogCaptureFixture) -> None:
    t, dev = nc([("coarse A +10;", "i\tPiezo voltage breakdown\ro\t\r")])
    with t, caplog.at_level(logging.DEBUG, logger="stickslip.devices.nanocontrol"):
        dev.step(1, 10)
    msgs = [r.getMessage() for r in caplog.records]
    assert "-> coarse A +10;" in msgs
    assert any("Piezo voltage breakdown" in m for m in msgs)


def test_crlf_replies_and_plain_lines_are_accepted() -> None:
    t, dev = nc([("coarse A +10;", "ok\r\n"), ("counterread;", "1 2 3\r\n")])
    with t:
        dev.step(1, 10)
        assert dev.counters() == {1: 1, 2: 2, 3: 3}


def test_error_reply_raises_device_error_and_stops() -> None:
    t, dev = nc([("coarse A +10;", "e\tchannel not connected\r"), ("stop;", "o\t\r")])
    with t:
        with pytest.raises(DeviceError, match="refused 'coarse A \\+10;': channel not connected"):
            dev.step(1, 10)


def test_garbage_reply_raises_and_stops() -> None:
    t, dev = nc([("coarse B -10;", b"\x00\xff\x13\r"), ("stop;", "o\t\r")])
    with t:
        with pytest.raises(DeviceError, match="garbage reply"):
            dev.step(2, -10)


def test_no_answer_times_out_within_timeout_and_stops() -> None:
    # reply None = the device stays silent
    t, dev = nc([("coarse A +10;", None), ("stop;", None)], nominal_hz=1e6, timeout=0.2)
    with t:
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match=r"did not answer 'coarse A \+10;'.*within 0\.2"):
            dev.step(1, 10)
        elapsed = time.monotonic() - t0
    assert elapsed < 0.2 + 0.2 + 0.3  # reply timeout + stop's short wait + slack


def test_fake_transport_fails_on_unexpected_and_leftover_messages() -> None:
    t = FakeTransport([("version;", "o\tx\r"), ("coarse A +1;", "o\t\r")])
    dev = NanoControl(t, timeout=0.05)
    with pytest.raises(TranscriptError, match="left over"):
        t.assert_done()
    with pytest.raises(TranscriptError, match="expected b'coarse A \\+1;'"):
        dev.step(1, 2)


def test_ack_off_sends_without_waiting_for_replies() -> None:
    t = FakeTransport([("coarse A +5;", None)])
    dev = NanoControl(t, timeout=0.05, ack=False, nominal_hz=1e5)
    with t:
        dev.step(1, 5)


def test_unplugged_port_names_the_port() -> None:
    with pytest.raises(DeviceError, match="/dev/ttyNOPE"):
        open_device("mm3a:///dev/ttyNOPE?timeout=0.1")


def test_bad_url_options() -> None:
    with pytest.raises(ValueError, match="unknown option"):
        open_device("mm3a:///dev/ttyUSB0?sped=3")
    with pytest.raises(ValueError, match="channel of joint 2"):
        open_device("mm3a:///dev/ttyUSB0?channels=AXC")


class _AutoAck(FakeTransport):
    """Answers every `;`-terminated command with "o\\t\\r" and records it."""

    def __init__(self) -> None:
        super().__init__([], name="auto")
        self.commands: list[str] = []

    def _send(self, data: bytes) -> None:
        for part in data.decode().split(";")[:-1]:
            self.commands.append(part)
            self._buffer += b"o\tNC\r" if part == "version" else b"o\t\r"


@given(n=st.integers(-3 * MAX_COARSE - 5, 3 * MAX_COARSE + 5), joint=st.sampled_from([1, 2, 3]))
@settings(max_examples=60, deadline=None)
def test_any_step_count_is_sent_as_well_formed_bursts_summing_to_it(n: int, joint: int) -> None:
    t = _AutoAck()
    dev = NanoControl(t, timeout=0.05, nominal_hz=1e9)
    dev.step(joint, n)
    coarse = t.commands[1:]
    ch = "ABC"[joint - 1]
    assert all(re.fullmatch(rf"coarse {ch} [+-][1-9]\d*", c) for c in coarse)
    counts = [int(c.split()[2]) for c in coarse]
    assert sum(counts) == n
    assert all(0 < abs(k) <= MAX_COARSE for k in counts)
    assert len(counts) == -(-abs(n) // MAX_COARSE)  # the fewest bursts


def test_a_stop_from_another_thread_during_a_coarse_leaves_it_uncertain_and_sends_no_further_burst() -> None:
    # audit60's question 5: stop() read the line (read_available) while the stepping thread waited for the coarse's
    # answer, and took it: the step still waited after 10 s (its wait is 5 s + 1.5 x the burst's 65.5 s). And a stop
    # ended only the chunk under way of a long step. A console that cuts the burst short at 40 000 steps of 65535
    import threading

    from held_console import HeldConsole

    from stickslip.devices.base import StepsUncertain

    t = HeldConsole([VERSION, ("coarse C +65535;", None), ("stop;", "o\t\ro\t\r"),
                     ("counterread;", "o\t0 0 40000 0\r")], name="/dev/fake")
    dev = NanoControl(t, timeout=5.0)
    outcome: list[object] = []

    def stepping() -> None:
        try:
            dev.step(3, 100000)  # two chunks: 65535 and 34465
            outcome.append(100000)
        except Exception as e:  # noqa: BLE001
            outcome.append(e)

    worker = threading.Thread(target=stepping, daemon=True)
    worker.start()
    assert t.held_sent.wait(5.0)
    dev.stop()  # from this thread, while the worker waits for the coarse's answer
    worker.join(10.0)
    assert not worker.is_alive()
    (result,) = outcome
    assert isinstance(result, StepsUncertain), result
    assert (result.made, result.at_most) == (0, 65535)  # the true 40 000 inside; the second chunk never sent
    assert dev.counters()[3] == 40000  # the next command reads its own answer
    assert t.expected == []
