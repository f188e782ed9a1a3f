"""The needle's two edges followed back from a candidate tip: a check the template fit cannot give.

The template fit (:mod:`.refine`) weighs every window pixel together and sets aside
what disagrees (Tukey's weights), and its brightness planes explain smooth ground well:
a tip under a particle, a fit a few pixels ahead of the tip with the wrong blur copy,
or a fit on the ground or a blob far from the tip can all score well. This check looks
instead at *where* the needle is: across the shaft, at stations 1.5 to 14 px back from
the candidate tip, the frame's profile (averaged over three lines along the shaft) is
compared with the template's at the same station and blur copy, both with their level
and slope taken out (the ground's shading), the frame's shifted sideways by up to 1 px.
At each station it measures

* ``a``, the profile's contrast against the template's (least squares: 1 for the needle
  as in the first frame, 0 for plain ground);
* ``r``, their correlation (near 1 where the two edges are where the template has them).

Edges faint further back (``a``) or elsewhere (``r``) say the fit is not on the needle;
edges that fade right behind the tip (the stations within 4.5 px) against further back
say something lies over the tip, or the fit is ahead of it. See docs/vision.md,
"Tracking the tip".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .sampling import Patch, median, sample, sample_value_xy

__all__ = ["EdgeProfiles", "EdgeCheck", "STATIONS", "NEAR", "learn_edges", "check_edges"]

FloatArray = NDArray[np.float64]

STATIONS = (1.5, 3.0, 4.5, 6.0, 8.0, 10.0, 12.0, 14.0)
"""Distances from the tip back along the shaft where the profile across it is compared, px."""

NEAR = 3
"""The first ``NEAR`` stations are "right behind the tip"."""

LINES = (-1.0, 0.0, 1.0)
"""Offsets along the shaft of the lines averaged at each station, px (against the noise)."""

STEP = 0.5
"""Spacing of the samples across the shaft, px."""

SHIFTS = 2
"""Largest lateral shift tried, in samples (``SHIFTS * STEP`` px)."""

GROUND = 7.0
"""Ground on each side of the needle that a profile takes in, px."""

GAP = 2.0
"""A station is kept only where the window holds ground on both sides from this far out of the needle's
edge, px."""


@dataclass(frozen=True)
class _Profile:
    """The template's side of one station's comparison (:func:`_station`)."""

    idx: NDArray[np.intp]
    tc: FloatArray
    e: FloatArray
    ve: float
    shifted: NDArray[np.intp]  # idx shifted by each of -SHIFTS..SHIFTS samples, a row each


@dataclass(frozen=True)
class EdgeProfiles:
    """The template's profiles across the shaft, for each blur copy (learnt once).

    Attributes
    ----------
    shaft : tuple of float
        Unit vector from the tip back along the needle (window axes).
    offsets : ndarray, shape (m, q, 2)
        Each sample's offset from the tip, px (window axes, before a turn), for the
        stations ``s`` and samples across the shaft (padded by :data:`SHIFTS` on each side).
    use : ndarray of bool, shape (m, q)
        Which samples a station's comparison uses (the needle and :data:`GROUND` px of
        ground on each side, within the template's window; none in the padding).
    expected : list of ndarray, shape (m, q)
        The template's profile at each blur copy, grey units (averaged over :data:`LINES`).
    s : ndarray, shape (m,)
        The stations kept (those where the template's needle is seen), px.
    stations : list of list
        For each blur copy and station, what :func:`_station` compares the frame's profile with:
        the samples used, the unit vector of their level-free slope, the template's profile
        with its level and slope taken out and its sum of squares (``None`` where it is flat).
    lines, lines_perp : ndarray, shape (2, len(LINES) * m * q)
        Every sample of every line, its offset from the tip (x, y; px, before a turn), one
        line after the other; and ``(-y, x)`` of each (a turn in three operations).
    """

    shaft: tuple[float, float]
    offsets: FloatArray
    use: NDArray[np.bool_]
    expected: list[FloatArray]
    s: FloatArray
    stations: list[list[_Profile | None]] = field(default_factory=list)
    lines: FloatArray = field(default_factory=lambda: np.zeros((2, 0)))
    lines_perp: FloatArray = field(default_factory=lambda: np.zeros((2, 0)))


@dataclass(frozen=True)
class EdgeCheck:
    """What the edges behind a candidate tip show.

    Attributes
    ----------
    near, far : float
        The profiles' contrast against the template's right behind the tip (the stations
        within 4.5 px, weighted by their noise) and further back (the median), 1.
    near_sd : float
        Standard deviation of ``near`` from the pixel noise, 1.
    shift : float
        The median lateral shift of the needle's axis that matched best, px.
    a, sd : ndarray
        Each station's contrast and its standard deviation from the pixel noise, 1.
    shape : float
        The median of the stations' correlations with the template's profiles, 1.
    """

    near: float
    far: float
    near_sd: float
    shift: float
    a: FloatArray
    sd: FloatArray
    shape: float


def _across(mask: NDArray[np.bool_], apex: tuple[float, float], shaft: tuple[float, float], s: float,
            ts: FloatArray) -> tuple[float, float] | None:
    """The needle's axis (offset across the shaft) and half-width at ``s`` px back from the tip, px, from the
    run of ``mask`` across the shaft nearest the axis; ``None`` where the mask shows no needle."""
    n = mask.shape[0]
    ux, uy = shaft
    ix = np.round(apex[0] + s * ux - ts * uy).astype(int)
    iy = np.round(apex[1] + s * uy + ts * ux).astype(int)
    inwin = (ix >= 0) & (ix < n) & (iy >= 0) & (iy < n)
    on = np.zeros(ts.size, dtype=bool)
    on[inwin] = mask[iy[inwin], ix[inwin]]
    if not on.any():
        return None
    idx = np.flatnonzero(on)
    c = int(idx[np.argmin(np.abs(ts[idx]))])
    lo = hi = c
    while lo > 0 and on[lo - 1]:
        lo -= 1
    while hi < ts.size - 1 and on[hi + 1]:
        hi += 1
    return 0.5 * float(ts[lo] + ts[hi]), 0.5 * float(ts[hi] - ts[lo]) + 0.5


def learn_edges(bank: list[FloatArray], apex: tuple[float, float], mask: NDArray[np.bool_],
                shaft: tuple[float, float]) -> EdgeProfiles:
    """The template's profiles across the shaft at :data:`STATIONS`, for each copy in ``bank``.

    ``mask`` is the needle in the window, ``apex`` the tip in the window (x, y; px),
    ``shaft`` the unit vector from the tip back along the needle.
    """
    n = mask.shape[0]
    ux, uy = shaft
    nx, ny = -uy, ux
    t_half = n / 2.0
    ts = np.arange(-t_half, t_half + 1e-9, STEP)
    q = ts.size + 2 * SHIFTS
    # the needle's axis and half-width at each station, from the mask across the shaft (a station nearer the
    # tip than the mask reaches, where the threshold ate the blurred end, takes the nearest station's)
    found = [_across(mask, apex, shaft, s, ts) for s in STATIONS]
    known = [f for f in found if f is not None]
    offs, uses, kept = [], [], []
    for s, f in zip(STATIONS, found, strict=True):
        if f is None:
            if not known or s > STATIONS[NEAR - 1]:
                continue
            f = (known[0][0], 1.0)  # nearer the tip than the mask reaches: the axis there, the needle narrow
        centre, half = f
        tt = centre + (np.arange(q) - (q // 2)) * STEP
        use = np.abs(tt - centre) <= half + GROUND
        use[:SHIFTS] = False
        use[-SHIFTS:] = False
        ox = s * ux + tt * nx
        oy = s * uy + tt * ny
        # every line of the station must lie within the window
        for line in LINES:
            wx = apex[0] + ox + line * ux
            wy = apex[1] + oy + line * uy
            use &= (wx >= 0) & (wx <= n - 1) & (wy >= 0) & (wy <= n - 1)
        if int(use.sum()) < 8:
            continue
        # the needle and ground on both sides of it (beyond its blurred edge) in the window
        left = use & (tt - centre <= -half - GAP)
        right = use & (tt - centre >= half + GAP)
        if int(left.sum()) < 3 or int(right.sum()) < 3:
            continue
        offs.append(np.stack([ox, oy], axis=-1))
        uses.append(use)
        kept.append(s)
    if not kept:
        return EdgeProfiles(shaft, np.zeros((0, q, 2)), np.zeros((0, q), dtype=bool), [np.zeros((0, q))] * len(bank),
                            np.zeros(0))
    offsets = np.stack(offs)
    use_a = np.stack(uses)
    expected = []
    for b in bank:
        gy, gx = np.gradient(b)
        p = Patch(np.stack([b, gx, gy]), 0, 0, (n, n))
        acc = np.zeros(use_a.shape)
        for line in LINES:
            v, _ = sample(p, apex[0] + offsets[..., 0].ravel() + line * ux,
                           apex[1] + offsets[..., 1].ravel() + line * uy)
            acc += v[0].reshape(use_a.shape)
        expected.append(acc / len(LINES))
    stations = [[_profile(E[j, np.flatnonzero(use_a[j])], np.flatnonzero(use_a[j])) for j in range(len(kept))]
                for E in expected]
    ox, oy = offsets[..., 0], offsets[..., 1]
    wx = np.concatenate([(ox + line * ux).ravel() for line in LINES])
    wy = np.concatenate([(oy + line * uy).ravel() for line in LINES])
    return EdgeProfiles(shaft, offsets, use_a, expected, np.array(kept), stations, np.stack([wx, wy]),
                        np.stack([-wy, wx]))


def _flat(v: FloatArray, tc: FloatArray) -> FloatArray:
    """``v`` with its mean and its slope along the unit vector ``tc`` taken out."""
    v = v - v.sum() / v.size
    return np.asarray(v - float(v @ tc) * tc)


def _profile(expected: FloatArray, idx: NDArray[np.intp]) -> _Profile | None:
    """The template's profile ``expected`` at the samples ``idx`` made ready for :func:`_station` (``None``:
    flat)."""
    # the profiles' level and slope taken out (the ground's shading, vignetting): the needle's two edges left
    tc = idx - idx.sum() / idx.size
    tc = tc / math.sqrt(float(tc @ tc))
    e = _flat(expected, tc)
    ve = float(e @ e)
    if ve <= 1e-18:
        return None
    return _Profile(idx, tc, e, ve, idx[None, :] + np.arange(-SHIFTS, SHIFTS + 1)[:, None])


def _station(pr: _Profile, F: FloatArray, ok: NDArray[np.bool_] | None) -> tuple[float, float, float, float] | None:
    """One station: the frame's profile ``F`` (all samples, ``ok`` where in the frame; ``None``: every one)
    against the template's (:func:`_profile`), shifted by up to :data:`SHIFTS` samples.

    Returns the contrast, the correlation and the shift (px) that correlates best, and the
    template profile's sum of squares; ``None`` when no shift lies in the frame. Every shift
    is compared at once (a row each).
    """
    if ok is None:  # every sample in the frame: every shift is
        good: list[bool] = [True] * pr.shifted.shape[0]
    else:
        in_frame: NDArray[np.bool_] = np.asarray(ok[pr.shifted].all(axis=1), dtype=bool)
        if not in_frame.any():
            return None
        good = in_frame.tolist()
    tc, e, ve = pr.tc, pr.e, pr.ve
    f = F[pr.shifted]
    f -= f.sum(axis=1, keepdims=True) / f.shape[1]
    f -= (f @ tc)[:, None] * tc
    vf = np.einsum("ij,ij->i", f, f)
    cov = f @ e
    best: tuple[float, float, float, float] | None = None
    for k, (g, c, v) in enumerate(zip(good, cov.tolist(), vf.tolist(), strict=True)):
        if not g:
            continue
        r = c / math.sqrt(ve * v) if v > 0 else 0.0
        if best is None or r > best[1]:
            best = (c / ve, r, (k - SHIFTS) * STEP, ve)
    return best


def check_edges(ep: EdgeProfiles, copy: int, frame: Patch, x: float, y: float, theta: float,
                noise: float) -> EdgeCheck | None:
    """The edges behind a tip at ``(x, y)`` (frame px) turned by ``theta`` (rad), against blur copy ``copy``.

    ``frame`` is the frame's patch smoothed as that copy is compared; ``noise`` the
    standard deviation of one of its samples (grey units). ``None`` when too few
    stations lie in the frame to say.
    """
    m = ep.s.size
    if m < 3:
        return None
    # the three lines of every station sampled in one go, turned about the tip and moved to it
    xy = ep.lines * math.cos(theta)
    xy += ep.lines_perp * math.sin(theta)
    xy[0] += x
    xy[1] += y
    v, inside = sample_value_xy(frame, xy)
    F = v.reshape(len(LINES), *ep.use.shape).sum(axis=0) / len(LINES)
    ok: NDArray[np.bool_] = np.asarray(inside.reshape(len(LINES), *ep.use.shape).all(axis=0), dtype=bool)
    all_in = bool(ok.all())  # (nearly always): no station's shifts need looking at
    a = np.full(m, np.nan)
    sd = np.full(m, np.inf)
    shift = np.zeros(m)
    rs = np.full(m, np.nan)
    for j, pr in enumerate(ep.stations[copy]):
        if pr is None:
            continue
        res = _station(pr, F[j], None if all_in else ok[j])
        if res is None:
            continue
        a[j], rs[j], shift[j], ve = res
        # samples STEP apart on a frame smoothed by about 1 px: about one independent sample a pixel
        sd[j] = noise / math.sqrt(len(LINES)) / math.sqrt(ve * STEP)
    is_near = ep.s <= STATIONS[NEAR - 1]
    near_ok = np.isfinite(a) & is_near
    far_ok = np.isfinite(a) & ~is_near
    if not near_ok.any() or int(far_ok.sum()) < 2:
        return None
    w = 1.0 / sd[near_ok] ** 2
    near = float((w * a[near_ok]).sum() / w.sum())
    near_sd = float(1.0 / math.sqrt(w.sum()))
    far = median(a[far_ok])
    return EdgeCheck(near, far, near_sd, median(shift[np.isfinite(a)]), a, sd, median(rs[np.isfinite(rs)]))
