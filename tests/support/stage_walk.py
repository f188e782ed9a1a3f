"""An independent generator of a stage's traverses: a walk of scattered steps, counted.

Written from the stage's side, not from the project's simulator or estimator: a stage
moves by discrete steps whose sizes scatter about a true mean (each step independent,
normal with a relative spread); a traverse is either

* from stop to stop: steps are counted until the walk has covered the whole range (the
  stop ends it; the stops' positions are known to their repeatability), or
* a commanded number of steps from a stop, the end read by a position sensor with its
  own noise.

The table is written as CSV text by hand (docs/design.md §7's header, SI units), so that
the project's table writer is not what is tested.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HEADER = "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps"


@dataclass(frozen=True)
class StageTruth:
    """What the walk is made with.

    Attributes
    ----------
    steps : dict
        ``(joint, direction) ->`` the true mean step, m.
    lower, upper : float
        Each stage's stops, m.
    spread : float
        Relative standard deviation of one step about its mean.
    stop_sd : float
        Repeatability of a stop's position, m.
    sensor_sd : float
        Noise of the position sensor that reads a commanded traverse's end, m.
    """

    steps: dict[tuple[int, str], float]
    lower: float = -0.0099
    upper: float = 0.0099
    spread: float = 0.2
    stop_sd: float = 0.3e-6
    sensor_sd: float = 1.0e-6


def _walk(rng: np.random.Generator, mean: float, spread: float, n: int) -> np.ndarray:
    """Positions after each of ``n`` steps of sizes scattered about ``mean`` (m), from 0."""
    sizes = mean * (1.0 + spread * rng.standard_normal(n))
    return np.cumsum(np.abs(sizes))


def traverses(truth: StageTruth, per_direction: int, seed: int, day: str = "2026-11-22") -> list[str]:
    """The table's rows: ``per_direction`` traverses of each joint and direction, alternating full and part.

    Returns CSV lines (without the header). Every row's pose columns are the other stages'
    positions (at 0) and no tilt; the moving stage's start and end are what was measured.
    Keep the stops a little inside the rig file's range: a stop's scatter must not read
    as a position beyond it.
    """
    rng = np.random.default_rng(seed)
    span = truth.upper - truth.lower
    rows = []
    for (joint, direction), mean in sorted(truth.steps.items()):
        for k in range(per_direction):
            if k % 2 == 0:  # stop to stop: count the steps until the walk covers the range
                n_max = int(2 * span / mean) + 100
                pos = _walk(rng, mean, truth.spread, n_max)
                n = int(np.searchsorted(pos, span)) + 1  # the step that reaches the stop
                lo = truth.lower + truth.stop_sd * rng.standard_normal()
                hi = truth.upper + truth.stop_sd * rng.standard_normal()
                start, end = (lo, hi) if direction == "+" else (hi, lo)
            else:  # a commanded number of steps from a stop, the end read by the sensor
                length = span * rng.uniform(0.3, 0.8)
                n = int(length / mean)
                moved = float(_walk(rng, mean, truth.spread, n)[-1])
                stop = truth.lower if direction == "+" else truth.upper
                sign = 1.0 if direction == "+" else -1.0
                start = stop + truth.stop_sd * rng.standard_normal()
                end = stop + sign * moved + truth.sensor_sd * rng.standard_normal()
            rows.append(f"{day},{joint},{direction},0,0,0,0,0,{float(start)!r},{float(end)!r},{n}")
    return rows


def table(truth: StageTruth, per_direction: int, seed: int) -> str:
    """The whole CSV text of :func:`traverses`."""
    return "\n".join([HEADER, *traverses(truth, per_direction, seed)]) + "\n"
