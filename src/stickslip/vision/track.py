"""Tip tracking: a sub-pixel fix with its confidence in every frame, or a refusal with its reason.

:class:`TipTracker` learns the tip from the first frame and the tip's pixel
(:class:`~.template.TipTemplate`), then for each later frame:

1. **looks near the last fix**: the weighted normalised correlation of the template over a
   square of :attr:`~.template.TrackerParams.search_radius` around it (by FFT), at the blur
   copy that matched last; the best peak, then the blur copy that matches it best;
2. **refines** it to a fraction of a pixel (:func:`~.refine.refine`: rigid motion about the
   tip, contrast and brightness, robust to what disagrees), with the fix's covariance;
3. **decides** (docs/vision.md, "Decision rules"): the fix is refused

   * *out of the field* when it lies within :attr:`~.template.TrackerParams.edge_margin`
     (plus twice its blur) of the field's edge, or beyond: a tip just past the edge looks
     like a tip on it;
   * *out of focus* when only the most blurred copies match, or the blur is beyond
     :attr:`~.template.TrackerParams.max_blur`;
   * *occluded* when more than :attr:`~.template.TrackerParams.occluded_fraction` of the
     template's weight disagrees with the frame;
   * *lost* when the correlation is below :attr:`~.template.TrackerParams.min_score` or the
     fix's standard deviation above :attr:`~.template.TrackerParams.max_sigma` (its position
     is not determined: only the shaft is seen);

4. **follows the needle's edges** back from a fix the rules take (:mod:`.edges`): the fix
   is refused when they are faint or misplaced (*lost*: the fit is on the ground or a
   blob) or fade right behind the tip (*occluded*: something over it, or the fit ahead
   of it); where they hold, **the shaft further back** (:mod:`.shaft`, as far as the
   first frame showed the needle) must be where the first frame had it (*lost*: the fit
   took the end of something over the tip, a grain's lobe, for the tip), and its taper
   must put the tip within 3 px (plus 3 standard deviations) of the fix along the axis
   (*occluded*: a grain as dark as the needle prolongs it, its end taken for the tip);
   last, **the needle's width** at each station behind the fix (:mod:`.width`) must be
   the first frame's there, within what 3 px along the axis change it (*occluded* when
   most stations differ: the far end of a chip stuck on the tip, wider than the needle
   where it lies and the needle narrower behind it; or when at any station the needle's
   extent across the shaft is narrower than the first frame's beyond the taper's 3 px and a
   slack: past an occluder taken for the tip, the needle's own end lies further back or to
   the side); where the first frame showed such
   stations and fewer than three lie in the frame behind the fix (the shaft leaves the field), the
   fix is refused (*lost*): nothing vouches that the end seen is the tip, unless the fit passes the
   stricter rules for a tip found again (they vouch for it instead); else the frame goes on to the
   whole frame's search, whose rules vouch for a tip found again;
5. when the tip is not found near the last fix (or was refused in the frame before), it is
   **looked for in the whole frame** (down-sampled correlation, the best few peaks refined)
   and taken only with the stricter :attr:`~.template.TrackerParams.reacquire_score`; the
   frame is padded so the template may hang over its border until its tip lies on the edge,
   the part outside left out of the correlation (:func:`~.template.inside_ncc`): a tip near
   the edge is found again as one in the middle is;
   not when the fit near the last fix was refused by another rule while its edges hold
   (the tip is there, only its position or focus not vouched for).

A fix is never a guess: a frame the rules cannot vouch for is refused.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.fft import next_fast_len

from .average import TemplateAverage, anchor
from .confirm import Confirmation, confirm_mask
from .edges import EdgeCheck, check_edges, learn_edges
from .frame import Frame, as_image
from .needle import needle_for, refit
from .refine import Refinement, Steepest, _window_cells, refine, steepest
from .sampling import Patch, bilinear, median, neighbours, patch, sample_value_xy, with_slopes
from .shaft import ShaftCheck, ShaftProfiles, check_shaft, learn_shaft
from .template import (
    TemplateError,
    TipTemplate,
    TrackerParams,
    _level_weights,
    _surroundings,
    _window,
    inside_ncc,
    masked_ncc,
    region_spectra,
)
from .width import OutlineStations, WidthCheck, WidthStations, check_outline, check_width, learn_outline, learn_width

__all__ = [
    "Fix",
    "Lost",
    "TipTracker",
    "TrackerParams",
    "TemplateError",
    "REASONS",
    "track",
]

FloatArray = NDArray[np.float64]

REASONS = ("out of the field", "occluded", "out of focus", "lost")
"""Why a frame gives no fix."""


@dataclass(frozen=True)
class Fix:
    """The tip found in a frame.

    Attributes
    ----------
    x, y : float
        The tip, px (x right, y down, the centre of the top-left pixel at (0, 0)).
    score : float
        Confidence: the weighted correlation of the frame with the tip's template, 0..1.
    sigma : float
        Standard deviation of the position along its worst direction, px.
    blur : float
        Extra blur of the tip against the first frame (Gaussian sigma), px.
    angle : float
        The needle's turn since the first frame, rad.
    """

    x: float
    y: float
    score: float
    sigma: float
    blur: float = 0.0
    angle: float = 0.0

    def as_dict(self) -> dict[str, float]:
        """``{"x", "y", "score", "sigma"}`` (px, 1, px)."""
        return {"x": self.x, "y": self.y, "score": self.score, "sigma": self.sigma}


@dataclass(frozen=True)
class Lost:
    """A frame without a fix, and why.

    Attributes
    ----------
    reason : str
        One of :data:`REASONS`.
    detail : str
        What the tracker saw (the correlation, the distance from the edge, ...).
    """

    reason: str
    detail: str = ""


Result = Fix | Lost


@dataclass(frozen=True)
class _Candidate:
    ref: Refinement
    level: int
    ncc: float
    patch: Patch
    edges: EdgeCheck | None = None
    shaft: ShaftCheck | None = None
    width: WidthCheck | None = None
    unvouched: bool = False  # refused only because nothing vouches for it (too few width stations in the frame)


def _needled(t: TipTracker, image: FloatArray, ref: Refinement, lvl: int, patches: dict[float, Patch]
             ) -> _Candidate:
    """The candidate of a fit at copy ``lvl``; with :attr:`~.template.TrackerParams.needle` on and ``needle_judge``
    off, its position and covariance are the needle's (:func:`~.needle.refit`) when the needle's fit holds (with
    ``needle_judge`` on, the needle is fitted only for a fix the rules take: :func:`_placed`)."""
    if t._needle is not None and not t.params.needle_judge and math.isfinite(ref.x) and math.isfinite(ref.y):
        got = refit(t._needle, image, ref.x, ref.y, ref.theta, t._spec[lvl][2], t.params)
        if got is not None:
            ref = replace(ref, x=got[0], y=got[1], cov=got[2] if t.params.needle_sigma else ref.cov)
    return _Candidate(ref, lvl, ref.score, t._patch(patches, image, ref.x, ref.y, t._spec[lvl][1]))


def _placed(t: TipTracker, fix: Fix, cand: _Candidate, image: FloatArray) -> Fix:
    """Accept ``fix`` (:meth:`TipTracker._accept`) and give it at the needle's tip when the rules judged the
    template's fit (``needle_judge``) and the needle's fit near it holds (:func:`~.needle.refit`). With
    ``needle_state`` the tracker keeps the needle's tip as its last fix (the next frame's search starts there);
    without, the template's fit, so that every decision is the tracker's without the stage."""
    got = None
    if t._needle is not None and t.params.needle_judge:
        got = refit(t._needle, image, cand.ref.x, cand.ref.y, cand.ref.theta, t._spec[cand.level][2], t.params)
    placed = fix if got is None else replace(fix, x=got[0], y=got[1])
    kept = t._accept(placed if t.params.needle_state else fix, cand, image)
    return placed if got is not None else kept


def _downsample(a: FloatArray, f: int) -> FloatArray:
    """``a`` averaged over blocks of ``f`` x ``f`` pixels (the rows and columns past the last whole block dropped).

    ``a[:h, :w].reshape(h // f, f, w // f, f).mean(axis=(1, 3))`` bit for bit, signed zeros
    included, in a sixth of its time: numpy sums each block's rows from 0, then the rows' sums
    from 0, and divides by ``f²``; the same sums here, one slice of every block at a time. Where
    numpy sums otherwise (blocks of 8 or more pixels a side, summed pairwise; a single block
    across, whose rows it takes as one), its own mean.
    """
    if f <= 1:
        return a
    h, w = (a.shape[0] // f) * f, (a.shape[1] // f) * f
    if f >= 8 or w < 2 * f:
        return np.asarray(a[:h, :w].reshape(h // f, f, w // f, f).mean(axis=(1, 3)), dtype=float)
    blocks = np.asarray(a, dtype=float)[:h, :w].reshape(h // f, f, w // f, f)
    rows = blocks[..., 0] + 0.0  # each block's rows summed along x: (h // f, f, w // f)
    for k in range(1, f):
        rows += blocks[..., k]
    out = rows[:, 0] + 0.0  # then the rows' sums down each block
    for k in range(1, f):
        out += rows[:, k]
    out /= f * f
    return out


def _local_max(a: FloatArray, r: int) -> FloatArray:
    """The largest value of ``a`` within ``r`` px along each axis of each pixel (a square of side ``2 r + 1``
    cut by the edges): :func:`scipy.ndimage.maximum_filter` of that size, whose mirrored edges hold no other
    values, for an array without NaN; along x, then along y, in a third of its time."""
    h, w = a.shape
    wide = np.full((h, w + 2 * r), -np.inf)
    wide[:, r : r + w] = a
    across = wide[:, :w].copy()
    for d in range(1, 2 * r + 1):
        np.maximum(across, wide[:, d : d + w], out=across)
    tall = np.full((h + 2 * r, w), -np.inf)
    tall[r : r + h] = across
    out = tall[:h].copy()
    for d in range(1, 2 * r + 1):
        np.maximum(out, tall[d : d + h], out=out)
    return out


def _peak_cells(ncc: FloatArray, floor: float) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The rows and columns of the pixels of ``ncc`` above ``floor`` that are each the largest within 2 px (a
    5 x 5 square), row by row."""
    ii, jj = np.nonzero((ncc == _local_max(ncc, 2)) & (ncc > floor))
    return ii, jj


def _region(image: FloatArray, h: int, cx: float, cy: float, radius: int) -> tuple[FloatArray, int, int]:
    """A region of the frame holding every template position (window half-width ``h``) within ``radius`` of
    ``(cx, cy)``, and its top-left corner in the frame (px); past the frame's edge, the frame's median level."""
    H, W = image.shape
    x0 = int(round(cx)) - radius - h
    y0 = int(round(cy)) - radius - h
    n = 2 * (radius + h) + 1
    ys, xs = max(0, y0), max(0, x0)
    ye, xe = min(H, y0 + n), min(W, x0 + n)
    if ys == y0 and xs == x0 and ye == y0 + n and xe == x0 + n:  # within the frame: a copy
        return image[ys:ye, xs:xe].copy(), x0, y0
    out = np.full((n, n), float(np.median(image[::8, ::8])))
    if ye > ys and xe > xs:
        out[ys - y0 : ye - y0, xs - x0 : xe - x0] = image[ys:ye, xs:xe]
    return out, x0, y0


def _padded(image: FloatArray, f: int, half: int, cache: dict[object, object]
            ) -> tuple[FloatArray, FloatArray, int]:
    """The frame down-sampled by ``f``, padded with zeros by ``pad`` cells each side (and below and to the right
    to a size the FFT is quick at), which of its cells lie in the frame (kept in ``cache``), and ``pad``: the
    coarse template's window (half-width ``half`` px) may start ``pad`` cells before the frame, where its tip
    lies on the edge; the whole-frame search then reaches a tip anywhere in the frame."""
    small = _downsample(image, f)
    pad = -(-(half + 1) // f)  # the tip lies half + 1/2 px or less from the window's edge
    hs, ws = small.shape
    shape = (next_fast_len(hs + 2 * pad, real=True), next_fast_len(ws + 2 * pad, real=True))
    out = np.zeros(shape)
    out[pad : pad + hs, pad : pad + ws] = small
    inside = cache.get(("inside", shape, hs, ws))
    if not isinstance(inside, np.ndarray):
        inside = np.zeros(shape)
        inside[pad : pad + hs, pad : pad + ws] = 1.0
        cache[("inside", shape, hs, ws)] = inside
    return out, inside, pad


_Peaks = tuple[FloatArray, NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]
"""Peaks of the whole-frame correlation: their significance, rows, columns and blur copies."""


def _ranked(ncc: FloatArray, cover: FloatArray, k: int) -> _Peaks:
    """The peaks (:func:`_peak_cells`) of the whole-frame correlation ``ncc`` of copy ``k``, each ranked by its
    significance: Fisher's ``atanh(r)`` times the square root of the share ``cover`` of the template's weight
    inside the frame.

    Over ``N`` pixels where nothing matches, ``atanh(r)`` spreads by about ``1 / sqrt(N)``: a part of the
    template matches junk by chance better than the whole does, and a peak at the border would otherwise crowd
    out the tip in the middle. Where all the weight lies in the frame the order is the correlation's own.
    """
    ii, jj = _peak_cells(ncc, 0.3)
    z = np.arctanh(np.minimum(ncc[ii, jj], 1.0 - 1e-12)) * np.sqrt(np.minimum(cover[ii, jj], 1.0))
    return z, ii, jj, np.full(ii.size, k, dtype=np.intp)


def _by_rank(peaks: Sequence[_Peaks]) -> Iterator[tuple[float, int, int, int]]:
    """Every copy's peaks (:func:`_ranked`) as ``(significance, row, column, copy)``, the largest first (ties: the
    larger row, column, copy first): ``sorted(..., reverse=True)`` of those tuples, made one at a time as they are
    read (the search reads a few of a thousand or more)."""
    z, ii, jj, kk = (np.concatenate([q[n] for q in peaks]) if peaks else np.zeros(0) for n in range(4))
    order = np.lexsort((kk, jj, ii, z))[::-1]  # the tuples' order, none the same (one peak per cell and copy)
    zl, il, jl, kl = (a[order].tolist() for a in (z, ii, jj, kk))
    yield from zip(zl, il, jl, kl, strict=True)


def _look(image: FloatArray, t: TipTemplate, p: TrackerParams, cache: dict[object, object], x: float, y: float,
          k: int) -> tuple[FloatArray, int, int]:
    """The correlation of blur copy ``k`` at whole pixels within ``2 coarse_factor`` of ``(x, y)`` and the
    region's top-left corner (px): where the region leaves the frame, over the part inside
    (:func:`~.template.inside_ncc`)."""
    region, rx0, ry0 = _region(image, t.half, x, y, 2 * p.coarse_factor)
    H, W = image.shape
    n = region.shape[0]
    if rx0 >= 0 and ry0 >= 0 and rx0 + n <= W and ry0 + n <= H:
        return masked_ncc(region, t.bank[k], t.level_weights[k], cache, ("local", k), single=True), rx0, ry0
    yy, xx = np.arange(ry0, ry0 + n), np.arange(rx0, rx0 + n)
    inside = (((yy >= 0) & (yy < H))[:, None] & ((xx >= 0) & (xx < W))[None, :]).astype(float)
    ncc, _ = inside_ncc(region * inside, inside, t.bank[k], t.level_weights[k], cache, ("look", k),
                        least=p.min_coverage, single=True)
    return ncc, rx0, ry0


def _front_offsets(t: TipTemplate, blur: float, cache: dict[object, object] | None
                   ) -> tuple[FloatArray, FloatArray, int]:
    """The template's core, ring and front offsets (the front's only those ahead of a tip blurred by ``blur`` px)
    as one array (px, shape (2, n)), the same turned a quarter (``(-y, x)``), and how many of the front's are
    kept; kept in ``cache`` for the template's core, ring and front (made again when they are)."""
    kept = cache.get(("front", blur)) if cache is not None else None
    if isinstance(kept, tuple) and kept[0] is t.core and kept[1] is t.ring and kept[2] is t.front:
        return kept[3], kept[4], kept[5]
    fx, fy = t.front
    far = np.hypot(fx, fy) >= 2.0 + 2.0 * blur  # a blurred tip spreads ahead of itself
    o = np.stack((np.concatenate([t.core[0], t.ring[0], fx[far]]), np.concatenate([t.core[1], t.ring[1], fy[far]])))
    out = (o, np.stack((-o[1], o[0])), int(far.sum()))
    if cache is not None:
        cache[("front", blur)] = (t.core, t.ring, t.front, *out)
    return out


def _front_share(t: TipTemplate, cand: _Candidate, blur: float, cache: dict[object, object] | None = None) -> float:
    """Share of the half-ring in front of the tip whose grey level is nearer the needle's than the background's.

    The template's core, ring and front offsets are turned and moved to the candidate's fit
    and sampled in its patch; ``blur`` (px) keeps the ground a blurred tip spreads over out.
    ``cache``: where the offsets are kept (:func:`_front_offsets`).
    """
    r = cand.ref
    if t.core[0].size < 3 or t.ring[0].size < 8:
        return 0.0
    # the core, the ring and the front ahead of a blurred tip, sampled in one go: cos o + sin (-y, x) is, bit for
    # bit, (cos x - sin y, sin x + cos y)
    o, perp, n_far = _front_offsets(t, blur, cache)
    xy = o * math.cos(r.theta)
    xy += perp * math.sin(r.theta)
    xy[0] += r.x
    xy[1] += r.y
    v, _ = sample_value_xy(cand.patch, xy)
    nc, nr = t.core[0].size, t.ring[0].size
    needle = median(v[:nc])  # numpy.median's, bit for bit
    ground = median(v[nc : nc + nr])
    if abs(needle - ground) < 1e-12:
        return 1.0
    if n_far < 6:
        return 0.0
    like = (v[nc + nr :] - ground) / (needle - ground) > 0.5
    return float(np.mean(like))


FOCUS_STEP = "the focus would have changed"
"""How the focus step rule's refusal begins (:meth:`TipTracker._rules`)."""


@dataclass(frozen=True)
class _View:
    """The frame's pixels around a fix (a copy), enough to compare the blur copies there again.

    Attributes
    ----------
    pixels : ndarray
        The frame's grey values in the crop.
    x0, y0 : int
        The crop's top-left pixel in the frame.
    shape : tuple of int
        The frame's ``(height, width)``.
    """

    pixels: FloatArray
    x0: int
    y0: int
    shape: tuple[int, int]

    @classmethod
    def keep(cls, image: FloatArray, x: float, y: float, half: int) -> _View:
        """A copy of every pixel :meth:`TipTracker._levels` reads for a tip at ``(x, y)`` (window ``half``, px):
        within its patches' radius (``half sqrt 2 + 12``) and the patch's own margin, with room to spare."""
        r = int(math.ceil(half * math.sqrt(2.0) + 12.0)) + 8
        H, W = image.shape
        xi, yi = int(math.floor(x)), int(math.floor(y))
        x0, y0 = min(max(xi - r, 0), W), min(max(yi - r, 0), H)
        return cls(image[y0 : max(min(yi + r + 1, H), y0), x0 : max(min(xi + r + 1, W), x0)].copy(), x0, y0,
                   (int(H), int(W)))

    def frame(self) -> FloatArray:
        """A frame holding the kept pixels where they were, zeros elsewhere (never read)."""
        out = np.zeros(self.shape)
        h, w = self.pixels.shape
        out[self.y0 : self.y0 + h, self.x0 : self.x0 + w] = self.pixels
        return out


def _as_usual(score: float, usual: float | None) -> bool:
    """Whether a fit correlating by ``score`` matches as the recent fixes did (their median ``1 - score``
    ``usual``; ``None`` before three): a mismatch at most half as large again, and 0.005."""
    return usual is not None and 1.0 - score <= 1.5 * usual + 0.005


def _focus_reread(t: TipTracker, cand: _Candidate, image: FloatArray, reacquire: bool) -> Result:
    """The template fit's rules on ``cand``, the focus step judged against the last fix's blur as read there.

    The blur copy a fix was fitted with is not a reading of its focus: the copies are compared
    only when a fit matches worse than the recent fixes did, so a fix keeps the last one's copy
    while the focus drifts, until a fit is compared and the copy jumps by the drift of many
    frames at once. When the copy chosen lies further from the last fix's than the focus may
    drift (:attr:`~.template.TrackerParams.max_blur_step` a frame), the copies are compared at
    the last fix, on its own pixels (kept by :meth:`_View.keep`), as :meth:`TipTracker._try`
    compares them (the copy fitted unless another matches better by
    :attr:`~.template.TrackerParams.level_hysteresis`), and the step is judged from the copy
    they pick. Only for a fit
    that matches as the recent fixes did (:func:`_as_usual`): a lag of the copy is then all
    that changed; a fit that matches worse (a grain over the tip) changed more than its focus.
    """
    res = t._rules(cand, image, reacquire, t._level)
    view = t._last_view
    if view is None or t._last is None or not (isinstance(res, Lost) and res.detail.startswith(FOCUS_STEP)):
        return res
    if not _as_usual(cand.ref.score, t._usual_mismatch()):  # more than the focus changed: the step stands
        return res
    scores = t._levels({}, view.frame(), t._last[0], t._last[1], t._theta)
    read = _pick_level(scores, t._level, t.params.level_hysteresis)
    return res if read == t._level else t._rules(cand, image, reacquire, last=read)


def _top_matches(t: TipTracker, cand: _Candidate, image: FloatArray) -> bool:
    """Whether the most blurred copy matches a fit with the copy next to it at least as well, at the fit
    (:attr:`~.template.TrackerParams.focus_top_read`; no hysteresis: the copy is read, not kept)."""
    if not t.params.focus_top_read or cand.level != t._top - 1:
        return False
    r = cand.ref
    scores = t._levels({}, image, r.x, r.y, r.theta)
    return scores[t._top] >= scores[cand.level]


def _pick_level(scores: list[float], current: int, hysteresis: float) -> int:
    """The blur copy that matches best; the ``current`` one unless another beats it by ``hysteresis``."""
    best = int(np.argmax(scores))
    if best != current and scores[best] < scores[current] + hysteresis:
        return current
    return best


def _frame_stats(Iw: FloatArray, w: FloatArray) -> tuple[float, FloatArray, float]:
    """The sum of the weights ``w``, and the frame's samples ``Iw`` less their weighted mean with their weighted
    sum of squares (what :func:`_noise_free_ncc` needs of the frame, the same for every copy)."""
    sw = float(w.sum())
    if sw <= 1e-9:
        return sw, Iw, 0.0
    mi = float((w * Iw).sum() / sw)
    di = Iw - mi
    vi = float((w * di * di).sum())
    return sw, di, vi


_Samples = tuple[FloatArray, tuple[float, FloatArray, float], bool]
"""A frame blur's samples at the template's weighted pixels: the weights in the frame, :func:`_frame_stats` of the
samples under them, and whether every sample lies in the frame."""


def _blur_samples(t: TipTracker, patches: dict[float, Patch], image: FloatArray, x: float, y: float, theta: float
                  ) -> dict[float, _Samples]:
    """For each frame blur of ``t``'s levels, the frame sampled at the widest mask's pixels for a tip at ``(x, y)``
    turned by ``theta`` (:func:`~.refine.warped`'s values, bit for bit), as :meth:`TipTracker._levels` reads them.

    The patches of one place and size (the blurs' patches made around one fit: the same corner, the same shape)
    share the points' cells, fractions and in-frame flags and the weights in the frame; only the values gathered
    differ, so each is worked out once.
    """
    out: dict[float, _Samples] = {}
    cells: dict[tuple[int, int, int, int], tuple[NDArray[np.intp], FloatArray, FloatArray, FloatArray, bool]] = {}
    for _, f, _ in t._spec:
        if f in out:
            continue
        p = t._patch(patches, image, x, y, f, slopes=False)  # (values only)
        _, ch, cw = p.data.shape
        key = (p.x0, p.y0, ch, cw)
        c = cells.get(key)
        if c is None:
            i00, fx, fy, inside = _window_cells(p, t._select, x, y, theta)  # (None: every one in, w * True is w)
            c = cells[key] = (neighbours(i00, ch, cw), fx, fy, t._select.w if inside is None else t._select.w * inside,
                              inside is None or bool(inside.all()))
        at, fx, fy, w, all_in = c
        out[f] = (w, _frame_stats(bilinear(p.data[0].reshape(-1).take(at), fx, fy), w), all_in)
    return out


def _frame_patch(t: TipTracker, patches: dict[float, Patch], image: FloatArray, x: float, y: float, f: float,
                 slopes: bool = True) -> Patch:
    """The frame's patch around ``(x, y)`` smoothed like ``t``'s template plus ``f`` px, made once per frame (kept in
    ``patches``); with its derivatives (the fit's) unless ``slopes`` is false (made then when asked for)."""
    pt = patches.get(f)
    if pt is None:
        s = math.hypot(t.params.template_blur, f)
        pt = patches[f] = patch(image, x, y, t.template.half * math.sqrt(2.0) + 12.0, s, slopes)
    elif slopes and not pt.slopes:
        pt = patches[f] = with_slopes(pt)
    return pt


def _copy_terms(b: FloatArray, w: FloatArray, sw: float) -> tuple[FloatArray, float]:
    """Copy ``b``'s part of :func:`_noise_free_ncc` under the weights ``w`` (their sum ``sw``): ``w`` times ``b``
    less its weighted mean, and its weighted sum of squares (made once for the samples all in the frame)."""
    wdt = b - float((w * b).sum() / sw)
    vt = float((wdt * w * wdt).sum())  # (w * dt * dt).sum(): the products commute, their order is kept
    wdt *= w
    return wdt, vt


def _noise_free_ncc(b: FloatArray, frame: tuple[float, FloatArray, float], w: FloatArray, n_t2: float,
                    n_f2: float, terms: tuple[FloatArray, float] | None = None) -> float:
    """The weighted correlation of copy ``b`` with the frame's samples (:func:`_frame_stats` of them and the
    weights ``w``), divided by what the copy's and the frame's own noise (variances ``n_t2``, ``n_f2`` a
    sample) cost it. ``terms``: :func:`_copy_terms` of ``b`` and ``w``, when the caller has them."""
    sw, di, vi = frame
    wdt, vt = _copy_terms(b, w, sw) if terms is None else terms
    den = math.sqrt(vi * vt)
    ncc = float((wdt * di).sum()) / den if den > 0 else 0.0
    keep_t = 1.0 - n_t2 * sw / vt if vt > 0 else 1.0
    keep_f = 1.0 - n_f2 * sw / vi if vi > 0 else 1.0
    return ncc / math.sqrt(max(keep_t, 0.25) * max(keep_f, 0.25))


def _learn_shaft(image: FloatArray, tip: Sequence[float], t: TipTemplate, params: TrackerParams,
                 spec: Sequence[tuple[int, float, float]]
                 ) -> tuple[ShaftProfiles, WidthStations | None, OutlineStations | None]:
    """The first frame's shaft behind ``tip`` (:func:`.shaft.learn_shaft`), its edges there
    (:func:`.width.learn_width`) and its outline's, every 2 px (:func:`.width.learn_outline`), smoothed as each
    blur copy is."""
    s0 = params.template_blur
    smooth = [(math.hypot(s0, params.blur_bank[k]), math.hypot(s0, f)) for k, f, _ in spec]
    at = (float(tip[0]), float(tip[1]))
    g = (t.ground[0], t.ground[1], params.contrast)
    return (learn_shaft(image, at, t.shaft, *g, smooth),
            learn_width(image, at, t.shaft, *g, t.noise, smooth, params.width_shift, params.width_slack,
                        params.extent_depth),
            learn_outline(image, at, t.shaft, *g, smooth, params.width_shift))


def _edge_refusal(ec: EdgeCheck | None, p: TrackerParams, sc: ShaftCheck | None = None) -> Lost | None:
    """The edge stage's refusal of a fix whose edges (and shaft) were checked (``None``: they hold, or were not
    checked)."""
    if sc is not None and (sc.back < p.edge_contrast or sc.shape < p.edge_shape):
        return Lost("lost", f"the needle's shaft {sc.reach:.0f} px behind the tip is not where the first frame "
                            f"had it (contrast {sc.back:.2f}, profiles correlate by {sc.shape:.2f}; needs "
                            f"{p.edge_contrast:g}, {p.edge_shape:g})")
    if sc is not None and abs(sc.along) > p.along_limit + p.along_sigmas * sc.along_sd:
        return Lost("occluded", f"the needle's taper puts its end {abs(sc.along):.1f} px "
                                f"{'behind' if sc.along < 0 else 'ahead of'} the fit's tip (+-{sc.along_sd:.1f} px)")
    if ec is None:
        return None
    if ec.far < p.edge_contrast:
        return Lost("lost", f"the needle's edges behind the tip have {ec.far:.2f} of the template's contrast "
                            f"(needs {p.edge_contrast:g})")
    if ec.shape < p.edge_shape:
        return Lost("lost", f"the needle's edges behind the tip are not where the template's are (profiles "
                            f"correlate by {ec.shape:.2f}, needs {p.edge_shape:g})")
    if ec.near < p.edge_near * ec.far:
        return Lost("occluded", f"the needle's edges fade right behind the tip ({ec.near:.2f} of their "
                                f"contrast further back, needs {p.edge_near:g})")
    return None


def _width_of(ws: WidthStations | None, p: TrackerParams, cand: _Candidate,
              image: FloatArray, found_sigma: float | None = None) -> tuple[WidthCheck | None, bool]:
    """The needle's width behind a candidate (:func:`.width.check_width`), and whether, unchecked, it is to be
    refused: the first frame showed the stations and fewer than ``p.width_stations`` lie in the frame behind a
    fit near the last fix. A tip found again (its standard deviation ``found_sigma``, px) has passed the
    stricter rules for one (its correlation, its mismatch against the recent fixes'): they vouch for it
    instead when its standard deviation is at most ``p.unvouched_sigma`` (docs/vision.md, "Decision rules")."""
    vouched = found_sigma is not None and found_sigma <= p.unvouched_sigma
    if ws is None:
        # the first frame showed fewer than width_stations: nothing behind the tip can be checked
        return None, p.vouch_unlearnt and not p.trust_unchecked and not vouched
    r = cand.ref
    wc = check_width(ws, cand.level, image, r.x, r.y, r.theta, p.along_limit, p.along_sigmas, p.width_stations)
    return wc, wc is None and not p.trust_unchecked and not vouched


def _vouched_as_found(t: TipTracker, r: Refinement, sigma: float) -> bool:
    """Whether a fit near the last fix (its standard deviation ``sigma``, px) passes the rules a tip found again by
    the whole frame's search must pass where no width station vouches for it: a correlation of
    ``reacquire_score``, a mismatch at most ``reacquire_ratio`` times the recent fixes' median plus the floor, and
    ``sigma`` at most ``unvouched_sigma`` (docs/vision.md, "Decision rules")."""
    p = t.params
    return sigma <= p.unvouched_sigma and r.score >= p.reacquire_score and (
        1.0 - r.score <= t._mismatch_limit(p.reacquire_ratio))


def _outline_vouches(t: TipTracker, cand: _Candidate, image: FloatArray) -> bool:
    """Whether the needle's outline vouches for a fit behind which too few width stations lie in the frame: read on
    each edge alone (:func:`.width.check_outline`) as far as ``outline_reach`` px behind it, no edge moves inward
    going back, nor lies from the first frame's (its median), by ``outline_slack`` px or more (docs/vision.md,
    "Decision rules"). A sideways offset of the fit moves an edge alike at every station; a bead's far rim taken
    for the tip has the outline close behind it (the needle narrower, its own tip further back) or stand out."""
    p, r = t.params, cand.ref
    if t._outline is None or not math.isfinite(p.outline_reach):
        return False
    reach, closing, offset = check_outline(t._outline, t._spec[cand.level][0], image, r.x, r.y, r.theta)
    return reach >= p.outline_reach and closing < p.outline_slack and offset < p.outline_slack


def _vouched(t: TipTracker, cand: _Candidate, image: FloatArray, sigma: float) -> bool:
    """Whether a fit behind which too few width stations lie in the frame (its standard deviation ``sigma``, px) is
    vouched for all the same: by the rules for a tip found again (:func:`_vouched_as_found`), else by its outline
    (:func:`_outline_vouches`, read only then)."""
    return _vouched_as_found(t, cand.ref, sigma) or _outline_vouches(t, cand, image)


def _not_found(refused: tuple[float, Lost] | None) -> Lost:
    """The refusal of a frame with nothing near the last fix and no fix in the whole frame: what refused the
    frame's best-correlating candidate (``refused``: its correlation and refusal), or that there was none."""
    if refused is None:
        return Lost("lost", "not found near the last fix nor anywhere in the frame")
    return Lost("lost", f"not found near the last fix; in the frame, the best candidate was refused "
                        f"({refused[1].reason}): {refused[1].detail}")


def _width_refusal(wc: WidthCheck | None, unvouched: bool = False, least: int = 3,
                   slack: float = math.inf, narrow: float = math.inf, near_wide: float = math.inf) -> Lost | None:
    """The refusal of a fix behind which the needle is not as wide as the first frame showed it
    (:mod:`.width`; ``None``: it is, or was not checked): most stations' widths differ, or at one
    station the needle's extent across the shaft is narrower by more than ``slack`` px beyond what
    the along-axis limit changes it by (:attr:`~.width.WidthCheck.short`), or the two stations nearest the tip are
    both wider than they allow by more than ``near_wide`` px (:attr:`~.width.WidthCheck.near_wide`); with
    ``unvouched``, of a
    fix behind which fewer than ``least`` of the stations the first frame showed lie in the frame."""
    if wc is None and unvouched:
        return Lost("lost", f"fewer than {least} of the needle's width stations behind the fit's tip lie in the "
                            f"field (or the first frame showed fewer): nothing vouches that the end seen is the tip")
    if wc is None:
        return None
    if wc.excess > 0.0:
        return Lost("occluded", f"the needle behind the fit's tip is not as wide as the first frame showed it at "
                                f"{wc.disagree} of {wc.n} stations (up to {max(abs(d) for d in wc.dw):.1f} px off): "
                                f"the end of something over the tip")
    if wc.near_wide > near_wide:
        return Lost("occluded", f"the needle {wc.s[0]:.0f} and {wc.s[1]:.0f} px behind the fit's tip is wider than the "
                                f"first frame's by {wc.near_wide:.1f} px more than the stations allow (at most "
                                f"{near_wide:g}): something over the tip, the stations further back outvoting them")
    j, by = wc.narrow
    if by > narrow:
        return Lost("occluded", f"the needle's registered width {wc.s[j]:.0f} px behind the fit's tip is narrower "
                                f"than the first frame's by {by:.1f} px more than the station allows (at most "
                                f"{narrow:g}): the far end of something over the tip, the needle's own end further "
                                f"back")
    k = int(np.argmax(wc.short)) if wc.short else -1
    if k < 0 or not wc.short[k] > slack:
        return None
    return Lost("occluded", f"the needle {wc.s[k]:.0f} px behind the fit's tip is narrower than the first frame showed "
                            f"it by {wc.short[k]:.1f} px more than its taper allows (at most {slack:g}): the far end "
                            f"of something over the tip, the needle's own end further back")


class TipTracker:
    """Tracks one tip through a sequence of frames (see the module docstring).

    Parameters
    ----------
    first : ndarray or Frame
        The first frame.
    tip : tuple of float
        The tip in it, px ``(x, y)``.
    params : TrackerParams
        The tracker's constants.

    Raises
    ------
    TemplateError
        When nothing that can be tracked stands at ``tip``.
    ImageError
        When ``first`` is no image (:func:`~.frame.as_image`: not 2-D, too small, a pixel NaN, infinite or
        beyond :data:`~.frame.MAX_VALUE`). Later frames given as arrays are taken as they are: a
        :class:`~.frame.Frame` (made by :func:`~.frame.as_image`) is checked.
    """

    # the fit's parts of the template, made by _fit_parts (again when the template is averaged)
    _steep: list[Steepest]
    _select: Steepest
    _bank_sel: list[FloatArray]
    _bank_terms: list[tuple[FloatArray, float]]
    _coarse: list[FloatArray]
    _bank_noise2: list[float]
    _spec_noise2: list[float]

    def __init__(self, first: FloatArray | Frame, tip: tuple[float, float], params: TrackerParams = TrackerParams()):
        # an array is checked as a file's pixels are (2-D, finite, in range), its values kept as they are
        image = first.image if isinstance(first, Frame) else as_image(np.asarray(first, dtype=float), "the first frame")
        self.params = params
        self.template = TipTemplate.learn(image, tip, params)
        self.shape = (int(image.shape[0]), int(image.shape[1]))
        t = self.template
        # levels: (template copy, the frame's extra blur px, the signed blur px): the blurred copies for a tip out of
        # focus, then the sharp template against a blurred frame for a tip sharper than in the first frame
        nb = len(params.blur_bank)
        self._spec = [(k, 0.0, b) for k, b in enumerate(params.blur_bank)] + [(0, f, -f) for f in params.sharpen_bank]
        self._top = nb - 1  # the most blurred copy: a tip that needs it is out of focus
        self._fft: dict[object, object] = {}  # the template's transforms, by region size
        _fit_parts(self, 1.0)
        self._coarse_w = _downsample(t.weights, params.coarse_factor)
        self._edges = learn_edges(t.bank, t.apex, t.mask, t.shaft)
        self._shaft, self._width, self._outline = _learn_shaft(image, tip, t, params, self._spec)
        self._needle = needle_for(image, tip, t.mask, t.apex, t.shaft, params, t.noise)
        self._last_view: _View | None = None  # the last fix's pixels, its blur re-read from them (_focus_reread)
        self._last: tuple[float, float] | None = (float(tip[0]), float(tip[1]))
        self._theta = 0.0
        self._level = 0
        self._fresh = True  # the last frame gave a fix
        self._since = 1  # frames since the last fix (1: the last frame gave one)
        self._mismatch: list[float] = []  # 1 - score of the recent fixes
        self._mask_check: _Awaiting | Confirmation | None = _pending(tip, image, params)  # confirm.py's stage
        self._average = TemplateAverage(image, tip, t, params.average_frames) if params.average_frames else None
        s0 = params.template_blur
        # what noise alone costs a perfect match, until fixes say better: the frame's and the template's noise
        # over the needle's contrast (both smoothed by s0)
        n2 = 2.0 * t.noise**2 / (4.0 * math.pi * s0 * s0)
        self._first_mismatch = min(0.5, 1.0 - 1.0 / math.sqrt(1.0 + n2 / max(t.contrast**2, 1e-300)))

    # ------------------------------------------------------------------ helpers

    def _levels(self, patches: dict[float, Patch], image: FloatArray, x: float, y: float, theta: float) -> list[float]:
        """Weighted correlation of each level with the frame, at the widest mask's pixels, for a tip at ``(x, y)``.

        Each correlation is divided by what the template's and the frame's own noise cost it
        (``sqrt(1 - noise² / variance)`` each): the smoother copies would otherwise win on noise alone.
        """
        out = []
        # copies of one blur share samples (:func:`_blur_samples`); all in the frame, the copies' terms made at
        # learning (w * True is w)
        seen = _blur_samples(self, patches, image, x, y, theta)
        for (k, f, _), n_t2 in zip(self._spec, self._spec_noise2, strict=True):
            w, stats, all_in = seen[f]
            n_f2 = self.template.noise**2 / (4.0 * math.pi * (self.params.template_blur**2 + f * f))
            out.append(-1.0 if stats[0] <= 1e-9 else _noise_free_ncc(
                self._bank_sel[k], stats, w, n_t2, n_f2, self._bank_terms[k] if all_in else None))
        return out

    def _patch(self, patches: dict[float, Patch], image: FloatArray, x: float, y: float, f: float,
               slopes: bool = True) -> Patch:
        """The frame's patch around ``(x, y)`` smoothed like the template plus ``f`` px (:func:`_frame_patch`)."""
        return _frame_patch(self, patches, image, x, y, f, slopes)

    def _try(self, image: FloatArray, x: float, y: float, theta: float, level: int,
             worth: float = -1.0) -> _Candidate:
        """Refine a tip position found by correlation, and settle the level of blur that matches it.

        The blur copies are compared only when the first fit correlates by ``worth`` or more.
        """
        corr = self.params.sigma_factor
        patches: dict[float, Patch] = {}
        lvl = level
        ref = refine(self._patch(patches, image, x, y, self._spec[lvl][1]), self._steep[lvl], (x, y), theta,
                     correlation=corr)
        usual = self._usual_mismatch()
        # the blur copies are compared only when the fit matches worse than the recent fixes did (focus changed)
        settled = ref.converged and _as_usual(ref.score, usual)
        settled = settled or ref.score < worth
        for _ in range(0 if settled else 2):
            if not (math.isfinite(ref.x) and math.isfinite(ref.y)):
                break
            lvl2 = _pick_level(self._levels(patches, image, ref.x, ref.y, ref.theta), lvl,
                               self.params.level_hysteresis)
            if lvl2 == lvl:
                break
            pt2 = self._patch(patches, image, ref.x, ref.y, self._spec[lvl2][1])
            ref2 = refine(pt2, self._steep[lvl2], (ref.x, ref.y), ref.theta, correlation=corr)
            if not ref2.score >= ref.score - self.params.level_hysteresis or (ref.converged and not ref2.converged):
                break
            ref, lvl = ref2, lvl2
        return _needled(self, image, ref, lvl, patches)

    def _edge_check(self, patches: dict[float, Patch], image: FloatArray, ref: Refinement, level: int
                    ) -> EdgeCheck | None:
        """The needle's edges behind the fitted tip against blur copy ``level``'s (:func:`~.edges.check_edges`)."""
        if not (math.isfinite(ref.x) and math.isfinite(ref.y)):
            return None
        k, f, _ = self._spec[level]
        noise = self.template.noise / (2.0 * math.sqrt(math.pi) * math.hypot(self.params.template_blur, f))
        return check_edges(self._edges, k, self._patch(patches, image, ref.x, ref.y, f), ref.x, ref.y, ref.theta,
                           noise)

    # ------------------------------------------------------------------ search

    def _local(self, image: FloatArray) -> _Candidate | None:
        assert self._last is not None
        p = self.params
        region, x0, y0 = _region(image, self.template.half, self._last[0], self._last[1], p.search_radius)
        t = self.template
        k = self._spec[self._level][0]
        ncc = masked_ncc(region, t.bank[k], t.level_weights[k], self._fft, ("local", k), single=True)
        i, j = np.unravel_index(int(np.argmax(ncc)), ncc.shape)
        if ncc[i, j] < 0.5 * p.min_score:
            return None
        x = x0 + j + t.apex[0]
        y = y0 + i + t.apex[1]
        return self._try(image, x, y, self._theta, self._level)

    def _global(self, image: FloatArray) -> list[_Candidate | None]:
        """Candidates from the whole frame (:func:`_padded`, :func:`_ranked`): the best few peaks of the
        down-sampled correlation, each looked at in full resolution (:func:`_look`) and fitted."""
        p, t = self.params, self.template
        f = p.coarse_factor
        small, inside, pad = _padded(image, f, t.half, self._fft)
        peaks: list[_Peaks] = []
        spectra = region_spectra(small, inside, single=True)  # the same for every copy
        # the last fix's blur copy and its neighbours, and the sharp one (the tip comes back as it left, or as
        # it was learnt)
        for k in sorted({0, *(min(max(self._spec[self._level][0] + d, 0), self._top) for d in (-1, 0, 1))}):
            peaks.append(_ranked(*inside_ncc(small, inside, self._coarse[k], self._coarse_w, self._fft, ("coarse", k),
                                             spectra, p.min_coverage, single=True), k))
        out: list[_Candidate | None] = []
        seen: list[tuple[float, float]] = []
        for _s, i, j, k in _by_rank(peaks):
            if len(out) >= p.candidates:
                break
            x, y = (j - pad) * f + t.apex[0], (i - pad) * f + t.apex[1]
            if any(math.hypot(x - a, y - b) < 2 * f for a, b in seen):
                continue
            seen.append((x, y))
            # a full-resolution look around the coarse peak, then the fit
            ncc, rx0, ry0 = _look(image, t, p, self._fft, x, y, k)
            i2, j2 = (int(v) for v in np.unravel_index(int(np.argmax(ncc)), ncc.shape))
            if ncc[i2, j2] < p.reacquire_ncc:  # too unlike the tip to be found again: not worth a fit
                out.append(None)
                continue
            # a tip found again must correlate by reacquire_score: a fit far below is not worth the copies' comparison
            out.append(self._try(image, rx0 + j2 + t.apex[0], ry0 + i2 + t.apex[1], 0.0, k,
                                 p.reacquire_score - 0.1))
        return out

    # ------------------------------------------------------------------ decision

    def _judge(self, cand: _Candidate, image: FloatArray, reacquire: bool = False) -> tuple[Result, _Candidate]:
        """The decision on a candidate (docs/vision.md, "Decision rules"), and the candidate decided on.

        A candidate that correlates well enough to be taken is checked by the needle's edges
        behind it (:mod:`.edges`); a fix the template's rules take stands only if the edges'
        rules take it too. A refusal by the template's rules stands without them: its edges
        (and shaft) are read only for a fit near the last fix refused as lost or out of focus,
        where :meth:`update` reads them to decide whether to search the whole frame.
        """
        p = self.params
        res = _focus_reread(self, cand, image, reacquire)
        r = cand.ref
        # the edges only for a fit that correlates well enough to be taken (the template's rules refuse the others)
        if r.score < (p.reacquire_score if reacquire else p.min_score) or not r.converged or isinstance(res, Lost) and (
                reacquire or res.reason not in ("lost", "out of focus")):
            return res, cand  # a refusal stands; only update's check of a fit near the last fix reads its edges
        patches: dict[float, Patch] = {self._spec[cand.level][1]: cand.patch}
        ec = self._edge_check(patches, image, cand.ref, cand.level)
        # the shaft further back only where the edges near the tip hold (their refusal stands without it)
        sc = None if ec is None or _edge_refusal(ec, p) else check_shaft(
            self._shaft, cand.level, image, r.x, r.y, r.theta)
        refusal = _edge_refusal(ec, p, sc) if isinstance(res, Fix) else None
        # the needle's width behind a fix every other rule takes; unchecked, a found-again tip's rules vouch (or not)
        wc, unvouched = (None, False) if refusal or not isinstance(res, Fix) else _width_of(
            self._width, p, cand, image, res.sigma if reacquire else None)
        unvouched = unvouched and not (isinstance(res, Fix) and _vouched(self, cand, image, res.sigma))
        refusal = refusal or _width_refusal(wc, unvouched, p.width_stations, p.extent_slack, p.width_narrow,
                                                p.width_near_wide)
        return (refusal or res), replace(cand, edges=ec, shaft=sc, width=wc, unvouched=unvouched)

    def _rules(self, cand: _Candidate, image: FloatArray, reacquire: bool, last: int) -> Result:
        """The template fit's rules: a :class:`Fix` or the first rule's :class:`Lost`; ``last``: the last fix's copy."""
        p = self.params
        r = cand.ref
        H, W = image.shape
        blur = self._spec[cand.level][2]
        min_score = p.reacquire_score if reacquire else p.min_score
        edge = min(r.x, r.y, W - 1 - r.x, H - 1 - r.y)
        margin = p.edge_margin + 2.0 * max(blur, 0.0)
        if not (math.isfinite(r.x) and math.isfinite(r.y)):
            return Lost("lost", "the fit did not converge")
        if edge < margin:
            where = "beyond the edge" if edge < 0 else f"{edge:.1f} px from the edge"
            return Lost("out of the field", f"the tip would be {where} (needs {margin:.1f} px)")
        if r.coverage < p.min_coverage:
            return Lost("out of the field", f"{100 * (1 - r.coverage):.0f} % of the tip's window is outside the field")
        sigma = max(p.sigma_floor, p.sigma_factor * r.sigma)
        if r.outliers > p.occluded_fraction:
            return Lost("occluded", f"{100 * r.outliers:.0f} % of the tip's template disagrees with the frame")
        front = _front_share(self.template, cand, max(blur, 0.0), self._fft)
        if front > p.front_fraction:
            return Lost("occluded", f"{100 * front:.0f} % of the ground in front of the tip looks like the needle")
        if cand.level == self._top or blur > p.max_blur:
            return Lost("out of focus", f"blurred by {blur:g} px or more against the first frame")
        if _top_matches(self, cand, image):
            return Lost("out of focus", f"blurred by {self._spec[self._top][2]:g} px or more against the first frame "
                                        "(that copy matches as well)")
        if r.score < min_score:
            return Lost("lost", f"correlation {r.score:.2f} < {min_score:.2f}")
        limit = self._mismatch_limit(p.reacquire_ratio if reacquire else p.mismatch_ratio)
        if 1.0 - r.score > limit:
            return Lost("lost", f"correlation {r.score:.3f}: worse than this sequence's fixes (needs {1 - limit:.3f})")
        if abs(r.theta) > p.max_turn:
            return Lost("lost", f"the match needs a turn of {math.degrees(r.theta):.1f} deg (at most "
                                f"{math.degrees(p.max_turn):.0f} deg)")
        if not r.converged:
            return Lost("lost", "the fit did not settle")
        max_sigma = p.reacquire_sigma if reacquire else p.max_sigma
        if sigma > max_sigma:
            return Lost("lost", f"position undetermined (sigma {sigma:.2f} px > {max_sigma:g} px)")
        last_blur = self._spec[last][2]
        if abs(blur - last_blur) > p.max_blur_step * math.sqrt(self._since):
            return Lost("lost", f"{FOCUS_STEP} by {blur - last_blur:+g} px in {self._since} "
                                f"frame(s) (at most {p.max_blur_step:g} px a frame)")
        if reacquire and cand.level <= self._top and cand.level > last + 1 and blur > last_blur:
            return Lost("lost", f"found again only blurred by {blur:g} px (the last fix: {last_blur:g} px)")
        return Fix(r.x, r.y, float(min(max(r.score, 0.0), 1.0)), sigma, blur, r.theta)

    def update(self, frame: FloatArray | Frame) -> Result:
        """The tip in the next frame: a :class:`Fix` or a :class:`Lost` with its reason."""
        image = frame.image if isinstance(frame, Frame) else np.asarray(frame, dtype=float)
        if image.shape != self.shape:
            raise ValueError(
                f"a frame of {image.shape[1]} x {image.shape[0]} px after frames of "
                f"{self.shape[1]} x {self.shape[0]} px"
            )
        first_refusal: Lost | None = None
        if self._last is not None:
            cand = self._local(image)
            if cand is not None:
                res, cand = self._judge(cand, image)
                if isinstance(res, Fix):
                    return _take(self, res, cand, image, False)
                first_refusal = res
                if res.reason in ("lost", "out of focus") and cand.edges is not None and not cand.unvouched and (
                        _edge_refusal(cand.edges, self.params, cand.shaft) is None):
                    # the edges are where the fit put its tip, which a rule refused (its position undetermined, its
                    # focus changed too fast; not "nothing vouches": the whole frame's stricter rules decide that)
                    self._fresh = False
                    self._since += 1
                    return res
        # not found near the last fix (or refused there, or refused last time): the whole frame
        best: Result | None = None
        refused: tuple[float, Lost] | None = None  # the best-correlating candidate of the frame a rule refused
        for cand in self._global(image):
            if cand is None:
                continue
            res, cand = self._judge(cand, image, reacquire=True)
            if isinstance(res, Fix):
                if best is None or not isinstance(best, Fix) or res.score > best.score:
                    best = res
                    best_cand = cand
            elif refused is None or cand.ref.score > refused[0]:
                refused = (cand.ref.score, res)
        if isinstance(best, Fix):
            return _take(self, best, best_cand, image, True)
        self._fresh = False
        self._since += 1
        return first_refusal if first_refusal is not None else _not_found(refused)

    def _usual_mismatch(self) -> float | None:
        """The median ``1 - score`` of the recent fixes (``None`` before three)."""
        if len(self._mismatch) < 3:
            return None
        return median(np.array(self._mismatch[-self.params.recent :], dtype=float))  # numpy.median's

    def _mismatch_limit(self, ratio: float) -> float:
        """Largest ``1 - score`` a fix may have: ``ratio`` times the recent fixes' median mismatch, plus the floor
        (before three fixes, the first frame's own: its noise against the template, plus ``first_mismatch_slack``)."""
        usual, p = self._usual_mismatch(), self.params
        return ratio * (self._first_mismatch if usual is None else usual) + (
            p.first_mismatch_slack if usual is None else p.mismatch_floor)

    def _accept(self, fix: Fix, cand: _Candidate, image: FloatArray) -> Fix:
        self._last_view = _View.keep(image, fix.x, fix.y, self.template.half)
        self._mismatch.append(1.0 - fix.score)
        del self._mismatch[: -self.params.recent]
        self._last = (fix.x, fix.y)
        self._theta = cand.ref.theta
        self._level = cand.level
        self._fresh = True
        self._since = 1
        _averaged(self, cand, image)
        return fix


_Awaiting = tuple[tuple[float, float], FloatArray]
"""The first frame's tip (px) and a copy of the frame, kept while the mask awaits its confirmation."""


def _pending(tip: tuple[float, float], image: FloatArray, params: TrackerParams) -> _Awaiting | None:
    """The first frame's tip and a copy of the frame (the vouching models are learnt again on it), while the mask
    awaits the move that confirms it (:mod:`.confirm`); ``None``: the stage is off (``confirm_move`` infinite, or
    the template averaged: it is made again from later frames)."""
    on = math.isfinite(params.confirm_move) and params.average_frames == 0
    return ((float(tip[0]), float(tip[1])), np.array(image, dtype=float)) if on else None


def _take(tr: TipTracker, fix: Fix, cand: _Candidate, image: FloatArray, reacquire: bool) -> Result:
    """Accept ``fix``; the first fix ``confirm_move`` px or more from the first frame's tip first confirms the
    template's mask (:func:`~.confirm.confirm_mask`): where a region stayed with the ground it is dropped, the
    template's weights and the models that vouch for a fix (:func:`_vouchers`, on the first frame) are made again
    from the mask confirmed, and the fix is fitted and judged again with them (its verdict stands, a refusal too).
    Where every region read as ground the mask is kept (:attr:`~.confirm.Confirmation.emptied`)."""
    awaiting, t, p = tr._mask_check, tr.template, tr.params
    if not isinstance(awaiting, tuple) or math.hypot(fix.x - awaiting[0][0], fix.y - awaiting[0][1]) < p.confirm_move:
        return _placed(tr, fix, cand, image)
    first, first_frame = awaiting
    inside = _window(np.zeros(tr.shape), int(round(first[0])), int(round(first[1])), t.half)[1]
    conf = confirm_mask(t.bank[0], t.mask, inside, t.apex, first, image, (fix.x, fix.y, cand.ref.theta),
                        p.template_blur, p.edge_px, p.confirm_margin)
    tr._mask_check = conf
    if conf.dropped == 0:
        return _placed(tr, fix, cand, image)
    t.mask = conf.mask
    t.level_weights = _level_weights(conf.mask, inside, t.apex, p)
    t.weights = t.level_weights[0]
    _fit_parts(tr, 1.0)
    tr._coarse_w = _downsample(t.weights, p.coarse_factor)
    _vouchers(tr, first_frame, first, inside)
    res, refit = tr._judge(tr._try(image, fix.x, fix.y, cand.ref.theta, cand.level), image, reacquire)
    if isinstance(res, Fix):
        return _placed(tr, res, refit, image)
    tr._fresh = False
    tr._since += 1
    return res


def _vouchers(tr: TipTracker, first_frame: FloatArray, first_tip: tuple[float, float],
              inside: NDArray[np.bool_]) -> None:
    """The models that vouch for a fix learnt again from the template's mask, on the first frame as at learning
    (``first_tip`` its tip, px; ``inside`` which of the window's pixels lay in it): the shaft's direction and the
    core, ring and front the occlusion check reads (:func:`~.template._surroundings`), the edges' profiles
    (:func:`.edges.learn_edges`), the shaft's profiles and the width's stations (:func:`_learn_shaft`)."""
    t, p = tr.template, tr.params
    t.shaft, t.core, t.ring, t.front = _surroundings(t.mask, inside, t.apex, p)
    tr._edges = learn_edges(t.bank, t.apex, t.mask, t.shaft)
    tr._shaft, tr._width, tr._outline = _learn_shaft(first_frame, first_tip, t, p, tr._spec)


def _fit_parts(tr: TipTracker, share: float) -> None:
    """The fit's parts of ``tr``'s template (its bank, apex and weights): each level's steepest-descent images (a
    copy blurred by 2 px or more, with the smoothing both get, fitted on every second pixel), the levels' samples
    on the widest mask (where they are compared), the coarse copies for the whole-frame search, and the noise
    variance left in each copy: ``share`` of the first frame's (white noise smoothed by a Gaussian of sigma ``s``
    keeps ``1 / (4 pi s²)`` of its variance)."""
    t, p = tr.template, tr.params
    tr._steep = [steepest(t.bank[k], t.apex, w, thin=math.hypot(p.template_blur, abs(b)) >= p.thin_blur,
                          lap_blur=p.lap_blur)
                 for (k, _, b), w in zip(tr._spec, t.level_weights, strict=True)]
    sel = tr._steep[int(np.argmax([float(w.sum()) for w in t.level_weights]))]
    tr._select = sel
    tr._bank_sel = [b[sel.keep] for b in t.bank]
    tr._bank_terms = [_copy_terms(b, sel.w, float(sel.w.sum())) for b in tr._bank_sel]  # all in the frame
    tr._coarse = [_downsample(b, p.coarse_factor) for b in t.bank]
    tr._fft.clear()
    s0 = p.template_blur
    tr._bank_noise2 = [share * t.noise**2 / (4.0 * math.pi * (s0 * s0 + b * b)) for b in p.blur_bank]
    tr._spec_noise2 = [tr._bank_noise2[k] for k, _, _ in tr._spec]


def _averaged(tr: TipTracker, cand: _Candidate, image: FloatArray) -> None:
    """Give a fix fitted with the sharp copy to the template's average (:mod:`.average`); with the last one in,
    the template made again from the average and its apex anchored on the first frame, or left as it was when
    the anchoring fit does not settle within :attr:`~.template.TrackerParams.anchor_limit`."""
    avg = tr._average
    if avg is None or cand.level != 0:
        return
    win = avg.add(image, cand.ref.x, cand.ref.y, cand.ref.theta)
    if win is None:
        if not avg.open:
            tr._average = None
        return
    tr._average = None
    t, p = tr.template, tr.params
    kept = t.bank
    s0 = p.template_blur
    t.bank = [ndimage.gaussian_filter(win, math.hypot(s0, b), mode="nearest") for b in p.blur_bank]
    share = 1.0 / (avg.count + 1)
    _fit_parts(tr, share)
    first = patch(avg.first, avg.tip[0], avg.tip[1], t.half * math.sqrt(2.0) + 12.0, s0)
    move = anchor(first, tr._steep[0], avg.tip, p.sigma_factor, p.anchor_limit)
    if move is None:
        t.bank = kept
        _fit_parts(tr, 1.0)
        return
    t.apex = (t.apex[0] + move[0], t.apex[1] + move[1])
    _fit_parts(tr, share)


def track(frames: Iterable[FloatArray | Frame], tip: tuple[float, float],
          params: TrackerParams = TrackerParams()) -> Iterator[Result]:
    """The tip in each frame: the first frame's is the tip given (score 1), the others tracked."""
    it = iter(frames)
    try:
        first = next(it)
    except StopIteration:
        return
    tracker = TipTracker(first, tip, params)
    yield Fix(float(tip[0]), float(tip[1]), 1.0, 0.0)
    for f in it:
        yield tracker.update(f)
