"""The needle's width behind a candidate tip, station by station, against the first frame's.

A needle widens away from its tip (its taper), and does so the same way in every frame:
``s`` px behind its tip it is as wide as the first frame showed it ``s`` px behind the
tip. Behind a fix that is the tip, every station of the shaft (:mod:`.shaft`'s, as far as
the first frame showed the needle) has the first frame's width there. Behind the far end
of something dark stuck on the tip (a chip, a grain larger than the tip) taken for the
tip, they do not: where the thing lies the dark is wider than the needle, and behind it
the needle is narrower than the first frame's at that distance, its own tip being
further back. :mod:`.shaft`'s correlation hardly sees a few px of width on a profile 20
to 40 px wide, and its taper (a first-order model) under-reads a displacement of 15 to
25 px as 1 to 4 px; this check measures the width itself, without a first-order model.

At each station the frame's profile across the shaft (the mean of three lines 1 px
apart, sampled every 1 px, smoothed as the blur copy is) is registered to the first
frame's, each edge on its own: the outward shift of the edge (up to
:attr:`~.template.TrackerParams.width_shift`) at which the edge's half of the profile
(from the needle's middle to :data:`~.shaft.GROUND` px of ground beyond the edge)
correlates best, tried every :data:`SHIFT_STEP` px and then refined by a parabola. The
two shifts' sum is the width's change ``dw``. Its standard deviation comes from the
pixel noise and the first frame's edge gradients (a matched filter's); the taper, the
width's growth per px along the shaft, from registering the first frame's profiles
:data:`~.shaft.ALONG_STEP` px nearer the tip and further from it the same way.

A station *disagrees* when ``|dw|`` exceeds what a fix
:attr:`~.template.TrackerParams.along_limit` px off along the axis would show through the
taper, plus :attr:`~.template.TrackerParams.along_sigmas` standard deviations; the fix is
refused (*occluded*) when the stations' median of ``|dw|`` less that allowance is positive
(most stations disagree; :func:`~.track._edge_refusal`). A station whose width in the
first frame (the needle's run across the shaft) lies off the needle's straight taper (a
robust line through all the stations' widths) by more than
:attr:`~.template.TrackerParams.width_slack` is not used: something lay beside the needle
there, or the run found was not the needle's (an SEM needle's dark middle splits it).

The registration reaches :attr:`~.template.TrackerParams.width_shift` px an edge, and the
median wants most stations: past an occluder whose chord near the fit is as wide as the
needle's end (the blunt chord), an edge 10 or 20 px inside reads a clipped shift at one or
two stations. So each station also measures the needle's *extent* (:func:`runs`: the first
to the last sample standing out from the ground, without a shift limit) against the first
frame's, smoothed alike; :attr:`WidthCheck.short` is how much narrower it is, less what
``along_limit`` px along the axis change it. Past an occluder taken for the tip the needle
is its own, its end further back or to the side, so narrower; anything beside it only
widens it: one station over :attr:`~.template.TrackerParams.extent_slack` refuses the fix
(:func:`~.track._width_refusal`). Only stations where the first frame's needle stands
:attr:`~.template.TrackerParams.extent_depth` times the threshold from the ground are
compared (an SEM needle's edge contrast is not measured so).
See docs/vision.md, "Tracking the tip".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from .sampling import gaussian_weights, median
from .shaft import (
    ALONG_STEP,
    BACK_STEP,
    GROUND,
    LINES,
    REACH,
    STEP,
    follow_shaft,
    mean_lines,
    sample_frame,
    station_profiles,
)

__all__ = ["WidthStations", "WidthCheck", "OutlineStations", "SHIFT_STEP", "FROM", "learn_width", "check_width",
           "learn_outline", "check_outline"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

SHIFT_STEP = 0.5
"""Spacing of the edge shifts tried, px (the best is then refined by a parabola)."""

FROM = 6.0
"""The first station, px behind the tip; then every :data:`~.shaft.BACK_STEP` px as far as the first frame
showed the needle (as :mod:`.shaft`'s stations, which start further back)."""


@dataclass(frozen=True)
class _Shifted:
    """What :func:`_register` gathers: see :class:`WidthStations`."""

    count: FloatArray
    below: IntArray
    above: IntArray
    w_below: FloatArray
    w_above: FloatArray
    shifts: FloatArray


@dataclass(frozen=True)
class WidthStations:
    """The first frame's edges at the stations behind the tip (learnt once).

    Attributes
    ----------
    s : ndarray, shape (m,)
        The stations (px behind the tip).
    lines : ndarray, shape (2, m * q * len(LINES))
        Every sample of every line, its offset from the tip (x, y; px, before a turn).
    q : int
        Samples across the shaft at a station (every :data:`~.shaft.STEP` px).
    refs : list of ndarray, shape (m, 2, L)
        For each blur copy, each station's two edge windows of the first frame's profile
        (smoothed as the copy is), their mean taken out (0 past a window's end).
    ref_ss : list of ndarray, shape (m, 2)
        Their sums of squares.
    sd : list of ndarray, shape (m,)
        For each blur copy, the standard deviation of a station's width change, px.
    shifted : _Shifted
        For each station, edge and outward shift tried (``k`` of them, every
        :data:`SHIFT_STEP` px): the samples in each window (``count``, shape ``(m, 2, 1)``),
        the flat indices into a frame's ``(m, q)`` profiles (and a zero after them) of the
        samples either side of each shifted place (``below``, ``above``, shape
        ``(m, 2, k, L)``) and their shares in the linear interpolation (``w_below``,
        ``w_above``; 0 past a window's end), and the shifts (``shifts``, px).
    span : ndarray of bool, shape (m, q)
        The samples a station's registration may reach (they must lie in the frame).
    taper : ndarray, shape (m,)
        The width's growth per px along the shaft at each station, 1 (the first frame's).
    smooth : list of float
        For each blur copy, the smoothing of a frame's profiles across the shaft (Gaussian
        sigma, px).
    level, threshold : float
        The ground's grey level and how far from it a sample is the needle's (grey units; as
        :func:`.shaft.follow_shaft` tells the needle from the ground).
    reach : ndarray, shape (m,)
        How far from a station's middle its extent is looked for: half the needle's width
        there in the first frame and :data:`~.shaft.GROUND` px, px.
    runs : list of ndarray, shape (m,)
        For each blur copy, the needle's extent across the shaft at each station in the first
        frame smoothed as the copy is (:func:`runs`), px.
    ring, ground : ndarray of bool, shape (m, q), and float
        The samples beside the needle beyond ``reach`` (within ``span``), and the first
        frame's median there (grey units).
    """

    s: FloatArray
    lines: FloatArray
    q: int
    refs: list[FloatArray]
    ref_ss: list[FloatArray]
    sd: list[FloatArray]
    shifted: _Shifted
    span: NDArray[np.bool_]
    taper: FloatArray
    smooth: list[float]
    level: float = 0.0
    threshold: float = math.inf
    reach: FloatArray | None = None
    runs: tuple[FloatArray, ...] = ()
    ring: NDArray[np.bool_] | None = None
    ground: float = 0.0


@dataclass(frozen=True)
class WidthCheck:
    """The needle's width behind a candidate tip against the first frame's.

    Attributes
    ----------
    n : int
        Stations compared (those whose samples lie in the frame).
    disagree : int
        Stations whose width differs by more than a fix within the along-axis limit shows.
    s : tuple of float
        The stations compared, px behind the candidate tip.
    dw : tuple of float
        Each station's width change (px; positive: wider than in the first frame).
    tolerance : tuple of float
        What each station allows, px.
    short : tuple of float
        At each station, how much narrower the needle's extent across the shaft is than the
        first frame's there (:func:`runs`; px, positive: narrower), less what
        ``along_limit`` px along the axis change it through the taper.
    """

    n: int
    disagree: int
    s: tuple[float, ...]
    dw: tuple[float, ...]
    tolerance: tuple[float, ...]
    short: tuple[float, ...] = ()

    @property
    def excess(self) -> float:
        """The stations' median of ``|dw|`` less what each allows, px (positive: most disagree)."""
        return median(np.abs(np.asarray(self.dw)) - np.asarray(self.tolerance))  # numpy.median's, bit for bit

    @property
    def near_wide(self) -> float:
        """How much wider than they allow the two stations nearest the candidate tip both are, px (the smaller
        of their ``dw`` less the tolerance; negative: one of them is not; ``-inf`` with fewer than two)."""
        if len(self.dw) < 2:
            return -math.inf
        return min(self.dw[0] - self.tolerance[0], self.dw[1] - self.tolerance[1])

    @property
    def narrow(self) -> tuple[int, float]:
        """The station (its index) whose width is narrower than it allows by the most, and by how much, px
        (``-dw`` less the tolerance; negative: no station is)."""
        k = int(np.argmax(-np.asarray(self.dw) - np.asarray(self.tolerance)))
        return k, -self.dw[k] - self.tolerance[k]


def _windows(widths: Sequence[float], ts: FloatArray) -> list[tuple[IntArray, IntArray]]:
    """Each station's left and right edge windows: sample indices from the needle's middle out to
    :data:`~.shaft.GROUND` px beyond its edge (the left one from the outside in)."""
    out = []
    for w in widths:
        reach = 0.5 * w + GROUND + 1e-9
        left = np.flatnonzero((ts >= -reach) & (ts <= 0.0))
        right = np.flatnonzero((ts >= 0.0) & (ts <= reach))
        out.append((left, right))
    return out


def _shifted(windows: list[tuple[IntArray, IntArray]], q: int, shifts: FloatArray, length: int) -> _Shifted:
    """For every station, edge and shift: the samples either side of each shifted place (flat indices into
    ``(m, q)`` profiles, the place past a window's end the zero after them) and their interpolation shares."""
    m, k = len(windows), shifts.size
    below = np.full((m, 2, k, length), m * q, dtype=np.intp)
    w_below = np.zeros((m, 2, k, length))
    w_above = np.zeros((m, 2, k, length))
    count = np.zeros((m, 2, 1))
    for i, pair in enumerate(windows):
        for e, (idx, sign) in enumerate(zip(pair, (-1.0, 1.0), strict=True)):
            pos = idx[None, :] + sign * shifts[:, None] / STEP
            lo = np.clip(np.floor(pos), 0, q - 2)
            frac = np.clip(pos - lo, 0.0, 1.0)
            below[i, e, :, : idx.size] = i * q + lo.astype(np.intp)
            w_below[i, e, :, : idx.size] = 1.0 - frac
            w_above[i, e, :, : idx.size] = frac
            count[i, e, 0] = idx.size
    above = np.where(below < m * q, below + 1, m * q)
    return _Shifted(count, below, above, w_below, w_above, shifts)


def _register(refs: FloatArray, ref_ss: FloatArray, profiles: FloatArray, g: _Shifted) -> FloatArray:
    """Each station's two outward edge shifts (px, shape ``(m, 2)``) registering ``profiles`` (``(m, q)``)
    to the edge windows ``refs`` (their mean out, sums of squares ``ref_ss``)."""
    flat = np.append(profiles.reshape(-1), 0.0)
    f = flat.take(g.below) * g.w_below + flat.take(g.above) * g.w_above
    n = g.count
    shifts = g.shifts
    s1 = f.sum(axis=3)
    ff = (f * f).sum(axis=3) - s1 * s1 / n
    cov = np.einsum("iekl,iel->iek", f, refs)
    r = cov / np.sqrt(np.maximum(ff * ref_ss[:, :, None], 1e-300))
    j = np.clip(r.argmax(axis=2), 1, shifts.size - 2)
    a = np.take_along_axis(r, (j - 1)[..., None], axis=2)[..., 0]
    b = np.take_along_axis(r, j[..., None], axis=2)[..., 0]
    c = np.take_along_axis(r, (j + 1)[..., None], axis=2)[..., 0]
    den = a - 2.0 * b + c
    off = np.where(den < 0.0, 0.5 * (a - c) / np.where(den < 0.0, den, -1.0), 0.0)
    step = float(shifts[1] - shifts[0])
    return np.asarray(shifts[j] + np.clip(off, -0.5, 0.5) * step)


def _gather(windows: list[tuple[IntArray, IntArray]], q: int, length: int) -> tuple[IntArray, FloatArray]:
    """The edge windows as flat indices into ``(m, q)`` profiles (shape ``(m, 2, length)``, 0 past a window's
    end) and which places hold a sample."""
    m = len(windows)
    index = np.zeros((m, 2, length), dtype=np.intp)
    mask = np.zeros((m, 2, length))
    for i, pair in enumerate(windows):
        for e, idx in enumerate(pair):
            index[i, e, : idx.size] = i * q + idx
            mask[i, e, : idx.size] = 1.0
    return index, mask


def _edges(profiles: FloatArray, index: IntArray, mask: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The edge windows (:func:`_gather`) of ``profiles`` (``(m, q)``), their mean taken out, and their sums of
    squares."""
    v = profiles.reshape(-1).take(index) * mask
    out = (v - (v.sum(axis=2) / mask.sum(axis=2))[..., None]) * mask
    return out, (out * out).sum(axis=2)


def runs(profiles: FloatArray, level: float, threshold: float, reach: FloatArray,
         inside: NDArray[np.bool_] | None = None) -> FloatArray:
    """The needle's extent across the shaft at each station, px (shape ``(m,)``): from the first to the last
    sample that is the needle's within ``reach`` (px, one a station) of the station's middle, 0 where none is.

    A sample is the needle's where it lies more than ``threshold`` from the ground's ``level`` (and,
    with ``inside``, in the frame), as :func:`.shaft.follow_shaft` tells the needle from the ground;
    the extent, not the run through the middle, so that an SEM needle's middle near the ground's
    level does not split it. Anything beside the needle only widens it.
    """
    m, q = profiles.shape
    ts = (np.arange(q) - (q - 1) // 2) * STEP
    on = (np.abs(profiles - level) > threshold) & (np.abs(ts)[None, :] <= reach[:, None])
    if inside is not None:
        on &= inside
    any_on = on.any(axis=1)
    first = np.argmax(on, axis=1)
    last = q - 1 - np.argmax(on[:, ::-1], axis=1)
    return np.asarray(np.where(any_on, (last - first + 1) * STEP, 0.0), dtype=float)


def _solid(profiles: FloatArray, level: float, threshold: float, reach: FloatArray, extents: FloatArray,
           depth: float) -> FloatArray:
    """``extents`` (the first frame's, :func:`runs`), 0 at the stations where the needle does not stand
    ``depth`` times ``threshold`` from the ground's ``level`` (the median over the extent's middle): there
    the threshold crosses the needle's edges near their foot or its middle, and the extent is not a
    measure of the needle (an SEM needle's edge contrast)."""
    m, q = profiles.shape
    ts = (np.arange(q) - (q - 1) // 2) * STEP
    out = extents.copy()
    for i in range(m):
        inner = np.abs(ts) <= min(0.5 * extents[i], reach[i])
        if not inner.any() or median(np.abs(profiles[i, inner] - level)) < depth * threshold:
            out[i] = 0.0
    return out


def _on_the_taper(s: FloatArray, widths: FloatArray, slack: float) -> list[int]:
    """The stations whose width (px, at ``s`` px behind the tip) lies within ``slack`` px of the needle's
    straight taper, a robust line through them all (Siegel's repeated median: each station's median slope to
    the others, their median, then the median intercept; up to half the stations may be off it)."""
    if s.size < 3:
        return []
    ds = s[None, :] - s[:, None]
    np.fill_diagonal(ds, np.nan)
    slope = float(np.median(np.nanmedian((widths[None, :] - widths[:, None]) / ds, axis=1)))
    base = float(np.median(widths - slope * s))
    return [int(k) for k in np.flatnonzero(np.abs(widths - base - slope * s) <= slack)]


def learn_width(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float], level: float,
                spread: float, contrast: float, noise: float, smooth: list[tuple[float, float]],
                max_shift: float, slack: float, depth: float = math.inf) -> WidthStations | None:
    """The first frame's edges at the shaft's stations behind ``tip`` (``None``: fewer than three).

    ``image`` is the first frame, ``tip`` the tip in it (x, y; px), ``shaft`` the unit vector
    from the tip back along the needle; ``level``, ``spread`` and ``contrast`` find the needle
    as :func:`.shaft.learn_shaft` does; ``noise`` is the pixel noise (grey units); ``smooth``
    gives, for each blur copy, the smoothing of the first frame's profiles and of a later
    frame's (Gaussian sigma, px); ``max_shift`` the largest edge shift tried and ``slack`` how
    much wider than a station further back one may be (px); ``depth``: how many times
    ``contrast * spread`` the needle must stand from the ground at a station for its extent
    across the shaft to be compared (:func:`runs`; ``inf``: never).
    """
    half_q = int(round(REACH / STEP))
    ts: FloatArray = (np.arange(2 * half_q + 1, dtype=np.float64) - half_q) * STEP
    offs, raws, widths, kept = follow_shaft(image, tip, shaft, level, spread, contrast, ts, FROM)
    use = _on_the_taper(np.asarray(kept), np.asarray(widths), slack)
    if len(use) < 3:
        return None
    ux, uy = shaft
    offs = [offs[i] for i in use]
    raw = np.stack([raws[i] for i in use])
    widths = [widths[i] for i in use]
    q = ts.size
    shifts = np.arange(-max_shift, max_shift + 1e-9, SHIFT_STEP)
    windows = _windows(widths, ts)
    length = max(max(a.size, b.size) for a, b in windows)
    shifted = _shifted(windows, q, shifts, length)
    reach = np.array([0.5 * w + GROUND + max_shift + 1.0 for w in widths])
    span = np.abs(ts)[None, :] <= reach[:, None]
    # the taper: the first frame's profiles ALONG_STEP px nearer the tip registered to those as far beyond
    o = np.stack(offs)
    near, far = (station_profiles(image, tip[0], tip[1], o[..., 0] + d * ux, o[..., 1] + d * uy, ux, uy)[0]
                 for d in (-ALONG_STEP, ALONG_STEP))
    s0 = smooth[0][0]
    index, wmask = _gather(windows, q, length)
    near_e, near_ss = _edges(ndimage.gaussian_filter1d(near, s0 / STEP, axis=1, mode="nearest"), index, wmask)
    far_s = ndimage.gaussian_filter1d(far, s0 / STEP, axis=1, mode="nearest")
    taper = _register(near_e, near_ss, far_s, shifted).sum(axis=1) / (2.0 * ALONG_STEP)
    reach0 = np.array([0.5 * w + GROUND for w in widths])
    refs, ref_ss, sds, run0 = [], [], [], []
    n2 = noise * noise / len(LINES)  # a sample of the mean of the lines
    made: dict[float, tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = {}
    for tsig, _ in smooth:
        if tsig not in made:
            e = ndimage.gaussian_filter1d(raw, tsig / STEP, axis=1, mode="nearest")
            g = np.gradient(e, STEP, axis=1).reshape(-1).take(index) * wmask
            # a matched filter's variance for each edge, the frame's noise and the first frame's alike
            made[tsig] = (*_edges(e, index, wmask), np.sqrt((2.0 * n2 / np.maximum((g * g).sum(axis=2), 1e-300))
                                                           .sum(axis=1)),
                         _solid(e, level, contrast * spread, reach0, runs(e, level, contrast * spread, reach0), depth))
        r, ss, sd, w0 = made[tsig]
        refs.append(r)
        ref_ss.append(ss)
        sds.append(sd)
        run0.append(w0)
    offsets = o
    d_lines = np.asarray(LINES)
    lines = np.stack([(offsets[..., 0][..., None] + d_lines * ux).ravel(),
                      (offsets[..., 1][..., None] + d_lines * uy).ravel()])
    ring = span & (np.abs(ts)[None, :] > reach0[:, None])
    return WidthStations(np.array([kept[i] for i in use]), lines, q, refs, ref_ss, sds, shifted, span,
                         np.asarray(taper, dtype=float), [f for _, f in smooth], level, contrast * spread, reach0,
                         tuple(run0), ring, median(raw[ring]) if ring.any() else level)


def check_width(ws: WidthStations, copy: int, image: FloatArray, x: float, y: float, theta: float,
                along_limit: float, sigmas: float, least: int = 3) -> WidthCheck | None:
    """The needle's width at the stations behind a tip at ``(x, y)`` (frame px) turned by ``theta`` (rad),
    against blur copy ``copy``; ``None`` when fewer than ``least`` (at least one) stations lie in the frame.

    A station disagrees when its width change exceeds ``along_limit`` px of the taper plus
    ``sigmas`` standard deviations. For the extent (:func:`runs`) the frame's grey levels are
    moved by the change of the ground beside the needle (the median over :attr:`WidthStations.ring`
    against the first frame's): a lamp a few per cent brighter would otherwise put the whole
    ground beyond the threshold.
    """
    m = ws.s.size
    ct, st_ = math.cos(theta), math.sin(theta)
    lx, ly = ws.lines
    v, inside = sample_frame(image, ct * lx - st_ * ly + x, st_ * lx + ct * ly + y)
    n = len(LINES)
    shape = (m, ws.q, n)
    profiles = mean_lines(v.reshape(shape))
    seen = np.asarray(inside.reshape(shape).all(axis=2), dtype=bool)  # each sample's three lines in the frame
    ok = (seen | ~ws.span).all(axis=1)
    if int(ok.sum()) < max(least, 1):
        return None
    f = ws.smooth[copy]
    if f > 0:
        # scipy.ndimage.gaussian_filter1d's correlation, its kernel made once for each smoothing
        profiles = ndimage.correlate1d(profiles, gaussian_weights(f / STEP), 1, mode="nearest")
    dw = _register(ws.refs[copy], ws.ref_ss[copy], profiles, ws.shifted).sum(axis=1)
    tol = along_limit * np.abs(ws.taper) + sigmas * ws.sd[copy]
    short = np.full(m, -math.inf)
    if ws.runs and ws.reach is not None:
        # the frame's ground against the first frame's, beside the needle at every station: a lamp a few per
        # cent brighter would otherwise put the whole ground beyond the threshold
        beside = None if ws.ring is None else ws.ring & seen
        shift = median(profiles[beside]) - ws.ground if beside is not None and beside.any() else 0.0
        extent = runs(np.asarray(profiles - shift, dtype=float), ws.level, ws.threshold, ws.reach, seen)
        short = np.asarray(ws.runs[copy] - extent - along_limit * np.abs(ws.taper), dtype=float)
    dw, tol, short = dw[ok], tol[ok], short[ok]
    # (tolist: the same Python floats as float() of each, in one call)
    return WidthCheck(int(ok.sum()), int(np.count_nonzero(np.abs(dw) > tol)), tuple(ws.s[ok].tolist()),
                      tuple(dw.tolist()), tuple(tol.tolist()), tuple(short.tolist()))


OUTLINE_FROM = 4.0
"""The outline's first station, px behind the tip (nearer, the blunt end's edges are too curved to register)."""

OUTLINE_STEP = 2.0
"""The outline's stations' spacing along the shaft, px."""

OUTLINE_TO = 40.0
"""The outline's last station, px behind the tip."""


@dataclass(frozen=True)
class OutlineStations:
    """The first frame's two edges at dense stations behind the tip, each registered on its own
    (:func:`learn_outline`): what vouches for a fit behind which the needle leaves the field.

    Attributes
    ----------
    s : ndarray, shape (m,)
        The stations, px behind the tip.
    lines : ndarray, shape (2, m * q * len(LINES))
        Every sample of every line, its offset from the tip (x, y; px, before a turn).
    q : int
        Samples across the shaft at a station.
    refs, ref_ss : list of ndarray
        For each blur copy, each station's two edge windows (:class:`WidthStations`'s).
    shifted : _Shifted
        The shifted windows' samples (:class:`WidthStations`'s).
    sides : ndarray of bool, shape (2, m, q)
        The samples each edge's registration reaches (left, right): they must lie in the frame.
    smooth : list of float
        For each blur copy, the smoothing of a frame's profiles across the shaft, px.
    """

    s: FloatArray
    lines: FloatArray
    q: int
    refs: list[FloatArray]
    ref_ss: list[FloatArray]
    shifted: _Shifted
    sides: NDArray[np.bool_]
    smooth: list[float]


def learn_outline(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float], level: float,
                  spread: float, contrast: float, smooth: list[tuple[float, float]], max_shift: float
                  ) -> OutlineStations | None:
    """The first frame's edges every :data:`OUTLINE_STEP` px from :data:`OUTLINE_FROM` to :data:`OUTLINE_TO` px
    behind ``tip`` as far as it shows the needle (:func:`.shaft.follow_shaft`'s walk, begun at each offset);
    ``None``: fewer than three stations. The arguments are :func:`learn_width`'s."""
    half_q = int(round(REACH / STEP))
    ts: FloatArray = (np.arange(2 * half_q + 1, dtype=np.float64) - half_q) * STEP
    found: dict[float, tuple[FloatArray, FloatArray, float]] = {}
    for start in np.arange(OUTLINE_FROM, OUTLINE_FROM + BACK_STEP - 1e-9, OUTLINE_STEP):
        offs, raws, widths, kept = follow_shaft(image, tip, shaft, level, spread, contrast, ts, float(start))
        for o, r, w, s in zip(offs, raws, widths, kept, strict=True):
            if s <= OUTLINE_TO + 1e-9:
                found[float(s)] = (o, r, w)
    if len(found) < 3:
        return None
    s_all = np.array(sorted(found))
    offs_l = [found[float(s)][0] for s in s_all]
    raw = np.stack([found[float(s)][1] for s in s_all])
    run = [found[float(s)][2] for s in s_all]
    q = ts.size
    windows = _windows(run, ts)
    length = max(max(a.size, b.size) for a, b in windows)
    shifted = _shifted(windows, q, np.arange(-max_shift, max_shift + 1e-9, SHIFT_STEP), length)
    index, wmask = _gather(windows, q, length)
    refs, ref_ss = [], []
    for tsig, _ in smooth:
        r, ss = _edges(ndimage.gaussian_filter1d(raw, tsig / STEP, axis=1, mode="nearest"), index, wmask)
        refs.append(r)
        ref_ss.append(ss)
    reach = np.array([0.5 * w + GROUND + max_shift + 1.0 for w in run])
    sides = np.stack([(ts[None, :] <= 0.0) & (-ts[None, :] <= reach[:, None]),
                      (ts[None, :] >= 0.0) & (ts[None, :] <= reach[:, None])])
    ux, uy = shaft
    o = np.stack(offs_l)
    d_lines = np.asarray(LINES)
    lines = np.stack([(o[..., 0][..., None] + d_lines * ux).ravel(), (o[..., 1][..., None] + d_lines * uy).ravel()])
    return OutlineStations(s_all, lines, q, refs, ref_ss, shifted, sides, [f for _, f in smooth])


def check_outline(os_: OutlineStations, copy: int, image: FloatArray, x: float, y: float, theta: float
                  ) -> tuple[float, float, float]:
    """One edge at a time, the needle's outline behind a tip at ``(x, y)`` (frame px) turned by ``theta`` (rad)
    against blur copy ``copy``'s: each edge's outward shift at every station whose registration lies in the frame
    (:func:`_register`). Returns the furthest station read on either edge (px behind the tip; 0: none), the
    largest inward move of an edge going back (an edge's shift at a station less the least shift at the stations
    behind it, px), and the largest of the edges' median shifts in size (px).

    A sideways offset of the fit moves an edge the same at every station, so neither the inward move nor (within
    the fit's sideways error) the median shift reads it; behind a fit that is the tip an edge lies where the first
    frame had it. Behind the far rim of a bead over the tip taken for it the outline closes: the needle there is
    narrower than the first frame showed it as far behind its tip, its own tip being further back."""
    m = os_.s.size
    ct, st_ = math.cos(theta), math.sin(theta)
    lx, ly = os_.lines
    v, inside = sample_frame(image, ct * lx - st_ * ly + x, st_ * lx + ct * ly + y)
    shape = (m, os_.q, len(LINES))
    profiles = mean_lines(v.reshape(shape))
    seen = np.asarray(inside.reshape(shape).all(axis=2), dtype=bool)
    # (2, m): each edge's registration in the frame
    valid = np.asarray((seen[None, :, :] | ~os_.sides).all(axis=2), dtype=bool)
    if not valid.any():
        return 0.0, 0.0, 0.0
    f = os_.smooth[copy]
    if f > 0:
        profiles = ndimage.correlate1d(profiles, gaussian_weights(f / STEP), 1, mode="nearest")
    shifts = _register(os_.refs[copy], os_.ref_ss[copy], profiles, os_.shifted)  # (m, 2)
    closing, offset = 0.0, 0.0
    for e in range(2):
        d = shifts[valid[e], e]
        if d.size:
            behind = np.minimum.accumulate(d[::-1])[::-1]  # the least shift at each station and behind it
            closing = max(closing, float(np.max(d[:-1] - behind[1:])) if d.size > 1 else 0.0)
            offset = max(offset, abs(median(d)))
    return float(os_.s[valid.any(axis=0)].max()), closing, offset
