"""The SmarAct MCS and MCS2 drivers: URLs, byte-exact transcripts, fuzzed answers, honest timeouts.

Transcripts are replayed by FakeTransport (a message that differs from the next expected
one fails at once; one left unsent fails on leaving the ``with``). The commands and
answers are those of docs/devices/smaract.md. Time is a fake clock that sleeping
advances, so the status polls of a burst are exact: the first at the burst's duration
``d = |n| / f`` after it started, then every 10 ms, the last before ``1.5 d + timeout``.
"""

from __future__ import annotations

import logging
import re
import socket
import threading
import time
from collections.abc import Callable

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from stickslip.devices import open_device
from stickslip.devices.base import DeviceError, StepsUncertain, device_key
from stickslip.devices.smaract import SmarActMCS, SmarActMCS2, parse_channels
from stickslip.devices.smaract._common import POLL_S
from stickslip.devices.smaract.mcs import ERRORS
from stickslip.devices.transport import FakeTransport, Transport

MCS_OPEN = [(":SCM0\n", ":E-1,0\n"), (":GNC\n", ":N3\n"), (":GSI\n", ":ID4242\n"), (":GIV\n", ":IV1,0,9\n")]
MCS2_OPEN = [(":SYST:ERR:COUN?\r\n", "0\r\n"), (":DEV:NOCH?\r\n", "6\r\n"), (":DEV:SNUM?\r\n", "MCS2-123\r\n")]


class FakeClock:
    """Monotonic time that only sleeping advances."""

    def __init__(self) -> None:
        self.t = 100.0
        self.slept: list[float] = []

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        assert s >= 0
        self.slept.append(s)
        self.t += s


def mcs(transcript: list[tuple[str | None, str | bytes | None]], clock: FakeClock | None = None, **kw: object) -> tuple[
    SmarActMCS, FakeTransport
]:
    t = FakeTransport(MCS_OPEN + transcript)
    c = clock or FakeClock()
    return SmarActMCS(t, clock=c, sleep=c.sleep, **kw), t  # type: ignore[arg-type]


def mcs2(transcript: list[tuple[str | None, str | None]], clock: FakeClock | None = None, **kw: object) -> tuple[
    SmarActMCS2, FakeTransport
]:
    t = FakeTransport(MCS2_OPEN + transcript)
    c = clock or FakeClock()
    return SmarActMCS2(t, clock=c, sleep=c.sleep, **kw), t  # type: ignore[arg-type]


# -- URLs ---------------------------------------------------------------------------------


@pytest.mark.parametrize("url, words", [
    ("smaract-mcs:///dev/nonexistent?speed=3", r"unknown option\(s\) \['speed'\]"),
    ("smaract-mcs:///dev/nonexistent?hz=18501", r"hz must be an integer in 1\.\.18500 Hz, got '18501'"),
    ("smaract-mcs:///dev/nonexistent?hz=1000.5", r"1\.\.18500 Hz"),
    ("smaract-mcs2://127.0.0.1:9?hz=20001", r"1\.\.20000 Hz"),
    ("smaract-mcs:///dev/nonexistent?amplitude=0", r"amplitude must be an integer in 1\.\.4095"),
    ("smaract-mcs2://127.0.0.1:9?amplitude=65536", r"1\.\.65535"),
    ("smaract-mcs:///dev/nonexistent?timeout=0", r"timeout must be a number in 0\.001\.\.3600 s"),
    ("smaract-mcs:///dev/nonexistent?timeout=nan", r"timeout must be"),
    ("smaract-mcs:///dev/nonexistent?baud=300", r"baud must be an integer in 9600\.\.115200"),
    ("smaract-mcs+socket://127.0.0.1:9?baud=9600", r"baud is an option of a serial port"),
    ("smaract-mcs:///dev/nonexistent?channels=0,0", r"two joints share a channel"),
    ("smaract-mcs:///dev/nonexistent?channels=0,x", r"channel of joint 2 must be a channel number"),
    ("smaract-mcs:///dev/nonexistent?channels=--1", r"channel of joint 1"),
    ("smaract-mcs:///dev/nonexistent?channels=0,,1", r"comma-separated"),
    ("smaract-mcs:///dev/nonexistent?channels=300", r"0\.\.255"),
    ("smaract-mcs2://127.0.0.1:9/extra", r"give the host"),
    ("smaract-mcs2://127.0.0.1:99999", r"Port out of range|port"),
    ("smaract-mcs://", r"give the serial port"),
])
def test_a_bad_url_is_refused_before_anything_is_opened(url: str, words: str) -> None:
    with pytest.raises(ValueError, match=words) as e:
        open_device(url)
    assert "\n" not in str(e.value)


