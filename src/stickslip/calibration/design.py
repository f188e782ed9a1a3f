"""Which traverse next: poses that most reduce the prediction uncertainty (docs/models.md §6).

For one joint, the calibration's model in each direction is linearised in its parameters:
``g(pose) = d log gamma_avg / d theta`` for a full-range traverse at ``pose``. With the
information matrix ``M`` of the parameters (the inverse of the calibration's covariance;
for the paper's procedure, which keeps none, that of its own traverses at the paper's poses;
else a weak ridge) and ``sigma`` the relative model error,
a traverse at pose ``c`` adds ``g_c g_c^T / sigma^2`` to ``M``. The workspace's average
prediction variance is ``trace(W M^-1)`` with ``W`` the mean of ``g g^T`` over random
workspace poses (I-optimality). Poses are chosen greedily: each time the candidate
whose + and - traverses reduce that trace most (Sherman-Morrison, exact for one added
traverse), then ``M`` is updated and the next is chosen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..models import PrismaticParams, RotaryParams
from ..models.families import FamilyModel, FamilyParams, average_from_features, traverse_features
from .family_fit import unit_scale
from .groups import load_coordinates_of, load_quantities
from .intervals import model_sigma
from .paper import PRISMATIC_PAPER_POSES, ROTARY_PAPER_POSES
from .result import Calibration

__all__ = ["Suggestion", "suggest_poses", "workspace_poses", "spread_poses", "check_poses", "load_coordinates"]


@dataclass(frozen=True)
class Suggestion:
    """A pose to traverse next.

    Attributes
    ----------
    joint : int
    pose : Pose
        The fixed joints and the tilt (rad, rad, m; rad); the joint's own column is 0.
    rms_sd_before, rms_sd_after : float
        Root-mean-square relative standard deviation of the mean-step prediction over
        the workspace, before and after traversing this pose in both directions (1).
    """

    joint: int
    pose: kin.Pose
    rms_sd_before: float
    rms_sd_after: float

    def as_dict(self) -> dict[str, object]:
        return {
            "joint": self.joint,
            **{k: float(v) for k, v in self.pose._asdict().items()},
            "rms_sd_before": self.rms_sd_before,
            "rms_sd_after": self.rms_sd_after,
        }


def workspace_poses(joint: int, n: int, seed: int = 0, stream: int = 0) -> list[kin.Pose]:
    """``n`` random poses of the workspace for ``joint`` (tilts within ±90° and ±60°), reproducible
    (``stream`` > 0: another sequence of the same ``seed``)."""
    rng = np.random.default_rng([seed, joint] if stream == 0 else [seed, joint, stream])
    out = []
    for _ in range(n):
        q1 = 0.0 if joint == 1 else float(rng.uniform(-0.5, 0.5))
        q2 = float(rng.uniform(kin.JOINTS[2].lower, kin.JOINTS[2].upper)) if joint != 2 else 0.0
        q3 = float(rng.uniform(0.0, kin.Q3_MAX)) if joint != 3 else 0.0
        out.append(kin.Pose(q1, q2, q3, float(rng.uniform(-math.pi / 2, math.pi / 2)),
                            float(rng.uniform(-math.pi / 3, math.pi / 3))))
    return out


def _as_family(model: object) -> FamilyParams:
    if isinstance(model, FamilyModel):
        return model.params
    p = getattr(model, "params", None)
    j = int(getattr(model, "joint", 0))
    if isinstance(p, PrismaticParams):
        return FamilyParams("paper", 3, (p.a, p.b, p.c))
    if isinstance(p, RotaryParams):
        return FamilyParams("paper", j, (p.gamma0[0], p.gamma0[1], p.d[0], p.d[1]))
    raise TypeError(f"no model family for {type(model).__name__}")


def _gradients(fp: FamilyParams, direction: str, poses: list[kin.Pose]) -> NDArray[np.float64]:
    """``d log gamma_avg / d theta~`` (scaled parameters) of full-range traverses at ``poses``, (n, p)."""
    spec = fp.spec
    spec_j = kin.JOINTS[fp.joint]
    start, end = (spec_j.lower, spec_j.upper) if direction == "+" else (spec_j.upper, spec_j.lower)
    cols = np.array([list(p) for p in poses], dtype=float)
    f = traverse_features(fp.joint, start, end, cols[:, 0], cols[:, 1], cols[:, 2], cols[:, 3], cols[:, 4])
    us = unit_scale(spec, fp.joint)
    x = np.array(fp.values) / us
    base = np.log(average_from_features(spec, x * us, f, fp.scale))
    out = np.empty((len(poses), len(x)))
    for i in range(len(x)):
        h = 1e-5 * max(1.0, abs(x[i]))
        e = np.zeros_like(x)
        e[i] = h
        out[:, i] = (np.log(average_from_features(spec, (x + e) * us, f, fp.scale)) - base) / h
    return out


def suggest_poses(
    cal: Calibration, joint: int, n: int = 4, candidates: int = 300, workspace: int = 300, seed: int = 0
) -> list[Suggestion]:
    """The ``n`` poses whose traverses (both calibrated directions) most reduce the workspace's
    average prediction variance of ``joint``'s mean step (greedy I-optimal design)."""
    dirs = sorted(d for j, d in cal.models if j == joint)
    if not dirs:
        raise KeyError(f"joint {joint} is not in this calibration")
    cand = workspace_poses(joint, candidates, seed + 1)
    work = workspace_poses(joint, workspace, seed + 2)
    state = {}
    for d in dirs:
        fp = _as_family(cal.models[(joint, d)])
        sig, _ = model_sigma(cal, joint, d)
        us = unit_scale(fp.spec, joint)
        cov = cal.covariance.get((joint, d))
        paper = _paper_poses(joint) if cal.method.startswith("paper") else []
        if cov is not None and cov.shape == (len(us), len(us)):
            m = np.linalg.pinv(cov / np.outer(us, us)) + 1e-9 * np.eye(len(us))
        elif paper:  # the paper's procedure keeps no covariance: the information of its own traverses
            gp = _gradients(fp, d, paper)
            m = gp.T @ gp / sig**2 + 1e-9 * np.eye(len(us))
        else:
            m = 1e-6 * np.eye(len(us))  # nothing known: design from scratch
        gw = _gradients(fp, d, work)
        state[d] = (m, gw.T @ gw / len(work), _gradients(fp, d, cand), sig)

    def rms() -> float:
        return math.sqrt(sum(float(np.trace(w @ np.linalg.inv(m))) for m, w, _, _ in state.values()) / len(state))

    out: list[Suggestion] = []
    chosen: set[int] = set()
    for _ in range(n):
        before = rms()
        gain = np.zeros(len(cand))
        for m, w, gc, sig in state.values():
            minv = np.linalg.inv(m)
            a = gc @ minv  # (c, p)
            num = np.einsum("cp,pq,cq->c", a, w, a)
            den = sig**2 + np.einsum("cp,cp->c", a, gc)
            gain += num / den
        gain[list(chosen)] = -np.inf
        k = int(np.argmax(gain))
        chosen.add(k)
        for d, (m, w, gc, sig) in list(state.items()):
            state[d] = (m + np.outer(gc[k], gc[k]) / sig**2, w, gc, sig)
        out.append(Suggestion(joint, cand[k], before, rms()))
    return out


