"""Sound added to the stepping from the start of listening: how much of the first template is not the joint's.

The floor the drops are measured from (:mod:`.template`) is the lowest template heard so
far. A sound that plays from the first sample (another instrument stepping in bursts, a
radio) is in the first template, and so in the floor: when it pauses, the sub-bands it
filled fall below the floor as a stop's drops do, and the drop channel heard a stop (the
tenth generator: an equally loud instrument at 730 Hz in bursts, 6 of 8 arms counted to
an onset 1.7-1.9 s before the stop).

The tuning knows the joint's own stepping levels. At the warm-up's end, where the step rate
heard is the tuning's (within ``RateParams.min_change``: another rate moves the levels by
several spreads), the first template is compared with them: less a gain (a low quantile of
the sub-bands' differences: added sound only raises sub-bands), a sub-band that stands
``min_spreads`` of the tuning's spreads (and ``min_db``) above them holds added sound, and
the joint's own level there is the tuning's plus the gain. That level caps the floor (the
drops are measured from it) until the template comes down to it (the added sound stopped) or the floor restarts;
the sound added over it masks the signature there (:func:`~.fit.masked_signature`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..paramfield import param
from .tuned import TunedTemplate

__all__ = ["ADDED", "AddedParams", "joint_alone_db"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class AddedParams:
    """When the first template is taken to hold sound added to the joint's."""

    gain_quantile: float = param(
        0.25, "", "the gain between the tuning's stepping and the first template: this quantile of the changes"
    )
    min_spreads: float = param(
        3.0, "spreads", "a sub-band this far over the tuning's stepping plus the gain (and min_db) holds added sound"
    )
    min_db: float = param(6.0, "dB", "and this far: under it the first template is the joint's own, at another gain")
    max_rate_change: float = param(
        0.01, "of the tuning's rate", "judged only at the tuning's rate: another rate moves the levels by spreads"
    )


ADDED = AddedParams()


def joint_alone_db(
    template: FloatArray, tuned: TunedTemplate, rate_hz: float, p: AddedParams = ADDED
) -> FloatArray | None:
    """The joint's own level per sub-band under the first ``template`` (dB), or None where nothing was added.

    ``rate_hz`` is the step rate heard in the warm-up (Hz). Sub-bands without added sound
    keep the template's level.
    """
    tu = tuned
    r0 = tu.step_rate_hz
    if tu.stepping_levels_db is None or r0 is None or not abs(rate_hz / r0 - 1.0) <= p.max_rate_change:
        return None  # also NaN: no rate heard
    T = np.asarray(template, dtype=np.float64)
    S = np.asarray(tu.stepping_levels_db, dtype=np.float64)
    sigma = np.asarray(tu.spread_db, dtype=np.float64)
    diff = T - S
    gain = float(np.percentile(diff, 100 * p.gain_quantile))
    excess = diff - gain
    added = (excess >= p.min_spreads * sigma) & (excess >= p.min_db)
    if not added.any():
        return None
    return np.asarray(np.where(added, S + gain, T), dtype=np.float64)
