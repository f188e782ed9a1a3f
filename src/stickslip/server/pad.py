"""The jog pad of the page (and of the API): held directions in, key names out, with a dead man's switch.

:func:`stickslip.procedures.jog.jog` reads keys from a
:class:`~stickslip.procedures.jog.KeySource`, the way a terminal types them: a held key
repeats, and the tip stops when no repeat comes within the session's ``hold``.
:class:`PadKeys` is that source for a web page or a client: while a direction is held
the client sends it again at least every :data:`KEEPALIVE_S` (a keep-alive); each one is
a key repeat. When none has come for :data:`HOLD_S` (the client let go, hung, or lost its
connection), the pad itself says ``space`` (stop at once). After :data:`IDLE_END_S`
with nothing held it says ``q`` and the jog session ends, so that a move can run.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

__all__ = ["DIRECTIONS", "HOLD_S", "IDLE_END_S", "KEEPALIVE_S", "PadKeys"]

KEEPALIVE_S = 0.05
"""How often a client repeats a held direction, s (the page sends one every 50 ms)."""

HOLD_S = 0.15
"""A held direction with no keep-alive for this long is let go (the dead man's switch), s.

With the jog loop's tick (0.05 s) and one tick's bursts, motion ends within 0.3 s of the
last keep-alive (``benchmarks/bench_serve.py`` measures it)."""

IDLE_END_S = 2.0
"""Nothing held for this long ends the jog session (a move may run then), s."""

DIRECTIONS = {
    "+x": "right",
    "-x": "left",
    "+y": "up",
    "-y": "down",
    "+z": "pgup",
    "-z": "pgdn",
}
"""Tip directions a client names, and the jog key each is (names of :data:`stickslip.procedures.jog.DIRECTION_KEYS`)."""

class PadKeys:
    """Key names for :func:`~stickslip.procedures.jog.jog` from held directions (a :class:`KeySource`).

    Parameters
    ----------
    hold_s : float
        A held direction without a keep-alive for this long is let go, s.
    idle_end_s : float
        Nothing held for this long ends the session (``q``), s.
    clock : callable
        Monotonic clock, s.
    """

    def __init__(
        self, hold_s: float = HOLD_S, idle_end_s: float = IDLE_END_S, clock: Callable[[], float] = time.monotonic
    ):
        self.hold_s = float(hold_s)
        self.idle_end_s = float(idle_end_s)
        self._clock = clock
        self._cond = threading.Condition()
        self._keys: list[str] = []
        self._held: str | None = None
        self._last = clock()  # the last keep-alive or release
        self._ended = False
        self._reading = False
        self.deadman = 0
        """How many times a held direction was let go for want of a keep-alive."""

    @property
    def held(self) -> str | None:
        """The direction held now (``"+x"``, ...), or ``None``."""
        return self._held

    def hold(self, direction: str, speed: int | None = None) -> None:
        """``direction`` is held (a keep-alive); ``speed`` (1-7) picks the speed preset. ``ValueError`` if unknown."""
        key = DIRECTIONS.get(direction)
        if key is None:
            raise ValueError(f"unknown direction {direction!r} (one of {', '.join(DIRECTIONS)})")
        if speed is not None and not (isinstance(speed, int) and 1 <= speed <= 7):
            raise ValueError(f"speed must be a preset 1-7, got {speed!r}")
        with self._cond:
            if speed is not None:
                self._keys.append(str(speed))
            self._keys.append(key)
            self._held = direction
            self._last = self._clock()
            self._cond.notify_all()

    def release(self) -> None:
        """Let go: stop at once."""
        with self._cond:
            self._keys.append("space")
            self._held = None
            self._last = self._clock()
            self._cond.notify_all()

    def end(self) -> None:
        """End the session now (STOP, or the client went away)."""
        with self._cond:
            self._keys.extend(["space", "q"])
            self._held = None
            self._ended = True
            self._cond.notify_all()

    def read(self, timeout: float) -> list[str]:
        """The keys since the last call, waiting up to ``timeout`` s for one; ``space`` when the dead man lets go."""
        with self._cond:
            if not self._keys:
                self._cond.wait(max(0.0, min(timeout, self.hold_s)))
            keys, self._keys = self._keys, []
            now = self._clock()
            if not self._reading:  # the session starts reading now: nothing moved before, the hold counts from here
                self._reading = True
                self._last = now
            if self._held is not None and now - self._last > self.hold_s:
                self._held = None
                self._last = now  # let go now: the session's idle time counts from here
                self.deadman += 1
                keys.append("space")
            elif self._held is None and not self._ended and now - self._last > self.idle_end_s:
                self._ended = True
                keys.append("q")
            return keys

    def close(self) -> None:
        """Nothing to give back (a terminal would be restored here)."""
