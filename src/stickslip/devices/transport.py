"""Byte transports for controller drivers: a serial port, a TCP socket, a replayed transcript.

Drivers (:mod:`.nanocontrol`, :mod:`.anc300`) are handed a transport and never open
ports themselves; :func:`stickslip.devices.base.open_device` builds the transport from
the URL. Every transport has the same small surface:

``write(data)``
    send bytes;
``read_until(terminators, timeout)``
    the bytes up to and including the first terminator, raising :class:`DeviceError`
    (saying what was read so far) if nothing complete arrives within ``timeout`` s;
``read_available(quiet)``
    whatever arrives until the line has been quiet for ``quiet`` s (banners, flushing);
``close()``.

:class:`FakeTransport` replays an exact transcript of ``(sent, reply)`` pairs in the
spirit of pymeasure's ``expected_protocol``: a message that differs from the next
expected one fails at once, and :meth:`FakeTransport.assert_done` (called on leaving
its ``with`` block) fails if any expected message was never sent.
"""

from __future__ import annotations

import logging
import os
import select
import socket
import threading
import time
from collections.abc import Callable, Iterable, Sequence

from .base import DeviceError, windows_com_port

__all__ = [
    "Transport",
    "SerialTransport",
    "SocketTransport",
    "FakeTransport",
    "StopAside",
    "TranscriptError",
    "serial_port_name",
    "windows_com_port",
]

log = logging.getLogger("stickslip.devices.transport")

_CHUNK = 4096


class Transport:
    """Buffered byte stream with timeouts; subclasses provide ``_send`` and ``_recv``.

    Parameters
    ----------
    name : str
        What people call the other end (``/dev/ttyUSB0``, ``192.168.1.5:7230``); every
        error message names it.
    timeout : float
        Default time to wait for a reply, s.
    """

    def __init__(self, name: str, timeout: float = 2.0) -> None:
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout!r}")
        self.name = name
        self.timeout = float(timeout)
        self._buffer = b""
        self.closed = False
        self.resyncs_failed = 0
        """How many :meth:`resync` queries went unanswered: drivers alternate two queries of different answers,
        so a late answer to a failed one is discarded by the next, not taken for it."""
        self.silent = False
        """True once a reply did not come within its timeout, until one does: the other end stopped answering,
        and best-effort commands (a stop, grounding on close) are then sent without waiting for answers."""

    # -- to implement -------------------------------------------------------------------
    def _send(self, data: bytes) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _recv(self, timeout: float) -> bytes:  # pragma: no cover - abstract
        """Bytes that arrive within ``timeout`` s (b"" if none). Raise DeviceError on EOF."""
        raise NotImplementedError

    def _close(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- shared -------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        """Send ``data``. Raises :class:`DeviceError` if the link is closed or broken."""
        if self.closed:
            raise DeviceError(f"{self.name}: the connection is closed")
        try:
            self._send(data)
        except OSError as e:
            raise DeviceError(f"{self.name}: could not send {data!r}: {e}") from e

    def read_until(
        self, terminators: bytes | Sequence[bytes], timeout: float | None = None
    ) -> bytes:
        """Read up to and including the first of ``terminators``.

        Raises :class:`DeviceError` after ``timeout`` s (default :attr:`timeout`) without
        a complete message; what did arrive stays in the buffer and is named in the error.
        """
        terms = [terminators] if isinstance(terminators, bytes) else list(terminators)
        timeout = self.timeout if timeout is None else float(timeout)
        deadline = time.monotonic() + timeout
        last_look = False
        while True:
            cut = _first_terminator(self._buffer, terms)
            if cut is not None:
                message, self._buffer = self._buffer[:cut], self._buffer[cut:]
                self.silent = False
                return message
            if last_look:
                self.silent = True
                partial = f" (received so far: {self._buffer!r})" if self._buffer else ""
                raise DeviceError(f"{self.name}: no complete reply within {timeout:g} s{partial}")
            remaining = deadline - time.monotonic()
            if remaining <= 0:  # one look without waiting first: a reply that came while this process was not
                last_look, remaining = True, 0.0  # running (a loaded PC, a pause) came in time
            if self.closed:
                raise DeviceError(f"{self.name}: the connection is closed")
            try:
                self._buffer += self._recv(min(remaining, 0.5))
            except OSError as e:
                raise DeviceError(f"{self.name}: read failed: {e}") from e

    def read_available(self, quiet: float = 0.05, limit: float | None = None) -> bytes:
        """All that arrives until nothing more comes for ``quiet`` s (at most ``limit`` s)."""
        limit = self.timeout if limit is None else limit
        deadline = time.monotonic() + limit
        data, self._buffer = self._buffer, b""
        first = True  # one look at least, however late this process runs
        while first or time.monotonic() < deadline:
            first = False
            try:
                chunk = self._recv(quiet)
            except (OSError, DeviceError):
                break
            if not chunk:
                break
            data += chunk
        return data

    def drain(self) -> bytes:
        """Take whatever has arrived unasked (buffered or waiting now), without waiting."""
        data, self._buffer = self._buffer, b""
        try:
            while not self.closed:
                chunk = self._recv(0.0)
                if not chunk:
                    break
                data += chunk
        except (OSError, DeviceError):
            pass
        return data

    def resync(self, queries: Sequence[tuple[bytes, Callable[[bytes], bool]]], terminator: bytes | Sequence[bytes],
               who: str, timeout: float | None = None) -> None:
        """Put the line back in step after a reply timed out: send a query, discard lines until its answer.

        A late answer to an earlier command would otherwise be read as the next one's (no dialect here
        echoes the command it answers). ``queries`` are ``(query, is_answer)`` pairs, taken in turn as
        queries go unanswered (:attr:`resyncs_failed`: a late answer to one is then not the next one's);
        ``is_answer`` tells the query's known answer (a line with its terminator) from any other line;
        lines before it are discarded (logged). Raises :class:`DeviceError` naming ``who`` and the query
        if the answer does not come within ``timeout`` s (default :attr:`timeout`); the line then stays
        :attr:`silent`, so the next command syncs again.
        """
        query, is_answer = queries[self.resyncs_failed % len(queries)]
        wait = self.timeout if timeout is None else float(timeout)
        deadline = time.monotonic() + wait
        self.write(query)
        while True:
            try:
                line = self.read_until(terminator, timeout=max(deadline - time.monotonic(), 0.0))
            except DeviceError as e:
                self.silent = True
                self.resyncs_failed += 1
                raise DeviceError(f"{who} did not answer {query!r}, sent to re-synchronise the line after "
                                  f"a reply timed out: {e}") from None
            if is_answer(line):
                return
            if line.strip(b"\r\n\t "):  # (the LF of a CR LF is no news)
                log.warning("%s: discarding %r while re-synchronising the line", self.name, line)

    def set_baudrate(self, baudrate: int) -> None:
        """Switch the line to ``baudrate`` (8N1). A link without a baud rate (TCP) ignores it."""
        log.debug("%s: no baud rate to set (%d ignored)", self.name, baudrate)

    def close(self) -> None:
        """Release the port (idempotent)."""
        if not self.closed:
            self.closed = True
            try:
                self._close()
            except OSError as e:  # pragma: no cover - best effort
                log.warning("%s: error while closing: %s", self.name, e)

    def __enter__(self) -> Transport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}>"


