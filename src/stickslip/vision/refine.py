"""Sub-pixel refinement of a tip's position: the template fitted to the frame by Gauss-Newton.

The template window ``T`` (one of the blur bank's copies) is fitted to the frame ``I``
under a rigid motion about the tip and a change of brightness and contrast:

    I(R(θ)(x - a) + t) ≈ g(x) T(x) + c(x)        for every window pixel x of weight w(x) > 0

with ``a`` the tip in the window, ``t`` the tip in the frame (px), ``θ`` the turn (rad)
and ``g``, ``c`` the contrast and brightness, each a plane across the window (uneven
illumination: vignetting, a detector that sees one side better, a background whose
level changes across the window). Each iteration samples the (smoothed) frame
and its gradients at the warped window (bilinear), fits ``g`` and ``c`` by weighted
least squares, and updates the motion by inverse composition (Baker and Matthews 2004)
with the mean of the template's and the frame's gradients (the efficient second-order
minimisation of Benhimane and Malis 2004: it converges in a few iterations where the
template's gradients alone, sharper than a blurred frame's, would creep).
From the second iteration to :data:`ROBUST_ITERATIONS` the residuals are weighed by Tukey's biweight (what
disagrees by more than 4.685 robust spreads weighs nothing: a particle over the needle,
the background that moved with the tip).

The fix's covariance is ``s² (Jᵀ W J)⁻¹`` over the motion's parameters (``s²`` the
weighted residual variance), in frame pixels after the turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from .sampling import Patch, _corners, _limits, bilinear, flat_cells, median, neighbours, sample_value_xy

__all__ = ["Refinement", "refine", "Steepest", "steepest", "warped"]

FloatArray = NDArray[np.float64]

TUKEY = 4.685
"""Tukey's biweight constant (95 % efficiency for Gaussian residuals), robust spreads."""

ROBUST_ITERATIONS = 6
"""The robust weights are recomputed up to this iteration, then kept (a pixel near the cut would flip in and out
and keep the fit from settling)."""


@dataclass(frozen=True)
class Steepest:
    """A template's fixed parts for the inverse compositional fit, on its weighted pixels only.

    Attributes
    ----------
    template : ndarray
        The template window (for :func:`warped`), ``(n, n)``.
    apex : tuple of float
        The tip in the window, px.
    t, w, rx, ry : ndarray
        The template's value, weight and offset from the tip (px) at each pixel of weight
        above 0.1 % of the largest.
    sd : ndarray, shape (3, m)
        Steepest-descent images: d/dtx, d/dty, d/dtheta.
    basis : ndarray, shape (m, 6)
        The photometric model's columns: ``T``, ``T x``, ``T y``, ``1``, ``x``, ``y`` (x, y
        across the window, about ±0.5).
    lap : ndarray, shape (m,)
        The template's Laplacian (per px²): the blur term's column (a Gaussian blur of
        variance ``v`` changes the template by ``v/2`` times its Laplacian, the heat equation).
    sd_lap : ndarray, shape (3, m)
        The Laplacian's steepest-descent images (the blur term's part of the model's gradient).
    keep : ndarray of bool, shape (n, n)
        Which window pixels these are.
    density : float
        The share of the weighted pixels kept (1, or 1/2 when every second one is, in a
        chequerboard, for a template blurred enough that its neighbours say the same).
    r, r_perp : ndarray, shape (2, m)
        ``(rx, ry)`` and ``(-ry, rx)`` stacked (px): a turned window's points in three
        operations (:func:`_turned`).
    bx, by : ndarray, shape (m,)
        The basis's x and y columns, contiguous.
    score_terms : tuple
        The template's side of the fit's score (:func:`_score`) over all of its weights:
        the weights' sum, the weighted mean ``t_w``, ``w (t - t_w)`` and ``sum w (t -
        t_w)²``, made once.
    reach : float
        The largest distance of these pixels from the tip, px, with a margin for rounding
        (:func:`_warped3` tells from it that a turned window lies inside its patch).
    """

    template: FloatArray
    apex: tuple[float, float]
    t: FloatArray
    w: FloatArray
    rx: FloatArray
    ry: FloatArray
    sd: FloatArray
    basis: FloatArray
    keep: NDArray[np.bool_]
    lap: FloatArray
    sd_lap: FloatArray
    density: float = 1.0
    r: FloatArray = field(default_factory=lambda: np.zeros((2, 0)))
    r_perp: FloatArray = field(default_factory=lambda: np.zeros((2, 0)))
    bx: FloatArray = field(default_factory=lambda: np.zeros(0))
    by: FloatArray = field(default_factory=lambda: np.zeros(0))
    score_terms: tuple[float, float, FloatArray, float] | None = None
    reach: float = math.inf


