"""The tuner's parameters (:class:`TuneParams`): how a template is chosen from a labelled recording."""

from __future__ import annotations

from dataclasses import dataclass

from ..paramfield import param

__all__ = ["TUNE", "TuneParams"]


@dataclass(frozen=True)
class TuneParams:
    """How ``tune`` chooses the template, its threshold and its resolution."""

    hold_s: float = param(0.016, "s", "default hold: how long a stop must last before the detector fires")
    range_db: float = param(25.0, "dB", "the template spans where the stepping is within this of its spectral peak")
    trim_fraction: float = param(0.1, "of the sub-bands", "a frame's fit may drop this share (the most excess)")
    min_threshold: float = param(0.4, "stop-likeness", "the lowest threshold on the stop-likeness")
    max_threshold: float = param(0.7, "stop-likeness", "the highest, where the separation allows")
    threshold_share: float = param(
        0.4, "of the margin", "the threshold sits this far from the worst stepping frame towards the stop's low"
    )
    min_margin: float = param(0.05, "stop-likeness", "candidates that separate the stop by less are not verified")
    whole_margin: float = param(
        0.3, "stop-likeness", "all the sub-bands come first unless they separate by less than this: more to tell by"
    )
    max_candidates: int = param(8, "candidates", "at most this many candidates are verified")
    verified: int = param(3, "candidates", "this many that verify are enough (more while none checks the drops)")
    default_per_octave: float = param(3.0, "sub-bands per octave", "the template's resolution when none is asked")
    finer_per_octave: tuple[float, ...] = param(
        (6.0, 12.0), "sub-bands per octave", "tried when the default is refused or weak: a stop that moves its modes"
    )
    finer_below: float = param(0.8, "stop-likeness", "a default template that separates by this is kept as it is")
    finer_gain: float = param(
        0.2, "stop-likeness", "a finer template replaces a coarser one only with this much more margin ..."
    )
    finer_min_margin: float = param(
        0.3, "stop-likeness", "... and at least this margin, on as many sub-bands (a refusal is safer)"
    )
    wide_range_db: float | None = param(
        45.0, "dB", "every resolution refused: the template spans this far from the peak (a mode moved out of it)"
    )
    fine_skip_s: float = param(0.3, "s", "the fine spectrum of stepping skips the recording's first this long ...")
    fine_skip_stop_s: float = param(0.1, "s", "... and that of the stop its first this long after the stop")
    drop_margin: float = param(1.6, "", "drop thresholds: this many times the stepping part's worst drop ...")
    drop_tail: float = param(
        6.0, "robust SDs", "... and at least its median plus this (a traverse is longer than the tuning recording) ..."
    )
    drop_floor: tuple[float, float] = param((1.0, 2.0), "spreads", "... and at least these (broad, local)")
    clock_piece_s: float = param(
        0.25, "s", "the stepping part's step rate is heard again in pieces this long (another instrument's bursts)"
    )
    clock_min_db: float = param(
        10.0, "dB", "a piece's rate counts where its envelope line stands this far over the continuum (noise: 0-2)"
    )
    clock_off: float = param(
        0.15, "of the rate", "pieces heard this far from their median rate and its harmonics: another clock (refused)"
    )
    clock_end_s: float = param(
        0.15, "s", "the step rate is heard up to this long before the labelled stop (the stop's own sound left out)"
    )
    clock_told_tol: float = param(
        0.03, "of the rate", "two clocks, the rate told: the one this close to it is the joint's (the other left out)"
    )
    clock_cut_s: float = param(
        0.1, "s", "the recording is cut in pieces this long from the stop outwards (a burst's edge: 0.1 s lost)"
    )
    clock_cut_db: float = param(
        6.0,
        "dB",
        "a piece where the other clock's envelope line stands this clear is left out (noise 0-5, bursts 10-24)",
    )
    clock_kept_s: float = param(
        0.5, "s", "refused where less stepping than this is left (the template and its checks learn from it)"
    )


TUNE = TuneParams()
