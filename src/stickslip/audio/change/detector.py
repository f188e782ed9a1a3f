"""The change detector as a stream: samples in, fires out (:class:`TemplateDetector`, the fast path).

It cuts the stream into frames (:mod:`stickslip.audio.features.frames`), measures each
frame's sub-band levels (:mod:`stickslip.audio.features.spectra`) and hands them to the
:class:`~.state.ChangeState`; a fire becomes a :class:`~stickslip.audio.events.StopEvent`
whose onset is the crossing that began the hold less the tuning's onset lag. Every fire is
emitted: confirming it by its persistence is the next stage's
(:mod:`stickslip.audio.confirm`), which reads the per-frame evidence this detector keeps
(:attr:`TemplateDetector.evidence`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..events import StopEvent
from ..features.frames import FrameCutter, HeadSamples, RecentSamples, bounded
from ..features.spectra import FramePowers, SubbandLevels, subband_bins, window
from ..tuningfile import Tuning
from .state import ChangeParams, ChangeState
from .tuned import TunedTemplate

__all__ = ["TemplateDetector"]


class TemplateDetector:
    """Streaming end-stop detector of a template tuning: ``feed`` blocks of samples, get :class:`StopEvent` s.

    Parameters
    ----------
    tuning : Tuning
        A template tuning (``method == "template"``; its ``sample_rate`` must be the stream's).
    t0_s : float
        Stream time of the first sample fed, s.
    params : ChangeParams, optional
        The change detector's parameters (default: :class:`~.state.ChangeParams`).
    """

    #: the no-signal guard applies: this detector listens to samples
    uses_audio = True

    def __init__(self, tuning: Tuning, t0_s: float = 0.0, params: ChangeParams | None = None) -> None:
        if tuning.method != "template":
            raise ValueError(f"a TemplateDetector needs a template tuning, not method {tuning.method!r}")
        self.tuning = tuning
        self.params = params or ChangeParams()
        #: the change detector's state (the template, the fits, the latch)
        self.state = ChangeState(TunedTemplate.from_tuning(tuning, self.params.template.chunk), self.params, t0_s)
        assert tuning.edges_hz is not None
        self._w, self._scale = window(tuning.frame)
        self._edge_bins = subband_bins(tuning.edges_hz, tuning.sample_rate, tuning.frame)
        self._levels = SubbandLevels(self._w, self._scale, self._edge_bins, self.params.spectra)
        self._cutter = FrameCutter(tuning.frame, tuning.hop)
        st = self.state
        # the warm-up's samples, for the judgement whether listening began at the stop (tunings with a step rate)
        self._head = HeadSamples(st.head_samples) if tuning.step_rate_hz is not None else None
        self._recent: RecentSamples | None = None
        if st.needs_samples:  # enough for the stepping before a fire and the span after it
            sp = self.params.stale
            keep = int((sp.gap_s + sp.ref_s + sp.after_s) * tuning.sample_rate) + 4 * tuning.frame + 128 * tuning.hop
            self._recent = RecentSamples(keep)
            st.samples = self._recent.get
        #: set to a list to collect every frame's *margin* over the threshold (``a / threshold - 1``; >= 0: the frame
        #: is stop-like; NaN while the template is learned). Frame ``i`` ends at stream sample
        #: ``i * hop + frame - 1``. What :mod:`stickslip.audio.confirm` watches after a fire.
        self.evidence: list[float] | None = None
        #: set to a list to collect every frame's full verdict alongside :attr:`evidence`: True where the frame is
        #: *hot* (stop-like by the fit with its residual and the drops in proportion, or by the drop channel)
        self.hot_evidence: list[bool] | None = None
        #: set to share the frames' spectra of whole sounds between detectors (a tuning's candidates): a stream fed
        #: in one block has its spectra from there (the same floats, computed once per sound)
        self.powers: FramePowers | None = None
        self.reset(t0_s)

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Forget everything; the next sample fed is at stream time ``t0_s``.

        ``step_rate_hz``: the step rate the controller commands, Hz (None: not told). The
        step clock is then heard near it, and the stop's signature is predicted at the rate
        heard up to ``RateParams.commanded_window`` from the tuning's (a traverse tells it).
        """
        self.t0_s = float(t0_s)
        self._cutter.reset()
        #: frames heard since the last reset (frame ``i`` ends at sample ``i * hop + frame - 1``)
        self.frames_seen = 0
        if self._head is not None:
            self._head.reset()
        if self._recent is not None:
            self._recent.reset()
        self.state.reset(t0_s, step_rate_hz)

    def hold(self, on: bool) -> None:
        """While ``on``, a latched detector does not re-arm by itself (a confirmation decides; :meth:`unlatch`)."""
        self.state.held = bool(on)

    @property
    def hold_on_fire(self) -> bool:
        """Whether every fire holds the latch from its own frame on (:meth:`hold`), until its owner decides.

        A confirming detector sets it: it hears of a fire only once the block that held it was
        fed, and holding from there would make the events depend on the block size.
        """
        return self.state.hold_on_fire

    @hold_on_fire.setter
    def hold_on_fire(self, on: bool) -> None:
        self.state.hold_on_fire = bool(on)

    def unlatch(self) -> None:
        """Forget the latest fire and listen for the next stop from the next frame on.

        For a fire that was not confirmed: the template, frozen since the fire, resumes
        following the stepping sound, so the rejected span never enters it.
        """
        self.state.unlatch()

    @property
    def latency_s(self) -> float:
        """Typical detected_at - true onset, s (for a traverse's latency correction)."""
        return self.tuning.latency_s

    @property
    def latched(self) -> bool:
        """True while a stop is being heard (after it fired, until released)."""
        return self.state.latched

    @property
    def level(self) -> float:
        """The latest frame's stop-likeness (0 stepping, 1 the tuned stop)."""
        return self.state.last_a

    @property
    def ready(self) -> bool:
        """False while the detector is still learning the stepping sound (it cannot fire yet)."""
        return not self.state.warming

    @property
    def relearned(self) -> list[int]:
        """The stream samples at which a template that fitted nothing was learned anew."""
        return self.state.relearned

    def feed(self, block: NDArray[Any]) -> list[StopEvent]:
        """Consume a block of mono samples; return the stops that fired in it."""
        x = bounded(block, self.params.spectra)
        st = self.state
        if self._head is not None and st.head is None:
            self._head.push(x)
            st.head = self._head.samples
        if self._recent is not None and x.size:
            self._recent.push(x)
        whole = self.powers is not None and self.frames_seen == 0 and self._cutter.fresh
        view = self._cutter.push(x)
        n = view.shape[0]
        events: list[StopEvent] = []
        if n > 0:
            if whole and self.powers is not None:
                v = self._levels.from_powers(self._levels.powers(x, self.tuning.hop, self.powers))
            else:
                v = self._levels(view)
            events = self._decide(v, self._cutter.ends(n))
            self.frames_seen += n
        self._cutter.advance(n)
        return events

    def _decide(self, v: NDArray[np.float64], ends: NDArray[np.int64]) -> list[StopEvent]:
        tu, st = self.tuning, self.state
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
        return [
            StopEvent(
                detected_at_s=self.t0_s + dec.end_sample / tu.sample_rate,
                onset_s=dec.cross_t_s - tu.onset_lag_s,
                level_db=dec.a,
                onset_uncertain=dec.uncertain,
            )
            for dec in decisions
        ]
