"""The console's line and its speed profiles (see :mod:`.console` for the protocol).

:class:`ConsoleLine` sends one CR-terminated command and reads its one answer, and stops
every channel at once when something goes wrong; :class:`SpeedProfiles` writes the
scratch profile a burst needs and makes the user's profile active again after it.
"""

from __future__ import annotations

import threading

from ..base import DeviceError
from ..transport import Transport
from ._common import log, parse_console_reply

__all__ = ["CHANNELS", "COUNT_RANGE", "PROFILES", "ConsoleLine", "SpeedProfiles", "parse_profile"]

COUNT_RANGE = (1, 64)
"""Allowed coarse step count per interval of a profile entry ``cNN``, inclusive."""

PROFILES = (1, 2, 3, 4, 5, 6)
"""The speed profiles ``speed P`` selects."""

CHANNELS = "ABCD"
"""The console's channel letters, in the order its commands list them."""


def parse_profile(message: str) -> tuple[int, tuple[str, str, str, str]]:
    """``"P cNNN cNNN cNNN cNNN"`` (the answer to ``speed ?``) as ``(P, (vA, vB, vC, vD))``.

    Each value is normalised to ``c``/``f`` and its count (``"c064"`` -> ``"c64"``).
    Raises ``ValueError`` naming what does not fit.

    >>> parse_profile("2 c064 c032 f008 c016")
    (2, ('c64', 'c32', 'f08', 'c16'))
    """
    words = message.split()
    if len(words) != 5:
        raise ValueError(f"expected 'P cNNN cNNN cNNN cNNN', got {message!r}")
    try:
        number = int(words[0])
    except ValueError:
        raise ValueError(f"profile number {words[0]!r} is not an integer in {message!r}") from None
    if number not in PROFILES:
        raise ValueError(f"profile number {number} is not in 1..6 in {message!r}")
    values = []
    for w in words[1:]:
        kind, digits = w[:1].lower(), w[1:]
        if kind not in ("c", "f") or not digits.isdigit() or not 1 <= int(digits) <= COUNT_RANGE[1]:
            raise ValueError(f"speed value {w!r} is not c1..c64 or f1..f64 in {message!r}")
        values.append(f"{kind}{int(digits):02d}")
    return number, (values[0], values[1], values[2], values[3])


class ConsoleLine:
    """The serial line: one command, one answer (:meth:`command`); the emergency stop.

    The attributes are set by :class:`~.console.NanoControlConsole`.
    """

    transport: Transport
    timeout: float
    _lock: threading.RLock
    _brief: float | None
    _driving: bool

    def command(self, text: str, timeout: float | None = None, sync: bool = True) -> str:
        """Send ``text`` + CR and return the message of its answer (without the status).

        An ``i`` answer is logged as a warning and returned. After a reply timed out, the line
        is first re-synchronised (``version``, its answer awaited, anything before it discarded;
        ``speed ?`` and its profile after an unanswered one) unless ``sync`` is false (a stop is
        sent at once; its answer may be an earlier command's: the line stays out of step).

        Raises
        ------
        DeviceError
            On no answer within ``timeout`` (default :attr:`timeout`), an ``e`` answer,
            or garbage; the message names the command and the port. If the re-synchronising
            ``version`` is not answered in time (``text`` is then not sent).
        """
        wait = self.timeout if timeout is None else timeout
        if self._brief is not None:  # best-effort after a timeout: the console may not answer at all
            wait = min(wait, self._brief)
        with self._lock:
            unsynced = self.transport.silent and not sync
            if sync and self.transport.silent:
                where = f"NanoControl on {self.transport.name}"
                queries = ((b"version\r", self._is_version), (b"speed ?\r", self._is_profile))
                self.transport.resync(queries, b"\r", where, wait)
            stale = self.transport.drain()
            if stale.strip(b"\r\n\t "):
                log.warning("discarding unexpected bytes from %s: %r", self.transport.name, stale)
            self._write(text)
            try:
                raw = self.transport.read_until(b"\r", timeout=wait)
            except DeviceError as e:
                raise DeviceError(
                    f"NanoControl on {self.transport.name} did not answer {text!r}: {e}"
                ) from None
            log.debug("<- %r", raw)
            self.transport.silent = unsynced  # an answer read unsynced may be an earlier command's
            status, message = parse_console_reply(raw[:-1], text, self.transport.name)
            if status == "info":
                log.warning("NanoControl says: %s (after %s)", message, text)
            elif status == "error":
                raise DeviceError(
                    f"NanoControl on {self.transport.name} refused {text!r}: {message}"
                )
            return message

    def _is_version(self, line: bytes) -> bool:
        """Whether ``line`` is ``version``'s answer: ``o<TAB>`` and the version read on opening (if known)."""
        try:
            status, message = parse_console_reply(line[:-1], "version", self.transport.name)
        except DeviceError:
            return False
        known = getattr(self, "version", None)
        return status == "ok" and (message == known if known is not None else bool(message))

    def _is_profile(self, line: bytes) -> bool:
        """Whether ``line`` is ``speed ?``'s answer: ``o<TAB>P cNNN cNNN cNNN cNNN``."""
        try:
            status, message = parse_console_reply(line[:-1], "speed ?", self.transport.name)
            parse_profile(message)
        except (DeviceError, ValueError):
            return False
        return status == "ok"

    def _write(self, text: str) -> None:
        log.debug("-> %s<CR>", text)
        self.transport.write(text.encode("ascii") + b"\r")

    def _emergency_stop(self, wait: float = 0.25) -> str:
        """``stopnack`` at once, then ``stop``, its answer awaited at most ``min(timeout, wait)`` s.

        Returns ``"acknowledged"``, ``"unanswered"`` or ``"unsent"`` (the line is down).
        Never raises. Sent while an earlier answer is overdue, the first ``stop``'s answer may be that
        answer, arrived late: ``stop`` is then sent again on a re-synchronised line, and only its
        answer acknowledges the stop.
        """
        overdue = self.transport.silent
        try:
            self._write("stopnack")
        except DeviceError as e:
            log.warning("could not send stopnack to %s: %s", self.transport.name, e)
            return "unsent"
        try:
            self.command("stop", timeout=min(self.timeout, wait), sync=False)
            if overdue:
                self.command("stop", timeout=min(self.timeout, wait))
        except DeviceError as e:
            log.warning("no answer to stop from %s: %s", self.transport.name, e)
            return "unanswered"
        self._driving = False
        return "acknowledged"


