"""Which parts of the template moved with the tip: the needle's mask confirmed by the first move.

The template's mask keeps every region standing out from the ground that comes within 8 px of
the tip (:mod:`.template`): one frame cannot tell a dust grain beside the tip from a piece of
the needle that broke off at the threshold (an SEM needle's edges), by size or by gap. The
motion can: the needle moves, the ground stays (it drifts slowly, as a whole). Once the tracker
has a fix after the tip has moved by :attr:`~.template.TrackerParams.confirm_move` px or more,
each region of the mask (grown by :attr:`~.template.TrackerParams.edge_px`, so its edges count)
is compared with that frame twice: where the first frame had it (the ground's place) and where
the fix puts it (moved and turned with the tip). A region that correlates at its old place
better than at the new one by :attr:`~.template.TrackerParams.confirm_margin` is ground, and is
dropped from the mask; the others stay. Where every region reads as ground the fix, not the
mask, is in doubt: the mask is kept as it was, and :attr:`Confirmation.emptied` says so.

Before the first such move nothing is confirmed and the template is the first frame's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from .sampling import patch, sample_value

__all__ = ["RegionReading", "Confirmation", "confirm_mask"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RegionReading:
    """One region of the mask read in the moved frame.

    Attributes
    ----------
    size : int
        Its pixels in the mask (not grown), 1.
    distance : float
        Its nearest pixel's distance from the tip, px.
    at_old, at_new : float
        Its weighted correlation with the frame where the first frame had it, and where the fix
        puts it (moved and turned with the tip), 1.
    ground : bool
        Whether it stayed with the ground (``at_old`` beyond ``at_new`` by the margin).
    """

    size: int
    distance: float
    at_old: float
    at_new: float
    ground: bool


@dataclass(frozen=True)
class Confirmation:
    """What the first move said of the template's mask.

    Attributes
    ----------
    mask : ndarray of bool
        The mask confirmed: the regions that moved with the tip (the old mask when none did).
    regions : tuple of RegionReading
        Each region's reading.
    move : float
        How far the tip had moved from the first frame's, px.
    emptied : bool
        Every region read as ground: the mask was kept as it was (the fix is in doubt, not the mask).
    """

    mask: NDArray[np.bool_]
    regions: tuple[RegionReading, ...]
    move: float
    emptied: bool

    @property
    def dropped(self) -> int:
        """Regions dropped from the mask, 1 (0 when it was kept)."""
        return 0 if self.emptied else sum(r.ground for r in self.regions)


def _ncc(a: FloatArray, b: FloatArray) -> float:
    """The correlation of two equal-length samples (0 where either is flat or has fewer than two values), 1."""
    if a.size < 2:
        return 0.0
    da, db = a - a.mean(), b - b.mean()
    den = math.sqrt(float((da * da).sum()) * float((db * db).sum()))
    return float((da * db).sum()) / den if den > 1e-300 else 0.0


def confirm_mask(
    window: FloatArray, mask: NDArray[np.bool_], inside: NDArray[np.bool_], apex: tuple[float, float],
    first_tip: tuple[float, float], image: FloatArray, fix: tuple[float, float, float], smooth: float,
    grow: int, margin: float,
) -> Confirmation:
    """The regions of ``mask`` that moved with the tip from ``first_tip`` to ``fix``.

    Parameters
    ----------
    window : ndarray
        The template's window (the first frame's, smoothed by ``smooth``), grey units.
    mask : ndarray of bool
        The needle's mask in the window.
    inside : ndarray of bool
        Which of the window's pixels lay in the first frame.
    apex : tuple of float
        The tip in window coordinates, px.
    first_tip : tuple of float
        The tip in the first frame, px ``(x, y)``.
    image : ndarray
        The frame of the fix.
    fix : tuple of float
        The fix: ``(x, y)`` px and the needle's turn since the first frame, rad.
    smooth : float
        Gaussian smoothing of the frame before sampling, px (the template's).
    grow : int
        Each region is grown by this many pixels before it is compared, px (its edges count).
    margin : float
        How much better a region must correlate at its old place than at the new one to be ground, 1.
    """
    labels, n = ndimage.label(mask)
    h = (window.shape[0] - 1) // 2
    yy, xx = np.mgrid[0 : 2 * h + 1, 0 : 2 * h + 1]
    ox, oy = xx - apex[0], yy - apex[1]
    x, y, theta = fix
    move = math.hypot(x - first_tip[0], y - first_tip[1])
    cx, cy = 0.5 * (x + first_tip[0]), 0.5 * (y + first_tip[1])
    pt = patch(image, cx, cy, h * math.sqrt(2.0) + 0.5 * move + 4.0, smooth)
    ct, st = math.cos(theta), math.sin(theta)
    dist = np.hypot(ox, oy)
    readings = []
    for k in range(1, n + 1):
        own = labels == k
        sel = np.asarray(ndimage.binary_dilation(own, iterations=grow) if grow > 0 else own) & inside
        px, py = ox[sel].astype(float), oy[sel].astype(float)
        old, _ = sample_value(pt, first_tip[0] + px, first_tip[1] + py)
        new, _ = sample_value(pt, x + ct * px - st * py, y + st * px + ct * py)
        t = window[sel]
        at_old, at_new = _ncc(t, old), _ncc(t, new)
        readings.append(RegionReading(int(own.sum()), float(dist[own].min()), at_old, at_new,
                                      at_old > at_new + margin))
    kept = np.isin(labels, [k + 1 for k, r in enumerate(readings) if not r.ground])
    emptied = not kept.any()
    return Confirmation(mask if emptied else np.asarray(kept), tuple(readings), move, emptied)
