"""The console dialect against exact transcripts (pymeasure's expected_protocol style).

Every byte the driver sends and every answer is written out: CR-terminated commands,
`<status>\\t<message>\\r` answers, none to `stopnack`. Time is a fake clock advanced by
the driver's own sleep, so a burst's timing (and a Ctrl-C in the middle of it) is exact.
Reference values: T = ceil(1000 (N/f + margin + 2 timeout)) ms (the driver's rule in
stickslip.devices.nanocontrol.console); steps = count x |m| per go.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.devices.base import DeviceError, StepsUncertain, open_device
from stickslip.devices.nanocontrol import (
    MAX_BURST,
    NanoControl,
    NanoControlConsole,
    detect_dialect,
    split_burst,
)
from stickslip.devices.nanocontrol.console import parse_profile
from stickslip.devices.transport import FakeTransport, TranscriptError

TIMEOUT = 0.05
MARGIN = 0.05
OPEN = [("version\r", "o\tNanoControl 4.2\r"), ("speed ?\r", "o\t3 c016 c032 f008 c064\r")]


def T(steps: int, hz: int = 1000) -> int:
    """The go interval the driver must choose, ms."""
    return math.ceil(round(1000 * (steps / hz + MARGIN + 2 * TIMEOUT), 6))


class Clock:
    """A fake monotonic clock; ``sleep`` advances it (and may raise, as Ctrl-C would)."""

    def __init__(self, interrupt_after: int | None = None) -> None:
        self.t = 100.0
        self.slept = 0.0
        self.calls = 0
        self.interrupt_after = interrupt_after

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.calls += 1
        if self.interrupt_after is not None and self.calls > self.interrupt_after:
            raise KeyboardInterrupt
        self.t += dt
        self.slept += dt


Entry = tuple[str | bytes | None, str | bytes | None]


def console(
    transcript: Sequence[Entry], clock: Clock | None = None, **kw: Any
) -> tuple[FakeTransport, NanoControlConsole, Clock]:
    clock = clock or Clock()
    t = FakeTransport([*OPEN, *transcript], name="/dev/fake")
    dev = NanoControlConsole(t, timeout=TIMEOUT, margin=MARGIN, clock=clock, sleep=clock.sleep, **kw)
    return t, dev, clock


FREQ = ("frequency 1000 1000 1000 1000\r", "o\t\r")


def test_open_asks_version_and_the_active_profile_and_reports_them() -> None:
    t, dev, _ = console([])
    with t:
        info = dev.info
    assert info.model == "Kleindiek NanoControl (NanoControl 4.2), console dialect"
    assert info.extra["dialect"] == "console"
    assert info.extra["version"] == "NanoControl 4.2"
    assert info.extra["active_profile"] == 3
    assert info.extra["active_profile_values"] == ["c16", "c32", "f08", "c64"]
    assert info.extra["frequency_hz"] == dict.fromkeys("ABCD", 1000)
    assert info.extra["frequency_sent"] is False
    assert dev.settings()["scratch_profile"] == 6


def test_an_exact_burst_sets_frequency_writes_scratch_goes_stops_and_restores() -> None:
    t, dev, clock = console(
        [
            FREQ,
            ("speed 6 c01 c01 c50 c01\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            (f"go 0 0 20 0 {T(1000)}\r", "o\t\r"),
            ("stop\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
        ]
    )
    with t:
        dev.step(3, 1000)
        assert clock.slept == pytest.approx(1000 / 1000 + MARGIN, abs=1e-12)  # d + margin, then stop
        assert dev.info.extra["frequency_sent"] is True
        dev.close()  # nothing more to send: stopped and restored


def test_a_burst_that_does_not_factor_takes_two_gos_and_negative_steps_reverse() -> None:
    n = 1009  # prime: 64 x 15 + 49 x 1
    t, dev, clock = console(
        [
            FREQ,
            ("speed 6 c64 c01 c01 c01\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            (f"go -15 0 0 0 {T(960)}\r", "o\t\r"),
            ("stop\r", "o\t\r"),
            ("speed 6 c49 c01 c01 c01\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            (f"go -1 0 0 0 {T(49)}\r", "o\t\r"),
            ("stop\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
        ]
    )
    with t:
        dev.step(1, -n)
        assert clock.slept == pytest.approx(n / 1000 + 2 * MARGIN, abs=1e-12)


def test_frequency_and_channel_map_are_used_for_timing() -> None:
    t, dev, clock = console(
        [
            ("frequency 1000 1000 1000 20000\r", "o\t\r"),  # set_frequency
            ("frequency 1000 1000 1000 20000\r", "o\t\r"),  # step(): sent at every call
            ("speed 6 c01 c01 c01 c64\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            (f"go 0 0 0 100 {T(6400, 20000)}\r", "o\t\r"),
            ("stop\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
        ],
        channels={1: "A", 2: "B", 3: "D"},
    )
    with t:
        dev.set_frequency(3, 20000)
        dev.step(3, 6400)
        assert clock.slept == pytest.approx(6400 / 20000 + MARGIN, abs=1e-12)


def test_when_the_users_profile_is_the_scratch_one_its_values_are_written_back() -> None:
    t, dev, _ = console(
        [
            FREQ,
            ("speed 3 c16 c32 c05 c64\r", "o\t\r"),  # the fine f08 of channel C never drives
            ("speed 3\r", "o\t\r"),
            (f"go 0 0 1 0 {T(5)}\r", "o\t\r"),
            ("stop\r", "o\t\r"),
            ("speed 3 c16 c32 f08 c64\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
        ],
        profile=3,
    )
    with t:
        dev.step(3, 5)


def _burst(go_reply: str | bytes | None, *after: Entry) -> list[Entry]:
    return [
        FREQ,
        ("speed 6 c01 c01 c50 c01\r", "o\t\r"),
        ("speed 6\r", "o\t\r"),
        (f"go 0 0 20 0 {T(1000)}\r", go_reply),
        *after,
    ]


def test_an_error_answer_to_go_sends_stopnack_then_stop_and_names_command_and_port() -> None:
    t, dev, _ = console(
        _burst("e\tmotor driver fault\r", ("stopnack\r", None), ("stop\r", "o\t\r"), ("speed 3\r", "o\t\r"))
    )
    with t:
        with pytest.raises(StepsUncertain, match=r"/dev/fake refused 'go 0 0 20 0 \d+': motor driver fault") as e:
            dev.step(3, 1000)
    assert (e.value.made, e.value.at_most) == (0, 1000)  # acknowledged: at most this go's steps


@pytest.mark.parametrize("reply, words", [(None, "did not answer 'go"), (b"\x00\xff\r", "garbage reply")])
def test_silence_or_garbage_after_go_stops_and_leaves_the_bound_open_if_unacknowledged(
    reply: bytes | None, words: str
) -> None:
    t, dev, _ = console(
        _burst(reply, ("stopnack\r", None), ("stop\r", None), ("stopnack\r", None), ("stop\r", None))
    )
    with t:
        with pytest.raises(StepsUncertain, match=words) as e:
            dev.step(3, 1000)
        assert e.value.made == 0 and e.value.at_most is None  # may still be driving
        assert "may still be driving" in str(e.value) and "/dev/fake" in str(e.value)
        dev.close()  # closing tries again: stopnack, stop


def test_ctrl_c_mid_burst_sends_stopnack_at_once_then_stop_and_propagates() -> None:
    clock = Clock(interrupt_after=3)
    t, dev, _ = console(
        _burst("o\t\r", ("stopnack\r", None), ("stop\r", "o\t\r"), ("speed 3\r", "o\t\r")), clock=clock
    )
    with t:
        with pytest.raises(KeyboardInterrupt):
            dev.step(3, 1000)
        dev.close()  # stopped and restored: nothing to send


def test_ctrl_c_with_an_unanswered_stop_becomes_an_open_bound() -> None:
    clock = Clock(interrupt_after=0)
    t, dev, _ = console(
        _burst("o\t\r", ("stopnack\r", None), ("stop\r", None), ("stopnack\r", None), ("stop\r", "o\t\r"),
               # that answer may be the unanswered stop's: the stop is sent again on a re-synchronised line
               OPEN[0], ("stop\r", "o\t\r"), ("speed 3\r", "o\t\r")),
        clock=clock,
    )
    with t:
        with pytest.raises(StepsUncertain, match=r"interrupted \(Ctrl-C\).*not acknowledged") as e:
            dev.step(3, 1000)
        assert isinstance(e.value.__cause__, KeyboardInterrupt)
        assert (e.value.made, e.value.at_most) == (0, None)
        dev.close()  # stops again (now acknowledged) and restores the profile


class LateStop(FakeTransport):
    """The answer to `stop` comes `delay` s (fake clock) after it is sent."""

    def __init__(self, transcript: Sequence[Entry], clock: Clock, delay: float) -> None:
        super().__init__(transcript, name="/dev/fake")
        self.clock, self.delay = clock, delay

    def _send(self, data: bytes) -> None:
        if data == b"stop\r":
            self.clock.t += self.delay
        super()._send(data)


def test_a_late_stop_records_the_first_interval_and_bounds_the_rest() -> None:
    clock = Clock()
    t = LateStop([*OPEN, *_burst("o\t\r", ("stop\r", "o\t\r"), ("speed 3\r", "o\t\r"))], clock, delay=2.0)
    dev = NanoControlConsole(t, timeout=TIMEOUT, margin=MARGIN, clock=clock, sleep=clock.sleep)
    with t:
        with pytest.raises(StepsUncertain, match="up to 3 intervals") as e:
            dev.step(3, 1000)
    # stop answered d + margin + 2 s = 3.05 s after go; T = 1.15 s: ceil(3.05 / 1.15) = 3 intervals
    assert (e.value.made, e.value.at_most) == (1000, 3000)


def test_an_unanswered_stop_after_a_full_burst_keeps_its_steps_and_opens_the_bound() -> None:
    t, dev, _ = console(
        _burst("o\t\r", ("stop\r", None), ("stopnack\r", None), ("stop\r", None), ("stopnack\r", None),
               ("stop\r", None))
    )
    with t:
        with pytest.raises(StepsUncertain, match="did not answer 'stop'") as e:
            dev.step(3, 1000)
        assert (e.value.made, e.value.at_most) == (1000, None)
        dev.close()


class Unplugged(FakeTransport):
    """The cable is pulled as `go` is written: that write and every later one fail."""

    def __init__(self, transcript: Sequence[Entry]) -> None:
        super().__init__(transcript, name="/dev/fake")
        self.pulled = False

    def _send(self, data: bytes) -> None:
        if data.startswith(b"go") or self.pulled:
            self.pulled = True
            raise OSError(5, "Input/output error")
        super()._send(data)


def test_an_unplugged_line_at_go_says_no_stop_could_be_sent() -> None:
    clock = Clock()
    t = Unplugged([*OPEN, FREQ, ("speed 6 c01 c01 c50 c01\r", "o\t\r"), ("speed 6\r", "o\t\r")])
    dev = NanoControlConsole(t, timeout=TIMEOUT, margin=MARGIN, clock=clock, sleep=clock.sleep)
    with t:
        with pytest.raises(StepsUncertain, match=r"/dev/fake.*Input/output error.*no stop could be sent") as e:
            dev.step(3, 1000)
        assert (e.value.made, e.value.at_most) == (0, None)
        dev.close()  # never raises


def test_a_failure_in_a_later_burst_keeps_the_earlier_bursts() -> None:
    t, dev, _ = console(
        [
            FREQ,
            ("speed 6 c01 c01 c64 c01\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            (f"go 0 0 100 0 {T(6400)}\r", "o\t\r"),
            ("stop\r", "o\t\r"),
            (f"go 0 0 100 0 {T(6400)}\r", "e\toverheated\r"),
            ("stopnack\r", None),
            ("stop\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
        ]
    )
    with t:
        with pytest.raises(StepsUncertain, match="overheated") as e:
            dev.step(3, 2 * 6400)
    assert (e.value.made, e.value.at_most) == (6400, 12800)


def test_an_unreadable_profile_refuses_bursts_and_sends_nothing() -> None:
    t = FakeTransport([("version\r", "o\tNC\r"), ("speed ?\r", "o\tprofile one\r")], name="/dev/fake")
    dev = NanoControlConsole(t, timeout=TIMEOUT)
    with t:
        with pytest.raises(DeviceError, match="could not be read"):
            dev.step(3, 10)
        assert dev.info.extra["active_profile"] is None


def test_info_answers_are_answers_and_are_logged(caplog: pytest.LogCaptureFixture) -> None:
    t, dev, _ = console([("beep 1500 150\r", "i\tPiezo voltage breakdown\r")])
    with t, caplog.at_level("WARNING", logger="stickslip.devices.nanocontrol"):
        dev.beep(1500, 150)  # an i answer is an answer: no error
    assert any("Piezo voltage breakdown" in r.getMessage() for r in caplog.records)


def test_fine_with_coarse_is_sent_for_all_four_channels() -> None:
    t, dev, _ = console([("finewithcoarse 0 1 0 0\r", "o\t\r")])
    with t:
        dev.set_fine_with_coarse({"A": False, "B": True, "C": False, "D": False})


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda d: d.set_frequency(1, 299), r"300\.\.20000 Hz"),
        (lambda d: d.set_frequency(1, 20001), r"300\.\.20000 Hz"),
        (lambda d: d.set_frequency(1, 1000.5), r"integer"),
        (lambda d: d.step(4, 10), r"joint must be one of \[1, 2, 3\]"),
        (lambda d: d.step(1, 2.5), r"integer"),
        (lambda d: d.beep(0, 10), r"1\.\.20000"),
        (lambda d: d.set_fine_with_coarse({"A": True}), r"every channel"),
    ],
)
def test_out_of_range_settings_raise_and_send_nothing(call: Callable[[NanoControlConsole], None], match: str) -> None:
    t, dev, _ = console([])
    with t:
        with pytest.raises(ValueError, match=match):
            call(dev)


@pytest.mark.parametrize("kw, match", [({"profile": 7}, "1..6"), ({"margin": 0}, "margin"), ({"hz": 100}, "300")])
def test_bad_construction_options(kw: dict[str, Any], match: str) -> None:
    t = FakeTransport([], name="/dev/fake")
    with pytest.raises(ValueError, match=match):
        NanoControlConsole(t, **kw)


@given(n=st.integers(1, MAX_BURST))
@settings(max_examples=300, deadline=None)
def test_split_burst_is_exact_with_at_most_two_valid_parts(n: int) -> None:
    parts = split_burst(n)
    assert 1 <= len(parts) <= 2
    assert sum(c * m for c, m in parts) == n
    assert all(1 <= c <= 64 and 1 <= m <= 100 for c, m in parts)


def test_split_burst_prefers_one_go_and_refuses_nonsense() -> None:
    assert split_burst(6400) == [(64, 100)] and split_burst(1) == [(1, 1)] and split_burst(97) == [(1, 97)]
    for bad in (0, 6401, -5, 2.0, True):
        with pytest.raises(ValueError):
            split_burst(bad)  # type: ignore[arg-type]  # wrong types on purpose


class AutoConsole(FakeTransport):
    """Answers every console command `o` (`speed ?` with a profile; nothing to `stopnack`)."""

    def __init__(self) -> None:
        super().__init__([], name="auto")
        self.commands: list[str] = []

    def _send(self, data: bytes) -> None:
        for part in data.decode().split("\r")[:-1]:
            self.commands.append(part)
            if part == "speed ?":
                self._buffer += b"o\t1 c010 c010 c010 c010\r"
            elif part != "stopnack":
                self._buffer += b"o\t\r"


@given(n=st.integers(-3 * MAX_BURST - 7, 3 * MAX_BURST + 7), joint=st.sampled_from([1, 2, 3]))
@settings(max_examples=60, deadline=None)
def test_any_step_count_is_made_of_gos_on_one_channel_summing_to_it(n: int, joint: int) -> None:
    """An independent reading of the transcript: each go's steps = the count last written x |m|."""
    clock = Clock()
    t = AutoConsole()
    dev = NanoControlConsole(t, timeout=TIMEOUT, margin=MARGIN, clock=clock, sleep=clock.sleep)
    dev.step(joint, n)
    count = dict.fromkeys("ABCD", 10)
    made = dict.fromkeys("ABCD", 0)
    gos = 0
    for c in t.commands:
        w = c.split()
        if w[0] == "speed" and len(w) == 6 and w[1] == "6":
            count = {ch: int(v[1:]) for ch, v in zip("ABCD", w[2:], strict=True)}
            assert all(v.startswith("c") for v in w[2:])  # never a fine entry
        elif w[0] == "go":
            gos += 1
            for ch, m in zip("ABCD", map(int, w[1:5]), strict=True):
                made[ch] += count[ch] * m
    ch = "ABC"[joint - 1]
    assert made == {c: (n if c == ch else 0) for c in "ABCD"}
    assert gos <= 2 * math.ceil(abs(n) / MAX_BURST)
    assert t.commands[-1] == ("speed 1" if n else "speed ?")  # the user's profile active again


