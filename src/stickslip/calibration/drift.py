"""The step's drift within a session, from poses traversed twice in it (docs/models.md §4).

A joint's step changes while a session goes on: a cold piezo steps further than a warm one
(the physics arm's warm-up), the room and the drive warm. Every cross-validation of one
session compares traverses of that session, so none can see it; a pose traversed again
later in the same session can. For each joint and direction, every pair of traverses at the
same pose on the same day (consecutive ones where a pose has more) is a measurement of the
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

__all__ = ["SessionDrift", "session_drift"]

POSE_DECIMALS = 4
"""Poses are the same when the fixed joints and the tilt agree to 1e-4 (rad, m), as the groups' poses."""


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
    traverses: Sequence[Traverse], joint: int, direction: str, step_noise: float = 0.03
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
    by_day: dict[str, list[Traverse]] = {}
    for t in traverses:
        if t.joint == joint:
            by_day.setdefault(t.day, []).append(t)
    delta: list[float] = []
    tau: list[float] = []
    steps: list[float] = []
    ahead: list[float] = []  # per traverse of this direction: the joint's traverses after it that day
    for rows in by_day.values():
        seen: dict[tuple[float, ...], tuple[int, Traverse]] = {}
        for rank, t in enumerate(rows):
            if t.direction != direction:
                continue
            ahead.append(float(len(rows) - 1 - rank))
            key = tuple(0.0 if k == joint - 1 else round(float(v), POSE_DECIMALS)
                        for k, v in enumerate((t.q1, t.q2, t.q3, t.theta, t.psi)))
            if key in seen:
                r0, t0 = seen[key]
                delta.append(math.log(t.gamma / t0.gamma))
                tau.append(float(rank - r0))
                steps.append(2.0 / (1.0 / t.steps + 1.0 / t0.steps))
            seen[key] = (rank, t)
    if not delta:
        return None
    d, x = np.array(delta), np.array(tau)
    sxx = float(x @ x)
    rate = float(d @ x) / sxx
    if len(d) >= 2:
        s2 = float(np.sum((d - rate * x) ** 2)) / (len(d) - 1)  # a pair's variance about the line
    else:
        s2 = 2.0 * step_noise**2 / steps[0]  # two traverses' per-step scatter
    rate_sd = math.sqrt(s2 / sxx)
    lead = float(np.mean(ahead))
    span = float(x.max())
    return SessionDrift(rate, rate_sd, span, rate * span, -rate * lead, rate_sd * lead, len(d))
