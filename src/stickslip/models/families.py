"""Step-size model families beyond the paper's (docs/models.md §2), each with its equation.

The paper's Eqs. 2, 3, 7, 8 live in :mod:`stickslip.models` and are the family
``paper``. The families here extend them where the physics of a stick-slip contact
says the paper's form is too narrow (the step is not linear in the static load; a
load across the axis changes the normal force and so the friction; the rotary
joint's inertia and lever grow with q3 in a way a straight line between two knots
does not follow). All are pure and vectorised; SI units (steps in m or rad).

Prismatic joint 3, direction i (every family is this equation with some terms zero)::

    gamma_3 = s * eta(q2) * (a - c L - e L^2 - f X - h Y)                  (F1)
    eta(q2) = 1 - b |cos q2| - b2 cos^2 q2                                 (F2)

and the family ``friction-ratio``, where the load acts through its ratio to the
friction capacity, which the normal load ``X`` changes::

    gamma_3 = s * eta(q2) * (a - c Λ - e Λ^2 - f X),  Λ = L / (1 + k X)     (F4)

and the family ``load-mount``, where the load's effect depends on how compliant the
mount is, which the arm's elevation sets (the same ``|cos q2|`` as the efficiency)::

    gamma_3 = s * eta(q2) * (a - (c + m |cos q2|) L - e L^2)                (F5)

with ``L = -g0 . z2`` (the paper's axial load, ``cos(zeta) cos(theta)`` at q1 = 0),
``X = -g0 . x2`` and ``Y = -g0 . z1`` the two components of gravity across the axis
(``x2 = z1 x z2``; ``L^2 + X^2 + Y^2 = 1``).

Rotary joint j (1 or 2), direction i, with ``w = q3 / 12 mm``::

    gamma_j = s * (G(w) + D(w) T + t2 T^2 + E R + f P)                     (F3)

``T`` is the paper's load term (Eq. 8; :func:`stickslip.kinematics.load_term`), ``R``
the gravity along the arm (joint 2: the radial load on its contact; joint 1: 0),
``P = |g0 . axis|`` the gravity along the joint's axis (a normal load on the contact),
and ``G``, ``D`` are linear in ``w`` (values at q3 = 0 and 12 mm, as the paper) or
quadratic (values at 0, 6 and 12 mm). ``s`` is a step scale, 1 after a calibration
and updated by :func:`stickslip.calibration.update.update_calibration`.

The average step over a traverse is ``|end - start| / integral dq / gamma``; the
integral is exact for the prismatic joint (the step does not depend on q3) and a
48-point Gauss-Legendre rule for rotary joints (the step is smooth along the travel;
agreement with the closed form of the paper family is ~1e-12, a test checks it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import kinematics as kin
from ..joints import joint_spec
from ..units import DIMENSIONLESS_PARAMETERS
from .paper import STALL_RATIO, JointModel, NonPhysicalError, StepProfile

__all__ = [
    "FamilySpec",
    "FAMILIES",
    "families_for",
    "FamilyParams",
    "FamilyModel",
    "Features",
    "features",
    "TabulatedProfile",
    "RATIO_NAMES",
    "BOUNDS",
    "FitBasis",
    "fit_basis",
    "average_and_jacobian",
]

Q3_MID = kin.Q3_MAX / 2.0

RATIO_NAMES = tuple(sorted(DIMENSIONLESS_PARAMETERS))
"""Dimensionless parameters (all others are steps: m for joint 3, rad for rotary joints)."""

BOUNDS = {"a": (0.0, math.inf), "b": (0.0, 0.95), "b2": (-0.95, 0.95), "k": (-0.9, 0.9)}
"""Ranges a fit keeps parameters in (so that eta > 0 and 1 + k X > 0); the rest are free."""


@dataclass(frozen=True)
class FamilySpec:
    """A model family: which parameters of (F1)-(F3) are free.

    Attributes
    ----------
    name : str
    kind : str
        ``"prismatic"`` or ``"rotary"``.
    names : tuple of (str, float or None)
        Free parameters in order: name and, for q3-dependent rotary terms, the knot (m).
    summary : str
        One line for people.
    """

    name: str
    kind: str
    names: tuple[tuple[str, float | None], ...]
    summary: str

    @property
    def n_params(self) -> int:
        """Number of free parameters."""
        return len(self.names)


_LIN = (0.0, kin.Q3_MAX)
_QUAD = (0.0, Q3_MID, kin.Q3_MAX)


def _rot(*parts: tuple[str, tuple[float, ...] | None]) -> tuple[tuple[str, float | None], ...]:
    out: list[tuple[str, float | None]] = []
    for name, knots in parts:
        if knots is None:
            out.append((name, None))
        else:
            out.extend((name, k) for k in knots)
    return tuple(out)


FAMILIES: dict[str, FamilySpec] = {
    s.name: s
    for s in (
        FamilySpec("constant", "prismatic", (("a", None),), "a constant step (the paper's comparator)"),
        FamilySpec("paper", "prismatic", (("a", None), ("b", None), ("c", None)), "Eq. 3: eta(q2) (a - c L)"),
        FamilySpec(
            "load2", "prismatic", (("a", None), ("b", None), ("c", None), ("e", None)),
            "Eq. 3 with a load term quadratic in L",
        ),
        FamilySpec(
            "smooth-eta", "prismatic", (("a", None), ("b2", None), ("c", None), ("e", None)),
            "eta = 1 - b2 cos^2 q2 (no kink), load quadratic in L",
        ),
        FamilySpec(
            "load-mount", "prismatic", (("a", None), ("b", None), ("c", None), ("e", None), ("m", None)),
            "quadratic load whose strength changes with the mount's compliance (c + m |cos q2|)",
        ),
        FamilySpec(
            "normal", "prismatic", (("a", None), ("b", None), ("c", None), ("f", None), ("h", None)),
            "Eq. 3 plus normal-load terms from gravity across the axis",
        ),
        FamilySpec(
            "load2-normal", "prismatic",
            (("a", None), ("b", None), ("c", None), ("e", None), ("f", None), ("h", None)),
            "quadratic load plus normal-load terms",
        ),
        FamilySpec(
            "friction-ratio", "prismatic",
            (("a", None), ("b", None), ("b2", None), ("c", None), ("e", None), ("k", None), ("f", None)),
            "the load over the friction capacity, L / (1 + k X), quadratic; normal load f X",
        ),
        FamilySpec(
            "full", "prismatic",
            (("a", None), ("b", None), ("b2", None), ("c", None), ("e", None), ("f", None), ("h", None)),
            "every term of (F1), (F2)",
        ),
    )
}
for _s in (
    FamilySpec("constant", "rotary", (("gamma0", None),), "a constant step (the paper's comparator)"),
    FamilySpec("paper", "rotary", _rot(("gamma0", _LIN), ("d", _LIN)), "Eqs. 7, 8: gamma0 + d T, linear in q3"),
    FamilySpec(
        "torque2", "rotary", _rot(("gamma0", _LIN), ("d", _LIN), ("t2", None)), "Eq. 8 plus a term in T^2"
    ),
    FamilySpec(
        "radial", "rotary", _rot(("gamma0", _LIN), ("d", _LIN), ("e", None)),
        "Eq. 8 plus the radial load (gravity along the arm)",
    ),
    FamilySpec(
        "normal", "rotary", _rot(("gamma0", _LIN), ("d", _LIN), ("f", None)),
        "Eq. 8 plus the normal load (gravity along the joint axis)",
    ),
    FamilySpec(
        "q3-quadratic", "rotary", _rot(("gamma0", _QUAD), ("d", _QUAD)), "Eq. 8 with gamma0, d quadratic in q3"
    ),
    FamilySpec(
        "torque2-radial", "rotary", _rot(("gamma0", _LIN), ("d", _LIN), ("t2", None), ("e", None), ("f", None)),
        "Eq. 8 plus T^2, radial and normal loads",
    ),
    FamilySpec(
        "rich", "rotary", _rot(("gamma0", _QUAD), ("d", _QUAD), ("t2", None), ("e", None), ("f", None)),
        "every term of (F3)",
    ),
):
    FAMILIES[f"rotary:{_s.name}"] = _s


def families_for(joint: int) -> list[FamilySpec]:
    """The families of ``joint`` (3: prismatic; 1, 2: rotary), simplest first."""
    if joint_spec(joint).prismatic:
        return [s for k, s in FAMILIES.items() if not k.startswith("rotary:")]
    return [s for k, s in FAMILIES.items() if k.startswith("rotary:")]


def family_spec(joint: int, name: str) -> FamilySpec:
    """The :class:`FamilySpec` called ``name`` for ``joint``; ``KeyError`` lists the known names."""
    for s in families_for(joint):
        if s.name == name:
            return s
    known = ", ".join(s.name for s in families_for(joint))
    raise KeyError(f"no model family {name!r} for joint {joint} (known: {known})")


# ---------------------------------------------------------------- features


@dataclass(frozen=True)
class Features:
    """The pose-dependent quantities of (F1)-(F3), arrays of one shape (dimensionless, w in 1)."""

    L: NDArray[np.float64]
    X: NDArray[np.float64]
    Y: NDArray[np.float64]
    abs_cos_q2: NDArray[np.float64]
    T: NDArray[np.float64]
    R: NDArray[np.float64]
    P: NDArray[np.float64]
    q3: NDArray[np.float64]


def features(
    joint: int, q1: ArrayLike, q2: ArrayLike, q3: ArrayLike, theta: ArrayLike, psi: ArrayLike
) -> Features:
    """The terms of (F1)-(F3) in a pose (vectorised); the moving joint's own column is used."""
    q1a, q2a, q3a, tha, psa = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (q1, q2, q3, theta, psi)))
    g = kin.gravity_base(tha, psa)
    z2 = kin.arm_axis(q1a, q2a)
    z1 = kin.joint2_axis(q1a)
    x2 = np.cross(z1, z2)
    L = -np.sum(g * z2, axis=-1)
    X = -np.sum(g * x2, axis=-1)
    Y = -np.sum(g * z1, axis=-1)
    if joint_spec(joint).prismatic:
        T = np.zeros_like(L)
        R = np.zeros_like(L)
        P = np.zeros_like(L)
    else:
        T = kin.load_term(joint, q1a, q2a, q3a, tha, psa)
        if joint == 2:
            R, P = L, np.abs(Y)
        else:
            R, P = np.zeros_like(L), np.abs(g[..., 2])
    return Features(L, X, Y, np.abs(np.cos(q2a)), T, R, P, q3a)


