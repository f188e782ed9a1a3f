"""When a latched detector re-arms: the joint steps again (a session with several stops).

After a fire the detector stays latched (one stop, one event). It re-arms in one of two
ways: the quiet release (the stop-likeness stayed under ``threshold - hysteresis`` for the
tuning's ``release_s``), or, once latched for ``after_s`` and not held by a confirmation,
when over the last ``release_s`` at least ``share`` of the frames sounded like stepping
again rather than like the stop that fired (:class:`StopRelease`). A frame sounds like
stepping again when its departure from the frozen template, projected on the stop's *own*
departure (the median of the first ``stop_rows`` frames after the fire), is under ``c`` of
it, and it is not ``silent_db`` under the template (silence after a stop is not stepping).
The template is then learned anew from those frames: after a stop the joint may step at
another rate or the other way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..paramfield import param
from .tuned import TunedTemplate

__all__ = ["RELEASE", "Release", "ReleaseParams", "StopRelease"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ReleaseParams:
    """When a latched detector re-arms because the joint steps again."""

    share: float = param(
        0.8, "", "this share of the release window's frames must sound like stepping (not: every frame quiet)"
    )
    after_s: float = param(
        0.5, "s", "counted only once latched this long: a fire on a voice is the confirmation's to reject"
    )
    stop_rows: int = param(8, "frames", "the stop's own departure is the median of this many frames after the fire")
    c: float = param(0.5, "", "a frame whose departure projects under this share of the stop's sounds like stepping")
    silent_db: float = param(10.0, "dB", "... unless its median sub-band is this far under the template (silence)")


RELEASE = ReleaseParams()


class Release:
    """A sliding window of ``frames`` frames: :meth:`push` is True once ``share`` of it sounded like stepping.

    :meth:`stepping_rows` gives those frames' levels (the template is learned anew from them).
    """

    def __init__(self, frames: int, share: float = RELEASE.share) -> None:
        self.frames = max(1, int(frames))
        self.share = share
        self.reset()

    def reset(self) -> None:
        self._flags: list[bool] = []
        self._rows: list[FloatArray | None] = []
        self._start = 0
        self.count = 0

    def push(self, stepping: bool, row: FloatArray | None = None) -> bool:
        self._flags.append(stepping)
        self._rows.append(row)
        self.count += stepping
        if len(self._flags) - self._start > self.frames:
            self.count -= self._flags[self._start]
            self._rows[self._start] = None
            self._start += 1
            if self._start > 4 * self.frames:  # keep the lists short
                del self._flags[: self._start]
                del self._rows[: self._start]
                self._start = 0
        n = len(self._flags) - self._start
        return n >= self.frames and self.count >= self.share * n

    def push_many(self, stepping: NDArray[np.bool_], rows: FloatArray, armed: bool = True) -> int | None:
        """:meth:`push` of each frame in turn (``rows[i]`` its levels), stopping after the first that fills the window.

        The index of that frame, or None (all pushed); with ``armed`` False all are pushed
        and None is returned. The window's counts come from one cumulative sum.
        """
        prior = self._flags[self._start :]
        m, frames = len(prior), self.frames
        csum = np.concatenate(([0], np.cumsum(np.concatenate((np.asarray(prior, dtype=bool), stepping)))))
        pos = m + np.arange(1, len(stepping) + 1)  # frames in the lists once frame i is pushed
        n = np.minimum(pos, frames)
        full = (n >= frames) & (csum[pos] - csum[pos - n] >= self.share * n)
        hit = np.flatnonzero(full) if armed else np.empty(0, dtype=np.intp)
        upto = int(hit[0]) + 1 if hit.size else len(stepping)
        keep = min(m + upto, frames)
        flags = [*prior, *stepping[:upto].tolist()][-keep:]
        self._rows = [*self._rows[self._start :], *rows[max(0, upto - keep) : upto]][-keep:]
        self._flags, self._start, self.count = flags, 0, sum(flags)
        return upto - 1 if hit.size else None

    def stepping_rows(self) -> list[FloatArray]:
        """The levels of the window's frames that sounded like stepping (those pushed with a row)."""
        return [
            r for f, r in zip(self._flags[self._start :], self._rows[self._start :], strict=True) if f and r is not None
        ]