class SpeedProfiles(ConsoleLine):
    """The speed profiles: read the user's, write the scratch one for a burst, make the user's active again."""

    scratch: int
    user_profile: int | None
    user_values: tuple[str, str, str, str] | None
    _active: int | None
    _scratch_values: tuple[str, str, str, str] | None
    _profile_dirty: bool

    def _read_user_profile(self) -> None:
        message = self.command("speed ?")
        try:
            self.user_profile, self.user_values = parse_profile(message)
        except ValueError as e:
            log.warning(
                "NanoControl on %s: cannot read the active speed profile (%s); "
                "bursts are refused until it can be restored", self.transport.name, e
            )
            return
        self._active = self.user_profile
        if self.user_profile == self.scratch:
            self._scratch_values = self.user_values

    def _activate(self, number: int) -> None:
        if self._active != number:
            self._active = None  # unknown until answered: a switch made but not answered must be sent again
            self.command(f"speed {number}")
            self._active = number

    def _write_scratch(self, channel: str, count: int) -> None:
        base = self.user_values if self.user_profile == self.scratch else self._scratch_values
        values = list(base or ("c01",) * 4)
        values = [v if v.startswith("c") else "c01" for v in values]  # never a fine entry
        values[CHANNELS.index(channel)] = f"c{count:02d}"
        new = (values[0], values[1], values[2], values[3])
        if new != self._scratch_values or self._active != self.scratch:
            if new != self._scratch_values:
                self._profile_dirty = True
                self._scratch_values = None  # unknown until answered (written or not), so written again next time
                self.command(f"speed {self.scratch} " + " ".join(new))
                self._scratch_values = new
            self._active = None  # written: activate it again (assumption, see docstring)
            self._activate(self.scratch)

    def _restore_profile(self) -> None:
        """Make the user's profile active again (writing its values back if it is the scratch one)."""
        if self.user_profile is None or self.user_values is None:
            return
        if self.user_profile == self.scratch and self._scratch_values != self.user_values:
            self._scratch_values = None
            self.command(f"speed {self.scratch} " + " ".join(self.user_values))
            self._scratch_values = self.user_values
            self._active = None
        self._activate(self.user_profile)
        self._profile_dirty = False

    def _restore_quietly(self) -> None:
        """Make the user's profile active again, best effort (a warning if that fails).

        After a reply timed out (the console stopped answering), each command of it waits
        at most 0.25 s: the URL's timeout bounds the fault, not the fault plus a timeout per
        clean-up command.
        """
        if self.transport.closed or self._driving:
            return
        if getattr(self.transport, "silent", False):
            self._brief = min(self.timeout, 0.25)
        try:
            self._restore_profile()
        except DeviceError as e:
            log.warning("could not make the user's speed profile active again: %s", e)
        finally:
            self._brief = None
