"""The needle's shaft followed back from a candidate tip as far as the first frame showed it.

The edge check (:mod:`.edges`) compares the needle's two edges with the template's within
the template's window, 1.5 to 14 px behind the candidate tip. Something over the tip that
is about as wide as the needle there (a rounded lobe of a dust grain) has edges like the
needle's for that short way, and the fit can take its end for the tip. Behind it, the
grain ends; the needle's shaft, further back, is where the *real* tip puts it, not where
the candidate puts it. This check follows the shaft from :data:`BACK_FROM` px behind the
tip, every :data:`BACK_STEP` px, as far as the first frame showed the needle
continuously (at most :data:`BACK_TO` px): at each station the frame's profile across the
shaft (averaged over three lines 1 px apart along it, smoothed across it as the blur copy
is) is compared with the first frame's, each with its level and slope taken out, the
frame's shifted sideways by up to :data:`SHIFTS` samples. Each station gives the
profile's contrast against the first frame's (1 for the shaft as first seen, 0 for plain
ground) and their correlation (near 1 where the two edges are where the first frame had
them).

The same stations also say where the needle *ends*, through its taper: a needle widens
away from its tip, so the profile at ``s`` px behind a fix displaced by ``d`` px along
the axis is the first frame's at ``s - d``. At each station the frame's profile is fitted
(least squares) by the first frame's ``e``, its derivative along the shaft ``de/ds`` and
its second derivative across the shaft (a blur's change; the heat equation), ``a e + b
de/ds + c e''``; ``b / a`` is the displacement (minus ``d``), and the stations' median is
compared with :attr:`~.template.TrackerParams.along_limit` plus ``along_sigmas`` standard
deviations (:func:`~.track._edge_refusal`). The basis is the first frame's profiles smoothed
by the larger of the copy's two smoothings (a sharpen copy smooths the frame more than the
first frame: a basis less smooth than the frame reads the widening at about half its gain).
It sees
a fix the shaft's position cannot: one moved along the needle's axis (a grain as dark as
the needle prolonging it, its end taken for the tip).

The first frame's profiles are learnt from the frame itself, beyond the template's
window; the blur copies' profiles are the first frame's smoothed across the shaft (the
shaft is straight over a station's lines: a Gaussian blur of the image is the same blur
of the profile across it). See docs/vision.md, "Tracking the tip".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from .sampling import bilinear as _interpolate
from .sampling import cells, neighbours

__all__ = [
    "ShaftProfiles",
    "ShaftCheck",
    "BACK_FROM",
    "BACK_STEP",
    "BACK_TO",
    "learn_shaft",
    "check_shaft",
    "sample_frame",
    "station_profiles",
    "follow_shaft",
    "mean_lines",
]

FloatArray = NDArray[np.float64]

BACK_FROM = 18.0
"""The first station behind the tip, px (the edge check's stations end at 14 px)."""

BACK_STEP = 6.0
"""Spacing of the stations along the shaft, px."""

BACK_TO = 64.0
"""The last station the shaft is followed to, px."""

LINES = (-1.0, 0.0, 1.0)
"""Offsets along the shaft of the lines averaged at each station, px (against the noise)."""

STEP = 1.0
"""Spacing of the samples across the shaft, px (the shaft is wide this far back, and its
profile smoothed by 1 px or more)."""

SHIFTS = 1
"""Largest lateral shift tried, in samples (``SHIFTS * STEP`` px): an error of the fitted turn
moves a station far back sideways (1 deg: 1 px at 60 px)."""

GROUND = 7.0
"""Ground on each side of the needle that a profile takes in, px."""

REACH = 48.0
"""Half the span across the shaft sampled when learning, px (a needle up to 2 x (REACH - GROUND) px wide)."""

PAD = 12.0
"""Samples beyond the ground on each side, px: room for smoothing the frame's profile across the shaft."""

ALONG_STEP = 3.0
"""Half the span along the shaft over which the first frame's profiles are differenced (their taper), px."""

GAP_ACROSS = 12.0
"""Gaps in a needle's run across the shaft up to this wide are closed, px (an SEM needle's middle can sink
into the ground's spread between its bright edges)."""


@dataclass(frozen=True)
class ShaftProfiles:
    """The first frame's shaft profiles at the stations behind the tip, for each blur copy (learnt once).

    Attributes
    ----------
    shaft : tuple of float
        Unit vector from the tip back along the needle (frame axes of the first frame).
    s : ndarray, shape (m,)
        The stations kept (behind the tip, where the first frame showed the needle), px.
    offsets : ndarray, shape (m, q, 2)
        Each sample's offset from the tip, px (before a turn), across the shaft at each
        station (every :data:`STEP` px, centred on the needle's axis there).
    gather : ndarray of int, shape (m, 2 * SHIFTS + 1, n)
        For each station and lateral shift, the flat indices (into the ``(m, q)`` profiles)
        of the samples compared: the needle and :data:`GROUND` px of ground each side.
    shift_ok : ndarray of bool, shape (m, 2 * SHIFTS + 1)
        Which shifts keep a station's samples within its profile (a shift past its end is
        not tried).
    valid : ndarray of bool, shape (m, n)
        Which of the ``n`` places of a station hold a sample (stations differ in width).
    tc : ndarray, shape (m, n)
        Each station's unit slope across the shaft (zero-mean), for taking the slope out.
    lengths : ndarray, shape (m,)
        The samples compared at each station.
    e : list of ndarray, shape (m, n)
        For each blur copy, the first frame's profiles with their level and slope taken out.
    ve : list of ndarray, shape (m,)
        Their sums of squares.
    smooth : list of ndarray or None
        For each blur copy, the matrix that smooths a frame's profiles across the shaft
        (``F @ smooth[k]``: a Gaussian, the profile's end samples repeated beyond it).
    lines : ndarray, shape (2, m * q * len(LINES))
        Every sample of every line, its offset from the tip (x, y; px, before a turn).
    valid_f, invalid : ndarray, shape (m, 1, n)
        :attr:`valid` as 1 and 0, and its negation, shaped as the gathered samples.
    basis : list of ndarray, shape (m, 3, n)
        For each blur copy, what a station's profile is fitted with for the taper: the first
        frame's profiles smoothed by the larger of the copy's two smoothings, their derivative
        along the shaft (per px behind the tip) and their second derivative across the shaft
        (px⁻²), level and slope taken out.
    gram_inv : list of ndarray, shape (m, 3, 3)
        The inverses of their Gram matrices (NaN where singular).
    """

    shaft: tuple[float, float]
    s: FloatArray
    offsets: FloatArray
    gather: NDArray[np.intp]
    shift_ok: NDArray[np.bool_]
    valid: NDArray[np.bool_]
    tc: FloatArray
    lengths: FloatArray
    e: list[FloatArray]
    ve: list[FloatArray]
    smooth: list[FloatArray | None]
    lines: FloatArray
    valid_f: FloatArray
    invalid: NDArray[np.bool_]
    basis: list[FloatArray]
    gram_inv: list[FloatArray]


@dataclass(frozen=True)
class ShaftCheck:
    """What the shaft behind a candidate tip shows.

    Attributes
    ----------
    back : float
        The median of the stations' contrasts against the first frame's, 1.
    shape : float
        The median of the stations' correlations with the first frame's profiles, 1.
    reach : float
        The furthest station compared, px behind the tip.
    n : int
        Stations compared.
    along, along_sd : float
        The displacement of the candidate from the tip along the needle's axis that the
        taper shows (the median of the stations'; negative: the tip lies behind the
        candidate, towards the shaft), px, and its standard deviation from the pixel noise.
    """

    back: float
    shape: float
    reach: float
    n: int
    along: float = 0.0
    along_sd: float = math.inf


def sample_frame(image: FloatArray, xs: FloatArray, ys: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Bilinear samples of ``image`` at ``(xs, ys)`` (px), and which lie in the frame (the others: its edge).

    x and y are handled together and the four neighbours gathered at once (:mod:`.sampling`'s pieces, on the
    whole frame): the same values as each coordinate and neighbour apart, bit for bit.
    """
    H, W = image.shape
    xy = np.stack((np.ravel(xs), np.ravel(ys))).astype(float, copy=False)
    i00, fx, fy, inside = cells(xy, H, W)
    v = image.reshape(-1).take(neighbours(i00, H, W))
    shape = np.shape(xs)
    return _interpolate(v, fx, fy).reshape(shape), inside.reshape(shape)


def station_profiles(image: FloatArray, x: float, y: float, ox: FloatArray, oy: FloatArray, ux: float, uy: float
           ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The mean over :data:`LINES` of ``image`` at the offsets ``(ox, oy)`` from ``(x, y)`` (px), and which
    samples lie in the frame on every line."""
    d = np.asarray(LINES)
    xs = (ox[..., None] + d * ux + x).ravel()
    ys = (oy[..., None] + d * uy + y).ravel()
    v, inside = sample_frame(image, xs, ys)
    n = len(LINES)
    return mean_lines(v.reshape(*ox.shape, n)), np.asarray(inside.reshape(*ox.shape, n).all(axis=-1), dtype=bool)


def mean_lines(v: FloatArray) -> FloatArray:
    """``v.mean(axis=-1)`` bit for bit, signed zeros included, for a last axis of fewer than 8 (the lines'
    samples): numpy sums it from 0, one after the other, and divides by its length; here a slice at a time, in
    a third of its time."""
    n = v.shape[-1]
    if not 1 <= n < 8:  # numpy sums 8 or more pairwise
        return np.asarray(v.mean(axis=-1), dtype=float)
    out = v[..., 0] + 0.0
    for k in range(1, n):
        out += v[..., k]
    out /= n
    return out


def _median(a: FloatArray) -> float:
    """The median of a few values (:func:`numpy.median`'s, without its overhead)."""
    b = np.sort(a)
    n = b.size
    return float(b[n // 2]) if n % 2 else 0.5 * float(b[n // 2 - 1] + b[n // 2])


def learn_shaft(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float], level: float,
                spread: float, contrast: float, smooth: list[tuple[float, float]]) -> ShaftProfiles:
    """The first frame's profiles across the shaft behind the tip, as far as it shows the needle.

    ``image`` is the first frame, ``tip`` the tip in it (x, y; px), ``shaft`` the unit
    vector from the tip back along the needle; a sample is needle where the profile,
    smoothed by 1 px, stands more than ``contrast`` times ``spread`` from the ground's
    ``level`` (grey units). ``smooth`` gives, for each blur copy, the smoothing of the
    first frame's profile and of a later frame's across the shaft (Gaussian sigma, px).
    """
    half_q = int(round(REACH / STEP))
    ts: FloatArray = (np.arange(2 * half_q + 1, dtype=np.float64) - half_q) * STEP
    offs, raws, widths, kept = follow_shaft(image, tip, shaft, level, spread, contrast, ts)
    n_copies = len(smooth)
    if not kept:
        z = np.zeros((0, 0))
        return ShaftProfiles(shaft, np.zeros(0), np.zeros((0, 0, 2)), np.zeros((0, 2 * SHIFTS + 1, 0), dtype=np.intp),
                             np.zeros((0, 2 * SHIFTS + 1), dtype=bool), np.zeros((0, 0), dtype=bool), z, np.zeros(0),
                             [z] * n_copies, [np.zeros(0)] * n_copies, [None] * n_copies, np.zeros((2, 0)),
                             np.zeros((0, 1, 0)), np.zeros((0, 1, 0), dtype=bool), [np.zeros((0, 3, 0))] * n_copies,
                             [np.zeros((0, 3, 3))] * n_copies)
    # the same lines ALONG_STEP px nearer the tip and further from it: the profiles' change along the shaft (taper)
    ux, uy = shaft
    nearer, further = ([station_profiles(image, tip[0], tip[1], o[..., 0] + d * ux, o[..., 1] + d * uy, ux, uy)[0]
                        for o in offs] for d in (-ALONG_STEP, ALONG_STEP))
    return _assemble(shaft, ts, offs, (raws, nearer, further), widths, kept, smooth)


def follow_shaft(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float], level: float, spread: float,
            contrast: float, ts: FloatArray, start: float = BACK_FROM
            ) -> tuple[list[FloatArray], list[FloatArray], list[float], list[float]]:
    """:func:`learn_shaft`'s walk back along the needle from ``start`` px behind the tip: each station's sample
    offsets, raw profile, the needle's width there (px) and its distance behind the tip (px), as far as the
    first frame shows it."""
    ux, uy = shaft
    nx, ny = -uy, ux
    half_q = (ts.size - 1) // 2
    x0, y0 = tip
    offs: list[FloatArray] = []
    raws: list[FloatArray] = []
    widths: list[float] = []
    kept: list[float] = []
    centre = 0.0
    width = 0.0
    for s in np.arange(start, BACK_TO + 1e-9, BACK_STEP):
        ox = s * ux + (centre + ts) * nx
        oy = s * uy + (centre + ts) * ny
        raw, ok = station_profiles(image, x0, y0, ox, oy, ux, uy)
        sm = ndimage.gaussian_filter1d(raw, 1.0 / STEP, mode="nearest")
        on = (np.abs(sm - level) > contrast * spread) & ok
        # a needle whose middle is nearer the ground than its edges (an SEM's edge contrast) is one run
        on = ndimage.binary_closing(on, np.ones(int(round(GAP_ACROSS / STEP)) + 1, dtype=bool)) & ok
        mid = half_q
        # the run of needle samples nearest the axis followed so far
        idx = np.flatnonzero(on)
        if idx.size == 0:
            break
        c = int(idx[np.argmin(np.abs(idx - mid))])
        if abs(c - mid) * STEP > 2.0 + 0.5 * width:
            break  # the needle is not where it was followed to
        lo = hi = c
        while lo > 0 and on[lo - 1]:
            lo -= 1
        while hi < on.size - 1 and on[hi + 1]:
            hi += 1
        new_width = (hi - lo + 1) * STEP
        g = int(round((GROUND + PAD) / STEP))
        if lo - g < 0 or hi + g > on.size - 1 or not ok[lo - g : hi + g + 1].all():
            break  # the frame ends (or the needle is too wide to hold): as far as the first frame shows it
        g, gap = int(round(GROUND / STEP)), max(1, int(round(1.0 / STEP)))
        if on[lo - g : lo - gap].any() or on[hi + gap + 1 : hi + g + 1].any():
            break  # no plain ground beside it: something lies against the needle
        if width > 0 and new_width > width + 2.0 * BACK_STEP + 2.0:
            break  # much wider than a station before: something merges with it
        width = new_width
        centre = centre + 0.5 * (ts[lo] + ts[hi])
        ox = s * ux + (centre + ts) * nx
        oy = s * uy + (centre + ts) * ny
        offs.append(np.stack([ox, oy], axis=-1))
        raws.append(station_profiles(image, x0, y0, ox, oy, ux, uy)[0])
        widths.append(width)
        kept.append(float(s))
    return offs, raws, widths, kept


def _assemble(shaft: tuple[float, float], ts: FloatArray, offs: list[FloatArray],
              raws: tuple[list[FloatArray], list[FloatArray], list[FloatArray]], widths: list[float],
              kept: list[float], smooth: list[tuple[float, float]]) -> ShaftProfiles:
    """:func:`learn_shaft`'s profiles from the stations followed (``raws``: at the stations, :data:`ALONG_STEP`
    px nearer the tip and further from it): what a check gathers and compares."""
    ux, uy = shaft
    # the samples a check needs: the widest station's needle and ground, the shifts, and room to smooth
    reach = max(0.5 * w + GROUND for w in widths) + SHIFTS * STEP + 3.0 * max(f for _, f in smooth)
    cut = np.flatnonzero(np.abs(ts) <= reach + 1e-9)
    k0, q = int(cut[0]), int(cut.size)
    tq = ts[k0 : k0 + q]
    m = len(kept)
    lengths = np.array([int(np.count_nonzero(np.abs(tq) <= 0.5 * w + GROUND)) for w in widths])
    starts = np.array([int(np.flatnonzero(np.abs(tq) <= 0.5 * w + GROUND)[0]) for w in widths])
    lmax = int(lengths.max())
    j_ = np.arange(lmax)
    valid = j_[None, :] < lengths[:, None]
    tc = np.where(valid, j_[None, :] - 0.5 * (lengths[:, None] - 1), 0.0)
    tc /= np.sqrt((tc * tc).sum(axis=1, keepdims=True))
    d = np.arange(-SHIFTS, SHIFTS + 1)
    k = starts[:, None, None] + j_[None, None, :] + d[None, :, None]  # (m, shifts, lmax)
    shift_ok = np.asarray((((k >= 0) & (k < q)) | ~valid[:, None, :]).all(axis=2), dtype=bool)
    gather = np.arange(m)[:, None, None] * q + np.clip(k, 0, q - 1)
    take = np.arange(m)[:, None] * q + np.clip(starts[:, None] + j_[None, :], 0, q - 1)

    def flat(raw: FloatArray, tsig: float) -> FloatArray:
        """Profiles smoothed by ``tsig`` px, gathered, their level and slope taken out."""
        e = ndimage.gaussian_filter1d(raw, tsig / STEP, axis=1, mode="nearest")[:, k0 : k0 + q].take(take)
        e = np.where(valid, e, 0.0)
        e = e - np.where(valid, e.sum(axis=1, keepdims=True) / lengths[:, None], 0.0)
        return np.asarray(e - (e * tc).sum(axis=1, keepdims=True) * tc)

    es, ves, bases, grams = [], [], [], []
    for tsig, fsig in smooth:
        e = flat(np.stack(raws[0]), tsig)
        es.append(e)
        ves.append((e * e).sum(axis=1))
        # the taper's basis smoothed as much as the smoother of the two profiles compared (a sharpen copy's frame)
        bsig = max(tsig, fsig)
        e = e if bsig == tsig else flat(np.stack(raws[0]), bsig)
        de = (flat(np.stack(raws[2]), bsig) - flat(np.stack(raws[1]), bsig)) / (2.0 * ALONG_STEP)
        ett = np.where(valid, np.gradient(np.gradient(e, STEP, axis=1), STEP, axis=1), 0.0)
        ett = ett - np.where(valid, ett.sum(axis=1, keepdims=True) / lengths[:, None], 0.0)
        basis = np.stack([e, de, ett - (ett * tc).sum(axis=1, keepdims=True) * tc], axis=1)
        gram = np.einsum("kin,kjn->kij", basis, basis)
        ok = np.abs(np.linalg.det(gram)) > 1e-30
        inv = np.full(gram.shape, np.nan)
        inv[ok] = np.linalg.inv(gram[ok])
        bases.append(basis)
        grams.append(inv)
    offsets = np.stack(offs)[:, k0 : k0 + q]
    d_lines = np.asarray(LINES)
    lines = np.stack([(offsets[..., 0][..., None] + d_lines * ux).ravel(),
                      (offsets[..., 1][..., None] + d_lines * uy).ravel()])
    kernels: dict[float, FloatArray] = {}
    for _, f in smooth:
        if f > 0 and f not in kernels:
            kernels[f] = ndimage.gaussian_filter1d(np.eye(q), f / STEP, axis=1, mode="nearest")
    return ShaftProfiles(shaft, np.array(kept), offsets, gather, shift_ok, valid, tc, lengths.astype(float), es, ves,
                         [kernels.get(f) for _, f in smooth], lines, valid[:, None, :].astype(float),
                         ~valid[:, None, :], bases, grams)


def check_shaft(sp: ShaftProfiles, copy: int, image: FloatArray, x: float, y: float, theta: float
                ) -> ShaftCheck | None:
    """The shaft behind a tip at ``(x, y)`` (frame px) turned by ``theta`` (rad), against blur copy ``copy``.

    ``None`` when fewer than three stations lie in the frame (too few to say).
    """
    m = sp.s.size
    if m < 3:
        return None
    ct, st_ = math.cos(theta), math.sin(theta)
    lx, ly = sp.lines
    v, inside = sample_frame(image, ct * lx - st_ * ly + x, st_ * lx + ct * ly + y)
    n = len(LINES)
    shape = (m, sp.offsets.shape[1], n)
    F = mean_lines(v.reshape(shape))
    ok = inside.reshape(shape).all(axis=2)
    kernel = sp.smooth[copy]
    if kernel is not None:
        F = F @ kernel
    # every station at every shift at once: its samples' sums against the flat ones, the slope and the profile
    G = F.reshape(-1).take(sp.gather)
    G *= sp.valid_f
    good = sp.shift_ok
    if not ok.all():  # part of the shaft outside the frame: the shifts that reach past it are not compared
        good = good & (ok.reshape(-1).take(sp.gather) | sp.invalid).all(axis=2)
    s1 = G.sum(axis=2)
    G2 = G * G
    vf = G2.sum(axis=2) - s1 * s1 / sp.lengths[:, None] - np.einsum("isk,ik->is", G, sp.tc) ** 2
    e, ve = sp.e[copy], sp.ve[copy]
    cov = np.einsum("isk,ik->is", G, e)
    use = good & (vf > 0) & (ve[:, None] > 1e-18)
    r = np.where(use, cov / np.sqrt(np.maximum(ve[:, None] * vf, 1e-300)), -np.inf)
    best = r.argmax(axis=1)
    rows = np.arange(m)
    seen = use[rows, best]
    if int(seen.sum()) < 3:
        return None
    a = cov[rows, best][seen] / ve[seen]
    along, along_sd = _taper(sp, copy, G[rows, best][seen], vf[rows, best][seen], seen)
    return ShaftCheck(_median(a), _median(r[rows, best][seen]), float(sp.s[seen].max()),
                      int(seen.sum()), along, along_sd)


def _taper(sp: ShaftProfiles, copy: int, G: FloatArray, vf: FloatArray, seen: NDArray[np.bool_]
           ) -> tuple[float, float]:
    """The displacement along the axis that the stations' profiles ``G`` (at their best shifts; ``vf`` their sums
    of squares with level and slope taken out) show through the taper, px (the median of the stations'), and its
    standard deviation; ``(0, inf)`` when fewer than three stations say."""
    basis, inv = sp.basis[copy][seen], sp.gram_inv[copy][seen]
    # the basis has no level nor slope: G's own drop out of its products with it
    rhs = np.einsum("kin,kn->ki", basis, G)
    sol = np.einsum("kij,kj->ki", inv, rhs)
    a, b = sol[:, 0], sol[:, 1]
    n = sp.lengths[seen]
    s2 = np.maximum(vf - (sol * rhs).sum(axis=1), 0.0) / np.maximum(n - 4.0, 1.0)
    good = np.isfinite(a) & (np.abs(a) > 1e-9)
    if int(good.sum()) < 3:
        return 0.0, math.inf
    a, b, s2, inv = a[good], b[good], s2[good], inv[good]
    d = b / a
    # the ratio's variance, to first order, from the fit's covariance s2 * inv
    var = s2 * (inv[:, 1, 1] + d * d * inv[:, 0, 0] - 2.0 * d * inv[:, 0, 1]) / (a * a)
    w = 1.0 / np.maximum(var, 1e-6)
    return _median(d), float(1.0 / math.sqrt(float(w.sum())))
