"""The NanoControl's legacy dialect: the ``;``-terminated command set of 2002-2015 public code.

Opened by :func:`stickslip.devices.nanocontrol.open_url` when the controller answers
``version;`` at 19200 baud (or with ``?dialect=legacy``). URL options of this dialect:
``hz`` (the stepping frequency assumed until a speed is set, default 1000),
``ack=0`` (the controller sends no replies: fire and forget, wait out each burst).

Protocol (what public code sends to this controller)
----------------------------------------------------
Commands are ASCII, terminated by ``;``, no newline::

    coarse A +N;        N signed coarse steps on channel A (|N| <= 65535 per command)
    speed A n;          speed level n on channel A (integer 1..15)
    amplitudepos A n;   amplitude of + steps, 1..80
    amplitudeneg A n;   amplitude of - steps, 1..80
    pause ms;           the controller waits ms milliseconds (1..65535)
    counterread;        the coarse step counters of all channels
    counterreset;       zero the counters
    version;            firmware identification
    stop;               stop all channels (newer firmware; sent only after a failed
                        coarse command, best-effort, or by stop() from another thread
                        during a step: its answer is then read by the stepping thread)

Assumptions about replies (no public source documents the old firmware's replies;
these follow the NanoControl's documented newer console, and are lenient):

* every command is answered, after it has been carried out, by one line ending in
  CR (a following LF is ignored): ``<status><TAB><message>`` with status ``o`` (ok),
  ``e`` (error) or ``i`` (information, e.g. a piezo voltage breakdown; logged as a
  warning, and the answer still follows);
* a printable line without the ``<status><TAB>`` prefix is taken as an ok answer
  whose message is the whole line, unless it starts with ``error``;
* ``counterread`` answers with whitespace-separated integers, one per channel A, B, ...;
* ``version`` answers the same text at any time as on opening: after an answer timed out,
  ``version;`` (or ``counterread;`` after an unanswered one) is sent before the next command
  and every line before its answer discarded, so a late answer is not taken for the next
  command's (no answer echoes its command); ``stop;`` goes at once;
* a reply with non-printable bytes is garbage: :class:`DeviceError`, and the joint is
  stopped;
* a ``coarse`` answer arrives once the steps are done, so each burst waits up to
  ``timeout + 1.5 |N| / f`` with ``f`` the stepping frequency of the channel;
* the speed levels' stepping frequencies are not published: :data:`SPEED_HZ` is a
  placeholder table (measure yours: time a burst of 10 000 steps) and can be passed in.

How to check them on your controller (``stickslip -vv`` logs every message with its time):

* answers, and their form: ``stickslip -vv where -d URL?dialect=legacy`` shows ``version;``
  answered (``<- b'o\\t...\\r'``) and the version; if nothing answers within the timeout, the
  firmware may never answer: ``?ack=0`` (fire and forget) opens it without answers;
* a ``coarse`` answered once its steps are done: in ``stickslip -vv move -d URL --joint 3
  --steps 2000``, ``<- b'o\\t\\r'`` follows ``-> coarse C +2000;`` by the burst's duration,
  2000 / f (2 s at 1000 Hz, as on ``python -m stickslip.sim.emulators --realtime 1``), when
  the stepping sound ends. An answer within milliseconds means the controller answers on
  receipt: the next burst would go out while this one still steps, and a failure's bounds
  and a stop's timing rest on the answer marking the end; report it before relying on moves;
* ``counterread`` answering one integer per channel: ``stickslip -vv`` after a timeout
  (``?timeout=0.001``) shows its answer when ``version;`` went unanswered;
* ``stop;`` (best-effort): Ctrl-C a long ``--steps`` move: the sound ends with it on firmware
  that knows ``stop;``; otherwise when the burst is done (the joint is left uncertain either way).

Every message sent and received is logged on logger ``"stickslip.devices.nanocontrol"``
(DEBUG level; ``logging.basicConfig(level=logging.DEBUG)`` shows it).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping

from ..base import DeviceError, DeviceInfo, StepsUncertain, check_setting, check_steps
from ..transport import StopAside, Transport
from ._common import DEFAULT_CHANNELS, log
from ._common import check_channels as _check_channels
from ._common import parse_reply as _parse_reply_text

__all__ = [
    "NanoControl",
    "SPEED_HZ",
    "AMPLITUDE_RANGE",
    "MAX_COARSE",
    "PAUSE_RANGE_MS",
    "DEFAULT_CHANNELS",
    "LEGACY_BAUD",
]

LEGACY_BAUD = 19200
"""The legacy dialect's baud rate (8N1), as public code of 2002-2015 opens the port."""

