"""A calibration's traverses grouped once, by joint and direction and by pose, and handed down.

:func:`group_traverses` sorts the traverses of one calibration into joints and directions
and, per joint, into what a fit needs (:class:`JointData`: the traverses as a
:class:`~stickslip.models.families.FitBasis`, their measured averages, the pose each was
taken in, where the poses lie in the load space). Every later stage (the paper's
procedure, the families' fits, the cross-validation, the provenance) takes these groups
instead of regrouping the traverses.
"""

from __future__ import annotations

import operator
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..measurements import Traverse, check_traverses
from ..models.families import FitBasis, features, fit_basis

__all__ = ["POSE_DECIMALS", "JointData", "TraverseGroups", "group_traverses", "load_coordinates_of",
           "load_quantities", "nearest", "pose_keys"]

_COLS = ("start", "end", "q1", "q2", "q3", "theta", "psi")

POSE_DECIMALS = 4
"""Two traverses of a joint lie at one pose when their other joints and tilts agree to this many decimals
(0.1 mm, 0.1 mrad): a pose read back from a table or a device carries float noise far below that, and
no design places two poses that close."""


def pose_keys(joint: int, poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """The key of each pose of ``joint`` (rows ``q1, q2, q3, theta, psi`` in m and rad): the joint's own
    column zeroed, the rest rounded to :data:`POSE_DECIMALS`. Equal rows are one pose."""
    raw = np.array(poses, dtype=float, copy=True)
    raw[:, joint - 1] = 0.0
    return np.round(raw, POSE_DECIMALS)


@dataclass(frozen=True)
class JointData:
    """The traverses of one joint, as the families' fits and their cross-validation use them.

    Attributes
    ----------
    joint : int
    dirs : tuple of str
        The directions present, sorted (``"+"`` before ``"-"``).
    basis : dict
        ``direction -> FitBasis`` of its traverses, in table order.
    gamma : dict
        ``direction ->`` measured average steps (m or rad).
    pose : dict
        ``direction ->`` the pose index (into ``poses``) of each traverse: the fixed joints and
        the tilt, rounded to 1e-4 (rad, m), the moving joint's own column ignored.
    poses : ndarray, shape (n_poses, 5)
        Each distinct pose (q1, q2, q3, theta, psi), SI.
    coords : ndarray, shape (n_poses, k)
        Where each pose lies in the space of the loads the step depends on
        (:func:`load_coordinates_of`), 1.
    """

    joint: int
    dirs: tuple[str, ...]
    basis: dict[str, FitBasis]
    gamma: dict[str, NDArray[np.float64]]
    pose: dict[str, NDArray[np.int64]]
    poses: NDArray[np.float64]
    coords: NDArray[np.float64]

    @property
    def n_poses(self) -> int:
        return int(len(self.poses))

    def n_rows(self) -> int:
        return int(sum(len(g) for g in self.gamma.values()))

    def poses_of(self, direction: str) -> int:
        """Distinct poses among ``direction``'s traverses."""
        return int(np.unique(self.pose[direction]).size)

    def sample(self, rows: int, seed: int = 0) -> JointData:
        """The traverses of a seeded random sample of the poses, at most ``rows`` of them (every traverse
        of each pose taken; at least one pose)."""
        counts = np.zeros(self.n_poses, dtype=np.int64)
        for d in self.dirs:
            counts += np.bincount(self.pose[d], minlength=self.n_poses)
        order = np.random.default_rng(seed).permutation(self.n_poses)
        take = order[: max(1, int(np.searchsorted(np.cumsum(counts[order]), rows, side="right")))]
        chosen = np.zeros(self.n_poses, dtype=bool)
        chosen[take] = True
        renumber = np.cumsum(chosen) - 1
        basis, gamma, pose = {}, {}, {}
        for d in self.dirs:
            m = chosen[self.pose[d]]
            basis[d] = self.basis[d].take(m)
            gamma[d] = self.gamma[d][m]
            pose[d] = renumber[self.pose[d][m]].astype(np.int64)
        dirs = tuple(d for d in self.dirs if gamma[d].size)
        return JointData(self.joint, dirs, {d: basis[d] for d in dirs}, {d: gamma[d] for d in dirs},
                         {d: pose[d] for d in dirs}, self.poses[chosen], self.coords[chosen])


def load_coordinates_of(joint: int, poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """Where poses (rows of q1, q2, q3, theta, psi; SI) lie in the space of what the step depends on.

    Joint 3: the axial load ``L``, the loads across the axis ``X``, ``Y`` and ``|cos q2|``
    ((F1), (F2)). Rotary joints: the torque term ``T``, the radial and axial loads ``R``,
    ``P`` at five points along a full-range traverse (each group divided by sqrt(5), so
    that each quantity weighs as much as one coordinate) and ``2 q3 / 12 mm - 1`` ((F3)).
    Every coordinate is within [-1, 1]. Shape ``(n, 4)`` or ``(n, 16)``.
    """
    cols = np.asarray(poses, dtype=float).reshape(-1, 5)
    if kin.joint_spec(joint).prismatic:
        f = features(joint, cols[:, 0], cols[:, 1], cols[:, 2], cols[:, 3], cols[:, 4])
        return np.stack([f.L, f.X, f.Y, f.abs_cos_q2], axis=1)
    spec = kin.JOINTS[joint]
    q = np.linspace(spec.lower, spec.upper, 5)
    args = [cols[:, k, None] * np.ones_like(q) for k in range(5)]
    args[joint - 1] = np.broadcast_to(q, (len(cols), 5))
    f = features(joint, *args)
    g = 1.0 / np.sqrt(5.0)
    return np.concatenate([g * f.T, g * f.R, g * f.P, (2.0 * cols[:, 2:3] / kin.Q3_MAX - 1.0)], axis=1)


def load_quantities(joint: int) -> tuple[slice, ...]:
    """The columns of :func:`load_coordinates_of` that describe one load quantity each.

    Joint 3: ``L``, ``X``, ``Y``, ``|cos q2|``, a column each. Rotary joints: ``T``, ``R``,
    ``P`` (five columns each, the quantity along the traverse) and ``q3``.
    """
    if kin.joint_spec(joint).prismatic:
        return tuple(slice(k, k + 1) for k in range(4))
    return (slice(0, 5), slice(5, 10), slice(10, 15), slice(15, 16))


def nearest(
    points: NDArray[np.float64], sites: NDArray[np.float64], chunk: int = 4096
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Distance from each of ``points`` to the nearest of ``sites`` (Euclidean, rows), and its index.

    Brute force by blocks of ``chunk`` points (memory ``chunk x len(sites)``), so a million
    points against a few hundred sites stays in bounded memory. The nearest site is found with
    one matrix product per block; its distance is then computed from the difference itself, so
    a point's distance does not depend on the block it was in (to the last bit).
    """
    p = np.asarray(points, dtype=float)
    s = np.asarray(sites, dtype=float)
    dist = np.empty(len(p))
    index = np.empty(len(p), dtype=np.int64)
    s2 = np.sum(s**2, axis=1)
    for i in range(0, len(p), chunk):
        block = p[i : i + chunk]
        d2 = np.sum(block**2, axis=1)[:, None] - 2.0 * block @ s.T + s2[None, :]
        k = np.argmin(d2, axis=1)
        index[i : i + chunk] = k
        dist[i : i + chunk] = np.sqrt(np.sum((block - s[k]) ** 2, axis=1))
    return dist, index


class TraverseGroups:
    """The traverses of one calibration, grouped by joint and direction once (and by pose on demand).

    Parameters
    ----------
    traverses : sequence of Traverse
        Refused (:class:`~stickslip.measurements.TableError`) where one could not be a row of a
        measurement table whatever the arm (:func:`~stickslip.measurements.check_traverses`).
    """

    def __init__(self, traverses: Sequence[Traverse]) -> None:
        self.traverses: list[Traverse] = list(traverses)
        check_traverses(self.traverses)  # a tilt in degrees was fitted; steps 0 a ZeroDivisionError
        idx: dict[tuple[int, str], list[int]] = {}
        for i, t in enumerate(self.traverses):
            idx.setdefault((t.joint, t.direction), []).append(i)
        self._index = idx
        self._joint: dict[int, JointData] = {}

    def __len__(self) -> int:
        return len(self.traverses)

    def __bool__(self) -> bool:
        return bool(self.traverses)

    @property
    def keys(self) -> list[tuple[int, str]]:
        """The (joint, direction) pairs present, sorted."""
        return sorted(self._index)

    @property
    def joints(self) -> list[int]:
        return sorted({j for j, _ in self._index})

    def rows(self, key: tuple[int, str]) -> NDArray[np.int64]:
        """The positions in the table of one joint and direction's traverses, in table order."""
        return np.asarray(self._index.get(key, []), dtype=np.int64)

    def of(self, key: tuple[int, str]) -> list[Traverse]:
        """The traverses of one joint and direction, in table order."""
        return [self.traverses[i] for i in self._index.get(key, [])]

    def as_dict(self) -> dict[tuple[int, str], list[Traverse]]:
        """``(joint, direction) -> traverses`` (what :func:`stickslip.calibration.result._group` gave)."""
        return {k: self.of(k) for k in self.keys}

    def only(self, keys: Iterable[tuple[int, str]]) -> TraverseGroups:
        """The traverses of the given (joint, direction) pairs, in table order (a new grouping)."""
        wanted = set(keys)
        return TraverseGroups([t for t in self.traverses if (t.joint, t.direction) in wanted])

    def joint_data(self, joint: int) -> JointData:
        """The :class:`JointData` of ``joint`` (computed once)."""
        if joint not in self._joint:
            self._joint[joint] = _joint_data(joint, {d: self.of((j, d)) for j, d in self.keys if j == joint})
        return self._joint[joint]


def group_traverses(traverses: Sequence[Traverse] | TraverseGroups) -> TraverseGroups:
    """The traverses grouped (a :class:`TraverseGroups` is returned as it is)."""
    return traverses if isinstance(traverses, TraverseGroups) else TraverseGroups(traverses)


def _joint_data(joint: int, by_dir: dict[str, list[Traverse]]) -> JointData:
    dirs = tuple(sorted((d for d, ts in by_dir.items() if ts), key=lambda d: d != "+"))
    cols: dict[str, dict[str, NDArray[np.float64]]] = {}
    for d in dirs:
        ts = by_dir[d]
        cols[d] = {k: np.fromiter(map(operator.attrgetter(k), ts), dtype=float, count=len(ts)) for k in _COLS}
        cols[d]["steps"] = np.fromiter(map(operator.attrgetter("steps"), ts), dtype=float, count=len(ts))
    # poses: the fixed joints and the tilt, rounded, shared by both directions
    raw = np.concatenate([np.stack([cols[d][k] for k in ("q1", "q2", "q3", "theta", "psi")], axis=1)
                          for d in dirs]) if dirs else np.empty((0, 5))
    raw[:, joint - 1] = 0.0
    keyed = pose_keys(joint, raw)
    uniq, first, inverse = np.unique(keyed, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # poses numbered in order of first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    inverse = rank[np.asarray(inverse).reshape(-1)]
    poses = raw[first[order]] if uniq.size else np.empty((0, 5))
    basis: dict[str, FitBasis] = {}
    gamma: dict[str, NDArray[np.float64]] = {}
    pose: dict[str, NDArray[np.int64]] = {}
    k = 0
    for d in dirs:
        c = cols[d]
        basis[d] = fit_basis(joint, c["start"], c["end"], c["q1"], c["q2"], c["q3"], c["theta"], c["psi"])
        gamma[d] = np.abs(c["end"] - c["start"]) / c["steps"]
        n = len(c["start"])
        pose[d] = inverse[k : k + n].astype(np.int64)
        k += n
    return JointData(joint, dirs, basis, gamma, pose, poses, load_coordinates_of(joint, poses))
