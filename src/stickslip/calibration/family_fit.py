"""Fitting one model family (:mod:`stickslip.models.families`) to the traverses of one joint.

Residuals are relative, ``gamma_pred / gamma_meas - 1`` per traverse, with the traverse
average predicted exactly (prismatic) or by Gauss-Legendre quadrature (rotary), and its
derivatives in closed form (:func:`~stickslip.models.families.average_and_jacobian`).
Both directions of a joint are fitted at once, optionally with the terms of the joint's
mechanics shared by + and -. Parameters are fitted in nm / µrad / 1 so the problem is well
scaled, by Levenberg-Marquardt with the bounds of :data:`~stickslip.models.families.BOUNDS`
(a step that leaves them is projected back). The covariance is ``s^2 (J^T J)^-1`` with
``s^2 = RSS / (n - p)``; a family whose Jacobian is rank deficient at the solution is *not
identifiable* from these poses.

A fit can be restricted to some of the traverses (``rows``) and started from another
solution (``x0``): that is how the cross-validation refits a family without the traverses
it holds out (:mod:`.selection`), a few iterations from the fit on all of them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..models.families import BOUNDS, RATIO_NAMES, FamilySpec, average_and_jacobian
from .groups import JointData

__all__ = [
    "JointFit",
    "FamilyProblem",
    "unit_scale",
    "shared_names",
    "SHAREABLE",
    "PRIOR_SD",
    "PRIOR_WEIGHT",
]

FloatArray = NDArray[np.float64]
Rows = Mapping[str, NDArray[np.bool_]]

PRIOR_SD = {"e": 0.3, "f": 0.2, "h": 0.2, "t2": 0.3, "b2": 0.3, "k": 0.3, "m": 0.3}
"""Prior standard deviations of the terms beyond the paper's (relative to the typical step
for step-valued terms, absolute for b2, k and m): a gentle ridge towards the paper's model, so
that a family with more terms than the poses pin down does not swing wildly between them."""

PRIOR_WEIGHT = 0.03
"""The ridge's residuals are ``PRIOR_WEIGHT * value / prior_sd``: the prior counts like one
traverse with a 3 % relative error per term."""

SHAREABLE = {"prismatic": ("b", "b2", "f", "h", "k"), "rotary": ("e", "f")}
"""Terms of the joint's mechanics rather than of a direction of the drive (the mount's
efficiency, the normal-load coupling): a *shared* fit gives them one value for + and -."""

_STALL = 10.0
"""Residual of a traverse the model would stall on (its step <= 0 somewhere along it)."""


def unit_scale(spec: FamilySpec, joint: int) -> FloatArray:
    """Per-parameter unit of the fit: 1e-9 (nm) or 1e-6 (µrad) for steps, 1 for b, b2, k, m."""
    step = 1e-9 if joint == 3 else 1e-6
    return np.array([1.0 if name in RATIO_NAMES else step for name, _ in spec.names])


def shared_names(spec: FamilySpec) -> tuple[str, ...]:
    """The terms of ``spec`` a shared fit would share (empty if none)."""
    return tuple(sorted({n for n, _ in spec.names if n in SHAREABLE[spec.kind]}))


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
        ``direction -> relative residuals`` of the traverses fitted.
    identifiable : bool
    x : ndarray
        The solution in the fit's units (nm / µrad / 1), every direction's parameters once:
        where a refit starts.
    s2 : float
        Residual variance ``RSS / (n - p)`` of the relative residuals (nan when ``n <= p``).
    r, jac : ndarray or None
        Residuals (data rows, then the ridge's) and their Jacobian (fit units) at the solution:
        what a one-step refit without some traverses starts from.
    """

    spec: FamilySpec
    joint: int
    shared: tuple[str, ...]
    values: dict[str, FloatArray]
    cov: dict[str, FloatArray | None]
    residuals: dict[str, FloatArray]
    identifiable: bool
    x: FloatArray
    s2: float = math.nan
    r: FloatArray | None = field(default=None, repr=False)
    jac: FloatArray | None = field(default=None, repr=False)

    @property
    def label(self) -> str:
        return self.spec.name + ("+shared" if self.shared else "")

    @property
    def n_params(self) -> int:
        return int(self.x.size)

    @property
    def rms(self) -> float:
        r = np.concatenate(list(self.residuals.values()))
        return float(np.sqrt(np.mean(r**2))) if r.size else float("nan")


