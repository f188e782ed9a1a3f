"""A fire is a stop only if it persists: the window after it, and the rule it must meet.

A real end stop lasts as long as the controller keeps stepping into it; interference that
looks like the stop for a moment (a held chord, a voice's fricatives in the stop's
sub-band, babble over a run of weaker steps) does not. Of the frames of the ``confirm_s``
after a fire, at least ``min_share`` must be stop-like (the stop-likeness at or above the
tuning's threshold, by the fit or by the drop channel), no run of the others may last
``gap_s``, and at least ``min_hot`` must be *hot* (the detector's full verdict: also the
fit's residual and the drops the stop shows in proportion). A voice over a stop-like
sub-band keeps the stop-likeness up for seconds but seldom shows the stop's drops with it;
a stop shows both, as long as the joint steps into it. A fire that comes within
``recent_s`` of a rejected one must persist for ``after_reject_s``: the interference is
still going on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..paramfield import param
from ..tuningfile import Tuning

__all__ = [
    "PERSISTENCE",
    "PersistenceParams",
    "Windows",
    "check_confirm_s",
    "longest_gap",
    "persisted",
    "stoplike_throughout",
]


@dataclass(frozen=True)
class PersistenceParams:
    """When a fire persisted: the window after it and the rule it must meet."""

    confirm_s: float = param(
        0.5, "s", "a stop must persist this long after the fire (a traverse steps this much longer into it)"
    )
    min_share: float = param(0.7, "", "this share of the window's frames must be stop-like ...")
    gap_s: float = param(
        0.15, "s", "... with no run of others this long (inside true stops: 40 ms; under talk over joint P: 88 ms) ..."
    )
    min_hot: float = param(0.25, "", "... and this share must be hot: the fit's residual and the drops too")
    recent_s: float = param(
        2.0, "s", "a fire this soon after a rejected one gets the longer window: the interference goes on"
    )
    after_reject_s: float | None = param(2.0, "s", "that window (None: confirm_s): talk fires again and again")
    max_confirm_s: float = param(5.0, "s", "the longest window accepted (a traverse steps this long into the stop)")

    def __post_init__(self) -> None:
        if not (isinstance(self.min_share, (int, float)) and 0.0 < float(self.min_share) <= 1.0):
            raise ValueError(f"min_share = {self.min_share!r} is outside (0, 1]")
        if not (isinstance(self.min_hot, (int, float)) and 0.0 <= float(self.min_hot) <= 1.0):
            raise ValueError(f"min_hot = {self.min_hot!r} is outside [0, 1]")


PERSISTENCE = PersistenceParams()


def check_confirm_s(confirm_s: float, p: PersistenceParams = PERSISTENCE) -> float:
    """``confirm_s`` as a float, or ``ValueError`` naming the accepted range (0 = no confirmation)."""
    try:
        c = float(confirm_s)
    except (TypeError, ValueError):
        raise ValueError(f"confirm_s = {confirm_s!r} is not a number of seconds") from None
    if not (math.isfinite(c) and 0.0 <= c <= p.max_confirm_s):
        raise ValueError(f"confirm_s = {confirm_s!r} s is outside [0, {p.max_confirm_s:g}] (0: no confirmation)")
    return c


@dataclass(frozen=True)
class Windows:
    """The confirmation's spans for one tuning and window, in frames of the tuning's hop."""

    #: the window after a fire
    window: int
    #: the window of a fire that comes within ``recent_s`` of a rejected one (the interference goes on)
    after_reject: int
    #: how soon after a rejected window a fire counts as recent
    recent: int
    #: the frames a fire needs (the hold and its dips), plus one
    refire: int
    #: a run of this many frames that are not stop-like ends a stop
    gap: int

    @property
    def hold(self) -> int:
        """The hold and its dips: the frames that fire."""
        return self.refire - 1

    @property
    def look(self) -> int:
        """How far back from a fire the evidence is always kept, whatever the block size."""
        return self.after_reject + 4 * self.refire - 2

    @classmethod
    def of(cls, tuning: Tuning, confirm_s: float, p: PersistenceParams = PERSISTENCE) -> Windows:
        """The spans for ``tuning`` and a window of ``confirm_s`` (checked, s)."""
        H, sr = int(tuning.hop), int(tuning.sample_rate)
        window = max(1, int(round(confirm_s * sr / H)))
        a = confirm_s if p.after_reject_s is None else max(confirm_s, check_confirm_s(p.after_reject_s, p))
        hold = int(tuning.hold_frames) + int(tuning.max_dips)
        return cls(
            window=window,
            after_reject=max(window, int(round(a * sr / H))),
            recent=int(round(p.recent_s * sr / H)),
            refire=hold + 1,
            gap=max(hold, int(round(p.gap_s * sr / H))),
        )


def longest_gap(ok: NDArray[np.bool_]) -> int:
    """The longest run of False in ``ok``."""
    edges = np.flatnonzero(np.diff(np.concatenate(([1], ok.astype(np.int8), [1]))))
    return int(np.max(edges[1::2] - edges[0::2])) if edges.size else 0


def persisted(
    m: NDArray[np.float64], hot: NDArray[np.bool_], gap_frames: int, p: PersistenceParams = PERSISTENCE
) -> bool:
    """Did the stop persist over the window's margins ``m`` and hot flags? (none heard: nothing contradicts it)"""
    if m.size and float(np.mean(hot)) < float(p.min_hot):
        return False
    return stoplike_throughout(m, gap_frames, p)


def stoplike_throughout(m: NDArray[np.float64], gap_frames: int, p: PersistenceParams = PERSISTENCE) -> bool:
    """Were ``min_share`` of the window's margins ``m`` stop-like, with no run of others ``gap_frames`` long? (the
    persistence rule without its hot share; none heard: nothing contradicts it)"""
    if m.size == 0:
        return True
    ok = m >= 0.0
    if float(np.mean(ok)) < float(p.min_share):
        return False
    return longest_gap(ok) < gap_frames