def _score_terms(t: FloatArray, w: FloatArray) -> tuple[float, float, FloatArray, float]:
    """:attr:`Steepest.score_terms` for the template's values ``t`` and weights ``w``, as :func:`_score` makes them."""
    sw = float(w.sum())
    if not sw > 1e-9:
        return sw, 0.0, np.zeros_like(t), 0.0
    mt = float((w * t).sum() / sw)
    return sw, mt, w * (t - mt), float((w * (t - mt) ** 2).sum())


def steepest(template: FloatArray, apex: tuple[float, float], weights: FloatArray, thin: bool = False,
             lap_blur: float = 1.0) -> Steepest:
    """The fixed parts of ``template`` (weighed by ``weights``) for a turn about ``apex`` (x, y, window px).

    ``thin`` keeps every second pixel (a chequerboard): for a template blurred by 2 px or
    more, neighbouring pixels carry nearly the same information and the fit costs half.
    ``lap_blur`` (px): the template is smoothed by this Gaussian more before its Laplacian (the blur term's column).
    """
    grads: list[FloatArray] = list(np.gradient(template))
    gy, gx = grads[0], grads[1]
    n = template.shape[0]
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    rx, ry = xx - apex[0], yy - apex[1]
    top = float(np.max(weights)) if weights.size else 0.0
    keep: NDArray[np.bool_] = weights > 1e-3 * top if top > 0 else weights > 0
    density = 1.0
    if thin:
        full = int(keep.sum())
        keep = keep & ((yy + xx).astype(int) % 2 == 0)
        density = int(keep.sum()) / max(full, 1)
    T = template[keep]
    rxm, rym = rx[keep], ry[keep]
    sd = np.stack([gx[keep], gy[keep], -gx[keep] * rym + gy[keep] * rxm])
    bx, by = rxm / n, rym / n
    basis = np.stack([T, T * bx, T * by, np.ones_like(T), bx, by], axis=1)
    # the Laplacian of the template smoothed by lap_blur more: of the template itself it would be mostly its noise
    lap_full = ndimage.gaussian_laplace(template, lap_blur, mode="nearest")
    ly, lx = np.gradient(lap_full)
    sd_lap = np.stack([lx[keep], ly[keep], -lx[keep] * rym + ly[keep] * rxm])
    reach = float(np.sqrt((rxm * rxm + rym * rym).max())) + 1e-6 if T.size else 0.0
    return Steepest(template, apex, T, weights[keep], rxm, rym, sd, basis, keep, lap_full[keep], sd_lap, density,
                    np.stack([rxm, rym]), np.stack([-rym, rxm]), bx.copy(), by.copy(), _score_terms(T, weights[keep]),
                    reach)


@dataclass(frozen=True)
class Refinement:
    """The fitted motion of the tip.

    Attributes
    ----------
    x, y : float
        The tip in the frame, px.
    theta : float
        The window's turn, rad.
    gain, offset : float
        Contrast and brightness of the frame against the template (grey units).
    cov : ndarray, shape (2, 2)
        Covariance of ``(x, y)``, px².
    score : float
        Weighted correlation of the warped frame with the template over the template's
        weights (not the robust ones), 1.
    outliers : float
        Share of the template's weight that the robust fit set aside, 1.
    coverage : float
        Share of the template's weight that fell inside the frame, 1.
    iterations : int
    converged : bool
    dvar : float
        Blur variance of the frame beyond the template's, px² (the blur term's coefficient,
        twice; negative: sharper than the template).
    """

    x: float
    y: float
    theta: float
    gain: float
    offset: float
    cov: FloatArray
    score: float
    outliers: float
    coverage: float
    iterations: int
    converged: bool
    dvar: float = 0.0

    @property
    def sigma(self) -> float:
        """The largest standard deviation of the position, px (along the worst direction)."""
        ev = np.linalg.eigvalsh(self.cov)
        return float(math.sqrt(max(float(ev[-1]), 0.0))) if np.all(np.isfinite(ev)) else math.inf