def test_a_password_is_refused_and_never_shown() -> None:
    for url in ("smaract-mcs2://admin:hunter2@127.0.0.1", "smaract-mcs2://127.0.0.1?password=hunter2"):
        with pytest.raises(ValueError) as e:
            open_device(url)
        assert "hunter2" not in str(e.value)
    assert device_key("smaract-mcs2://192.168.1.2:55551?channels=0,-1,2&hz=10") == "smaract-mcs2://192.168.1.2:55551"


@given(st.lists(st.tuples(st.integers(0, 255), st.booleans()), min_size=1, max_size=8,
                unique_by=lambda e: e[0]))
def test_a_channel_map_round_trips_through_its_text(entries: list[tuple[int, bool]]) -> None:
    text = ",".join(("-" if neg else "") + str(c) for c, neg in entries)
    cmap = parse_channels(text)
    assert cmap.channels == {j: (c, -1 if neg else 1) for j, (c, neg) in enumerate(entries, start=1)}
    assert ",".join(cmap.text().values()) == text
    assert parse_channels("+0, 1").channels == {1: (0, 1), 2: (1, 1)}


# -- MCS transcripts ----------------------------------------------------------------------


def test_mcs_opens_steps_and_reports_with_exact_messages() -> None:
    clock = FakeClock()
    dev, t = mcs([(":GS2\n", ":S2,0\n"), (":MST2,100,4095,1000\n", ":E2,0\n"), (":GS2\n", ":S2,1\n"),
                  (":GS2\n", ":S2,0\n")], clock)
    with t:
        dev.step(3, 100)
    # the first question after the burst's duration (0.1 s, in 50 ms slices), then 10 ms later
    assert clock.slept == pytest.approx([0.05, 0.05, POLL_S], abs=1e-12)
    info = dev.info
    assert info.model == "SmarAct MCS (system id 4242)" and info.extra["version"] == "1.0.9"
    assert info.joints == (1, 2, 3) and info.extra["frequency_hz"] == {"ch0": 1000.0, "ch1": 1000.0, "ch2": 1000.0}
    s = dev.settings()
    assert s["amplitude_v"] == {"1": 100.0, "2": 100.0, "3": 100.0}
    assert s["protocol"] == "MCS ASCII" and s["system_id"] == "4242"


def test_mcs_reversed_channel_long_burst_split_and_zero_sends_nothing() -> None:
    transcript: list[tuple[str | None, str | None]] = []
    for k in (29999, 29999, 5002):  # 65000 steps of joint 1, reversed on channel 0
        transcript += [(":GS0\n", ":S0,0\n"), (f":MST0,{-k},2000,18500\n", ":E0,0\n"), (":GS0\n", ":S0,0\n")]
    dev, t = mcs(transcript, channels=parse_channels("-0,1,2"), hz=18500, amplitude=2000)
    with t:
        dev.step(1, 0)
        dev.step(1, 65000)


def test_mcs_settings_change_the_next_burst_and_bad_ones_send_nothing() -> None:
    # holding counts as stopped
    dev, t = mcs([(":GS1\n", ":S1,0\n"), (":MST1,-7,1,1\n", ":E-1,0\n"), (":GS1\n", ":S1,3\n")])
    with t:
        for call, words in [(lambda: dev.set_frequency(2, 18501), r"1\.\.18500 Hz"),
                            (lambda: dev.set_frequency(2, 0.5), r"1\.\.18500 Hz"),
                            (lambda: dev.set_amplitude(2, 0), r"1\.\.4095"),
                            (lambda: dev.set_amplitude(2, 4096), r"1\.\.4095"),
                            (lambda: dev.set_frequency(4, 100), r"joint must be one of \[1, 2, 3\]"),
                            (lambda: dev.step(2, 2.5), r"step count must be an integer")]:
            with pytest.raises(ValueError, match=words):
                call()
        dev.set_frequency(2, 1)
        dev.set_amplitude(2, 1)
        dev.step(2, -7)
    assert dev.frequency(2) == 1.0 and dev.amplitude(2) == 1