class StopAside:
    """One thread steps and reads the line; a stop from another thread is only written, its answer left to it.

    Two threads reading one line take each other's answers (audit60). During a ``step()``
    (:meth:`begin` .. :meth:`end`) :meth:`send` from another thread writes at once (prompt:
    no wait for the burst's answer) and counts the answer owed; the stepping thread sees
    :attr:`owed`, reads those answers after the one it waits for, and stops stepping.
    :meth:`write` is every other write: one at a time, and unread bytes are discarded
    first (stale) only when no stop's answer is owed.
    """

    def __init__(self, transport: Transport) -> None:
        self.transport = transport
        self.wire = threading.Lock()
        self.stepper: int | None = None
        self.owed = 0

    def begin(self) -> None:
        """The calling thread starts a step: it alone reads the line until :meth:`end`."""
        with self.wire:
            self.stepper, self.owed = threading.get_ident(), 0

    def end(self) -> int:
        """The step is over: how many stops other threads wrote meanwhile (their answers are the caller's to read)."""
        with self.wire:
            owed, self.owed, self.stepper = self.owed, 0, None
        return owed

    def end_reading(self, terminators: Sequence[bytes], wait: float) -> int:
        """:meth:`end`, then read the owed answers (a line each, ``wait`` s at most; none on a silent line). Best
        effort: a stop not answered (firmware without it) leaves the line :attr:`Transport.silent`, to be
        re-synchronised by the next command."""
        owed = self.end()
        for _ in range(owed):
            if self.transport.silent:
                break
            try:
                while not self.transport.read_until(terminators, timeout=wait).strip():
                    pass  # the LF of a CRLF
            except DeviceError as e:
                log.debug("no answer to a stop sent from another thread: %s", e)
                break
        return owed

    def send(self, *messages: bytes) -> bool:
        """Write ``messages`` (stops, each answered once) if another thread is stepping; whether it was (then
        nothing else is to be done). All are written under one hold of the line, so the step cannot end between
        them; a failed write ends them (best effort)."""
        with self.wire:
            if self.stepper is None or self.stepper == threading.get_ident():
                return False
            for data in messages:
                try:
                    log.debug("-> %r on %s (from another thread, during a step)", data, self.transport.name)
                    self.transport.write(data)
                    self.owed += 1
                except DeviceError as e:
                    log.warning("could not send %r to %s: %s", data, self.transport.name, e)
                    break
            return True

    def write(self, data: bytes) -> bytes:
        """Write ``data``; the stale bytes discarded before it (none while a stop's answer is owed)."""
        with self.wire:
            stale = self.transport.drain() if not self.owed else b""
            self.transport.write(data)
        return stale


