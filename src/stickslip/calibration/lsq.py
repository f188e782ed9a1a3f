"""Calibration from any set of traverses by nonlinear least squares, with standard errors
and a check that the poses determine every parameter."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..measurements import Traverse
from ..models import (
    JointModel,
    Params,
    PrismaticParams,
    RotaryParams,
    steps_between,
)
from .groups import TraverseGroups, group_traverses
from .result import Calibration, CalibrationError, Provenance, _check_physical, _constant_step, _day_of, _provenance

FloatArray = NDArray[np.float64]

# ----------------------------------------------------------------------------- least squares

# the fit works in nm (a, c), 1 (b) and µrad (gamma0, d) so the problem is well scaled
_PRISMATIC_SCALE = np.array([1e-9, 1.0, 1e-9])
_ROTARY_SCALE = np.array([1e-6, 1e-6, 1e-6, 1e-6])
_HINTS = {
    "a": "traverses at two different |cos q2| (e.g. q2 = -pi/2 and q2 = 0) with a known axial load",
    "b": "traverses at two different |cos q2| (e.g. q2 = -pi/2 and q2 = 0)",
    "c": "a traverse with an axial load (cos(zeta) cos(theta) != 0, e.g. (q2, theta, psi) = (0, 0, 0))",
    "gamma0": "traverses at two different q3 (e.g. 0 and 12 mm), at least one without gravity torque",
    "d": "traverses with gravity torque (e.g. theta = 0) at two different q3",
}


def _residual_fn(
    j: int, ts: Sequence[Traverse], knots: tuple[float, float]
) -> tuple[Callable[[FloatArray], FloatArray], FloatArray]:
    """Relative residuals of joint ``j``'s traverses as a function of the scaled parameters.

    Returns ``(resid, scale)``: ``resid(x)`` is ``predicted / measured - 1`` per traverse
    with SI parameters ``x * scale``.
    """
    cols = {
        k: np.array([getattr(t, k) for t in ts], dtype=float)
        for k in ("start", "end", "q1", "q2", "q3", "theta", "psi")
    }
    meas = np.array([t.gamma for t in ts])
    span = np.abs(cols["end"] - cols["start"])
    if j == 3:
        load = kin.prismatic_load(cols["q1"], cols["q2"], cols["theta"], cols["psi"])
        absc = np.abs(np.cos(cols["q2"]))
        scale = _PRISMATIC_SCALE

        def pred(x: FloatArray) -> FloatArray:
            a, b, c = x * scale
            out: FloatArray = (1.0 - b * absc) * (a - c * load)
            return out
    else:
        al, be = kin.rotary_load_coefficients(j, cols["q1"], cols["q2"], cols["q3"], cols["theta"], cols["psi"])
        w = (cols["q3"] - knots[0]) / (knots[1] - knots[0])
        scale = _ROTARY_SCALE

        def pred(x: FloatArray) -> FloatArray:
            g00, g01, d0, d1 = x * scale
            g0 = g00 + (g01 - g00) * w
            d = d0 + (d1 - d0) * w
            A = g0
            # where the step would be <= 0 along a traverse, return a large residual instead of failing
            with np.errstate(all="ignore"):
                B = np.abs(d) * np.hypot(al, be)
                ok = A > B
                n = np.full(A.shape, np.inf)
                if ok.any():
                    n[ok] = steps_between(cols["start"][ok], cols["end"][ok], A[ok], (d * al)[ok], (d * be)[ok])
            out: FloatArray = span / n
            return out

    def resid(x: FloatArray) -> FloatArray:
        out: FloatArray = pred(x) / meas - 1.0
        return out

    return resid, scale


def _initial_guess(j: int, ts: Sequence[Traverse]) -> FloatArray:
    g = np.array([t.gamma for t in ts])
    if j == 3:
        return np.array([np.max(g) * 1e9, 0.2, 0.0])
    m = float(np.median(g)) * 1e6
    return np.array([m, m, 0.0, 0.0])


def _identifiability(j: int, d: str, names: list[tuple[str, float | None]], jac: FloatArray) -> None:
    """Refuse when the Jacobian is rank deficient, naming the parameters the poses leave free."""
    n, p = jac.shape
    colnorm = np.linalg.norm(jac, axis=0)
    colnorm[colnorm == 0] = 1.0
    jn = jac / colnorm
    # thin SVD: V is all that is needed (p x p when n >= p); the full U would be n x n (80 GB at n = 1e5)
    _, s, vt = np.linalg.svd(jn, full_matrices=n < p)
    s_full = np.zeros(p)
    s_full[: len(s)] = s
    tol = max(n, p) * np.finfo(float).eps * 1e4 * (s_full[0] if s_full[0] > 0 else 1.0)
    null = vt[s_full <= max(tol, 1e-9 * s_full[0])]
    if len(null) == 0:
        return
    involved = np.nonzero(np.any(np.abs(null) > 0.1, axis=0))[0]
    labels = []
    for i in involved:
        name, q3 = names[i]
        labels.append(f"{name}{d}" + (f" (q3 = {q3 * 1e3:g} mm)" if q3 is not None else ""))
    hints = sorted({_HINTS[names[i][0]] for i in involved})
    raise CalibrationError(
        f"joint {j}{d}: the poses given cannot determine {', '.join(labels)} "
        f"({n} traverse{'s' if n != 1 else ''}, {p} parameters, only {p - len(null)} independent); "
        f"add {'; and '.join(hints)}"
    )


def calibrate_lsq(
    traverses: Sequence[Traverse] | TraverseGroups,
    day: str | None = None,
    source: str | None = None,
    knots: tuple[float, float] = (0.0, kin.Q3_MAX),
    provenance: Provenance | None = None,
    weights: Sequence[float] | None = None,
) -> Calibration:
    """Nonlinear least squares on any set of traverses, per joint and direction.

    Minimises the relative residuals ``gamma_pred / gamma_meas - 1`` of the traverse
    averages (predicted exactly, with the closed-form integral for rotary joints).
    Standard errors come from ``s^2 (J^T J)^-1`` with ``s^2 = RSS / (n - p)``; they are
    ``None`` when the traverses exactly determine the parameters (``n = p``).

    ``weights`` (one per traverse, > 0; default all 1) multiply each relative residual:
    a step size measured at a pose (:class:`~stickslip.measurements.StepSize`, given as a
    short traverse) weighs by its uncertainty beside the traverses
    (:func:`~stickslip.calibration.auto.calibrate`). Equal weights change nothing.

    Raises
    ------
    CalibrationError
        When the poses cannot determine a parameter (rank-deficient Jacobian, with the
        parameter named and a hint which pose would help), or the fit is non-physical.
    """
    from scipy.optimize import least_squares

    grouped = group_traverses(traverses)
    groups = grouped.as_dict()
    traverses = grouped.traverses
    if not groups:
        raise CalibrationError("no traverses to calibrate from")
    group_w: dict[tuple[int, str], FloatArray] = {}
    if weights is not None:
        if len(weights) != len(traverses):
            raise ValueError(f"{len(weights)} weights for {len(traverses)} traverses")
        by_key: dict[tuple[int, str], list[float]] = {}
        for t, w in zip(traverses, weights, strict=True):
            if not (np.isfinite(w) and w > 0):
                raise ValueError(f"a traverse's weight must be finite and > 0, got {w!r}")
            by_key.setdefault((t.joint, t.direction), []).append(float(w))
        group_w = {k: np.asarray(v) for k, v in by_key.items()}
    models: dict[tuple[int, str], JointModel] = {}
    stderr: dict[tuple[int, str], FloatArray | None] = {}
    notes: list[str] = []
    for (j, d), ts in sorted(groups.items()):
        resid, scale = _residual_fn(j, ts, knots)
        if (j, d) in group_w:
            resid = _weighted(resid, group_w[(j, d)])
        x0 = _initial_guess(j, ts)
        if j == 3:
            names = PrismaticParams(0, 0, 0).names()
            lb, ub = np.array([0.0, 0.0, -np.inf]), np.array([np.inf, 0.999999, np.inf])
            probe = x0 + np.array([0.0, 0.0, 0.05 * x0[0]])
        else:
            names = RotaryParams((0, 0), (0, 0), knots).names()
            lb, ub = np.array([0.0, 0.0, -np.inf, -np.inf]), np.full(4, np.inf)
            probe = x0 + np.array([0.0, 0.0, 0.05 * x0[0], 0.05 * x0[0]])
        # identifiability at a generic point (non-zero load sensitivity), before fitting
        jac0 = _numjac(resid, probe)
        _identifiability(j, d, names, jac0)
        res = least_squares(
            resid, x0, bounds=(lb, ub), x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000, method="trf"
        )
        if not np.all(np.isfinite(res.fun)):
            raise CalibrationError(f"joint {j}{d}: the fit did not converge to a physical model (a step would be <= 0)")
        jac = _numjac(resid, res.x)
        _identifiability(j, d, names, jac)
        n, p = len(ts), len(x0)
        x = res.x * scale
        if n > p:
            s2 = float(res.fun @ res.fun) / (n - p)
            try:
                cov = np.linalg.inv(jac.T @ jac) * s2
                se = np.sqrt(np.clip(np.diag(cov), 0, None)) * scale
            except np.linalg.LinAlgError:
                se = np.full(p, np.nan)
            stderr[(j, d)] = se
        else:
            stderr[(j, d)] = None
            notes.append(f"joint {j}{d}: {n} traverses for {p} parameters: exactly determined, no standard errors")
        params: Params = PrismaticParams.from_vector(x) if j == 3 else RotaryParams.from_vector(x, knots)
        models[(j, d)] = JointModel(j, d, params)
    _check_physical(models)
    consts = {k: _constant_step(k[0], k[1], m) for k, m in models.items()}
    return Calibration(
        models, stderr, consts, _day_of(traverses, day), "lsq",
        _provenance(provenance, traverses, source, len(traverses), notes),
    )


def _weighted(f: Callable[[FloatArray], FloatArray], w: FloatArray) -> Callable[[FloatArray], FloatArray]:
    """``f``'s residuals, each multiplied by its weight."""

    def g(x: FloatArray) -> FloatArray:
        out: FloatArray = f(x) * w
        return out

    return g


def _numjac(f: Callable[[FloatArray], FloatArray], x: FloatArray) -> FloatArray:
    """Central-difference Jacobian of ``f`` at ``x`` (x is well scaled: nm / µrad / 1)."""
    x = np.asarray(x, dtype=float)
    f0 = f(x)
    jac = np.empty((len(f0), len(x)))
    for i in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[i]))
        e = np.zeros_like(x)
        e[i] = h
        jac[:, i] = (f(x + e) - f(x - e)) / (2 * h)
    return jac


