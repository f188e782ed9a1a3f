"""A stream cut into frames, and the samples a detector keeps for the judgements that look back.

The detectors are fed blocks of any length; everything they decide happens at frame
boundaries counted from the stream start (frame ``i`` covers samples
``[i*hop, i*hop + frame)``), so their events do not depend on how the stream was cut into
blocks. :class:`FrameCutter` holds the samples of the frame not yet complete;
:class:`HeadSamples` keeps the stream's first samples (the warm-up's) and
:class:`RecentSamples` its latest ones.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..events import sample_block
from .spectra import SPECTRA, SpectraParams

__all__ = ["FrameCutter", "HeadSamples", "RecentSamples", "bounded"]

FloatArray = NDArray[np.float64]


def bounded(block: NDArray[Any], p: SpectraParams = SPECTRA) -> FloatArray:
    """A mono block as float64, NaN and values beyond ``sample_limit`` clipped (``ValueError`` if not 1-D floats)."""
    x = np.asarray(sample_block(block), dtype=np.float64)
    lim = p.sample_limit
    # NaN, infinity or absurd values: bounded (the largest and the smallest sample: no array of magnitudes made)
    if x.size and not (float(x.max()) <= lim and float(x.min()) >= -lim):
        x = np.clip(np.nan_to_num(x, nan=0.0, posinf=lim, neginf=-lim), -lim, lim)
    return x


class FrameCutter:
    """Cuts a stream into frames of ``frame`` samples every ``hop``: the frames each block completes."""

    def __init__(self, frame: int, hop: int) -> None:
        self.frame, self.hop = int(frame), int(hop)
        self.reset()

    def reset(self) -> None:
        """Forget the samples held; the next sample pushed is sample 0."""
        self._buf = np.zeros(0, dtype=np.float64)
        self._buf_start = 0  # absolute sample index of _buf[0]
        #: the absolute sample index where the next frame starts
        self.next = 0

    @property
    def fresh(self) -> bool:
        """Nothing pushed since the last reset: the next push's frames are those of its samples alone."""
        return self.next == 0 and self._buf.size == 0

    def push(self, x: FloatArray) -> FloatArray:
        """Hold the samples ``x``; the frames now complete (frames x ``frame``, a read-only view).

        Call :meth:`advance` with the number of frames used before the next push.
        """
        F, H = self.frame, self.hop
        self._buf = np.concatenate((self._buf, x)) if self._buf.size else x.copy()
        avail_end = self._buf_start + self._buf.size
        n_frames = (avail_end - F - self.next) // H + 1 if avail_end - self.next >= F else 0
        seg = self._buf[self.next - self._buf_start :]
        if n_frames <= 0:
            return np.zeros((0, F))
        # the frames as a read-only view of the samples (made directly: as_strided's checks cost more than the view)
        step = seg.itemsize
        view: FloatArray = np.ndarray((n_frames, F), dtype=seg.dtype, buffer=seg, strides=(H * step, step))
        view.flags.writeable = False
        return view

    def ends(self, n_frames: int) -> NDArray[np.int64]:
        """The absolute index of the last sample of each of the next ``n_frames`` frames."""
        return self.next + np.arange(n_frames, dtype=np.int64) * self.hop + self.frame - 1

    def advance(self, n_frames: int) -> None:
        """``n_frames`` frames were used: drop the samples no later frame needs."""
        self.next += n_frames * self.hop
        drop = self.next - self._buf_start
        if drop > 0:
            self._buf = self._buf[drop:]
            self._buf_start += drop


class HeadSamples:
    """The stream's first ``n`` samples, once they are all in (:attr:`samples`; None until then)."""

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self.reset()

    def reset(self) -> None:
        self._parts: list[FloatArray] = []
        self._got = 0
        self.samples: FloatArray | None = None

    def push(self, x: FloatArray) -> None:
        if self.samples is not None:
            return
        need = self.n - self._got
        if need > 0 and x.size:
            self._parts.append(x[:need].copy())
            self._got += min(need, x.size)
        if self._got >= self.n:
            self.samples = np.concatenate(self._parts)
            self._parts = []


class RecentSamples:
    """The stream's latest samples: at least the last ``keep`` before the block pushed last, and that block."""

    def __init__(self, keep: int) -> None:
        self.keep = int(keep)
        self.reset()

    def reset(self) -> None:
        self._ring: list[FloatArray] = []
        self._ring0 = 0  # absolute index of the first sample kept
        self._ring_n = 0

    def push(self, x: FloatArray) -> None:
        """Keep a copy of ``x`` (the next samples after those pushed before)."""
        self._ring.append(x.copy())
        self._ring_n += x.size
        if self._ring_n - self._ring[-1].size > 2 * self.keep:  # trim now and then, not every block
            whole = np.concatenate(self._ring[:-1])[-self.keep :]
            self._ring0 += self._ring_n - self._ring[-1].size - whole.size
            self._ring = [whole, self._ring[-1]]
            self._ring_n = whole.size + self._ring[-1].size

    def get(self, lo: int, hi: int) -> FloatArray | None:
        """The stream's samples ``[lo, hi)`` (absolute indices), or None where they are not kept."""
        if lo < self._ring0 or hi > self._ring0 + self._ring_n or lo < 0 or hi <= lo:
            return None
        whole = np.concatenate(self._ring) if len(self._ring) > 1 else self._ring[0]
        if len(self._ring) > 1:
            self._ring = [whole]
        return np.asarray(whole[lo - self._ring0 : hi - self._ring0], dtype=np.float64)
