"""The one interface every stick-slip controller backend implements.

Nothing above this layer knows which backend it talks to: traverses, planning-driven
moves and the demo take a :class:`Controller` and nothing else. Backends are opened
from a URL by :func:`open_device`; the scheme picks the backend::

    sim://                      the simulated MM3A (default)
    sim://?seed=3&day=2026-11-22
    mm3a:///dev/ttyUSB0         Kleindiek NanoControl over a serial port
    anc300://host[:7230]        Attocube ANC300
    smaract-mcs:///dev/ttyUSB0  SmarAct MCS (step mode) on a serial port
    smaract-mcs2://host         SmarAct MCS2 (step mode)

Backends register a factory with :func:`register_backend`; the registry imports
backend modules lazily so optional extras (pyserial, pymeasure) are needed only by
the URLs that use them.
"""

from __future__ import annotations

import importlib
import logging
import math
import numbers
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable
from urllib.parse import parse_qs, urlsplit

__all__ = [
    "Controller",
    "ControllerProxy",
    "PoseSettable",
    "KnowsTruePosition",
    "VirtualClock",
    "HasMicrophone",
    "DeviceInfo",
    "DeviceError",
    "StepsUncertain",
    "BurstStopped",
    "DrivenElsewhere",
    "BACKENDS",
    "register_backend",
    "open_device",
    "query_options",
    "device_key",
    "controller_of",
    "DEFAULT_PORTS",
    "windows_com_port",
    "check_setting",
    "check_device_url",
    "check_steps",
    "url_options",
    "redact_url",
    "command_url",
    "redact_text",
    "RedactSecrets",
    "RedactText",
    "SECRET_OPTIONS",
    "URL_TIMEOUT_S",
    "URL_BAUD",
    "NO_HOST_FORMS",
    "URL_CHECKS",
]

URL_TIMEOUT_S = (0.001, 3600.0)
"""A device URL's ``timeout`` option, s: below 1 ms nothing answers; beyond an hour a fault is a hang (and ``inf``
overflowed the socket's own timeout)."""
URL_BAUD = (50, 4_000_000)
"""A device URL's ``baud`` option, an integer: the slowest rate serial ports offer and the fastest USB-serial
adapters' (FTDI's high-speed parts run 3 Mbaud; the controllers supported here use 9600-115200)."""

SECRET_OPTIONS = frozenset({"password", "passwd", "pw", "pass", "secret", "token"})
"""URL query options whose values are secrets: never stored, logged, printed or echoed."""

_SECRET_QUERY = re.compile(
    r"(?i)(^|[?&;])(" + "|".join(sorted(SECRET_OPTIONS)) + r")=([^&;#]*)"
)


def redact_url(url: str) -> str:
    """``url`` with every secret (``user:PASSWORD@``, ``?password=...``) replaced by ``***``.

    Used at every boundary a URL crosses (error messages, logs, the database, JSON
    output). Never raises, even on a malformed URL.

    >>> redact_url("anc300://admin:hunter2@10.0.0.2:7230?password=123&axes=1,2,3")
    'anc300://admin:***@10.0.0.2:7230?password=***&axes=1,2,3'
    >>> redact_url("admin:hunter2@10.0.0.2")
    'admin:***@10.0.0.2'

    A password written unencoded may hold ``@``, ``/``, ``?`` or ``#``: it runs to the URL's last ``@``
    (a path or option holding an ``@`` after a ``host:port`` is redacted with it, the safe side):

    >>> redact_url("anc300://admin:pa/ss@word@10.0.0.2:7230")
    'anc300://admin:***@10.0.0.2:7230'
    """
    text = _USERINFO_AFTER_SCHEME.sub(r"\1:***@", str(url))
    text = _USERINFO_NO_SCHEME.sub(r"\1:***@", text)
    return _SECRET_QUERY.sub(lambda m: f"{m.group(1)}{m.group(2)}=***", text)


_SHELL_SAFE = re.compile(r"[A-Za-z0-9_@%+=:,./-]+")