def _paper_poses(joint: int) -> list[kin.Pose]:
    """The poses of the paper's calibration traverses of ``joint`` (none for joint 1), the joint's own
    column 0: the traverses a calibration by the paper's procedure was made from."""
    if joint == 3:
        return [kin.Pose(0.0, q2, 0.0, th, ps) for q2, th, ps in PRISMATIC_PAPER_POSES.values()]
    if joint == 2:
        return [kin.Pose(0.0, 0.0, q3, th, ps) for q3, th, ps in ROTARY_PAPER_POSES]
    return []


def load_coordinates(joint: int, poses: list[kin.Pose]) -> NDArray[np.float64]:
    """Where traverses at ``poses`` lie in the space of what the step depends on, ``(n, k)`` (1).

    :func:`~.groups.load_coordinates_of` (its one home) for a list of :class:`~stickslip.kinematics.Pose`.
    """
    return load_coordinates_of(joint, np.array([list(p) for p in poses], dtype=float))


def spread_poses(
    joint: int,
    n: int,
    seed: int = 0,
    existing: list[kin.Pose] | None = None,
    candidates: int = 2000,
    criterion: str | None = None,
) -> list[kin.Pose]:
    """``n`` poses for ``joint`` spread over its load space, reproducible (docs/models.md §3).

    From ``candidates`` random workspace poses (:func:`workspace_poses`), poses are added one
    at a time to ``existing`` (e.g. the paper's calibration poses) by ``criterion``:

    * ``"maxpro"`` (the default for joint 3): a greedy maximum projection design. The next
      pose is the candidate that adds least to ``sum_j prod_q 1 / d_q(c, j)^2`` over the poses
      there, ``d_q`` the distance in one load quantity (:func:`~.groups.load_quantities`). A
      pose close to another in *any* quantity is penalised, so every quantity's range is
      filled, its middle included;
    * ``"maximin"`` (the default for the rotary joints): the candidate farthest (Euclidean, in
      :func:`load_coordinates`) from every pose there. It covers the corners of the load
      space first and leaves each coordinate's middle to interpolation.

    Without ``existing`` the first pose is the candidate farthest from the candidates' mean.
    """
    if criterion is None:
        criterion = "maxpro" if kin.joint_spec(joint).prismatic else "maximin"
    if criterion not in ("maxpro", "maximin"):
        raise ValueError(f"criterion {criterion!r}: not 'maxpro' or 'maximin'")
    if n < 1:
        return []
    cand = workspace_poses(joint, candidates, seed)
    x = load_coordinates(joint, cand)
    sites = load_coordinates(joint, existing) if existing else np.empty((0, x.shape[1]))
    pick = _max_projection if criterion == "maxpro" else _maximin
    return [cand[k] for k in pick(joint, x, sites, n)]