def test_mcs_refused_burst_is_certain_nothing_and_sends_no_stop() -> None:
    dev, t = mcs([(":GS2\n", ":S2,0\n"), (":MST2,29999,4095,1000\n", ":E2,0\n"), (":GS2\n", ":S2,0\n"),
                  (":GS2\n", ":S2,0\n"), (":MST2,1,4095,1000\n", ":E2,142\n")], hz=1000)
    with t, pytest.raises(StepsUncertain) as e:
        dev.step(3, 30000)
    assert (e.value.made, e.value.at_most) == (29999, 29999)
    assert "refused 'MST2,1,4095,1000': error 142 (end stop reached) on channel 2" in str(e.value)


@pytest.mark.parametrize("reply, words", [
    (None, "did not answer 'MST2,100,4095,1000'"),
    (":E2,0", "did not answer"),  # no line end: a cut line
    (b"\x00\xff:E2,0\n", "garbage reply"),
    (":N3\n", "unexpected reply ':N3'"),
    (":E1,0\n", "unexpected reply ':E1,0'"),
    (":E2,abc\n", "garbage reply"),
])
def test_mcs_unanswered_or_garbled_start_is_bounded_and_stopped(reply: str | bytes | None, words: str) -> None:
    dev, t = mcs([(":GS2\n", ":S2,0\n"), (":MST2,100,4095,1000\n", reply), (":S2\n", ":E2,0\n")], timeout=0.02)
    with t, pytest.raises(StepsUncertain) as e:
        dev.step(3, 100)
    assert (e.value.made, e.value.at_most) == (0, 100)
    assert words in str(e.value) and "channel 2 was sent a stop, acknowledged" in str(e.value)
    assert "\n" not in str(e.value)
    dev.close()  # the stop was acknowledged: closing sends nothing more


@pytest.mark.parametrize("status, words", [(1, "stepping"), (6, "calibrating"), (7, "finding the reference mark")])
def test_mcs_channel_already_moving_gets_no_burst(status: int, words: str) -> None:
    # another program drives the channel (a :MST would take it over): nothing sent, bounded by its end stop (audit57)
    dev, t = mcs([(":GS2\n", f":S2,{status}\n")])
    with t, pytest.raises(StepsUncertain, match=f"channel 2 is already moving \\(status {status}: {words}\\)") as e:
        dev.step(3, 10)
    assert (e.value.made, e.value.at_most) == (0, None)
    assert "another program may be driving it; nothing was sent of a burst of +10 steps" in str(e.value)


def test_mcs_locked_channel_ends_the_burst_early() -> None:
    dev, t = mcs([(":GS2\n", ":S2,0\n"), (":MST2,-100,4095,1000\n", ":E2,0\n"), (":GS2\n", ":S2,9\n")])
    with t, pytest.raises(StepsUncertain, match="locked") as e:
        dev.step(3, -100)
    assert (e.value.made, e.value.at_most) == (0, -100)


def test_ctrl_c_mid_burst_stops_the_channel_and_propagates() -> None:
    clock = FakeClock()
    dev, t = mcs([(":GS2\n", ":S2,0\n"), (":MST2,100,4095,1000\n", ":E2,0\n"), (":S2\n", ":E2,0\n")], clock)

    def sleep(s: float) -> None:
        raise KeyboardInterrupt

    dev._sleep = sleep
    with t, pytest.raises(KeyboardInterrupt):
        dev.step(3, 100)
    dev.close()  # the stop was acknowledged: nothing more is sent


