"""The step's drift within a session, from poses traversed twice in it (docs/models.md §4).

A joint's step changes while a session goes on: a cold piezo steps further than a warm one
(the physics arm's warm-up), the room and the drive warm. Every cross-validation of one
session compares traverses of that session, so none can see it; a pose traversed again
later in the same session can. For each joint and direction, every pair of traverses at the
same pose (the fits' pose groups: fixed joints and tilt to 1e-4) on the same day
(consecutive ones where a pose has more) is a measurement of the
relative drift over the traverses between them,
``log(gamma_later / gamma_earlier) = r tau + noise``, ``tau`` the number of the joint's
traverses (both directions) from the earlier to the later one: the joint's own stepping
warms it. The rate ``r`` (per traverse) is the least-squares line through the origin; its
standard error is from the pairs' scatter about the line where there are at least two pairs,
else from the per-step scatter (:data:`~.intervals.STEP_NOISE` over the traverses' steps).

What the intervals take from it is the *bias* of the calibration towards later in the session,
where a user predicts: the fit represents the session around the mean position of its
traverses, the session's end lies ``r`` times the mean number of the joint's traverses after
each of them (``n_day - 1 - rank``) further on. A table whose row order is the order
measured (as a session writes it) gives the sign and size; the interval adds the bias and its
standard error in quadrature (:func:`~.intervals.relative_sd`). No pose traversed twice on
one day: no drift term, and no widening.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..measurements import Traverse
from .groups import TraverseGroups, group_traverses

__all__ = ["SessionDrift", "session_drift", "session_drifts"]

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
    bias : float
        The calibration's relative offset from the step at the session's end,
        ``-rate * mean(n_day - 1 - rank)`` over the direction's traverses, 1 (positive: the
        calibration predicts a larger step than the joint makes by then, as a joint that warms
        and steps less; a predicted step over the measured one, minus one).
    bias_sd : float
        Its standard error, 1.
    pairs : int
        Pairs of traverses at the same pose on the same day.
    """

    rate: float
    rate_sd: float
    span: float
    change: float
    bias: float
    bias_sd: float
    pairs: int

    @property
    def term(self) -> float:
        """What the interval adds in quadrature: ``sqrt(bias^2 + bias_sd^2)``, 1."""
        return math.hypot(self.bias, self.bias_sd)


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
    ahead = n_day[day] - 1.0 - rank
    out: dict[str, SessionDrift] = {}
    for d in data.dirs:
        at = np.searchsorted(table, where[d])  # this direction's rows among the joint's
        gamma = data.gamma[d]
        ok = np.isfinite(gamma) & (gamma > 0.0)  # no step to compare: never paired
        key = day[at] * data.n_poses + data.pose[d]
        order = np.lexsort((np.arange(len(at)), key))  # by day and pose, then in table order
        order = order[ok[order]]
        same = key[order][1:] == key[order][:-1]
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
        lead = float(np.mean(ahead[at]))
        span = float(tau.max())
        out[d] = SessionDrift(rate, rate_sd, span, rate * span, -rate * lead, rate_sd * lead, int(delta.size))
    return out
