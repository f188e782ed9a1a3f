"""What the confirmation keeps of the stream: the fast path's per-frame evidence, and the latest samples.

Both are indexed from the stream start (frame ``i`` ends at sample ``i * hop + frame - 1``),
and each keeps at least as far back as any judgement looks, whatever the block size: the
verdicts do not depend on how the stream is cut into blocks.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["FrameLog", "KeptSamples"]

FloatArray = NDArray[np.float64]


class FrameLog:
    """The fast path's per-frame margins over its threshold and hot flags, the latest ``keep`` frames at least.

    A margin is ``a / threshold - 1`` for a template tuning (>= 0: stop-like), the level
    over the threshold in dB for a band tuning; NaN while the template is learned.
    """

    def __init__(self, hop: int, frame: int, sample_rate: int, keep: int) -> None:
        self.hop, self.frame, self.sample_rate, self.keep = hop, frame, sample_rate, keep
        self.reset(0.0)

    def reset(self, t0_s: float) -> None:
        self.t0 = float(t0_s)
        self._margins: list[float] = []
        self._hot: list[bool] = []
        #: the frame index of the first frame kept
        self.base = 0

    def absorb(self, evidence: list[float] | None, hot: list[bool] | None) -> None:
        """Take (and clear) the frames the detector added to its evidence lists."""
        if evidence:
            self._margins.extend(evidence)
            evidence.clear()
        if hot:
            self._hot.extend(hot)
            hot.clear()
        extra = len(self._margins) - self.keep
        if extra > 4 * self.keep:  # trim now and then, not every block
            del self._margins[:extra]
            del self._hot[:extra]
            self.base += extra

    def window(self, fire: int, n: int) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Margins (NaN as -1) and hot flags of the ``n`` frames after frame ``fire``."""
        lo, hi = max(fire + 1 - self.base, 0), max(fire + 1 - self.base + n, 0)
        m = np.nan_to_num(np.asarray(self._margins[lo:hi], dtype=np.float64), nan=-1.0)
        return m, np.asarray(self._hot[lo:hi], dtype=bool)

    def between(self, i0: int, i1: int) -> FloatArray:
        """The margins of frames ``i0 .. i1 - 1`` that are kept, as they are (NaN kept)."""
        return np.asarray(self._margins[max(i0 - self.base, 0) : max(i1 - self.base, 0)], dtype=np.float64)

    def margin(self, i: int) -> float:
        """The margin of frame ``i`` (-1 where it is not kept or NaN)."""
        j = i - self.base
        if not 0 <= j < len(self._margins):
            return -1.0
        v = self._margins[j]
        return v if math.isfinite(v) else -1.0

    def hot(self, i: int) -> bool:
        """Whether frame ``i`` (kept) was hot."""
        return self._hot[i - self.base]

    def end_s(self, i: int) -> float:
        """Stream time of the last sample of frame ``i``, s."""
        return self.t0 + (i * self.hop + self.frame - 1) / self.sample_rate

    def run_start(self, k: int, lo: int, level: float, dips: int) -> int:
        """The first frame of the run that ends in frame ``k``, walking back no further than ``lo``: frames whose margin
        is at least ``level``, dips under it of up to ``dips`` frames not ending the run."""
        while k > lo:
            if self.margin(k - 1) >= level:
                k -= 1
                continue
            j = k - 1
            while j >= lo and self.margin(j) < level and k - j <= dips:
                j -= 1
            if j >= lo and self.margin(j) >= level and k - 1 - j <= dips:
                k = j
                continue
            break
        return k

    def crossing_s(self, f: int, lag_s: float) -> float:
        """The onset of a crossing of the threshold in frame ``f``: interpolated from the frame before, less the lag."""
        m0, m1 = self.margin(f - 1), self.margin(f)
        frac = (0.0 - m0) / (m1 - m0) if m0 < 0.0 < m1 else 1.0
        return self.end_s(f) - (1.0 - frac) * self.hop / self.sample_rate - lag_s


class KeptSamples:
    """The stream's latest samples (float64 copies): at least the last ``keep``, from absolute sample 0."""

    def __init__(self, keep: int) -> None:
        self.keep = keep
        self.reset()

    def reset(self) -> None:
        self._chunks: list[FloatArray] = []
        self._chunks0 = 0
        self._chunks_n = 0

    def keep_copy(self, x: NDArray[Any]) -> FloatArray:
        """Keep a copy of ``x`` (damaged samples are mended when read, :meth:`get`); the copy."""
        v = np.array(x, dtype=np.float64)
        self._chunks.append(v)
        self._chunks_n += v.size
        if self._chunks_n > 2 * self.keep:  # trim now and then, not every block
            whole = np.concatenate(self._chunks)[-self.keep :]
            self._chunks0 += self._chunks_n - whole.size
            self._chunks, self._chunks_n = [whole], whole.size
        return v

    def get(self, lo: int, hi: int) -> FloatArray:
        """The kept samples with absolute indices lo .. hi - 1 (those still kept; NaN and infinities mended)."""
        whole = np.concatenate(self._chunks) if len(self._chunks) != 1 else self._chunks[0]
        self._chunks = [whole]
        a, b = max(lo - self._chunks0, 0), max(min(hi - self._chunks0, whole.size), 0)
        if b <= a:
            return np.zeros(0)
        v = whole[a:b]
        return v if np.all(np.isfinite(v)) else np.nan_to_num(v, nan=0.0, posinf=1.0, neginf=-1.0)