def test_closing_after_an_unacknowledged_stop_stops_the_channel_again() -> None:
    dev, t = mcs([(":GS2\n", ":S2,0\n"), (":MST2,100,4095,1000\n", None), (":S2\n", None), (":S2\n", ":E2,0\n")],
                 timeout=0.01)
    with t:
        with pytest.raises(StepsUncertain, match="not acknowledged"):
            dev.step(3, 100)
        dev.close()


def test_mcs_stop_and_close() -> None:
    dev, t = mcs([(":S0\n", ":E0,0\n"), (":S1\n", ":E1,0\n"), (":S2\n", ":E2,0\n"), (":S1\n", ":E-1,146\n")])
    with t:
        dev.stop()
        dev.stop(2)  # refused: logged, never raised
        dev.stop(7)  # no such joint: logged
        dev.close()
        dev.close()
    assert t.closed


def test_mcs_with_too_few_channels_names_them() -> None:
    t = FakeTransport([(":SCM0\n", ":E-1,0\n"), (":GNC\n", ":N2\n")])
    with pytest.raises(DeviceError, match=r"has 2 channel\(s\) \(0\.\.1\); the URL's channels name \[2\]"):
        SmarActMCS(t)


# -- MCS2 transcripts ---------------------------------------------------------------------


def _burst2(ch: int, n: int, hz: int = 1000, ampl: int = 65535, state_before: str = "262144",
            state_after: str = "262144") -> list[tuple[str | None, str | None]]:
    return [
        (f":CHAN{ch}:STAT?\r\n", f"{state_before}\r\n"),
        (f":CHAN{ch}:MMOD 4\r\n", None),
        (f":CHAN{ch}:STEP:FREQ {hz}\r\n", None),
        (f":CHAN{ch}:STEP:AMPL {ampl}\r\n", None),
        (":SYST:ERR:COUN?\r\n", "0\r\n"),
        (f":MOVE{ch} {n}\r\n", None),
        (":SYST:ERR:COUN?\r\n", "0\r\n"),
        (f":CHAN{ch}:STAT?\r\n", f"{state_after}\r\n"),
    ]


def test_mcs2_opens_steps_and_reports_with_exact_messages(caplog: pytest.LogCaptureFixture) -> None:
    t = FakeTransport([(":SYST:ERR:COUN?\r\n", "2\r\n"), (":SYST:ERR?\r\n", '-113,"Undefined header"\r\n'),
                       (":SYST:ERR?\r\n", "34\n"), (":DEV:NOCH?\r\n", "6\r\n"), (":DEV:SNUM?\r\n", "S-9\r\n"),
                       *_burst2(5, -100, 2000, 1000)[:-1],
                       (":CHAN5:STAT?\r\n", "1\r\n"), (":CHAN5:STAT?\r\n", "0\r\n")])
    clock = FakeClock()
    with caplog.at_level(logging.WARNING, "stickslip.devices.smaract"), t:
        dev = SmarActMCS2(t, channels=parse_channels("4,-5"), hz=2000, amplitude=1000, clock=clock, sleep=clock.sleep)
        dev.step(2, 100)
    assert "errors left in the queue from before: [(-113, 'Undefined header'), (34, 'no text')]" in caplog.text
    assert clock.slept == pytest.approx([0.05, POLL_S], abs=1e-12)
    assert dev.info.model == "SmarAct MCS2 (serial S-9)" and dev.info.joints == (1, 2)
    assert dev.settings()["channels"] == {"1": "4", "2": "-5"}


def test_mcs2_splits_long_bursts() -> None:
    transcript = _burst2(0, 100000, 20000) + _burst2(0, 100000, 20000) + _burst2(0, 1, 20000)
    dev, t = mcs2(transcript, hz=20000)
    with t:
        dev.step(1, 200001)