def _turned(st: Steepest, x: float, y: float, theta: float) -> FloatArray:
    """The template's weighted pixels in the frame (shape (2, m), px), the tip at ``(x, y)`` turned by ``theta``:
    ``cos(theta) rx - sin(theta) ry + x`` and ``sin(theta) rx + cos(theta) ry + y``, bit for bit."""
    xy = st.r * math.cos(theta)
    xy += st.r_perp * math.sin(theta)
    xy[0] += x
    xy[1] += y
    return xy


def warped(p: Patch, st: Steepest, x: float, y: float, theta: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The frame sampled at the template's weighted pixels, the tip at ``(x, y)`` (px) turned by ``theta`` (rad).

    Returns the values, shape ``(m,)``, and which samples lie inside the frame.
    """
    return sample_value_xy(p, _turned(st, x, y, theta))


def _window_cells(p: Patch, st: Steepest, x: float, y: float, theta: float
                  ) -> tuple[NDArray[np.intp], FloatArray, FloatArray, NDArray[np.bool_] | None]:
    """:func:`~.sampling._corners` of the patch at :func:`_turned`'s points, bit for bit: each point's cell, its
    fractions, and which points lie in the frame, or ``None`` when every one does.

    When the window, turned anyhow, lies strictly inside a patch within the frame (its reach
    about the tip, :attr:`Steepest.reach`, from the patch's first and last pixel: nearly
    always), the points need no test: the same cells and fractions in fewer operations (the
    tip's place and then the patch's corner added to the turned offsets as two rows at once,
    ``(v + x) - x0`` as :func:`~.sampling._corners` makes it).
    """
    H, W = p.shape
    _, ch, cw = p.data.shape
    lx, ly = x - p.x0, y - p.y0
    if not (min(lx, ly) - st.reach > 0.0 and max(lx, ly) + st.reach < min(cw, ch) - 1.000001 and p.x0 >= 0
            and p.y0 >= 0 and p.x0 + cw <= W and p.y0 + ch <= H):  # (a NaN tip, too): every point tested
        return _corners(p, _turned(st, x, y, theta))
    xy = st.r * math.cos(theta)
    xy += st.r_perp * math.sin(theta)
    xy += np.array(((x,), (y,)))
    xy -= np.array(((float(p.x0),), (float(p.y0),)))
    return (*flat_cells(xy, cw), None)


def _warped3(p: Patch, st: Steepest, x: float, y: float, theta: float) -> tuple[FloatArray, NDArray[np.bool_] | None]:
    """:func:`~.sampling.sample_xy` of the patch at :func:`_turned`'s points, bit for bit; which lie in the frame, or
    ``None`` when every one does (:func:`_window_cells`)."""
    i00, fx, fy, inside = _window_cells(p, st, x, y, theta)
    v = p.data.reshape(-1).take(np.add(_limits(*p.data.shape[1:])[3], i00))
    return bilinear(v, fx, fy), inside


def _solve(A: FloatArray, w: FloatArray, y: FloatArray) -> FloatArray | None:
    """Weighted least squares ``A beta ≈ y``; ``None`` if singular."""
    Aw = A * w[:, None]
    M = Aw.T @ A
    try:
        return np.asarray(np.linalg.solve(M + 1e-12 * np.trace(M) * np.eye(A.shape[1]), Aw.T @ y), dtype=float)
    except np.linalg.LinAlgError:
        return None


_ALL = np.arange(10)
_NO_GAIN_PLANE = np.array([0, 3, 4, 5, 6, 7, 8, 9])
_NL = 7
_EYE = {n: np.eye(n) for n in (_ALL.size, _NO_GAIN_PLANE.size)}
"""The linear columns before the motion's: the six brightness planes and the blur term."""


_SOLVE1 = getattr(getattr(np.linalg, "_umath_linalg", None), "solve1", None)
"""The gufunc behind :func:`numpy.linalg.solve` for one right-hand side (the same LAPACK call, without the
wrapper's checks: 4 us against 10 us for a 10 x 10 system); ``None`` where numpy has it elsewhere."""


def _solve_small(M: FloatArray, rhs: FloatArray, held: bool = False) -> FloatArray | None:
    """:func:`numpy.linalg.solve` of the square system ``M x = rhs``, bit for bit; ``None`` where it is singular.

    A solution that is not finite everywhere (a singular matrix gives NaN) is solved again
    by :func:`numpy.linalg.solve`, which tells a singular matrix (``None``) from one that gives NaN.
    ``held``: the caller holds ``numpy.errstate(invalid="ignore")`` already (the fit's loop: entered
    once, not at every step).
    """
    if _SOLVE1 is not None:
        try:  # a private numpy function: a numpy that changed it falls back to the public solve
            if held:
                sol = np.asarray(_SOLVE1(M, rhs, signature="dd->d"), dtype=float)
            else:
                with np.errstate(invalid="ignore"):
                    sol = np.asarray(_SOLVE1(M, rhs, signature="dd->d"), dtype=float)
        except (TypeError, ValueError):
            sol = np.full(len(rhs), np.nan)
        if sol.shape == rhs.shape and np.isfinite(sol).all():
            return sol
    try:
        return np.asarray(np.linalg.solve(M, rhs), dtype=float)
    except np.linalg.LinAlgError:
        return None


def _joint(D: FloatArray, w: FloatArray, y: FloatArray, cols: NDArray[np.intp], kappa: float,
           turn: float, held: bool = False) -> FloatArray | None:
    """Weighted least squares of ``y`` on the columns ``cols`` of ``D`` (10: 6 brightness, blur, 3 motion).

    ``kappa`` weighs a prior that pulls the turn's step towards ``turn`` (the current turn's
    distance from its prior). The columns left out are 0 in the result. ``held``: as
    :func:`_solve_small`'s.
    """
    # D is column-major, as indexing its columns makes them: the products come out the same either way
    Dc = D if cols is _ALL else D[:, cols]
    Dw = Dc * w[:, None]
    M = Dw.T @ Dc
    rhs = Dw.T @ y
    if kappa > 0:
        M[-1, -1] += kappa
        rhs[-1] += kappa * turn
    # M + 1e-12 trace(M) I: the diagonal's sums, in place (M is new and C-contiguous: its diagonal a view); off it,
    # x + 0.0 is x
    diag = M.ravel()[:: len(cols) + 1]
    diag += 1e-12 * M.trace()
    sol = _solve_small(M, rhs, held)
    if sol is None:
        return None
    if cols is _ALL:
        return np.asarray(sol, dtype=float)
    out = np.zeros(D.shape[1])
    out[cols] = sol
    return out


def refine(
    image: Patch,
    st: Steepest,
    start: tuple[float, float],
    theta: float = 0.0,
    max_iter: int = 20,
    tol: float = 0.01,
    robust: bool = True,
    theta_sd: float | None = 0.05,
    theta_prior: float = 0.0,
    correlation: float = 1.0,
) -> Refinement:
    """Fit the template to the frame patch ``image`` from the tip at ``start`` (frame px) and turn ``theta`` (rad).

    ``theta_sd`` (rad) is the prior standard deviation of the turn about ``theta_prior``
    (the first frame's orientation): a thin needle's short window says little about its
    turn, and an unchecked turn would move the tip; ``None`` fits the turn freely.
    ``correlation`` is how much the residuals' correlation overstates what the pixels
    say (:attr:`~.template.TrackerParams.sigma_factor`): the prior weighs against the
    pixels' true information. Converged: the last step moved the tip by less than ``tol``
    px (a turn counted at 20 px from the tip).
    """
    T, w0, sd, basis = st.t, st.w, st.sd, st.basis
    tx, ty = float(start[0]), float(start[1])
    g, c = 1.0, 0.0
    beta_prev = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    kappa: float | None = None
    prev_dp: FloatArray | None = None
    dp_norm: float | None = None
    model: NDArray[np.intp] | None = None
    last_jac = sd
    robust_w = np.ones_like(T)
    converged, step, blur_c = False, math.inf, 0.0
    scale: float | None = None
    it, e = 0, np.zeros_like(T)
    inside: NDArray[np.bool_] | None = None  # which samples lie in the frame (None: every one)
    kept: _Kept | None = None
    D = _design(image, basis)
    bx, by = st.bx, st.by  # the position across the window, x and y: contiguous
    with np.errstate(invalid="ignore"):  # the solve's (a singular system gives NaN, told apart there): once a fit
        for it in range(1, max_iter + 1):
            v3, inside = _warped3(image, st, tx, ty, theta)
            Iw = v3[0]
            omega, sw, kept = _weights(w0, inside, robust_w, kept)
            if sw <= 1e-9:
                break
            jac = _esm_jacobian(st, v3, theta, g, blur_c)
            # one linear least squares for the brightness planes and the motion together: apart, the planes
            # would soak up half of every edge's shift at each step, and the motion would creep
            np.multiply(st.lap, g, out=D[:, 6])
            np.multiply(jac, g, out=D[:, _NL:].T)
            if theta_sd is not None and (kappa is None or it <= 2):  # the needle turns little: a prior on the turn
                r0 = Iw - basis @ beta_prev
                kappa = correlation**2 * float((omega * r0 * r0).sum()) / max(sw, 1e-12) / theta_sd**2
            sol, gain, model = _solve_positive_gain(D, omega, Iw, bx, by, model, kappa or 0.0, theta - theta_prior,
                                                    True)
            if sol is None or gain is None:  # contrast reversed, or no solution: not this template
                converged = False
                break
            beta_prev = sol[:6]
            sl = sol.tolist()  # (the same Python floats as float() of each; blur_c: half the blur variance the
            g, c, blur_c = sl[0], sl[3], sl[6] / sl[0]  # frame has beyond the template's, px²)
            e = _residual(Iw, sl[3:6], bx, by, gain, T, blur_c, st.lap)
            if robust and 2 <= it <= ROBUST_ITERATIONS:  # then the weights are kept: ones that flip never settle
                robust_w, scale = _tukey_weights(e, omega, scale)
            dp, dp_norm = _damped(sol[_NL:], prev_dp, dp_norm)  # (a view: nothing else reads sol's motion)
            prev_dp = dp
            tx, ty, theta, step = _moved(tx, ty, theta, dp)
            last_jac = jac
            if step < tol:
                converged = True
                break
            if not (math.isfinite(tx) and math.isfinite(ty)) or abs(theta) > 1.0:
                break
    if not converged and step < 5 * tol:  # still creeping by less than a twentieth of a pixel: settled
        converged = True
    omega = w0 * robust_w if inside is None else w0 * inside * robust_w
    cov = _covariance(st, g, last_jac, omega, e, theta)
    score, outliers, coverage = _score(image, st, tx, ty, theta, inside, robust_w)
    return Refinement(tx, ty, theta, g, c, cov, score, outliers, coverage, it, converged, 2.0 * blur_c)


def _design(image: Patch, basis: FloatArray) -> FloatArray:
    """The fit's design matrix with the brightness planes' columns ``basis`` in place; each step's blur and motion
    columns are filled in by the step; column-major (see :func:`_joint`). Raises ``ValueError`` for a patch
    ``image`` made without its derivatives (:func:`~.sampling.with_slopes`): the fit reads them."""
    if not image.slopes:
        raise ValueError("the fit needs the patch's derivatives: made without them (sampling.with_slopes makes them)")
    D = np.empty((basis.shape[0], 10), order="F")
    D[:, :6] = basis
    return D


_Kept = tuple[FloatArray, FloatArray, float]
"""The fit's weights made with every sample in the frame: the robust weights they were made from, the weights and
their sum."""


def _weights(w0: FloatArray, inside: NDArray[np.bool_] | None, robust_w: FloatArray, kept: _Kept | None
             ) -> tuple[FloatArray, float, _Kept | None]:
    """The fit's weights ``w0 * inside * robust_w`` and their sum, bit for bit, and what to keep for the next step.

    With every sample in the frame (``inside`` ``None``) ``w0 * True`` is ``w0``: ``w0 * robust_w``, made again only
    when the robust weights changed (``kept``: the last ones made so).
    """
    if inside is not None:
        omega = w0 * inside * robust_w
        return omega, float(omega.sum()), None
    if kept is not None and kept[0] is robust_w:
        return kept[1], kept[2], kept
    omega = w0 * robust_w
    sw = float(omega.sum())
    return omega, sw, (robust_w, omega, sw)


def _residual(Iw: FloatArray, c: list[float], bx: FloatArray, by: FloatArray, gain: FloatArray, T: FloatArray,
              blur_c: float, lap: FloatArray) -> FloatArray:
    """``(Iw - c3 - c4 bx - c5 by) / gain - T - blur_c lap``, the fit's residual in the template's units, the
    operations in that order and in place (one temporary, not eight)."""
    c3, c4, c5 = c
    e = Iw - c3
    tmp = np.multiply(bx, c4)
    e -= tmp
    np.multiply(by, c5, out=tmp)
    e -= tmp
    e /= gain
    e -= T
    np.multiply(lap, blur_c, out=tmp)
    e -= tmp
    return e


_SIGNS = np.array(((1.0,), (-1.0,)))


def _esm_jacobian(st: Steepest, v3: FloatArray, theta: float, g: float, blur_c: float) -> FloatArray:
    """The motion's Jacobian (3 x window): the mean of the model's and the warped frame's gradients.

    Efficient second-order minimisation (Benhimane and Malis 2004): the frame's gradients
    (``v3[1:]``) turned into the template's axes and divided by its contrast ``g``; the
    model's are the template's plus the blur term's (``blur_c``, px²).
    """
    ct, st_ = math.cos(theta), math.sin(theta)
    f = np.empty_like(st.sd)  # the frame's: fgx, fgy and the turn's, made in place
    fth = f[2]
    # (gx cos + gy sin, gy cos - gx sin) / g, both rows at once
    np.multiply(v3[1:], ct, out=f[:2])
    f[:2] += v3[2:0:-1] * (_SIGNS * st_)
    f[:2] /= g
    turn = f[:2] * st.r[::-1]  # (fgx ry, fgy rx)
    np.subtract(turn[1], turn[0], out=fth)  # fgy rx - fgx ry is, bit for bit, -fgx ry + fgy rx
    model = blur_c * st.sd_lap
    model += st.sd
    model += f
    model *= 0.5
    return model


def _solve_positive_gain(
    D: FloatArray, omega: FloatArray, Iw: FloatArray, bx: FloatArray, by: FloatArray,
    model: NDArray[np.intp] | None, kappa: float, turn: float, held: bool = False,
) -> tuple[FloatArray | None, FloatArray | None, NDArray[np.intp] | None]:
    """The joint solution (:func:`_joint`), its contrast across the window and the columns used.

    A contrast plane too steep for this window (the contrast below a fifth of its centre's
    somewhere): a plain contrast, and that for good (``model``: a model that changed back
    and forth between iterations would never settle). ``(None, None, model)`` when no
    solution has a positive contrast. ``bx``, ``by``: each pixel's place across the window
    (the basis's x and y columns). ``held``: as :func:`_solve_small`'s.
    """
    choices = (_ALL, _NO_GAIN_PLANE) if model is None or model is _ALL else (_NO_GAIN_PLANE,)
    for cols in choices:  # once plain, plain to the end
        sol = _joint(D, omega, Iw, cols, kappa, turn, held)
        if sol is None:
            break
        s0, s1, s2 = sol[:3].tolist()  # (Python floats: numpy's scalars cost more against an array)
        gain = s0 + s1 * bx + s2 * by
        # above a fifth everywhere (no NaN), above it where omega > 0: the subset is looked at only otherwise
        quick = gain.size > 0 and float(gain.min()) > 0.2 * s0
        if s0 > 1e-12 and (quick or bool((gain[omega > 0] > 0.2 * s0).all())):
            return sol, gain, cols
    return None, None, model


def _tukey_weights(e: FloatArray, omega: FloatArray, scale: float | None) -> tuple[FloatArray, float]:
    """Tukey's biweights of the residuals ``e``, and the robust spread (computed once, then ``scale``).

    The spread is fixed at its first value: a spread that moved with the weights would never settle.
    """
    if scale is None:
        m = omega > 0
        scale = max(1.4826 * median(np.abs(e[m])) if m.any() else 0.0, 1e-12)
    u = e / (TUKEY * scale)
    return np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0), scale


