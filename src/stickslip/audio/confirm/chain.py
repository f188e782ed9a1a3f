"""The fire being confirmed, and the fires rejected before it: a chain of fires on one interference.

A fire that does not persist is rejected and the fast path listens again at once. What
happens next depends on that history: a fire soon after a rejected one (``recent_s``) gets
the longer window (the interference goes on) and keeps the chain's stepping as its
reference; a fire heard without a gap since the rejected window may be a stop that began
inside it (its onset is uncertain); a rejected window that was *covered* (sound added where
the stop lowers it) may have hidden this stop (:mod:`.onset`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..events import StopEvent
from .evidence import FrameLog
from .onset import OnsetJudge
from .persistence import Windows, longest_gap

__all__ = ["Fire", "FireChain"]


@dataclass
class Fire:
    """A fire being confirmed: its event, its frame and its window (frames)."""

    ev: StopEvent
    frame: int
    window: int

    def end(self, hop: int, frame: int) -> int:
        """The sample after the window's last frame, counted from the stream's start (``hop``, ``frame``: samples)."""
        return (self.frame + self.window) * hop + frame


class FireChain:
    """The pending fire and the rejection history since the last confirmed stop (see the module docstring)."""

    def __init__(self, w: Windows, frames: FrameLog, onset: OnsetJudge) -> None:
        self.w, self.frames, self.onset = w, frames, onset
        self.reset()

    def reset(self) -> None:
        #: the fire being confirmed (None: none)
        self.pending: Fire | None = None
        self._last_reject: int | None = None
        self._rejected_at: int | None = None
        #: the end of the latest rejected window that was covered (since the last confirmed stop)
        self.covered_at: int | None = None
        #: the frame of the latest rejected fire since the last confirmed stop
        self.rejected_fire: int | None = None

    def refired(self, fire: int) -> Fire | None:
        """The fast path fired again at frame ``fire`` inside the pending window: the pending fire, rejected."""
        prev = self.pending
        if prev is None:
            return None
        self._last_reject = self.rejected_fire = prev.frame
        if self.onset.covered(self.frames.window(prev.frame, fire - prev.frame)[0]):
            self.covered_at = prev.frame  # what broke it covered the stop: this fire may be the same stop
        self.pending = None
        return prev

    def flagged(self, ev: StopEvent, fire: int) -> StopEvent:
        """``ev`` (a fire at frame ``fire``), flagged where the stop-like sound had not gone away since the last
        rejected window: the stop may have begun inside it, or before it; when, is not known."""
        if self._rejected_at is not None and self._continues_from_rejection(fire):
            ev = replace(ev, onset_uncertain=True)
        self._rejected_at = None
        return ev

    def _continues_from_rejection(self, fire: int) -> bool:
        """No gap of ``w.gap`` frames between the last rejected window's end and frame ``fire``?"""
        assert self._rejected_at is not None
        if fire - self._rejected_at <= self.w.refire:
            return True  # heard at once on un-latching
        m, _ = self.frames.window(self._rejected_at - 1, fire - self._rejected_at)  # frames rejected_at .. fire - 1
        return longest_gap(m >= 0.0) < self.w.gap

    def recent(self, fire: int) -> bool:
        """Does a fire at frame ``fire`` come within ``recent_s`` of a rejected one?"""
        return self._last_reject is not None and fire - self._last_reject <= self.w.recent

    def start(self, ev: StopEvent, fire: int, recent: bool) -> None:
        """Hold the fire ``ev`` at frame ``fire`` for its window."""
        self.pending = Fire(ev, fire, self.w.after_reject if recent else self.w.window)

    def due(self, frames_seen: int) -> Fire | None:
        """The pending fire, taken, once its window is heard (``frames_seen`` frames); else None."""
        fire = self.pending
        if fire is None or frames_seen <= fire.frame + fire.window:
            return None
        self.pending = None
        return fire

    def rejected(self, fire: Fire) -> None:
        """``fire``'s window did not persist: the chain goes on from its end."""
        last = fire.frame + fire.window
        self._rejected_at = self._last_reject = last
        self.rejected_fire = fire.frame
        if self.onset.covered(self.frames.window(fire.frame, fire.window)[0]):
            self.covered_at = last

    def confirmed(self) -> None:
        """A stop was confirmed: the rejections before it no longer bear on the next one."""
        self.covered_at = self.rejected_fire = None
