"""A reply that arrived while this process was not running is a reply in time.

On a loaded lab PC (or under a debugger, a garbage collection, Windows' scheduler) a
process can be paused for longer than a short timeout between asking and reading. The
transport then found its deadline passed before it had looked once, and declared the
controller silent though its answer sat in the buffer: a burst counted as failed, a
joint marked uncertain, a stop sent for nothing (seen as a flaky legacy fuzz case under
load, audit57). The clock here is moved by hand, so nothing depends on the machine's speed.
"""

from __future__ import annotations

import pytest

from stickslip.devices import transport as tr
from stickslip.devices.base import DeviceError


class _Paused(tr.Transport):
    """A link whose reply is already waiting (the clock fixture pauses the reading process past its deadline)."""

    def __init__(self, reply: bytes) -> None:
        super().__init__("paused", timeout=0.005)
        self._waiting = [reply] if reply else []
        self.looks: list[float] = []

    def _send(self, data: bytes) -> None:
        pass

    def _recv(self, timeout: float) -> bytes:
        self.looks.append(timeout)
        return self._waiting.pop(0) if self._waiting else b""

    def _close(self) -> None:
        pass


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    now = [100.0]

    def monotonic() -> float:  # each reading of the clock finds the process paused a little longer
        now[0] += 0.01
        return now[0]

    monkeypatch.setattr(tr.time, "monotonic", monotonic)
    return now


def test_a_reply_waiting_past_the_deadline_is_read_not_called_silence(clock: list[float]) -> None:
    link = _Paused(b"o\tok\r")
    assert link.read_until(b"\r") == b"o\tok\r"  # was: "no complete reply within 0.005 s", never having looked
    assert link.looks == [0.0] and not link.silent


def test_with_nothing_waiting_the_timeout_is_still_a_timeout(clock: list[float]) -> None:
    link = _Paused(b"")
    with pytest.raises(DeviceError, match=r"paused: no complete reply within 0\.005 s"):
        link.read_until(b"\r")
    assert link.looks == [0.0] and link.silent  # one look, without waiting, then the timeout


def test_a_partial_reply_past_the_deadline_is_named_in_the_timeout(clock: list[float]) -> None:
    link = _Paused(b"o\tok")
    with pytest.raises(DeviceError, match=r"received so far: b'o\\tok'"):
        link.read_until(b"\r")


def test_read_available_looks_once_however_late(clock: list[float]) -> None:
    link = _Paused(b"o\tstopped\r")
    assert link.read_available(quiet=0.001, limit=0.001) == b"o\tstopped\r"  # was: b"" (the stop's answer left)