def _damped(dp: FloatArray, prev_dp: FloatArray | None, prev_norm: float | None = None
            ) -> tuple[FloatArray, float | None]:
    """The motion's step ``dp``, halved when it turned back on the last one (overshooting), and its norm when
    made and the step not halved (the next call's ``prev_norm``: ``prev_dp``'s, or ``None`` to make it)."""
    if prev_dp is None:
        return dp, None
    # the norms as numpy.linalg.norm makes them (the square root of the vector's dot with itself)
    norm = math.sqrt(dp.dot(dp))
    if prev_norm is None:
        prev_norm = math.sqrt(prev_dp.dot(prev_dp))
    if float(dp @ prev_dp) < -0.5 * (norm * prev_norm):
        dp *= 0.5
        return dp, None
    return dp, norm


def _moved(tx: float, ty: float, theta: float, dp: FloatArray) -> tuple[float, float, float, float]:
    """The tip (frame px) and turn (rad) after the inverse-compositional step ``dp``, and the step's size.

    The size is the tip's move plus the turn's at 20 px from the tip (px).
    """
    dx, dy, dth = dp.tolist()
    theta_new = theta - dth
    ct2, s2 = math.cos(theta_new), math.sin(theta_new)
    tx -= ct2 * dx - s2 * dy
    ty -= s2 * dx + ct2 * dy
    return tx, ty, theta_new, math.hypot(dx, dy) + abs(dth) * 20.0