def command_url(url: str) -> str:
    """``url``, its secrets redacted, as one word of a command a user copies into a shell.

    As it is when it holds only characters no shell (bash, cmd, PowerShell) treats specially;
    else in double quotes, which all three read as one word: ``sim://?seed=4&day=1`` unquoted
    would run ``stickslip ... -d sim://?seed=4`` in the background in bash, and ``***`` would glob.

    >>> command_url("mm3a:///dev/ttyUSB0")
    'mm3a:///dev/ttyUSB0'
    >>> command_url("sim://?seed=4&day=2026-11-22")
    '"sim://?seed=4&day=2026-11-22"'
    """
    text = redact_url(url)
    return text if _SHELL_SAFE.fullmatch(text) else '"' + text.replace('"', "%22") + '"'


_USERINFO_AFTER_SCHEME = re.compile(r"(://[^/@?#:\s]*):\S*@")
"""``user:PASSWORD@`` after a scheme's ``//``: the password to the last ``@`` before a space."""
_USERINFO_NO_SCHEME = re.compile(r"^([^/@?#:\\\s]*):(?![/\\])\S*@")
"""``user:PASSWORD@`` at the start of a URL written without a scheme; not a Windows path (``C:\\data\\a@b.csv``,
``C:/data/a@b.csv``: a drive letter's colon is followed by a slash)."""


def _malformed(url: str, why: str) -> str:
    """The message for a device URL that cannot be read: ``why`` (urllib's reason, which may quote a piece of
    the URL's user part, e.g. a password's first characters read as a port) only where the URL holds no secret."""
    if _USERINFO_AFTER_SCHEME.search(url) or _USERINFO_NO_SCHEME.search(url):
        why = ("its user:password@ part hides the host (a password holding @ / ? # must be percent-encoded: "
               "/ as %2F, @ as %40)")
    return f"malformed device URL {redact_url(url)!r}: {why}"