def _lagrange(q3: NDArray[np.float64], knots: tuple[float, ...], values: list[float]) -> NDArray[np.float64]:
    out = np.zeros_like(q3)
    for i, (ki, vi) in enumerate(zip(knots, values, strict=True)):
        basis = np.ones_like(q3)
        for j, kj in enumerate(knots):
            if j != i:
                basis = basis * (q3 - kj) / (ki - kj)
        out = out + vi * basis
    return out


def evaluate(spec: FamilySpec, values: ArrayLike, f: Features, scale: float = 1.0) -> NDArray[np.float64]:
    """Mean step (m or rad) of family ``spec`` with parameter ``values`` (SI) at the features ``f``: (F1)-(F3)."""
    v = np.asarray(values, dtype=float)
    groups: dict[str, list[tuple[float | None, float]]] = {}
    for (name, knot), x in zip(spec.names, v, strict=True):
        groups.setdefault(name, []).append((knot, float(x)))

    def scalar(name: str) -> float:
        return groups[name][0][1] if name in groups else 0.0

    def of_q3(name: str) -> NDArray[np.float64]:
        if name not in groups:
            return np.zeros_like(f.q3)
        items = groups[name]
        if len(items) == 1 and items[0][0] is None:
            return np.full_like(f.q3, items[0][1])
        knots = tuple(float(k) for k, _ in items if k is not None)
        return _lagrange(f.q3, knots, [x for _, x in items])

    if spec.kind == "prismatic":
        eta = 1.0 - scalar("b") * f.abs_cos_q2 - scalar("b2") * f.abs_cos_q2**2
        lam = f.L / (1.0 + scalar("k") * f.X) if "k" in groups else f.L  # (F4): load over friction capacity
        c_eff = scalar("c") + scalar("m") * f.abs_cos_q2  # (F5): the mount's compliance changes the load's effect
        core = scalar("a") - c_eff * lam - scalar("e") * lam**2 - scalar("f") * f.X - scalar("h") * f.Y
        out: NDArray[np.float64] = scale * eta * core
        return out
    g0 = of_q3("gamma0")
    d = of_q3("d")
    res: NDArray[np.float64] = scale * (g0 + d * f.T + scalar("t2") * f.T**2 + scalar("e") * f.R + scalar("f") * f.P)
    return res


