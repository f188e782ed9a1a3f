"""A scripted controller line whose answers arrive as a socket's do, for a stop from another thread during a burst.

:class:`HeldConsole` answers a transcript of ``(sent, reply)`` pairs in order, like
:class:`stickslip.devices.transport.FakeTransport`, but its answers arrive through ``_recv``
(never written into the reader's buffer from the writer's thread, which two threads would
race on). A ``None`` reply holds the answer: the burst runs until the next command (the
stop) is written, whose reply then carries the held answer first. ``held_sent`` is set
when the command with the held answer has been written.
"""

from __future__ import annotations

import threading

from stickslip.devices.transport import Transport


def _b(x: bytes | str | None) -> bytes | None:
    return x.encode("ascii") if isinstance(x, str) else x


class HeldConsole(Transport):
    """The transcript's controller on a line two threads may use (see the module docstring)."""

    def __init__(self, transcript: list[tuple[bytes | str | None, bytes | str | None]], name: str = "fake") -> None:
        super().__init__(name, 0.05)
        self.expected = [(_b(s), _b(r)) for s, r in transcript]
        self.sent: list[bytes] = []
        self._inbox = b""
        self._arrived = threading.Condition()
        self.held_sent = threading.Event()
        self._answer(None)

    def _answer(self, sent: bytes | None) -> None:
        with self._arrived:
            if sent is not None:
                assert self.expected, f"unexpected {sent!r}: transcript used up"
                want, reply = self.expected.pop(0)
                assert sent == want, f"sent {sent!r}, transcript expected {want!r}"
                self.sent.append(sent)
                if reply is None:
                    self.held_sent.set()
                self._inbox += reply or b""
            while self.expected and self.expected[0][0] is None:
                self._inbox += self.expected.pop(0)[1] or b""
            self._arrived.notify_all()

    def _send(self, data: bytes) -> None:
        self._answer(data)

    def _recv(self, timeout: float) -> bytes:
        with self._arrived:
            self._arrived.wait_for(lambda: self._inbox, timeout)
            data, self._inbox = self._inbox, b""
        return data

    def _close(self) -> None:
        pass