class StopRelease:
    """The stepping-again release of one latched stop (see the module docstring)."""

    def __init__(self, tuned: TunedTemplate, p: ReleaseParams = RELEASE) -> None:
        self.p = p
        self.delta = np.asarray(tuned.signature_db, dtype=np.float64)
        self.inv_sigma = 1.0 / np.asarray(tuned.spread_db, dtype=np.float64)
        self.window = Release(tuned.release_frames, p.share)
        self.min_latch = int(math.ceil(p.after_s * tuned.sample_rate / tuned.hop))
        self.reset()

    def reset(self) -> None:
        """A new fire (or none): the window and the stop's own sound forgotten."""
        self.window.reset()
        self._stop_rows: list[FloatArray] = []  # the first frames after a fire (departures from the template)
        self._stop_e: FloatArray | None = None  # the stop's own departure (their median), weighted and scaled
        self.latched_frames = 0  # frames heard since the latest fire

    def frame(self, d: FloatArray, v: FloatArray, held: bool) -> bool:
        """One latched frame (its departure ``d`` and levels ``v``, dB): whether the detector re-arms at it."""
        self.latched_frames += 1
        stepping = self.stepping_again(d)
        return self.latched_frames > self.min_latch and self.window.push(stepping, v) and not held

    def scan(self, v: FloatArray, template: FloatArray, held: bool) -> int | None:
        """While latched: the frames ``v`` (levels, dB) into the window; the index of the re-arming frame, or None.

        The template is frozen while latched, so each frame's departure is known before the
        frames are judged: the piece is cut at the frame that re-arms, and the frames after
        it are heard with the template learned anew.
        """
        d = v - template
        n, k = v.shape[0], 0
        while self._stop_e is None and k < n:  # frames that still teach the stop's own departure
            if self.frame(d[k], v[k], held):
                return k
            k += 1
        # the stop's departure known: the rest judged at once, as stepping_again and frame would one by one
        first = k + max(0, self.min_latch - self.latched_frames)  # the first frame counted in the window
        if first >= n:
            self.latched_frames += n - k
            return None
        stepping = self._stepping(d[first:])
        hit = self.window.push_many(stepping, v[first:], armed=not held)
        end = n if hit is None else first + hit + 1
        self.latched_frames += end - k
        return None if hit is None else first + hit

    def _stepping(self, d: FloatArray) -> NDArray[np.bool_]:
        """:meth:`stepping_again` of each row of ``d`` once the stop's own departure is known."""
        assert self._stop_e is not None
        like = (np.sum(d * self._stop_e, axis=-1) < self.p.c) & (np.median(d, axis=-1) > -self.p.silent_db)
        return np.asarray(like, dtype=np.bool_)

    def stepping_again(self, d: FloatArray) -> bool:
        """Whether a latched frame (its departure ``d`` from the frozen template, dB) sounds like stepping again.

        Judged against the stop's *own* sound, not against the threshold: after a stop the
        joint may step at another rate or the other way, which the frozen template does not
        know (4 % of rate shows as drops and rises of a few spreads), while the stop's
        departure is the change that fired.
        """
        if self._stop_e is None:
            self._stop_rows.append(d)
            if len(self._stop_rows) < self.p.stop_rows:
                return False
            e = np.median(np.stack(self._stop_rows), axis=0)
            self._stop_rows = []
            w = self.inv_sigma**2
            if float((e * w) @ e) < 1.0:  # the stop departed by less than a spread in all: judge by the tuned signature
                e = self.delta
            # weighted, and scaled so that the projection of the stop's own departure is 1
            self._stop_e = e * w / max(float((e * w) @ e), 1e-12)
        return bool(self._stepping(d))