@pytest.mark.parametrize("where", ["settings", "move"])
def test_mcs2_refused_setting_or_move_is_certain_nothing(where: str) -> None:
    burst = _burst2(2, 10)
    i = 4 if where == "settings" else 6
    burst = burst[:i] + [(":SYST:ERR:COUN?\r\n", "1\r\n"), (":SYST:ERR?\r\n", '259,"No sensor present"\r\n')]
    dev, t = mcs2(burst)
    with t, pytest.raises(StepsUncertain) as e:
        dev.step(3, 10)
    assert (e.value.made, e.value.at_most) == (0, 0)
    assert "error 259 (No sensor present)" in str(e.value)
    sent = "':CHAN2:MMOD 4; :CHAN2:STEP:FREQ 1000; :CHAN2:STEP:AMPL 65535'" if where == "settings" else "':MOVE2 10'"
    assert f"refused {sent}" in str(e.value)


def test_mcs2_channel_already_moving_gets_no_burst() -> None:
    # another program drives the channel: none of our steps made, the joint bounded only by its end stop (audit57)
    dev, t = mcs2(_burst2(2, 100000) + [(":CHAN2:STAT?\r\n", "1\r\n")])
    with t, pytest.raises(StepsUncertain, match="channel 2 is already moving") as e:
        dev.step(3, 100011)  # one burst of 100000 made, then the channel is found moving
    assert (e.value.made, e.value.at_most) == (100000, None)
    assert "nothing was sent of a burst of +11 steps on joint 3 (channel 2)" in str(e.value)


def test_mcs2_trouble_that_appears_during_a_burst_ends_it_early(caplog: pytest.LogCaptureFixture) -> None:
    # movement failed (0x800) appears: uncertain; end stop (0x100) set before and after: only a warning
    dev, t = mcs2(_burst2(2, 10, state_before="0", state_after=str(0x800 | 0x40000))
                  + _burst2(2, 10, state_before="256", state_after="256"))
    with t:
        failed = r"ended early: channel 2 reports movement failed \(state 0x40800\)"
        with pytest.raises(StepsUncertain, match=failed) as e:
            dev.step(3, 10)
        assert (e.value.made, e.value.at_most) == (0, 10)
        with caplog.at_level(logging.WARNING, "stickslip.devices.smaract"):
            dev.step(3, 10)
    assert "still reports end stop reached from before this burst" in caplog.text


@pytest.mark.parametrize("reply, words", [
    (None, "did not answer ':SYST:ERR:COUN?'"),
    ("x\r\n", "garbage reply 'x'"),
    ("1\r\n", "garbage reply"),  # a count, then the error itself unanswered... is a garbled error line
])
def test_mcs2_unanswered_error_count_after_move_is_bounded_and_stopped(reply: str | None, words: str) -> None:
    burst = _burst2(2, 10)[:6] + [(":SYST:ERR:COUN?\r\n", reply)]
    if reply == "1\r\n":
        burst += [(":SYST:ERR?\r\n", "\x07\r\n")]
    burst += [(":STOP2\r\n", None), (":SYST:ERR:COUN?\r\n", "0\r\n")]
    dev, t = mcs2(burst, timeout=0.02)
    with t, pytest.raises(StepsUncertain) as e:
        dev.step(3, 10)
    assert (e.value.made, e.value.at_most) == (0, 10)
    assert words in str(e.value) and "acknowledged" in str(e.value)


def test_mcs2_stop_during_a_burst_leaves_the_steps_uncertain() -> None:
    clock = FakeClock()
    dev, t = mcs2(_burst2(0, 5000, 1000)[:-1] + [(":STOP0\r\n", None), (":SYST:ERR:COUN?\r\n", "0\r\n"),
                                                  (":CHAN0:STAT?\r\n", "0\r\n")], clock)

    def sleep(s: float) -> None:  # stop() arrives (as from another thread) during the first slice of the wait
        if not clock.slept:
            dev.stop(1)
        clock.sleep(s)

    dev._sleep = sleep
    with t, pytest.raises(StepsUncertain, match="stopped part-way by stop") as e:
        dev.step(1, 5000)
    assert (e.value.made, e.value.at_most) == (0, 5000)
    assert clock.slept == [0.05]  # the 5 s wait ended as soon as stop() was called


# -- the deadline, fuzzed answers ---------------------------------------------------------


