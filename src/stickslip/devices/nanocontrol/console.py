"""The NanoControl's current console (2025): CR-terminated commands, speed profiles, ``go``/``stop``.

Opened by :func:`stickslip.devices.nanocontrol.open_url` when the controller answers
``version<CR>`` at 115200 baud (or with ``?dialect=console``).

The console, as a public driver for the current NanoControl uses it
-------------------------------------------------------------------
115200 baud 8N1; every command ends in CR; every command except ``stopnack`` is
answered by one line ``<status><TAB><message><CR>``, status ``o`` (ok), ``e`` (error)
or ``i`` (information). The commands this driver sends::

    version                          firmware identification (on opening)
    speed ?                          the active speed profile: "P cNNN cNNN cNNN cNNN"
    frequency fA fB fC fD            stepping frequency per channel, 300..20000 Hz (at every step())
    speed P vA vB vC vD              set profile P (1..6); v = cNN (NN coarse steps
                                     per interval, 1..64) or fNN (fine; never sent here)
    speed P                          make profile P active
    go mA mB mC mD T                 every T ms, each channel makes (its profile's
                                     count) x |m| steps in the sign of m (|m| <= 100)
    stop                             halt every channel (answered)
    stopnack                         halt every channel, no answer (lowest latency)
    finewithcoarse a b c d           only if the URL asks (``?finewithcoarse=0``)

An exact burst of N coarse steps on one channel
-----------------------------------------------
The console has no "N steps" command: it drives until told to stop. A burst is
therefore timed. N (at most :data:`MAX_BURST` = 6400) is split into at most two parts
``count x multiplier`` (:func:`split_burst`). For each part the scratch profile
(``?profile=``, default 6) gets ``c<count>`` on the joint's channel, is made active, and
``go`` is sent with multiplier ``m`` on that channel only (0 on the others) and an
interval ``T``: the part's duration ``d = count |m| / f`` plus the margin plus twice the
timeout, at most :data:`T_MAX_MS`. Once ``go`` is answered, the driver waits ``d + margin`` and
sends ``stop``. Then:

* ``go`` was received between its sending and its answer, and ``stop`` between its
  sending and its answer; the first interval's steps were done before ``stop`` was
  sent, and if ``stop`` was answered less than ``T`` after ``go`` was sent no second
  interval can have begun: exactly ``count |m|`` steps were made (*on time*);
* otherwise (a late stop) between one and ``ceil(elapsed / T)`` intervals' steps were
  made, and :class:`~stickslip.devices.base.StepsUncertain` says so;
* a ``stop`` that is not answered leaves the channel possibly driving: the steps are
  bounded only by the joint's end stop.

Before the first burst the driver sets every channel's stepping frequency with
``frequency`` (the URL's ``hz``, default 1000 Hz; never the power-on value, which
cannot be read); the user's active profile, read with ``speed ?`` on opening, is made
active again after every ``step()`` (and its values written back if it is the scratch
profile itself).

Assumptions no public source documents (docs/devices/nanocontrol.md says how to check
each on real hardware): the first interval's steps begin when ``go`` is received and
run at the channel's stepping frequency; ``go`` is answered on receipt, before its
steps; writing a profile does not change the active one until ``speed P`` is sent;
``T`` may be as large as 65535 ms.

Stops that hold: an error, a timeout or Ctrl-C while a channel may be driving sends
``stopnack`` at once, then ``stop`` (its answer awaited at most 0.25 s; sent again on a
re-synchronised line when an earlier answer was overdue, which the first one's could be);
:meth:`NanoControlConsole.close` does the same if a ``go`` was never confirmed stopped.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Mapping

from ..base import DeviceError, DeviceInfo, StepsUncertain, check_setting, check_steps
from ..transport import Transport
from ._common import DEFAULT_CHANNELS, check_channels, log
from .console_line import CHANNELS, COUNT_RANGE, PROFILES, SpeedProfiles, parse_profile

__all__ = [
    "NanoControlConsole",
    "CONSOLE_BAUD",
    "FREQUENCY_RANGE_HZ",
    "COUNT_RANGE",
    "MULTIPLIER_MAX",
    "PROFILES",
    "MAX_BURST",
    "T_MAX_MS",
    "split_burst",
    "parse_profile",
]

CONSOLE_BAUD = 115200
"""The console's baud rate (8N1)."""