def serial_port_name(path: str) -> str:
    """The serial port a device URL's path names: ``/COM3`` (of ``mm3a:///COM3``) is Windows' ``COM3``.

    A URL's path starts with ``/`` (``mm3a:///dev/ttyUSB0``); written the same way on Windows
    (``mm3a:///COM3``) it reached pyserial as ``/COM3``, which Windows cannot open. Any other
    path (``/dev/ttyUSB0``, ``/dev/pts/4``) is given back as it is.
    """
    return windows_com_port(path) or path


def _first_terminator(buffer: bytes, terms: Iterable[bytes]) -> int | None:
    best: int | None = None
    for t in terms:
        i = buffer.find(t)
        if i >= 0 and (best is None or i + len(t) < best):
            best = i + len(t)
    return best


class SerialTransport(Transport):
    """A serial port through pyserial (extra ``serial``): 8N1 at ``baudrate``.

    Works for USB-serial adapters (``/dev/ttyUSB0``, ``COM3``) and pseudo-terminals
    (``/dev/pts/N``), which the emulators use.

    Raises
    ------
    DeviceError
        If the port cannot be opened (unplugged, no permission), naming the port.
    """

    def __init__(self, port: str, baudrate: int = 19200, timeout: float = 2.0) -> None:
        super().__init__(port, timeout)
        try:
            import serial  # noqa: PLC0415  (optional extra, imported when a port is opened)
        except ImportError as e:
            raise DeviceError("serial ports need pyserial: pip install 'stickslip[serial]'") from e
        exclusive = True if os.name == "posix" else None  # one program per port
        try:
            self._port = serial.Serial(
                port,
                baudrate=baudrate,
                bytesize=8,
                parity="N",
                stopbits=1,
                timeout=0,
                exclusive=exclusive,
            )
        except (serial.SerialException, OSError, ValueError) as e:
            hint = "is another program using it?" if "lock" in str(e).lower() else "is it plugged in?"
            raise DeviceError(f"cannot open serial port {port}: {e} ({hint})") from e
        self._serial_exception = serial.SerialException
        log.debug("opened %s at %d baud 8N1", port, baudrate)

    def set_baudrate(self, baudrate: int) -> None:
        """Switch the open port to ``baudrate`` (8N1); :class:`DeviceError` if it cannot."""
        try:
            self._port.baudrate = int(baudrate)
        except (self._serial_exception, OSError, ValueError) as e:
            raise DeviceError(f"{self.name}: cannot set {baudrate} baud: {e}") from e
        log.debug("%s now at %d baud 8N1", self.name, baudrate)

    def _send(self, data: bytes) -> None:
        try:
            self._port.write(data)
            self._port.flush()
        except self._serial_exception as e:
            raise DeviceError(f"{self.name}: write failed: {e} (unplugged?)") from e

    def _recv(self, timeout: float) -> bytes:
        try:
            fd = self._port.fileno()
        except Exception:  # noqa: BLE001 - platforms without fileno: poll instead
            fd = None
        try:
            if fd is not None:
                ready, _, _ = select.select([fd], [], [], timeout)
                if not ready:
                    return b""
                data: bytes = self._port.read(self._port.in_waiting or 1)
                if not data:
                    raise DeviceError(f"{self.name}: the port went away (unplugged?)")
                return data
            time.sleep(min(timeout, 0.01))
            polled: bytes = self._port.read(self._port.in_waiting or 0)
            return polled
        except self._serial_exception as e:
            raise DeviceError(f"{self.name}: read failed: {e} (unplugged?)") from e

    def _close(self) -> None:
        self._port.close()


