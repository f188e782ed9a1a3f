"""The hold: a stop fires when ``hold`` of the last ``hold + max_dips`` frames were hot and it has not decayed.

A knock or a burst of speech lights fewer frames than a stop, and a transient rings down
while a stop does not: the frame that fires must have at least ``decay_ratio`` of the
largest stop-likeness in the window. The onset is the interpolated crossing of the
threshold that began the run of hot frames (a lone earlier hot frame is forgotten), less
the lag the drop channel's average costs (:mod:`.drops`).
"""

from __future__ import annotations

import math

from .tuned import TunedTemplate

__all__ = ["Hold"]


class Hold:
    """The hold window over the frames while the detector is not latched (see the module docstring)."""

    def __init__(self, tuned: TunedTemplate) -> None:
        self.tuned = tuned
        self.window_n = tuned.hold_frames + tuned.max_dips
        self.reset(0.0)

    def reset(self, t0_s: float) -> None:
        self.t0 = t0_s
        self.clear()
        #: the latest frame's stop-likeness (-inf: none yet, or the template was learned anew)
        self.prev_a = -math.inf
        #: the onset of the current run of hot frames: the threshold's crossing, stream time, s
        self.cross_t = math.nan

    def clear(self) -> None:
        """Forget the window (re-armed)."""
        #: bit i: frame i hops ago was hot
        self.mask = 0
        self.recent: list[float] = []

    def frame(self, ai: float, hi: bool, end: int, lag_s: float, prev: float) -> bool:
        """One frame (stop-likeness ``ai``, hot ``hi``, last sample ``end``; ``prev`` the frame before's): fires?"""
        tu = self.tuned
        if hi and (self.mask == 0 or (not self.mask & 1 and self.mask.bit_count() < max(1, tu.hold_frames // 2))):
            # the latest upward crossing that starts a run (a lone earlier hot frame is forgotten)
            t_end = self.t0 + end / tu.sample_rate
            if math.isfinite(prev) and prev < tu.threshold and ai > prev:
                frac = (tu.threshold - prev) / (ai - prev)
                self.cross_t = float(t_end - (1 - frac) * tu.hop / tu.sample_rate) - lag_s
            else:
                self.cross_t = t_end - lag_s
        self.mask = ((self.mask << 1) | int(hi)) & ((1 << self.window_n) - 1)
        self.recent = (self.recent + [ai])[-self.window_n :]
        return hi and self.mask.bit_count() >= tu.hold_frames and ai >= tu.decay_ratio * max(self.recent)

    def settle(self) -> None:
        """After a frame: an empty window forgets its stop-likeness."""
        if self.mask == 0:
            self.recent = []