FREQUENCY_RANGE_HZ = (300, 20000)
"""Allowed stepping frequency of a channel, Hz (``frequency``), inclusive."""

MULTIPLIER_MAX = 100
"""Largest |m| of ``go``."""

MAX_BURST = COUNT_RANGE[1] * MULTIPLIER_MAX
"""Most steps of one burst (at most two ``go`` parts; longer ``step()`` calls are split)."""

T_MAX_MS = 65535
"""Longest ``go`` interval this driver sends, ms (an assumption: see the module docstring)."""

_MIN_SLACK_MS = 200.0
"""Least time between a burst's stop being due and the next interval when T is capped, ms."""


def split_burst(n: int) -> list[tuple[int, int]]:
    """``n`` steps (1..:data:`MAX_BURST`) as at most two ``(count, multiplier)`` parts.

    One part ``count x multiplier = n`` if ``n`` factors with ``count`` in 1..64 and
    ``multiplier`` in 1..100 (the largest such ``count``); else ``64 x (n // 64)`` and
    ``(n % 64) x 1``.

    >>> split_burst(1000)
    [(50, 20)]
    >>> split_burst(1009)
    [(64, 15), (49, 1)]
    """
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_BURST:
        raise ValueError(f"a burst must be an integer in 1..{MAX_BURST} steps, got {n!r}")
    hi = COUNT_RANGE[1]
    for count in range(hi, 0, -1):
        if n % count == 0 and n // count <= MULTIPLIER_MAX:
            return [(count, n // count)]
    m, r = divmod(n, hi)  # n % 64 != 0 here, and n >= 64 (smaller n factor as n x 1)
    return [(hi, m), (r, 1)]


def _halted(dev: NanoControlConsole, what: str, made: int, at_most: int) -> StepsUncertain:
    """A ``step()`` ended by :meth:`NanoControlConsole.stop` from another thread: ``made`` steps certain, at most
    ``at_most`` (the stopped part made between none and all of its steps; a part never sent, none)."""
    return StepsUncertain(f"NanoControl on {dev.transport.name}: {what}", made, at_most)


class NanoControlConsole(SpeedProfiles):
    """A current Kleindiek NanoControl (console dialect), as a :class:`~stickslip.devices.base.Controller`.

    Parameters
    ----------
    transport : Transport
        An open byte transport (serial port at 115200 baud, socket, or a fake).
    channels : mapping of int to str
        Channel letter (``A``-``D``) of each joint; default joints 1, 2, 3 -> A, B, C.
    timeout : float
        Time to wait for an answer, s.
    hz : int or mapping of str to int
        Stepping frequency of every channel (or per channel letter), Hz, in 300..20000;
        sent with ``frequency`` at the start of every :meth:`step` (a controller switched off and on since the
        last one steps at its power-on frequency).
    profile : int
        The scratch speed profile (1..6) whose values bursts overwrite.
    margin : float
        Time added to a burst's duration before ``stop`` is sent, s (> 0).
    url : str
        The URL it was opened with (for :attr:`info`).
    version : str, optional
        The firmware answer to ``version`` if already asked (detection); else it is asked.
    clock, sleep : callable
        Monotonic clock (s) and sleep; tests pass fakes (a ``KeyboardInterrupt`` from
        ``sleep`` is a Ctrl-C in the middle of a burst).

    Raises
    ------
    DeviceError
        If the controller does not answer ``version`` within ``timeout``.
    """

    dialect = "console"

    def __init__(
        self,
        transport: Transport,
        *,
        channels: Mapping[int, str] | None = None,
        timeout: float = 2.0,
        hz: int | Mapping[str, int] = 1000,
        profile: int = 6,
        margin: float = 0.05,
        url: str = "mm3a://",
        version: str | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.transport = transport
        self.channels = check_channels(channels or DEFAULT_CHANNELS)
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout!r}")
        self.timeout = float(timeout)
        self.margin = check_setting("margin", margin, 1e-3, 10.0, "s")
        if isinstance(profile, bool) or profile not in PROFILES:
            raise ValueError(f"scratch profile must be an integer in 1..6, got {profile!r}")
        self.scratch = int(profile)
        per = {c: hz for c in CHANNELS} if not isinstance(hz, Mapping) else dict(hz)
        self._hz: dict[str, int] = {}
        for c in CHANNELS:
            value = check_setting(
                f"frequency of channel {c}", per.get(c, 1000), *FREQUENCY_RANGE_HZ, "Hz", integer=True
            )
            self._hz[c] = int(value)
        self.url = url
        self._clock = clock
        self._sleep = sleep
        self._lock = threading.RLock()
        self._frequency_sent = False
        self._driving = False  # a go was sent and not yet confirmed stopped
        self._halt = False  # stop() from another thread during a burst
        self._in_step = False
        self._active: int | None = None
        self._scratch_values: tuple[str, str, str, str] | None = None
        self._profile_dirty = False
        self._brief: float | None = None
        self.user_profile: int | None = None
        self.user_values: tuple[str, str, str, str] | None = None
        self.version = self.command("version") if version is None else version
        self._read_user_profile()

    def _channel(self, joint: int) -> str:
        try:
            return self.channels[int(joint)]
        except (KeyError, ValueError, TypeError):
            raise ValueError(
                f"joint must be one of {sorted(self.channels)}, got {joint!r}"
            ) from None

    # -- settings -----------------------------------------------------------------------
    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint``'s channel, Hz (an integer in 300..20000).

        Sends ``frequency`` with all four channels (the console sets them together).
        Raises ``ValueError`` naming the range for anything else; nothing is rounded.
        """
        ch = self._channel(joint)
        value = int(check_setting("frequency", hz, *FREQUENCY_RANGE_HZ, "Hz", integer=True))
        old = self._hz[ch]
        self._hz[ch] = value
        try:
            self._send_frequency()
        except BaseException:
            self._hz[ch] = old
            raise

    def _send_frequency(self) -> None:
        self.command("frequency " + " ".join(str(self._hz[c]) for c in CHANNELS))
        self._frequency_sent = True

    def frequency(self, joint: int) -> float:
        """Stepping frequency of ``joint``'s channel, Hz (sent at the start of every :meth:`step`)."""
        return float(self._hz[self._channel(joint)])

    def set_fine_with_coarse(self, values: Mapping[str, bool]) -> None:
        """Send ``finewithcoarse a b c d`` (every channel must be given: the console cannot be read)."""
        missing = [c for c in CHANNELS if c not in values]
        if missing:
            raise ValueError(f"finewithcoarse needs a value for every channel; missing {missing}")
        self.command("finewithcoarse " + " ".join("1" if values[c] else "0" for c in CHANNELS))

    def beep(self, hz: int, ms: int) -> None:
        """Let the controller beep at ``hz`` Hz for ``ms`` ms (integers, 1..20000 and 1..5000)."""
        f = int(check_setting("beep frequency", hz, 1, 20000, "Hz", integer=True))
        d = int(check_setting("beep duration", ms, 1, 5000, "ms", integer=True))
        self.command(f"beep {f} {d}")

    # -- motion -------------------------------------------------------------------------
    def step(self, joint: int, n: int) -> None:
        """Make exactly ``n`` signed coarse steps on ``joint`` by timed bursts; return when done.

        Raises
        ------
        StepsUncertain
            If a burst fails (an ``e`` answer, no answer, garbage, a late or unanswered
            ``stop``): ``made`` steps of earlier bursts are certain, the rest bounded.
            A stop (``stopnack``, then ``stop``) has been sent where the line works.
            Also after :meth:`stop` from another thread: the stopped burst made between none
            and all of its steps, and no later burst is sent (as every other driver does).
        DeviceError
            If the user's speed profile could not be read on opening (nothing is sent).
        """
        ch = self._channel(joint)
        n = check_steps(n)
        if n == 0:
            return
        if self.user_profile is None:
            raise DeviceError(
                f"NanoControl on {self.transport.name}: its active speed profile could not be "
                "read ('speed ?'), so it could not be restored after a burst; nothing was sent"
            )
        sign = 1 if n > 0 else -1
        made = 0
        self._halt = False
        with self._lock:
            self._in_step = True
            try:
                # set again at every call, as if never sent: a controller switched off and on since the last call
                # (a long session: serve, Bluesky) steps at its power-on frequency with its power-on profiles
                self._scratch_values = None
                self._send_frequency()
                left = abs(n)
                while left and not self._halt:
                    chunk = min(left, MAX_BURST)
                    for count, mult in split_burst(chunk):
                        if self._halt:
                            break
                        self._part(ch, count, sign * mult, made)
                        made += sign * count * mult
                    left -= chunk
            except StepsUncertain:
                raise
            except DeviceError as e:  # a setting was refused between gos: nothing more moved
                raise StepsUncertain(str(e), made, made) from None
            finally:
                self._in_step = False
                self._restore_quietly()
            if made != n:  # stop() from another thread before a burst: the rest was not sent
                raise _halted(self, f"{n - made:+d} steps on channel {ch} were not sent: stop() was called from "
                              "another thread", made, made)

    def _part(self, ch: str, count: int, m: int, made: int) -> None:
        """One ``go``: ``count x |m|`` steps in the sign of ``m``, stopped on time or raising."""
        steps = count * abs(m)
        sign = 1 if m > 0 else -1
        f = self._hz[ch]
        d = steps / f
        # room for both answers' latency; capped (whether stop came on time is measured anyway)
        t_ms = min(math.ceil(round(1000.0 * (d + self.margin + 2.0 * self.timeout), 6)), T_MAX_MS)
        if t_ms == T_MAX_MS and t_ms < 1000.0 * (d + self.margin) + _MIN_SLACK_MS:
            raise DeviceError(
                f"a burst of {steps} steps at {f} Hz lasts {d:.3f} s, too long for the longest go "
                f"interval sent ({T_MAX_MS} ms); raise the frequency (?hz=)"
            )
        self._write_scratch(ch, count)
        mults = " ".join(str(m) if c == ch else "0" for c in CHANNELS)
        go = f"go {mults} {t_ms}"
        t_sent = self._clock()
        self._driving = True
        try:
            self.command(go)
            t_answer = self._clock()
            self._wait_until(t_answer + d + self.margin)
        except BaseException as e:
            outcome = self._emergency_stop()
            acked = outcome == "acknowledged"
            what = "interrupted (Ctrl-C)" if isinstance(e, KeyboardInterrupt) else str(e)
            if not isinstance(e, DeviceError) and acked:
                raise  # Ctrl-C, stopped: the caller's journal covers this burst
            # every T ms another interval may begin until the stop is acknowledged
            intervals = max(1, math.ceil((self._clock() - t_sent) / (t_ms / 1000.0)))
            tail = {
                "acknowledged": "; stopnack and stop were sent and the stop was acknowledged"
                + (f" (up to {intervals} intervals of {steps} steps)" if intervals > 1 else ""),
                "unanswered": "; stopnack and stop were sent but the stop was not acknowledged: "
                f"channel {ch} may still be driving",
                "unsent": f"; no stop could be sent (the line is down): channel {ch} may still be driving",
            }[outcome]
            raise StepsUncertain(
                what + tail, made, made + sign * steps * intervals if acked else None
            ) from (None if isinstance(e, DeviceError) else e)
        try:
            self.command("stop", sync=False)
        except DeviceError as e:
            self._emergency_stop()
            raise StepsUncertain(
                f"{e}; channel {ch} may still be driving", made + sign * steps, None
            ) from None
        t_stopped = self._clock()
        self._driving = False
        if self._halt:  # stopped early by stop() from another thread, as asked: how far it went is not known
            raise _halted(self, f"{go!r} was stopped by stop() from another thread: between none and all of its "
                          f"{steps} steps were made", made, made + sign * steps)
        late = t_stopped - t_sent
        if late >= t_ms / 1000.0:
            intervals = math.ceil(late / (t_ms / 1000.0))
            raise StepsUncertain(
                f"NanoControl on {self.transport.name}: 'stop' was answered {late:.3f} s after "
                f"{go!r} was sent, not within its {t_ms} ms interval: up to {intervals} intervals "
                f"of {steps} steps may have been made",
                made + sign * steps,
                made + sign * steps * intervals,
            )

    def _wait_until(self, deadline: float) -> None:
        while not self._halt:
            left = deadline - self._clock()
            if left <= 0:
                return
            self._sleep(min(left, 0.05))

    def stop(self, joint: int | None = None) -> None:
        """Stop every channel now (the console has no per-channel stop). Never raises.

        During a ``step()`` (from another thread) it sends ``stopnack`` at once if a
        channel is driving, and the ``step()`` ends early, sending ``stop`` itself;
        while another thread has the line (a ``step()`` about to begin) that step sends
        no burst; otherwise it sends ``stop``.
        """
        if self._driving or self._in_step:
            self._halt = True
            if self._driving:
                try:
                    self._write("stopnack")
                except DeviceError as e:
                    log.warning("could not send stopnack to %s: %s", self.transport.name, e)
            return
        if not self._lock.acquire(blocking=False):  # another thread has the line: a step about to begin sends no go
            self._halt = True
            return
        try:
            self.command("stop", sync=False)
        except DeviceError as e:
            log.warning("stop: %s", e)
        finally:
            self._lock.release()

    # -- protocol -----------------------------------------------------------------------
    @property
    def info(self) -> DeviceInfo:
        """Model, URL, joints, and in ``extra``: dialect, version, frequencies, profiles."""
        return DeviceInfo(
            url=self.url,
            model=f"Kleindiek NanoControl{f' ({self.version})' if self.version else ''}, console dialect",
            joints=tuple(sorted(self.channels)),
            extra={
                "dialect": self.dialect,
                "version": self.version,
                "port": self.transport.name,
                "channels": dict(self.channels),
                "frequency_hz": dict(self._hz),
                "frequency_sent": self._frequency_sent,
                "active_profile": self.user_profile,
                "active_profile_values": list(self.user_values) if self.user_values else None,
                "scratch_profile": self.scratch,
            },
        )

    def settings(self) -> dict[str, object]:
        """Dialect, channel map, frequency per joint (Hz), profiles, timeout and margin (s)."""
        return {
            "dialect": self.dialect,
            "channels": {str(j): c for j, c in self.channels.items()},
            "frequency_hz": {str(j): float(self._hz[c]) for j, c in self.channels.items()},
            "frequency_sent": self._frequency_sent,
            "user_profile": self.user_profile,
            "scratch_profile": self.scratch,
            "timeout_s": self.timeout,
            "margin_s": self.margin,
            "port": self.transport.name,
        }

    def close(self) -> None:
        """Stop a channel left driving, make the user's profile active again, release the port.

        Never raises; nothing is sent when every burst was stopped and restored.
        """
        if self.transport.closed:
            return
        try:
            if self._driving:  # a go never confirmed stopped: stop it, without waiting long
                self._emergency_stop(wait=0.1)
            if self._profile_dirty or (self.user_profile is not None and self._active != self.user_profile):
                self._restore_quietly()
        finally:
            self.transport.close()

    def __enter__(self) -> NanoControlConsole:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