_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)


def traverse_features(
    joint: int,
    start: ArrayLike,
    end: ArrayLike,
    q1: ArrayLike,
    q2: ArrayLike,
    q3: ArrayLike,
    theta: ArrayLike,
    psi: ArrayLike,
) -> Features:
    """Features along traverses: shape ``(n,)`` for joint 3, ``(n, 48)`` at the Gauss-Legendre nodes (rotary)."""
    st, en, a1, a2, a3, th, ps = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (start, end, q1, q2, q3, theta, psi))
    )
    if joint_spec(joint).prismatic:
        return features(joint, a1, a2, a3, th, ps)
    mid, half = 0.5 * (st + en), 0.5 * (en - st)
    q = mid[..., None] + half[..., None] * _GL_X
    cols = [a1[..., None], a2[..., None], a3[..., None]]
    cols[joint - 1] = q
    return features(joint, cols[0], cols[1], cols[2], th[..., None], ps[..., None])


def average_from_features(
    spec: FamilySpec, values: ArrayLike, f: Features, scale: float = 1.0
) -> NDArray[np.float64]:
    """Average step over traverses from :func:`traverse_features` (m or rad); nan where it would stall."""
    return average_from_gamma(spec.kind, evaluate(spec, values, f, scale))


def average_from_gamma(kind: str, g: NDArray[np.float64]) -> NDArray[np.float64]:
    """Average step over traverses from the step along them (prismatic: ``(n,)``; rotary: ``(n, 48)`` at the
    Gauss-Legendre nodes of :func:`traverse_features`), m or rad; nan where it would stall."""
    if kind == "prismatic":
        return np.where(g > 0.0, g, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        avg = 1.0 / (np.sum(_GL_W / g, axis=-1) * 0.5)
    return np.where(np.all(g > 0.0, axis=-1), avg, np.nan)


@dataclass(frozen=True)
class FitBasis:
    """Traverses of one joint in the form a fit needs: what (F1)-(F5) depend on, per traverse.

    Prismatic joint (the step does not change along its own travel): the features at the
    pose, ``feats`` (shape ``(n,)``). Rotary joints: every load of (F3) is a sinusoid of the
    joint's own angle, ``F(q) = F0 + Fc cos q + Fs sin q`` (gravity projected on axes that
    turn with the joint), so a traverse is its coefficients (``T``, ``R``: ``(3, n)``), the
    constant normal load ``P`` and ``q3`` (``(n,)``), and the 48 Gauss-Legendre nodes along
    it (``cos``, ``sin``, and ``T2 = T(q)^2``: ``(n, 48)``; the rule of
    :func:`traverse_features`, so averages agree with it to rounding).
    """

    kind: str
    feats: Features | None = None
    q3: NDArray[np.float64] | None = None
    T: NDArray[np.float64] | None = None
    R: NDArray[np.float64] | None = None
    P: NDArray[np.float64] | None = None
    cos: NDArray[np.float64] | None = None
    sin: NDArray[np.float64] | None = None
    T2: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        if self.feats is not None:
            return int(np.size(self.feats.L))
        assert self.q3 is not None
        return int(self.q3.size)

    def knot_basis(self, knots: tuple[float, ...]) -> list[NDArray[np.float64]]:
        """The Lagrange basis functions of ``knots`` at these traverses' ``q3`` (computed once per knots)."""
        cache: dict[tuple[float, ...], list[NDArray[np.float64]]] = self.__dict__.setdefault("_knots", {})
        if knots not in cache:
            cache[knots] = _knot_basis(_req(self.q3), knots)
        return cache[knots]

    def take(self, index: NDArray[np.intp] | NDArray[np.bool_]) -> FitBasis:
        """The traverses selected by ``index`` (an index array or a mask)."""
        if self.feats is not None:
            feats = Features(*(getattr(self.feats, k)[index] for k in Features.__dataclass_fields__))
            return FitBasis(self.kind, feats)
        assert self.T is not None and self.R is not None
        return FitBasis(
            self.kind, None, _req(self.q3)[index], self.T[:, index], self.R[:, index], _req(self.P)[index],
            _req(self.cos)[index], _req(self.sin)[index], _req(self.T2)[index],
        )


def _req(x: NDArray[np.float64] | None) -> NDArray[np.float64]:
    assert x is not None
    return x


def fit_basis(
    joint: int,
    start: ArrayLike,
    end: ArrayLike,
    q1: ArrayLike,
    q2: ArrayLike,
    q3: ArrayLike,
    theta: ArrayLike,
    psi: ArrayLike,
) -> FitBasis:
    """The :class:`FitBasis` of traverses of ``joint`` (arrays of one length; SI)."""
    st, en, a1, a2, a3, th, ps = (
        np.atleast_1d(x) for x in np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (start, end, q1, q2, q3,
                                                                                               theta, psi)))
    )
    if joint_spec(joint).prismatic:
        return FitBasis("prismatic", features(joint, a1, a2, a3, th, ps))
    # the sinusoids' coefficients from the loads at q = 0, pi/2, pi
    at = []
    for q in (0.0, 0.5 * math.pi, math.pi):
        cols = [a1, a2, a3]
        cols[joint - 1] = np.full_like(a1, q)
        at.append(features(joint, cols[0], cols[1], cols[2], th, ps))

    def coef(name: str) -> NDArray[np.float64]:
        f0, f1, f2 = (getattr(f, name) for f in at)
        mid = 0.5 * (f0 + f2)
        return np.stack([mid, 0.5 * (f0 - f2), f1 - mid])

    T, R = coef("T"), coef("R")
    mid, half = 0.5 * (st + en), 0.5 * (en - st)
    q = mid[:, None] + half[:, None] * _GL_X
    c, s = np.cos(q), np.sin(q)
    t_along = T[0][:, None] + T[1][:, None] * c + T[2][:, None] * s
    return FitBasis("rotary", None, a3, T, R, at[0].P, c, s, t_along**2)