_URL_IN_TEXT = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:(?://|[^\s'\"<>]*@)[^\s'\"<>]*")
_SECRET_IN_TEXT = re.compile(r"(?i)(?<![A-Za-z0-9_])(" + "|".join(sorted(SECRET_OPTIONS)) + r")=([^\s&;#'\"]*)")


def redact_text(text: str) -> str:
    """``text`` (a message, a log line, a stored note) with each device URL in it redacted.

    Every ``scheme://...`` in the text goes through :func:`redact_url`, and so does a
    ``password=...`` (or ``token=``, ...) outside a URL: the one redaction, wherever a URL
    was pasted into a message. Never raises.

    >>> redact_text("on anc300://HOST:7230?password=hunter2 measure with '--device anc300://u:pw@h'")
    "on anc300://HOST:7230?password=*** measure with '--device anc300://u:***@h'"
    >>> redact_text("token=abc and 5 um")
    'token=*** and 5 um'
    """
    text = str(text)
    if "=" not in text and "@" not in text:
        return text
    text = _URL_IN_TEXT.sub(lambda m: redact_url(m.group(0)), text)
    return _SECRET_IN_TEXT.sub(lambda m: f"{m.group(1)}=***", text)


class RedactSecrets(logging.Filter):
    """A logging filter that replaces given secret strings in every record by ``***``.

    Attach it to a logger that may see a secret (a driver that writes a password to the
    wire and logs what it writes). The record's message is rendered, redacted and frozen.
    """

    def __init__(self, *secrets: str) -> None:
        super().__init__()
        self.secrets = [s for s in secrets if s]

    def filter(self, record: logging.LogRecord) -> bool:
        msg = record.getMessage()
        for s in self.secrets:
            msg = msg.replace(s, "***")
        record.msg, record.args = msg, None
        return True


class RedactText(logging.Filter):
    """A logging filter that passes every record's message through :func:`redact_text` (URLs, ``password=...``).

    Attached to every handler the command line installs (``-v``, ``--log-file``), so no
    log line shows a secret that reached a message in a URL.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg, record.args = redact_text(record.getMessage()), None
        return True


def secret_from_env(name: str) -> str | None:
    """The secret in environment variable ``name`` (``None`` if unset or empty)."""
    value = os.environ.get(name)
    return value or None


class DeviceError(RuntimeError):
    """A controller refused, timed out, or could not be opened. The message says which and why."""


class StepsUncertain(DeviceError):
    """A step command failed part-way, and the controller says how far it may have gone.

    Raised by backends that know more than "the burst failed": ``made`` signed steps
    were certainly made by the failed ``step()`` call (bursts stopped on time), and at
    most ``at_most`` (same sign; ``None`` if a channel may still be driving, so only the
    joint's end stop bounds it). :func:`stickslip.procedures.move.drive` keeps the
    position of ``made`` steps and marks the joint uncertain up to ``at_most``.
    """

    def __init__(self, message: str, made: int, at_most: int | None) -> None:
        super().__init__(message)
        self.made = int(made)
        self.at_most = None if at_most is None else int(at_most)


class DrivenElsewhere(StepsUncertain):
    """Another program drives the joint's channel (the vendor's software, hand control): nothing of ours was sent
    of the failed burst, and the joint goes wherever that program takes it, either way.

    :func:`stickslip.procedures.move.drive` keeps the ``made`` steps and marks the joint
    uncertain over its whole range (not only up to the end stop of the burst's direction:
    the other program's direction is not known).
    """

    def __init__(self, message: str, made: int):
        super().__init__(message, made, None)


class BurstStopped(StepsUncertain):
    """A stop command ended a burst early, and the controller knows exactly how many steps it made.

    ``made == at_most``: :func:`stickslip.procedures.move.drive` keeps the position of the
    steps made and no uncertainty. Raised by a controller that counts its steps as it
    makes them (the simulator in real time, :mod:`stickslip.sim.realtime`) when
    :meth:`Controller.stop` comes from another thread during :meth:`Controller.step`.
    """

    def __init__(self, message: str, made: int):
        super().__init__(message, made, made)


@dataclass(frozen=True)
class DeviceInfo:
    """What a controller says about itself.

    Attributes
    ----------
    url : str
        The URL it was opened with.
    model : str
        Human-readable model, e.g. ``"simulated MM3A"`` or ``"Kleindiek NanoControl 3.1"``.
    joints : tuple of int
        The joints it drives (1, 2, 3 for an MM3A).
    extra : dict
        Backend-specific details (firmware version, channel map, ...).
    identity : str or None
        Which controller this is, as the controller itself tells it (``"MCS2 serial MCS2-00001234"``,
        ``"MCS system id 3015"``, the simulator's ``"simulator seed 0"``); ``None``: it cannot tell (the
        ANC300 and NanoControl drivers know only a firmware version). Compared with the one kept beside the
        positions at every opening (:mod:`stickslip.devices.identity`): a field, not an ``extra`` entry,
        because its absence must mean "cannot tell" for every backend, and wrappers that forward ``info``
        carry it unchanged.
    """

    url: str
    model: str
    joints: tuple[int, ...] = (1, 2, 3)
    extra: dict[str, object] = field(default_factory=dict)
    identity: str | None = None


@runtime_checkable
class Controller(Protocol):
    """A stick-slip controller: step a joint by a signed number of steps, stop, report settings.

    Step counts are signed (``+`` = joint coordinate increasing, docs/design.md §2).
    Frequencies are in Hz. Every setter validates its argument and raises
    ``ValueError`` naming the allowed range; nothing is clipped silently.

    Optional: a backend on a virtual clock (the simulator) exposes ``clock_s``, the
    device time in s; :func:`stickslip.procedures.traverse.measure_traverse` then keeps its audio
    in step with it (otherwise it uses the wall clock).
    """

    @property
    def info(self) -> DeviceInfo:
        """Model, URL and joints of this controller."""
        ...

    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint`` (Hz). Raises ``ValueError`` out of range."""
        ...

    def frequency(self, joint: int) -> float:
        """The stepping frequency of ``joint`` (Hz)."""
        ...

    def step(self, joint: int, n: int) -> None:
        """Command ``n`` signed steps on ``joint`` at its frequency; returns once they are issued.

        The burst takes ``|n| / frequency`` seconds on the device. Raises
        :class:`DeviceError` if the controller does not accept the command.
        """
        ...

    def stop(self, joint: int | None = None) -> None:
        """Stop ``joint`` (or all joints) now."""
        ...

    def settings(self) -> dict[str, object]:
        """Current settings (frequencies in Hz, amplitudes in V, channel map, ...)."""
        ...

    def close(self) -> None:
        """Stop everything and release the transport."""
        ...


class ControllerProxy:
    """A :class:`Controller` that hands every call to ``inner``: a wrapper overrides only what it changes (the
    rig's STOP read before each burst, an arm's channel map), and whatever else the controller has (a pose to
    set, a clock, a microphone) is the controller's own."""

    def __init__(self, inner: Controller) -> None:
        self._inner = inner

    @property
    def info(self) -> DeviceInfo:
        return self._inner.info

    def set_frequency(self, joint: int, hz: float) -> None:
        self._inner.set_frequency(joint, hz)

    def frequency(self, joint: int) -> float:
        return self._inner.frequency(joint)

    def step(self, joint: int, n: int) -> None:
        self._inner.step(joint, n)

    def stop(self, joint: int | None = None) -> None:
        self._inner.stop(joint)

    def settings(self) -> dict[str, object]:
        return self._inner.settings()

    def close(self) -> None:
        self._inner.close()

    def __getattr__(self, name: str) -> Any:
        inner = self.__dict__.get("_inner")
        if inner is None:
            raise AttributeError(name)
        return getattr(inner, name)

# -- capabilities: what some controllers can do beyond the interface ---------------------------
# Declared as protocols so that code asks ``isinstance(dev, PoseSettable)`` of a type the
# checker knows, instead of probing attribute names. The simulator has them all; a real
# controller has none (its pose is set by hand, its truth is unknown, it runs on wall time).


@runtime_checkable
class PoseSettable(Protocol):
    """Capability: the controller can be placed in a pose (joints rad, rad, m; tilt rad)."""

    def set_pose(
        self,
        q1: float | None = None,
        q2: float | None = None,
        q3: float | None = None,
        theta: float | None = None,
        psi: float | None = None,
    ) -> None:
        """Place the joints and tilt the base; ``None`` keeps a value."""
        ...


@runtime_checkable
class KnowsTruePosition(Protocol):
    """Capability: the controller knows where a joint really is (a simulator's truth)."""

    def position(self, joint: int) -> float:
        """True position of ``joint`` (rad or m)."""
        ...


@runtime_checkable
class VirtualClock(Protocol):
    """Capability: the controller runs on its own clock, which audio and timing must follow."""

    clock_s: float
    """Device time, s."""


@runtime_checkable
class HasMicrophone(Protocol):
    """Capability: the controller renders what a microphone beside the arm hears."""

    sample_rate: int
    """Sample rate of the rendered sound, Hz."""

    def microphone(self, block: int = 1024, silent: bool = False) -> Callable[[], list[Any]]:
        """A virtual microphone starting now: calling it returns the blocks recorded since the last call."""
        ...


Factory = Callable[[str], Controller]

BACKENDS: dict[str, str | Factory] = {
    # scheme -> factory, or "module:function" imported on first use
    "sim": "stickslip.sim.urls:open_url",
    "sim+physics": "stickslip.sim.urls:open_url",
    "mm3a": "stickslip.devices.nanocontrol:open_url",
    "mm3a+socket": "stickslip.devices.nanocontrol:open_url",
    "anc300": "stickslip.devices.anc300:open_url",
    "smaract-mcs": "stickslip.devices.smaract:open_mcs",
    "smaract-mcs+socket": "stickslip.devices.smaract:open_mcs",
    "smaract-mcs2": "stickslip.devices.smaract:open_mcs2",
}


URL_CHECKS: dict[str, str | Callable[[str], object]] = {
    # scheme -> its driver's check of a URL's options (ValueError), nothing opened; imported on first use
    "mm3a": "stickslip.devices.nanocontrol:check_url",
    "mm3a+socket": "stickslip.devices.nanocontrol:check_url",
    "anc300": "stickslip.devices.anc300:check_url",
    "smaract-mcs": "stickslip.devices.smaract:check_mcs_url",
    "smaract-mcs+socket": "stickslip.devices.smaract:check_mcs_url",
    "smaract-mcs2": "stickslip.devices.smaract:check_mcs2_url",
}
"""Each scheme's check of its URL's options, run by :func:`check_device_url` (a scheme not here: at opening)."""

NO_HOST_FORMS: dict[str, str] = {
    # scheme -> what a URL of it names, for one that names nothing (a scheme not here gets the general advice)
    "mm3a": "give the serial port: mm3a:///dev/ttyUSB0 (mm3a://COM3 on Windows; a serial-over-network adapter is "
    "mm3a+socket://host:port)",
    "mm3a+socket": "give the adapter's network address and port: mm3a+socket://192.168.1.20:4001",
    "anc300": "give its network address (anc300://192.168.1.2) or its serial port (anc300:///dev/ttyUSB0)",
    "smaract-mcs": "give the serial port: smaract-mcs:///dev/ttyUSB0 (smaract-mcs://COM3 on Windows; an MCS's "
    "network interface is smaract-mcs+socket://host)",
    "smaract-mcs+socket": "give its network address: smaract-mcs+socket://192.168.1.5",
    "smaract-mcs2": "give its network address: smaract-mcs2://192.168.1.200 (the MCS2 is reached over TCP only)",
}
"""The form each scheme's URL takes, said to a URL of that scheme that names no host and no port."""


def register_backend(
    scheme: str, factory: str | Factory, check: str | Callable[[str], object] | None = None
) -> None:
    """Make ``scheme://...`` URLs open with ``factory(url)`` (a callable or ``"module:function"``).

    ``check(url)``: the driver's check of a URL's options that opens nothing (``ValueError``
    with the reason), run by :func:`check_device_url` before a URL is used or stored
    (:data:`URL_CHECKS`); without one only the URL's shape is checked.
    """
    BACKENDS[scheme] = factory
    if check is not None:
        URL_CHECKS[scheme] = check


def check_device_url(url: str) -> str:
    """``url`` if it names a device that could be opened; ``ValueError`` (without a secret) if it never can.

    Checked without opening anything: a scheme with ``//`` (:func:`url_scheme`) that a
    backend is registered for, a URL that parses, a port in 1..65535, a host name DNS
    could carry (labels of 1 to 63 characters, at most 253 in all), a host or a
    port for anything but the simulator, no option given twice (which one would
    the device take?), and each option as its driver takes it (:data:`URL_CHECKS`). A URL that
    passes may still fail to open (nothing answers there); one that fails never would,
    and is neither opened nor stored.

    >>> check_device_url("anc300://10.0.0.2:7230?axes=1,2,3")
    'anc300://10.0.0.2:7230?axes=1,2,3'
    >>> check_device_url("anc300://h:99999")
    Traceback (most recent call last):
    ...
    ValueError: malformed device URL 'anc300://h:99999': the port must be a number in 1..65535
    >>> check_device_url("sim://?seed=1&seed=2")
    Traceback (most recent call last):
    ...
    ValueError: device URL 'sim://?seed=1&seed=2' gives the option 'seed' twice: give it once
    """
    scheme = url_scheme(url)
    if BACKENDS.get(scheme) is None:  # a variant (mm3a+socket) is registered as such: anc300+x is no URL
        known = ", ".join(f"{s}://" for s in sorted(BACKENDS))
        raise ValueError(f"unknown device URL scheme {scheme!r} in {redact_url(url)!r} (known: {known})")
    try:
        parts = urlsplit(url)
        port = parts.port
        host = parts.hostname
    except ValueError:
        raise ValueError(_malformed(url, "the port must be a number in 1..65535")) from None
    if port == 0:
        raise ValueError(f"malformed device URL {redact_url(url)!r}: the port must be a number in 1..65535")
    query_options(parts.query, url)
    if not scheme.startswith("sim") and not (host or parts.path.strip("/")):
        form = NO_HOST_FORMS.get(
            scheme, f"give the serial port ({scheme}:///dev/ttyUSB0) or, where the controller has one, its network "
            "address"
        )
        raise ValueError(f"device URL {redact_url(url)!r} names no host and no port: {form}")
    if host and not (host.startswith("[") or ":" in host):  # a name (or IPv4 address), not an IPv6 address
        labels = host.rstrip(".").split(".")
        if len(host) > 253 or any(not 1 <= len(label) <= 63 for label in labels):
            raise ValueError(
                f"the host name in {redact_url(url)[:80]!r} cannot exist: a host name has labels of 1 to 63 "
                f"characters between its dots, at most 253 in all (this one: {len(host)}, its longest label "
                f"{max(map(len, labels))})"
            )
    _check_options(scheme, url)
    return url


def _check_options(scheme: str, url: str) -> None:
    """The driver's check of ``url``'s options (:data:`URL_CHECKS`): its ``ValueError``, without a secret."""
    check = URL_CHECKS.get(scheme)
    if check is None:
        return
    if isinstance(check, str):
        mod_name, func_name = check.split(":")
        try:
            check = getattr(importlib.import_module(mod_name), func_name)
        except ImportError:  # said when the device is opened (the backend could not be loaded)
            return
    try:
        check(url)
    except ValueError as e:
        raise ValueError(redact_text(str(e))) from None


def query_options(query: str, url: str, kind: str = "device") -> dict[str, str]:
    """The options of a ``kind`` URL's ``query``, each given once; ``ValueError`` (without a secret) naming an
    option given twice, since which of the two to take is not for us to guess."""
    given = parse_qs(query, keep_blank_values=True)
    twice = sorted(k for k, v in given.items() if len(v) > 1)
    if twice:
        raise ValueError(f"{kind} URL {redact_url(url)!r} gives the option {twice[0]!r} twice: give it once")
    return {k: v[0] for k, v in given.items()}


def open_device(url: str = "sim://") -> Controller:
    """Open the controller a URL names.

    Raises :class:`DeviceError` for an unknown scheme or a device that cannot be opened,
    ``ValueError`` for a malformed URL or option (:func:`check_device_url`); messages
    never contain a secret.
    """
    scheme = url_scheme(url)
    base_scheme = scheme.split("+", 1)[0]
    factory = BACKENDS.get(scheme) or BACKENDS.get(base_scheme)
    if factory is None:
        known = ", ".join(f"{s}://" for s in sorted(BACKENDS))
        raise DeviceError(
            f"unknown device URL scheme {scheme!r} in {redact_url(url)!r} (known: {known})"
        )
    check_device_url(url)
    if isinstance(factory, str):
        mod_name, func_name = factory.split(":")
        try:
            module = importlib.import_module(mod_name)
        except ImportError as e:
            raise DeviceError(f"the backend for {scheme}:// could not be loaded: {e}") from e
        factory = getattr(module, func_name)
    try:
        return factory(url)
    except (DeviceError, ValueError) as e:
        raise type(e)(redact_text(str(e))) from None  # URL by URL: the text after a secret option is kept


def url_scheme(url: str) -> str:
    """The scheme of a device URL (``"sim"``, ``"mm3a"``, ...); ``ValueError`` when it names none.

    A bare port (``/dev/ttyUSB0``, ``COM3``) or an empty URL is refused rather than read
    as ``sim://``: the simulator must never answer in a real arm's place. The message
    says how to write the URL and never contains a secret.
    """
    try:
        scheme = urlsplit(url).scheme
    except ValueError as e:
        raise ValueError(_malformed(url, str(e))) from None
    if scheme in BACKENDS and "://" not in url:  # sim: or mm3a:/dev/ttyUSB0: the // is missing
        rest = url.split(":", 1)[1]
        rest = rest if rest.startswith("/") else rest.lstrip("/")  # a path keeps its own slash: mm3a:///dev/...
        raise ValueError(f"device URL {redact_url(url)!r} lacks the // after {scheme}: write {scheme}://{redact_url(rest)}")
    if not scheme or "://" not in url:
        raise ValueError(
            f"device URL {redact_url(url)!r} has no scheme: write mm3a://{_port_path(url)} for a "
            "NanoControl on that port, anc300://HOST for an ANC300, or sim:// for the simulator"
        )
    return scheme


def _port_path(url: str) -> str:
    """A bare serial port as it goes after ``mm3a://`` (``/dev/ttyUSB0``, ``COM3``), for the hint."""
    return redact_url(url).strip() or "/dev/ttyUSB0"


_WINDOWS_COM = re.compile(r"/?(COM[0-9]+)", re.IGNORECASE)


def windows_com_port(text: str) -> str | None:
    """``COM3`` of ``COM3`` or ``/COM3`` (any case), else ``None``."""
    m = _WINDOWS_COM.fullmatch(text)
    return m.group(1) if m else None


def device_key(url: str) -> str:
    """The name a device's data is kept under: its URL without options.

    Options such as ``?timeout=5`` (or an ANC300 password) do not change which arm is at
    the other end and are never stored. For ``sim://`` the ``seed`` picks the simulated
    arm and is kept; its ``day`` is a session, not an arm, and is dropped.

    >>> device_key("anc300://192.168.1.2:7230?password=123456")
    'anc300://192.168.1.2:7230'
    >>> device_key("sim://?seed=3&day=2026-11-22")
    'sim://?seed=3'
    >>> device_key("sim://?seed=0"), device_key("sim://?physics=1&seed=2")
    ('sim://', 'sim+physics://?seed=2')
    >>> device_key("anc300://admin:secret@[fe80::1]:7230")
    'anc300://[fe80::1]:7230'
    >>> device_key("mm3a:///COM3"), device_key("mm3a://COM3?timeout=5")
    ('mm3a://com3', 'mm3a://com3')

    A Windows serial port is one key however it is written (``COM3``, ``com3``, ``/COM3``:
    Windows' port names know no case); a device file is kept as written (``/dev/ttyUSB0``
    and a ``/dev/serial/by-id/`` link to it are two keys: the link is the one that names
    the same controller after a reboot).

    A user name or password in the URL is dropped too. Raises ``ValueError`` (without the
    secret) for a malformed URL such as ``anc300://[::1``.
    """
    try:
        parts = urlsplit(url or "sim://")
        scheme = parts.scheme or "sim"
        if scheme == "sim" or scheme.startswith("sim+"):
            return _sim_key(scheme, parse_qs(parts.query))
        host = parts.hostname or ""
        if ":" in host:
            host = f"[{host}]"
        port = f":{parts.port}" if parts.port is not None else ""
    except ValueError as e:
        raise ValueError(_malformed(url, str(e))) from None
    com = windows_com_port(parts.path) if not host and not port else None
    if com is not None:  # mm3a:///COM3 is mm3a://COM3, whose host urlsplit gives in lower case
        return f"{scheme}://{com.lower()}"
    return f"{scheme}://{host}{port}{parts.path}"


DEFAULT_PORTS: dict[str, int] = {"anc300": 7230, "smaract-mcs+socket": 5000, "smaract-mcs2": 55551}
"""The TCP port each network scheme's driver opens when its URL gives none (``anc300.DEFAULT_PORT``,
``smaract.mcs.TCP_PORT``, ``smaract.mcs2.TCP_PORT``)."""


def controller_of(url: str) -> str:
    """The controller a device URL (or key) reaches: its :func:`device_key` with the scheme's default port
    written out and no ``/`` after a host.

    Two keys with one ``controller_of`` are one controller written two ways: one device, whose rows,
    kept positions and lock are stored under this name (:func:`stickslip.storage.schema.stored_device`;
    docs/storage.md). ``ValueError`` for a malformed URL.

    >>> controller_of("anc300://h"), controller_of("anc300://H:7230/"), controller_of("anc300://COM3")
    ('anc300://h:7230', 'anc300://h:7230', 'anc300://com3')
    """
    key = device_key(url)
    parts = urlsplit(key)
    host = parts.hostname
    if not host or key.startswith("sim") or windows_com_port(host) is not None:
        return key
    port = parts.port or DEFAULT_PORTS.get(parts.scheme)
    host = f"[{host}]" if ":" in host else host
    return f"{parts.scheme}://{host}{'' if port is None else f':{port}'}{'' if parts.path == '/' else parts.path}"


def _sim_key(scheme: str, query: dict[str, list[str]]) -> str:
    """A simulated arm's key: which simulator (closed-form or physics) and its seed (0 unless given)."""
    physics = scheme == "sim+physics" or "1" in query.get("physics", [])
    seed = query.get("seed", ["0"])[-1].strip()
    if seed.isdigit():
        seed = str(int(seed))  # "007" and "7" are one arm
    return ("sim+physics://" if physics else "sim://") + ("" if seed == "0" else f"?seed={seed}")


def check_setting(what: str, value: object, lo: float, hi: float, unit: str = "", integer: bool = False) -> float:
    """Validate a controller setting: a finite number (a whole one if ``integer``) in ``[lo, hi]``.

    Returns the value (an ``int`` if ``integer``). Raises ``ValueError`` naming the allowed
    range and the value given; nothing is ever clipped.

    >>> check_setting("frequency", 1200, 1, 5000, "Hz")
    1200.0
    >>> check_setting("amplitude", 90, 1, 80, integer=True)
    Traceback (most recent call last):
    ...
    ValueError: amplitude must be an integer in 1..80, got 90
    """
    kind = "an integer" if integer else "a number"
    span = f"{int(lo)}..{int(hi)}" if integer else f"{lo:g}..{hi:g}"  # (an integer's bounds in full: 4000000)
    allowed = f"{kind} in {span}" + (f" {unit}" if unit else "")
    if isinstance(value, bool):
        raise ValueError(f"{what} must be {allowed}, got {value!r}")
    try:
        v = float(value)  # type: ignore[arg-type]  # any object: what float() refuses is caught below
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be {allowed}, got {value!r}") from None
    if not (math.isfinite(v) and lo <= v <= hi) or (integer and not v.is_integer()):
        raise ValueError(f"{what} must be {allowed}, got {value!r}")
    return int(v) if integer else v


def url_options(url: str, known: set[str] | frozenset[str]) -> dict[str, str]:
    """The ``?key=value`` options of a device URL (last one wins); unknown keys are refused.

    Raises ``ValueError`` naming the unknown option(s) and the known ones, or an option
    given empty (``?hz=`` was dropped unsaid, its default taken: not what was written).
    """
    opts = {k: v[-1] for k, v in parse_qs(urlsplit(url).query, keep_blank_values=True).items()}
    unknown = sorted(set(opts) - set(known))
    if unknown:
        raise ValueError(
            f"unknown option(s) {unknown} in {redact_url(url)!r} (known: {sorted(known)})"
        )
    empty = sorted(k for k, v in opts.items() if not v.strip())
    if empty:
        raise ValueError(f"{redact_url(url)!r}: the option {empty[0]!r} is empty: give its value or leave it out")
    return opts


def check_steps(n: object) -> int:
    """A signed step count as an ``int``: integers (numpy's too) and whole floats pass.

    Anything else (``True``, ``2.5``, ``"10"``) raises ``ValueError``. Every backend's
    ``step(joint, n)`` starts with it.
    """
    if isinstance(n, bool):
        raise ValueError(f"step count must be an integer, got {n!r}")
    if isinstance(n, numbers.Integral):
        return int(n)
    if isinstance(n, float) and n.is_integer():
        return int(n)
    raise ValueError(f"step count must be an integer, got {n!r}")
