"""Kleindiek NanoControl backend for the MM3A, in both of its dialects, over serial or TCP.

URLs (opened by :func:`open_url` through :func:`stickslip.devices.open_device`)::

    mm3a:///dev/ttyUSB0                      detect the dialect, then drive
    mm3a:///dev/ttyUSB0?dialect=console      the current console, 115200 baud
    mm3a:///dev/ttyUSB0?dialect=legacy       the 2002-2015 command set, 19200 baud
    mm3a:///dev/ttyUSB0?timeout=5&channels=CBA
    mm3a:///COM3 (or mm3a://COM3)            a serial port on Windows
    mm3a+socket://192.168.1.20:4001          a serial-over-network adapter (raw TCP)

Two dialects (docs/devices/nanocontrol.md lists the commands of each):

* ``console`` (:mod:`.console`, :class:`NanoControlConsole`): the controller sold
  today; CR-terminated commands at 115200 baud, speed profiles and timed ``go``/``stop``
  bursts;
* ``legacy`` (:mod:`.legacy`, :class:`NanoControl`): ``coarse A +N;`` at 19200 baud.

Detection (no ``dialect`` option) moves nothing: it sends ``version<CR>`` at 115200 baud
and waits up to ``min(timeout, 0.5 s)``; a well-formed ``o<TAB>...`` answer means the
console. Otherwise it switches to 19200 baud, sends ``;`` (which ends the probe for a
legacy controller that buffered it; its answer is read and dropped) and asks
``version;``; an answer means the legacy dialect. An ``e`` answer to either probe
(bytes left on the line) is retried once. Both probes and the result are logged
(logger ``stickslip.devices.nanocontrol``: INFO for the result, DEBUG for the bytes).

Query options: ``dialect`` (``console`` or ``legacy``), ``timeout`` (s to wait for an
answer, default 2), ``channels`` (channel letters of joints 1, 2, 3, default ``ABC``),
``baud`` (both dialects; default 115200 for the console, 19200 for legacy), ``hz``
(console: every channel's stepping frequency, an integer in 300..20000 Hz, default 1000;
legacy: the frequency assumed until a speed is set), console only: ``profile`` (the
scratch speed profile, 1..6, default 6), ``margin`` (s added to a burst before ``stop``,
default 0.05), ``finewithcoarse`` (``0``/``1`` for every channel, or four digits, sent on
opening); legacy only: ``ack=0`` (no answers; implies ``dialect=legacy``).
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import urlsplit

from ..base import URL_BAUD, URL_TIMEOUT_S, DeviceError, check_setting, url_options
from ..transport import SerialTransport, SocketTransport, Transport, serial_port_name
from ._common import DEFAULT_CHANNELS, check_channels, log, parse_console_reply
from .console import CONSOLE_BAUD, FREQUENCY_RANGE_HZ, MAX_BURST, PROFILES, NanoControlConsole, split_burst
from .legacy import (
    AMPLITUDE_RANGE,
    LEGACY_BAUD,
    MAX_COARSE,
    PAUSE_RANGE_MS,
    SPEED_HZ,
    NanoControl,
)

__all__ = [
    "NanoControl",
    "NanoControlConsole",
    "open_url",
    "check_url",
    "detect_dialect",
    "DIALECTS",
    "SPEED_HZ",
    "AMPLITUDE_RANGE",
    "MAX_COARSE",
    "PAUSE_RANGE_MS",
    "DEFAULT_CHANNELS",
    "CONSOLE_BAUD",
    "LEGACY_BAUD",
    "MAX_BURST",
    "split_burst",
]

DIALECTS = ("console", "legacy")
"""The command sets a NanoControl may speak; ``?dialect=`` picks one."""

_OPTIONS = frozenset(
    {"dialect", "timeout", "channels", "baud", "hz", "ack", "profile", "margin", "finewithcoarse"}
)
_PROBE_S = 0.5
"""Longest wait for the console's answer to the first probe, s (a device answers in ms)."""
_FLUSH_S = 0.25
"""Longest wait for a legacy controller's answer to the ``;`` that ends the console probe, s."""


