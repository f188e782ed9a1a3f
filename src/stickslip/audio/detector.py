"""Streaming end-stop detector: samples in, :class:`StopEvent` s out.

A :class:`~stickslip.audio.tuningfile.Tuning` of version 2 (what ``tune`` makes) runs
the spectral-template detector of :mod:`.template`; what follows describes the
band-power detector of version-1 tunings.

Per frame of ``frame`` samples (every ``hop`` samples) the detector takes a
Hann-windowed rfft and the power in the joint's band ``band_hz``, in dB relative to
full scale (``10 log10`` of the mean square the band contributes, so white noise of
variance s^2 spread over the whole spectrum sums to ``10 log10 s^2`` over all bands).

A stop is declared when the band level stays at or above ``threshold_db`` for
``hold_s`` (a knock or a burst of speech is shorter; up to ``max_dips`` frames of the
hold may dip below); it then stays latched until the
level has been below ``threshold_db - hysteresis_db`` for ``release_s``, so one stop
gives one event. There is no look-ahead beyond one frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..plotting import has_display
from .template import STALE_AFTER_S, STALE_GAP_S, STALE_REF_S, TemplateState, levels_from_frames
from .tuningfile import Tuning, TuningFileError

__all__ = [
    "StopDetector",
    "StopEvent",
    "Tuning",
    "TuningFileError",
    "band_levels_db",
    "detect",
    "frame_levels_db",
    "plot_levels",
]

_FLOOR = 1e-20
_LIMIT = 1e15  # samples beyond this (full scale is 1) are clipped: their squares stay finite in float32


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
        :mod:`.confirm`); ``None`` from a detector that does not confirm.
    confirmed_s : float or None
        How long the stop was heard persisting after it fired before it was emitted, s:
        the confirmation window, or less when the stream ended first; ``None`` from a
        detector that does not confirm.
    onset_uncertain : bool
        The stop was already there when the confirming detector began listening again
        after a fire it rejected: it began before ``onset_s``, by up to that fire's
        window (:mod:`.confirm`). Do not count to it.
    found_late : bool
        The fast path never heard this stop: the late path found it on the step clock's
        lines 0.5-0.75 s after it and estimated its onset back (:mod:`.late`, opt-in).
        ``detected_at_s`` is when it was found, not the fast path's 30-50 ms.
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


def _band_bins(tuning_or_band: tuple[float, float], sample_rate: int, frame: int) -> tuple[int, int]:
    lo, hi = tuning_or_band
    freqs = np.fft.rfftfreq(frame, 1 / sample_rate)
    i0 = int(np.searchsorted(freqs, lo, side="left"))
    i1 = int(np.searchsorted(freqs, hi, side="right"))
    return i0, max(i1, i0 + 1)


def _window(frame: int) -> tuple[np.ndarray, float]:
    w = np.hanning(frame + 1)[:-1]  # periodic Hann
    scale = 2.0 / (frame * float(np.sum(w**2)))
    return w, scale


def frame_power_spectra(samples: np.ndarray, frame: int, hop: int) -> np.ndarray:
    """Per-frame one-sided power spectra (frames x bins), scaled so bins sum to mean square.

    Frame ``i`` covers samples ``[i*hop, i*hop + frame)``.
    """
    x = np.asarray(samples, dtype=np.float64)
    if x.size < frame:
        return np.zeros((0, frame // 2 + 1))
    frames = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    w, scale = _window(frame)
    spec = np.fft.rfft(frames * w, axis=1)
    p = (spec.real**2 + spec.imag**2) * scale
    p[:, 0] *= 0.5
    if frame % 2 == 0:
        p[:, -1] *= 0.5
    return p


def frame_levels_db(samples: np.ndarray, tuning: Tuning) -> np.ndarray:
    """The detector's level for every frame of ``samples`` (frame i ends at sample i*hop+frame-1).

    dBFS, or dB relative to the reference band when the tuning has one; for a template
    tuning the stop-likeness (dimensionless, NaN while the template is learned).
    """
    if tuning.method == "template":
        det = StopDetector(tuning)
        assert det._template is not None
        det._template.trace = []
        det.feed(np.asarray(samples))
        return np.asarray(det._template.trace, dtype=np.float64)
    return band_levels_db(samples, tuning.sample_rate, tuning.frame, tuning.hop, tuning.band_hz, tuning.reference_hz)


def band_levels_db(
    samples: NDArray[Any],
    sample_rate: int,
    frame: int,
    hop: int,
    band_hz: tuple[float, float],
    reference_hz: tuple[float, float] | None = None,
) -> NDArray[np.float64]:
    """Band level per frame, dBFS (see :func:`frame_power_spectra`); minus the reference band's if given."""
    p = frame_power_spectra(samples, frame, hop)
    i0, i1 = _band_bins(band_hz, sample_rate, frame)
    level = 10 * np.log10(p[:, i0:i1].sum(axis=1) + _FLOOR)
    if reference_hz is not None:
        r0, r1 = _band_bins(reference_hz, sample_rate, frame)
        level -= 10 * np.log10(p[:, r0:r1].sum(axis=1) + _FLOOR)
    return np.asarray(level, dtype=np.float64)


