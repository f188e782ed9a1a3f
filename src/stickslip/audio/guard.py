"""A no-signal guard for the audio limit switch: is the input alive at all?

A dead or unplugged microphone gives digital silence, a constant (a DC offset) or, with a
broken preamplifier, a signal pinned at full scale. A stop detector that compares band
levels can fire on such input within milliseconds, and a traverse would then record a
bogus step count. The guard looks at each block before the detector does and raises
:class:`NoSignalError` once the input has been dead for ``hold_s`` without a break.

Thresholds (samples are floats in [-1, 1], full scale 1):

* silence: peak amplitude below ``floor`` (default 1e-6, -120 dBFS; a real microphone's
  self-noise is far above it);
* constant: peak-to-peak below ``floor`` (a DC offset, however large);
* clipping: more than half the samples at or beyond 0.999 of full scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["NoSignalError", "SignalGuard", "block_problem"]


class NoSignalError(RuntimeError):
    """The audio input is dead (silence, a constant or clipping throughout)."""


def block_problem(block: ArrayLike, floor: float = 1e-6) -> str | None:
    """Why ``block`` carries no usable signal ("silence", "a constant", "clipping"), or ``None`` if it is alive."""
    x = np.asarray(block, dtype=np.float64).ravel()
    if x.size == 0:
        return None
    if not np.all(np.isfinite(x)):
        return "non-finite samples"
    peak = float(np.max(np.abs(x)))
    if peak < floor:
        return "silence"
    if float(np.ptp(x)) < floor:
        return "a constant"
    if float(np.mean(np.abs(x) >= 0.999)) > 0.5:
        return "clipping"
    return None


@dataclass
class SignalGuard:
    """Raise :class:`NoSignalError` when the input stays dead for ``hold_s`` seconds.

    Parameters
    ----------
    sample_rate : float
        Samples per second of the blocks, Hz.
    hold_s : float
        How long the input must be dead without a break before the guard trips, s.
    floor : float
        Amplitude below which a block is silent (full scale 1).
    """

    sample_rate: float
    hold_s: float = 0.2
    floor: float = 1e-6
    dead_s: float = 0.0

    def check(self, block: ArrayLike) -> bool:
        """Account for one block: ``True`` if it is alive, ``False`` if it is dead.

        An event the detector reports on a dead block is not a stop (its level statistics
        can call silence one); once the input has been dead for ``hold_s`` without a break,
        :class:`NoSignalError`.
        """
        x = np.asarray(block)
        problem = block_problem(x, self.floor)
        if problem is None:
            self.dead_s = 0.0
            return True
        self.dead_s += x.shape[0] / self.sample_rate
        if self.dead_s >= self.hold_s:
            raise NoSignalError(
                f"no signal from the audio input: {problem} for {self.dead_s:.2f} s "
                "(is the microphone plugged in, switched on and not muted?); nothing was recorded"
            )
        return False
