"""An emulator of the current NanoControl console, driving a simulated MM3A.

It answers the console dialect (:mod:`stickslip.devices.nanocontrol.console`) on a
pseudo-terminal or a loopback TCP port: CR-terminated commands, one
``<status><TAB><message><CR>`` answer each (none to ``stopnack``). A ``go`` starts the
channels driving in real time: every ``T`` ms each channel makes (its active profile's
count) x |m| steps at its stepping frequency, the first interval starting when ``go``
is received; ``stop``, ``stopnack`` or another ``go`` halts them, and the steps made by
then (counted from the wall clock) move the simulated joint::

    from stickslip.devices import open_device
    from stickslip.sim.console_emulator import ConsoleEmulator

    with ConsoleEmulator() as emu:              # e.g. /dev/pts/7
        dev = open_device(emu.url)              # detects the console dialect
        dev.step(3, 1000)                       # ~1 s at the 1000 Hz the driver sets
        emu.steps["C"]                          # 1000

The power-on stepping frequency is 700 Hz (not the 1000 Hz a driver might assume), the
power-on profiles are ``c16`` on every channel, profile 1 active. Everything received
is kept in :attr:`received`; :meth:`inject` makes it fail (``"silent"``: carry out but
never answer; ``"garbage"``: carry out and answer noise; ``"error"``: refuse every
command, ``stop`` too), counting ``go`` commands (``stopnack`` always halts, unanswered);
:meth:`unplug` closes the line. Run it by hand with ``python -m stickslip.sim.console_emulator``
(prints the URL).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from .arm import FREQUENCY_RANGE, SimulatedMM3A
from .emulators import GARBAGE, _Emulator, serve_until_interrupted

__all__ = ["ConsoleEmulator", "POWER_ON_HZ"]

POWER_ON_HZ = 700
"""Stepping frequency of every channel at power-on, Hz."""

_CH = "ABCD"


@dataclass
class _Drive:
    """One channel driving since ``t0`` (s, monotonic): ``per`` steps every ``interval`` s."""

    t0: float
    per: int
    interval: float
    sign: int
    hz: float
    fine: bool


class _Refuse(Exception):
    """The emulated console answers ``e``."""


def steps_by(elapsed: float, per: int, interval: float, hz: float) -> int:
    """Steps a channel has made ``elapsed`` s after ``go``: ``per`` at ``hz`` each ``interval``."""
    if elapsed <= 0:
        return 0
    total = 0
    k = 0
    while k * interval <= elapsed:
        total += min(per, math.floor((elapsed - k * interval) * hz))
        k += 1
    return total


class ConsoleEmulator(_Emulator):
    """The current NanoControl console on a pseudo-terminal (``transport="pty"``) or loopback TCP.

    Parameters
    ----------
    sim : SimulatedMM3A, optional
        The arm it drives (default: a fresh one, seed 0).
    transport : {"pty", "tcp"}
    channels : str
        Channel letters of joints 1, 2, 3 (default ``"ABC"``); the others are unconnected
        (their steps are counted but move nothing).
    power_on_hz : int
        Every channel's stepping frequency until ``frequency`` is sent, Hz.
    clock : callable
        Monotonic clock, s (the wall clock; steps are counted from it).
    """

    def __init__(
        self,
        sim: SimulatedMM3A | None = None,
        transport: str = "pty",
        channels: str = "ABC",
        power_on_hz: int = POWER_ON_HZ,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(sim, transport, 0.0, {c: i + 1 for i, c in enumerate(channels)})
        self.clock = clock
        self.hz = dict.fromkeys(_CH, int(power_on_hz))
        self.profiles = {p: ["c16"] * 4 for p in range(1, 7)}
        self.active = 1
        self.fine_with_coarse = dict.fromkeys(_CH, False)
        self.steps = dict.fromkeys(_CH, 0)
        """Signed coarse steps each channel has made."""
        self.fine_steps = dict.fromkeys(_CH, 0)
        """Signed steps made with a fine (``fNN``) profile entry."""
        self.gos: list[tuple[str, int]] = []
        """``(channel, steps)`` of each halted drive, in order."""
        self._driving: dict[str, _Drive] = {}
        self._state = threading.Lock()

    @property
    def url(self) -> str:
        """The URL a driver opens this emulator with."""
        if self.port is None:
            raise RuntimeError("start the emulator first")
        if self.transport == "pty":
            return f"mm3a://{self.port}"
        return f"mm3a+socket://127.0.0.1:{self.port}"

    @property
    def driving(self) -> list[str]:
        """Channels driving now."""
        with self._state:
            return sorted(self._driving)

    def stop(self) -> None:
        """Halt every channel (as at power-off), then stop serving."""
        self._halt()
        super().stop()

    # -- the line -------------------------------------------------------------------------
    def _split(self, buffer: bytes) -> tuple[list[str], bytes]:
        *parts, rest = buffer.split(b"\r")
        return [p.decode("ascii", "replace") for p in parts], rest

    def _answer(self, message: str) -> tuple[bytes, bool]:
        words = message.split(" ")
        name = words[0]
        fault = self._fault_for(name == "go")
        if name == "stopnack" and message == "stopnack":  # halts, never answered, faulty or not
            self._halt()
            return b"", False
        if fault == "error":
            return b"e\tinternal error (injected)\r", False
        try:
            out = self._execute(name, [w for w in words[1:] if w])
        except _Refuse as e:
            return (b"" if fault == "silent" else f"e\t{e}\r".encode()), False
        if fault == "silent" or out is None:
            return b"", False
        if fault == "garbage":
            return GARBAGE, False
        return f"o\t{out}\r".encode(), False

    # -- the console ----------------------------------------------------------------------
    def _halt(self) -> None:
        now = self.clock()
        with self._state:
            for ch, drv in self._driving.items():
                n = drv.sign * steps_by(now - drv.t0, drv.per, drv.interval, drv.hz)
                self.gos.append((ch, n))
                if drv.fine:
                    self.fine_steps[ch] += n
                    continue
                self.steps[ch] += n
                if ch in self.joints and n:
                    self.sim.step(self.joints[ch], n)
            self._driving.clear()

    def _execute(self, name: str, args: list[str]) -> str | None:
        """One command; its answer's message, or None for no answer (``stopnack``)."""
        handler = {
            "version": self._version, "stopnack": self._stop_command, "stop": self._stop_command, "beep": self._beep,
            "frequency": self._frequency, "finewithcoarse": self._fine_with_coarse, "speed": self._speed,
            "go": self._go,
        }.get(name)
        if handler is None:
            raise _Refuse(f"unknown command {name!r}")
        return handler(name, args)

    def _version(self, name: str, args: list[str]) -> str:
        _nargs(args, 0)
        return "NanoControl console emulator 1.0 (stickslip)"

    def _stop_command(self, name: str, args: list[str]) -> str | None:
        _nargs(args, 0)
        self._halt()
        return "stopped" if name == "stop" else None  # stopnack is not answered

    def _beep(self, name: str, args: list[str]) -> str:
        _nargs(args, 2)
        _int(args[0], 1, 20000, "beep frequency")
        _int(args[1], 1, 5000, "beep duration")
        return ""

    def _frequency(self, name: str, args: list[str]) -> str:
        _nargs(args, 4)
        values = [_int(a, 300, 20000, "frequency") for a in args]
        self.hz = dict(zip(_CH, values, strict=True))
        for ch, j in self.joints.items():
            lo, hi = FREQUENCY_RANGE
            self.sim.set_frequency(j, min(max(float(self.hz[ch]), lo), hi))
        return ""

    def _fine_with_coarse(self, name: str, args: list[str]) -> str:
        _nargs(args, 4)
        flags = [_int(a, 0, 1, "finewithcoarse") for a in args]
        self.fine_with_coarse = {c: bool(v) for c, v in zip(_CH, flags, strict=True)}
        return ""

    def _speed(self, name: str, args: list[str]) -> str:
        if args == ["?"]:
            padded = " ".join(f"{v[0]}{int(v[1:]):03d}" for v in self.profiles[self.active])
            return f"{self.active} {padded}"
        if len(args) not in (1, 5):
            raise _Refuse("syntax error: speed P | speed P vA vB vC vD | speed ?")
        p = _int(args[0], 1, 6, "speed profile")
        if len(args) == 1:
            self.active = p
            return ""
        for v in args[1:]:
            if len(v) != 3 or v[0] not in "cf" or not v[1:].isdigit() or not 1 <= int(v[1:]) <= 64:
                raise _Refuse(f"speed value {v!r} is not c01..c64 or f01..f64")
        self.profiles[p] = list(args[1:])
        return ""

    def _go(self, name: str, args: list[str]) -> str:
        _nargs(args, 5)
        mults = [_int(a, -100, 100, "step multiplier") for a in args[:4]]
        t_ms = _int(args[4], 1, 65535, "interval (ms)")
        self._halt()
        now = self.clock()
        with self._state:
            for ch, m in zip(_CH, mults, strict=True):
                if m == 0:
                    continue
                value = self.profiles[self.active][_CH.index(ch)]
                self._driving[ch] = _Drive(
                    now, int(value[1:]) * abs(m), t_ms / 1000.0, 1 if m > 0 else -1,
                    float(self.hz[ch]), value[0] == "f",
                )
        return ""


def _nargs(args: list[str], n: int) -> None:
    if len(args) != n:
        raise _Refuse(f"syntax error: expected {n} argument(s), got {len(args)}")


def _int(word: str, lo: int, hi: int, what: str) -> int:
    try:
        v = int(word)
    except ValueError:
        raise _Refuse(f"syntax error: {what} {word!r} is not an integer") from None
    if not lo <= v <= hi:
        raise _Refuse(f"{what} {v} out of range {lo}..{hi}")
    return v


def main(argv: list[str] | None = None) -> int:
    """Serve the console emulator until Ctrl-C: ``python -m stickslip.sim.console_emulator``."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m stickslip.sim.console_emulator",
        description="Serve a NanoControl console emulator driving a simulated MM3A (Ctrl-C stops).",
    )
    parser.add_argument("--tcp", action="store_true", help="a loopback TCP port instead of a pty")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed")
    parser.add_argument("--day", default="emulator", help="simulator day label")
    args = parser.parse_args(argv)
    emu = ConsoleEmulator(SimulatedMM3A(seed=args.seed, day=args.day), "tcp" if args.tcp else "pty")
    return serve_until_interrupted(emu, lambda: f"{len(emu.received)} commands received; steps {emu.steps}")


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
