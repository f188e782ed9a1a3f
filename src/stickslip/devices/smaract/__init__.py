"""SmarAct controllers in step mode (open loop, no sensor needed): the MCS and the MCS2.

URLs (opened by :func:`open_mcs` and :func:`open_mcs2` through
:func:`stickslip.devices.open_device`)::

    smaract-mcs:///dev/ttyUSB0                 an MCS on a serial port (9600 baud 8N1)
    smaract-mcs://COM3?baud=115200             (Windows; the baud rate set in the controller)
    smaract-mcs+socket://192.168.1.5           an MCS's network interface (TCP port 5000)
    smaract-mcs2://192.168.1.200               an MCS2 (TCP port 55551)
    smaract-mcs2://192.168.1.200:55551?channels=0,-1,2&hz=2000&timeout=5

Query options (both): ``channels`` (the channel of joints 1, 2, 3, ...; a ``-`` in
front reverses a joint, ``-0`` too; default ``0,1,2``), ``timeout`` (s to wait for any
answer, 0.001..3600, default 2), ``hz`` (stepping frequency of every joint, an integer:
MCS 1..18500 Hz, MCS2 1..20000 Hz; default 1000), ``amplitude`` (step amplitude,
controller units: MCS 1..4095, MCS2 1..65535, the largest being 100 V; default the
largest); MCS on a serial port only: ``baud`` (9600..115200, default 9600).

The dialects (docs/devices/smaract.md lists every command sent and every assumption):

* :mod:`.mcs`, :class:`SmarActMCS`: ``:MST<ch>,<steps>,<amplitude>,<frequency>`` then
  ``:GS<ch>`` until the channel has stopped;
* :mod:`.mcs2`, :class:`SmarActMCS2`: ``:CHAN<ch>:MMOD 4``, ``:STEP:FREQ``, ``:STEP:AMPL``,
  ``:MOVE<ch> <steps>``, then ``:CHAN<ch>:STAT?`` until the channel has stopped.

Neither controller has a password; a URL with a user or password is refused.
"""

from __future__ import annotations

from urllib.parse import urlsplit

from ..base import redact_url, url_options
from ..transport import SerialTransport, SocketTransport, Transport, serial_port_name
from . import mcs, mcs2
from ._common import OPTIONS, ChannelMap, SmarActBase, float_option, int_option, parse_channels
from .mcs import SmarActMCS
from .mcs2 import SmarActMCS2

__all__ = [
    "SmarActMCS",
    "SmarActMCS2",
    "SmarActBase",
    "ChannelMap",
    "parse_channels",
    "open_mcs",
    "open_mcs2",
    "check_mcs_url",
    "check_mcs2_url",
    "DEFAULT_CHANNELS",
    "TIMEOUT_RANGE_S",
]

DEFAULT_CHANNELS = "0,1,2"
"""Channels of joints 1, 2, 3 unless the URL's ``channels`` says otherwise."""
TIMEOUT_RANGE_S = (0.001, 3600.0)
"""Allowed ``timeout`` option, s, inclusive."""


def _common(url: str, known: frozenset[str]) -> tuple[dict[str, str], ChannelMap, float]:
    parts = urlsplit(url)
    if parts.username is not None or parts.password is not None:
        raise ValueError(f"{redact_url(url)!r}: a SmarAct controller has no user or password; leave them out")
    opts = url_options(url, known)
    channels = parse_channels(opts.get("channels", DEFAULT_CHANNELS))
    timeout = float_option(opts, "timeout", 2.0, *TIMEOUT_RANGE_S, "s")
    return opts, channels, timeout


def _port(url: str, default: int) -> int:
    try:
        return urlsplit(url).port or default
    except ValueError as e:
        raise ValueError(f"{redact_url(url)!r}: {e}") from None


def _build(cls: type[SmarActBase], transport: Transport, **kwargs: object) -> SmarActBase:
    try:
        return cls(transport, **kwargs)  # type: ignore[arg-type]  # the options were checked above
    except BaseException:
        transport.close()
        raise


_Settings = tuple[dict[str, str], ChannelMap, float, int, int]
"""A SmarAct URL's options, each checked: (the options, channels, timeout s, hz, amplitude)."""