class FamilyProblem:
    """The least-squares problem of one family (and sharing) on one joint's traverses.

    Parameters
    ----------
    spec : FamilySpec
    data : JointData
        The joint's traverses, grouped (:func:`~.groups.group_traverses`).
    shared : tuple of str
        Terms with one value for both directions (see :data:`SHAREABLE`).
    """

    def __init__(self, spec: FamilySpec, data: JointData, shared: tuple[str, ...] = ()) -> None:
        self.spec, self.data, self.shared = spec, data, shared
        self.dirs = data.dirs
        scale1 = unit_scale(spec, data.joint)
        self.index: dict[str, NDArray[np.intp]] = {}
        gs: list[float] = []
        lb: list[float] = []
        ub: list[float] = []
        shared_at: dict[str, int] = {}
        for d in self.dirs:
            idx = []
            for i, (name, knot) in enumerate(spec.names):
                key = name if knot is None else f"{name}@{knot}"
                if name in shared and key in shared_at:
                    idx.append(shared_at[key])
                    continue
                if name in shared:
                    shared_at[key] = len(gs)
                idx.append(len(gs))
                gs.append(float(scale1[i]))
                lo, hi = BOUNDS.get(name, (-math.inf, math.inf))
                lb.append(lo)
                ub.append(hi)
            self.index[d] = np.array(idx, dtype=np.intp)
        self.gs = np.array(gs)
        self.lb, self.ub = np.array(lb), np.array(ub)
        # the ridge towards the paper's form: one residual per extension term and direction
        self.prior: list[tuple[int, float]] = []  # (global index, 1 / reference in fit units)
        for d in self.dirs:
            typical = float(np.median(data.gamma[d]))
            for i, (name, _) in enumerate(spec.names):
                sd = PRIOR_SD.get(name)
                if sd is None:
                    continue
                ref = sd if name in RATIO_NAMES else sd * typical
                k = int(self.index[d][i])
                self.prior.append((k, self.gs[k] / ref))

    @property
    def n_params(self) -> int:
        return int(self.gs.size)

    def values(self, x: FloatArray, d: str) -> FloatArray:
        """Direction ``d``'s parameters (SI) of the solution ``x`` (fit units)."""
        i = self.index[d]
        out: FloatArray = x[i] * self.gs[i]
        return out

    def initial(self, known: Mapping[tuple[str, str, float | None], float] | None = None) -> FloatArray:
        """A starting point (fit units): ``known`` values ``(direction, name, knot) -> SI`` where given
        (a simpler family's solution), else the median step for ``a``/``gamma0``, 0.1 for ``b``, 0."""
        x = np.zeros(self.n_params)
        for d in self.dirs:
            med = float(np.median(self.data.gamma[d]))
            has_b = any(n == "b" for n, _ in self.spec.names)
            for i, (name, knot) in enumerate(self.spec.names):
                k = int(self.index[d][i])
                v = None if known is None else _known(known, d, name, knot)
                if v is None:
                    if name == "a":
                        v = med * (1.2 if has_b else 1.0)
                    elif name == "gamma0":
                        v = med
                    elif name == "b":
                        v = 0.1
                    else:
                        v = 0.0
                x[k] = v / self.gs[k]
        return self._clip(x)

    def _clip(self, x: FloatArray) -> FloatArray:
        lo = self.lb + 1e-9 * np.isfinite(self.lb)
        hi = self.ub - 1e-9 * np.isfinite(self.ub)
        out: FloatArray = np.clip(x, lo, hi)
        return out

    def residuals(self, x: FloatArray, rows: Rows | None = None) -> tuple[FloatArray, FloatArray, int]:
        """Relative residuals and their Jacobian (fit units), data rows then the ridge's; and how many
        rows are data. Rows not in ``rows`` (masks per direction) are zero."""
        rs: list[FloatArray] = []
        js: list[FloatArray] = []
        for d in self.dirs:
            avg, jac = average_and_jacobian(self.spec, self.values(x, d), self.data.basis[d])
            meas = self.data.gamma[d]
            r = avg / meas - 1.0
            bad = ~np.isfinite(r)
            jrow = jac * (self.gs[self.index[d]] / meas[:, None])
            if bad.any():
                r = np.where(bad, _STALL, r)
                jrow[bad] = 0.0
            if rows is not None:
                w = rows[d].astype(float)
                r = r * w
                jrow = jrow * w[:, None]
            full = np.zeros((r.size, self.n_params))
            full[:, self.index[d]] = jrow  # a direction's own indices are distinct (shared: across directions)
            rs.append(r)
            js.append(full)
        n_data = sum(r.size for r in rs)
        pr = np.array([PRIOR_WEIGHT * x[k] * s for k, s in self.prior])
        pj = np.zeros((len(self.prior), self.n_params))
        for row, (k, s) in enumerate(self.prior):
            pj[row, k] = PRIOR_WEIGHT * s
        return np.concatenate([*rs, pr]), np.concatenate([*js, pj]), n_data

    def average(self, x: FloatArray, d: str, rows: NDArray[np.bool_] | None = None) -> FloatArray:
        """Predicted averages (SI) of direction ``d``'s traverses (those in ``rows``); nan where it stalls."""
        basis = self.data.basis[d] if rows is None else self.data.basis[d].take(rows)
        return average_and_jacobian(self.spec, self.values(x, d), basis)[0]

    def solve(self, x0: FloatArray, rows: Rows | None = None, max_iter: int = 100) -> tuple[FloatArray, FloatArray,
                                                                                               FloatArray, int]:
        """Levenberg-Marquardt from ``x0`` (fit units) on ``rows``: ``(x, residuals, jacobian, n_data)``."""
        return _levenberg_marquardt(lambda x: self.residuals(x, rows), self._clip(x0), self._clip, max_iter)

    def one_step(self, fit: JointFit, held: NDArray[np.bool_]) -> tuple[FloatArray, bool]:
        """The solution without the traverses ``held`` (a mask over every traverse, directions in order),
        in one Gauss-Newton step from ``fit`` (closed form: the normal equations less the held rows'
        share), and whether the rest still identifies every parameter."""
        assert fit.r is not None and fit.jac is not None
        n_data = int(held.size)
        keep = np.concatenate([~held, np.ones(fit.r.size - n_data, dtype=bool)])
        jk, rk = fit.jac[keep], fit.r[keep]
        if int((~held).sum()) < self.n_params or not full_rank(jk[: int((~held).sum())]):
            return fit.x, False
        a = jk.T @ jk
        try:
            step = np.linalg.solve(a + 1e-12 * np.trace(a) / a.shape[0] * np.eye(a.shape[0]), -(jk.T @ rk))
        except np.linalg.LinAlgError:
            return fit.x, False
        return self._clip(fit.x + step), True

    def covariance(
        self, r: FloatArray, jac: FloatArray, n_data: int, rows: Rows | None = None
    ) -> tuple[float, FloatArray | None]:
        """``s^2 = RSS / (n - p)`` over the data rows (those in ``rows``) and the parameters' covariance
        ``s^2 (J^T J)^-1`` (SI, every parameter once), or ``(nan, None)`` when ``n <= p`` or singular."""
        n = n_data if rows is None else int(sum(int(m.sum()) for m in rows.values()))
        if n <= self.n_params:
            return math.nan, None
        s2 = float(r[:n_data] @ r[:n_data]) / (n - self.n_params)
        try:
            inv = np.linalg.inv(jac.T @ jac)
        except np.linalg.LinAlgError:
            return s2, None
        return s2, np.asarray(inv * s2 * np.outer(self.gs, self.gs), dtype=float)

    def fit(self, x0: FloatArray | None = None, max_iter: int = 100) -> JointFit:
        """The fit on every traverse, from ``x0`` (fit units) or :meth:`initial`."""
        x, r, jac, n_data = self.solve(self.initial() if x0 is None else x0, None, max_iter)
        ident = n_data >= self.n_params and full_rank(jac[:n_data])
        s2, cov_all = self.covariance(r, jac, n_data) if ident else (math.nan, None)
        values = {d: self.values(x, d) for d in self.dirs}
        cov = {d: None if cov_all is None else cov_all[np.ix_(self.index[d], self.index[d])] for d in self.dirs}
        residuals: dict[str, FloatArray] = {}
        k = 0
        for d in self.dirs:
            n = self.data.gamma[d].size
            residuals[d] = r[k : k + n]
            k += n
        return JointFit(self.spec, self.data.joint, self.shared, values, cov, residuals, ident, x, s2, r, jac)


