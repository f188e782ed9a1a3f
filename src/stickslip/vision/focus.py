"""How blurred the first frame is: the needle's two shaft edges fitted across, an absolute focus reading.

The tracker learns the needle from the first frame, and a first frame out of focus costs
every later fix (docs/vision-log.md, track69/70/72); its blur copies read only the blur
*difference* to the first frame, never the first frame's own. Here the shaft's two long
straight edges say it: across the shaft each edge is a step blurred by the frame's blur,
and over tens of pixels along it the pixel noise averages out.

The pixels of a band of the shaft (``start`` to ``start + length`` px behind the tip, out to
:data:`MARGIN` px beyond each edge) are fitted by least squares with
``a + g s + h u + b (Phi((u - l(s)) / sigma) + Phi((r(s) - u) / sigma) - 1)``, ``s`` along the
shaft and ``u`` across it, ``l`` and ``r`` each edge's place as a quadratic in ``s`` (a
needle's cone, or the paraboloid of an etched end), ``Phi`` the normal distribution
(the fit of track61's ``edgeblur.py``, its first-frame half). :func:`first_frame_focus`
turns its ``sigma²`` into the optics' blur, px.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, optimize, special

from .shaft import station_profiles

FloatArray = NDArray[np.float64]

MARGIN = 8.0
"""px beyond each edge that the band reaches: the blurred step's tail (3 sigma of a 2.7 px blur)."""
STATION_STEP = 3.0
"""px between the first frame's coarse stations (each a profile across the shaft)."""
REACH = 40.0
"""px either side of the axis that the coarse stations look for the edges."""
MOVE = 3.0
"""px an edge's line may move from where it was put in and still be the needle's edge."""

STEP_SE = 5.0
"""Standard errors the needle's step across the edges must stand out by (less: no needle's edge there)."""

__all__ = ["EdgeBlur", "Focus", "first_frame_focus", "learn_edge_blur"]


@dataclass(frozen=True)
class EdgeBlur:
    """The first frame's shaft edges, as fitted.

    Attributes
    ----------
    var : float
        The edges' blur variance in the first frame, px² (the PSF's plus the edge's own).
    se : float
        Its standard error, px².
    contrast : float
        The needle's step (grey units; the sign says darker or brighter than the ground).
    lines : tuple of float
        Each edge's place across the shaft, ``c + m s' + q s'²`` (``s'`` px from the band's
        middle along the shaft), left ``(c, m, q)`` then right, px.
    s0, s1 : float
        The band along the shaft, px behind the tip.
    count : int
        The band's pixels in the first frame.
    """

    var: float
    se: float
    contrast: float
    lines: tuple[float, float, float, float, float, float]
    s0: float
    s1: float
    count: int


@dataclass(frozen=True)
class _Band:
    s: FloatArray  # along the shaft, from the band's middle, px
    u: FloatArray  # across it, px
    v: FloatArray  # the pixels' values


def _band(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float], lines: FloatArray,
          s0: float, s1: float) -> _Band | None:
    """The pixels between ``s0`` and ``s1`` px behind ``tip`` and within :data:`MARGIN` px outside ``lines``."""
    ux, uy = shaft
    nx, ny = -uy, ux
    sm, half = 0.5 * (s0 + s1), 0.5 * (s1 - s0)
    ends = np.array([-half, 0.0, half])
    lo = float(np.min(lines[0] + lines[1] * ends + lines[2] * ends**2)) - MARGIN
    hi = float(np.max(lines[3] + lines[4] * ends + lines[5] * ends**2)) + MARGIN
    if not hi - lo < 4.0 * REACH:
        return None
    xs = [tip[0] + s * ux + u * nx for s in (s0, s1) for u in (lo, hi)]
    ys = [tip[1] + s * uy + u * ny for s in (s0, s1) for u in (lo, hi)]
    h, w = image.shape
    x0, x1 = max(0, int(min(xs)) - 1), min(w, int(max(xs)) + 2)
    y0, y1 = max(0, int(min(ys)) - 1), min(h, int(max(ys)) + 2)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return None
    yy, xx = np.mgrid[y0:y1, x0:x1]
    rx, ry = xx - tip[0], yy - tip[1]
    s = rx * ux + ry * uy - sm
    u = rx * nx + ry * ny
    left = lines[0] + lines[1] * s + lines[2] * s * s
    right = lines[3] + lines[4] * s + lines[5] * s * s
    keep = (np.abs(s) <= half) & (u >= left - MARGIN) & (u <= right + MARGIN)
    return _Band(s[keep].astype(float), u[keep].astype(float), image[yy[keep], xx[keep]].astype(float))