def _covariance(
    st: Steepest, g: float, last_jac: FloatArray, omega: FloatArray, e: FloatArray, theta: float
) -> FloatArray:
    """Covariance of the translation (frame px²), from the last iteration's weights ``omega`` and residuals.

    The brightness planes are estimated alongside: their uncertainty widens the motion's.
    """
    D = np.concatenate([st.basis, g * st.lap[:, None], (g * last_jac).T], axis=1)
    M = (D * omega[:, None]).T @ D
    s2 = float((omega * (g * e) ** 2).sum()) / max(float(omega.sum()) - 10.0, 1.0)
    inv = _inverse(M)
    cov_win = np.full((2, 2), np.inf) if inv is None else (inv * s2)[_NL : _NL + 2, _NL : _NL + 2]
    R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    cov_win = cov_win * st.density  # the pixels left out said what their kept neighbours say
    return np.asarray(R @ cov_win @ R.T if np.all(np.isfinite(cov_win)) else cov_win)


_INV = getattr(getattr(np.linalg, "_umath_linalg", None), "inv", None)
"""The gufunc behind :func:`numpy.linalg.inv` (the same LAPACK call without the wrapper's checks; see
:data:`_SOLVE1`)."""


def _inverse(M: FloatArray) -> FloatArray | None:
    """:func:`numpy.linalg.inv` of the square matrix ``M``, bit for bit; ``None`` where it is singular.

    An inverse that is not finite everywhere (a singular matrix gives NaN) is made again by
    :func:`numpy.linalg.inv`, which tells a singular matrix from one that gives NaN.
    """
    if _INV is not None:
        try:  # a private numpy function: a numpy that changed it falls back to the public inverse
            with np.errstate(invalid="ignore"):
                out = np.asarray(_INV(M, signature="d->d"), dtype=float)
        except (TypeError, ValueError):
            out = np.full(M.shape, np.nan)
        if out.shape == M.shape and np.isfinite(out).all():
            return out
    try:
        return np.asarray(np.linalg.inv(M), dtype=float)
    except np.linalg.LinAlgError:
        return None