class Responder(Transport):
    """A device answering by a function of each message (``None``: no answer)."""

    def __init__(self, answer: Callable[[bytes], bytes | None], timeout: float = 0.02) -> None:
        super().__init__("fuzz", timeout)
        self.answer = answer
        self.sent: list[bytes] = []

    def _send(self, data: bytes) -> None:
        self.sent.append(data)
        reply = self.answer(data)
        if reply:
            self._buffer += reply

    def _recv(self, timeout: float) -> bytes:
        time.sleep(min(timeout, 0.001))
        return b""

    def _close(self) -> None:
        pass


def _mcs_answers(mst: bytes | None = b":E2,0\n", gs: bytes | None = b":S2,0\n") -> Callable[[bytes], bytes | None]:
    """Answers of an MCS: ``mst`` to a burst, ``gs`` to a status question after it (before it: stopped)."""
    fixed = {b":SCM0\n": b":E-1,0\n", b":GNC\n": b":N3\n", b":GSI\n": b":ID1\n", b":GIV\n": b":IV1,0,0\n",
             b":S2\n": b":E2,0\n"}
    started = {"mst": False}

    def answer(msg: bytes) -> bytes | None:
        if msg in fixed:
            return fixed[msg]
        if msg.startswith(b":MST"):
            started["mst"] = True
            return mst
        return gs if started["mst"] else b":S2,0\n"  # the channel is idle before the burst

    return answer


@pytest.mark.parametrize("timeout", [0.05, 0.5])
def test_a_burst_that_never_ends_is_stopped_at_its_deadline(timeout: float) -> None:
    clock = FakeClock()
    t = Responder(_mcs_answers(gs=b":S2,1\n"))
    dev = SmarActMCS(t, timeout=timeout, hz=1000, clock=clock, sleep=clock.sleep)
    t0 = clock()
    with pytest.raises(StepsUncertain, match=r"channel 2 still stepping .* should take 0\.200 s") as e:
        dev.step(3, 200)
    assert (e.value.made, e.value.at_most) == (0, 200)
    assert clock() - t0 == pytest.approx(1.5 * 0.2 + timeout, abs=POLL_S + 1e-9)  # 1.5 d + timeout
    assert t.sent[-1] == b":S2\n"


reply_bytes = st.one_of(
    st.binary(max_size=12),
    st.sampled_from([b":E2,0", b":E2,0\r\n", b" :E2,0 \n", b":E-1,0\n", b":E2,7\n", b":S2,0\n", b":E2\n", b":\n",
                     b"\n", b":E2,0\n:E2,0\n", b":e2,0\n"]),
    st.builds(lambda ch, code: b":E%d,%d\n" % (ch, code), st.sampled_from([2, -1, 0]), st.integers(-5, 300)),
)


@settings(max_examples=60, deadline=None)  # waits on real (short) timeouts
@given(reply_bytes)
@example(b":E0,1\n")  # another channel's error is not this burst's refusal: it may have started
def test_mcs_any_answer_to_a_burst_is_a_success_or_a_bounded_uncertainty(reply: bytes) -> None:
    t = Responder(_mcs_answers(mst=reply))
    dev = SmarActMCS(t, timeout=0.005, hz=18500)
    try:
        dev.step(3, 1)
    except StepsUncertain as e:
        assert e.made == 0 and e.at_most in (0, 1)
        assert "\n" not in str(e) and "SmarAct MCS on fuzz" in str(e)
        if e.at_most == 0:  # refused: a known error code from the channel or the system (-1), named
            code = int(re.match(rb"\s*:E(?:2|-1),(-?\d+)", reply).group(1))  # type: ignore[union-attr]
            assert f"error {code} ({ERRORS[code]})" in str(e)
    else:
        assert re.fullmatch(rb"\s*:E(2|-1),0\s*\n(.|\n)*", reply)


@settings(max_examples=60, deadline=None)  # waits on real (short) timeouts
@given(reply_bytes)
def test_mcs_any_status_answer_is_a_success_or_a_bounded_uncertainty(reply: bytes) -> None:
    t = Responder(_mcs_answers(gs=reply))
    dev = SmarActMCS(t, timeout=0.005, hz=18500)
    try:
        dev.step(3, -1)
    except StepsUncertain as e:
        assert (e.made, e.at_most) == (0, -1) and "\n" not in str(e)
    else:
        assert re.fullmatch(rb"\s*:S2,[03]\s*\n(.|\n)*", reply)


