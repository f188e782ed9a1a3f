"""The SmarAct MCS2: its SCPI-like ASCII interface over TCP (port 55551).

Opened by :func:`stickslip.devices.smaract.open_mcs2` (``smaract-mcs2://host[:port]``).

The interface, as public drivers use it
---------------------------------------
A command is ASCII ending in CR LF. A query (ending in ``?``) is answered by one line
ending in CR LF; a setting or a command is not answered at all. Errors are not answered
inline: they go to a queue, counted by ``:SYST:ERR:COUN?`` and read (oldest first) by
``:SYST:ERR?`` as ``<code>,"<text>"``. The commands this driver sends::

    :SYST:ERR:COUN?            errors queued                   -> <count>
    :SYST:ERR?                 the oldest error                -> <code>,"<text>"
    :DEV:NOCH?                 number of channels              -> <count>
    :DEV:SNUM?                 serial number                   -> <text>
    :CHAN<ch>:STAT?            channel state (bits, below)     -> <integer>
    :CHAN<ch>:MMOD 4           move mode 4: step (open loop)   (no answer)
    :CHAN<ch>:STEP:FREQ <f>    stepping frequency, 1..20000 Hz (no answer)
    :CHAN<ch>:STEP:AMPL <a>    step amplitude, 1..65535 (65535 = 100 V)  (no answer)
    :MOVE<ch> <n>              in step mode: n steps, -100000..-1 or 1..100000  (no answer)
    :STOP<ch>                  stop the channel                (no answer)

State bits used: 0x0001 actively moving, 0x0010 move delayed, 0x0100 end stop reached,
0x0800 movement failed, 0x2000 positioner overload, 0x4000 over temperature.

Every setting and command is followed by ``:SYST:ERR:COUN?``; a count other than 0 is
read and reported as a refusal (one line naming the code, its text and the command).
Before each burst the channel's state is read (a channel already moving is not sent a
burst) and its move mode, frequency and amplitude are sent again, so that another
program changing them cannot turn a burst into something else. Assumptions no public
source documents are listed, with a check on real hardware, in docs/devices/smaract.md.
Every message is logged on ``"stickslip.devices.smaract"`` (DEBUG).
"""

from __future__ import annotations

import re

from ..base import DeviceError
from ._common import ChannelMoving, Refused, SmarActBase, log, printable

__all__ = [
    "SmarActMCS2",
    "MAX_STEPS",
    "FREQUENCY_RANGE_HZ",
    "AMPLITUDE_RANGE",
    "AMPLITUDE_FULL",
    "TCP_PORT",
    "STEP_MODE",
    "STATE_BITS",
]

MAX_STEPS = 100_000
"""Most steps of one ``:MOVE`` in step mode."""
FREQUENCY_RANGE_HZ = (1, 20000)
"""Allowed stepping frequency (``:STEP:FREQ``), integer Hz, inclusive."""
AMPLITUDE_RANGE = (1, 65535)
"""Allowed step amplitude (``:STEP:AMPL``), controller units, inclusive."""
AMPLITUDE_FULL = 65535
"""Amplitude that stands for 100 V."""
TCP_PORT = 55551
"""TCP port of the MCS2's ASCII interface."""
STEP_MODE = 4
"""``:MMOD`` value of step mode (0 and 1 are closed loop, 2 and 3 scanning)."""

ACTIVELY_MOVING = 0x0001
MOVE_DELAYED = 0x0010
END_STOP_REACHED = 0x0100
MOVEMENT_FAILED = 0x0800
POSITIONER_OVERLOAD = 0x2000
OVER_TEMPERATURE = 0x4000

STATE_BITS: dict[int, str] = {
    ACTIVELY_MOVING: "actively moving",
    MOVE_DELAYED: "move delayed",
    END_STOP_REACHED: "end stop reached",
    MOVEMENT_FAILED: "movement failed",
    POSITIONER_OVERLOAD: "positioner overload",
    OVER_TEMPERATURE: "over temperature",
}
"""The bits of ``:CHAN<ch>:STAT?`` this driver reads."""