def _probe_console(transport: Transport, wait: float) -> tuple[str | None, str]:
    """``(version, "")`` if ``version<CR>`` gets a console answer, else ``(None, why not)``."""
    why = ""
    for _ in range(2):
        transport.drain()
        log.debug("-> version<CR> (console probe)")
        transport.write(b"version\r")
        try:
            raw = transport.read_until(b"\r", timeout=wait)
        except DeviceError as e:
            return None, str(e)
        log.debug("<- %r", raw)
        try:
            status, message = parse_console_reply(raw[:-1], "version", transport.name)
        except DeviceError as e:
            return None, str(e)
        if status != "error":
            return message, ""
        why = f"answered {raw!r}"  # bytes left on the line before the probe: ask once more
    return None, why


def _probe_legacy(transport: Transport, timeout: float) -> tuple[str | None, str]:
    """``(version, "")`` if ``version;`` gets an answer, else ``(None, why not)``."""
    log.debug("-> ; (ends the console probe for a controller that buffered it)")
    try:
        transport.write(b";")
        flushed = transport.read_until((b"\r", b"\n"), timeout=min(timeout, _FLUSH_S))
        flushed += transport.read_available(quiet=0.02, limit=0.1)
        log.debug("<- %r (dropped)", flushed)
    except DeviceError:
        pass
    transport.silent = False  # the console probe's timeouts are not this dialect's: the line was just flushed
    dev = NanoControl(transport, timeout=timeout, query_version=False)
    why = ""
    for _ in range(2):
        try:
            return dev.command("version"), ""
        except DeviceError as e:
            why = str(e)
            if "refused" not in why:
                return None, why
    return None, why


def detect_dialect(transport: Transport, timeout: float = 2.0, baud: int | None = None) -> tuple[str, str]:
    """Which dialect the controller on ``transport`` speaks, and its firmware version.

    Sends only ``version`` (in both forms) and ``;``; nothing moves. ``baud`` (if given)
    is used for both probes, else each dialect's own. Returns ``(dialect, version)``.

    Raises
    ------
    DeviceError
        If neither probe is answered, naming the port and what each probe got.
    """
    console_baud = baud or CONSOLE_BAUD
    legacy_baud = baud or LEGACY_BAUD
    transport.set_baudrate(console_baud)
    version, why_console = _probe_console(transport, min(timeout, _PROBE_S))
    if version is not None:
        log.info("NanoControl on %s speaks the console dialect (%s)", transport.name, version)
        return "console", version
    log.info("NanoControl on %s: no console answer (%s); trying the legacy dialect", transport.name, why_console)
    transport.set_baudrate(legacy_baud)
    version, why_legacy = _probe_legacy(transport, timeout)
    if version is not None:
        log.info("NanoControl on %s speaks the legacy dialect (%s)", transport.name, version)
        return "legacy", version
    raise DeviceError(
        f"NanoControl on {transport.name} did not answer 'version' in either dialect "
        f"(console, 'version<CR>' at {console_baud} baud: {why_console}; legacy, 'version;' at "
        f"{legacy_baud} baud: {why_legacy}); is it on, connected, and is this its port? "
        "(?dialect=console or ?dialect=legacy skips detection)"
    )


def _fine_with_coarse(text: str) -> dict[str, bool]:
    digits = text.strip()
    if digits in ("0", "1"):
        digits *= 4
    if len(digits) != 4 or set(digits) - {"0", "1"}:
        raise ValueError(f"finewithcoarse must be 0, 1 or four digits 0/1 (A..D), got {text!r}")
    return {c: d == "1" for c, d in zip("ABCD", digits, strict=True)}


def open_url(url: str) -> NanoControl | NanoControlConsole:
    """Open ``mm3a:///dev/ttyUSB0[?options]`` or ``mm3a+socket://host:port[?options]``.

    See the module docstring for the options and how the dialect is detected. Raises
    :class:`DeviceError` if the port cannot be opened or nothing answers, ``ValueError``
    for a malformed URL or option (before the port is opened).
    """
    o = _url_settings(url)
    transport = _open_transport(url, o)
    try:
        dialect, version = o.dialect, None
        if dialect is None:
            dialect, version = detect_dialect(transport, o.timeout, o.baud)
        else:
            log.info("NanoControl on %s: %s dialect (from the URL)", transport.name, dialect)
        if dialect == "legacy":
            hz = float(o.hz_text) if o.hz_text is not None else 1000.0
            legacy = NanoControl(
                transport, channels=o.channels, timeout=o.timeout, nominal_hz=hz, ack=o.ack, url=url,
                query_version=version is None,
            )
            if version is not None:
                legacy.version = version
            return legacy
        console = NanoControlConsole(
            transport,
            channels=o.channels,
            timeout=o.timeout,
            hz=_console_hz(o.hz_text),
            profile=o.profile,
            margin=o.margin,
            url=url,
            version=version,
        )
        if o.fwc is not None:
            console.set_fine_with_coarse(o.fwc)
        return console
    except BaseException:
        transport.close()
        raise