def check_poses(joint: int, n: int, seed: int = 0) -> list[kin.Pose]:
    """``n`` random workspace poses for ``joint``'s check traverses (docs/models.md §4), reproducible.

    Traversed after the calibration's poses and not fitted (:func:`~.check.apply_check`): random, so that
    they lie between the calibrated poses as new poses do (a spread design's poses lie at its edges).
    Their own stream of ``seed``, not :func:`spread_poses`' candidates.
    """
    return workspace_poses(joint, n, seed, stream=1) if n > 0 else []


def _farthest_from_mean(x: NDArray[np.float64]) -> int:
    return int(np.argmax(np.linalg.norm(x - x.mean(axis=0), axis=1)))


def _maximin(joint: int, x: NDArray[np.float64], sites: NDArray[np.float64], n: int) -> list[int]:
    """Greedy maximin: ``n`` rows of ``x``, each the farthest from ``sites`` and the rows chosen before."""
    if len(sites):
        d_min = np.min(np.linalg.norm(x[:, None, :] - sites[None, :, :], axis=-1), axis=1)
    else:  # the first is the farthest from the candidates' mean
        d_min = np.linalg.norm(x - x.mean(axis=0), axis=1)
    out: list[int] = []
    for _ in range(n):
        k = int(np.argmax(d_min))
        out.append(k)
        d_min = np.minimum(d_min, np.linalg.norm(x - x[k], axis=1))
    return out


def _max_projection(joint: int, x: NDArray[np.float64], sites: NDArray[np.float64], n: int) -> list[int]:
    """Greedy maximum projection: ``n`` rows of ``x``, each adding least to the criterion's sum."""
    quantities = load_quantities(joint)
    # a floor under each squared distance (a millionth of the quantity's variance over the
    # candidates) keeps a quantity that is equal at two poses finite
    eps = [1e-6 * float(np.sum(np.var(x[:, q], axis=0))) + 1e-300 for q in quantities]

    def log_term(site: NDArray[np.float64]) -> NDArray[np.float64]:
        """``-sum_q log(d_q^2)`` of every candidate to ``site``: the log of its criterion term."""
        out = np.zeros(len(x))
        for q, e in zip(quantities, eps, strict=True):
            out -= np.log(np.sum((x[:, q] - site[q]) ** 2, axis=1) + e)
        return out

    crit = np.full(len(x), -np.inf)  # log of the criterion's sum, per candidate
    for site in sites:
        crit = np.logaddexp(crit, log_term(site))
    out: list[int] = []
    for _ in range(n):
        k = int(np.argmin(crit)) if len(sites) or out else _farthest_from_mean(x)
        out.append(k)
        crit = np.logaddexp(crit, log_term(x[k]))
        crit[k] = np.inf
    return out
