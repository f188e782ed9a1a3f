"""A parametric needle fitted to a frame, its blur free: the tip as the model's geometric end (track79, issue 30).

The template's refinement (:mod:`.refine`) carries the first frame's appearance, its blur
included; where a later frame's blur differs, the fit can settle ahead of or behind the
tip along the axis. This stage carries no pixels of the first frame: it fits a model of
a needle whose blur is one of its parameters, so the tip it reports (the model's
geometric end) does not move with the blur.

The model, in the needle's axes (``s`` along the axis from the end up the shaft, ``n``
across it; px): the needle is the region ``s >= 0``, ``|n| <= w(s)`` with the half-width

    w(s) = a s^p + b s

a power law at the end (``p = 1/2``: a parabolic end of radius ``a²/2``; ``p = 1``: a
pointed one; ``p < 1/2``: a blunt one, as a spherical cap on a cone looks over its first
pixels) plus a linear taper (a cone's sides far back). Three free terms fit a rounded
cone, an etched paraboloid and a cylinder with a round end without a form chosen for any
of them; they are learnt on the first frame and held. The needle is uniform across (a
term ``(n/w)²`` for a rim was tried: on a uniform synthetic needle it traded with the
half-width, the shape went to its bound and the end moved 0.3 px between blurs), of
contrast ``c0`` of either sign (bright or dark needle), on a background plane
``g0 + gx x + gy y``, the whole blurred by a Gaussian of ``σ`` px. The Gaussian is
separable in the needle's axes, so the blurred needle is exactly

    M(s, n) = ∫_0^∞ g_σ(s - s') [Φ((n + w(s'))/σ) - Φ((n - w(s'))/σ)] ds'

(error functions across, a midpoint sum of step :data:`STEP` along). For a held shape
``M`` is tabulated on a grid of ``(s, |n|)`` at each ``σ`` of a grid of step
:data:`SIGMA_STEP` (built when first needed) and read bilinearly, linear in ``σ``
between grid values.

Later frames fit the end ``(tx, ty)``, the axis angle ``φ``, ``σ``, the contrast and the
background plane by Gauss-Newton from the template's fix, the residuals weighed by
Tukey's biweight from the second iteration (a grain over the needle) as :mod:`.refine`
does. The end's covariance is ``s² (Jᵀ W J)⁻¹`` over ``(tx, ty)``. The tracker reports
the tip at the first frame's offset from the model's end, in the needle's axes
(:attr:`NeedleModel.anchor`): the tip the user gave against the end the first frame's fit
found, a constant that no later blur changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.special import ndtr

from .template import TrackerParams

__all__ = ["NeedleShape", "NeedleFit", "NeedleModel", "learn_needle", "fit_needle", "render_needle", "start_shape",
           "tip_of", "needle_for", "refit"]

FloatArray = NDArray[np.float64]

STEP = 0.25
"""The tables' grid and the midpoint sum's step along the axis, px."""
SIGMA_STEP = 0.1
"""The blur grid's step, px (a table each; linear between)."""
SIGMA_RANGE = (0.3, 6.0)
"""The blur the fit may take, px: below 0.3 px the pixel's own size dominates; above 6 px the tracker's copies
call the tip out of focus."""
TABLES = 64
"""Tables kept per model (each about 1 MB at ``needle_half`` 20), the oldest dropped first."""
TUKEY = 4.685
"""Tukey's biweight constant, robust spreads (as :mod:`.refine`)."""
_LIN = 6
"""The linear terms: the needle's contrast plane (3) and the background plane (3)."""
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


@dataclass(frozen=True)
class NeedleShape:
    """The half-width ``w(s) = a s^p + b s`` (px) at ``s`` px behind the end."""

    a: float
    p: float
    b: float

    def width(self, s: FloatArray) -> FloatArray:
        return np.asarray(self.a * np.power(np.maximum(s, 0.0), self.p) + self.b * np.maximum(s, 0.0))


