"""Attocube ANC300 backend: pymeasure's driver (extra ``anc300``) behind our Controller.

URLs (opened by :func:`open_url` through :func:`stickslip.devices.open_device`)::

    anc300://192.168.1.2                 the telnet console, port 7230
    anc300://192.168.1.2:7230?password=123456&axes=1,2,3&timeout=2
    anc300:///dev/ttyUSB0                the USB/serial console, 38400 baud 8N1
    anc300:///COM3 (or anc300://COM3)    the same on Windows

The console password comes from the environment variable ``STICKSLIP_ANC300_PASSWORD``
(default ``123456``, the factory default); a ``password`` option in the URL is still
accepted but discouraged (shells keep history). It is never stored, logged (the driver's
log records are redacted), printed or echoed: the URL is redacted at every boundary.
Other query options: ``axes`` (the ANC300 axis numbers of joints 1, 2, 3, default ``1,2,3``),
``timeout`` (s beyond a burst's own duration, default 2), ``delay`` (s between a
command and reading its answer, pymeasure's ``query_delay``, default 0.05),
``baud`` (serial only, default 38400).

The protocol is pymeasure's :class:`pymeasure.instruments.attocube.ANC300Controller`
(password prompt, ``echo off``, answers ending in ``OK`` or ``ERROR``); this module
only carries its bytes over our transports (:class:`TransportAdapter`) and wraps it:

* a step of ``n`` sends ``stepu AXIS n`` or ``stepd AXIS |n|`` with ``n`` never 0
  (``stepu AXIS 0`` or ``c`` would start a continuous move), after setting mode
  ``stp`` once, then waits with ``stepw AXIS`` until the burst is done;
* ``setf`` takes integer Hz in 1..10000 and ``setv`` volts in 0..150 (validated here
  first, naming the range; nothing is clipped);
* ``stop AXIS`` stops; closing stops every axis and grounds it (mode ``gnd``);
* a stop from another thread while ``step()`` waits for an answer (Bluesky's ``stop()``,
  the server's STOP, ``rigstop``) is written at once, and the stepping thread reads its
  answer after the one it waits for: one thread reads the line, so no answer is taken for
  another command's. That ``step()`` raises ``StepsUncertain`` (0 to ``n`` steps made:
  ``stepw`` does not say how far a stopped burst went; nothing made if ``stepu`` was not
  sent yet). Other commands take turns, one command and its answer at a time.

Assumptions: the serial console speaks the same console as telnet, password prompt
included (check: ``stickslip -vv where -d anc300:///dev/ttyUSB0`` logs ``READ:`` of the
stars answering the password, then ``Authorization success``).
A serial line has no connection to prompt on: if the console prompts once after power-up,
as the emulator's pseudo-terminal does, a later session's password is taken as a command
and opening fails, naming that (power the controller off and on; report it, with the log).
``ver`` answers the same line as on opening, then ``OK``, at any time. After an answer
timed out, the next command is preceded by ``ver`` and every line before its answer is
discarded (a late ``OK`` echoes no command: it would pass for the next command's; stops
are sent at once, without it); no answer within the timeout refuses the command, naming
``ver``. Check: in a ``stickslip -vv`` log after a timeout, ``ver`` is answered by the
version ``where`` shows, then ``OK``, before the next command. Every
message is logged on ``"stickslip.devices.anc300"`` (DEBUG).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar
from urllib.parse import unquote, urlsplit

from .base import (
    URL_BAUD,
    URL_TIMEOUT_S,
    DeviceError,
    DeviceInfo,
    RedactSecrets,
    StepsUncertain,
    check_setting,
    check_steps,
    redact_url,
    secret_from_env,
    url_options,
)
from .transport import SerialTransport, SocketTransport, StopAside, Transport, serial_port_name, windows_com_port

PASSWORD_ENV = "STICKSLIP_ANC300_PASSWORD"
"""Environment variable holding the ANC300 console password."""

__all__ = ["ANC300", "TransportAdapter", "open_url", "check_url", "FREQUENCY_RANGE", "VOLTAGE_RANGE"]

log = logging.getLogger("stickslip.devices.anc300")

FREQUENCY_RANGE = (1, 10000)
"""Allowed stepping frequencies (``setf``), integer Hz, inclusive."""
VOLTAGE_RANGE = (0.0, 150.0)
"""Allowed step amplitudes (``setv``), V, inclusive."""
DEFAULT_PORT = 7230
DEFAULT_PASSWORD = "123456"

T = TypeVar("T")


def _pymeasure() -> tuple[Any, Any]:
    try:
        from pymeasure.adapters import Adapter  # noqa: PLC0415
        from pymeasure.instruments.attocube import ANC300Controller  # noqa: PLC0415
    except ImportError as e:
        raise DeviceError(
            f"the ANC300 backend needs pymeasure: pip install 'stickslip[anc300]' ({e})"
        ) from e
    return Adapter, ANC300Controller


def _login_advice(msg: str) -> str:
    """What to do after pymeasure's login failed with ``msg`` (``Attocube authorization failed '<reply>'``)."""
    if not msg.startswith("Attocube authorization failed"):
        return ""
    if msg.endswith("'Authorization failed'"):  # the console refused the password: say where it comes from
        return (f"; give the console's password in ${PASSWORD_ENV} (not in the URL; without it the factory "
                f"default {DEFAULT_PASSWORD} is sent)")
    # another answer: the console took the password as a command, so it asked for none (a serial console still
    # logged in from the program before: the emulator's pty does this to every session after the first)
    return ("; the console asked for no password (still logged in from an earlier session?): power the controller "
            "off and on, or use its network console")