def _model(p: FloatArray, b: _Band) -> tuple[FloatArray, FloatArray]:
    """The band's model and its Jacobian in ``p = (a, g, h, contrast, left c m q, right c m q, log sigma)``."""
    s, u = b.s, b.u
    sig = math.exp(min(max(float(p[10]), -5.0), 5.0))  # (beyond: sigma under 0.01 px or over 150 px, no edge)
    zl = (u - (p[4] + p[5] * s + p[6] * s * s)) / sig
    zr = (p[7] + p[8] * s + p[9] * s * s - u) / sig
    cover = special.ndtr(zl) + special.ndtr(zr) - 1.0
    gl = p[3] * np.exp(-0.5 * zl * zl) / math.sqrt(2.0 * math.pi)
    gr = p[3] * np.exp(-0.5 * zr * zr) / math.sqrt(2.0 * math.pi)
    J = np.empty((s.size, 11))
    J[:, 0], J[:, 1], J[:, 2], J[:, 3] = 1.0, s, u, cover
    J[:, 4] = -gl / sig
    J[:, 5], J[:, 6] = J[:, 4] * s, J[:, 4] * s * s
    J[:, 7] = gr / sig
    J[:, 8], J[:, 9] = J[:, 7] * s, J[:, 7] * s * s
    J[:, 10] = -(gl * zl + gr * zr)
    return p[0] + p[1] * s + p[2] * u + p[3] * cover, J


def _fit(b: _Band, lines: FloatArray, sig0: float) -> tuple[FloatArray, FloatArray] | None:
    """Least squares of the band's model from the edges at ``lines``; the parameters and their covariance."""
    left = lines[0] + lines[1] * b.s + lines[2] * b.s**2
    right = lines[3] + lines[4] * b.s + lines[5] * b.s**2
    inside = (b.u > left + 1.0) & (b.u < right - 1.0)
    outside = (b.u < left - 3.0) | (b.u > right + 3.0)
    if inside.sum() < 5 or outside.sum() < 5:
        return None
    ground = float(b.v[outside].mean())
    p0 = np.concatenate([[ground, 0.0, 0.0, float(b.v[inside].mean()) - ground], lines, [math.log(sig0)]])
    try:
        r = optimize.least_squares(lambda p: _model(p, b)[0] - b.v, p0, jac=lambda p: _model(p, b)[1],
                                   method="lm", x_scale="jac", max_nfev=100)
    except (ValueError, OverflowError, np.linalg.LinAlgError):
        return None
    dof = max(b.v.size - 11, 1)
    s2 = float(r.fun @ r.fun) / dof
    try:
        cov = np.linalg.inv(r.jac.T @ r.jac) * s2
    except np.linalg.LinAlgError:
        return None
    p = np.asarray(r.x, dtype=float)
    if not (np.all(np.isfinite(p)) and p[10] < 5.0 and np.all(np.abs(p[4:10:3] - lines[0:6:3]) <= MOVE)):
        return None
    return p, cov


