"""Another instrument's step clock in a tuning recording: refused, or left out where the joint's rate is told.

The step rate is heard again in pieces of the stepping part (:func:`two_clocks`): a joint's
clock holds throughout, so pieces heard ``clock_off`` or more from the pieces' median rate
(and its harmonics and fractions) are another instrument's, stepping in bursts. Which of
the two clocks is the joint's the recording alone cannot say, and a tuning that learnt the
other instrument's bursts coming and going as the stop fires early: untold, :func:`~.tune.tune`
refuses.

The traverse that made the recording knows the rate it commanded. Told it,
:func:`joint_clock_only` keeps the clock within ``clock_told_tol`` of it as the joint's and
cuts the recording into pieces of ``clock_cut_s`` from the labelled stop outwards (the stop
stays at a piece boundary); a piece where the other clock's envelope line stands
``clock_cut_db`` over the continuum (noise alone 0-5 dB; a burst 10-24 dB) is left out, and
the rest joined in order: the joint's stepping, then its stop, with the label at the join.
Refused where neither clock is the told one, or where less than ``clock_kept_s`` of stepping
is left (the template and its checks need stepping to learn from).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..features.stepclock import clear_rates_hz, rate_prominence_db
from .labels import TuningError
from .params import TUNE, TuneParams

__all__ = ["joint_clock_only", "two_clocks"]

FloatArray = NDArray[np.float64]


def two_clocks(x: FloatArray, sample_rate: int, p: TuneParams = TUNE) -> tuple[float, float] | None:
    """The two step clocks heard in turns in the stepping part ``x``: (the pieces' median rate, the other's), Hz;
    None where one clock is heard. A piece's rate counts where its line is ``clock_min_db`` clear."""
    rates = clear_rates_hz(x, sample_rate, max(1, round(p.clock_piece_s * sample_rate)), p.clock_min_db)
    if len(rates) < 2:
        return None
    mid = float(np.median(rates))
    off = [r for r in rates if min(abs(q / round(q) - 1.0) for q in (r / mid, mid / r) if round(q) >= 1) >= p.clock_off]
    return (mid, float(np.median(off))) if off else None


def joint_clock_only(
    x: FloatArray, sample_rate: int, stop_at_s: float, clocks: tuple[float, float], told_hz: float, p: TuneParams = TUNE
) -> tuple[FloatArray, float]:
    """The recording ``x`` without the pieces the other clock holds, and its labelled stop, s (see the module).

    ``clocks`` are the two rates heard (:func:`two_clocks`), ``told_hz`` the rate the joint was commanded, Hz.
    :class:`TuningError` where neither clock is the told one or too little stepping is left.
    """
    near = [abs(c / told_hz - 1.0) <= p.clock_told_tol for c in clocks]
    if near.count(True) != 1:
        lo, hi = sorted(clocks)
        raise TuningError(
            f"holds two step clocks ({lo:.0f} Hz and {hi:.0f} Hz, in turns), neither (or both) the commanded "
            f"{told_hz:g} Hz: which is the joint's is not known"
        )
    other = clocks[near.index(False)]
    sr = int(sample_rate)
    n = max(1, round(p.clock_cut_s * sr))
    stop = int(round(stop_at_s * sr))

    def kept(lo: int, hi: int) -> bool:  # heard, and the other clock not heard in it (NaN: too short, silent)
        return bool(rate_prominence_db(x[lo:hi], sr, other) < p.clock_cut_db)

    before = [(max(0, hi - n), hi) for hi in range(stop, 0, -n)][::-1]
    after = [(lo, min(x.size, lo + n)) for lo in range(stop, x.size, n)]
    stepping = [x[lo:hi] for lo, hi in before if kept(lo, hi)]
    stopped = [x[lo:hi] for lo, hi in after if kept(lo, hi)]
    left = sum(v.size for v in stepping) / sr
    if left < p.clock_kept_s or not stopped:
        raise TuningError(
            f"holds another instrument's step clock ({other:.0f} Hz) besides the joint's ({told_hz:g} Hz): left out, "
            f"{left:.2f} s of stepping is left, under {p.clock_kept_s:g} s; record again without it"
        )
    return np.concatenate(stepping + stopped), left