class StopDetector:
    """Streaming end-stop detector: ``feed`` blocks of samples, get :class:`StopEvent` s.

    Parameters
    ----------
    tuning : Tuning
        Band, threshold and timing (its ``sample_rate`` must be the stream's).
    t0_s : float
        Stream time of the first sample fed, s.

    Examples
    --------
    >>> det = StopDetector(Tuning(band_hz=(5600, 7100), threshold_db=-50))
    >>> det.feed(np.zeros(4800, dtype=np.float32))
    []
    """

    def __init__(self, tuning: Tuning, t0_s: float = 0.0) -> None:
        self.tuning = tuning
        self._template: TemplateState | None = None
        if tuning.method == "template":
            assert tuning.edges_hz is not None
            self._template = TemplateState(tuning.template_params(), t0_s)
            freqs = np.fft.rfftfreq(tuning.frame, 1 / tuning.sample_rate)
            self._edge_bins = np.asarray(
                np.searchsorted(freqs, np.asarray(tuning.edges_hz), side="left"), dtype=np.intp
            )
        self._w, self._scale = _window(tuning.frame)
        self._i0, self._i1 = _band_bins(tuning.band_hz, tuning.sample_rate, tuning.frame)
        self._ref = _band_bins(tuning.reference_hz, tuning.sample_rate, tuning.frame) if tuning.reference_hz else None
        self._hold = tuning.hold_frames
        self._full = (1 << (self._hold + tuning.max_dips)) - 1
        self._release = max(1, int(math.ceil(tuning.release_s * tuning.sample_rate / tuning.hop)))
        #: set to a list to collect every frame's *margin* over the threshold (>= 0: the frame is
        #: stop-like): ``a / threshold - 1`` for a template tuning (the stop-likeness, NaN while the
        #: template is learned), ``level - threshold`` in dB for a band tuning. Frame ``i`` ends at
        #: stream sample ``i * hop + frame - 1``. What :mod:`.confirm` watches after a fire.
        self.evidence: list[float] | None = None
        #: set to a list to collect every frame's full verdict, alongside :attr:`evidence`: True where
        #: the frame is *hot* (template: stop-like by the fit with its residual and the drops the stop
        #: shows in proportion, or by the drop channel; band: the level at or above the threshold)
        self.hot_evidence: list[bool] | None = None
        self.reset(t0_s)

    def reset(self, t0_s: float = 0.0) -> None:
        """Forget everything; the next sample fed is at stream time ``t0_s``."""
        self._t0 = float(t0_s)
        self._buf = np.zeros(0, dtype=np.float64)
        self._buf_start = 0  # absolute sample index of _buf[0]
        self._next = 0  # absolute sample index where the next frame starts
        self._mask = 0  # bit i: frame i hops ago was above threshold
        self._latched = False
        self._below = 0
        self._prev_db = -np.inf
        self._cross_t = math.nan
        self.levels_seen = 0
        self._head: list[np.ndarray] = []  # the warm-up's samples, kept until the template state has them
        self._head_n = 0
        self._ring: list[np.ndarray] = []  # the latest samples, from absolute sample _ring0 on (stale-template check)
        self._ring0 = 0
        self._ring_n = 0
        if self._template is not None:
            self._template.reset(t0_s)
            if self._template._checks or self._template.predicts:
                self._template.samples = self._samples

    def hold(self, on: bool) -> None:
        """While ``on``, a latched template detector does not re-arm by itself (:mod:`.confirm` holds it while it
        decides whether the latest fire was a stop; :meth:`unlatch` re-arms it). A band tuning's detector ignores it."""
        if self._template is not None:
            self._template.held = bool(on)

    def unlatch(self) -> None:
        """Forget the latest fire and listen for the next stop from the next frame on.

        For a fire that was not confirmed (:mod:`.confirm`): the template, frozen since the
        fire, resumes following the stepping sound, so the rejected span never enters it.
        """
        if self._template is not None:
            self._template.unlatch()
        else:
            self._latched = False
            self._below = 0
            self._mask = 0

    @property
    def frames_seen(self) -> int:
        """Frames heard since the last :meth:`reset` (frame ``i`` ends at sample ``i * hop + frame - 1``)."""
        return self.levels_seen

    @property
    def latency_s(self) -> float:
        """Typical detected_at - true onset, s (for a traverse's latency correction)."""
        return self.tuning.latency_s

    @property
    def latched(self) -> bool:
        """True while a stop is being heard (after it fired, until released)."""
        if self._template is not None:
            return self._template.latched
        return self._latched

    @property
    def level(self) -> float:
        """The latest frame's level in the tuning's unit (stop-likeness for a template tuning)."""
        if self._template is not None:
            return self._template.last_a
        return float(self._prev_db)

    @property
    def ready(self) -> bool:
        """False while a template detector is still learning the stepping sound (it cannot fire yet)."""
        return self._template is None or not self._template.warming

    def feed(self, block: np.ndarray) -> list[StopEvent]:
        """Consume a block of mono samples; return the stops that fired in it."""
        x = np.asarray(block, dtype=np.float64)
        if x.ndim != 1:
            raise ValueError(f"feed expects a 1-D mono block, got shape {x.shape}")
        if x.size and not float(np.max(np.abs(x))) <= _LIMIT:  # NaN, infinity or absurd values: bounded
            x = np.clip(np.nan_to_num(x, nan=0.0, posinf=_LIMIT, neginf=-_LIMIT), -_LIMIT, _LIMIT)
        tu = self.tuning
        F, H = tu.frame, tu.hop
        st0 = self._template
        if st0 is not None and st0.head is None and tu.step_rate_hz is not None:
            # the warm-up's samples, for the judgement whether listening began at the stop (template.py)
            need = st0.head_samples - self._head_n
            if need > 0 and x.size:
                self._head.append(x[:need].copy())
                self._head_n += min(need, x.size)
            if self._head_n >= st0.head_samples:
                st0.head = np.concatenate(self._head)
                self._head = []
        if st0 is not None and st0.samples is not None and x.size:
            self._keep(x)
        self._buf = np.concatenate((self._buf, x)) if self._buf.size else x.copy()
        avail_end = self._buf_start + self._buf.size
        n_frames = (avail_end - F - self._next) // H + 1 if avail_end - self._next >= F else 0
        events: list[StopEvent] = []
        if n_frames > 0:
            off = self._next - self._buf_start
            seg = self._buf[off:]
            view = np.lib.stride_tricks.as_strided(
                seg,
                shape=(n_frames, F),
                strides=(H * seg.strides[0], seg.strides[0]),
                writeable=False,
            )
            if self._template is not None:
                v = levels_from_frames(view, self._w, self._scale, self._edge_bins)
                ends = self._next + np.arange(n_frames, dtype=np.int64) * H + F - 1
                st = self._template
                if self.evidence is not None and st.trace is None:
                    st.trace = []
                if self.hot_evidence is not None and st.hot_trace is None:
                    st.hot_trace = []
                decisions = st.process(v, ends)
                if self.evidence is not None and st.trace is not None:
                    self.evidence.extend((np.asarray(st.trace) / tu.threshold_db - 1.0).tolist())
                    st.trace.clear()
                if self.hot_evidence is not None and st.hot_trace is not None:
                    self.hot_evidence.extend(st.hot_trace)
                    st.hot_trace.clear()
                for dec in decisions:
                    events.append(
                        StopEvent(
                            detected_at_s=self._t0 + dec.end_sample / tu.sample_rate,
                            onset_s=dec.cross_t_s - tu.onset_lag_s,
                            level_db=dec.a,
                            onset_uncertain=dec.uncertain,
                        )
                    )
                levels = None
            elif self._ref is None:
                spec = np.fft.rfft(view * self._w, axis=1)[:, self._i0 : self._i1]
                power = (spec.real**2 + spec.imag**2).sum(axis=1) * self._scale
                levels = 10 * np.log10(power + _FLOOR)
            else:  # the band relative to the reference band: a microphone gain change cancels
                spec = np.fft.rfft(view * self._w, axis=1)
                p = spec.real**2 + spec.imag**2
                r0, r1 = self._ref
                levels = 10 * np.log10(p[:, self._i0 : self._i1].sum(axis=1) * self._scale + _FLOOR) - 10 * np.log10(
                    p[:, r0:r1].sum(axis=1) * self._scale + _FLOOR
                )
            if levels is not None:
                if self.evidence is not None:
                    self.evidence.extend((levels - tu.threshold_db).tolist())
                if self.hot_evidence is not None:
                    self.hot_evidence.extend((levels >= tu.threshold_db).tolist())
                ends = self._next + np.arange(n_frames) * H + F - 1
                events = self._run(levels, ends)
            self._next += n_frames * H
            self.levels_seen += n_frames
        drop = self._next - self._buf_start
        if drop > 0:
            self._buf = self._buf[drop:]
            self._buf_start += drop
        return events

    def _keep(self, x: np.ndarray) -> None:
        """Keep the latest samples: enough for the stepping before a fire and the span after it."""
        tu = self.tuning
        keep = int((STALE_GAP_S + STALE_REF_S + STALE_AFTER_S) * tu.sample_rate) + 4 * tu.frame + 128 * tu.hop
        self._ring.append(x.copy())
        self._ring_n += x.size
        if self._ring_n - self._ring[-1].size > 2 * keep:  # trim now and then, not every block
            whole = np.concatenate(self._ring[:-1])[-keep:]
            self._ring0 += self._ring_n - self._ring[-1].size - whole.size
            self._ring = [whole, self._ring[-1]]
            self._ring_n = whole.size + self._ring[-1].size

    def _samples(self, lo: int, hi: int) -> np.ndarray | None:
        """The stream's samples ``[lo, hi)`` (absolute indices), or None where they are not kept."""
        if lo < self._ring0 or hi > self._ring0 + self._ring_n or lo < 0 or hi <= lo:
            return None
        whole = np.concatenate(self._ring) if len(self._ring) > 1 else self._ring[0]
        if len(self._ring) > 1:
            self._ring = [whole]
        return np.asarray(whole[lo - self._ring0 : hi - self._ring0], dtype=np.float64)

    def _run(self, levels: np.ndarray, ends: np.ndarray) -> list[StopEvent]:
        tu = self.tuning
        thr, rel = tu.threshold_db, tu.threshold_db - tu.hysteresis_db
        sr, H = tu.sample_rate, tu.hop
        if not self._latched and self._mask == 0 and float(levels.max()) < thr:
            self._prev_db = float(levels[-1])  # fast path: nothing near a stop
            return []
        events = []
        prev = self._prev_db
        full = self._full
        for lev, end in zip(levels.tolist(), ends.tolist(), strict=True):
            if self._latched:
                if lev < rel:
                    self._below += 1
                    if self._below >= self._release:
                        self._latched = False
                        self._mask = 0
                else:
                    self._below = 0
            else:
                above = lev >= thr
                if above and self._mask == 0:
                    # interpolate the crossing between the previous frame and this one
                    t_end = self._t0 + end / sr
                    if math.isfinite(prev) and prev < thr and lev > prev:
                        frac = (thr - prev) / (lev - prev)
                        self._cross_t = float(t_end - (1 - frac) * H / sr)
                    else:
                        self._cross_t = t_end
                # debounce: hold_frames above threshold among the last
                # hold_frames + max_dips frames (a knock lights fewer; a stop all)
                self._mask = ((self._mask << 1) | above) & full
                if above and self._mask.bit_count() >= self._hold:
                    self._latched = True
                    self._below = 0
                    events.append(
                        StopEvent(
                            detected_at_s=self._t0 + end / sr,
                            onset_s=self._cross_t - tu.onset_lag_s,
                            level_db=float(lev),
                        )
                    )
            prev = lev
        self._prev_db = prev
        return events