def _coarse(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float], s0: float,
            s1: float) -> FloatArray | None:
    """Each edge's line ``(c, m, 0)`` from the steepest step either side of the axis at stations along the shaft."""
    ux, uy = shaft
    us = np.arange(-REACH, REACH + 0.25, 0.5)
    sm = 0.5 * (s0 + s1)
    found: dict[int, list[tuple[float, float, float]]] = {-1: [], 1: []}
    for s in np.arange(s0, s1 + 1e-9, STATION_STEP):
        # the profile across the shaft, averaged over the shaft's station lines (its edge clipped, as there)
        prof = station_profiles(image, tip[0] + s * ux, tip[1] + s * uy, -us * uy, us * ux, ux, uy)[0]
        g = np.gradient(ndimage.gaussian_filter1d(prof, 2.0))
        for side in (-1, 1):
            i = int(np.argmax(np.abs(g) * (us * side > 0.5)))
            found[side].append((float(s - sm), float(us[i]), float(g[i])))
    out: list[float] = []
    for side in (-1, 1):
        a = np.array(found[side])
        a = a[np.sign(a[:, 2]) == np.sign(np.median(a[:, 2]))]
        for _ in range(2):  # a line, then again without the stations far off it
            if len(a) < 4:
                return None
            m, c = np.polyfit(a[:, 0], a[:, 1], 1)
            off = np.abs(a[:, 1] - (c + m * a[:, 0]))
            a = a[off < max(2.0, 2.5 * float(np.median(off)))]
        out += [float(c), float(m), 0.0]
    found_lines = np.array(out, dtype=float)
    return found_lines if found_lines[3] - found_lines[0] > 1.0 else None


def learn_edge_blur(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float], start: float,
                    length: float) -> EdgeBlur | None:
    """The first frame's shaft edges ``start`` to ``start + length`` px behind ``tip`` (``shaft``: a unit vector
    from the tip back along the needle); ``None`` where no two edges can be fitted there."""
    s0, s1 = start, start + length
    lines = _coarse(image, tip, shaft, s0, s1)
    band = None if lines is None else _band(image, tip, shaft, lines, s0, s1)
    if lines is None or band is None or band.v.size < 2.0 * MARGIN * length:
        return None
    fit = _fit(band, lines, 2.0)
    if fit is None:
        return None
    p, cov = fit
    v10 = float(cov[10, 10])
    var = math.exp(2.0 * float(p[10]))
    if not (0.05 < var < 100.0 and abs(float(p[3])) > max(STEP_SE * math.sqrt(max(float(cov[3, 3]), 0.0)), 1e-6)):
        return None
    ln = tuple(float(x) for x in p[4:10])
    return EdgeBlur(var, 2.0 * var * math.sqrt(max(v10, 0.0)), float(p[3]), ln,  # type: ignore[arg-type]
                    s0, s1, int(band.v.size))


PIXEL_VAR = 1.0 / 12.0
"""px²: what a pixel's width adds to an edge's blur variance (a 1 px box), taken off the fitted ``sigma²``."""


@dataclass(frozen=True)
class Focus:
    """The first frame's focus as the needle's shaft edges show it.

    Attributes
    ----------
    sigma : float
        The edges' blur, px: the standard deviation of a Gaussian blur that would give them
        (a pixel's own width, :data:`PIXEL_VAR`, taken off); 0 for an edge as sharp as a pixel.
    se : float
        Its standard error from the fit, px.
    edges : EdgeBlur
        The fit itself.
    """

    sigma: float
    se: float
    edges: EdgeBlur


def first_frame_focus(image: FloatArray, tip: tuple[float, float], shaft: tuple[float, float],
                      start: float = 10.0, length: float = 40.0) -> Focus | None:
    """How blurred ``image`` is at the needle, read on its shaft's two edges ``start`` to ``start + length`` px
    behind ``tip`` (px, x right, y down; ``shaft``: a unit vector from the tip back along the needle).

    ``None`` where two edges cannot be fitted there (the shaft leaving the frame, no step across it).
    """
    eb = learn_edge_blur(image, tip, shaft, start, length)
    if eb is None:
        return None
    v = max(eb.var - PIXEL_VAR, 0.0)
    sigma = math.sqrt(v)
    se = eb.se / (2.0 * max(sigma, 0.25))
    return Focus(sigma, se, eb)
