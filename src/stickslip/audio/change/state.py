"""The change detector's state over a stream: frames' sub-band levels in, fires out (:class:`ChangeState`).

Per frame, the departure from the stepping template (:mod:`.template`) is fitted to the
stop's signature (:mod:`.fit`, :mod:`.rate`): the stop-likeness ``a`` and the residual
``rho``. A frame is *hot* when ``a >= threshold``, ``rho <= residual_max`` and the drops the
stop shows come with it in proportion, or when the drop channel hears a lasting drop
(:mod:`.drops`). The detector fires when ``hold`` of the last ``hold + max_dips`` frames
were hot, the current one included, and the current ``a`` has not decayed below
``decay_ratio`` of the largest in that window (a transient rings down, a stop does not); the
onset is the interpolated crossing of the threshold that began the run. It then stays
latched until ``a`` stayed below ``threshold - hysteresis`` for ``release_s``, or the joint
steps again (:mod:`.release`). Two judgements may undo or make a fire: the stale-template
check (:mod:`.stale`) and, at the warm-up's end, whether listening began at the stop
(:mod:`.start`).

Everything that changes the state happens at frame boundaries counted from the stream
start (the template is updated every ``chunk`` frames), and each frame's numbers are
computed frame by frame (:mod:`.fit`, :func:`.drops.window_sums`: no rounding that depends
on the frames fed with it), so the fires do not depend on how the stream is cut into blocks.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..events import check_step_rate
from ..features.fine import SignaturePredictor
from ..features.spectra import SPECTRA, SpectraParams
from ..features.stepclock import rate_near_hz
from .added import ADDED, AddedParams, joint_alone_db
from .drops import DROPS, DropCheck, DropParams
from .fit import FIT, FitParams
from .hold import Hold
from .rate import RATE, RateFits, RateParams
from .release import RELEASE, ReleaseParams, StopRelease
from .stale import STALE, StaleCheck, StaleParams
from .start import START, StartParams, start_shift
from .template import TEMPLATE, RunningTemplate, TemplateParams
from .tuned import Decision, TunedTemplate

__all__ = ["ChangeParams", "ChangeState"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ChangeParams:
    """The change detector's parameters, one dataclass per part."""

    template: TemplateParams = field(default_factory=lambda: TEMPLATE)
    fit: FitParams = field(default_factory=lambda: FIT)
    drops: DropParams = field(default_factory=lambda: DROPS)
    rate: RateParams = field(default_factory=lambda: RATE)
    start: StartParams = field(default_factory=lambda: START)
    stale: StaleParams = field(default_factory=lambda: STALE)
    release: ReleaseParams = field(default_factory=lambda: RELEASE)
    spectra: SpectraParams = field(default_factory=lambda: SPECTRA)
    #: sound added from the start of listening (None: the floor is the templates' alone, as before)
    added: AddedParams | None = field(default_factory=lambda: ADDED)


