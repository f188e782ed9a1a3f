"""The step's drift within a session, from poses traversed twice in it, and the bias the
calibration's fit leaves at the session's end (docs/models.md §4).

A joint's step changes while a session goes on: a cold piezo steps further than a warm one
(the physics arm's warm-up), the room and the drive warm. Every cross-validation of one
session compares traverses of that session, so none can see it; a pose traversed again
later in the same session can.

**The drift** (:func:`session_drifts`, what ``calibrate`` reports). For each joint and
direction, every pair of traverses at the same pose (the fits' pose groups: fixed joints and
tilt to 1e-4) on the same day (consecutive ones where a pose has more) is a measurement of
the relative drift over the traverses between them,
``log(gamma_later / gamma_earlier) = r tau + noise``, ``tau`` the number of the joint's
traverses (both directions) from the earlier to the later one: the joint's own stepping
warms it. The rate ``r`` (per traverse) is the least-squares line through the origin; its
standard error is from the pairs' scatter about the line where there are at least two pairs,
else from the per-step scatter (:data:`~.intervals.STEP_NOISE` over the traverses' steps).

**The bias the fit leaves at the session's end** (:func:`end_bias`, what the intervals add).
A user predicts later in the session, so what matters is how far the *fitted* model is from
the step there, not how far the step moved: a fit through traverses of which only the first
was cold is hardly moved by it, and a repeat in the fit pulls it towards the warm step
already; how much of a drift a fit keeps depends on when in the session it happened (a
warm-up over within the first traverse, a drift that goes on), which two traverses cannot
tell. The latest traverse of each repeated pose (on each day) measures it directly: it is
the session's end, and its relative residual ``e = predicted / measured - 1`` against the
calibration's model is

    e = b + m,   m ~ N(0, s²),   s² = floor²

``b`` the fit's bias at the session's end, ``m`` the model's own misfit at a calibrated pose,
whose size the interval already carries as its ``floor`` (the RMS of the residuals at the
calibrated poses). Over ``k`` repeats the mean residual ``ē`` has ``s² = floor² / k``.
Counting ``ē²`` in the interval would count the misfit twice (once in the floor, once in the
term); the term is the bias alone, estimated by empirical Bayes: a prior
``b ~ N(0, τ²)`` whose variance is the one the residual shows beyond the misfit,
``τ² = max(0, ē² − s²)`` (method of moments), gives the posterior

    mean  ē τ² / (τ² + s²),   sd  s τ / sqrt(τ² + s²)

and the interval adds their squares, the posterior mean square of the bias,
``mean² + sd² = τ² = max(0, ē² − s²)``: nothing where the repeat's residual is within the
model's own error at a calibrated pose (the fit absorbed the drift, or there was none),
the bias less the misfit's share where it is not. The residual is at the repeated pose, a
calibrated one: the bias at new poses is taken to be the same (a fit's scale carries most
of it). Where that pose weighs much in the fit (an edge of the load space), the fit is pulled
towards the repeat and its earlier twin, and the residual shows only part of a bias the whole
calibration carries, and the twin's own pull (docs/models-log.md). No pose traversed twice on
one day: no term, and no widening.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..measurements import Traverse
from .groups import TraverseGroups, group_traverses

__all__ = ["EndBias", "SessionDrift", "end_bias", "session_drift", "session_drifts"]


@dataclass(frozen=True)
class SessionDrift:
    """The within-session drift of one joint and direction's step (docs/models.md §4).

    Attributes
    ----------
    rate : float
        Relative change of the step per traverse of the joint (``log`` ratio per traverse), 1.
    rate_sd : float
        Its standard error, 1.
    span : float
        Traverses of the joint over which the repeated poses measured it (the longest pair).
    change : float
        ``rate * span``: the drift the repeats saw (e.g. the first pose traversed again at the
        end of the calibration: its relative change over the session), 1.
    pairs : int
        Pairs of traverses at the same pose on the same day.
    late : tuple of Traverse
        The latest traverse of each repeated pose on each day, in table order: the session's end,
        where :func:`end_bias` measures the fit's bias.
    """

    rate: float
    rate_sd: float
    span: float
    change: float
    pairs: int
    late: tuple[Traverse, ...] = ()


@dataclass(frozen=True)
class EndBias:
    """The bias a calibration's fit leaves at its session's end, from its late repeats (:func:`end_bias`).

    Attributes
    ----------
    residual : float
        Mean relative residual of the calibration at the late repeats, ``predicted / measured - 1``, 1
        (positive: it predicts a larger step than the joint makes by then).
    misfit : float
        The standard deviation of that mean from the model's own misfit at a calibrated pose,
        ``floor / sqrt(repeats)``, 1.
    bias : float
        Posterior mean of the bias (empirical Bayes), 1.
    bias_sd : float
        Its posterior standard deviation, 1.
    repeats : int
        Late repeats the residual is the mean of.
    """

    residual: float
    misfit: float
    bias: float
    bias_sd: float
    repeats: int

    @property
    def term(self) -> float:
        """What the interval adds in quadrature, ``sqrt(bias^2 + bias_sd^2) = sqrt(max(0, residual^2 -
        misfit^2))``, 1."""
        return math.hypot(self.bias, self.bias_sd)


def end_bias(late_errors: ArrayLike, floor: float) -> EndBias:
    """The bias the fit leaves at the session's end, from its relative residuals at the late repeats.

    Parameters
    ----------
    late_errors : array_like
        ``predicted / measured - 1`` of the calibration's model at the latest traverse of each
        repeated pose (:attr:`SessionDrift.late`), 1; non-finite ones are left out.
    floor : float
        The model's relative error at a calibrated pose (the interval's ``floor``), 1.

    Returns
    -------
    EndBias
        The posterior mean and standard deviation of the bias, whose squares sum to
        ``max(0, mean(e)^2 - floor^2 / k)`` (module docstring); all zero without a finite residual.
    """
    e = np.asarray(late_errors, dtype=float).reshape(-1)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return EndBias(0.0, 0.0, 0.0, 0.0, 0)
    mean = float(e.mean())
    s2 = (floor**2 if math.isfinite(floor) else 0.0) / e.size
    tau2 = max(0.0, mean * mean - s2)
    shrink = tau2 / (tau2 + s2) if tau2 > 0.0 else 0.0
    return EndBias(mean, math.sqrt(s2), mean * shrink, math.sqrt(s2 * shrink), int(e.size))


def session_drift(
    traverses: Sequence[Traverse] | TraverseGroups, joint: int, direction: str, step_noise: float = 0.03
) -> SessionDrift | None:
    """The drift of ``joint``'s step in ``direction`` within a session, from its repeated poses.

    Parameters
    ----------
    traverses : sequence of Traverse
        The calibration's table, in the order measured within each day (``day`` is the session).
    joint : int
    direction : {"+", "-"}
    step_noise : float
        Relative standard deviation of one step (1), for a single pair's standard error:
        ``sqrt(2 / steps) step_noise`` for a pair averaged over ``steps`` steps.

    Returns
    -------
    SessionDrift or None
        ``None`` where no pose of this joint and direction was traversed twice on one day.
    """
    return session_drifts(traverses, joint, step_noise).get(direction)


def session_drifts(
    traverses: Sequence[Traverse] | TraverseGroups, joint: int, step_noise: float = 0.03
) -> dict[str, SessionDrift]:
    """:func:`session_drift` of both directions of ``joint`` at once, from the grouped table (its
    poses as the fits' groups number them: vectorised, a history of 1e5 rows costs tens of ms);
    only the directions with a repeated pose."""
    groups = group_traverses(traverses)
    if joint not in groups.joints:
        return {}
    data = groups.joint_data(joint)
    where = {d: groups.rows((joint, d)) for d in data.dirs}
    table = np.sort(np.concatenate(list(where.values())))  # the joint's rows, in table order
    day = np.unique(np.array([groups.traverses[i].day for i in table]), return_inverse=True)[1].reshape(-1)
    by_day = np.argsort(day, kind="stable")
    n_day = np.bincount(day)
    first_of_day = np.concatenate([[0], np.cumsum(n_day)[:-1]])
    rank = np.empty(len(table))
    rank[by_day] = np.arange(len(table)) - first_of_day[day[by_day]]  # among the joint's traverses that day
    out: dict[str, SessionDrift] = {}
    for d in data.dirs:
        at = np.searchsorted(table, where[d])  # this direction's rows among the joint's
        gamma = data.gamma[d]
        ok = np.isfinite(gamma) & (gamma > 0.0)  # no step to compare: never paired
        key = day[at] * data.n_poses + data.pose[d]
        order = np.lexsort((np.arange(len(at)), key))  # by day and pose, then in table order
        order = order[ok[order]]
        keys = key[order]
        same = keys[1:] == keys[:-1]
        if not same.any():
            continue
        later, earlier = order[1:][same], order[:-1][same]
        delta = np.log(gamma[later] / gamma[earlier])
        tau = rank[at[later]] - rank[at[earlier]]
        sxx = float(tau @ tau)
        rate = float(delta @ tau) / sxx
        if delta.size >= 2:
            s2 = float(np.sum((delta - rate * tau) ** 2)) / (delta.size - 1)  # a pair's variance about the line
        else:  # the two traverses' per-step scatter
            n1, n0 = (groups.traverses[int(where[d][k])].steps for k in (later[0], earlier[0]))
            s2 = step_noise**2 * (1.0 / n1 + 1.0 / n0)
        rate_sd = math.sqrt(s2 / sxx)
        span = float(tau.max())
        last = np.concatenate([keys[1:] != keys[:-1], [True]]) & np.concatenate([[False], same])
        late = tuple(groups.traverses[int(where[d][k])] for k in np.sort(order[last]))  # each repeated pose's latest
        out[d] = SessionDrift(rate, rate_sd, span, rate * span, int(delta.size), late)
    return out