SPEED_HZ: dict[int, float] = {
    1: 1.0,
    2: 2.0,
    3: 5.0,
    4: 10.0,
    5: 20.0,
    6: 50.0,
    7: 100.0,
    8: 200.0,
    9: 500.0,
    10: 1000.0,
    11: 1500.0,
    12: 2000.0,
    13: 3000.0,
    14: 4000.0,
    15: 5000.0,
}
"""Speed level -> stepping frequency, Hz. A placeholder: calibrate it on your controller."""

AMPLITUDE_RANGE = (1, 80)
"""Allowed ``amplitudepos``/``amplitudeneg`` values (controller units), inclusive."""

MAX_COARSE = 65535
"""Largest |N| of one ``coarse`` command; longer moves are split."""

PAUSE_RANGE_MS = (1, 65535)
"""Allowed ``pause`` argument, ms, inclusive."""


class NanoControl:
    """A Kleindiek NanoControl driving an MM3A, as a :class:`~stickslip.devices.base.Controller`.

    Parameters
    ----------
    transport : Transport
        An open byte transport (serial port, socket, or a :class:`FakeTransport`).
    channels : mapping of int to str
        Channel letter (``A``-``D``) of each joint; default joints 1, 2, 3 -> A, B, C.
    timeout : float
        Time to wait for a reply beyond a burst's own duration, s.
    speed_hz : mapping of int to float
        Stepping frequency of each speed level, Hz (default :data:`SPEED_HZ`).
    nominal_hz : float
        Stepping frequency assumed for a channel whose speed was never set, Hz.
    ack : bool
        Whether the controller answers commands (default True).
    url : str
        The URL it was opened with (for :attr:`info`).
    query_version : bool
        Ask ``version;`` on opening (a quick check that something answers).

    Raises
    ------
    DeviceError
        If the controller does not answer ``version;`` within ``timeout``.
    """

    def __init__(
        self,
        transport: Transport,
        *,
        channels: Mapping[int, str] | None = None,
        timeout: float = 2.0,
        speed_hz: Mapping[int, float] | None = None,
        nominal_hz: float = 1000.0,
        ack: bool = True,
        url: str = "mm3a://",
        query_version: bool = True,
    ) -> None:
        self.transport = transport
        self.channels = _check_channels(channels or DEFAULT_CHANNELS)
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout!r}")
        self.timeout = float(timeout)
        self.speed_hz = dict(speed_hz or SPEED_HZ)
        if not nominal_hz > 0:
            raise ValueError(f"nominal_hz must be > 0 Hz, got {nominal_hz!r}")
        self.ack = ack
        self.url = url
        self._hz = {j: float(nominal_hz) for j in self.channels}
        self._speed: dict[int, int | None] = {j: None for j in self.channels}
        self._amp: dict[int, dict[str, int | None]] = {
            j: {"+": None, "-": None} for j in self.channels
        }
        self._lock = threading.RLock()  # one exchange at a time; a step() holds it throughout
        self._aside = StopAside(transport)  # a stop from another thread during a step(): written, answer read by it
        self._busy = False
        self.version = ""
        if query_version and ack:
            self.version = self.command("version")

    # -- the wire -----------------------------------------------------------------------
    def command(self, text: str, timeout: float | None = None) -> str:
        """Send ``text;`` and return the message of its answer (without the status).

        After a reply timed out, the line is first re-synchronised (``version;``, or
        ``counterread;`` after an unanswered one; their answers awaited, anything before
        them discarded: :meth:`~stickslip.devices.transport.Transport.resync`).

        Raises
        ------
        DeviceError
            On no answer within ``timeout`` (default :attr:`timeout`), an ``e`` answer,
            or garbage; the message says what was sent. If the re-synchronising query is
            not answered in time (``text`` is then not sent).
        """
        wire = f"{text};".encode("ascii")
        wait = self.timeout if timeout is None else timeout
        with self._lock:
            if self.ack and self.transport.silent:  # a reply timed out: its answer may still come, put the line in step
                queries = ((b"version;", self._is_version), (b"counterread;", self._is_counters))
                self.transport.resync(queries, (b"\r", b"\n"), f"NanoControl on {self.transport.name}", wait)
            log.debug("-> %s", wire.decode())
            stale = self._aside.write(wire)
            if stale.strip(b"\r\n\t "):  # the LF of a CRLF answer is no news
                log.warning("discarding unexpected bytes from %s: %r", self.transport.name, stale)
            if not self.ack:
                return ""
            while True:
                try:
                    raw = self.transport.read_until((b"\r", b"\n"), timeout=wait)
                except DeviceError as e:
                    raise DeviceError(
                        f"NanoControl on {self.transport.name} did not answer "
                        f"{wire.decode()!r}: {e}"
                    ) from None
                log.debug("<- %r", raw)
                line = raw.rstrip(b"\r\n")
                if not line.strip():
                    continue  # the LF of a CRLF, or an empty line
                status, message = _parse_reply(line, wire, self.transport.name)
                if status == "info":
                    log.warning("NanoControl says: %s (after %s)", message, wire.decode())
                    continue
                if status == "error":
                    raise DeviceError(
                        f"NanoControl on {self.transport.name} refused {wire.decode()!r}: {message}"
                    )
                return message

    def _is_version(self, line: bytes) -> bool:
        """Whether ``line`` is ``version;``'s answer: ok and the version read on opening (any ok message if
        none was read)."""
        try:
            status, message = _parse_reply(line.rstrip(b"\r\n"), b"version;", self.transport.name)
        except DeviceError:
            return False
        return status == "ok" and (message == self.version if self.version else bool(message))

    def _is_counters(self, line: bytes) -> bool:
        """Whether ``line`` is ``counterread;``'s answer: ok and one integer per channel."""
        try:
            status, message = _parse_reply(line.rstrip(b"\r\n"), b"counterread;", self.transport.name)
            values = [int(w) for w in message.split()]
        except (DeviceError, ValueError):
            return False
        return status == "ok" and len(values) >= len(self.channels)

    def _channel(self, joint: int) -> str:
        try:
            return self.channels[int(joint)]
        except (KeyError, ValueError, TypeError):
            raise ValueError(
                f"joint must be one of {sorted(self.channels)}, got {joint!r}"
            ) from None

    # -- settings -----------------------------------------------------------------------
    def set_speed(self, joint: int, level: int) -> None:
        """Set the speed level of ``joint`` (integer 1..15 in the default table; ``speed X n;``)."""
        ch = self._channel(joint)
        allowed = sorted(self.speed_hz)
        if isinstance(level, bool) or not isinstance(level, int) or level not in self.speed_hz:
            raise ValueError(
                f"speed level must be an integer in {allowed[0]}..{allowed[-1]}, got {level!r}"
            )
        self.command(f"speed {ch} {level}")
        self._speed[joint] = level
        self._hz[joint] = float(self.speed_hz[level])

    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint``, Hz: one of the speed table's frequencies.

        Raises ``ValueError`` naming the allowed frequencies for any other value
        (the NanoControl has discrete speed levels; nothing is rounded).
        """
        self._channel(joint)
        for level, f in self.speed_hz.items():
            if math.isclose(float(hz), f, rel_tol=1e-9):
                self.set_speed(joint, level)
                return
        allowed = ", ".join(f"{f:g}" for f in sorted(self.speed_hz.values()))
        raise ValueError(
            "the NanoControl steps at discrete speeds; frequency must be one of "
            f"{allowed} Hz, got {hz!r}"
        )

    def frequency(self, joint: int) -> float:
        """Stepping frequency of ``joint``, Hz (the nominal one until a speed is set)."""
        self._channel(joint)
        return self._hz[joint]

    def set_amplitude(
        self, joint: int, positive: int | None = None, negative: int | None = None
    ) -> None:
        """Set the step amplitude of ``joint`` for + and/or - steps (integers 1..80)."""
        ch = self._channel(joint)
        for name, value in (("positive", positive), ("negative", negative)):
            if value is not None:
                check_setting(f"{name} amplitude", value, *AMPLITUDE_RANGE, integer=True)
        if positive is not None:
            self.command(f"amplitudepos {ch} {positive}")
            self._amp[joint]["+"] = positive
        if negative is not None:
            self.command(f"amplitudeneg {ch} {negative}")
            self._amp[joint]["-"] = negative

    def pause(self, ms: int) -> None:
        """Let the controller wait ``ms`` milliseconds (integer 1..65535)."""
        lo, hi = PAUSE_RANGE_MS
        if isinstance(ms, bool) or not isinstance(ms, int) or not lo <= ms <= hi:
            raise ValueError(f"pause must be an integer number of ms in {lo}..{hi}, got {ms!r}")
        self.command(f"pause {ms}", timeout=self.timeout + ms / 1000.0)

    def counters(self) -> dict[int, int]:
        """The controller's coarse step counters, per joint (``counterread;``)."""
        message = self.command("counterread")
        try:
            values = [int(v) for v in message.replace(",", " ").split()]
        except ValueError:
            raise DeviceError(
                f"NanoControl on {self.transport.name}: cannot read counters from {message!r}"
            ) from None
        out = {}
        for joint, ch in self.channels.items():
            i = ord(ch) - ord("A")
            if i >= len(values):
                raise DeviceError(
                    f"NanoControl on {self.transport.name}: no counter for channel {ch} "
                    f"in {message!r}"
                )
            out[joint] = values[i]
        return out

    def reset_counters(self) -> None:
        """Zero the coarse step counters (``counterreset;``)."""
        self.command("counterreset")

    # -- motion -------------------------------------------------------------------------
    def step(self, joint: int, n: int) -> None:
        """Make ``n`` signed coarse steps on ``joint`` and return when the controller has done them.

        Bursts longer than :data:`MAX_COARSE` are split. ``n = 0`` sends nothing.
        If the controller fails to answer or answers garbage, the joint is sent a stop
        (best effort) and :class:`DeviceError` is raised. After a :meth:`stop` from another
        thread no further burst is sent and ``StepsUncertain`` is raised (the stopped
        burst made between none and all of its steps).
        """
        ch = self._channel(joint)
        remaining = check_steps(n)
        made = 0
        with self._lock:
            self._aside.begin()
            try:
                while remaining and not self._aside.owed:
                    chunk = max(-MAX_COARSE, min(MAX_COARSE, remaining))
                    _coarse(self, joint, ch, chunk)
                    if self._aside.owed:
                        raise StepsUncertain(
                            f"NanoControl on {self.transport.name}: 'coarse {ch} {chunk:+d};' was stopped by stop() "
                            "from another thread before it was answered: how many of its steps were made is not "
                            "known", made, made + chunk)
                    made += chunk
                    remaining -= chunk
            finally:
                _end_step(self)
            if remaining:
                raise StepsUncertain(f"NanoControl on {self.transport.name}: {remaining:+d} steps on channel {ch} "
                                     "were not sent: stop() was called from another thread", made, made)

    def stop(self, joint: int | None = None) -> None:
        """Stop all channels now (``stop;``: there is no per-channel stop). Never raises.

        A burst is over once the controller has answered it, so ``stop;`` is sent only
        while a burst may still be running (from another thread, or after a burst that
        failed or was interrupted); otherwise there is nothing to stop and nothing is sent.
        From another thread during :meth:`step` it is written at once, its answer read by
        the stepping thread (:class:`~stickslip.devices.transport.StopAside`).
        """
        if not self._aside.send(b"stop;") and (self._busy or not self.ack):
            self._send_stop()

    def _send_stop(self) -> None:
        try:
            log.debug("-> stop;")
            self._aside.write(b"stop;")
            if self.ack:
                try:
                    self.transport.read_available(quiet=0.02, limit=min(self.timeout, 0.2))
                except DeviceError:  # pragma: no cover - best effort
                    pass
        except DeviceError as e:
            log.warning("could not send stop to %s: %s", self.transport.name, e)
        finally:
            self._busy = False

    # -- protocol -----------------------------------------------------------------------
    @property
    def info(self) -> DeviceInfo:
        """Model, URL, joints, channel map and firmware version."""
        return DeviceInfo(
            url=self.url,
            model=f"Kleindiek NanoControl{f' ({self.version})' if self.version else ''}",
            joints=tuple(sorted(self.channels)),
            extra={
                "dialect": "legacy",
                "channels": dict(self.channels),
                "version": self.version,
                "port": self.transport.name,
                "frequency_hz": {self.channels[j]: f for j, f in sorted(self._hz.items())},
                "frequency_sent": all(v is not None for v in self._speed.values()),
            },
        )

    def settings(self) -> dict[str, object]:
        """Channel map, speed level, frequency (Hz), amplitudes (None = never set), timeout (s)."""
        return {
            "dialect": "legacy",
            "channels": {str(j): c for j, c in self.channels.items()},
            "speed_level": {str(j): s for j, s in self._speed.items()},
            "frequency_hz": {str(j): f for j, f in self._hz.items()},
            "amplitude_pos": {str(j): a["+"] for j, a in self._amp.items()},
            "amplitude_neg": {str(j): a["-"] for j, a in self._amp.items()},
            "timeout_s": self.timeout,
            "port": self.transport.name,
        }

    def close(self) -> None:
        """Release the transport.

        Nothing is moving then: every ``coarse`` has been answered once done, and a
        failed one was already followed by ``stop;``. So a normal session sends only
        the documented command set.
        """
        if not self.transport.closed:
            self.transport.close()

    def __enter__(self) -> NanoControl:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _coarse(dev: NanoControl, joint: int, ch: str, chunk: int) -> None:
    """One ``coarse`` burst of :meth:`NanoControl.step`; on a failure or Ctrl-C the joint is sent a stop."""
    duration = abs(chunk) / dev._hz[joint]
    dev._busy = True
    try:
        if dev.ack:
            dev.command(f"coarse {ch} {chunk:+d}", timeout=dev.timeout + 1.5 * duration)
        else:
            dev.command(f"coarse {ch} {chunk:+d}")
            _sleep(duration)
    except BaseException:  # a refused or unanswered burst, or Ctrl-C: stop the joint
        _end_step(dev)
        dev._send_stop()
        raise
    dev._busy = False


def _end_step(dev: NanoControl) -> None:
    """Leave :meth:`NanoControl.step`: read the answers to the stops another thread wrote meanwhile (best effort)."""
    if dev.ack:
        dev._aside.end_reading((b"\r", b"\n"), min(dev.timeout, 0.2))
    else:
        dev._aside.end()


def _sleep(seconds: float) -> None:
    import time

    time.sleep(seconds)


def _parse_reply(line: bytes, sent: bytes, port: str) -> tuple[str, str]:
    return _parse_reply_text(line, sent.decode("ascii", "replace"), port)
