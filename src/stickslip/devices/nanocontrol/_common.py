"""What both NanoControl dialects share: the logger, channel maps, answer lines."""

from __future__ import annotations

import logging
from collections.abc import Mapping

from ..base import DeviceError

__all__ = ["log", "DEFAULT_CHANNELS", "STATUS", "check_channels", "parse_reply", "parse_console_reply"]

log = logging.getLogger("stickslip.devices.nanocontrol")
"""One logger for both dialects: every message sent and received, at DEBUG level."""

DEFAULT_CHANNELS: dict[int, str] = {1: "A", 2: "B", 3: "C"}
"""Channel letter of each MM3A joint unless the URL's ``channels`` says otherwise."""

STATUS = {"o": "ok", "e": "error", "i": "info"}
"""The status letter that starts every answer line, and what it means."""


def check_channels(channels: Mapping[int, str]) -> dict[int, str]:
    """``{joint: letter}`` with letters in A..D, no two joints on one channel; else ``ValueError``."""
    out: dict[int, str] = {}
    for j, c in channels.items():
        c = str(c).upper()
        if c not in ("A", "B", "C", "D"):
            raise ValueError(f"channel of joint {j} must be one of A, B, C, D, got {c!r}")
        out[int(j)] = c
    if len(set(out.values())) != len(out):
        raise ValueError(f"two joints share a channel: {out}")
    return out


def _printable(line: bytes) -> str | None:
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        return None
    if any(not (c.isprintable() or c == "\t") for c in text):
        return None
    return text


def parse_reply(line: bytes, sent: str, port: str) -> tuple[str, str]:
    """A legacy-dialect answer line (lenient): ``(status, message)``.

    ``<status><TAB><message>`` as on the console; a printable line without that prefix
    is an ok answer (an error if it starts with ``error``). Non-printable bytes raise
    :class:`DeviceError` ("garbage reply").
    """
    text = _printable(line)
    if text is None:
        raise DeviceError(f"NanoControl on {port}: garbage reply {line!r} to {sent!r}")
    if len(text) >= 2 and text[1] == "\t" and text[0] in STATUS:
        return STATUS[text[0]], text[2:].strip()
    if text.strip().lower().startswith("error"):
        return "error", text.strip()
    return "ok", text.strip()


def parse_console_reply(line: bytes, sent: str, port: str) -> tuple[str, str]:
    """A console answer line (strict): ``<o|e|i><TAB><message>``, CR already removed.

    A leading LF (of a CR LF before it) is ignored. Anything else raises
    :class:`DeviceError` ("garbage reply ... to 'cmd'").
    """
    text = _printable(line.lstrip(b"\n"))
    if text is None or len(text) < 2 or text[1] != "\t" or text[0] not in STATUS:
        raise DeviceError(f"NanoControl on {port}: garbage reply {line!r} to {sent!r}")
    return STATUS[text[0]], text[2:].strip()
