"""Which poses the cross-validation leaves out together (docs/models.md §3).

A calibration's error at *new* poses is what matters, and a new pose is usually farther
from the calibration's poses (in the space of the loads the step depends on) than a
calibration pose is from its neighbours: leaving out one pose at a time measures
interpolation between close neighbours and promises too little error; leaving out large
regions measures extrapolation into empty parts of the workspace and promises too much.

The folds here are chosen by *nearest-neighbour distance matching* (kNNDM: Linnenbrink,
Milà, Ludwig & Meyer, Geoscientific Model Development 2024, after Milà et al., Methods in
Ecology and Evolution 2022): the poses are clustered by k-means in the load space
(:func:`~.groups.load_coordinates_of`) into ``q`` clusters, clusters are merged into at most
:data:`MAX_FOLDS` folds, and ``q`` is chosen so that the distribution of the distance from a
held-out pose to the nearest pose the refit keeps is closest (Wasserstein distance) to the
distribution of the distance from a random pose of the workspace
(:func:`~.design.workspace_poses`) to the nearest calibration pose. With well-spread poses
this is close to leaving one out; with poses bunched in one corner, whole regions are
held out, as new poses in the rest of the workspace will be.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .groups import load_coordinates_of, nearest

__all__ = [
    "FoldDesign", "cv_folds", "kmeans", "workspace_coordinates", "workspace_pose_array", "MAX_FOLDS",
    "WORKSPACE_SAMPLE", "DESIGN_SAMPLE",
]

MAX_FOLDS = 10
"""Folds at most when there are more poses than this (below it, up to one fold per pose)."""

WORKSPACE_SAMPLE = 1000
"""Random workspace poses whose distance to the calibration poses the folds are matched to."""

DESIGN_SAMPLE = 400
"""Poses the fold design is made on (a seeded sample of a longer table; the rest join the fold
of their nearest sampled pose)."""


@dataclass(frozen=True)
class FoldDesign:
    """How the poses were split.

    Attributes
    ----------
    folds : ndarray of int
        The fold of each pose, from 0.
    n_folds : int
    clusters : int
        k-means clusters the folds were made of (``= poses``: one pose per cluster).
    mismatch : float
        Wasserstein distance between the held-out and the workspace nearest-neighbour
        distances (load-space units, 1).
    """

    folds: NDArray[np.int64]
    n_folds: int
    clusters: int
    mismatch: float


@functools.lru_cache(maxsize=4)
def workspace_pose_array(joint: int) -> NDArray[np.float64]:
    """:data:`WORKSPACE_SAMPLE` random workspace poses of ``joint`` (rows of q1, q2, q3, theta, psi; SI),
    seeded, computed once: the new poses the cross-validation and the model error are about."""
    from .design import workspace_poses

    out = np.array([list(p) for p in workspace_poses(joint, WORKSPACE_SAMPLE, seed=33)], dtype=float)
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=4)
def workspace_coordinates(joint: int) -> NDArray[np.float64]:
    """Load coordinates of :func:`workspace_pose_array` (computed once)."""
    out = load_coordinates_of(joint, workspace_pose_array(joint))
    out.setflags(write=False)
    return out


def kmeans(x: NDArray[np.float64], k: int, seed: int = 0, iterations: int = 30) -> NDArray[np.int64]:
    """k-means labels (k-means++ start seeded with ``seed``, Lloyd's iterations), numbered from 0, none empty."""
    n = len(x)
    k = max(1, min(k, n))
    if k == n:
        return np.arange(n, dtype=np.int64)
    rng = np.random.default_rng(seed)
    centres = [x[int(rng.integers(n))]]
    d2 = np.sum((x - centres[0]) ** 2, axis=1)
    for _ in range(1, k):
        total = float(d2.sum())
        i = int(rng.choice(n, p=d2 / total)) if total > 0 else int(rng.integers(n))
        centres.append(x[i])
        d2 = np.minimum(d2, np.sum((x - x[i]) ** 2, axis=1))
    c = np.array(centres)
    label = np.full(n, -1, dtype=np.int64)
    sq = np.sum(x**2, axis=1)[:, None]
    for _ in range(iterations):
        dist = sq - 2.0 * x @ c.T + np.sum(c**2, axis=1)[None, :]
        new = np.argmin(dist, axis=1).astype(np.int64)
        if np.array_equal(new, label):
            break
        label = new
        counts = np.bincount(label, minlength=len(c))
        sums = np.zeros_like(c)
        np.add.at(sums, label, x)
        keep = counts > 0
        c[keep] = sums[keep] / counts[keep, None]
    _, out = np.unique(label, return_inverse=True)
    return np.asarray(out, dtype=np.int64).reshape(-1)


def _merge(labels: NDArray[np.int64], n_folds: int) -> NDArray[np.int64]:
    """Clusters merged into ``n_folds`` folds of similar size (largest cluster to the smallest fold)."""
    counts = np.bincount(labels)
    if len(counts) <= n_folds:
        return labels
    fold_of = np.empty(len(counts), dtype=np.int64)
    size = np.zeros(n_folds)
    for c in np.argsort(-counts, kind="stable"):
        f = int(np.argmin(size))
        fold_of[c] = f
        size[f] += counts[c]
    return fold_of[labels]


def _held_out_distances(dist: NDArray[np.float64], folds: NDArray[np.int64]) -> NDArray[np.float64]:
    """Each pose's distance to the nearest pose in another fold (``dist``: pairwise distances)."""
    same = folds[:, None] == folds[None, :]
    out: NDArray[np.float64] = np.where(same, np.inf, dist).min(axis=1)
    return out


def _candidates(n: int) -> list[int]:
    """Numbers of clusters to try: every one up to 20 poses, doubling above up to a quarter of them,
    and ``n`` (one pose per cluster)."""
    if n <= 20:
        return list(range(2, n + 1))
    out = {n}
    q = 2
    while q <= n // 4:
        out.add(q)
        q *= 2
    return sorted(out)


def wasserstein(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """The 1-Wasserstein distance between the empirical distributions of ``a`` and ``b``:
    the area between their cumulative distribution functions."""
    a, b = np.sort(np.asarray(a, dtype=float)), np.sort(np.asarray(b, dtype=float))
    grid = np.concatenate([a, b])
    grid.sort(kind="mergesort")
    fa = np.searchsorted(a, grid[:-1], side="right") / a.size
    fb = np.searchsorted(b, grid[:-1], side="right") / b.size
    return float(np.sum(np.abs(fa - fb) * np.diff(grid)))


def cv_folds(coords: NDArray[np.float64], workspace: NDArray[np.float64], seed: int = 0) -> FoldDesign:
    """Folds of the poses at ``coords`` (load coordinates, ``(n, k)``) matched to new poses at ``workspace``.

    See the module's docstring. Deterministic (``seed``).
    """
    x = np.asarray(coords, dtype=float)
    n = len(x)
    if n < 2:
        return FoldDesign(np.zeros(n, dtype=np.int64), 0, n, float("nan"))
    rng = np.random.default_rng(seed)
    sample = np.sort(rng.choice(n, DESIGN_SAMPLE, replace=False)) if n > DESIGN_SAMPLE else np.arange(n)
    xs = x[sample]
    m = len(xs)
    max_folds = m if m <= 2 * MAX_FOLDS else MAX_FOLDS
    d_pred = nearest(np.asarray(workspace, dtype=float), xs)[0]
    sq = np.sum(xs**2, axis=1)
    dist = np.sqrt(np.maximum(sq[:, None] - 2.0 * xs @ xs.T + sq[None, :], 0.0))
    best: tuple[float, int, NDArray[np.int64]] | None = None
    for q in reversed(_candidates(m)):  # from one pose per cluster down: a tie keeps the finer folds
        labels = _merge(kmeans(xs, q, seed), max_folds)
        if labels.max() < 1:
            continue
        w = wasserstein(_held_out_distances(dist, labels), d_pred)
        if best is None or w < best[0] - 1e-12:
            best = (w, q, labels)
    assert best is not None
    w, q, labels = best
    if m < n:  # the rest of a long table: the fold of the nearest sampled pose
        labels = labels[nearest(x, xs)[1]]
    _, folds = np.unique(labels, return_inverse=True)
    folds = np.asarray(folds, dtype=np.int64).reshape(-1)
    return FoldDesign(folds, int(folds.max()) + 1, q, w)
