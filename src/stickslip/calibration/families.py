"""Fitting one model family (:mod:`stickslip.families`) to traverses by least squares.

Residuals are relative, ``gamma_pred / gamma_meas - 1`` per traverse, with the
traverse average predicted exactly (prismatic) or by Gauss-Legendre quadrature
(rotary). Parameters are fitted in nm / µrad / 1 so the problem is well scaled. The
covariance is ``s^2 (J^T J)^-1`` with ``s^2 = RSS / (n - p)``; a family whose
Jacobian is rank deficient at the solution is *not identifiable* from these poses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..families import Features, FamilySpec, average_from_features, traverse_features
from ..measurements import Traverse

__all__ = ["FamilyFit", "fit_family", "traverse_columns", "unit_scale"]


@dataclass(frozen=True)
class FamilyFit:
    """The least-squares fit of one family to one joint and direction.

    Attributes
    ----------
    spec : FamilySpec
    joint : int
    values : ndarray
        Parameters, SI.
    cov : ndarray or None
        Covariance of ``values`` (SI), ``None`` when ``n <= p``.
    residuals : ndarray
        Relative residuals per traverse.
    identifiable : bool
        Whether the poses determine every parameter (full-rank Jacobian).
    """

    spec: FamilySpec
    joint: int
    values: NDArray[np.float64]
    cov: NDArray[np.float64] | None
    residuals: NDArray[np.float64]
    identifiable: bool

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.residuals**2)))


def unit_scale(spec: FamilySpec, joint: int) -> NDArray[np.float64]:
    """Per-parameter unit of the fit: 1e-9 (nm) or 1e-6 (µrad) for steps, 1 for b, b2."""
    step = 1e-9 if joint == 3 else 1e-6
    return np.array([1.0 if name in ("b", "b2") else step for name, _ in spec.names])


@dataclass(frozen=True)
class Columns:
    """Traverses of one joint as what a fit needs: the features along each, the measured averages."""

    joint: int
    feats: Features
    gamma: NDArray[np.float64]

    def subset(self, mask: NDArray[np.bool_]) -> Columns:
        f = Features(*(getattr(self.feats, k)[mask] for k in Features.__dataclass_fields__))
        return Columns(self.joint, f, self.gamma[mask])

    def __len__(self) -> int:
        return len(self.gamma)


def traverse_columns(ts: Sequence[Traverse]) -> Columns:
    """The features along the traverses ``ts`` (one joint) and their measured averages (SI)."""
    cols = {
        k: np.array([float(getattr(t, k)) for t in ts]) for k in ("start", "end", "q1", "q2", "q3", "theta", "psi")
    }
    joint = ts[0].joint if ts else 3
    feats = traverse_features(
        joint, cols["start"], cols["end"], cols["q1"], cols["q2"], cols["q3"], cols["theta"], cols["psi"]
    )
    return Columns(joint, feats, np.array([t.gamma for t in ts]))


def predict_columns(spec: FamilySpec, joint: int, values: NDArray[np.float64], cols: Columns) -> NDArray[np.float64]:
    """Predicted traverse averages (SI); nan where the model would stall."""
    return average_from_features(spec, values, cols.feats)


def _initial(spec: FamilySpec, joint: int, cols: Columns) -> NDArray[np.float64]:
    g = cols.gamma
    x = np.zeros(spec.n_params)
    for i, (name, _) in enumerate(spec.names):
        if name in ("a", "gamma0"):
            x[i] = float(np.median(g)) * (1.2 if joint == 3 and name == "a" and "b" in dict(spec.names) else 1.0)
        elif name in ("b", "b2"):
            x[i] = 0.1
    return x / unit_scale(spec, joint)


def fit_family(
    spec: FamilySpec,
    joint: int,
    ts: Sequence[Traverse],
    x0: NDArray[np.float64] | None = None,
    cols: Columns | None = None,
) -> FamilyFit:
    """Fit ``spec`` to the traverses ``ts`` of one joint and direction (relative least squares).

    ``x0`` (SI) starts the search (e.g. the fit on all data, for cross-validation).
    Never raises for a bad fit: a non-identifiable family comes back with
    ``identifiable=False``.
    """
    from scipy.optimize import least_squares

    cols = cols if cols is not None else traverse_columns(ts)
    scale = unit_scale(spec, joint)
    meas = cols.gamma

    def resid(x: NDArray[np.float64]) -> NDArray[np.float64]:
        pred = predict_columns(spec, joint, x * scale, cols)
        r = pred / meas - 1.0
        return np.where(np.isfinite(r), r, 10.0)

    start = _initial(spec, joint, cols) if x0 is None else np.asarray(x0, dtype=float) / scale
    lb = np.array([0.0 if name in ("a", "b", "b2") else -np.inf for name, _ in spec.names])
    ub = np.array([0.95 if name in ("b", "b2") else np.inf for name, _ in spec.names])
    start = np.clip(start, lb + 1e-9 * (np.isfinite(lb)), ub - 1e-9 * (np.isfinite(ub)))
    res = least_squares(resid, start, bounds=(lb, ub), x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10,
                        max_nfev=400 * (spec.n_params + 1), method="trf")
    x = res.x
    jac = _numjac(resid, x)
    n, p = jac.shape
    identifiable = n >= p and _full_rank(jac)
    cov: NDArray[np.float64] | None = None
    if identifiable and n > p:
        s2 = float(res.fun @ res.fun) / (n - p)
        try:
            cov_scaled = np.linalg.inv(jac.T @ jac) * s2
            cov = cov_scaled * np.outer(scale, scale)
        except np.linalg.LinAlgError:
            identifiable = False
    return FamilyFit(spec, joint, x * scale, cov, np.asarray(res.fun, dtype=float), identifiable)


def _full_rank(jac: NDArray[np.float64]) -> bool:
    colnorm = np.linalg.norm(jac, axis=0)
    if np.any(colnorm == 0.0):
        return False
    s = np.linalg.svd(jac / colnorm, compute_uv=False)
    return bool(s[-1] > 1e-6 * s[0])


def _numjac(f: object, x: NDArray[np.float64]) -> NDArray[np.float64]:
    assert callable(f)
    f0 = np.asarray(f(x))
    jac = np.empty((len(f0), len(x)))
    for i in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[i]))
        e = np.zeros_like(x)
        e[i] = h
        jac[:, i] = (np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h)
    return jac