@dataclass(frozen=True)
class _UrlSettings:
    """A NanoControl URL's options, checked (timeout and margin s, the frequency as given)."""

    dialect: str | None
    ack: bool
    timeout: float
    baud: int | None
    hz_text: str | None
    profile: int
    margin: float
    fwc: dict[str, bool] | None
    channels: dict[int, str]


def _url_settings(url: str) -> _UrlSettings:
    """The options of ``url``, each checked before any port is opened (``ValueError`` naming it)."""
    opts = url_options(url, _OPTIONS)
    dialect = opts.get("dialect", "").lower() or None
    if dialect is not None and dialect not in DIALECTS:
        raise ValueError(f"dialect must be one of {', '.join(DIALECTS)}, got {opts['dialect']!r}")
    ack = opts.get("ack", "1").lower() not in ("0", "no", "false", "off")
    if not ack:
        if dialect == "console":
            raise ValueError("ack=0 is a legacy-dialect option: the console always answers")
        dialect = "legacy"  # nothing answers, so nothing can be detected
    timeout = check_setting("timeout", opts.get("timeout", 2.0), *URL_TIMEOUT_S, "s")
    baud = int(check_setting("baud", opts["baud"], *URL_BAUD, integer=True)) if "baud" in opts else None
    hz_text = opts.get("hz")
    profile = int(check_setting("profile (the scratch speed profile)", opts.get("profile", 6), min(PROFILES),
                                max(PROFILES), integer=True))
    margin = check_setting("margin", opts.get("margin", 0.05), 1e-3, 10.0, "s")
    fwc = _fine_with_coarse(opts["finewithcoarse"]) if "finewithcoarse" in opts else None
    if dialect == "console":
        _console_hz(hz_text)  # refuse a bad frequency before opening the port
    letters = opts.get("channels", "ABC")
    if not letters.isalpha():  # 'A,B,C' (as SmarAct's channels and the ANC300's axes are written) read ',' as one
        raise ValueError(f"channels is the channel letters of joints 1, 2, 3 written together, e.g. ABC or CBA; "
                         f"got {letters!r}")
    channels = check_channels({i + 1: c for i, c in enumerate(letters)})
    return _UrlSettings(dialect, ack, timeout, baud, hz_text, profile, margin, fwc, channels)


def check_url(url: str) -> None:
    """``ValueError`` naming an option of ``url`` the driver would refuse; nothing is opened or asked."""
    _url_settings(url)


def _open_transport(url: str, o: _UrlSettings) -> Transport:
    """The serial port (``mm3a://``) or socket (``mm3a+socket://``) of ``url``, opened."""
    parts = urlsplit(url)
    if parts.scheme == "mm3a+socket":
        if not parts.hostname or not parts.port:
            raise ValueError(f"{url!r}: give host and port, e.g. mm3a+socket://192.168.1.20:4001")
        return SocketTransport(parts.hostname, parts.port, timeout=o.timeout)
    if parts.scheme == "mm3a":
        port = serial_port_name(parts.path or parts.netloc)
        if not port:
            raise ValueError(f"{url!r}: give the serial port, e.g. mm3a:///dev/ttyUSB0")
        first = o.baud or (LEGACY_BAUD if o.dialect == "legacy" else CONSOLE_BAUD)
        return SerialTransport(port, baudrate=first, timeout=o.timeout)
    raise ValueError(
        f"not a NanoControl URL: {url!r} (use mm3a:///dev/ttyUSB0 or mm3a+socket://host:port)"
    )


def _console_hz(text: str | None) -> int:
    if text is None:
        return 1000
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"hz must be an integer in 300..20000 Hz, got {text!r}") from None
    lo, hi = FREQUENCY_RANGE_HZ
    if not (value.is_integer() and lo <= value <= hi):
        raise ValueError(f"hz must be an integer in {lo}..{hi} Hz for the console dialect, got {text!r}")
    return int(value)