def _mcs_settings(url: str) -> _Settings:
    opts, channels, timeout = _common(url, OPTIONS | {"baud"})
    hz = int_option(opts, "hz", 1000, *mcs.FREQUENCY_RANGE_HZ, "Hz")
    amplitude = int_option(opts, "amplitude", mcs.AMPLITUDE_FULL, *mcs.AMPLITUDE_RANGE)
    if "baud" in opts and urlsplit(url).scheme == "smaract-mcs":
        int_option(opts, "baud", mcs.BAUD, *mcs.BAUD_RANGE, "baud")
    return opts, channels, timeout, hz, amplitude


def _mcs2_settings(url: str) -> _Settings:
    opts, channels, timeout = _common(url, OPTIONS)
    hz = int_option(opts, "hz", 1000, *mcs2.FREQUENCY_RANGE_HZ, "Hz")
    amplitude = int_option(opts, "amplitude", mcs2.AMPLITUDE_FULL, *mcs2.AMPLITUDE_RANGE)
    return opts, channels, timeout, hz, amplitude


def check_mcs_url(url: str) -> None:
    """``ValueError`` naming an option of an MCS URL the driver would refuse; nothing is opened or asked."""
    _mcs_settings(url)


def check_mcs2_url(url: str) -> None:
    """``ValueError`` naming an option of an MCS2 URL the driver would refuse; nothing is opened or asked."""
    _mcs2_settings(url)


def open_mcs(url: str) -> SmarActMCS:
    """Open ``smaract-mcs:///dev/ttyUSB0[?options]`` or ``smaract-mcs+socket://host[:5000][?options]``.

    See the module docstring for the options. Raises ``ValueError`` for a malformed URL
    or option (before the port is opened), :class:`~stickslip.devices.base.DeviceError`
    if the port cannot be opened or the controller does not answer.
    """
    parts = urlsplit(url)
    opts, channels, timeout, hz, amplitude = _mcs_settings(url)
    if parts.scheme == "smaract-mcs+socket":
        if "baud" in opts:
            raise ValueError(f"{redact_url(url)!r}: baud is an option of a serial port, not of a network link")
        if not parts.hostname:
            raise ValueError(f"{redact_url(url)!r}: give the host, e.g. smaract-mcs+socket://192.168.1.5")
        transport: Transport = SocketTransport(parts.hostname, _port(url, mcs.TCP_PORT), timeout)
    elif parts.scheme == "smaract-mcs":
        baud = int_option(opts, "baud", mcs.BAUD, *mcs.BAUD_RANGE, "baud")  # checked by _mcs_settings
        port = serial_port_name(parts.path or parts.netloc)
        if not port:
            raise ValueError(f"{redact_url(url)!r}: give the serial port, e.g. smaract-mcs:///dev/ttyUSB0")
        transport = SerialTransport(port, baudrate=baud, timeout=timeout)
    else:
        raise ValueError(
            f"not a SmarAct MCS URL: {redact_url(url)!r} "
            "(use smaract-mcs:///dev/ttyUSB0 or smaract-mcs+socket://host)"
        )
    dev = _build(SmarActMCS, transport, channels=channels, timeout=timeout, hz=hz, amplitude=amplitude, url=url)
    assert isinstance(dev, SmarActMCS)
    return dev


def open_mcs2(url: str) -> SmarActMCS2:
    """Open ``smaract-mcs2://host[:55551][?options]``.

    See the module docstring for the options. Raises ``ValueError`` for a malformed URL
    or option (before connecting), :class:`~stickslip.devices.base.DeviceError` if the
    controller cannot be reached within the timeout or does not answer.
    """
    parts = urlsplit(url)
    _, channels, timeout, hz, amplitude = _mcs2_settings(url)
    if parts.scheme != "smaract-mcs2":
        raise ValueError(f"not a SmarAct MCS2 URL: {redact_url(url)!r} (use smaract-mcs2://host)")
    port = _port(url, mcs2.TCP_PORT)
    if not parts.hostname or parts.path not in ("", "/"):
        raise ValueError(f"{redact_url(url)!r}: give the host, e.g. smaract-mcs2://192.168.1.200")
    transport = SocketTransport(parts.hostname, port, timeout)
    dev = _build(SmarActMCS2, transport, channels=channels, timeout=timeout, hz=hz, amplitude=amplitude, url=url)
    assert isinstance(dev, SmarActMCS2)
    return dev
