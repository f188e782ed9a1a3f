"""Protocol emulators: a NanoControl on a pseudo-terminal or TCP port, an ANC300 on TCP.

Each emulator answers its controller's command set the way
:mod:`stickslip.devices.nanocontrol` and :mod:`stickslip.devices.anc300` expect the
real device to, and moves a :class:`~stickslip.sim.arm.SimulatedMM3A` with
every step command, so a traverse measured through the emulator finds the
simulator's load-dependent step size. It runs in a background thread; use it as a
context manager, or call :meth:`start` and :meth:`stop`::

    from stickslip.devices import open_device
    from stickslip.sim.emulators import NanoControlEmulator

    with NanoControlEmulator() as emu:           # a pseudo-terminal, e.g. /dev/pts/7
        dev = open_device(emu.url)               # "mm3a:///dev/pts/7"
        dev.step(3, 1000)
        emu.sim.position(3)                      # where the simulated joint went

Everything received is kept in :attr:`received` (one string per command), so tests
can check what a driver sent. Fault injection (:meth:`inject`): ``"silent"`` (stop
answering), ``"garbage"`` (answer noise), ``"error"`` (answer every command with an
error), each optionally only after ``after`` more step commands have been answered
normally; :meth:`unplug` closes the line.

TCP emulators listen on 127.0.0.1 only.
"""

from __future__ import annotations

import logging
import os
import select
import socket
import threading
import time
from collections.abc import Callable

from ..devices.nanocontrol import AMPLITUDE_RANGE, MAX_COARSE, PAUSE_RANGE_MS, SPEED_HZ
from .arm import FREQUENCY_RANGE, SimulatedMM3A

__all__ = ["NanoControlEmulator", "ANC300Emulator", "FAULTS"]

log = logging.getLogger("stickslip.sim.emulators")

FAULTS = ("silent", "garbage", "error")
GARBAGE = b"\x00\xfe#\x13\x9c\x07~\r\n"

_CONTINUOUS = 10_000_000
"""Steps simulated for an ANC300 continuous move (more than any joint's full range)."""