def _score(
    image: Patch, st: Steepest, tx: float, ty: float, theta: float, inside: NDArray[np.bool_] | None,
    robust_w: FloatArray,
) -> tuple[float, float, float]:
    """The fit's score, outlier share and coverage.

    The score is the correlation over the template's own weights inside the frame; the
    outliers are the share of those weights the robust fit set to zero; the coverage is
    the share of the template's weight inside the frame (``inside`` ``None``: every sample).
    """
    T, w0 = st.t, st.w
    every = inside is None or bool(inside.all())
    terms = st.score_terms if st.score_terms is not None and every else None
    # all inside (nearly always): the template's side made once (w0 * True is w0, bit for bit)
    wi = w0 if terms is not None or inside is None else w0 * inside
    swi = terms[0] if terms is not None else float(wi.sum())
    wsum = float(w0.sum())
    score = 0.0
    outliers = 1.0
    if swi > 1e-9 and math.isfinite(tx) and math.isfinite(ty):
        i00, fx, fy, _ = _window_cells(image, st, tx, ty, theta)  # warped()'s values
        Iw = bilinear(image.data[0].reshape(-1).take(neighbours(i00, *image.data.shape[1:])), fx, fy)
        if terms is not None:
            _, mt, wtc, stt = terms
        else:
            mt = float((wi * T).sum() / swi)
            wtc, stt = wi * (T - mt), float((wi * (T - mt) ** 2).sum())
        mi = float((wi * Iw).sum() / swi)
        Ic = Iw - mi
        num = float((wtc * Ic).sum())
        Ic *= Ic
        Ic *= wi
        den = math.sqrt(stt * float(Ic.sum()))
        score = num / den if den > 0 else 0.0
        outliers = float((wi * (robust_w == 0)).sum() / swi)
    return score, outliers, swi / wsum if wsum > 0 else 0.0
