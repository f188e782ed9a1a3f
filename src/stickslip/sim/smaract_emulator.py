"""Emulators of the SmarAct MCS (ASCII) and MCS2 (SCPI-like) controllers, driving a simulated arm.

Each answers its controller's command set the way :mod:`stickslip.devices.smaract`
expects the real device to (docs/devices/smaract.md) and moves a
:class:`~stickslip.sim.arm.SimulatedMM3A` with every burst of steps: channels map to the
arm's joints (``channels="0,1,2"``; ``-0`` wires a channel reversed)::

    from stickslip.devices import open_device
    from stickslip.sim.smaract_emulator import MCS2Emulator

    with MCS2Emulator() as emu:                  # a loopback TCP port
        dev = open_device(emu.url)               # "smaract-mcs2://127.0.0.1:PORT"
        dev.step(3, 1000)
        emu.steps[2]                             # 1000: channel 2 drives joint 3

A burst lasts ``realtime x |n| / f`` of wall-clock time (``realtime=0``, the default:
it is over at once); the channel reports it is stepping until then, and a stop
part-way makes the steps made by then (counted from the wall clock). The simulated
joint moves when the burst ends or is stopped. Everything received is kept in
:attr:`received`; :meth:`inject` makes it misbehave: ``"silent"`` (carry out but never
answer), ``"garbage"`` (answer noise), ``"error"`` (refuse every command; the MCS2 still
answers queries, so its error queue can be read), ``"stuck"``
(accept bursts that then never end nor move, until stopped); :meth:`unplug` closes the
line. ``python -m stickslip.sim.smaract_emulator [mcs|mcs2]`` serves one and prints
its URL. TCP emulators listen on 127.0.0.1 only.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from ..devices.smaract import parse_channels
from .arm import FREQUENCY_RANGE, SimulatedMM3A
from .emulators import GARBAGE, _Emulator, serve_until_interrupted

__all__ = ["MCSEmulator", "MCS2Emulator", "FAULTS"]

FAULTS = ("silent", "garbage", "error", "stuck")
"""What :meth:`MCSEmulator.inject` and :meth:`MCS2Emulator.inject` can make the device do."""

_ENDLESS = 10_000_000
"""Steps an endless burst makes at once when ``realtime = 0`` (more than any joint's range)."""
AMPLIFIER_ENABLED = 0x40000
"""A state bit the MCS2 emulator always reports (the driver must look only at its own bits)."""


@dataclass
class _Drive:
    """A burst on one channel since ``t0`` (s, monotonic): ``n`` signed steps lasting ``duration`` s."""

    t0: float
    n: int
    hz: float
    duration: float
    stuck: bool = False
    moves: bool = True


class _Channels:
    """The channels of an emulated controller: bursts on a wall clock, moving the arm's joints."""

    def __init__(self, sim: SimulatedMM3A, channels: str, count: int, realtime: float,
                 clock: Callable[[], float]) -> None:
        self.sim = sim
        self.wiring = {c: (j, s) for j, (c, s) in parse_channels(channels).channels.items()}
        if any(c >= count for c in self.wiring):
            raise ValueError(f"channels={channels!r} names a channel beyond the {count} the device has")
        self.count = count
        self.realtime = realtime
        self.clock = clock
        self.steps = dict.fromkeys(range(count), 0)
        self.bursts: list[tuple[int, int]] = []
        self._drives: dict[int, _Drive] = {}
        self._lock = threading.Lock()

    def start(self, channel: int, n: int, hz: float, endless: bool = False, stuck: bool = False,
              moves: bool = True) -> None:
        """Start a burst of ``n`` steps at ``hz`` (``endless``: until stopped; ``moves``: the arm follows)."""
        self.halt(channel)
        now = self.clock()
        duration = math.inf if endless else self.realtime * abs(n) / hz
        with self._lock:
            self._drives[channel] = _Drive(now, n, hz, duration, stuck, moves)
        self.settle()

    def _made(self, d: _Drive, t: float) -> int:
        if d.stuck:
            return 0
        sign = 1 if d.n > 0 else -1
        if math.isinf(d.duration):
            if self.realtime == 0:
                return sign * _ENDLESS
            return sign * math.floor((t - d.t0) * d.hz / self.realtime)
        if d.duration == 0 or t >= d.t0 + d.duration:
            return d.n
        return sign * min(abs(d.n), math.floor(abs(d.n) * (t - d.t0) / d.duration))

    def _finish(self, channel: int, d: _Drive, made: int) -> None:
        self.steps[channel] += made
        self.bursts.append((channel, made))
        if channel in self.wiring and made and d.moves:
            joint, sign = self.wiring[channel]
            lo, hi = FREQUENCY_RANGE
            self.sim.set_frequency(joint, min(max(d.hz, lo), hi))
            self.sim.step(joint, sign * made)

    def settle(self) -> None:
        """End every burst whose time is up (moving the arm)."""
        now = self.clock()
        with self._lock:
            done = [c for c, d in self._drives.items()
                    if not d.stuck and not math.isinf(d.duration) and now >= d.t0 + d.duration]
            if self.realtime == 0:
                done += [c for c, d in self._drives.items() if math.isinf(d.duration) and c not in done]
            ended = [(c, self._drives.pop(c)) for c in done]
        for c, d in ended:
            self._finish(c, d, self._made(d, now))

    def halt(self, channel: int | None = None) -> None:
        """Stop one channel (or all) now: the steps made so far count."""
        now = self.clock()
        with self._lock:
            chosen = list(self._drives) if channel is None else [channel]
            ended = [(c, self._drives.pop(c)) for c in chosen if c in self._drives]
        for c, d in ended:
            self._finish(c, d, self._made(d, now))

    def moving(self, channel: int) -> bool:
        self.settle()
        with self._lock:
            return channel in self._drives

    @property
    def driving(self) -> list[int]:
        self.settle()
        with self._lock:
            return sorted(self._drives)


class _SmarActEmulator(_Emulator):
    """What both emulators share: the channels, faults, and the ``driving`` check."""

    def __init__(self, sim: SimulatedMM3A | None, transport: str, realtime: float, channels: str,
                 count: int, clock: Callable[[], float]) -> None:
        super().__init__(sim, transport, realtime, {})
        self.channels = _Channels(self.sim, channels, count, self.realtime, clock)

    @property
    def steps(self) -> dict[int, int]:
        """Signed steps each channel has made (bursts still running not yet counted)."""
        self.channels.settle()
        return dict(self.channels.steps)

    @property
    def bursts(self) -> list[tuple[int, int]]:
        """``(channel, steps)`` of every burst that ended or was stopped, in order."""
        self.channels.settle()
        return list(self.channels.bursts)

    @property
    def driving(self) -> list[int]:
        """Channels stepping now."""
        return self.channels.driving

    def inject(self, fault: str | None, after: int = 0) -> None:
        """Misbehave from now on (``after=0``) or from the ``after + 1``-th burst command on.

        ``fault`` is one of :data:`FAULTS`; ``None`` heals the device.
        """
        if fault is not None and fault not in FAULTS:
            raise ValueError(f"fault must be one of {FAULTS} or None, got {fault!r}")
        if after < 0:
            raise ValueError(f"after must be >= 0 burst commands, got {after!r}")
        with self._lock:
            self.fault = fault
            self._fault_after = self.step_commands + after if fault else None
            self._fault_now = fault is not None and after == 0

    def stop(self) -> None:
        """Halt every channel (as at power-off), then stop serving."""
        self.channels.halt()
        super().stop()


class _Refuse(Exception):
    """The emulated controller refuses a command with an error code."""

    def __init__(self, code: int, channel: int = -1, text: str = "") -> None:
        super().__init__(text or str(code))
        self.code = code
        self.channel = channel
        self.text = text


_MCS_COMMAND = re.compile(r"([A-Z]+)(-?\d+(?:,-?\d+)*)?")


class MCSEmulator(_SmarActEmulator):
    """A SmarAct MCS (ASCII interface) on a pseudo-terminal (``transport="pty"``) or loopback TCP.

    Parameters
    ----------
    sim : SimulatedMM3A, optional
        The arm it drives (default: a fresh one, seed 0).
    transport : {"pty", "tcp"}
    realtime : float
        0 ends every burst at once; 1 takes as long as the device would (|n| / f).
    channels : str
        The channel of joints 1, 2, 3 (default ``"0,1,2"``; ``-`` reverses one).
    count : int
        Channels the controller has (``:GNC``).
    clock : callable
        Monotonic clock, s.
    """

    system_id = "1234567890"

    def __init__(self, sim: SimulatedMM3A | None = None, transport: str = "pty", realtime: float = 0.0,
                 channels: str = "0,1,2", count: int = 3, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(sim, transport, realtime, channels, count, clock)
        self.mode = 0  # communication mode: 0 synchronous, 1 asynchronous

    @property
    def url(self) -> str:
        """The URL a driver opens this emulator with."""
        if self.port is None:
            raise RuntimeError("start the emulator first")
        if self.transport == "pty":
            return f"smaract-mcs://{self.port}"
        return f"smaract-mcs+socket://127.0.0.1:{self.port}"

    def _split(self, buffer: bytes) -> tuple[list[str], bytes]:
        *lines, rest = buffer.split(b"\n")
        out = []
        for line in lines:
            colon = line.find(b":")
            if colon < 0:
                continue  # what comes between a line feed and a colon is ignored
            text = line[colon + 1 :].decode("ascii", "replace").strip("\r")
            if text:
                out.append(text)
        return out, rest

    def _answer(self, message: str) -> tuple[bytes, bool]:
        m = _MCS_COMMAND.fullmatch(message)
        name = m.group(1) if m else ""
        fault = self._fault_for(name == "MST")
        if fault == "error":
            return b":E-1,150\n", False
        try:
            if m is None:
                raise _Refuse(1)
            args = [int(a) for a in m.group(2).split(",")] if m.group(2) else []
            out = self._execute(name, args, stuck=fault == "stuck")
        except _Refuse as e:
            out = f"E{e.channel},{e.code}"
        if fault == "silent" or out is None:
            return b"", False
        if fault == "garbage":
            return GARBAGE, False
        return f":{out}\n".encode(), False

    def _channel(self, args: list[int], n: int) -> int:
        if len(args) != n:
            raise _Refuse(5 if len(args) < n else 6)
        if not 0 <= args[0] < self.channels.count:
            raise _Refuse(7)
        return args[0]

    def _execute(self, name: str, args: list[int], stuck: bool) -> str | None:
        if name == "SCM":
            if args not in ([0], [1]):
                raise _Refuse(7)
            self.mode = args[0]
            return "E-1,0"
        if name == "GCM":
            return f"CM{self.mode}"
        if name == "GNC":
            return f"N{self.channels.count}"
        if name == "GSI":
            return f"ID{self.system_id}"
        if name == "GIV":
            return "IV1,0,9"
        if name == "R":
            self.channels.halt()
            return "E-1,0"
        if name == "MST":
            ch = self._channel(args, 4)
            n, amplitude, hz = args[1:]
            if not -30000 <= n <= 30000 or not 0 <= amplitude <= 4095 or not 1 <= hz <= 18500:
                raise _Refuse(7, ch)
            if n == 0:
                self.channels.halt(ch)
            else:  # amplitude 0: steps of 0 V, which move nothing
                self.channels.start(ch, n, hz, endless=abs(n) == 30000, stuck=stuck, moves=amplitude > 0)
            return None if self.mode == 1 else f"E{ch},0"
        if name == "GS":
            ch = self._channel(args, 1)
            return f"S{ch},{1 if self.channels.moving(ch) else 0}"
        if name == "S":
            ch = self._channel(args, 1)
            self.channels.halt(ch)
            return None if self.mode == 1 else f"E{ch},0"
        raise _Refuse(2)


_CHAN = re.compile(r":CHAN(\d+):([A-Z:]+)(\?)?(?: (\S+))?")
_CMD = re.compile(r":(MOVE|STOP)(\d+)(?: (\S+))?")


class MCS2Emulator(_SmarActEmulator):
    """A SmarAct MCS2 (SCPI-like ASCII interface) on a loopback TCP port (or a pseudo-terminal).

    Parameters as for :class:`MCSEmulator`; ``count`` defaults to 6 channels. Settings are
    not answered; errors go to a queue (``:SYST:ERR:COUN?``, ``:SYST:ERR?``). A ``:MOVE``
    outside step mode is refused (no sensor: closed-loop moves are impossible).
    """

    serial_number = "MCS2-00004711"

    def __init__(self, sim: SimulatedMM3A | None = None, transport: str = "tcp", realtime: float = 0.0,
                 channels: str = "0,1,2", count: int = 6, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(sim, transport, realtime, channels, count, clock)
        self.errors: list[tuple[int, str]] = []
        self.mmod = dict.fromkeys(range(count), 0)
        self.hz = dict.fromkeys(range(count), 1000)
        self.amplitude = dict.fromkeys(range(count), 65535)

    @property
    def url(self) -> str:
        """The URL a driver opens this emulator with."""
        if self.port is None:
            raise RuntimeError("start the emulator first")
        if self.transport == "pty":
            raise RuntimeError("an MCS2 is reached over TCP: use transport='tcp'")
        return f"smaract-mcs2://127.0.0.1:{self.port}"

    def _split(self, buffer: bytes) -> tuple[list[str], bytes]:
        *lines, rest = buffer.split(b"\n")
        return [ln.decode("ascii", "replace").strip("\r") for ln in lines if ln.strip(b"\r")], rest

    def _answer(self, message: str) -> tuple[bytes, bool]:
        fault = self._fault_for(message.startswith(":MOVE"))
        try:
            if fault == "error" and not message.endswith("?"):  # queries still answer (the error count)
                raise _Refuse(-300, text="Device-specific error (injected)")
            out = self._execute(message, stuck=fault == "stuck")
        except _Refuse as e:
            self.errors.append((e.code, e.text or "error"))
            out = None
        if out is None or fault == "silent":
            return b"", False
        if fault == "garbage":
            return GARBAGE, False
        return f"{out}\r\n".encode(), False

    def _ch(self, text: str) -> int:
        ch = int(text)
        if not 0 <= ch < self.channels.count:
            raise _Refuse(34, text="Invalid channel index")
        return ch

    @staticmethod
    def _int(text: str | None, lo: int, hi: int) -> int:
        if text is None:
            raise _Refuse(-109, text="Missing parameter")
        try:
            value = int(text)
        except ValueError:
            raise _Refuse(-104, text="Data type error") from None
        if not lo <= value <= hi:
            raise _Refuse(-222, text="Data out of range")
        return value

    def _execute(self, message: str, stuck: bool) -> str | None:
        if message == ":SYST:ERR:COUN?":
            return str(len(self.errors))
        if message in (":SYST:ERR?", ":SYST:ERR:NEXT?"):
            code, text = self.errors.pop(0) if self.errors else (0, "No error")
            return f'{code},"{text}"'
        if message == "*IDN?":
            return f"SmarAct,MCS2,{self.serial_number},1.0.0"
        if message == ":DEV:NOCH?":
            return str(self.channels.count)
        if message == ":DEV:SNUM?":
            return self.serial_number
        m = _CHAN.fullmatch(message)
        if m:
            ch, key, query, value = self._ch(m.group(1)), m.group(2), m.group(3), m.group(4)
            table = {"MMOD": (self.mmod, 0, 4), "STEP:FREQ": (self.hz, 1, 20000),
                     "STEP:AMPL": (self.amplitude, 1, 65535)}
            if key == "STAT" and query:
                return str((1 if self.channels.moving(ch) else 0) | AMPLIFIER_ENABLED)
            if key in table:
                store, lo, hi = table[key]
                if query:
                    return str(store[ch])
                store[ch] = self._int(value, lo, hi)
                return None
        m = _CMD.fullmatch(message)
        if m:
            ch = self._ch(m.group(2))
            if m.group(1) == "STOP":
                self.channels.halt(ch)
                return None
            if self.mmod[ch] != 4:
                raise _Refuse(259, text="No sensor present")
            n = self._int(m.group(3), -100000, 100000)
            if n == 0:
                raise _Refuse(-222, text="Data out of range")
            self.channels.start(ch, n, self.hz[ch], stuck=stuck)
            return None
        raise _Refuse(-113, text="Undefined header")


def main(argv: list[str] | None = None) -> int:
    """Serve an emulator until Ctrl-C: ``python -m stickslip.sim.smaract_emulator [mcs|mcs2]``."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m stickslip.sim.smaract_emulator",
        description="Serve a SmarAct MCS or MCS2 emulator driving a simulated MM3A (Ctrl-C stops).",
    )
    parser.add_argument("device", nargs="?", default="mcs2", choices=("mcs", "mcs2"))
    parser.add_argument("--tcp", action="store_true", help="MCS on a loopback TCP port instead of a pty")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed")
    parser.add_argument("--day", default="emulator", help="simulator day label")
    parser.add_argument("--realtime", type=float, default=0.0, help="1 = take as long as a device")
    args = parser.parse_args(argv)
    sim = SimulatedMM3A(seed=args.seed, day=args.day)
    emu: _SmarActEmulator
    if args.device == "mcs":
        emu = MCSEmulator(sim, "tcp" if args.tcp else "pty", realtime=args.realtime)
    else:
        emu = MCS2Emulator(sim, realtime=args.realtime)
    return serve_until_interrupted(emu, lambda: f"{len(emu.received)} commands received; steps {emu.steps}")


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