_BUSY = ACTIVELY_MOVING | MOVE_DELAYED
_TROUBLE = END_STOP_REACHED | MOVEMENT_FAILED | POSITIONER_OVERLOAD | OVER_TEMPERATURE
_INT = re.compile(r"[+-]?\d+")
_ERROR = re.compile(r'\s*([+-]?\d+)\s*(?:,\s*"?(.*?)"?)?\s*')
_MAX_READ_ERRORS = 20
"""Most queued errors read in one go (a full queue is named by its count)."""


class SmarActMCS2(SmarActBase):
    """A SmarAct MCS2 in step mode, as a :class:`~stickslip.devices.base.Controller`.

    See :class:`~stickslip.devices.smaract._common.SmarActBase` for the parameters. On
    opening it empties the error queue (logging what was left in it), asks
    ``:DEV:NOCH?`` (every mapped channel must exist) and ``:DEV:SNUM?``; nothing is set
    and nothing moves.

    Raises
    ------
    DeviceError
        If the controller does not answer, answers garbage, or has fewer channels than
        the map names.
    """

    name = "SmarAct MCS2"
    FREQUENCY_RANGE_HZ = FREQUENCY_RANGE_HZ
    AMPLITUDE_RANGE = AMPLITUDE_RANGE
    AMPLITUDE_FULL = AMPLITUDE_FULL
    MAX_STEPS = MAX_STEPS

    # -- the wire -------------------------------------------------------------------------
    def write(self, text: str) -> None:
        """Send ``text`` + CR LF (a setting or a command: no answer is expected)."""
        with self._lock:
            stale = self.transport.drain()
            if stale.strip(b"\r\n\t "):
                log.warning("discarding unexpected bytes from %s: %r", self.transport.name, stale)
            log.debug("-> %s<CR><LF>", text)
            self.transport.write(text.encode("ascii") + b"\r\n")

    def query(self, text: str, timeout: float | None = None) -> str:
        """Send ``text`` + CR LF and return its one-line answer (without the line end).

        Raises
        ------
        DeviceError
            On no complete answer within ``timeout`` (default :attr:`timeout`) or garbage;
            the message names the query and the port.
        """
        wait = self.timeout if timeout is None else timeout
        with self._lock:
            self.write(text)
            try:
                raw = self.transport.read_until(b"\n", timeout=wait)
            except DeviceError as e:
                raise DeviceError(f"{self._where()} did not answer {text!r}: {e}") from None
            log.debug("<- %r", raw)
            line = printable(raw.rstrip(b"\r\n"))
            if line is None or not line.strip():
                raise DeviceError(f"{self._where()}: garbage reply {raw!r} to {text!r}")
            return line.strip()

    def query_int(self, text: str) -> int:
        """A query answered by one integer; anything else is garbage (:class:`DeviceError`)."""
        answer = self.query(text)
        if not _INT.fullmatch(answer):
            raise DeviceError(f"{self._where()}: garbage reply {answer!r} to {text!r} (expected an integer)")
        return int(answer)

    def errors(self) -> list[tuple[int, str]]:
        """Read and empty the error queue: ``[(code, text), ...]``, oldest first."""
        with self._lock:
            count = self.query_int(":SYST:ERR:COUN?")
            if count < 0:
                raise DeviceError(f"{self._where()}: garbage reply {count!r} to ':SYST:ERR:COUN?'")
            out: list[tuple[int, str]] = []
            for _ in range(min(count, _MAX_READ_ERRORS)):
                answer = self.query(":SYST:ERR?")
                m = _ERROR.fullmatch(answer)
                if m is None:
                    raise DeviceError(f"{self._where()}: garbage reply {answer!r} to ':SYST:ERR?'")
                if int(m.group(1)) == 0:  # "no error": the queue is empty, so the count was not its length
                    raise DeviceError(
                        f"{self._where()}: ':SYST:ERR:COUN?' answered {count} but error {len(out) + 1} of the "
                        f"queue reads {answer!r} (no error): the count cannot be trusted"
                    )
                out.append((int(m.group(1)), (m.group(2) or "no text").strip()))
            if count > _MAX_READ_ERRORS:
                out.append((0, f"{count - _MAX_READ_ERRORS} more error(s) not read"))
            return out

    def command(self, *texts: str) -> None:
        """Send settings or commands, then check the error queue.

        Raises
        ------
        Refused
            If errors were queued: the first one's code and text, and the commands sent.
        DeviceError
            If the error count is not answered or garbage.
        """
        with self._lock:
            for text in texts:
                self.write(text)
            errs = self.errors()
            if errs:
                code, text = errs[0]
                more = f" (and {len(errs) - 1} more)" if len(errs) > 1 else ""
                raise Refused(f"{self._where()} refused {'; '.join(texts)!r}: error {code} ({text}){more}")

    # -- the dialect ----------------------------------------------------------------------
    def _open_session(self) -> None:
        stale = self.errors()
        if stale:
            log.warning("%s: errors left in the queue from before: %s", self._where(), stale)
        self.n_channels = self.query_int(":DEV:NOCH?")
        missing = sorted(c for c, _ in self.channel_map.channels.values() if c >= self.n_channels)
        if missing:
            raise DeviceError(
                f"{self._where()} has {self.n_channels} channel(s) (0..{self.n_channels - 1}); "
                f"the URL's channels name {missing}"
            )
        self.serial_number = self.query(":DEV:SNUM?")
        self.version = ""
        self.model = f"SmarAct MCS2 (serial {self.serial_number})"
        self.identity = f"MCS2 serial {self.serial_number}" if self.serial_number.strip() else None
        self._before: dict[int, int] = {}

    def _state(self, channel: int) -> int:
        return self.query_int(f":CHAN{channel}:STAT?")

    def _start(self, channel: int, steps: int, hz: int, amplitude: int) -> None:
        assert 0 < abs(steps) <= MAX_STEPS
        before = self._state(channel)
        if before & _BUSY:
            raise ChannelMoving(
                f"{self._where()}: channel {channel} is already moving (state {before:#x}); "
                "another program may be driving it"
            )
        self._before[channel] = before
        self.command(
            f":CHAN{channel}:MMOD {STEP_MODE}",
            f":CHAN{channel}:STEP:FREQ {hz}",
            f":CHAN{channel}:STEP:AMPL {amplitude}",
        )
        self.command(f":MOVE{channel} {steps}")  # Refused: not carried out; other errors: not known

    def _still_stepping(self, channel: int) -> tuple[bool, str | None]:
        state = self._state(channel)
        if state & _BUSY:
            return True, None
        new = state & _TROUBLE & ~self._before.get(channel, 0)
        if new:
            words = ", ".join(name for bit, name in STATE_BITS.items() if new & bit)
            return False, f"channel {channel} reports {words} (state {state:#x})"
        old = state & _TROUBLE
        if old:
            log.warning(
                "%s: channel %d still reports %s from before this burst; whether the burst ended early "
                "cannot be told from it", self._where(), channel,
                ", ".join(name for bit, name in STATE_BITS.items() if old & bit),
            )
        return False, None

    def _stop_channel(self, channel: int) -> bool:
        try:
            self.command(f":STOP{channel}")
            return True
        except DeviceError as e:
            log.warning("%s: stop of channel %d: %s", self._where(), channel, e)
            return False

    # -- protocol -------------------------------------------------------------------------
    def settings(self) -> dict[str, object]:
        """Channel map, frequency (Hz), amplitude (units and V) per joint, timeout (s), serial number."""
        return {"protocol": "MCS2", **super().settings(), "serial_number": self.serial_number}