def TransportAdapter(transport: Transport, timeout: float | None = None) -> Any:  # noqa: N802
    """A pymeasure ``Adapter`` that talks through one of our transports (CRLF lines).

    Lines with bytes other than printable ASCII, tab, CR or LF are garbage and raise
    :class:`DeviceError`; so does a line that does not arrive within the timeout. Bytes
    still unread when a command is written are discarded (logged): they answer an earlier one.
    Once ``sync_answer`` is set (the answer to ``ver``, read on opening), a command written
    after a reply timed out is preceded by ``ver``: lines are discarded until that answer and
    its ``OK`` (:meth:`Transport.resync`), so a late ``OK`` is never read as the command's.
    """
    Adapter, _ = _pymeasure()

    class _TransportAdapter(Adapter):  # type: ignore[misc,valid-type]  # pymeasure ships no types
        def __init__(self) -> None:
            super().__init__(log=log)
            self.transport = transport
            self.connection = transport
            self.read_timeout = timeout
            self.sync_answer: str | None = None
            self.aside = StopAside(transport)  # a stop from another thread during a step(): written, answer read by it

        def _write(self, command: str, **kwargs: Any) -> None:
            self._write_bytes((command + "\r\n").encode("ascii"))

        def _write_bytes(self, content: bytes, **kwargs: Any) -> None:
            # what is unread when a command goes out answers an earlier one (a stop sent without waiting):
            # read as this command's "OK", a stepu that never arrived passed for made
            if self.sync_answer is not None and self.transport.silent:
                where = f"ANC300 on {self.transport.name}"
                self.transport.resync([(b"ver\r\n", _version_then_ok(self.sync_answer))], b"\r\n", where,
                                      self.read_timeout)
            stale = self.aside.write(content)  # none while a stop's answer is owed: the stepping thread reads it
            if stale.strip(b"\r\n\t "):
                log.warning("discarding unexpected bytes from %s: %r", self.transport.name, stale)

        def _read(self, **kwargs: Any) -> str:
            raw = self.transport.read_until(b"\r\n", timeout=self.read_timeout)
            line = raw[:-2]
            try:
                text = line.decode("ascii")
            except UnicodeDecodeError:
                text = None
            if text is None or any(not (c.isprintable() or c in "\t\r\n") for c in text):
                raise DeviceError(f"ANC300 on {self.transport.name}: garbage reply {line!r}")
            return text

        def _read_bytes(self, count: int, break_on_termchar: bool, **kwargs: Any) -> bytes:
            if count < 0:
                return self.transport.read_available()
            data = b""
            while len(data) < count:
                data += self.transport.read_until(b"", timeout=self.read_timeout)[:count]
            return data

        def flush_read_buffer(self) -> None:
            dropped = self.transport.read_available(quiet=0.05)
            if dropped:
                log.debug("flushed %r", dropped)

        def __repr__(self) -> str:
            return f"<TransportAdapter {self.transport.name}>"

    return _TransportAdapter()


