"""Fitting one model family (:mod:`stickslip.models.families`) to traverses by least squares.

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

from ..measurements import Traverse
from ..models.families import BOUNDS, RATIO_NAMES, FamilySpec, Features, average_from_features, traverse_features

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


PRIOR_SD = {"e": 0.3, "f": 0.2, "h": 0.2, "t2": 0.3, "b2": 0.3, "k": 0.3, "m": 0.3}
"""Prior standard deviations of the terms beyond the paper's (relative to the typical step
for step-valued terms, absolute for b2 and k): a gentle ridge towards the paper's model, so
that a family with more terms than the poses pin down does not swing wildly between them."""

PRIOR_WEIGHT = 0.03
"""The ridge's residuals are ``PRIOR_WEIGHT * value / prior_sd``: the prior counts like one
traverse with a 3 % relative error per term."""


def prior_residuals(
    spec: FamilySpec, values: NDArray[np.float64], typical: float
) -> NDArray[np.float64]:
    """Ridge residuals of the extension terms of ``values`` (SI); ``typical`` is the median measured step."""
    out = []
    for (name, _), v in zip(spec.names, values, strict=True):
        sd = PRIOR_SD.get(name)
        if sd is None:
            continue
        ref = sd if name in RATIO_NAMES else sd * typical
        out.append(PRIOR_WEIGHT * v / ref)
    return np.array(out, dtype=float)


def unit_scale(spec: FamilySpec, joint: int) -> NDArray[np.float64]:
    """Per-parameter unit of the fit: 1e-9 (nm) or 1e-6 (µrad) for steps, 1 for b, b2."""
    step = 1e-9 if joint == 3 else 1e-6
    return np.array([1.0 if name in RATIO_NAMES else step for name, _ in spec.names])


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
        elif name == "b":
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

    typical = float(np.median(meas))

    def resid(x: NDArray[np.float64]) -> NDArray[np.float64]:
        pred = predict_columns(spec, joint, x * scale, cols)
        r = pred / meas - 1.0
        return np.concatenate((np.where(np.isfinite(r), r, 10.0), prior_residuals(spec, x * scale, typical)))

    start = _initial(spec, joint, cols) if x0 is None else np.asarray(x0, dtype=float) / scale
    lb = np.array([BOUNDS.get(name, (-np.inf, np.inf))[0] for name, _ in spec.names])
    ub = np.array([BOUNDS.get(name, (-np.inf, np.inf))[1] for name, _ in spec.names])
    start = np.clip(start, lb + 1e-9 * (np.isfinite(lb)), ub - 1e-9 * (np.isfinite(ub)))
    res = least_squares(resid, start, bounds=(lb, ub), x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10,
                        max_nfev=400 * (spec.n_params + 1), method="trf")
    x = res.x
    jac = _numjac(resid, x)
    n, p = len(meas), jac.shape[1]
    identifiable = n >= p and _full_rank(jac[:n])
    cov: NDArray[np.float64] | None = None
    if identifiable and n > p:
        s2 = float(res.fun[:n] @ res.fun[:n]) / (n - p)
        try:
            cov_scaled = np.linalg.inv(jac.T @ jac) * s2
            cov = cov_scaled * np.outer(scale, scale)
        except np.linalg.LinAlgError:
            identifiable = False
    return FamilyFit(spec, joint, x * scale, cov, np.asarray(res.fun, dtype=float)[: len(meas)], identifiable)


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


# ----------------------------------------------------------------------------- both directions at once

SHAREABLE = {"prismatic": ("b", "b2", "f", "h", "k"), "rotary": ("e", "f")}
"""Terms of the joint's mechanics rather than of a direction of the drive (the mount's
efficiency, the normal-load coupling): a *shared* fit gives them one value for + and -."""


@dataclass(frozen=True)
class JointFit:
    """A family fitted to both directions of one joint, optionally with shared terms.

    Attributes
    ----------
    spec : FamilySpec
    joint : int
    shared : tuple of str
        Names of the terms with one value for both directions.
    values : dict
        ``direction -> parameters`` (SI, order of ``spec.names``).
    cov : dict
        ``direction -> covariance`` (SI) or ``None``.
    residuals : dict
        ``direction -> relative residuals``.
    identifiable : bool
    """

    spec: FamilySpec
    joint: int
    shared: tuple[str, ...]
    values: dict[str, NDArray[np.float64]]
    cov: dict[str, NDArray[np.float64] | None]
    residuals: dict[str, NDArray[np.float64]]
    identifiable: bool

    @property
    def label(self) -> str:
        return self.spec.name + ("+shared" if self.shared else "")

    @property
    def n_params(self) -> int:
        per = self.spec.n_params
        n_shared = sum(1 for name, _ in self.spec.names if name in self.shared)
        return per * len(self.values) - n_shared * (len(self.values) - 1)

    @property
    def rms(self) -> float:
        r = np.concatenate(list(self.residuals.values()))
        return float(np.sqrt(np.mean(r**2)))


def shared_names(spec: FamilySpec) -> tuple[str, ...]:
    """The terms of ``spec`` a shared fit would share (empty if none)."""
    return tuple(sorted({n for n, _ in spec.names if n in SHAREABLE[spec.kind]}))


def fit_joint(
    spec: FamilySpec,
    joint: int,
    cols: dict[str, Columns],
    shared: tuple[str, ...] = (),
    x0: dict[str, NDArray[np.float64]] | None = None,
) -> JointFit:
    """Fit ``spec`` to both directions of ``joint`` at once (``cols``: direction -> traverses).

    With ``shared`` empty this is two independent fits; with shared terms, one value of
    each for both directions. Never raises for a bad fit (``identifiable=False``).
    """
    from scipy.optimize import least_squares

    dirs = sorted(cols)
    scale1 = unit_scale(spec, joint)
    index: dict[str, list[int]] = {}
    glob_scale: list[float] = []
    lb: list[float] = []
    ub: list[float] = []
    start: list[float] = []
    shared_at: dict[str, int] = {}
    for d in dirs:
        init = _initial(spec, joint, cols[d]) if x0 is None else np.asarray(x0[d], dtype=float) / scale1
        idx = []
        for i, (name, knot) in enumerate(spec.names):
            key = name if knot is None else f"{name}@{knot}"
            if name in shared and key in shared_at:
                idx.append(shared_at[key])
                continue
            k = len(glob_scale)
            if name in shared:
                shared_at[key] = k
            idx.append(k)
            glob_scale.append(float(scale1[i]))
            lb.append(BOUNDS.get(name, (-np.inf, np.inf))[0])
            ub.append(BOUNDS.get(name, (-np.inf, np.inf))[1])
            start.append(float(init[i]))
        index[d] = idx
    gs = np.array(glob_scale)
    lo, hi = np.array(lb), np.array(ub)
    x_start = np.clip(np.array(start), lo + 1e-9 * np.isfinite(lo), hi - 1e-9 * np.isfinite(hi))

    typical = {d: float(np.median(cols[d].gamma)) for d in dirs}
    n_data = sum(len(cols[d]) for d in dirs)

    def resid(x: NDArray[np.float64]) -> NDArray[np.float64]:
        parts = []
        for d in dirs:
            v = x[index[d]] * gs[index[d]]
            r = average_from_features(spec, v, cols[d].feats) / cols[d].gamma - 1.0
            parts.append(np.where(np.isfinite(r), r, 10.0))
        for d in dirs:
            parts.append(prior_residuals(spec, x[index[d]] * gs[index[d]], typical[d]))
        return np.concatenate(parts)

    res = least_squares(resid, x_start, bounds=(lo, hi), x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10,
                        max_nfev=400 * (len(x_start) + 1), method="trf")
    x = res.x
    jac = _numjac(resid, x)
    n, p = jac.shape
    identifiable = n_data >= p and _full_rank(jac[:n_data])
    cov_all: NDArray[np.float64] | None = None
    if identifiable and n_data > p:
        r_data = res.fun[:n_data]
        s2 = float(r_data @ r_data) / (n_data - p)
        try:
            cov_all = np.linalg.inv(jac.T @ jac) * s2 * np.outer(gs, gs)
        except np.linalg.LinAlgError:
            identifiable = False
    values = {d: x[index[d]] * gs[index[d]] for d in dirs}
    cov = {d: None if cov_all is None else cov_all[np.ix_(index[d], index[d])] for d in dirs}
    r_all = np.asarray(res.fun, dtype=float)
    residuals = {}
    k = 0
    for d in dirs:
        residuals[d] = r_all[k : k + len(cols[d])]
        k += len(cols[d])
    return JointFit(spec, joint, shared, values, cov, residuals, identifiable)