def test_parse_profile_refuses_malformed_answers() -> None:
    assert parse_profile("6 c1 c064 f64 C02") == (6, ("c01", "c64", "f64", "c02"))
    for bad in ("1 c064 c032 f008", "7 c01 c01 c01 c01", "x c01 c01 c01 c01", "1 c00 c01 c01 c01", "1 d01 c1 c1 c1"):
        with pytest.raises(ValueError):
            parse_profile(bad)


# -- detection ---------------------------------------------------------------------------


def test_detection_finds_the_console_with_one_version_at_115200() -> None:
    t = FakeTransport([("version\r", "o\tNanoControl 4.2\r")], name="/dev/fake")
    with t:
        assert detect_dialect(t, timeout=TIMEOUT) == ("console", "NanoControl 4.2")
    assert t.baudrates == [115200]


def test_detection_retries_once_after_an_error_answer() -> None:
    t = FakeTransport([("version\r", "e\tunknown command\r"), ("version\r", "o\tNC 4\r")], name="/dev/fake")
    with t:
        assert detect_dialect(t, timeout=TIMEOUT) == ("console", "NC 4")


def test_detection_falls_back_to_legacy_at_19200_ending_the_probe_with_a_semicolon() -> None:
    t = FakeTransport(
        [("version\r", None), (";", "e\tunknown command\r"), ("version;", "o\tNanoControl 2.1\r")], name="/dev/fake"
    )
    with t:
        assert detect_dialect(t, timeout=TIMEOUT) == ("legacy", "NanoControl 2.1")
    assert t.baudrates == [115200, 19200]