class _Emulator:
    """Shared machinery: a background thread serving one byte stream at a time."""

    def __init__(
        self, sim: SimulatedMM3A | None, transport: str, realtime: float, joints: dict[str, int]
    ):
        if transport not in ("pty", "tcp"):
            raise ValueError(f"transport must be 'pty' or 'tcp', got {transport!r}")
        if not realtime >= 0:
            raise ValueError(f"realtime must be >= 0 (0 = answer at once), got {realtime!r}")
        self.sim = sim if sim is not None else SimulatedMM3A(seed=0, day="emulator")
        self.transport = transport
        self.realtime = float(realtime)
        self.joints = dict(joints)
        self.received: list[str] = []
        self.fault: str | None = None
        self._fault_after: int | None = None
        self._fault_now = False
        self.step_commands = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._server: socket.socket | None = None
        self.port: str | int | None = None

    # -- lifecycle ------------------------------------------------------------------------
    def start(self) -> _Emulator:
        """Open the pseudo-terminal or listening socket and serve in a background thread."""
        if self._thread is not None:
            return self
        if self.transport == "pty":
            if os.name != "posix":
                raise OSError("a pseudo-terminal needs a POSIX system: use transport='tcp' (--tcp) here")
            import tty  # POSIX only: imported here so the TCP emulators run on Windows too

            self._master, self._slave = os.openpty()
            tty.setraw(self._slave)  # no echo, no line editing, until a driver opens it
            self.port = os.ttyname(self._slave)
        else:
            self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._server.bind(("127.0.0.1", 0))
            self._server.listen(1)
            self.port = self._server.getsockname()[1]
        self._thread = threading.Thread(target=self._serve, name=type(self).__name__, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close everything (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self._server is not None:
            self._server.close()
            self._server = None

    def unplug(self) -> None:
        """Close the line as if the cable were pulled."""
        self.stop()

    def __enter__(self) -> _Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- faults ---------------------------------------------------------------------------
    def inject(self, fault: str | None, after: int = 0) -> None:
        """Misbehave from now on (``after=0``) or from the ``after + 1``-th step command on.

        ``fault`` is ``"silent"``, ``"garbage"`` or ``"error"``; ``None`` heals the device.
        """
        if fault is not None and fault not in FAULTS:
            raise ValueError(f"fault must be one of {FAULTS} or None, got {fault!r}")
        if after < 0:
            raise ValueError(f"after must be >= 0 step commands, got {after!r}")
        with self._lock:
            self.fault = fault
            self._fault_after = self.step_commands + after if fault else None
            self._fault_now = fault is not None and after == 0

    def _fault_for(self, is_step: bool) -> str | None:
        """The fault that applies to the command just received (counting step commands)."""
        with self._lock:
            if is_step:
                self.step_commands += 1
            if self.fault is None or self._fault_after is None:
                return None
            if self._fault_now or self.step_commands > self._fault_after:
                self._fault_now = True
                return self.fault
            return None

    # -- serving --------------------------------------------------------------------------
    def _serve(self) -> None:
        try:
            if self.transport == "pty":
                assert self._master is not None
                self._session(self._master, is_socket=False)
            else:
                assert self._server is not None
                while not self._stop.is_set():
                    ready, _, _ = select.select([self._server], [], [], 0.05)
                    if not ready:
                        continue
                    conn, _ = self._server.accept()
                    with conn:
                        self._session(conn, is_socket=True)
        except Exception:  # pragma: no cover - a crash must not hang the tests
            log.exception("%s crashed", type(self).__name__)

    def _session(self, stream: socket.socket | int, is_socket: bool) -> None:
        def send(data: bytes) -> None:
            if not data:
                return
            try:
                if isinstance(stream, socket.socket):
                    stream.sendall(data)
                else:
                    os.write(stream, data)
            except OSError:
                pass

        self._on_connect(send)
        buffer = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([stream], [], [], 0.05)
            if not ready:
                continue
            try:
                chunk = stream.recv(4096) if isinstance(stream, socket.socket) else os.read(stream, 4096)
            except OSError:
                return
            if not chunk:
                return
            buffer += chunk
            messages, buffer = self._split(buffer)
            for message in messages:
                with self._lock:
                    self.received.append(message)
                reply, close = self._answer(message)
                send(reply)
                if close:
                    return

    def _wait(self, seconds: float) -> None:
        if self.realtime > 0 and seconds > 0:
            self._stop.wait(seconds * self.realtime)

    # -- to implement ---------------------------------------------------------------------
    def _on_connect(self, send: Callable[[bytes], None]) -> None:
        pass

    def _split(self, buffer: bytes) -> tuple[list[str], bytes]:  # pragma: no cover
        raise NotImplementedError

    def _answer(self, message: str) -> tuple[bytes, bool]:  # pragma: no cover
        raise NotImplementedError

    @property
    def url(self) -> str:  # pragma: no cover
        raise NotImplementedError


class NanoControlEmulator(_Emulator):
    """A Kleindiek NanoControl on a pseudo-terminal (``transport="pty"``) or loopback TCP.

    Answers the command set of :mod:`stickslip.devices.nanocontrol` with
    ``<status>\\t<message>\\r`` lines and steps the simulated joint of each channel.

    Parameters
    ----------
    sim : SimulatedMM3A, optional
        The arm it drives (default: a fresh one, seed 0).
    transport : {"pty", "tcp"}
    realtime : float
        0 answers at once (the simulator's virtual clock); 1 takes as long as the real
        device would (|N| / f per burst); values between scale that time.
    channels : str
        Channel letters of joints 1, 2, 3 (default ``"ABC"``); channel D is unconnected.
    """

    def __init__(
        self,
        sim: SimulatedMM3A | None = None,
        transport: str = "pty",
        realtime: float = 0.0,
        channels: str = "ABC",
    ):
        super().__init__(sim, transport, realtime, {c: i + 1 for i, c in enumerate(channels)})
        self.counters = dict.fromkeys("ABCD", 0)
        self.speed = dict.fromkeys("ABCD", 10)
        self.amplitude = {c: {"+": 80, "-": 80} for c in "ABCD"}

    @property
    def url(self) -> str:
        """The URL a driver opens this emulator with."""
        if self.port is None:
            raise RuntimeError("start the emulator first")
        if self.transport == "pty":
            return f"mm3a://{self.port}"
        return f"mm3a+socket://127.0.0.1:{self.port}"

    def _split(self, buffer: bytes) -> tuple[list[str], bytes]:
        *parts, rest = buffer.split(b";")
        out = [p.decode("ascii", "replace").strip() for p in parts]
        return [p for p in out if p], rest

    def _answer(self, message: str) -> tuple[bytes, bool]:
        words = message.split()
        name = words[0].lower() if words else ""
        fault = self._fault_for(name == "coarse")
        if fault == "silent":
            return b"", False
        if fault == "garbage":
            return GARBAGE, False
        if fault == "error":
            return b"e\tinternal error (injected)\r", False
        try:
            message_out = self._execute(name, words[1:])
        except _Refuse as e:
            return f"e\t{e}\r".encode(), False
        return f"o\t{message_out}\r".encode(), False

    def _joint(self, channel: str) -> int:
        ch = channel.upper()
        if ch not in "ABCD" or len(ch) != 1:
            raise _Refuse(f"unknown channel {channel!r}")
        if ch not in self.joints:
            raise _Refuse(f"channel {ch} not connected")
        return self.joints[ch]

    def _execute(self, name: str, args: list[str]) -> str:
        if name == "version":
            _nargs(args, 0)
            return "NanoControl emulator 1.0 (stickslip)"
        if name == "coarse":
            _nargs(args, 2)
            joint = self._joint(args[0])
            n = _int(args[1], -MAX_COARSE, MAX_COARSE, "coarse steps")
            self.sim.step(joint, n)
            self.counters[args[0].upper()] += n
            self._wait(abs(n) / self.sim.frequency(joint))
            return ""
        if name == "speed":
            _nargs(args, 2)
            joint = self._joint(args[0])
            lo, hi = min(SPEED_HZ), max(SPEED_HZ)
            level = _int(args[1], lo, hi, "speed")
            hz = min(max(SPEED_HZ[level], FREQUENCY_RANGE[0]), FREQUENCY_RANGE[1])
            self.sim.set_frequency(joint, hz)
            self.speed[args[0].upper()] = level
            return ""
        if name in ("amplitudepos", "amplitudeneg"):
            _nargs(args, 2)
            self._joint(args[0])
            value = _int(args[1], *AMPLITUDE_RANGE, what="amplitude")
            self.amplitude[args[0].upper()]["+" if name.endswith("pos") else "-"] = value
            return ""
        if name == "pause":
            _nargs(args, 1)
            ms = _int(args[0], *PAUSE_RANGE_MS, what="pause")
            self.sim.wait(ms / 1000.0)
            self._wait(ms / 1000.0)
            return ""
        if name == "counterread":
            _nargs(args, 0)
            return " ".join(str(self.counters[c]) for c in "ABCD")
        if name == "counterreset":
            _nargs(args, 0)
            self.counters = dict.fromkeys("ABCD", 0)
            return ""
        if name == "stop":
            return ""
        raise _Refuse(f"unknown command {name!r}")


class ANC300Emulator(_Emulator):
    """An Attocube ANC300 console on a loopback TCP port (telnet) or a pseudo-terminal (serial).

    On connection it sends a banner (with telnet negotiation bytes) and asks for the
    password; it echoes the password as ``*``, answers ``Authorization success`` (or
    ``Authorization failed`` and hangs up), then echoes commands (``> cmd``) until
    ``echo off``. Every command is answered by its output lines, then ``OK`` or
    ``ERROR``. Axes 1, 2, 3 drive joints 1, 2, 3; stepping needs mode ``stp``.
    ``stepu``/``stepd`` with ``c`` (or ``0``) start a continuous move, which runs the
    joint into its stop; :attr:`continuous_moves` counts them.
    """

    FREQUENCY_RANGE = (1, 10000)
    VOLTAGE_RANGE = (0.0, 150.0)
    MODES = ("gnd", "inp", "cap", "stp", "off", "stp+", "stp-")

    def __init__(
        self,
        sim: SimulatedMM3A | None = None,
        password: str = "123456",
        realtime: float = 0.0,
        axes: int = 3,
        transport: str = "tcp",
    ):
        super().__init__(sim, transport, realtime, {str(i): i for i in (1, 2, 3)})
        self.password = password
        self.n_axes = int(axes)
        self.mode = dict.fromkeys(range(1, self.n_axes + 1), "gnd")
        self.hz = dict.fromkeys(range(1, self.n_axes + 1), 1000)
        self.voltage = dict.fromkeys(range(1, self.n_axes + 1), 30.0)
        self.continuous_moves = 0
        self._authorized = False
        self._echo = True

    @property
    def url(self) -> str:
        """The URL a driver opens this emulator with (password included)."""
        if self.port is None:
            raise RuntimeError("start the emulator first")
        if self.transport == "pty":
            return f"anc300://{self.port}?password={self.password}"
        return f"anc300://127.0.0.1:{self.port}?password={self.password}"

    def _on_connect(self, send: Callable[[bytes], None]) -> None:
        self._authorized = False
        self._echo = True
        send(b"\xff\xfb\x01\xff\xfb\x03attocube ANC300 controller (stickslip emulator)\r\n")
        send(b"Authorization code: ")

    def _split(self, buffer: bytes) -> tuple[list[str], bytes]:
        *parts, rest = buffer.split(b"\n")
        return [p.decode("ascii", "replace").strip("\r") for p in parts], rest

    def _answer(self, message: str) -> tuple[bytes, bool]:
        if not self._authorized:
            stars = b"*" * len(message) + b"\r\n"
            if message == self.password:
                self._authorized = True
                return stars + b"Authorization success\r\n", False
            return stars + b"Authorization failed\r\n", True
        words = message.split()
        name = words[0].lower() if words else ""
        fault = self._fault_for(name in ("stepu", "stepd"))
        if fault == "silent":
            return b"", False
        if fault == "garbage":
            return GARBAGE, False
        echo = f"> {message}\r\n".encode() if self._echo else b""
        if fault == "error":
            return echo + b"Error: injected fault\r\nERROR\r\n", False
        try:
            lines = self._execute(name, words[1:])
        except _Refuse as e:
            return echo + f"{e}\r\nERROR\r\n".encode(), False
        body = "".join(f"{line}\r\n" for line in lines)
        return echo + f"{body}OK\r\n".encode(), False

    def _axis(self, word: str) -> int:
        try:
            a = int(word)
        except ValueError:
            raise _Refuse(f"Error: invalid axis {word!r}") from None
        if not 1 <= a <= self.n_axes:
            raise _Refuse(f"Error: axis {a} not present")
        return a

    def _execute(self, name: str, args: list[str]) -> list[str]:
        """One command: a console command, or an axis command (its first argument the axis)."""
        console = {"echo": self._echo_command, "ver": self._version, "getcser": self._controller_serial}
        if name in console:
            return console[name](args)
        if not args:
            raise _Refuse(f"Error: {name or 'empty command'}: missing axis")
        axis = self._axis(args[0])
        handler = {
            "getser": self._serial, "getm": self._get_mode, "setm": self._set_mode,
            "getf": self._get_frequency, "setf": self._set_frequency,
            "getv": self._get_voltage, "setv": self._set_voltage, "getc": self._capacitance,
            "stepu": self._step, "stepd": self._step, "stepw": self._nothing, "stop": self._nothing,
        }.get(name)
        if handler is None:
            raise _Refuse(f"Error: unknown command {name!r}")
        return handler(name, axis, args[1:])

    # -- console commands (no axis)

    def _echo_command(self, args: list[str]) -> list[str]:
        _nargs(args, 1)
        if args[0] not in ("on", "off"):
            raise _Refuse("Error: echo takes on or off")
        self._echo = args[0] == "on"
        return []

    def _version(self, args: list[str]) -> list[str]:
        return ["attocube ANC300 controller version 1.1.0 (stickslip emulator)"]

    def _controller_serial(self, args: list[str]) -> list[str]:
        return ["ANC300B-EMU-0001"]

    # -- axis commands: (command, axis, the arguments after the axis)

    def _serial(self, name: str, axis: int, rest: list[str]) -> list[str]:
        return [f"ANM-EMU-{axis:04d}"]

    def _get_mode(self, name: str, axis: int, rest: list[str]) -> list[str]:
        return [f"mode = {self.mode[axis]}"]

    def _set_mode(self, name: str, axis: int, rest: list[str]) -> list[str]:
        _nargs(rest, 1)
        if rest[0] not in self.MODES:
            raise _Refuse(f"Error: unknown mode {rest[0]!r}")
        self.mode[axis] = rest[0]
        return []

    def _get_frequency(self, name: str, axis: int, rest: list[str]) -> list[str]:
        return [f"frequency = {self.hz[axis]} Hz"]

    def _set_frequency(self, name: str, axis: int, rest: list[str]) -> list[str]:
        _nargs(rest, 1)
        value = _float(rest[0])
        lo, hi = self.FREQUENCY_RANGE
        if not (value.is_integer() and lo <= value <= hi):
            raise _Refuse(f"Error: frequency out of range ({lo}..{hi} Hz)")
        self.hz[axis] = int(value)
        if axis in self.joints.values():
            hz = float(min(max(value, FREQUENCY_RANGE[0]), FREQUENCY_RANGE[1]))
            self.sim.set_frequency(axis, hz)
        return []

    def _get_voltage(self, name: str, axis: int, rest: list[str]) -> list[str]:
        return [f"voltage = {self.voltage[axis]:.6f} V"]

    def _set_voltage(self, name: str, axis: int, rest: list[str]) -> list[str]:
        _nargs(rest, 1)
        value = _float(rest[0])
        vlo, vhi = self.VOLTAGE_RANGE
        if not vlo <= value <= vhi:
            raise _Refuse(f"Error: voltage out of range ({vlo:g}..{vhi:g} V)")
        self.voltage[axis] = value
        return []

    def _capacitance(self, name: str, axis: int, rest: list[str]) -> list[str]:
        return ["capacitance = 1000.000000 nF"]

    def _step(self, name: str, axis: int, rest: list[str]) -> list[str]:
        _nargs(rest, 1)
        if self.mode[axis] not in ("stp", "stp+", "stp-"):
            raise _Refuse("Axis in wrong mode")
        if rest[0] in ("c", "0"):
            self.continuous_moves += 1
            n = _CONTINUOUS
        else:
            n = _int(rest[0], 1, 2**31 - 1, "steps")
        if axis in self.joints.values():
            self.sim.step(axis, n if name == "stepu" else -n)
            self._wait(n / self.hz[axis] if n != _CONTINUOUS else 0.0)
        return []

    def _nothing(self, name: str, axis: int, rest: list[str]) -> list[str]:
        return []


class _Refuse(Exception):
    """The emulated device answers with an error."""


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


def _float(word: str) -> float:
    try:
        return float(word)
    except ValueError:
        raise _Refuse(f"Error: {word!r} is not a number") from None




def main(argv: list[str] | None = None) -> int:
    """Serve an emulator until Ctrl-C: ``python -m stickslip.sim.emulators [anc300]``.

    Prints the URL to open it with (e.g. ``mm3a:///dev/pts/7``), so that the command
    line can be tried without hardware:
    ``stickslip move --device mm3a:///dev/pts/7 --calibration cal.json --joint 3 --by 30um``.
    """
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m stickslip.sim.emulators",
        description="Serve a controller emulator driving a simulated MM3A (Ctrl-C stops).",
    )
    parser.add_argument(
        "device", nargs="?", default="nanocontrol", choices=("nanocontrol", "anc300")
    )
    parser.add_argument("--tcp", action="store_true", help="NanoControl on a loopback TCP port")
    parser.add_argument("--pty", action="store_true", help="ANC300 on a pseudo-terminal (serial)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed")
    parser.add_argument("--day", default="emulator", help="simulator day label")
    parser.add_argument("--realtime", type=float, default=0.0, help="1 = take as long as a device")
    parser.add_argument("--password", default="123456", help="ANC300 console password")
    args = parser.parse_args(argv)
    sim = SimulatedMM3A(seed=args.seed, day=args.day)
    emu: _Emulator
    if args.device == "anc300":
        kind = "pty" if args.pty else "tcp"
        emu = ANC300Emulator(sim, args.password, args.realtime, transport=kind)
    else:
        emu = NanoControlEmulator(sim, "tcp" if args.tcp else "pty", realtime=args.realtime)
    return serve_until_interrupted(emu, lambda: f"{len(emu.received)} commands received")


def serve_until_interrupted(emu: _Emulator, summary: Callable[[], str]) -> int:
    """Serve ``emu``, print its URL, and run until Ctrl-C or SIGTERM; then print ``summary()``. Returns 0."""
    import signal

    def _terminate(*_: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _terminate)
    with emu:
        try:  # the URL inside: a SIGTERM sent as soon as it was read may arrive while print returns (a flaky test)
            print(emu.url, flush=True)
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass
        print(summary(), flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
