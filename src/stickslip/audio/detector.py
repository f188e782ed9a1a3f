"""The end-stop detector, assembled from its stages: samples in, :class:`StopEvent` s out.

::

    sources ─────► features ─────────► change detector ──────► confirmation ─────────► events
    files, mic,    sub-band levels per   template, fit to the    persistence, pause,     StopEvent
    vibration;     frame, the step       stop's signature,       onset doubt; the step   (onset_s,
    the dead-      clock (rate, lines)   drops, masking: a fire  clock and the late      uncertain,
    input guard                          (the fast path)         path (opt-in)           found_late)

A tuning (:class:`~stickslip.audio.tuningfile.Tuning`, made by
:func:`~stickslip.audio.tuning.tune` from a labelled recording) says how one joint's stop
sounds. :func:`detector_for` gives the detector that fires on it (the change detector,
:class:`~stickslip.audio.change.TemplateDetector`, for a tuning of version 2; the
version-1 :class:`~stickslip.audio.comparators.BandDetector` for an older file);
:func:`~stickslip.audio.confirm.confirming` wraps it so that a fire is reported only once
it persisted (what ``listen`` and a traverse use); :func:`detect` runs both over a
recording. Every detector implements :class:`~stickslip.audio.events.StopDetector`.
docs/audio.md gives the rules each stage applies and why.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..plotting import has_display
from .change import ChangeParams, TemplateDetector
from .comparators import BandDetector
from .confirm import ConfirmedStopDetector, ConfirmParams
from .events import StopDetector, StopEvent
from .features.spectra import band_levels_db
from .tuningfile import Tuning, TuningFileError

__all__ = [
    "StopDetector",
    "StopEvent",
    "Tuning",
    "TuningFileError",
    "detect",
    "detector_for",
    "frame_levels_db",
    "plot_levels",
]


def detector_for(
    tuning: Tuning, t0_s: float = 0.0, params: ChangeParams | None = None
) -> TemplateDetector | BandDetector:
    """The detector that fires on ``tuning``'s stop (every fire; :func:`~.confirm.confirming` confirms them).

    Parameters
    ----------
    tuning : Tuning
        Version 2 (``method == "template"``): the change detector; version 1 (``"band"``):
        the band-power detector.
    t0_s : float
        Stream time of the first sample fed, s.
    params : ChangeParams, optional
        The change detector's parameters (template tunings).

    Examples
    --------
    >>> det = detector_for(Tuning(band_hz=(5600, 7100), threshold_db=-50))
    >>> det.feed(np.zeros(4800, dtype=np.float32))
    []
    """
    if tuning.method == "template":
        return TemplateDetector(tuning, t0_s, params)
    return BandDetector(tuning, t0_s)


def detect(
    samples: NDArray[Any] | Iterable[NDArray[Any]],
    tuning: Tuning,
    t0_s: float = 0.0,
    block: int = 1 << 16,
    confirm_s: float = 0.0,
    late: bool = False,
    step_clock: bool = False,
    change: ChangeParams | None = None,
    confirm: ConfirmParams | None = None,
    step_rate_hz: float | None = None,
) -> list[StopEvent]:
    """Run a fresh detector over a whole recording (or an iterable of blocks): its events.

    ``confirm_s`` > 0 reports a stop only once it persisted that long, s
    (:class:`~stickslip.audio.confirm.ConfirmedStopDetector`; a stop the recording ends on
    is reported if it persisted so far); 0, the default, reports every fire. ``late`` also
    reports stops the fast path never heard, found late on the step clock, and
    ``step_clock`` asks the step clock too (both with ``confirm_s`` > 0 only). ``change``
    and ``confirm`` are the stages' parameters (default: their dataclasses' defaults).
    ``step_rate_hz`` is the step rate the controller commanded, Hz, told to the detector as a
    traverse tells it (:meth:`~.events.StopDetector.reset`; None: not told).
    """
    fast = detector_for(tuning, t0_s, change)
    det: TemplateDetector | BandDetector | ConfirmedStopDetector = fast
    if confirm_s:
        det = ConfirmedStopDetector(fast, confirm_s, step_clock=step_clock, late=late, params=confirm)
    if step_rate_hz is not None:
        det.reset(t0_s, step_rate_hz)
    events: list[StopEvent] = []
    if isinstance(samples, np.ndarray):
        for i in range(0, samples.size, block):
            events += det.feed(samples[i : i + block])
    else:
        for b in samples:
            events += det.feed(b)
    if isinstance(det, ConfirmedStopDetector):
        events += det.finish()
    return events


def frame_levels_db(samples: NDArray[Any], tuning: Tuning) -> NDArray[np.float64]:
    """The detector's level for every frame of ``samples`` (frame i ends at sample i*hop+frame-1).

    dBFS, or dB relative to the reference band when the tuning has one; for a template
    tuning the stop-likeness (dimensionless, NaN while the template is learned).
    """
    if tuning.method == "template":
        det = TemplateDetector(tuning)
        det.state.trace = []
        det.feed(np.asarray(samples))
        return np.asarray(det.state.trace, dtype=np.float64)
    return band_levels_db(samples, tuning.sample_rate, tuning.frame, tuning.hop, tuning.band_hz, tuning.reference_hz)


def plot_levels(
    samples: NDArray[Any],
    tuning: Tuning,
    t0_s: float = 0.0,
    stop_at_s: float | None = None,
    ax: Any = None,
) -> Any:
    """Plot the band level of a recording over time with the threshold and the events.

    Parameters
    ----------
    samples : numpy.ndarray
        Mono recording at ``tuning.sample_rate``.
    tuning : Tuning
        Band and threshold to show.
    t0_s : float
        Stream time of the first sample, s.
    stop_at_s : float, optional
        True stop time, s, drawn as a dashed line.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on (default: a new figure).

    Returns
    -------
    matplotlib.axes.Axes
    """
    try:
        import matplotlib

        if ax is None and not has_display():
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'stickslip[plot]'") from e
    levels = frame_levels_db(samples, tuning)
    t = t0_s + (np.arange(levels.size) * tuning.hop + tuning.frame - 1) / tuning.sample_rate
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 3), constrained_layout=True)  # the axis labels inside the figure
    lo, hi = tuning.band_hz
    template = tuning.method == "template"  # its level is a stop-likeness over the band, not the band's level
    ax.plot(t, levels, lw=0.8, label=f"{'stop-likeness over ' if template else ''}band {lo:.0f}-{hi:.0f} Hz")
    ax.axhline(tuning.threshold_db, color="C3", lw=1, label="threshold")
    ax.axhline(tuning.threshold_db - tuning.hysteresis_db, color="C3", lw=0.8, ls=":", label="re-arm level")
    events = detect(samples, tuning, t0_s=t0_s)
    for i, ev in enumerate(events):
        ax.axvline(ev.detected_at_s, color="C2", lw=1, label="detected" if i == 0 else None)
    ax.set_title(f"end-stop detector: {len(events)} stop{'' if len(events) == 1 else 's'} detected")
    if stop_at_s is not None:
        ax.axvline(stop_at_s, color="k", ls="--", lw=1, label="true stop")
    ax.set_xlabel("time (s)")
    # a template tuning's level is a stop-likeness (its unit is a parenthesis): on two lines, to fit 3 inches
    ax.set_ylabel("stop-likeness\n(0 stepping, 1 the tuned stop)" if template else f"band level ({tuning.level_unit})")
    ax.legend(loc="best", fontsize="small")
    return ax