def _known(known: Mapping[tuple[str, str, float | None], float], d: str, name: str, knot: float | None) -> float | None:
    """A known value of ``name`` at ``knot``; a knot between two known ones is interpolated linearly."""
    key = (d, name, None if knot is None else round(knot, 9))
    if key in known:
        return known[key]
    if knot is None:
        return None
    pts = sorted((k, v) for (dd, n, k), v in known.items() if dd == d and n == name and k is not None)
    if len(pts) < 2:
        return None
    ks, vs = zip(*pts, strict=True)
    return float(np.interp(knot, ks, vs))


def full_rank(jac: FloatArray) -> bool:
    """Whether the columns of ``jac`` are independent (relative singular value > 1e-6, column-scaled).

    From the eigenvalues of the column-scaled normal matrix (``p x p``), so the cost is one
    pass over the rows.
    """
    a = jac.T @ jac
    d = np.sqrt(np.diag(a))
    if jac.shape[0] < jac.shape[1] or np.any(d == 0.0) or not np.all(np.isfinite(a)):
        return False
    ev = np.linalg.eigvalsh(a / np.outer(d, d))
    return bool(ev[0] > 1e-12 * ev[-1])


def _levenberg_marquardt(
    fun: Callable[[FloatArray], tuple[FloatArray, FloatArray, int]],
    x0: FloatArray,
    project: Callable[[FloatArray], FloatArray],
    max_iter: int,
) -> tuple[FloatArray, FloatArray, FloatArray, int]:
    """Minimise ``|r(x)|^2`` (``fun(x) -> (r, J, n_data)``) from ``x0``, steps projected by ``project``.

    Marquardt's scaling (``J^T J + lam diag(J^T J)``); a step that does not lower the cost
    raises ``lam`` tenfold, an accepted one lowers it. Stops after ``max_iter`` accepted steps,
    or when a step changes the cost by less than 1e-12 relative.
    """
    x = x0
    r, jac, n_data = fun(x)
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(max_iter):
        a = jac.T @ jac
        g = jac.T @ r
        dia = np.diag(a).copy()
        dia[dia <= 0.0] = 1.0
        accepted = False
        while lam < 1e12:
            try:
                step = np.linalg.solve(a + lam * np.diag(dia), -g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            xn = project(x + step)
            rn, jn, _ = fun(xn)
            cn = float(rn @ rn)
            if cn <= cost:
                accepted = True
                break
            lam *= 10.0
        if not accepted:
            break
        done = cost - cn <= 1e-12 * cost or not np.any(xn != x)
        x, r, jac, cost = xn, rn, jn, cn
        lam = max(lam / 10.0, 1e-9)
        if done:
            break
    return x, r, jac, n_data