def test_detection_honours_a_baud_override_for_both_probes() -> None:
    t = FakeTransport([("version\r", None), (";", None), ("version;", "o\tNC\r")], name="/dev/fake")
    with t:
        assert detect_dialect(t, timeout=TIMEOUT, baud=9600) == ("legacy", "NC")
    assert t.baudrates == [9600, 9600]


def test_detection_that_hears_nothing_names_the_port_and_both_probes() -> None:
    t = FakeTransport([("version\r", None), (";", None), ("version;", None)], name="/dev/fake")
    with t:
        with pytest.raises(DeviceError) as e:
            detect_dialect(t, timeout=TIMEOUT)
    msg = str(e.value)
    assert "/dev/fake" in msg and "115200" in msg and "19200" in msg and "?dialect=" in msg


def test_the_legacy_dialect_transcript_is_unchanged_when_forced() -> None:
    t = FakeTransport([("version;", "o\tNC 3.1\r"), ("coarse C +12;", "o\t\r")], name="/dev/fake")
    with t:
        dev = NanoControl(t, timeout=TIMEOUT)
        dev.step(3, 12)
        assert dev.info.extra["dialect"] == "legacy"


@pytest.mark.parametrize(
    "query, match",
    [
        ("dialect=modern", "dialect must be one of console, legacy"),
        ("dialect=console&ack=0", "ack=0 is a legacy-dialect option"),
        ("dialect=console&hz=100", r"300\.\.20000"),
        ("profile=0", r"1\.\.6"),
        ("margin=0", "margin"),
        ("finewithcoarse=2", "finewithcoarse"),
        ("speed=3", "unknown option"),
    ],
)
def test_bad_url_options_are_refused_before_the_port_is_opened(query: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        open_device(f"mm3a:///dev/ttyNOPE?{query}")


def test_an_unplugged_port_names_the_port() -> None:
    with pytest.raises(DeviceError, match="/dev/ttyNOPE"):
        open_device("mm3a:///dev/ttyNOPE?timeout=0.1")


# -- fuzzing the answers, and Ctrl-C inside the move loop -----------------------------------


@given(reply=st.binary(min_size=0, max_size=40))
@settings(max_examples=200, deadline=None)
def test_any_answer_to_version_is_a_version_or_one_device_error(reply: bytes) -> None:
    t = FakeTransport([("version\r", reply + b"\r")], name="/dev/fake")
    try:
        message = NanoControlConsole(t, timeout=TIMEOUT).version
    except DeviceError as e:
        assert "/dev/fake" in str(e)
        return
    except TranscriptError:  # it answered version well, then `speed ?` found the transcript used up
        first = reply.split(b"\r")[0].lstrip(b"\n")
        assert first[:2] in (b"o\t", b"i\t") and all(c == 9 or 32 <= c < 127 for c in first)
        return
    pytest.fail(f"opened without asking the profile: {message!r}")


def test_ctrl_c_in_the_move_loop_leaves_the_burst_journalled_and_nothing_driving() -> None:
    from stickslip.devices.positions import DeviceState
    from stickslip.procedures.move import drive

    clock = Clock(interrupt_after=30)  # 30 sleeps of 0.05 s: inside the second burst
    t, dev, _ = console(
        [
            FREQ,
            ("speed 6 c01 c01 c50 c01\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            (f"go 0 0 20 0 {T(1000)}\r", "o\t\r"),
            ("stop\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
            FREQ,  # every step() sets the frequency and the scratch profile again (a power cycle between calls)
            ("speed 6 c01 c01 c50 c01\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            (f"go 0 0 20 0 {T(1000)}\r", "o\t\r"),
            ("stopnack\r", None),
            ("stop\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
        ],
        clock=clock,
    )
    state = DeviceState.default("mm3a:///dev/fake")
    state.set_position(3, 1e-3, "set")
    with t:
        with pytest.raises(KeyboardInterrupt):
            drive(dev, state, 3, 2000, 1000, lambda n: 1e-3 + n * 1e-6, lambda s: None)
        dev.close()
    # the first burst is kept; the second is journalled: uncertain between its start and end
    assert state.positions[3] == pytest.approx(1e-3 + 1000e-6, abs=1e-15)
    assert state.uncertain[3] == pytest.approx((1e-3 + 1000e-6, 1e-3 + 2000e-6), abs=1e-15)


def test_a_long_timeout_caps_the_go_interval_at_65535_ms() -> None:
    t = FakeTransport(
        [
            *OPEN,
            FREQ,
            ("speed 6 c01 c01 c64 c01\r", "o\t\r"),
            ("speed 6\r", "o\t\r"),
            ("go 0 0 100 0 65535\r", "o\t\r"),  # 6.4 s + 0.05 s + 2 x 30 s would be 66450 ms
            ("stop\r", "o\t\r"),
            ("speed 3\r", "o\t\r"),
        ],
        name="/dev/fake",
    )
    clock = Clock()
    dev = NanoControlConsole(t, timeout=30, margin=MARGIN, clock=clock, sleep=clock.sleep)
    with t:
        dev.step(3, 6400)


class _Watched:
    """A lock that says when a thread waits for it (``waiting``), as a step() about to begin does."""

    def __init__(self) -> None:
        import threading

        self.lock = threading.RLock()
        self.waiting = threading.Event()

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        if blocking:
            self.waiting.set()
        return self.lock.acquire(blocking, timeout)

    def release(self) -> None:
        self.lock.release()

    def __enter__(self) -> _Watched:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def test_a_stop_from_another_thread_as_a_step_begins_is_not_held_back_until_the_step_is_over() -> None:
    # stop() saw neither a burst driving nor a step under way (the step waited for the line) and queued its own
    # 'stop' behind the line's lock: it went out only after the whole step, whose bursts it did not stop
    import threading

    t, dev, _ = console([FREQ])  # the step begins (frequency), then sends no go: it was stopped
    watched = _Watched()
    dev._lock = watched  # type: ignore[assignment]
    watched.lock.acquire()  # the line busy (an exchange of a third thread) as the step begins
    outcome: list[object] = []
    def stepping() -> None:
        try:
            dev.step(3, 100)
        except StepsUncertain as e:  # nothing sent: made 0, at most 0
            outcome.append((e.made, e.at_most, "were not sent" in str(e)))

    worker = threading.Thread(target=stepping, daemon=True)
    worker.start()
    try:
        assert watched.waiting.wait(5.0)  # the step waits for the line
        stopper = threading.Thread(target=dev.stop, daemon=True)
        stopper.start()
        stopper.join(5.0)
        assert not stopper.is_alive()  # the stop returned at once, not behind the step
    finally:
        watched.lock.release()
    worker.join(5.0)
    assert not worker.is_alive() and outcome == [(0, 0, True)]
    assert not any(m.startswith(b"go") for m in t.sent)  # no burst after the stop
    t.assert_done()
