"""Sampling a frame for the tracker's stages: patches with their gradients, bilinear samples, a fast median.

A :class:`Patch` is a crop of a frame, smoothed as the template was, with its x and y
derivatives; :func:`sample` and :func:`sample_value` read it at sub-pixel points by bilinear
interpolation (the four neighbours in one gather). :func:`cells`, :func:`neighbours` and
:func:`bilinear` are the pieces, shared with the whole frame's sampling (:mod:`.shaft`).
:func:`median` is :func:`numpy.median`'s value for a 1-D array without its overhead. Pixel
convention: x to the right, y down, the centre of the top-left pixel at (0, 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

__all__ = ["Patch", "patch", "with_slopes", "sample", "sample_value", "sample_xy", "sample_value_xy", "cells",
           "flat_cells", "neighbours", "bilinear", "median", "gaussian_weights"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Patch:
    """A crop of a frame with its gradients, for sampling at every iteration.

    Attributes
    ----------
    data : ndarray, shape (3, h, w)
        The (smoothed) crop and its x and y derivatives (grey units per px).
    x0, y0 : int
        The crop's top-left pixel in the frame.
    shape : tuple of int
        The frame's ``(height, width)``.
    slopes : bool
        Whether ``data[1:]`` hold the derivatives (made without them, NaN: :func:`with_slopes`
        makes them).
    """

    data: FloatArray
    x0: int
    y0: int
    shape: tuple[int, int]
    slopes: bool = True


def patch(image: FloatArray, cx: float, cy: float, radius: float, smooth: float = 0.0, slopes: bool = True
          ) -> Patch:
    """The patch of ``image`` holding every pixel within ``radius`` (px) of ``(cx, cy)``.

    ``smooth`` (px) blurs the crop first (Gaussian sigma), as the template was: what a
    camera under-samples (aliasing) then weighs little in the fit, and bilinear
    interpolation of the smoothed crop is exact to a hundredth of a pixel. ``slopes``:
    with its derivatives (else NaN until :func:`with_slopes` makes them; what reads only
    the values needs none).
    """
    H, W = image.shape
    x0 = max(0, int(math.floor(cx - radius)) - 3)
    y0 = max(0, int(math.floor(cy - radius)) - 3)
    x1 = min(W, int(math.ceil(cx + radius)) + 4)
    y1 = min(H, int(math.ceil(cy + radius)) + 4)
    if x1 - x0 < 4 or y1 - y0 < 4:
        return Patch(np.zeros((3, 4, 4)), x0, y0, (H, W))
    data = np.empty((3, y1 - y0, x1 - x0))
    crop = data[0]
    if smooth > 1e-15:  # scipy.ndimage.gaussian_filter's two passes, its kernel made once for each smoothing
        w = gaussian_weights(smooth)
        ndimage.correlate1d(image[y0:y1, x0:x1], w, 0, crop, "nearest")
        ndimage.correlate1d(crop, w, 1, crop, "nearest")
    else:
        crop[...] = image[y0:y1, x0:x1]
    if slopes:
        _gradient(crop, data[1], data[2])
    else:
        data[1:] = np.nan
    return Patch(data, x0, y0, (H, W), slopes)


def with_slopes(p: Patch) -> Patch:
    """``p`` with its derivatives: made now, in place in its data, when it was made without them (the values the
    patch would have had with them, bit for bit)."""
    if p.slopes:
        return p
    _gradient(p.data[0], p.data[1], p.data[2])
    return replace(p, slopes=True)


_CACHED = 256
"""At most this many kernels (or patch sizes' limits) are kept; then the cache starts again."""

_WEIGHTS: dict[float, FloatArray] = {}


def gaussian_weights(sigma: float) -> FloatArray:
    """The weights :func:`scipy.ndimage.gaussian_filter1d` correlates with for a Gaussian of ``sigma`` px (its
    default reach, 4 sigma), made once for each ``sigma``: read off its response to a single 1."""
    w = _WEIGHTS.get(sigma)
    if w is None:
        lw = int(4.0 * float(sigma) + 0.5)
        delta = np.zeros(2 * lw + 1)
        delta[lw] = 1.0
        w = ndimage.gaussian_filter1d(delta, sigma, mode="constant")[::-1].copy()
        w.flags.writeable = False
        if len(_WEIGHTS) >= _CACHED:
            _WEIGHTS.clear()
        _WEIGHTS[sigma] = w
    return w


def _gradient(a: FloatArray, gx: FloatArray, gy: FloatArray) -> None:
    """``a``'s derivatives along x and y into ``gx``, ``gy`` (px⁻¹), as :func:`numpy.gradient` makes them:
    central differences inside, one-sided at the edges (``a`` at least 2 x 2)."""
    np.subtract(a[:, 2:], a[:, :-2], out=gx[:, 1:-1])
    gx[:, 1:-1] /= 2.0
    np.subtract(a[:, 1], a[:, 0], out=gx[:, 0])
    np.subtract(a[:, -1], a[:, -2], out=gx[:, -1])
    np.subtract(a[2:], a[:-2], out=gy[1:-1])
    gy[1:-1] /= 2.0
    np.subtract(a[1], a[0], out=gy[0])
    np.subtract(a[-1], a[-2], out=gy[-1])


def _corners(p: Patch, xy: FloatArray) -> tuple[NDArray[np.intp], FloatArray, FloatArray, NDArray[np.bool_]]:
    """The flat index of the pixel up and left of each frame point ``xy`` (shape (2, m), x then y, px; overwritten)
    in the patch, the point's fractions to the right and down from it, and which points lie in the frame and the
    patch (the others sample the patch's edge).

    x and y are handled together, a row each: each value is what the two coordinates
    handled apart would give, bit for bit, in half the operations.
    """
    H, W = p.shape
    _, ch, cw = p.data.shape
    in_frame = None
    if p.x0 < 0 or p.y0 < 0 or p.x0 + cw > W or p.y0 + ch > H:  # a patch not within the frame (an empty one)
        in_frame = ((xy >= 0) & (xy <= np.array(((W - 1.0,), (H - 1.0,))))).all(axis=0)
    # (a patch within the frame: a point in the patch is in the frame; lx >= 0 is exact, xs - x0 being a multiple
    # of the ulp of xs >= x0 >= 0 no larger than xs)
    xy[0] -= p.x0
    xy[1] -= p.y0
    i00, fx, fy, inside = cells(xy, ch, cw)
    if in_frame is not None:
        inside &= in_frame
    return i00, fx, fy, inside


def cells(xy: FloatArray, ch: int, cw: int) -> tuple[NDArray[np.intp], FloatArray, FloatArray, NDArray[np.bool_]]:
    """For points ``xy`` (shape (2, m), x then y, px; overwritten) in an array of ``ch`` x ``cw`` px: the flat
    index of the pixel up and left of each, its fractions to the right and down, and which lie within the array
    (the others are clipped to its edge). Shared by the patch's sampling and the whole frame's (:mod:`.shaft`)."""
    if xy.size and float(xy.min()) > 0.0 and float(xy.max()) < min(cw, ch) - 1.000001:
        # every point strictly inside (no NaN; no point: the plain way): the clipping below leaves each value
        # as it is, and each is inside
        inside = np.ones(xy.shape[1], dtype=bool)
    else:
        last, clip = _limits(ch, cw)[:2]
        ok = xy >= 0
        ok &= xy <= last
        inside = ok[0] & ok[1]
        np.minimum(np.maximum(xy, 0.0, out=xy), clip, out=xy)  # numpy.clip's values, in place
    return (*flat_cells(xy, cw), inside)


def flat_cells(xy: FloatArray, cw: int) -> tuple[NDArray[np.intp], FloatArray, FloatArray]:
    """For points ``xy`` (shape (2, m), x then y, px; overwritten by their fractions) within an array ``cw`` px
    wide, none negative: the flat index of the pixel up and left of each and its fractions to the right and down."""
    ixy = xy.astype(np.intp)
    xy -= ixy  # the fractions
    i00 = ixy[1]
    i00 *= cw
    i00 += ixy[0]
    return i00, xy[0], xy[1]


_LIMITS: dict[tuple[int, int], tuple[FloatArray, FloatArray, NDArray[np.intp], NDArray[np.intp]]] = {}


def _limits(ch: int, cw: int) -> tuple[FloatArray, FloatArray, NDArray[np.intp], NDArray[np.intp]]:
    """For a patch of ``ch`` x ``cw`` px (made once for each size): its last column and row, the largest
    coordinates sampled (just inside them), each as a column (x, y), the flat offsets of a pixel's four
    neighbours (:func:`neighbours`), and the same offsets in each of a :class:`Patch`'s three planes (shape
    (4, 3, 1): a neighbour, then a plane)."""
    lim = _LIMITS.get((ch, cw))
    if lim is None:
        four = np.array(((0,), (cw,), (1,), (cw + 1,)), dtype=np.intp)
        lim = (np.array(((cw - 1.0,), (ch - 1.0,))), np.array(((cw - 1.000001,), (ch - 1.000001,))), four,
               four[:, None, :] + ch * cw * np.arange(3, dtype=np.intp)[None, :, None])
        for a in lim:
            a.flags.writeable = False
        if len(_LIMITS) >= _CACHED:
            _LIMITS.clear()
        _LIMITS[(ch, cw)] = lim
    return lim


def neighbours(i00: NDArray[np.intp], ch: int, cw: int) -> NDArray[np.intp]:
    """The flat indices of the four pixels around each point (up left, down left, up right, down right), one
    row of points after the other (shape (4, m)), in a patch of ``ch`` x ``cw`` px: the left pair and the
    right pair each contiguous (:func:`bilinear`)."""
    return np.add(_limits(ch, cw)[2], i00)


def bilinear(v: FloatArray, fx: FloatArray, fy: FloatArray) -> FloatArray:
    """The bilinear interpolation of the four neighbours ``v`` (shape (4, ..., m), as :func:`neighbours` orders
    them) at the fractions ``fx``, ``fy``: the top and bottom rows along x together, then along y.

    Every operand is a contiguous block (the left pair, the right pair, the top and bottom
    rows): numpy's quick loops, the same arithmetic in the same order.
    """
    left = v[0:2]  # (up left, down left); v[2:4] the right ones
    tb = v[2:4] - left
    tb *= fx
    tb += left
    top = tb[0]
    out: FloatArray = tb[1] - top
    out *= fy
    out += top
    return out


def sample_xy(p: Patch, xy: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`sample` at the points ``xy`` (shape (2, m), px; overwritten)."""
    i00, fx, fy, inside = _corners(p, xy)
    # the four neighbours in the three planes in one gather, shape (4, 3, m)
    v = p.data.reshape(-1).take(np.add(_limits(*p.data.shape[1:])[3], i00))
    return bilinear(v, fx, fy), inside


def sample_value_xy(p: Patch, xy: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`sample_value` at the points ``xy`` (shape (2, m), px; overwritten)."""
    i00, fx, fy, inside = _corners(p, xy)
    v = p.data[0].reshape(-1).take(neighbours(i00, *p.data.shape[1:]))
    return bilinear(v, fx, fy), inside


def sample(p: Patch, xs: FloatArray, ys: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Bilinear samples of the patch (value, d/dx, d/dy: shape (3, m)) at frame points ``(xs, ys)`` (px).

    Also which points lie in the frame and the patch (the others sample the patch's edge).
    """
    return sample_xy(p, np.stack((xs, ys)).astype(float, copy=False))


def sample_value(p: Patch, xs: FloatArray, ys: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The values of :func:`sample` only (shape (m,)): the same bilinear interpolation, not the gradients'."""
    return sample_value_xy(p, np.stack((xs, ys)).astype(float, copy=False))


def median(a: FloatArray) -> float:
    """:func:`numpy.median` of a 1-D array, bit for bit (NaN if it holds one, NaN for none), without its
    overhead: one partition and the middle value, or the mean of the middle two."""
    n = a.size
    if n == 0:
        return math.nan
    k = n // 2
    b = np.partition(a, (k, n - 1) if n % 2 else (k - 1, k, n - 1))
    if math.isnan(b[n - 1]):
        return math.nan
    return float(b[k]) if n % 2 else (float(b[k - 1]) + float(b[k])) / 2.0
