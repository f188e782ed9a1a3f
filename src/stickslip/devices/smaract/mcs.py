"""The SmarAct MCS (first generation): its ASCII command set on a serial port or TCP.

Opened by :func:`stickslip.devices.smaract.open_mcs` (``smaract-mcs://...``).

The command set, as public drivers and SmarAct's interface guide (quoted in them) use it
----------------------------------------------------------------------------------------
A command is ``:`` + the command + LF; an answer has the same form. A command that
returns no value is acknowledged (synchronous communication mode) by ``:E<channel>,0``;
a refused one by ``:E<channel>,<code>`` (``-1`` for the system as a whole). The commands
this driver sends::

    :SCM0                  synchronous communication mode   -> :E-1,0
    :GNC                   number of channels               -> :N<count>
    :GSI                   system id                        -> :ID<id>
    :GIV                   interface version                -> :IV<major>,<minor>,<update>
    :MST<ch>,<n>,<a>,<f>   n open-loop steps (n in -30000..30000, 0 stops, +-30000 never
                           ends), amplitude a (0..4095, 4095 = 100 V), frequency f
                           (1..18500 Hz)                    -> :E<ch>,0
    :GS<ch>                channel status                   -> :S<ch>,<status>
                           (before a burst too: a channel already moving, driven by
                           another program, is sent no burst)
    :S<ch>                 stop the channel                 -> :E<ch>,0

Status codes: 0 stopped, 1 stepping, 2 scanning, 3 holding, 4 targeting, 5 move delay,
6 calibrating, 7 finding the reference mark, 8 or 9 locked (the public sources differ).

This driver never sends 0 or +-30000 steps (a stop, an endless move): a burst has at most
:data:`MAX_STEPS` steps. Amplitude 0 (0 V: steps that do not move) is refused too.
Assumptions no public source documents are listed, with a check on real hardware, in
docs/devices/smaract.md. Every message is logged on ``"stickslip.devices.smaract"`` (DEBUG).
"""

from __future__ import annotations

import re

from ..base import DeviceError
from ._common import ChannelMoving, Refused, SmarActBase, log, printable

__all__ = [
    "SmarActMCS",
    "MAX_STEPS",
    "FREQUENCY_RANGE_HZ",
    "AMPLITUDE_RANGE",
    "AMPLITUDE_FULL",
    "BAUD",
    "BAUD_RANGE",
    "TCP_PORT",
    "ERRORS",
    "STATUS",
]

MAX_STEPS = 29999
"""Most steps of one ``:MST`` (its range is -30000..30000; 0 and +-30000 are never sent)."""
FREQUENCY_RANGE_HZ = (1, 18500)
"""Allowed stepping frequency, integer Hz, inclusive."""
AMPLITUDE_RANGE = (1, 4095)
"""Allowed step amplitude, controller units, inclusive (0 is documented but makes no step)."""
AMPLITUDE_FULL = 4095
"""Amplitude that stands for 100 V."""
BAUD = 9600
"""Baud rate (8N1) of the serial port unless the URL says otherwise."""
BAUD_RANGE = (9600, 115200)
"""Baud rates the controller can be set to (``:CB``, stored in the controller)."""
TCP_PORT = 5000
"""TCP port of the MCS's network interface."""

ERRORS: dict[int, str] = {
    1: "syntax error",
    2: "invalid command",
    3: "overflow",
    4: "parse error",
    5: "too few parameters",
    6: "too many parameters",
    7: "invalid parameter",
    8: "wrong mode",
    129: "no sensor present",
    140: "sensor disabled",
    141: "command overridden",
    142: "end stop reached",
    143: "wrong sensor type",
    144: "could not find reference mark",
    145: "wrong end effector type",
    146: "movement locked",
    147: "range limit reached",
    148: "physical position unknown",
    150: "command not processable",
    151: "waiting for trigger",
    152: "command not triggerable",
    153: "command queue full",
    154: "invalid component",
    155: "invalid sub component",
    156: "invalid property",
    157: "permission denied",
}
"""The error codes of ``:E<channel>,<code>`` answers, as the public sources name them."""

STATUS: dict[int, str] = {
    0: "stopped",
    1: "stepping",
    2: "scanning",
    3: "holding",
    4: "targeting",
    5: "move delay",
    6: "calibrating",
    7: "finding the reference mark",
    8: "locked",
    9: "locked",
}
"""The channel status codes of ``:S<channel>,<status>`` answers."""