def _knot_basis(q3: NDArray[np.float64], knots: tuple[float, ...]) -> list[NDArray[np.float64]]:
    """The Lagrange basis functions of ``knots`` at ``q3`` (one array per knot)."""
    return [_lagrange(q3, knots, [1.0 if i == k else 0.0 for i in range(len(knots))]) for k in range(len(knots))]


def average_and_jacobian(
    spec: FamilySpec, values: ArrayLike, basis: FitBasis
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Average step over each traverse of ``basis`` (m or rad; nan where it would stall) and its
    derivative with respect to the parameters ``values`` (SI), ``(n,)`` and ``(n, p)``.

    The same averages as :func:`average_from_features` ((F1)-(F5); rotary: the harmonic mean of
    (F3) at the 48 nodes), with the derivatives in closed form: for a rotary joint
    ``d avg / d x = avg^2 sum_k (w_k / 2) g_k^-2 d g_k / d x``, and ``g`` is linear in every
    parameter of (F3).
    """
    v = np.asarray(values, dtype=float)
    if basis.kind == "prismatic":
        return _prismatic_average_and_jacobian(spec, v, basis)
    return _rotary_average_and_jacobian(spec, v, basis)


def _prismatic_average_and_jacobian(
    spec: FamilySpec, v: NDArray[np.float64], basis: FitBasis
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(F1), (F2), (F4), (F5) at the poses and their derivatives (the step is the traverse's average)."""
    names = spec.names
    f = basis.feats
    assert f is not None
    idx = {name: i for i, (name, _) in enumerate(names)}

    def val(name: str) -> float:
        return float(v[idx[name]]) if name in idx else 0.0

    ac = f.abs_cos_q2
    eta = 1.0 - val("b") * ac - val("b2") * ac**2
    den = 1.0 + val("k") * f.X if "k" in idx else np.ones_like(f.L)
    lam = f.L / den
    c_eff = val("c") + val("m") * ac
    core = val("a") - c_eff * lam - val("e") * lam**2 - val("f") * f.X - val("h") * f.Y
    g = eta * core
    jac = np.empty((g.size, len(names)))
    for i, (name, _) in enumerate(names):
        if name == "a":
            jac[:, i] = eta
        elif name == "b":
            jac[:, i] = -ac * core
        elif name == "b2":
            jac[:, i] = -(ac**2) * core
        elif name == "c":
            jac[:, i] = -eta * lam
        elif name == "m":
            jac[:, i] = -eta * ac * lam
        elif name == "e":
            jac[:, i] = -eta * lam**2
        elif name == "f":
            jac[:, i] = -eta * f.X
        elif name == "h":
            jac[:, i] = -eta * f.Y
        elif name == "k":
            jac[:, i] = eta * (c_eff + 2.0 * val("e") * lam) * lam * f.X / den
        else:  # pragma: no cover - every prismatic name is above
            raise KeyError(name)
    ok = g > 0.0
    return np.where(ok, g, np.nan), jac


def _rotary_average_and_jacobian(
    spec: FamilySpec, v: NDArray[np.float64], basis: FitBasis
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(F3)'s harmonic mean along each traverse and its derivatives (``g`` is linear in every parameter)."""
    names = spec.names
    q3, T, R, P = _req(basis.q3), _req(basis.T), _req(basis.R), _req(basis.P)
    groups: dict[str, list[tuple[int, float | None]]] = {}
    for i, (name, knot) in enumerate(names):
        groups.setdefault(name, []).append((i, knot))

    def knots_of(name: str) -> tuple[float, ...]:
        return tuple(float(k) for _, k in groups[name] if k is not None)

    def of_q3(name: str) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]]:
        if name not in groups:
            return np.zeros_like(q3), []
        items = groups[name]
        if len(items) == 1 and items[0][1] is None:
            return np.full_like(q3, v[items[0][0]]), [np.ones_like(q3)]
        b = basis.knot_basis(knots_of(name))
        return sum((v[i] * bk for (i, _), bk in zip(items, b, strict=True)), np.zeros_like(q3)), b

    def scalar(name: str) -> float:
        return float(v[groups[name][0][0]]) if name in groups else 0.0

    G, g_basis = of_q3("gamma0")
    D, d_basis = of_q3("d")
    e, fcoef, t2 = scalar("e"), scalar("f"), scalar("t2")
    A = G + fcoef * P + D * T[0] + e * R[0]
    B = D * T[1] + e * R[1]
    C = D * T[2] + e * R[2]
    cs, sn = _req(basis.cos), _req(basis.sin)
    g = A[:, None] + B[:, None] * cs + C[:, None] * sn
    if t2:
        g = g + t2 * _req(basis.T2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / g
        avg = 1.0 / (0.5 * (inv @ _GL_W))
        wgt = (0.5 * _GL_W) * inv**2
        s0 = wgt.sum(axis=1)
        s1 = np.einsum("ik,ik->i", wgt, cs)
        s2 = np.einsum("ik,ik->i", wgt, sn)
        s3 = np.einsum("ik,ik->i", wgt, _req(basis.T2)) if "t2" in groups else None
        a2 = avg**2
    jac = np.empty((q3.size, len(names)))
    for k, (i, _) in enumerate(groups.get("gamma0", [])):
        jac[:, i] = a2 * s0 * g_basis[k]
    for k, (i, _) in enumerate(groups.get("d", [])):
        jac[:, i] = a2 * d_basis[k] * (T[0] * s0 + T[1] * s1 + T[2] * s2)
    if "e" in groups:
        jac[:, groups["e"][0][0]] = a2 * (R[0] * s0 + R[1] * s1 + R[2] * s2)
    if "f" in groups:
        jac[:, groups["f"][0][0]] = a2 * P * s0
    if s3 is not None:
        jac[:, groups["t2"][0][0]] = a2 * s3
    ok = np.all(g > 0.0, axis=1)
    return np.where(ok, avg, np.nan), jac


def average_over_traverse(
    spec: FamilySpec,
    values: ArrayLike,
    joint: int,
    start: ArrayLike,
    end: ArrayLike,
    q1: ArrayLike,
    q2: ArrayLike,
    q3: ArrayLike,
    theta: ArrayLike,
    psi: ArrayLike,
    scale: float = 1.0,
) -> NDArray[np.float64]:
    """Average step over traverses, ``|end - start| / integral dq / gamma`` (m or rad; vectorised).

    ``nan`` where the step is <= 0 somewhere on the way (the joint would stall).
    """
    f = traverse_features(joint, start, end, q1, q2, q3, theta, psi)
    return average_from_features(spec, values, f, scale)


# ---------------------------------------------------------------- params and model


@dataclass(frozen=True)
class FamilyParams:
    """Parameters of a family for one joint and direction (SI).

    Attributes
    ----------
    family : str
        The family's name (see :data:`FAMILIES`).
    joint : int
    values : tuple of float
        In the order of the family's ``names``: m for steps of joint 3 (``b``, ``b2``: 1),
        rad for rotary joints.
    scale : float
        Step scale ``s`` of (F1)/(F3), 1 after a calibration.
    """

    family: str
    joint: int
    values: tuple[float, ...]
    scale: float = 1.0

    @property
    def spec(self) -> FamilySpec:
        return family_spec(self.joint, self.family)

    @property
    def kind(self) -> str:
        return joint_spec(self.joint).kind

    def names(self) -> list[tuple[str, float | None]]:
        return list(self.spec.names)

    def unit(self, name: str) -> str:
        if name in RATIO_NAMES:
            return "1"
        return joint_spec(self.joint).unit

    def as_vector(self) -> NDArray[np.float64]:
        return np.array(self.values, dtype=float)

    def at(self, q3: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Rotary: ``(gamma0, d)`` at ``q3`` (m): the step with no load and its change per unit torque term."""
        q = np.asarray(q3, dtype=float)
        z = np.zeros_like(q)
        spec = self.spec
        linear = [0.0 if n == "t2" else v for (n, _), v in zip(spec.names, self.values, strict=True)]
        g0 = evaluate(spec, linear, Features(z, z, z, z, z, z, z, q), self.scale)
        g1 = evaluate(spec, linear, Features(z, z, z, z, z + 1.0, z, z, q), self.scale)
        return g0, g1 - g0

    def scaled(self, factor: float) -> FamilyParams:
        """The same model with every step multiplied by ``factor``."""
        return FamilyParams(self.family, self.joint, self.values, self.scale * float(factor))

    def check_physical(self) -> None:
        """Raise :class:`NonPhysicalError` unless the step is > 0 over a grid of every pose (more than
        :data:`~stickslip.models.paper.STALL_RATIO` of its largest there: zero to rounding is a stall)."""
        g = _pose_grid_gamma(self)
        if not np.all(np.isfinite(g)) or not float(np.min(g)) > STALL_RATIO * float(np.max(np.abs(g))):
            raise NonPhysicalError(
                f"family {self.family}: the step would be <= 0 (or stall) in some pose "
                f"(smallest {float(np.nanmin(g)):.3g})"
            )


def _pose_grid_gamma(p: FamilyParams) -> NDArray[np.float64]:
    rng = np.random.default_rng(12345)
    n = 4000
    q1 = rng.uniform(kin.JOINTS[1].lower, kin.JOINTS[1].upper, n)
    q2 = rng.uniform(kin.JOINTS[2].lower, kin.JOINTS[2].upper, n)
    q3 = rng.uniform(0.0, kin.Q3_MAX, n)
    th = rng.uniform(-math.pi / 2, math.pi / 2, n)
    ps = rng.uniform(-math.pi / 2, math.pi / 2, n)
    return evaluate(p.spec, p.values, features(p.joint, q1, q2, q3, th, ps), p.scale)


@dataclass(frozen=True)
class FamilyModel(JointModel):
    """A :class:`~stickslip.models.JointModel` whose step follows a family of (F1)-(F5), or an average of them.

    With ``members`` empty the step is the family ``params``'s. With ``members``, the
    step is the weighted average ``sum_k w_k gamma_k(pose)`` of those families (model
    averaging, docs/models.md §3), and ``params`` is the member with the largest weight
    (what ``parameters()``, standard errors and covariances describe).
    """

    params: FamilyParams  # type: ignore[assignment]  # narrows the paper's Params
    extra: dict[str, object] = field(default_factory=dict, compare=False)
    members: tuple[tuple[float, FamilyParams], ...] = ()
    """``(weight, params)`` of an averaged model (weights > 0, summing to 1); empty for one family."""
    member_labels: tuple[str, ...] = field(default=(), compare=False)
    """The selection's label of each member, in the order of ``members``: the family's name, with
    ``+shared`` where a parameter is shared by both directions (``normal`` and ``normal+shared`` are two
    members with the same ``params.family``); empty where not known (a file written before the labels)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.member_labels and len(self.member_labels) != len(self.members):
            raise ValueError(f"{len(self.member_labels)} member labels for {len(self.members)} members")

    @property
    def family(self) -> str:
        return self.params.family

    def parts(self) -> tuple[tuple[float, FamilyParams], ...]:
        """``(weight, params)`` of every family in the model (one with weight 1 unless averaged)."""
        return self.members if self.members else ((1.0, self.params),)

    def map_params(self, fn: Callable[[FamilyParams], FamilyParams]) -> FamilyModel:
        """The same model with ``fn`` applied to the parameters of every family in it."""
        return FamilyModel(
            self.joint,
            self.direction,
            fn(self.params),
            members=tuple((w, fn(p)) for w, p in self.members),
            member_labels=self.member_labels,
        )

    def _mix(self, f: Features) -> NDArray[np.float64]:
        out = np.zeros(np.shape(f.L))
        for w, p in self.parts():
            out = out + w * evaluate(p.spec, p.values, f, p.scale)
        return out

    def gamma(
        self, q1: ArrayLike, q2: ArrayLike, q3: ArrayLike, theta: ArrayLike, psi: ArrayLike
    ) -> NDArray[np.float64]:
        """Mean step size in a pose (m or rad), (F1)-(F5) (the weighted average of the members if averaged)."""
        return self._mix(features(self.joint, q1, q2, q3, theta, psi))

    def check_physical(self) -> None:
        """Raise :class:`NonPhysicalError` unless the step is > 0 over a grid of every pose (more than
        :data:`~stickslip.models.paper.STALL_RATIO` of its largest there: zero to rounding is a stall)."""
        g = sum(w * _pose_grid_gamma(p) for w, p in self.parts())
        if not np.all(np.isfinite(g)) or not float(np.min(g)) > STALL_RATIO * float(np.max(np.abs(g))):
            raise NonPhysicalError(
                f"family {self.family}: the step would be <= 0 (or stall) in some pose "
                f"(smallest {float(np.nanmin(g)):.3g})"
            )

    def rotary_coefficients(
        self, q1: ArrayLike, q2: ArrayLike, q3: ArrayLike, theta: ArrayLike, psi: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(A, alpha, beta)`` with ``gamma(q) ~ A + alpha cos q + beta sin q`` along the joint's travel.

        Exact for every family whose step is sinusoidal along the travel (all but those
        with ``t2``); for those, the least-squares sinusoid over the travel (9 points), for
        the paper's figures. Prismatic: ``(gamma, 0, 0)``.
        """
        if joint_spec(self.joint).prismatic:
            g = self.gamma(q1, q2, q3, theta, psi)
            z = np.zeros_like(g)
            return g, z, z
        spec = kin.JOINTS[self.joint]
        qs = np.linspace(spec.lower, spec.upper, 9)
        design = np.stack([np.ones_like(qs), np.cos(qs), np.sin(qs)], axis=1)
        pinv = np.linalg.pinv(design)  # (3, 9)
        cols = list(np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (q1, q2, q3, theta, psi))))
        args = [c[..., None] for c in cols]
        args[self.joint - 1] = np.broadcast_to(qs, cols[0].shape + qs.shape)
        g = self.gamma(args[0], args[1], args[2], args[3], args[4])
        coef = np.einsum("kn,...n->...k", pinv, g)
        return coef[..., 0], coef[..., 1], coef[..., 2]

    def average_gamma(
        self,
        start: ArrayLike,
        end: ArrayLike,
        q1: ArrayLike,
        q2: ArrayLike,
        q3: ArrayLike,
        theta: ArrayLike,
        psi: ArrayLike,
    ) -> NDArray[np.float64]:
        """Average step over a traverse (m or rad); raises :class:`NonPhysicalError` where it would stall."""
        f = traverse_features(self.joint, start, end, q1, q2, q3, theta, psi)
        out = average_from_gamma(joint_spec(self.joint).kind, self._mix(f))
        if np.any(np.isnan(out)):
            raise NonPhysicalError("the step size reaches zero along the traverse: the joint would stall there")
        return out

    def profile(self, pose: kin.Pose) -> StepProfile | TabulatedProfile:
        """The step along the joint's own travel in ``pose`` (for planning and dead reckoning)."""
        if joint_spec(self.joint).prismatic:
            return StepProfile(float(self.gamma(pose.q1, pose.q2, pose.q3, pose.theta, pose.psi)))
        spec = kin.JOINTS[self.joint]
        pad = 0.05 * spec.span
        q = np.linspace(spec.lower - pad, spec.upper + pad, 4097)
        cols = [np.full_like(q, pose.q1), np.full_like(q, pose.q2), np.full_like(q, pose.q3)]
        cols[self.joint - 1] = q
        g = self.gamma(cols[0], cols[1], cols[2], pose.theta, pose.psi)
        return TabulatedProfile(q, g)


class TabulatedProfile:
    """A step profile along a joint's travel from a table ``gamma(q)`` (planning; same interface as StepProfile).

    ``steps`` integrates ``1 / gamma`` with the trapezoidal rule on the table (4097
    points over the travel: relative error ~1e-8 for the smooth steps of (F3)). Beyond the
    table (5 % of the travel past each end stop) the step is the edge's, in ``steps`` and
    ``inverse`` alike, so the two stay each other's inverse there.
    """

    def __init__(self, q: NDArray[np.float64], gamma: NDArray[np.float64]) -> None:
        if not np.all(gamma > 0.0):
            raise NonPhysicalError("the step size reaches zero along the travel: the joint would stall there")
        self.q = q
        self.g = gamma
        inv = 1.0 / gamma
        self.cum = np.concatenate(([0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(q))))
        self.A = float(np.mean(gamma))

    def gamma(self, q: float) -> float:
        """Mean step size at ``q``."""
        return float(np.interp(q, self.q, self.g))

    def _F(self, q: float) -> float:
        """Steps from the table's start to ``q``; beyond the table, at the edge's step (as :meth:`inverse` goes)."""
        if q < self.q[0]:
            return float((q - self.q[0]) / self.g[0])
        if q > self.q[-1]:
            return float(self.cum[-1] + (q - self.q[-1]) / self.g[-1])
        return float(np.interp(q, self.q, self.cum))

    def steps(self, q0: float, q1: float) -> float:
        """Real-valued number of steps from ``q0`` to ``q1`` (>= 0)."""
        return abs(self._F(q1) - self._F(q0))

    def inverse(self, q0: float, n: float, sign: int) -> float:
        """Dead reckoning: where the joint is after ``n`` steps from ``q0`` in direction ``sign``."""
        target = self._F(q0) + sign * n
        if target < self.cum[0]:  # beyond the table: at the edge's step, as _F counts there
            return float(self.q[0] + (target - self.cum[0]) * self.g[0])
        if target > self.cum[-1]:
            return float(self.q[-1] + (target - self.cum[-1]) * self.g[-1])
        return float(np.interp(target, self.cum, self.q))