class SocketTransport(Transport):
    """A TCP connection (serial-over-network adapters, the ANC300's console on port 7230).

    Raises
    ------
    DeviceError
        If the connection cannot be made within ``timeout`` s, naming host and port.
    """

    def __init__(self, host: str, port: int, timeout: float = 2.0) -> None:
        super().__init__(f"{host}:{port}", timeout)
        try:
            self._sock = socket.create_connection((host, int(port)), timeout=timeout)
        except OSError as e:
            raise DeviceError(f"cannot connect to {host}:{port}: {e}") from e
        # each command goes out at once: without this, a command written right after one that is not
        # answered (an MCS2 setting) waits for the peer's delayed acknowledgement, tens of ms
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.setblocking(False)

    def _send(self, data: bytes) -> None:
        self._sock.setblocking(True)
        self._sock.settimeout(self.timeout)
        try:
            self._sock.sendall(data)
        finally:
            self._sock.setblocking(False)

    def _recv(self, timeout: float) -> bytes:
        ready, _, _ = select.select([self._sock], [], [], timeout)
        if not ready:
            return b""
        data = self._sock.recv(_CHUNK)
        if not data:
            raise DeviceError(f"{self.name}: the device closed the connection")
        return data

    def _close(self) -> None:
        self._sock.close()


class TranscriptError(AssertionError):
    """A driver sent something other than the transcript expected, or left messages unsent."""


class FakeTransport(Transport):
    """Replay an exact transcript: ``[(sent, reply), ...]`` as bytes or str.

    ``sent`` is what the driver must write next (``None`` for a reply the device sends
    unprompted, e.g. a banner or a second line); ``reply`` is what the device answers
    (``None`` for no answer, which the driver will see as a timeout). Writes are matched
    whole: a driver that writes one message in several pieces is joined until the
    expected length is reached.

    Raises
    ------
    TranscriptError
        On the first message that differs from the transcript, on a write after the
        transcript is used up, and from :meth:`assert_done` if messages are left over.
    """

    def __init__(
        self,
        transcript: Sequence[tuple[bytes | str | None, bytes | str | None]],
        name: str = "fake",
        timeout: float = 0.05,
    ) -> None:
        super().__init__(name, timeout)
        self._expected = [(_b(s), _b(r)) for s, r in transcript]
        self._pending = b""
        self.sent: list[bytes] = []
        self.baudrates: list[int] = []
        self._release_unprompted()

    def set_baudrate(self, baudrate: int) -> None:
        """Record the baud rate asked for (:attr:`baudrates`), so tests can check it."""
        self.baudrates.append(int(baudrate))

    def _release_unprompted(self) -> None:
        while self._expected and self._expected[0][0] is None:
            _, reply = self._expected.pop(0)
            self._buffer += reply or b""

    def _send(self, data: bytes) -> None:
        self._pending += data
        while self._pending:
            if not self._expected:
                raise TranscriptError(
                    f"unexpected message {self._pending!r}: transcript is used up"
                )
            want, reply = self._expected[0]
            assert want is not None
            if not want.startswith(self._pending[: len(want)]):
                raise TranscriptError(f"sent {self._pending!r}, transcript expected {want!r}")
            if len(self._pending) < len(want):
                return  # wait for the rest of the message
            self._expected.pop(0)
            self.sent.append(want)
            self._pending = self._pending[len(want) :]
            self._buffer += reply or b""
            self._release_unprompted()

    def _recv(self, timeout: float) -> bytes:
        time.sleep(min(timeout, 0.001))
        return b""

    def _close(self) -> None:
        pass

    @property
    def remaining(self) -> list[tuple[bytes | None, bytes | None]]:
        """Transcript entries not yet used."""
        return list(self._expected)

    def assert_done(self) -> None:
        """Fail if the driver did not send every expected message (or left a partial one)."""
        if self._expected or self._pending:
            left = [s for s, _ in self._expected]
            raise TranscriptError(
                f"messages left over: {left!r}"
                + (f"; partial write {self._pending!r}" if self._pending else "")
            )

    def __exit__(self, *exc: object) -> None:
        self.close()
        if not exc or exc[0] is None:  # leaving without an exception: all must have been sent
            self.assert_done()


def _b(x: bytes | str | None) -> bytes | None:
    if x is None or isinstance(x, bytes):
        return x
    return x.encode("ascii")