@dataclass(frozen=True)
class NeedleFit:
    """A frame's needle: its end ``(x, y)`` px, axis angle ``phi`` rad (from the end up the shaft), blur ``sigma``
    px, contrast ``c0``, the end's covariance ``cov`` px², the share of weight the robust fit set aside, whether it
    converged, and its iterations."""

    x: float
    y: float
    phi: float
    sigma: float
    c0: float
    cov: FloatArray
    outliers: float
    converged: bool
    iterations: int

    @property
    def sd(self) -> float:
        """The largest standard deviation of the end, px."""
        ev = np.linalg.eigvalsh(self.cov)
        return float(math.sqrt(max(float(ev[-1]), 0.0))) if np.all(np.isfinite(ev)) else math.inf


def _profile(shape: NeedleShape, s_grid: FloatArray, n_grid: FloatArray, sigma: float) -> FloatArray:
    """The needle blurred by ``sigma`` on ``s_grid`` x ``n_grid`` (px): exact across, a midpoint sum along."""
    h = STEP
    k = int(math.ceil((max(float(s_grid[-1]), 0.0) + 5.0 * sigma) / h)) + 1
    sk = (np.arange(k, dtype=float) + 0.5) * h  # midpoint nodes along the axis from the end
    w = np.maximum(shape.width(sk), 1e-6)[:, None]
    n = n_grid[None, :]
    across = ndtr((w - n) / sigma) - ndtr((-w - n) / sigma)
    d = (s_grid[:, None] - sk[None, :]) / sigma
    g = np.exp(-0.5 * d * d) * (h * _INV_SQRT_2PI / sigma)
    return np.asarray(g @ across)


@dataclass
class NeedleModel:
    """A learnt shape, the tip's offset from its end, and its tables by blur grid index (built when first read).

    ``anchor`` is the tip the first frame gave, less the model's end there, along the axis and across it (px).
    """

    shape: NeedleShape
    reach: float
    anchor: tuple[float, float] = (0.0, 0.0)
    s_grid: FloatArray = field(init=False)
    n_grid: FloatArray = field(init=False)
    raw: dict[int, FloatArray] = field(init=False, default_factory=dict)
    tables: dict[int, FloatArray] = field(init=False, default_factory=dict)
    phi: float = 0.0
    sigma: float = 1.0
    c0: float = 1.0

    def __post_init__(self) -> None:
        m = int(math.ceil(self.reach / STEP))
        self.s_grid = np.arange(-m, m + 1, dtype=float) * STEP
        self.n_grid = np.arange(0, m + 1, dtype=float) * STEP

    def _raw(self, k: int) -> FloatArray:
        t = self.raw.get(k)
        if t is None:
            t = _profile(self.shape, self.s_grid, self.n_grid, k * SIGMA_STEP)
            _keep(self.raw, k, t)
        return t

    def table(self, k: int) -> FloatArray:
        """Blur grid value ``k``'s table ``(len(s) * len(n), 4)``: the needle, its slopes along ``s`` and ``|n|``
        (per px) and towards grid value ``k + 1`` (per px of blur)."""
        t = self.tables.get(k)
        if t is None:
            m0, m1 = self._raw(k), self._raw(k + 1)
            ts = np.gradient(m0, STEP, axis=0)
            tn = np.empty_like(m0)
            tn[:, 1:-1] = (m0[:, 2:] - m0[:, :-2]) / (2.0 * STEP)
            tn[:, 0] = 0.0  # the needle is symmetric about its axis
            tn[:, -1] = (m0[:, -1] - m0[:, -2]) / STEP
            t = np.ascontiguousarray(np.stack([m0, ts, tn, (m1 - m0) / SIGMA_STEP], axis=-1).reshape(-1, 4))
            _keep(self.tables, k, t)
        return t

    def sample(self, s: FloatArray, n: FloatArray, sigma: float) -> FloatArray:
        """At points ``(s, n)`` (px) and blur ``sigma``: the needle and its slopes along ``s``, ``n`` and ``σ``,
        ``(4, m)``."""
        x = sigma / SIGMA_STEP
        k = int(math.floor(x))
        v = _bilinear(self.table(k), len(self.s_grid), len(self.n_grid), float(self.s_grid[0]), s, n)
        v[0] += (x - k) * SIGMA_STEP * v[3]
        return v


