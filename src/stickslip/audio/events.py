"""The seam every end-stop detector shares: samples in, :class:`StopEvent` s out (:class:`StopDetector`).

A traverse (:func:`stickslip.procedures.traverse.measure_traverse`) takes any
:class:`StopDetector`: the confirmed audio detector
(:class:`~stickslip.audio.confirm.ConfirmedStopDetector`), the detector that fires
(:class:`~stickslip.audio.change.TemplateDetector`, or the version-1
:class:`~stickslip.audio.comparators.BandDetector`), a position read-back
(:class:`~stickslip.audio.readback.ReadbackStopDetector`) or the simulator's oracle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["StopDetector", "StopEvent", "check_step_rate", "sample_block"]


@dataclass(frozen=True)
class StopEvent:
    """One end stop heard.

    Attributes
    ----------
    detected_at_s : float
        Stream time of the last sample consumed when the event fired, s: the last
        sample of the frame that completed the hold. It does not depend on how the
        stream was cut into blocks (later samples of the same block were not needed).
    onset_s : float
        Estimated time the stop actually began, s.
    level_db : float
        Band level of the frame that fired, dBFS (the stop-likeness, dimensionless, for a
        template tuning).
    confirmed_at_s : float or None
        Stream time at which the stop was confirmed by its persistence, s (the last
        sample of the confirmation window, or of the stream if it ended first; see
        :mod:`stickslip.audio.confirm`); ``None`` from a detector that does not confirm.
    confirmed_s : float or None
        How long the stop was heard persisting after it fired before it was emitted, s:
        the confirmation window, or less when the stream ended first; ``None`` from a
        detector that does not confirm.
    onset_uncertain : bool
        When the stop began is not known well enough to count to it: it was already there
        when the confirming detector began listening again after a fire it rejected, or the
        evidence around the fire doubts its onset (:mod:`stickslip.audio.confirm.onset`).
        A traverse refuses it.
    found_late : bool
        The fast path never heard this stop: the late path found it on the step clock's
        lines 0.5-0.75 s after it and estimated its onset back
        (:mod:`stickslip.audio.confirm.late`, opt-in), or the confirmation found it inside
        a rejected fire's window, read in phase with the steps at the window's end
        (:mod:`stickslip.audio.confirm.inside`). ``detected_at_s`` is when it was found,
        not the fast path's 30-50 ms.
    """

    detected_at_s: float
    onset_s: float
    level_db: float
    confirmed_at_s: float | None = None
    confirmed_s: float | None = None
    onset_uncertain: bool = False
    found_late: bool = False

    def to_dict(self) -> dict[str, float | bool | None]:
        return {
            "detected_at_s": self.detected_at_s,
            "onset_s": self.onset_s,
            "level_db": self.level_db,
            "confirmed_at_s": self.confirmed_at_s,
            "confirmed_s": self.confirmed_s,
            "onset_uncertain": self.onset_uncertain,
            "found_late": self.found_late,
        }


def check_step_rate(step_rate_hz: float | None) -> float | None:
    """``step_rate_hz`` as a float, or None; ``ValueError`` (one line) unless it is finite and positive, Hz."""
    if step_rate_hz is None:
        return None
    hz = float(step_rate_hz)
    if not (math.isfinite(hz) and hz > 0.0):
        raise ValueError(f"the commanded step rate must be a positive number of Hz, got {step_rate_hz!r}")
    return hz


def sample_block(block: Any) -> NDArray[np.floating[Any]]:
    """``block`` as a 1-D array of floats; ``ValueError`` (one line) for a block of another kind or shape.

    A detector's samples are floats: sound at full scale 1, vibration in its sensor's unit. Integer PCM
    fed as it is would be heard 90 dB (int16) louder than it was, and a band tuning's level in dBFS fires at
    once; booleans and complex numbers are not samples. The detectors' ``feed`` check it first.
    """
    x = np.asarray(block)
    if x.dtype.kind != "f":
        half = 2.0 ** (8 * x.dtype.itemsize - 1)
        hint = {"i": f": scale integer PCM to full scale 1 first (divide by {half:.0f})",
                "u": f": scale unsigned PCM to full scale 1 first (subtract {half:.0f}, then divide by it)"}
        raise ValueError(f"feed expects float samples, got an array of {x.dtype}{hint.get(x.dtype.kind, '')}")
    if x.ndim != 1:
        raise ValueError(f"feed expects a 1-D mono block, got shape {x.shape}")
    return x


class StopDetector(Protocol):
    """What a traverse needs of an end-stop detector.

    ``feed`` takes the next block of samples (mono; sound, vibration or positions) and
    returns the stops heard in it; ``reset`` starts a new stream at ``t0_s``;
    ``latency_s`` is the typical time from a stop's onset to its event (for
    ``latency="fixed"``); ``uses_audio`` says whether the no-signal guard applies (the
    simulator's oracle and a position read-back do not listen to sound).
    """

    uses_audio: bool

    @property
    def latency_s(self) -> float:
        """Typical ``detected_at_s`` minus the stop's onset, s."""
        ...

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Forget everything; the next sample fed is at stream time ``t0_s`` (s).

        ``step_rate_hz`` is the step rate the controller commands for the stream that
        follows, Hz (None: not told). A detector that hears the step clock looks for the
        rate near it, and may hear a stop at a rate farther from its tuning's; the others
        ignore it.
        """
        ...

    def feed(self, block: NDArray[Any]) -> list[StopEvent]:
        """Consume a block of samples; return the stops heard in it."""
        ...