def _version_then_ok(version: str) -> Callable[[bytes], bool]:
    """Tells the last line of ``ver``'s answer: ``OK`` right after the line ``version``."""
    seen = [False]

    def is_answer(line: bytes) -> bool:
        text = line.decode("ascii", "replace").strip()
        if seen[0] and text == "OK":
            return True
        seen[0] = text == version
        return False

    return is_answer


class ANC300:
    """An Attocube ANC300 as a :class:`~stickslip.devices.base.Controller`, via pymeasure.

    Parameters
    ----------
    transport : Transport
        An open byte transport to the console (TCP port 7230, or the serial port).
    password : str
        Console password (asked on telnet connections).
    axes : mapping of int to int
        ANC300 axis number (1..7) of each joint; default joints 1, 2, 3 -> axes 1, 2, 3.
    timeout : float
        Time to wait for an answer beyond a burst's own duration, s.
    query_delay : float
        Delay between a command and reading its answer, s (pymeasure's ``query_delay``).
    url : str
        The URL it was opened with.

    Raises
    ------
    DeviceError
        If pymeasure is missing, the password is refused or the console does not answer.
    """

    def __init__(
        self,
        transport: Transport,
        *,
        password: str = DEFAULT_PASSWORD,
        axes: Mapping[int, int] | None = None,
        timeout: float = 2.0,
        query_delay: float = 0.05,
        url: str = "anc300://",
    ) -> None:
        _, ANC300Controller = _pymeasure()
        self.axes = _check_axes(axes or {1: 1, 2: 2, 3: 3})
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout!r}")
        if not query_delay >= 0:
            raise ValueError(f"query_delay must be >= 0 s, got {query_delay!r}")
        self.timeout = float(timeout)
        self.transport = transport
        self.url = redact_url(url)
        self.adapter = TransportAdapter(transport, timeout=self.timeout)
        names = [f"axis{i}" for i in range(1, max(self.axes.values()) + 1)]
        self.adapter.log.addFilter(RedactSecrets(password))
        try:
            self._ctrl = ANC300Controller(
                self.adapter, axisnames=names, passwd=password, query_delay=query_delay
            )
        except DeviceError:
            raise
        except Exception as e:  # pymeasure raises a bare Exception on a wrong password
            msg = str(e).replace(password, "***") if password else str(e)
            raise DeviceError(f"ANC300 on {transport.name}: {msg}{_login_advice(msg)}") from None
        self._io = threading.RLock()  # one exchange (command and answer) at a time; a step() holds it throughout
        self._mode: dict[int, str | None] = dict.fromkeys(self.axes)
        self._hz: dict[int, float | None] = dict.fromkeys(self.axes)
        self._volt: dict[int, float | None] = dict.fromkeys(self.axes)
        self.version = self._device(lambda: str(self._ctrl.version), "ver")
        self.adapter.sync_answer = self.version  # re-synchronises the line after a timeout (see TransportAdapter)

    # -- helpers --------------------------------------------------------------------------
    def _axis(self, joint: int) -> Any:
        try:
            number = self.axes[int(joint)]
        except (KeyError, ValueError, TypeError):
            raise ValueError(f"joint must be one of {sorted(self.axes)}, got {joint!r}") from None
        return getattr(self._ctrl, f"axis{number}")

    def _device(self, call: Callable[[], T], what: str) -> T:
        """Run a pymeasure call; the device's ``ERROR`` answers become :class:`DeviceError`."""
        try:
            with self._io:
                return call()
        except DeviceError as e:
            raise DeviceError(f"ANC300 on {self.transport.name}, {what!r}: {e}") from None
        except ValueError as e:  # pymeasure: "Error after previous command with message ..." (the console's lines)
            said = " / ".join(line.strip() for line in str(e).splitlines() if line.strip())
            raise DeviceError(f"ANC300 on {self.transport.name} refused {what!r}: {said}") from None

    @contextmanager
    def _read_timeout(self, seconds: float) -> Iterator[None]:
        old = self.adapter.read_timeout
        self.adapter.read_timeout = seconds
        try:
            yield
        finally:
            self.adapter.read_timeout = old

    # -- settings -------------------------------------------------------------------------
    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint`` (``setf``): integer Hz in 1..10000."""
        ax = self._axis(joint)
        value = check_setting("frequency", hz, *FREQUENCY_RANGE, unit="Hz", integer=True)
        self._device(lambda: setattr(ax, "frequency", value), f"setf {ax.id} {value}")
        self._hz[int(joint)] = float(value)

    def frequency(self, joint: int) -> float:
        """The stepping frequency of ``joint``, Hz (``getf``, cached after the first read)."""
        ax = self._axis(joint)
        if self._hz[int(joint)] is None:
            answer = self._device(lambda: ax.frequency, f"getf {ax.id}")
            self._hz[int(joint)] = self._reading(answer, f"getf {ax.id}", FREQUENCY_RANGE, "Hz")
        hz = self._hz[int(joint)]
        assert hz is not None  # read from the controller just above
        return float(hz)

    def set_voltage(self, joint: int, volts: float) -> None:
        """Set the step amplitude of ``joint`` (``setv``), V, in 0..150."""
        ax = self._axis(joint)
        value = check_setting("voltage", volts, *VOLTAGE_RANGE, unit="V")
        self._device(lambda: setattr(ax, "voltage", value), f"setv {ax.id} {value:g}")
        self._volt[int(joint)] = value

    def voltage(self, joint: int) -> float:
        """The step amplitude of ``joint``, V (``getv``)."""
        ax = self._axis(joint)
        return self._reading(self._device(lambda: ax.voltage, f"getv {ax.id}"), f"getv {ax.id}", VOLTAGE_RANGE, "V")

    def _reading(self, answer: object, what: str, bounds: tuple[float, float], unit: str) -> float:
        """A number the console answered ``what`` with, in ``bounds``; :class:`DeviceError` naming it if not."""
        try:
            value = float(answer)  # type: ignore[arg-type]  # pymeasure hands back what it parsed, or the text
        except (TypeError, ValueError, OverflowError):
            value = math.nan
        lo, hi = bounds
        if not lo <= value <= hi:  # NaN fails too
            raise DeviceError(
                f"ANC300 on {self.transport.name} answered {what!r} with {answer!r}: "
                f"not a number in {lo:g}..{hi:g} {unit}"
            )
        return value

    # -- motion ---------------------------------------------------------------------------
    def step(self, joint: int, n: int) -> None:
        """Make ``n`` signed steps on ``joint`` and return when they are done (``stepw``).

        ``n = 0`` sends nothing (the ANC300 would read 0 as "move until stopped").
        On an error or no answer the axis is stopped (best effort) and
        :class:`DeviceError` raised. A :meth:`stop` from another thread meanwhile is
        sent at once; this thread reads its answer, and raises
        :class:`~stickslip.devices.base.StepsUncertain`: ``stepw`` does not say how many
        steps a stopped burst made (between 0 and ``n``; 0 if ``stepu`` was not sent yet).
        """
        ax = self._axis(joint)
        n = check_steps(n)
        if n == 0:
            return
        with self._io:
            self.adapter.aside.begin()  # this thread alone reads the line until _end_step
            try:
                sent = self._burst(ax, joint, n)
            except BaseException:  # refused, unanswered, garbage, or Ctrl-C: stop the axis
                self._end_step()
                self.stop(joint)
                raise
            if self._end_step():
                cmd = f"stepu {ax.id} {n}" if n > 0 else f"stepd {ax.id} {-n}"
                what = (f"{cmd} was stopped by stop() from another thread before stepw answered: the console does "
                        f"not say how many steps it made (0 to {n})" if sent
                        else f"{cmd} was not sent: stop() was called from another thread")
                raise StepsUncertain(f"ANC300 on {self.transport.name}: {what}", 0, n if sent else 0)

    def _burst(self, ax: Any, joint: int, n: int) -> bool:
        """``stepu``/``stepd`` then ``stepw``, unless a stop from another thread came first; whether it was sent."""
        if self._mode[int(joint)] != "stp":
            self._device(lambda: setattr(ax, "mode", "stp"), f"setm {ax.id} stp")
            self._mode[int(joint)] = "stp"
        hz = self.frequency(joint)
        if self.adapter.aside.owed:
            return False
        cmd = f"stepu {ax.id} {n}" if n > 0 else f"stepd {ax.id} {-n}"
        assert n != 0  # never "stepu X 0": that is a continuous move
        self._device(lambda: ax.move_raw(n), cmd)
        if self.adapter.aside.owed:
            return True
        with self._read_timeout(self.timeout + 1.5 * abs(n) / hz):
            self._device(lambda: ax.ask("stepw"), f"stepw {ax.id}")
        return True

    def _end_step(self) -> int:
        """Leave :meth:`step`: read the answers to the stops another thread wrote meanwhile; how many it wrote."""
        owed = int(self.adapter.aside.end())
        for _ in range(owed):
            if self.transport.silent:  # the console stopped answering: the next command re-synchronises the line
                break
            try:
                with self._read_timeout(min(self.timeout, 0.5)):
                    self._ctrl.read()
            except Exception as e:  # noqa: BLE001 - best effort, like stop() itself
                log.warning("no answer to a stop sent from another thread to %s: %s", self.transport.name, e)
        return owed

    def _send_unanswered(self, commands: Sequence[str]) -> None:
        """Send best-effort ``commands`` without waiting for answers (the console stopped answering). Never raises."""
        for command in commands:
            try:
                self.transport.write((command + "\r\n").encode("ascii"))
            except Exception as e:  # noqa: BLE001 - best effort, the caller has a real error
                log.warning("could not send %r to %s: %s", command, self.transport.name, e)
                return

    def stop(self, joint: int | None = None) -> None:
        """Stop ``joint`` (or every joint) now (``stop AXIS``). Never raises.

        When the console has stopped answering (a reply timed out), the stops are sent
        without waiting for answers: the URL's timeout is the whole wait for a fault,
        not that plus a wait per axis. From another thread during :meth:`step`, the stops
        are written at once and the stepping thread reads their answers (one reader: no
        answer is taken for another command's); that ``step()`` raises ``StepsUncertain``.
        """
        joints = sorted(self.axes) if joint is None else [int(joint)]
        if self.adapter.aside.send(*(f"stop {self._axis(j).id}\r\n".encode("ascii") for j in joints)):
            return
        with self._io:
            self._stop_here(joints)

    def _stop_here(self, joints: Sequence[int]) -> None:
        if getattr(self.transport, "silent", False):
            self._send_unanswered([f"stop {self._axis(j).id}" for j in joints])
            return
        for j in joints:
            ax = self._axis(j)
            try:
                with self._read_timeout(min(self.timeout, 0.5)):
                    ax.stop()
            except Exception as e:  # noqa: BLE001 - best effort, the caller has a real error
                log.warning("could not stop axis %s on %s: %s", ax.id, self.transport.name, e)
                try:
                    self.adapter.flush_read_buffer()
                except Exception:  # noqa: BLE001
                    pass

    # -- protocol -------------------------------------------------------------------------
    @property
    def info(self) -> DeviceInfo:
        """Model, URL, joints, axis map and version."""
        return DeviceInfo(
            url=self.url,
            model=f"Attocube ANC300 ({self.version})" if self.version else "Attocube ANC300",
            joints=tuple(sorted(self.axes)),
            extra={"axes": dict(self.axes), "version": self.version, "port": self.transport.name},
        )

    def settings(self) -> dict[str, object]:
        """Axis map, frequencies (Hz) and voltages (V) as last set or read (None = unknown)."""
        return {
            "axes": {str(j): a for j, a in self.axes.items()},
            "frequency_hz": {str(j): f for j, f in self._hz.items()},
            "voltage_v": {str(j): v for j, v in self._volt.items()},
            "timeout_s": self.timeout,
            "port": self.transport.name,
        }

    def close(self) -> None:
        """Stop every axis, ground it (mode ``gnd``), and release the transport.

        From another thread during :meth:`step`, the stops go out at once and the rest
        waits for that step to end (it reads the answers it is owed first).
        """
        if self.transport.closed:
            return
        try:
            self.stop()
            with self._io:
                self._ground()
        finally:
            self.transport.close()

    def _ground(self) -> None:
        if getattr(self.transport, "silent", False):  # not answering: ground every axis, waiting for no answer
            self._send_unanswered([f"setm {self._axis(j).id} gnd" for j in sorted(self.axes)])
            return
        for j in sorted(self.axes):
            ax = self._axis(j)
            try:
                with self._read_timeout(min(self.timeout, 0.5)):
                    ax.mode = "gnd"
            except Exception as e:  # noqa: BLE001
                log.warning("could not ground axis %s: %s", ax.id, e)

    def __enter__(self) -> ANC300:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _check_axes(axes: Mapping[int, int]) -> dict[int, int]:
    out = {}
    for j, a in axes.items():
        a = int(a)
        if not 1 <= a <= 7:
            raise ValueError(f"ANC300 axis of joint {j} must be in 1..7, got {a}")
        out[int(j)] = a
    if len(set(out.values())) != len(out):
        raise ValueError(f"two joints share an axis: {out}")
    return out


def _parse_axes(text: str) -> dict[int, int]:
    try:
        numbers: Sequence[int] = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(
            f"axes must be comma-separated axis numbers, e.g. 1,2,3; got {text!r}"
        ) from None
    return _check_axes({i + 1: a for i, a in enumerate(numbers)})


def _url_settings(url: str) -> tuple[dict[str, str], float, float, int, dict[int, int]]:
    """The options of ``url``, each checked, nothing opened: (the options, timeout s, delay s, baud, axes)."""
    opts = url_options(url, {"password", "axes", "timeout", "delay", "baud"})
    timeout = check_setting("timeout", opts.get("timeout", 2.0), *URL_TIMEOUT_S, "s")
    delay = check_setting("delay", opts.get("delay", 0.05), 0.0, 10.0, "s")
    baud = int(check_setting("baud", opts.get("baud", 38400), *URL_BAUD, integer=True))
    return opts, timeout, delay, baud, _parse_axes(opts.get("axes", "1,2,3"))


def check_url(url: str) -> None:
    """``ValueError`` naming an option of ``url`` the driver would refuse; nothing is opened or asked."""
    _url_settings(url)


def open_url(url: str) -> ANC300:
    """Open ``anc300://host[:7230][?options]`` or ``anc300:///dev/ttyUSB0[?options]``.

    See the module docstring for the options. Raises :class:`DeviceError` if the
    console cannot be reached or refuses the password, ``ValueError`` for a bad URL.
    """
    parts = urlsplit(url)
    opts, timeout, delay, baud, axes = _url_settings(url)
    password = unquote(opts.get("password") or secret_from_env(PASSWORD_ENV) or DEFAULT_PASSWORD)
    com = windows_com_port(parts.netloc)  # anc300://COM3: Windows' serial port where a host would stand
    if parts.hostname and not com:
        transport: Transport = SocketTransport(parts.hostname, parts.port or DEFAULT_PORT, timeout)
    elif com or parts.path:
        transport = SerialTransport(com or serial_port_name(parts.path), baudrate=baud, timeout=timeout)
    else:
        raise ValueError(
            f"{redact_url(url)!r}: give a host (anc300://192.168.1.2) or a port (anc300:///dev/ttyUSB0)"
        )
    try:
        return ANC300(
            transport, password=password, axes=axes, timeout=timeout, query_delay=delay, url=url
        )
    except Exception:
        transport.close()
        raise