@settings(max_examples=60, deadline=None)  # waits on real (short) timeouts
@given(st.one_of(st.binary(max_size=10), st.sampled_from([b"0\r\n", b"0\n", b"00\r\n", b"+0\r\n", b"-1\r\n"])))
def test_mcs2_any_error_count_is_a_success_or_a_bounded_uncertainty(reply: bytes) -> None:
    opened = {"n": 0}

    def answer(msg: bytes) -> bytes | None:
        if msg == b":SYST:ERR:COUN?\r\n":
            opened["n"] += 1
            return b"0\r\n" if opened["n"] <= 2 else reply  # the opening's and the settings' checks pass
        return {b":DEV:NOCH?\r\n": b"3\r\n", b":DEV:SNUM?\r\n": b"x\r\n", b":CHAN2:STAT?\r\n": b"0\r\n",
                b":SYST:ERR?\r\n": b'5,"fuzz"\r\n'}.get(msg)

    dev = SmarActMCS2(Responder(answer), timeout=0.005, hz=20000)
    try:
        dev.step(3, 2)
    except StepsUncertain as e:
        assert e.made == 0 and e.at_most in (0, 2) and "\n" not in str(e)
    else:
        assert re.fullmatch(rb"\+?0+\r?\n(.|\n)*", reply)


# -- timeouts over real sockets -----------------------------------------------------------


class SilentServer:
    """A TCP server that accepts and reads, answers the first ``answers`` queries, then nothing."""

    def __init__(self, answers: list[bytes] | None = None) -> None:
        self.answers = list(answers or [])
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        self.server.settimeout(0.05)
        while not self.done.is_set():
            try:
                conn, _ = self.server.accept()
            except OSError:
                continue
            with conn:
                conn.settimeout(0.05)
                while not self.done.is_set():
                    try:
                        data = conn.recv(1024)
                    except OSError:
                        continue
                    if not data:
                        break
                    for _ in range(data.count(b"?")):
                        if self.answers:
                            conn.sendall(self.answers.pop(0))

    def __enter__(self) -> SilentServer:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.done.set()
        self.thread.join(2)
        self.server.close()


@pytest.mark.parametrize("timeout", [0.1, 0.4])
def test_the_url_timeout_bounds_opening_a_silent_controller(timeout: float) -> None:
    with SilentServer() as srv:
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match=rf"127\.0\.0\.1:{srv.port}.*within {timeout:g} s") as e:
            open_device(f"smaract-mcs2://127.0.0.1:{srv.port}?timeout={timeout}")
        elapsed = time.monotonic() - t0
    assert "\n" not in str(e.value)
    assert timeout <= elapsed < timeout + 1.0


def test_the_url_timeout_bounds_a_burst_on_a_controller_gone_silent() -> None:
    with SilentServer([b"0\r\n", b"3\r\n", b"SN\r\n", b"0\r\n", b"0\r\n"]) as srv:
        dev = open_device(f"smaract-mcs2://127.0.0.1:{srv.port}?timeout=0.2&hz=20000")
        t0 = time.monotonic()
        with pytest.raises(StepsUncertain, match="did not answer ':SYST:ERR:COUN" ) as e:
            dev.step(3, 20)
        elapsed = time.monotonic() - t0
        dev.close()
    assert (e.value.made, e.value.at_most) == (0, 20)
    assert 0.2 <= elapsed < 0.2 + 0.2 + 1.0  # the MOVE's error count, then the stop's: 0.2 s each


def test_a_controller_that_is_not_there_is_one_line_naming_it() -> None:
    s = socket.create_server(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(DeviceError, match=rf"cannot connect to 127\.0\.0\.1:{port}") as e:
        open_device(f"smaract-mcs2://127.0.0.1:{port}?timeout=0.5")
    assert "\n" not in str(e.value)
