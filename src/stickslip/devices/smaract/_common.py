"""What both SmarAct dialects share: the channel map, URL options, reply checks, the burst loop.

A SmarAct controller drives stick-slip positioners on numbered channels (0, 1, 2, ...).
In *step mode* (open loop, no sensor needed) a channel makes a commanded number of
steps at a set frequency and amplitude, then stops by itself: the count is bounded by
the command, so a burst that fails part-way made between none and all of its steps,
never more. :class:`SmarActBase` turns ``step(joint, n)`` into such bursts for either
dialect (:mod:`.mcs`, :mod:`.mcs2`), which only say how to start a burst, ask whether a
channel still steps, and stop it.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ..base import DeviceError, DeviceInfo, DrivenElsewhere, StepsUncertain, check_setting, check_steps, redact_url
from ..transport import Transport

__all__ = [
    "log",
    "Refused",
    "ChannelMoving",
    "ChannelMap",
    "parse_channels",
    "printable",
    "SmarActBase",
    "POLL_S",
    "OPTIONS",
    "float_option",
    "int_option",
]

log = logging.getLogger("stickslip.devices.smaract")
"""One logger for both dialects: every message sent and received, at DEBUG level."""

POLL_S = 0.01
"""Time between two status questions while a burst runs, s."""

OPTIONS = frozenset({"channels", "timeout", "hz", "amplitude"})
"""URL options both dialects take (the MCS on a serial port also takes ``baud``)."""

_MAX_CHANNEL = 255
"""Largest channel number a URL may name (the controller's own count is checked on opening)."""


class Refused(DeviceError):
    """The controller answered a command with an error code: the command was not carried out."""


class ChannelMoving(Refused):
    """The joint's channel was moving before a burst was sent: another program drives it, so the burst is not sent,
    and the joint goes wherever that program takes it (not where it was kept)."""


@dataclass(frozen=True)
class ChannelMap:
    """Which controller channel drives each joint, and in which sense.

    Attributes
    ----------
    channels : dict of int to tuple of (int, int)
        ``{joint: (channel, sign)}``: a step of ``n`` on the joint is ``sign * n`` steps on
        the channel (``sign`` is +1 or -1).
    """

    channels: dict[int, tuple[int, int]]

    def text(self) -> dict[str, str]:
        """``{"1": "0", "2": "-1"}``: each joint's channel as the URL writes it."""
        return {str(j): ("-" if s < 0 else "") + str(c) for j, (c, s) in sorted(self.channels.items())}


def parse_channels(text: str) -> ChannelMap:
    """The ``channels`` option: channel numbers of joints 1, 2, 3, ... with an optional sign.

    ``"0,1,2"`` maps joints 1, 2, 3 to channels 0, 1, 2; ``"2,-0,1"`` maps joint 2 to
    channel 0 stepping the other way (``-0`` is channel 0 reversed). Raises ``ValueError``
    naming the entry and the reason.

    >>> parse_channels("0,-1,2").channels
    {1: (0, 1), 2: (1, -1), 3: (2, 1)}
    """
    entries = [e.strip() for e in str(text).split(",")]
    if not entries or any(not e for e in entries):
        raise ValueError(f"channels must be comma-separated channel numbers, e.g. 0,1,2 or 0,-1,2; got {text!r}")
    out: dict[int, tuple[int, int]] = {}
    for joint, entry in enumerate(entries, start=1):
        sign = -1 if entry.startswith("-") else 1
        digits = entry.lstrip("+-")
        if len(entry) - len(digits) > 1 or not digits.isdigit() or not digits.isascii():
            raise ValueError(
                f"channel of joint {joint} must be a channel number (0..{_MAX_CHANNEL}), '-' in front to "
                f"reverse it; got {entry!r} in channels={text!r}"
            )
        channel = int(digits)
        if channel > _MAX_CHANNEL:
            raise ValueError(f"channel of joint {joint} must be in 0..{_MAX_CHANNEL}, got {channel}")
        out[joint] = (channel, sign)
    used = [c for c, _ in out.values()]
    if len(set(used)) != len(used):
        raise ValueError(f"two joints share a channel in channels={text!r}")
    return ChannelMap(out)


def printable(line: bytes) -> str | None:
    """``line`` as text if it is printable ASCII (tabs allowed), else ``None`` (garbage)."""
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        return None
    if any(not (c.isprintable() or c == "\t") for c in text):
        return None
    return text


def float_option(opts: Mapping[str, str], name: str, default: float, lo: float, hi: float, unit: str) -> float:
    """A number option of the URL in ``[lo, hi]`` (``ValueError`` naming it and the range)."""
    if name not in opts:
        return default
    return check_setting(name, opts[name], lo, hi, unit)


def int_option(opts: Mapping[str, str], name: str, default: int, lo: int, hi: int, unit: str = "") -> int:
    """A whole-number option of the URL in ``lo..hi`` (``ValueError`` naming it and the range)."""
    if name not in opts:
        return default
    return int(check_setting(name, opts[name], lo, hi, unit, integer=True))


class SmarActBase:
    """A SmarAct controller's step mode as a :class:`~stickslip.devices.base.Controller`.

    Subclasses (one per dialect) provide the wire: :meth:`_open_session`,
    :meth:`_start`, :meth:`_still_stepping` and :meth:`_stop_channel`, and the class
    attributes below.

    Parameters
    ----------
    transport : Transport
        An open byte transport (serial port, TCP socket, or a fake replaying a transcript).
    channels : ChannelMap, optional
        Channel and sense of each joint (default joints 1, 2, 3 on channels 0, 1, 2).
    timeout : float
        Longest wait for any one answer, s; a burst may run at most ``1.5 d + timeout``
        (``d`` its own duration) before it is stopped and reported.
    hz : int
        Stepping frequency of every joint, Hz (an integer in :attr:`FREQUENCY_RANGE_HZ`).
    amplitude : int
        Step amplitude of every joint, controller units (an integer in
        :attr:`AMPLITUDE_RANGE`; :attr:`AMPLITUDE_FULL` units are 100 V).
    url : str
        The URL it was opened with (kept redacted).
    clock, sleep : callable
        Monotonic clock (s) and sleep; tests pass fakes.
    """

    name = "SmarAct"
    FREQUENCY_RANGE_HZ: tuple[int, int] = (1, 1)
    AMPLITUDE_RANGE: tuple[int, int] = (1, 1)
    AMPLITUDE_FULL = 1
    """Amplitude that stands for 100 V (the public sources' scale)."""
    MAX_STEPS = 1
    """Most steps one burst command may ask for; longer ``step()`` calls are split."""

    def __init__(
        self,
        transport: Transport,
        *,
        channels: ChannelMap | None = None,
        timeout: float = 2.0,
        hz: int = 1000,
        amplitude: int | None = None,
        url: str = "smaract://",
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.transport = transport
        self.channel_map = channels or ChannelMap({1: (0, 1), 2: (1, 1), 3: (2, 1)})
        if not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
            raise ValueError(f"timeout must be > 0 s, got {timeout!r}")
        self.timeout = float(timeout)
        self.url = redact_url(url)
        self._clock = clock
        self._sleep = sleep
        f = self._check_frequency(hz)
        a = self._check_amplitude(self.AMPLITUDE_FULL if amplitude is None else amplitude)
        self._hz = dict.fromkeys(self.channel_map.channels, f)
        self._amplitude = dict.fromkeys(self.channel_map.channels, a)
        self._lock = threading.RLock()  # one exchange (command and answer) at a time
        self._step_lock = threading.Lock()  # one step() at a time
        self._state_lock = threading.Lock()  # _halt and _stepping, read and written together
        self._stepping = 0  # step() calls begun and not yet ended (one runs, others wait for _step_lock)
        self._halt = False  # stop() was called while a step() runs
        self._running: int | None = None  # channel a burst was started on and not confirmed ended
        self.version = ""
        self.model = self.name
        self.identity: str | None = None  # which controller: the dialect's serial number or system id, if told
        self._open_session()

    # -- to implement ---------------------------------------------------------------------
    def _open_session(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _start(self, channel: int, steps: int, hz: int, amplitude: int) -> None:  # pragma: no cover
        """Start a burst of ``steps`` (signed, never 0) on ``channel``; :class:`Refused` if refused."""
        raise NotImplementedError

    def _still_stepping(self, channel: int) -> tuple[bool, str | None]:  # pragma: no cover
        """``(stepping, problem)``: whether the channel still steps; what went wrong if it stopped early."""
        raise NotImplementedError

    def _stop_channel(self, channel: int) -> bool:  # pragma: no cover
        """Stop ``channel``; ``True`` if the controller acknowledged it. Never raises."""
        raise NotImplementedError

    # -- helpers --------------------------------------------------------------------------
    def _check_frequency(self, hz: object) -> int:
        return int(check_setting("frequency", hz, *self.FREQUENCY_RANGE_HZ, "Hz", integer=True))

    def _check_amplitude(self, value: object) -> int:
        lo, hi = self.AMPLITUDE_RANGE
        what = f"amplitude ({self.AMPLITUDE_FULL} = 100 V)"
        return int(check_setting(what, value, lo, hi, integer=True))

    def _joint(self, joint: int) -> tuple[int, int]:
        try:
            return self.channel_map.channels[int(joint)]
        except (KeyError, ValueError, TypeError):
            raise ValueError(f"joint must be one of {sorted(self.channel_map.channels)}, got {joint!r}") from None

    def _where(self) -> str:
        return f"{self.name} on {self.transport.name}"

    # -- settings -------------------------------------------------------------------------
    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint``, Hz (an integer in :attr:`FREQUENCY_RANGE_HZ`).

        Used from the next burst on. Raises ``ValueError`` naming the range; nothing is
        rounded or clipped.
        """
        self._joint(joint)
        self._hz[int(joint)] = self._check_frequency(hz)

    def frequency(self, joint: int) -> float:
        """The stepping frequency of ``joint``, Hz."""
        self._joint(joint)
        return float(self._hz[int(joint)])

    def set_amplitude(self, joint: int, value: int) -> None:
        """Set the step amplitude of ``joint``, controller units (an integer in :attr:`AMPLITUDE_RANGE`).

        :attr:`AMPLITUDE_FULL` units are 100 V. Used from the next burst on. Raises
        ``ValueError`` naming the range; nothing is rounded or clipped.
        """
        self._joint(joint)
        self._amplitude[int(joint)] = self._check_amplitude(value)

    def amplitude(self, joint: int) -> int:
        """The step amplitude of ``joint``, controller units."""
        self._joint(joint)
        return self._amplitude[int(joint)]

    # -- motion ---------------------------------------------------------------------------
    def step(self, joint: int, n: int) -> None:
        """Make ``n`` signed steps on ``joint`` and return once the controller has made them.

        Bursts longer than :attr:`MAX_STEPS` are split; ``n = 0`` sends nothing. Each burst
        is started, then the channel is asked whether it still steps until it has stopped
        (at most ``1.5 d + timeout`` after it started, ``d = |steps| / f``).

        Raises
        ------
        StepsUncertain
            If a burst is refused, unanswered, answered with garbage, outlasts its time,
            ends with the controller reporting a failure, or is stopped by :meth:`stop`:
            ``made`` steps of earlier bursts are certain, at most ``at_most`` were made
            (a burst never makes more than it asked for). The channel is sent a stop
            unless the burst was refused or the controller had stopped it already.
        ValueError
            For an unknown joint or a step count that is not a whole number.
        """
        channel, sign = self._joint(joint)
        n = check_steps(n)
        if n == 0:
            return
        with self._state_lock:  # a stop() from now on stops this step: the halt is never cleared after it is set
            if not self._stepping:
                self._halt = False
            self._stepping += 1
        try:
            with self._step_lock:
                made = 0
                while made != n:
                    left = n - made
                    k = max(-self.MAX_STEPS, min(self.MAX_STEPS, left))
                    self._burst(int(joint), channel, sign, k, made)
                    made += k
        finally:
            with self._state_lock:
                self._stepping -= 1

    def _burst(self, joint: int, channel: int, sign: int, k: int, made: int) -> None:
        hz, amplitude = self._hz[joint], self._amplitude[joint]
        d = abs(k) / hz
        what = f"a burst of {k:+d} steps on joint {joint} (channel {channel})"
        try:
            if self._halt:
                raise StepsUncertain(f"{self._where()}: {what} was not sent: stop() was called", made, made)
            self._running = channel
            try:
                self._start(channel, sign * k, hz, amplitude)
            except ChannelMoving as e:  # nothing of ours sent; the joint moves as the other program drives it
                self._running = None
                raise DrivenElsewhere(f"{e}; nothing was sent of {what}", made) from None
            except Refused as e:
                self._running = None
                raise StepsUncertain(f"{e}; nothing was made of {what}", made, made) from None
            t0 = self._clock()
            deadline = t0 + 1.5 * d + self.timeout
            self._wait_until(t0 + d)  # the burst's own duration, then ask
            while True:
                stepping, problem = self._still_stepping(channel)
                if self._halt:
                    raise _Halted
                if not stepping:
                    self._running = None
                    if problem:
                        raise StepsUncertain(
                            f"{self._where()}: {what} ended early: {problem}", made, made + k
                        )
                    return
                now = self._clock()
                if now >= deadline:
                    raise DeviceError(
                        f"{self._where()}: channel {channel} still stepping {now - t0:.3f} s after {what} "
                        f"started (it should take {d:.3f} s at {hz} Hz; timeout {self.timeout:g} s)"
                    )
                self._sleep(min(POLL_S, deadline - now))
        except StepsUncertain:
            raise
        except _Halted:
            self._running = None  # stop() has sent the stop
            raise StepsUncertain(f"{self._where()}: {what} was stopped part-way by stop()", made, made + k) from None
        except DeviceError as e:
            raise StepsUncertain(f"{e}{self._stop_after(channel)}", made, made + k) from None
        except BaseException:  # Ctrl-C: stop the channel, let the caller's journal cover the burst
            self._stop_after(channel)
            raise

    def _wait_until(self, t: float) -> None:
        """Sleep until ``t`` (s, on :attr:`_clock`), in slices, ending early if :meth:`stop` is called."""
        while not self._halt:
            left = t - self._clock()
            if left <= 0:
                return
            self._sleep(min(left, 0.05))

    def _stop_after(self, channel: int) -> str:
        """Stop a channel after a failure; the words that say how it went. Never raises."""
        acked = self._stop_channel(channel)
        if acked:
            self._running = None
            return f"; channel {channel} was sent a stop, acknowledged"
        return f"; channel {channel} was sent a stop, not acknowledged (it stops by itself after its burst)"

    def stop(self, joint: int | None = None) -> None:
        """Stop ``joint``'s channel (every mapped channel if ``None``) now. Never raises.

        From another thread during :meth:`step`, the burst ends early and that ``step()``
        raises :class:`~stickslip.devices.base.StepsUncertain` (how many steps were made is
        not known), so the position is never taken as complete.
        """
        try:
            targets = (
                sorted({c for c, _ in self.channel_map.channels.values()})
                if joint is None else [self._joint(joint)[0]]
            )
        except ValueError as e:
            log.warning("stop: %s", e)
            return
        with self._state_lock:  # a step() begun (running, or waiting for the line) sends no further burst
            if self._stepping:
                self._halt = True
        for channel in targets:
            if not self._stop_channel(channel):
                log.warning("%s: the stop of channel %d was not acknowledged", self._where(), channel)

    # -- protocol -------------------------------------------------------------------------
    def _volts(self, value: int) -> float:
        return 100.0 * value / self.AMPLITUDE_FULL

    @property
    def info(self) -> DeviceInfo:
        """Model, URL, joints, and in ``extra``: version, port, channels, frequencies, amplitudes."""
        return DeviceInfo(
            url=self.url,
            model=self.model,
            joints=tuple(sorted(self.channel_map.channels)),
            extra={
                "version": self.version,
                "port": self.transport.name,
                "channels": self.channel_map.text(),
                "frequency_hz": {
                    f"ch{c}": float(self._hz[j]) for j, (c, _) in sorted(self.channel_map.channels.items())
                },
                "amplitude": {
                    f"ch{c}": self._amplitude[j] for j, (c, _) in sorted(self.channel_map.channels.items())
                },
            },
            identity=self.identity,
        )

    def settings(self) -> dict[str, object]:
        """Channel map, frequency (Hz), amplitude (controller units and V) per joint, timeout (s)."""
        return {
            "channels": self.channel_map.text(),
            "frequency_hz": {str(j): float(f) for j, f in sorted(self._hz.items())},
            "amplitude": {str(j): a for j, a in sorted(self._amplitude.items())},
            "amplitude_v": {str(j): round(self._volts(a), 6) for j, a in sorted(self._amplitude.items())},
            "timeout_s": self.timeout,
            "port": self.transport.name,
        }

    def close(self) -> None:
        """Stop a channel whose burst was never confirmed ended, then release the transport.

        Never raises. Channels this session did not leave stepping are not touched (another
        program may be driving them).
        """
        if self.transport.closed:
            return
        try:
            if self._running is not None:
                self._stop_after(self._running)
        finally:
            self.transport.close()

    def __enter__(self) -> SmarActBase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Halted(Exception):
    """stop() was called while a burst ran."""