def _keep(cache: dict[int, FloatArray], k: int, t: FloatArray) -> None:
    """Keep table ``t`` as ``k``, the oldest dropped beyond :data:`TABLES` (a table is about 1 MB)."""
    if len(cache) >= TABLES:
        del cache[next(iter(cache))]
    cache[k] = t


def _bilinear(t: FloatArray, ns: int, nn: int, s0: float, s: FloatArray, n: FloatArray) -> FloatArray:
    """Flat table ``t`` (``ns`` x ``nn`` cells of 4 values, rows from ``s0`` px) read bilinearly at ``(s, |n|)``,
    clipped to its grid; the ``n`` slope signed as ``n``; ``(4, m)``."""
    i = np.clip((s - s0) * (1.0 / STEP), 0.0, ns - 1.000001)
    j = np.clip(np.abs(n) * (1.0 / STEP), 0.0, nn - 1.000001)
    i0, j0 = i.astype(np.intp), j.astype(np.intp)
    fi, fj = (i - i0)[:, None], (j - j0)[:, None]
    idx = i0 * nn + j0
    lo = t[idx] + (t[idx + 1] - t[idx]) * fj
    hi = t[idx + nn] + (t[idx + nn + 1] - t[idx + nn]) * fj
    v: FloatArray = np.ascontiguousarray((lo + (hi - lo) * fi).T)
    v[2] *= np.where(n < 0, -1.0, 1.0)
    return v


