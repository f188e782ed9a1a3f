"""A controller that answers badly: an emulator answered in-process, its replies spoiled by a plan.

:class:`HostileLink` is a :class:`~stickslip.devices.transport.Transport` whose other end
is one of the protocol emulators (``stickslip.sim``), called directly (no thread, no
port). Each message the driver sends takes the next entry of a *plan*, which says what
the wire does with it:

``ok``        carried out, answered as the emulator answers;
``lost``      never reaches the device: not carried out, no answer;
``refuse``    not carried out, answered with the dialect's error line (``refusal(message)``, which may
              also queue the error in the emulator, as the MCS2 does);
``silent``    carried out, never answered;
``truncate``  carried out, the answer cut in half;
``garble``    carried out, one byte of the answer replaced by 0xFF (or a printable '#');
``split``     carried out, the answer arriving one or two bytes per read;
``extra``     carried out, answered, then an unasked line (``extra_line``);
``double``    carried out, the answer sent twice;
``late``      carried out, the answer held back until after the next message is sent
              (a reply to the previous command);
``later``     carried out, the answer held back until after the second message after it is sent
              (it lands after a stop sent at once has drained the line);
``nan``/``huge``/``negative``/``unknown``
              carried out, the first number of the answer replaced by ``nan``, ``1e308``,
              its negation, or the last one by ``977`` (an error code no driver knows);
``close``     carried out, then the port closes (every later read or write fails).

The plan's end is followed by ``ok``. The truth (what the device did) stays in the emulator,
so a test can check a driver never takes a step count as made when it was not.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence

from stickslip.devices.base import DeviceError
from stickslip.devices.transport import Transport

KINDS = ("ok", "lost", "refuse", "silent", "truncate", "garble", "split", "extra", "double", "late", "later",
         "nan", "huge", "negative", "unknown", "close")
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?")


class HostileLink(Transport):
    """``emulator``'s answers (``_split``/``_answer``) through the spoiling ``plan``."""

    def __init__(self, emulator: object, plan: Sequence[str], *, refusal: Callable[[str], bytes], extra_line: bytes,
                 timeout: float = 0.02, on_connect: Callable[[Callable[[bytes], None]], None] | None = None) -> None:
        super().__init__("hostile", timeout)
        self.emu = emulator
        self.plan = list(plan)
        self.refusal = refusal
        self.extra_line = extra_line
        self.used: list[tuple[str, str]] = []
        self._rx = b""
        self._arrivals: list[bytes] = []
        self._late: list[bytes] = []
        self._later: list[bytes] = []
        self.dead = False
        if on_connect is not None:
            on_connect(self._arrivals.append)

    def _send(self, data: bytes) -> None:
        if self.dead:
            raise OSError("the port is closed (the cable was pulled)")
        self._arrivals.extend(self._late)
        self._late, self._later = self._later, []
        self._rx += data
        messages, self._rx = self.emu._split(self._rx)  # type: ignore[attr-defined]
        for message in messages:
            kind = self.plan.pop(0) if self.plan else "ok"
            self.used.append((kind, message))
            self.emu.received.append(message)  # type: ignore[attr-defined]
            if kind == "lost":
                continue
            if kind == "refuse":
                self._arrivals.append(self.refusal(message))
                continue
            reply, _ = self.emu._answer(message)  # type: ignore[attr-defined]
            self._deliver(kind, reply)

    def _deliver(self, kind: str, reply: bytes) -> None:
        if kind == "close":
            self.dead = True
            return
        if kind == "silent" or not reply and kind != "extra":
            return
        if kind in ("late", "later"):
            (self._late if kind == "late" else self._later).append(reply)
            return
        if kind == "split":
            self._arrivals.extend(reply[i : i + 2] for i in range(0, len(reply), 2))
            return
        self._arrivals.append(_spoil(kind, reply, self.extra_line))

    def _recv(self, timeout: float) -> bytes:
        if self._arrivals:
            return self._arrivals.pop(0)
        if self.dead:
            raise DeviceError(f"{self.name}: the device closed the connection")
        if timeout > 0:
            time.sleep(timeout)
        return b""

    def _close(self) -> None:
        pass


def _spoil(kind: str, reply: bytes, extra_line: bytes) -> bytes:
    if kind == "truncate":
        return reply[: len(reply) // 2]
    if kind == "garble":
        i = len(reply) // 3
        return reply[:i] + (b"\xff" if len(reply) % 2 else b"#") + reply[i + 1 :]
    if kind == "extra":
        return reply + extra_line
    if kind == "double":
        return reply + reply
    if kind in ("nan", "huge", "negative"):
        m = _NUMBER.search(reply)
        if m is None:
            return reply
        new = {"nan": b"nan", "huge": b"1e308", "negative": b"-" + m.group().lstrip(b"-")}[kind]
        return reply[: m.start()] + new + reply[m.end() :]
    if kind == "unknown":
        found = list(_NUMBER.finditer(reply))
        if not found:
            return reply
        m = found[-1]
        return reply[: m.start()] + b"977" + reply[m.end() :]
    return reply
