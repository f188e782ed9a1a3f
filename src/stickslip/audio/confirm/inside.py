"""A stop that began inside a rejected fire's window, found on the joint's own clock.

A fire that does not persist is rejected at its window's end (2 s after a rejected fire:
:mod:`.persistence`), and the fast path listens again. A stop that began inside that window
was heard at best at the un-latching, its onset unknown (flagged: :mod:`.chain`), and not
at all where the levels had learned sound that was not the joint's (the tenth generator:
another instrument stepping in bursts at 730 Hz from the first sample; the joint alone
then reads stop-like to the levels, and its stop does not).

The traverse knows the rate it commands, and the joint's own clicks are in step with it: the
step clock's lines read in phase with the clock followed from the sound (:mod:`.clocked`)
hold the joint's sound alone, whatever else steps at another rate (its lines turn against
the clock and leave little in phase). So at a rejected window's end its samples are read so,
in pieces of ``piece_s``, against the chain's stepping (the clocked check's reference). A
stop began inside it where

* the pieces from one of them to the window's end each read ``min_affirm`` or more in phase
  (``ClockedParams``), at least ``min_run_s`` of them, and a piece before them read under
  ``min_a`` (the joint stepping inside the window: else the fire was the stop, judged as it);
* its onset is the time ``t``, searched every ``scan_s`` over the piece before the first
  affirmed one and that piece, where the piece after ``t`` reads most above the piece
  before ``t`` (the step of the reading from stepping to the stop);
* from that onset to the window's end both readings of the clocked check, on the comb and
  in phase, reach ``min_affirm`` (a fire the levels cannot confirm is affirmed so) and the
  stepping went on (not a pause: :mod:`.pause`, checked by the caller).

The event then carries ``found_late`` (``detected_at_s`` the window's end, when it was found)
and, where the reading's step over the onset is under ``min_step`` (a reading that does not
pin where the stop began), ``onset_uncertain``. It runs only at a rejected window's end,
never per frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..paramfield import param
from .clocked import ClockedCheck, OnClock, locked_reader

__all__ = ["INSIDE", "Inside", "InsideParams", "stop_inside"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class InsideParams:
    """A stop that began inside a rejected fire's window, found on the step clock's lines read in phase."""

    piece_s: float = param(
        0.1, "s", "the window is read in phase in pieces this long (5 of the lines' 20 ms frames: 100 steps at 1 kHz)"
    )
    min_run_s: float = param(
        0.2, "s", "at least this much of the window's end read as the stop, in whole pieces (one piece: a note)"
    )
    scan_s: float = param(0.005, "s", "the onset is searched this finely (a fifth of the 25 ms a count allows)")
    min_step: float = param(
        0.5, "", "the reading's step over the onset (piece after less piece before) under this: onset uncertain"
    )


INSIDE = InsideParams()


@dataclass(frozen=True)
class Inside:
    """A stop found inside a rejected window."""

    #: its onset, samples from the start of the samples read
    onset: int
    #: the reading's step over the onset: the piece after it less the piece before it
    step: float
    #: the clocked check's readings from the onset to the window's end
    on_clock: OnClock


def stop_inside(
    x: FloatArray, lead: int, clocked: ClockedCheck, heard_hz: float, p: InsideParams = INSIDE
) -> Inside | None:
    """The stop that began inside the rejected window ``x[lead:]`` (samples; ``x[:lead]`` before it), or None.

    ``clocked`` holds the chain's stepping (its reference) and the commanded rate; ``heard_hz`` the step rate heard
    in that stepping (Hz; NaN: none). See the module docstring.
    """
    cp, ref, sr = clocked.p, clocked.ref, clocked.sample_rate
    tu = clocked.tuning
    if not clocked.enabled or ref is None or ref.size < cp.min_s * sr or clocked.ref_stoplike > cp.max_ref_stoplike:
        return None  # as the clocked check: no stepping to compare with
    rate = clocked.rate(heard_hz)
    piece = int(round(p.piece_s * sr))
    if not math.isfinite(rate) or piece <= 0 or lead < piece:
        return None
    assert tu.edges_hz is not None and tu.signature_db is not None and tu.continuum_signature_db is not None
    read = locked_reader(ref, sr, rate, tu.edges_hz, tu.signature_db, tu.continuum_signature_db, cp)
    if read is None:
        return None
    n = (x.size - lead) // piece
    got = [read(x[lead + i * piece : lead + (i + 1) * piece]) for i in range(n)]
    j = n
    while j > 0 and got[j - 1] >= cp.min_affirm:  # NaN ends the run
        j -= 1
    stepping = [g for g in got[:j] if math.isfinite(g)]
    if (n - j) * piece < p.min_run_s * sr or not stepping or not min(stepping) < cp.min_a:
        return None
    step = max(1, int(round(p.scan_s * sr)))
    ts = range(lead + (j - 1) * piece, lead + (j + 1) * piece + 1, step)
    rises = [read(x[t : t + piece]) - read(x[t - piece : t]) for t in ts]
    if not np.any(np.isfinite(rises)):
        return None
    best = int(np.nanargmax(rises))
    onset = ts[best]
    on = clocked.judge(x[onset:], heard_hz)
    if not clocked.affirms(on):
        return None
    assert on is not None
    return Inside(onset, float(rises[best]), on)