def detect(
    samples: np.ndarray | Iterable[np.ndarray],
    tuning: Tuning,
    t0_s: float = 0.0,
    block: int = 1 << 16,
    confirm_s: float = 0.0,
    late: bool = False,
) -> list[StopEvent]:
    """Run a fresh :class:`StopDetector` over a whole recording (or an iterable of blocks).

    ``confirm_s`` > 0 reports a stop only once it persisted that long, s
    (:class:`~stickslip.audio.confirm.ConfirmedStopDetector`; a stop the recording ends on
    is reported if it persisted so far); 0, the default, reports every fire. ``late`` also
    reports stops the fast path never heard, found late on the step clock (:mod:`.late`;
    with ``confirm_s`` > 0 only).
    """
    from .confirm import ConfirmedStopDetector, confirming

    det = confirming(StopDetector(tuning, t0_s), confirm_s, late=late)
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


def plot_levels(
    samples: np.ndarray,
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
        _, ax = plt.subplots(figsize=(8, 3))
    lo, hi = tuning.band_hz
    ax.plot(t, levels, lw=0.8, label=f"band {lo:.0f}-{hi:.0f} Hz")
    ax.axhline(tuning.threshold_db, color="C3", lw=1, label="threshold")
    ax.axhline(tuning.threshold_db - tuning.hysteresis_db, color="C3", lw=0.8, ls=":", label="re-arm level")
    for i, ev in enumerate(detect(samples, tuning, t0_s=t0_s)):
        ax.axvline(ev.detected_at_s, color="C2", lw=1, label="detected" if i == 0 else None)
    if stop_at_s is not None:
        ax.axvline(stop_at_s, color="k", ls="--", lw=1, label="true stop")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"band level ({tuning.level_unit})")
    ax.legend(loc="best", fontsize="small")
    return ax