class ChangeState:
    """The streaming state of the change detector (see the module docstring).

    :meth:`process` takes the sub-band levels of consecutive frames and their end-sample
    indices and returns the :class:`~.tuned.Decision` s that fired.
    """

    def __init__(self, tuned: TunedTemplate, params: ChangeParams | None = None, t0_s: float = 0.0) -> None:
        self.tuned = tuned
        self.params = params = params or ChangeParams()
        self.delta = np.asarray(tuned.signature_db, dtype=np.float64)
        self.tpl = RunningTemplate(tuned.tau_s, tuned.hop, tuned.sample_rate, params.template)
        self.fits = RateFits(tuned, params.rate, params.fit)
        self.drops = DropCheck(tuned, params.drops, params.fit)
        self.release = StopRelease(tuned, params.release)
        self.hold = Hold(tuned)
        self.stale = StaleCheck(tuned, params.template.chunk, params.template.quantile, params.stale,
                                params.start, params.spectra)  # fmt: skip
        #: set to a list to collect every frame's stop-likeness (NaN while warming up)
        self.trace: list[float] | None = None
        #: set to a list to collect every frame's hot flag (False while warming up)
        self.hot_trace: list[bool] | None = None
        #: the stream's samples ``[lo, hi)`` (absolute indices), or None where they are gone; set by the stream's
        #: owner where the stale check or the rate prediction needs them
        self.samples: Callable[[int, int], FloatArray | None] | None = None
        #: set by a confirming owner: a fire holds the latch (:attr:`held`) from its own frame until the owner decides
        #: (not from the end of the block the owner hears of it in: that would depend on the block size)
        self.hold_on_fire = False
        self.reset(t0_s)

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Forget the template, the warm-up's samples and every decision; ``step_rate_hz``: the commanded rate, Hz."""
        #: the step rate the controller commands for the stream that follows, Hz (None: not told)
        self.commanded_hz = check_step_rate(step_rate_hz)
        #: the warm-up's samples from the stream start (:attr:`head_samples` of them); set by the stream's owner
        self.head: FloatArray | None = None
        self._head_rate: float | None = None  # the step rate heard in them (once), Hz
        self.t0 = float(t0_s)
        self.frame_no = 0
        self.latched = False
        self.below = 0
        self.held = False  # set by a confirming wrapper while it judges the latest fire: no re-arming by itself
        self.hold.reset(self.t0)
        self.last_a = 0.0
        self.last_rho = 0.0
        self._pending: list[Decision] = []
        for part in (self.tpl, self.fits, self.drops, self.release, self.stale):
            part.reset()

    # --- what others read -----------------------------------------------------------------------
    @property
    def warm_frames(self) -> int:
        return self.tuned.warmup_chunks * self.params.template.chunk

    @property
    def warming(self) -> bool:
        """True until the template has been learned from the first frames."""
        return self.tpl.template is None or self.frame_no < self.warm_frames

    @property
    def head_samples(self) -> int:
        """How many samples from the stream start the warm-up's frames span (what :attr:`head` must hold)."""
        return (self.warm_frames - 1) * self.tuned.hop + self.tuned.frame

    @property
    def needs_samples(self) -> bool:
        """The stale check or the rate prediction reads the stream's samples (:attr:`samples`)."""
        return self.stale.enabled or self.fits.predicts

    @property
    def relearned(self) -> list[int]:
        """The stream samples at which a template that fitted nothing was learned anew."""
        return self.tpl.relearned

    def predictor(self) -> SignaturePredictor:
        return self.fits.predictor()

    # --- latching -------------------------------------------------------------------------------
    def unlatch(self) -> None:
        """Re-arm: forget the latest fire and listen again from the next frame; the template is kept."""
        self.latched = False
        self.held = False
        self.below = 0
        self.release.reset()
        self.hold.clear()

    def _latch(self) -> None:
        """A stop fired (or listening began at it): latched, its release window and its own sound to learn anew."""
        self.latched = True
        self.held = self.held or self.hold_on_fire
        self.below = 0
        self.release.reset()

    # --- the stream -----------------------------------------------------------------------------
    def process(self, v: FloatArray, ends: NDArray[np.int64]) -> list[Decision]:
        """Consume the levels ``v`` (frames x bands, dB) of the next frames; ``ends`` are their last samples."""
        chunk = self.params.template.chunk
        out: list[Decision] = []
        i = 0
        n = v.shape[0]
        while i < n:
            room = chunk - self.frame_no % chunk
            left = self.stale.frames_left(self.frame_no)
            if left is not None:
                room = min(room, left)
            j = min(n, i + room)
            cut = None
            if self.latched and not self.warming and self.tpl.template is not None:
                cut = self.release.scan(v[i:j], self.tpl.template, self.held)
                if cut is not None:
                    j = i + cut + 1
            out += self._segment(v[i:j], ends[i:j])
            self.frame_no += j - i
            i = j
            if cut is not None:
                self._relearn_after_stop(int(ends[j - 1]))
            if self.stale.due(self.frame_no):
                self._stale_check(int(ends[j - 1]))
            if self.frame_no % chunk == 0:
                self._chunk_done(int(ends[j - 1]))
                out += self._pending
                self._pending = []
        return out

    def _segment(self, v: FloatArray, ends: NDArray[np.int64]) -> list[Decision]:
        tu = self.tuned
        tpl = self.tpl
        if self.frame_no < self.warm_frames or tpl.template is None:
            tpl.warm(v)
            if self.trace is not None:
                self.trace.extend([math.nan] * v.shape[0])
            if self.hot_trace is not None:
                self.hot_trace.extend([False] * v.shape[0])
            return []
        if self.stale.enabled:
            self.stale.remember(self.frame_no, v)
        d = v - tpl.template
        a, rho, pred_drops = self.fits.fit(d, self.params.drops.pred_drops_rho)
        hot = (a >= tu.threshold) & (rho <= tu.residual_max)
        quiet = a < self.params.template.quiet * tu.threshold
        floor = tpl.template if tpl.floor is None else tpl.floor
        a, hot, lag, unasked = self.drops.judge(v, floor, a, hot, ends, self.fits.pred_delta, pred_drops)
        self.last_a, self.last_rho = float(a[-1]), float(rho[-1])
        if self.trace is not None:
            self.trace.extend(a.tolist())
        if self.hot_trace is not None:
            self.hot_trace.extend(hot.tolist())
        # the template follows every frame that is not stop-like (the low quantile taken per chunk ignores knocks
        # and voices); a chunk that fits neither stepping nor the stop at all means the template is stale
        tpl.gather(d, quiet, rho, v)
        if not self.latched and self.hold.mask == 0 and not (hot | unasked).any():
            self.hold.prev_a = float(a[-1])
            return []
        return self._decide(a, hot | unasked, ends, lag, d, v)  # unasked (:mod:`.drops`): may fire, not hot

    def _decide(
        self, a: FloatArray, hot: NDArray[np.bool_], ends: NDArray[np.int64], lag: FloatArray, d: FloatArray,
        v: FloatArray,
    ) -> list[Decision]:  # fmt: skip
        """The hold: fire, latch, and the quiet release, frame by frame."""
        tu = self.tuned
        out: list[Decision] = []
        rel = tu.threshold - tu.hysteresis
        hold = self.hold
        prev = hold.prev_a
        fired_here = False
        for k, (ai, hi, end, li) in enumerate(zip(a.tolist(), hot.tolist(), ends.tolist(), lag.tolist(), strict=True)):
            if self.latched:
                # the quiet release: a stayed below the re-arm level for release_s; the template then goes on
                # following (what a confirming wrapper relies on while it judges a fire on interference)
                self.below = self.below + 1 if ai < rel else 0
                if ai < rel and self.below >= tu.release_frames:
                    self.unlatch()
                if fired_here and self.latched:  # a frame after a fire in this piece (a piece that began latched
                    # was scanned by process): it cannot end the stop, the window is longer than a piece, but counts
                    self.release.frame(d[k], v[k], self.held)
            else:
                if hold.frame(ai, hi, end, li, prev):
                    self._latch()
                    fired_here = True
                    out.append(Decision(int(end), hold.cross_t, float(ai), uncertain=end < self.stale.uncertain_until))
                    if self.stale.enabled and self.samples is not None:
                        self.stale.schedule(self.frame_no + k + 1, int(end))
                hold.settle()
            prev = ai
        hold.prev_a = prev
        return out

    # --- the template's updates -----------------------------------------------------------------
    def _set_floor(self, reset: bool = False) -> None:
        """The template changed: its floor, the sound added to it, and the fits masked by that sound."""
        self.tpl.set_floor(self.drops.scale, reset=reset)
        self.fits.mask(self.tpl.added_db)

    def _chunk_done(self, end: int) -> None:
        if self.frame_no <= self.warm_frames:
            self._warm_chunk_done(end)
            return
        tpl = self.tpl
        old = tpl.relearn_if_stale(self.latched, self.tuned.residual_max)
        if old is not None:
            assert tpl.template is not None
            # a new level in every sub-band (listening began in silence, the microphone moved closer): the floor
            # starts anew; a rise in some sub-bands only is a sound added (a loud voice): the floor keeps the
            # stepping's level, or the pause after the voice would look like a stop's drops
            self._set_floor(reset=bool(np.min(tpl.template - old) > self.params.template.stale_all_up_db))
            tpl.note_relearned(end)  # for the confirming detector: a stop the template learned
            self._hear_rate_over(end, self.params.template.chunk * self.tuned.hop + self.tuned.frame)
            self.drops.restart(end + int(self.params.drops.arm_s * self.tuned.sample_rate))
        if tpl.follow(self.latched):
            self._set_floor()
        tpl.clear_gathered()

    def _warm_chunk_done(self, end: int) -> None:
        """A chunk of the warm-up heard: the template from it; at the warm-up's end, the checks that start there."""
        warm = self.tpl.learn_warm()
        self._set_floor(reset=True)
        if self.frame_no != self.warm_frames:
            return
        # the drop channel judges drops in the larger of the tuning's and this stream's spreads
        self.drops.learn_spread(warm)
        self.tpl.end_warm()
        self.drops.arm(end)
        if self.fits.predicts:
            self._hear_rate(self._heard_head_rate(), end)
        self._added_from_start()
        self._start(end)

    def _added_from_start(self) -> None:
        """Sound added from the first sample: the floor capped at the joint's own level (:mod:`.added`)."""
        if self.params.added is None or self.tpl.template is None:
            return
        alone = joint_alone_db(self.tpl.template, self.tuned, self._heard_head_rate(), self.params.added)
        if alone is not None:
            self.tpl.set_joint_alone(alone, self.drops.scale)
            self.fits.mask(self.tpl.added_db)

    def _start(self, end: int) -> None:
        """Did listening begin at the stop (:mod:`.start`)? Then fire at once, the onset the start of listening."""
        pm = self.params
        shift = start_shift(
            self.tpl.template, self.tuned, self.head, self._heard_head_rate, pm.template.quantile,
            pm.start, pm.fit, pm.spectra,
        )  # fmt: skip
        if shift is None or self.tpl.template is None:
            return
        self.tpl.set_levels(self.tpl.template - shift * self.delta)
        self._set_floor(reset=True)
        self._latch()
        self._pending.append(Decision(int(end), self.t0 + self.tuned.onset_lag_s, float(shift)))

    def _relearn_after_stop(self, end: int) -> None:
        """A stop ended: re-arm, and learn the template anew from the release window's stepping frames.

        What follows a stop is a new stretch of stepping (the joint reversed, or a new
        traverse at another rate). The floor starts anew: a floor kept from before the stop
        is the old stepping's and hid the next stop's drops (the fourth generator's arm 3:
        the next stop heard 27-109 ms late); a template kept from before the stop fired on
        stepping 4 % faster after it.
        """
        tu = self.tuned
        rows = self.release.window.stepping_rows()
        self.unlatch()
        if len(rows) < tu.release_frames // 2:
            return
        self.tpl.set_levels(np.percentile(np.stack(rows), 100 * self.params.template.quantile, axis=0))
        self._set_floor(reset=True)
        self.tpl.clear_gathered(chunk=True)  # what was gathered this chunk was measured against the old template
        self.drops.restart()
        # a new stretch of stepping, perhaps at another rate: hear it over the release window
        self._hear_rate_over(end, tu.release_frames * tu.hop + tu.frame)

    def _stale_check(self, end: int) -> None:
        """The stale-template check (:mod:`.stale`); a stale fire: the template learned anew, the detector re-armed."""
        latched = self.latched and self.tpl.template is not None
        template = self.stale.judge(end, latched, self.samples)
        if template is None:
            return
        sr = self.tuned.sample_rate
        self.tpl.set_levels(template)
        self._set_floor(reset=True)
        self.unlatch()
        self.hold.prev_a = -math.inf
        self.tpl.clear_gathered()
        self.drops.restart(end + int(self.params.drops.arm_s * sr))
        self._hear_rate_over(end, int(self.params.stale.relearn_s * sr) + self.tuned.frame)

    # --- the step rate --------------------------------------------------------------------------
    def _rate_in(self, x: FloatArray | None) -> float:
        """The step rate heard in ``x``, Hz (NaN: none), near the commanded rate if told (:func:`rate_near_hz`)."""
        return rate_near_hz(x, self.tuned.sample_rate, self.commanded_hz, self.params.rate.commanded_tol)

    def _heard_head_rate(self) -> float:
        """The step rate heard in the warm-up's samples :attr:`head`, Hz (NaN: none), heard once."""
        if self._head_rate is None:
            self._head_rate = self._rate_in(self.head)
        return self._head_rate

    def _hear_rate(self, rate: float, end: int) -> None:
        self.fits.hear(rate, end, commanded=self.commanded_hz is not None)
        self.drops.forget_predicted(self.fits.pred_told)

    def _hear_rate_over(self, end: int, n: int) -> None:
        """The rate over the stream's last ``n`` samples up to sample ``end`` (where they are kept): which fits."""
        if not self.fits.predicts:
            return
        self._hear_rate(self._rate_in(None if self.samples is None else self.samples(end + 1 - n, end + 1)), end)
