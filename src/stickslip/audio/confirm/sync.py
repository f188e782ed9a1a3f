"""The step clock's verdict on a fire (opt-in: ``step_clock=True``): did the joint's own sound change?

Every sound the joint makes is a train of clicks at the step rate, at the stop too;
interference is not in step with it. With the step clock, a fire that persisted must also
have changed the joint's *step-synchronous* sound somewhere in the stepping band (the
tuning's sub-bands, end to end): the power on each harmonic line of the step rate, above
the continuum between them (:func:`~stickslip.audio.features.stepclock.line_change`), over
the ``span_s`` of stepping that end ``gap_s`` before the fire (for a fire soon after a
rejected one, the stepping before the first of them) against the first ``span_s`` of the
window, at the rate heard in the stepping. The lines' changes, each in standard deviations
of its estimate, are summed as squares (the largest dropped: a voice's harmonic on a line),
so a stop that raises some lines and lowers others does not cancel; the sum, as a normal
deviate, must reach ``min_z``, and a line kept in it must have moved by ``min_change_db``
or more. No verdict (the fire stands on persistence) when the lines were not sharp before
the fire (``min_sharpness``: a rough clock smears its higher harmonics) or held less than
``min_share`` of the band's power, when no rate or too few lines are heard, or when less
than ``min_s`` of stepping or ``min_after_s`` of the window was heard. Off by default: a
rough clock just sharp enough to be judged carries stops whose lines hardly change, and a
veto there would lose them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..features.stepclock import LineChange, line_change
from ..paramfield import param

__all__ = ["SYNC", "SyncCheck", "SyncParams", "step_clock_verdict"]


@dataclass(frozen=True)
class SyncParams:
    """The stepping before a fire, and the step clock's verdict on it."""

    min_z: float = param(
        4.0, "standard deviations", "the lines' trimmed chi-square, as a normal deviate, must reach this"
    )
    min_change_db: float = param(1.0, "dB", "and a line kept in it moved this much, up or down")
    min_sharpness: float = param(
        0.9, "", "judged only where the lines held this share of a comb four times wider's power before the fire"
    )
    min_share: float = param(0.05, "", "and this share of the band's power")
    span_s: float = param(0.48, "s", "the stepping before the fire, and the window after it, are this long")
    gap_s: float = param(0.06, "s", "the stepping ends this long before the fire (the hold and the onset lag)")
    min_s: float = param(0.2, "s", "not judged on less stepping (listening began at the stop)")
    min_after_s: float = param(0.1, "s", "nor on less of the window (a recording that ends sooner)")


SYNC = SyncParams()


def step_clock_verdict(got: LineChange, p: SyncParams = SYNC) -> bool | None:
    """The step clock's verdict on a fire: True (the lines changed), False (they did not) or None (no verdict).

    None where the lines before the fire were not sharp (``min_sharpness``), held less than
    ``min_share`` of the band's power, or nothing was measured (NaN).
    """
    if not (got.sharpness_before >= p.min_sharpness and got.share_before >= p.min_share):
        return None  # the clock's lines are smeared there, or hold next to nothing (or NaN)
    if not (math.isfinite(got.change_z) and math.isfinite(got.change_db)):
        return None
    return got.change_z >= p.min_z and abs(got.change_db) >= p.min_change_db


class SyncCheck:
    """The step clock's check over a stream: the stepping before a chain of fires, then each window."""

    def __init__(self, bands_hz: Sequence[tuple[float, float]], sample_rate: int, p: SyncParams = SYNC) -> None:
        #: the band the step clock is judged on (Hz; empty: no step-clock check)
        self.bands = list(bands_hz)
        self.sample_rate, self.p = sample_rate, p
        self.reset()

    def reset(self) -> None:
        #: the stepping before the fire that began the current chain
        self.ref: NDArray[np.float64] | None = None

    def judge(self, after: NDArray[np.float64]) -> LineChange | None:
        """The lines' change from the stepping to the window's first samples ``after`` (None: not measured)."""
        sr, p, ref = self.sample_rate, self.p, self.ref
        if not self.bands or ref is None:
            return None
        if ref.size < p.min_s * sr or after.size < p.min_after_s * sr:
            return None
        n = min(ref.size, after.size)
        return line_change(ref[-n:], after[:n], sr, self.bands)