def _pixels(image: FloatArray, x: float, y: float, half: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The pixels within ``half`` px of ``(x, y)`` in the frame: x, y and value of each."""
    H, W = image.shape
    cx, cy = int(round(x)), int(round(y))
    x0, x1, y0, y1 = max(cx - half, 0), min(cx + half + 1, W), max(cy - half, 0), min(cy + half + 1, H)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    keep = ((xx - x) ** 2 + (yy - y) ** 2 <= half * half).ravel()
    return (xx.ravel()[keep].astype(float), yy.ravel()[keep].astype(float),
            np.asarray(image[y0:y1, x0:x1], dtype=float).ravel()[keep])


def _axes(px: FloatArray, py: FloatArray, tx: float, ty: float, phi: float) -> tuple[FloatArray, FloatArray]:
    """Points' ``(s, n)`` in the needle's axes from the end ``(tx, ty)`` at angle ``phi`` (px)."""
    u, v = math.cos(phi), math.sin(phi)
    dx, dy = px - tx, py - ty
    return dx * u + dy * v, -dx * v + dy * u


def render_needle(shape: NeedleShape, xx: FloatArray, yy: FloatArray, tip: tuple[float, float], phi: float,
                  sigma: float) -> FloatArray:
    """The model's needle of contrast 1 (no background) at points ``(xx, yy)`` px."""
    s, n = _axes(np.ravel(xx), np.ravel(yy), tip[0], tip[1], phi)
    reach = float(np.max(np.abs(np.concatenate([s, n])))) + 1.0
    m = NeedleModel(shape, reach)
    t = _profile(shape, m.s_grid, m.n_grid, sigma)
    flat = np.repeat(t.reshape(-1, 1), 4, axis=1)
    return np.asarray(_bilinear(flat, len(m.s_grid), len(m.n_grid), float(m.s_grid[0]), s, n)[0]
                      ).reshape(np.shape(xx))


def _columns(m: NeedleModel, px: FloatArray, py: FloatArray, q: FloatArray, gain: FloatArray,
             plane: tuple[FloatArray, FloatArray]) -> FloatArray:
    """The design ``(10, m)``: the linear columns (the needle times a contrast plane: c0, cx, cy; the background
    plane: g0, gx, gy), then d/dtx, d/dty, d/dphi, d/dsigma at the contrast ``gain`` (``(c0, cx, cy)``)."""
    tx, ty, phi, sigma = (float(v) for v in q)
    u, v = math.cos(phi), math.sin(phi)
    s, n = _axes(px, py, tx, ty, phi)
    t = m.sample(s, n, sigma)
    g = gain[0] + gain[1] * plane[0] + gain[2] * plane[1]  # the contrast at each pixel
    ms, mn = g * t[1], g * t[2]  # the model's slopes along and across
    # ds/dtx = -u, ds/dty = -v, dn/dtx = v, dn/dty = -u, ds/dphi = n, dn/dphi = -s
    return np.stack([t[0], t[0] * plane[0], t[0] * plane[1], np.ones_like(px), plane[0], plane[1],
                     -u * ms + v * mn, -v * ms - u * mn, n * ms - s * mn, g * t[3]])


def _tukey(e: FloatArray) -> FloatArray:
    """Tukey's biweights of residuals ``e`` (their robust spread: 1.4826 times the median absolute residual)."""
    scale = 1.4826 * float(np.median(np.abs(e))) if e.size else 0.0
    if scale <= 0.0:
        return np.ones_like(e)
    r = e / (TUKEY * scale)
    return np.where(np.abs(r) < 1.0, (1.0 - r * r) ** 2, 0.0)


def _step(A: FloatArray, w: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """The weighted least squares of ``y ≈ Aᵀ x`` (``A`` by rows), and ``(Aᵀ W A)⁻¹``; ``None``: singular."""
    Aw = A * w
    M = Aw @ A.T
    d = np.sqrt(np.maximum(np.diag(M), 1e-300))
    try:
        inv = np.linalg.inv(M / np.outer(d, d) + 1e-9 * np.eye(len(d))) / np.outer(d, d)
    except np.linalg.LinAlgError:
        return None
    x = inv @ (Aw @ y)
    return (x, inv) if np.all(np.isfinite(x)) else None


def fit_needle(m: NeedleModel, image: FloatArray, start: tuple[float, float], phi: float, sigma: float,
               half: int, max_iter: int = 12, tol: float = 0.01) -> NeedleFit | None:
    """Fit the held shape ``m`` to ``image`` from the end ``start`` (px), axis ``phi`` (rad) and blur ``sigma``
    (px) over the pixels within ``half`` px; ``None`` when the fit has no solution. Each step solves the linear
    terms and the motion together (apart, the background would soak up part of each edge's shift)."""
    px, py, val = _pixels(image, start[0], start[1], half)
    plane = ((px - start[0]) / max(half, 1), (py - start[1]) / max(half, 1))
    q = np.array([start[0], start[1], phi, min(max(sigma, SIGMA_RANGE[0]), SIGMA_RANGE[1] - SIGMA_STEP)])
    first = _step(_columns(m, px, py, q, np.array([1.0, 0.0, 0.0]), plane)[:_LIN], np.ones_like(val), val)
    if first is None:  # (the contrast and background at the start)
        return None
    gain, robust = first[0][:3], np.ones_like(val)
    converged, it = False, 0
    for it in range(1, max_iter + 1):
        A = _columns(m, px, py, q, gain, plane)
        sol = _step(A, robust, val)
        if sol is None:
            return None
        x = sol[0]
        gain = x[:3]
        dq = np.array(x[_LIN:])
        dq[:2] = np.clip(dq[:2], -2.0, 2.0)
        dq[2] = float(np.clip(dq[2], -0.1, 0.1))
        dq[3] = float(np.clip(dq[3], -0.5, 0.5))
        q = q + dq
        q[3] = min(max(q[3], SIGMA_RANGE[0]), SIGMA_RANGE[1] - SIGMA_STEP)
        if 1 <= it <= 6:  # then kept: a pixel near the cut would flip in and out
            robust = _tukey(val - x @ A)
        if math.hypot(dq[0], dq[1]) < tol:
            converged = True
            break
    A = _columns(m, px, py, q, gain, plane)
    sol = _step(A, robust, val)
    if sol is None:
        return None
    e = val - sol[0][:_LIN] @ A[:_LIN]
    sw = float(robust.sum())
    s2 = float((robust * e * e).sum()) / max(sw - A.shape[0], 1.0)
    return NeedleFit(float(q[0]), float(q[1]), float(q[2]), float(q[3]), float(gain[0]),
                     s2 * sol[1][_LIN : _LIN + 2, _LIN : _LIN + 2],
                     1.0 - sw / max(val.size, 1), converged, it)


def start_shape(mask: FloatArray | NDArray[np.bool_], apex: tuple[float, float], axis: tuple[float, float],
                grown: float) -> NeedleShape:
    """A starting shape from the first frame's needle mask (grown by ``grown`` px): its half-width 4 and 12 px
    behind the end (px)."""
    yy, xx = np.mgrid[0 : mask.shape[0], 0 : mask.shape[1]]
    s = (xx - apex[0]) * axis[0] + (yy - apex[1]) * axis[1]
    widths = []
    for at in (4.0, 12.0):
        band = (np.abs(s - at) <= 1.5) & (np.asarray(mask, dtype=float) > 0.0)
        widths.append(max(float(band.sum()) / 3.0 / 2.0 - grown, 0.5))
    b = max((widths[1] - widths[0]) / 8.0 * 0.5, 0.0)
    a = max((widths[0] - 4.0 * b) / 2.0, 0.2)
    return NeedleShape(a, 0.5, b)


def learn_needle(image: FloatArray, tip: tuple[float, float], phi: float, half: int, start: NeedleShape,
                 noise: float) -> tuple[NeedleModel, NeedleFit] | None:
    """The first frame's shape, fitted with its end, axis, blur and contrast free (:func:`scipy.optimize.least_squares`
    with a soft L1 loss of scale 3 noise spreads, the linear terms solved inside each evaluation); the model's
    anchor is ``tip`` less the end found. ``None``: no fit."""
    px, py, val = _pixels(image, tip[0], tip[1], half)
    reach = half + 8.0  # the pixels lie within half px of the start, the start within 4 px of the end
    lin = np.stack([np.ones_like(px), (px - tip[0]) / max(half, 1), (py - tip[1]) / max(half, 1)])

    def design(x: FloatArray) -> FloatArray:
        shape = NeedleShape(float(x[4]), float(x[5]), float(x[6]))
        m = NeedleModel(shape, reach)
        t = _profile(shape, m.s_grid, m.n_grid, float(x[3]))
        s, n = _axes(px, py, float(x[0]), float(x[1]), float(x[2]))
        flat = np.repeat(t.reshape(-1, 1), 4, axis=1)
        col = _bilinear(flat, len(m.s_grid), len(m.n_grid), float(m.s_grid[0]), s, n)[0]
        return np.vstack([col[None, :], col * lin[1], col * lin[2], lin])

    def residual(x: FloatArray) -> FloatArray:
        A = design(x)
        return np.asarray(val - np.linalg.lstsq(A.T, val, rcond=None)[0] @ A)

    lo = [tip[0] - 4, tip[1] - 4, phi - 0.3, SIGMA_RANGE[0], 0.05, 0.1, 0.0]
    hi = [tip[0] + 4, tip[1] + 4, phi + 0.3, SIGMA_RANGE[1] - 0.1, 4.0 * half, 1.5, 3.0]
    x0 = np.clip(np.array([tip[0], tip[1], phi, 1.0, start.a, start.p, start.b]), np.array(lo) + 1e-6,
                 np.array(hi) - 1e-6)
    try:
        res = least_squares(residual, x0, bounds=(lo, hi), loss="soft_l1", f_scale=3.0 * max(noise, 1e-12),
                            x_scale=np.array([0.5, 0.5, 0.02, 0.2, 0.5, 0.1, 0.05]), max_nfev=200)
    except (ValueError, np.linalg.LinAlgError):
        return None
    x = res.x
    if not np.all(np.isfinite(x)):
        return None
    c0 = float(np.linalg.lstsq(design(x).T, val, rcond=None)[0][0])
    s, n = _axes(np.array([tip[0]]), np.array([tip[1]]), float(x[0]), float(x[1]), float(x[2]))
    model = NeedleModel(NeedleShape(float(x[4]), float(x[5]), float(x[6])), reach, (float(s[0]), float(n[0])),
                        float(x[2]), float(x[3]), c0)
    fit = NeedleFit(float(x[0]), float(x[1]), float(x[2]), float(x[3]), c0, np.zeros((2, 2)), 0.0,
                    bool(res.success), int(res.nfev))
    return model, fit


def tip_of(m: NeedleModel, x: float, y: float, phi: float, inverse: bool = False) -> tuple[float, float]:
    """The tip an end ``(x, y)`` at angle ``phi`` puts (px): the end plus the model's anchor in its axes;
    ``inverse``: the end a tip puts."""
    u, v = math.cos(phi), math.sin(phi)
    k = -1.0 if inverse else 1.0
    return x + k * (m.anchor[0] * u - m.anchor[1] * v), y + k * (m.anchor[0] * v + m.anchor[1] * u)


def needle_for(image: FloatArray, tip: tuple[float, float], mask: FloatArray | NDArray[np.bool_],
               apex: tuple[float, float], axis: tuple[float, float], params: TrackerParams, noise: float
               ) -> NeedleModel | None:
    """The first frame's needle (:func:`learn_needle`) from the template's mask and shaft, when ``params.needle``
    asks for it and its fit converged with its end within ``needle_move`` px of ``tip``; ``None`` otherwise."""
    if not params.needle:
        return None
    phi = math.atan2(axis[1], axis[0])
    out = learn_needle(image, tip, phi, params.needle_half, start_shape(mask, apex, axis, params.edge_px), noise)
    if out is None or math.hypot(*out[0].anchor) > params.needle_move:
        return None
    return out[0]


def refit(m: NeedleModel, image: FloatArray, x: float, y: float, turn: float, blur: float, params: TrackerParams
          ) -> tuple[float, float, FloatArray] | None:
    """The tip and its covariance (px, px²) from the needle fitted near the template's fix ``(x, y)`` turned by
    ``turn`` (rad) and blurred by ``blur`` px against the first frame (signed: negative sharper); ``None``: the
    fit failed, its contrast reversed, or its tip lies more than ``needle_move`` px from ``(x, y)``."""
    phi = m.phi + turn
    sigma = math.sqrt(max(m.sigma**2 + math.copysign(blur * blur, blur), SIGMA_RANGE[0] ** 2))
    ex, ey = tip_of(m, x, y, phi, inverse=True)
    fit = fit_needle(m, image, (ex, ey), phi, sigma, params.needle_half)
    if fit is None or not fit.converged or fit.c0 * m.c0 <= 0.0 or not math.isfinite(fit.sd):
        return None
    tx, ty = tip_of(m, fit.x, fit.y, fit.phi)
    if params.needle_along:  # only the move along the needle's axis: the template's fix across it is kept
        u, v = math.cos(fit.phi), math.sin(fit.phi)
        along = (tx - x) * u + (ty - y) * v
        tx, ty = x + along * u, y + along * v
    if not math.hypot(tx - x, ty - y) <= params.needle_move:
        return None
    return tx, ty, fit.cov