_STOPPED = {0, 3}
_LOCKED = {8, 9}
_REPLY = re.compile(r":([A-Z]+)(.*)")
_INTS = re.compile(r"-?\d+(,-?\d+)*")


class SmarActMCS(SmarActBase):
    """A SmarAct MCS in step mode, as a :class:`~stickslip.devices.base.Controller`.

    See :class:`~stickslip.devices.smaract._common.SmarActBase` for the parameters. On
    opening it sends ``:SCM0``, ``:GNC`` (every mapped channel must exist), ``:GSI`` and
    ``:GIV``; nothing moves.

    Raises
    ------
    DeviceError
        If the controller does not answer, answers garbage, or has fewer channels than
        the map names.
    """

    name = "SmarAct MCS"
    FREQUENCY_RANGE_HZ = FREQUENCY_RANGE_HZ
    AMPLITUDE_RANGE = AMPLITUDE_RANGE
    AMPLITUDE_FULL = AMPLITUDE_FULL
    MAX_STEPS = MAX_STEPS

    # -- the wire -------------------------------------------------------------------------
    def command(self, text: str, timeout: float | None = None, channel: int | None = None,
                sync: bool = True) -> tuple[str, str]:
        """Send ``:text`` + LF; return the answer as ``(name, rest)``, e.g. ``("S", "0,1")``.

        After a reply timed out, the line is first re-synchronised (``:GNC``, its ``:N<channels>``
        awaited, anything before it discarded; ``:GSI`` and its ``:ID<id>`` after an unanswered one) unless
        ``sync`` is false (a stop is sent at once; its answer may be an earlier command's: the line stays
        out of step).

        Raises
        ------
        Refused
            On an ``:E<channel>,<code>`` answer with a code of :data:`ERRORS`, naming the code
            (if ``channel`` is given: only from that channel or the system, ``-1``).
        DeviceError
            On an error answer from another channel than ``channel`` (not this command's), or
            with a code not in :data:`ERRORS` (it may not be a refusal: the command may have run).
            On no complete answer within ``timeout`` (default :attr:`timeout`) or garbage;
            the message names the command and the port. If the re-synchronising ``:GNC`` is
            not answered in time (``text`` is then not sent).
        """
        wait = self.timeout if timeout is None else timeout
        with self._lock:
            unsynced = self.transport.silent and not sync
            if sync and self.transport.silent:
                queries = ((b":GNC\n", self._is_channel_count), (b":GSI\n", self._is_system_id))
                self.transport.resync(queries, b"\n", self._where(), wait)
            stale = self.transport.drain()
            if stale.strip(b"\r\n\t "):
                log.warning("discarding unexpected bytes from %s: %r", self.transport.name, stale)
            log.debug("-> :%s<LF>", text)
            self.transport.write(b":" + text.encode("ascii") + b"\n")
            try:
                raw = self.transport.read_until(b"\n", timeout=wait)
            except DeviceError as e:
                raise DeviceError(f"{self._where()} did not answer {text!r}: {e}") from None
            log.debug("<- %r", raw)
            self.transport.silent = unsynced  # an answer read unsynced may be an earlier command's
            line = printable(raw.rstrip(b"\r\n"))
            m = _REPLY.fullmatch(line.strip()) if line is not None else None
            if m is None:
                raise DeviceError(f"{self._where()}: garbage reply {raw!r} to {text!r}")
            name, rest = m.group(1), m.group(2)
            if name == "E":
                source, code = self._ints(rest, 2, text, raw)
                if code != 0:
                    if channel is not None and source not in (channel, -1):
                        raise DeviceError(f"{self._where()}: unexpected reply {raw!r} to {text!r}")
                    where = "the system" if source == -1 else f"channel {source}"
                    if code not in ERRORS:  # not a refusal we can read: whether it was carried out is unknown
                        raise DeviceError(
                            f"{self._where()} answered {text!r} with error {code} on {where}, a code this "
                            "driver does not know: whether the command was carried out is not known"
                        )
                    raise Refused(
                        f"{self._where()} refused {text!r}: error {code} "
                        f"({ERRORS[code]}) on {where}"
                    )
            return name, rest

    def _is_channel_count(self, line: bytes) -> bool:
        """Whether ``line`` is ``:GNC``'s answer (``:N<count>``, the count read on opening if known)."""
        known = getattr(self, "n_channels", None)
        return re.fullmatch(rb":N(\d+)\r?\n", line) is not None and (
            known is None or line.strip() == f":N{known}".encode())

    def _is_system_id(self, line: bytes) -> bool:
        """Whether ``line`` is ``:GSI``'s answer (``:ID<id>``, the id read on opening if known)."""
        known = getattr(self, "system_id", "")
        return re.fullmatch(rb":ID[^\r\n]*\r?\n", line) is not None and (
            not known or line.strip() == f":ID{known}".encode())

    def _ints(self, rest: str, count: int, text: str, raw: bytes) -> list[int]:
        if not _INTS.fullmatch(rest) or len(rest.split(",")) != count:
            raise DeviceError(f"{self._where()}: garbage reply {raw!r} to {text!r}")
        return [int(v) for v in rest.split(",")]

    def _ack(self, text: str, channel: int, sync: bool = True) -> None:
        """Send a command that must be acknowledged by ``:E<channel>,0`` (or ``:E-1,0``)."""
        name, rest = self.command(text, channel=channel, sync=sync)
        if name != "E" or self._ints(rest, 2, text, rest.encode())[0] not in (channel, -1):
            raise DeviceError(f"{self._where()}: unexpected reply ':{name}{rest}' to {text!r}")

    # -- the dialect ----------------------------------------------------------------------
    def _open_session(self) -> None:
        self._ack("SCM0", -1)
        name, rest = self.command("GNC")
        if name != "N" or not rest.isdigit():
            raise DeviceError(f"{self._where()}: unexpected reply ':{name}{rest}' to 'GNC'")
        self.n_channels = int(rest)
        missing = sorted(c for c, _ in self.channel_map.channels.values() if c >= self.n_channels)
        if missing:
            raise DeviceError(
                f"{self._where()} has {self.n_channels} channel(s) (0..{self.n_channels - 1}); "
                f"the URL's channels name {missing}"
            )
        name, rest = self.command("GSI")
        self.system_id = rest if name == "ID" else ""
        name, rest = self.command("GIV")
        self.version = rest.replace(",", ".") if name == "IV" else ""
        self.model = f"SmarAct MCS (system id {self.system_id})" if self.system_id else "SmarAct MCS"
        self.identity = f"MCS system id {self.system_id}" if self.system_id.strip() else None

    def _start(self, channel: int, steps: int, hz: int, amplitude: int) -> None:
        assert 0 < abs(steps) <= MAX_STEPS  # never 0 (a stop) nor +-30000 (an endless move)
        status = self._status(channel)  # a :MST would take over a channel another program is driving
        if status not in _STOPPED | _LOCKED:
            raise ChannelMoving(
                f"{self._where()}: channel {channel} is already moving (status {status}: {STATUS[status]}); "
                "another program may be driving it"
            )
        self._ack(f"MST{channel},{steps},{amplitude},{hz}", channel)

    def _status(self, channel: int) -> int:
        """``channel``'s status code (:data:`STATUS`), asked with ``:GS``."""
        text = f"GS{channel}"
        name, rest = self.command(text, channel=channel)
        if name != "S":
            raise DeviceError(f"{self._where()}: unexpected reply ':{name}{rest}' to {text!r}")
        ch, status = self._ints(rest, 2, text, rest.encode())
        if ch != channel or status not in STATUS:
            raise DeviceError(f"{self._where()}: unexpected reply ':{name}{rest}' to {text!r}")
        return status

    def _still_stepping(self, channel: int) -> tuple[bool, str | None]:
        status = self._status(channel)
        if status in _LOCKED:
            return False, f"channel {channel} is locked (status {status}: an emergency stop)"
        return status not in _STOPPED, None

    def _stop_channel(self, channel: int) -> bool:
        try:
            self._ack(f"S{channel}", channel, sync=False)  # at once: a stop waits for no re-synchronisation
            return True
        except DeviceError as e:
            log.warning("%s: stop of channel %d: %s", self._where(), channel, e)
            return False

    # -- protocol -------------------------------------------------------------------------
    def settings(self) -> dict[str, object]:
        """Channel map, frequency (Hz), amplitude (units and V) per joint, timeout (s), system id."""
        return {"protocol": "MCS ASCII", **super().settings(), "system_id": self.system_id,
                "interface_version": self.version}
