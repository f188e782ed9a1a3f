"""Finding the tip without being told where it is: take what moved.

A joint is stepped back and forth while the camera looks (the device part is
:func:`stickslip.procedures.camera.acquire_tip`); :func:`find_moving_tip` compares the
frames taken at one end of the motion with those taken at the other:

1. the mean of each group, and their difference (each line's median over what did not
   change taken out: an SEM's scan lines change level from frame to frame) smoothed over 1 px; a pixel *changed*
   when the difference stands 5 noise spreads out (the noise from the frames of one group
   against each other, or from a frame's own pixel noise), and at least a fifth of the
   largest change;
2. the needle's axis is the long axis of what changed (a needle swung sideways sweeps
   along its length; one moved along itself changes its tapered edges), and its tip the
   end of what changed further from the field's edge (the needle enters the field there);
3. the tip is then the needle's furthest point that way in a window around that end, in
   the current frame (the needle: the largest region standing :data:`NEEDLE_SPREADS`
   spreads from the window edge's grey levels that runs out of the window).

Raises :class:`AcquireError` when nothing moved (or only specks), when no needle stands
where what moved ends, or the frames disagree in size.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from .template import noise_sigma

__all__ = ["AcquireError", "find_moving_tip", "CHANGE_SPREADS"]

FloatArray = NDArray[np.float64]

CHANGE_SPREADS = 5.0
"""A pixel changed when the smoothed difference stands this many noise spreads out, 1."""

MIN_REGION_PX = 20
"""Smallest changed region counted, px (smaller ones are noise or dust)."""

SNAP_WINDOW_PX = 64
"""Half the side of the window where the needle's end is looked for, px: wider than the move."""

NEEDLE_SPREADS = 3.0
"""A pixel is needle when it stands this many spreads of the window edge's grey levels from their median, 1."""




class AcquireError(ValueError):
    """The tip could not be found from the motion (the message says why)."""


def _mean(frames: Sequence[FloatArray]) -> FloatArray:
    stack = np.stack([np.asarray(f, dtype=float) for f in frames])
    return np.asarray(stack.mean(axis=0), dtype=float)


def _noise(frames: Sequence[FloatArray]) -> float:
    """Pixel noise of a group: from the frames against each other when there are two, else a frame's own."""
    if len(frames) >= 2:
        d = np.asarray(frames[1], dtype=float) - np.asarray(frames[0], dtype=float)
        return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))
    return noise_sigma(np.asarray(frames[0], dtype=float))


def find_moving_tip(before: Sequence[FloatArray], now: Sequence[FloatArray]) -> tuple[float, float]:
    """The tip's pixel ``(x, y)`` in the ``now`` frames, the joint having moved since the ``before`` frames.

    Both groups hold at least one frame of one size (2-D grey arrays); more frames in a
    group average its noise away.
    """
    if not before or not now:
        raise AcquireError("need frames from both ends of the motion")
    shapes = {np.asarray(f).shape for f in (*before, *now)}
    if len(shapes) != 1:
        raise AcquireError(f"the frames differ in size: {sorted(shapes)}")
    a, b = _mean(before), _mean(now)
    noise = math.hypot(_noise(before) / math.sqrt(len(before)), _noise(now) / math.sqrt(len(now)))
    raw = b - a
    # an SEM's scan lines differ in level from frame to frame: each line's median over what did not change
    quiet = np.where(np.abs(raw) < 3.0 * noise, raw, np.nan)
    with np.errstate(all="ignore"):
        lines = np.nanmedian(np.where(np.isnan(quiet).all(axis=1, keepdims=True), 0.0, quiet), axis=1)
    raw = raw - lines[:, None]
    diff = ndimage.gaussian_filter(raw, 1.0)
    spread = noise / (2.0 * math.sqrt(math.pi))  # white noise smoothed by a Gaussian of 1 px
    largest = float(np.percentile(np.abs(diff), 99.95))
    threshold = max(CHANGE_SPREADS * spread, 0.2 * largest)
    changed = np.abs(diff) > threshold
    if not changed.any() or largest < CHANGE_SPREADS * spread:  # noqa: SIM114
        raise AcquireError(
            "nothing moved in the image (the joint did not move the tip, or moved it along the optical axis): "
            "step more, or another joint"
        )
    # the needle's axis: the long axis of what changed (a needle moved sideways sweeps along its length, one
    # moved along itself changes its tapered edges)
    labels, n = ndimage.label(changed)
    sizes = ndimage.sum(np.ones_like(labels), labels, index=np.arange(1, n + 1))
    keep = np.isin(labels, 1 + np.nonzero(np.asarray(sizes) >= MIN_REGION_PX)[0])
    if not keep.any():
        raise AcquireError("what changed is only specks (noise or dust): step more")
    ys, xs = np.nonzero(keep)
    pts = np.stack([xs, ys], axis=1).astype(float)
    centre = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - centre, full_matrices=False)
    axis = vt[0]
    along = (pts - centre) @ axis
    ends = [centre + axis * float(np.percentile(along, q)) for q in (0.5, 99.5)]
    H, W = b.shape

    def from_edge(p: FloatArray) -> float:
        return float(min(p[0], p[1], W - 1 - p[0], H - 1 - p[1]))

    # the needle enters at the field's edge: its tip is the end of what moved further from the edge
    end = max(ends, key=from_edge)
    outward = axis if float(np.dot(end - centre, axis)) > 0 else -axis
    return _snap(ndimage.gaussian_filter(b, 1.5), end, outward, noise)


def _snap(smooth: FloatArray, end: FloatArray, outward: FloatArray, noise: float) -> tuple[float, float]:
    """The needle's end near ``end`` (px): its furthest point along ``outward`` in a window around it."""
    H, W = smooth.shape
    h = SNAP_WINDOW_PX
    cx, cy = int(round(float(end[0]))), int(round(float(end[1])))
    y0, y1, x0, x1 = max(0, cy - h), min(H, cy + h + 1), max(0, cx - h), min(W, cx + h + 1)
    win = smooth[y0:y1, x0:x1]
    ring = np.ones(win.shape, dtype=bool)
    ring[3:-3, 3:-3] = False
    level = float(np.median(win[ring]))
    spread = max(float(1.4826 * np.median(np.abs(win[ring] - level))), 0.3 * noise, 1e-12)
    stand = np.abs(win - level) / spread > NEEDLE_SPREADS
    labels, n = ndimage.label(stand)
    if n == 0:
        raise AcquireError("nothing stands out where the needle's end should be: is the tip in focus?")
    yy, xx = np.mgrid[y0:y1, x0:x1]
    # the needle: the largest region that leaves the window (its shaft runs on out of it)
    edge_ids = set(np.unique(labels[ring]).tolist()) - {0}
    sizes = np.asarray(ndimage.sum(np.ones_like(labels), labels, index=np.arange(1, n + 1)))
    ok = np.array([i + 1 in edge_ids for i in range(n)]) & (sizes >= 4)
    if not ok.any():
        raise AcquireError("no needle where what moved ends")
    needle = labels == (1 + int(np.argmax(np.where(ok, sizes, -1.0))))
    reach = (xx - end[0]) * outward[0] + (yy - end[1]) * outward[1]
    far = float(reach[needle].max())
    tip = needle & (reach >= far - 0.5)
    return float(xx[tip].mean()), float(yy[tip].mean())
