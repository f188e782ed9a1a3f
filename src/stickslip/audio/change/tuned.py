"""What the change detector takes from a tuning, in frames (:class:`TunedTemplate`), and what it gives back."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..tuningfile import Tuning

__all__ = ["Decision", "TunedTemplate"]


@dataclass(frozen=True)
class TunedTemplate:
    """What the template detector needs of a :class:`~stickslip.audio.tuningfile.Tuning`, in frames.

    The durations of the tuning (hold, release, warm-up) are counted in frames of
    ``hop`` samples here; the rest is the tuning's as it is (see its fields).
    """

    sample_rate: int
    frame: int
    hop: int
    edges_hz: tuple[float, ...]
    signature_db: tuple[float, ...]
    spread_db: tuple[float, ...]
    threshold: float
    residual_max: float
    hold_frames: int
    max_dips: int
    release_frames: int
    hysteresis: float
    decay_ratio: float
    tau_s: float
    warmup_chunks: int
    trim: int
    onset_lag_s: float
    stepping_levels_db: tuple[float, ...] | None = None
    drop_threshold: tuple[float, float] | None = None
    step_rate_hz: float | None = None
    continuum_levels_db: tuple[float, ...] | None = None
    continuum_signature_db: tuple[float, ...] | None = None
    continuum_spread_db: tuple[float, ...] | None = None
    fine_start_hz: float | None = None
    fine_bin_hz: float | None = None
    fine_stepping_db: tuple[float, ...] | None = None
    fine_stopped_db: tuple[float, ...] | None = None

    @classmethod
    def from_tuning(cls, tu: Tuning, chunk: int) -> TunedTemplate:
        """The template detector's view of ``tu`` (``method == "template"``), its warm-up in chunks of ``chunk``."""
        if tu.edges_hz is None or tu.signature_db is None or tu.spread_db is None:
            raise ValueError("a template detector needs a template tuning (edges_hz, signature_db, spread_db)")
        return cls(
            sample_rate=tu.sample_rate,
            frame=tu.frame,
            hop=tu.hop,
            edges_hz=tu.edges_hz,
            signature_db=tu.signature_db,
            spread_db=tu.spread_db,
            threshold=tu.threshold_db,
            residual_max=tu.residual_max,
            hold_frames=tu.hold_frames,
            max_dips=tu.max_dips,
            release_frames=max(1, int(math.ceil(tu.release_s * tu.sample_rate / tu.hop))),
            hysteresis=tu.hysteresis_db,
            decay_ratio=tu.decay_ratio,
            tau_s=tu.tau_s,
            warmup_chunks=max(1, int(math.ceil(tu.warmup_s * tu.sample_rate / tu.hop / chunk - 1e-9))),
            trim=tu.trim,
            onset_lag_s=tu.onset_lag_s,
            stepping_levels_db=tu.stepping_levels_db,
            drop_threshold=tu.drop_threshold,
            step_rate_hz=tu.step_rate_hz,
            continuum_levels_db=tu.continuum_levels_db,
            continuum_signature_db=tu.continuum_signature_db,
            continuum_spread_db=tu.continuum_spread_db,
            fine_start_hz=tu.fine_start_hz,
            fine_bin_hz=tu.fine_bin_hz,
            fine_stepping_db=tu.fine_stepping_db,
            fine_stopped_db=tu.fine_stopped_db,
        )

    @property
    def has_continuum(self) -> bool:
        """The tuning holds the continuum's signature and spread (the stale-template check can run)."""
        return self.continuum_signature_db is not None and self.continuum_spread_db is not None

    @property
    def has_fine(self) -> bool:
        """The tuning holds its step rate and fine spectra: the signature can be predicted at another rate."""
        return (
            self.step_rate_hz is not None
            and self.fine_start_hz is not None
            and self.fine_bin_hz is not None
            and self.fine_stepping_db is not None
            and self.fine_stopped_db is not None
        )


@dataclass
class Decision:
    """One fire, in the template detector's own terms."""

    #: the stream sample (absolute index) of the last sample of the frame that fired
    end_sample: int
    #: the interpolated crossing of the threshold that began the hold, stream time, s
    cross_t_s: float
    #: the stop-likeness of the frame that fired
    a: float
    #: the stop may have begun before ``cross_t_s``: it fired soon after a fire judged a stale template, and may have
    #: begun inside that fire's span (:mod:`.stale`)
    uncertain: bool = False
