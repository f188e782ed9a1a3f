"""Was a fire the template gone stale with a drifting step rate? The continuum says.

A click train's lines move across narrow modes as the step rate moves, and the sub-band
levels with them, faster than the template follows (a rate drifting 10 % over 2 s): the
levels depart from the template while the continuum between the lines
(:func:`~stickslip.audio.features.spectra.continuum_levels_db`), which the rate does not
move, stays as it was. A stop changes it, in level (a quieter stop) or in shape.
``after_s`` after a fire, the continuum since the fire is compared with the stepping's
before it (``ref_s`` ending ``gap_s`` before the fire), each at the step rate heard in it.
The fire was a stale template where the rate moved by ``min_rate_change`` or more, the level
by less than ``max_gain_db`` and the shape by less than ``max_shape`` (the RMS over
sub-bands of what is left after the level, in the tuning's continuum spreads), and the
stepping before it did not already sound like the stop (``ref_max_b``). The template is then
learned anew from the last ``relearn_s`` (from the frames before the fire where that no
longer sounds like stepping), the detector listens again, and a fire in the next
``uncertain_s`` is flagged uncertain. No verdict (the fire stands) when the detector is no
longer latched, the samples are gone, no rate is heard, or fewer than three sub-bands can
be judged. Tunings that hold the continuum only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..features.spectra import SPECTRA, SpectraParams, continuum_levels_db
from ..features.stepclock import step_rate_hz
from ..paramfield import param
from .start import START, StartParams, gain_and_signature
from .tuned import TunedTemplate

__all__ = ["STALE", "StaleCheck", "StaleParams"]

FloatArray = NDArray[np.float64]
Samples = Callable[[int, int], FloatArray | None]


@dataclass(frozen=True)
class StaleParams:
    """When a fire is judged a stale template (the step rate moved), not a stop."""

    after_s: float = param(0.3, "s", "the continuum over this long after the fire ...")
    ref_s: float = param(0.3, "s", "... against the stepping's over this long before it (at least half of it) ...")
    gap_s: float = param(0.06, "s", "... ending this long before the fire (the onset is a hold before it)")
    min_rate_change: float = param(
        0.01, "of the rate", "judged only where the rate moved this much: where it stayed, confirmation judges"
    )
    max_rate_jump: float = param(
        0.1, "of the rate", "a larger jump is an estimate that took a multiple: the rate over both spans decides"
    )
    max_gain_db: float = param(3.0, "dB", "the continuum's level moved less than this (a quieter stop: 7-8 dB) ...")
    max_shape: float = param(1.1, "spreads", "... and its shape less than this: stale")
    uncertain_s: float = param(0.3, "s", "a fire this soon after a stale verdict may have begun inside the span")
    relearn_s: float = param(0.15, "s", "the template is learned anew from this much of the span's end")
    ref_max_b: float = param(
        0.5, "signatures", "a stepping before the fire that gives the stop this much already was the stop (late fire)"
    )


STALE = StaleParams()


@dataclass(frozen=True)
class _Spans:
    """The two stretches compared, their rates (Hz) and the continuum's change between them."""

    levels: tuple[FloatArray, FloatArray]
    rates: tuple[float, float]
    moved: float
    gain: float
    shape: float
    ok: NDArray[np.bool_]
    w: FloatArray
    spread: FloatArray


class StaleCheck:
    """The stale-template check over a stream (see the module docstring)."""

    def __init__(
        self,
        tuned: TunedTemplate,
        chunk: int,
        quantile: float,
        p: StaleParams = STALE,
        start: StartParams = START,
        spectra: SpectraParams = SPECTRA,
    ) -> None:
        self.tuned, self.chunk, self.quantile = tuned, chunk, quantile
        self.p, self.start, self.spectra = p, start, spectra
        #: the tuning holds the continuum: the check runs
        self.enabled = tuned.has_continuum
        self.after_frames = max(chunk + 1, int(math.ceil(p.after_s * tuned.sample_rate / tuned.hop)))
        #: per check since the detector was made: (the fire's end sample, the rate's relative change, the
        #: continuum's level change dB and shape change (spreads), judged stale)
        self.log: list[tuple[int, float, float, float, bool]] = []
        self.reset()

    def reset(self) -> None:
        """A new stream (the log is kept)."""
        self._check: tuple[int, int] | None = None  # (frame at which to check, the fire's end sample)
        self.uncertain_until = -1  # a fire ending before this sample follows a stale-template verdict closely
        self._recent_v: list[tuple[int, FloatArray]] = []  # (first frame index, levels) of the latest frames

    def frames_left(self, frame_no: int) -> int | None:
        """Frames until the check is due (None: none pending, or due already)."""
        if self._check is not None and self._check[0] > frame_no:
            return self._check[0] - frame_no
        return None

    def schedule(self, frame_after_fire: int, fire_end: int) -> None:
        """A fire at stream sample ``fire_end``; ``frame_after_fire`` is the frame number after it."""
        self._check = (frame_after_fire + self.after_frames, int(fire_end))

    def due(self, frame_no: int) -> bool:
        return self._check is not None and frame_no >= self._check[0]

    def remember(self, frame_no: int, v: FloatArray) -> None:
        """Keep the levels ``v`` of the frames from ``frame_no`` on (as far back as a relearn may reach)."""
        self._recent_v.append((frame_no, v))
        while self._recent_v and self._recent_v[0][0] + self._recent_v[0][1].shape[0] < (
            frame_no - self.after_frames - self.chunk
        ):
            self._recent_v.pop(0)

    def judge(self, end: int, latched: bool, samples: Samples | None) -> FloatArray | None:
        """The check is due at stream sample ``end``: the template to learn anew (stale), or None (the fire stands)."""
        assert self._check is not None
        at, fire_end = self._check
        self._check = None
        if not latched or samples is None:
            return None
        spans = self._spans(fire_end, samples)
        if spans is None:
            return None
        p = self.p
        stale = spans.moved >= p.min_rate_change and abs(spans.gain) < p.max_gain_db and spans.shape < p.max_shape
        if stale:
            stale = not self._reference_was_stop(spans)
        self.log.append((fire_end, spans.moved, spans.gain, spans.shape, stale))
        if not stale:
            return None
        template = self._relearned(end, at, samples, spans)
        if template is not None:
            self.uncertain_until = end + int(p.uncertain_s * self.tuned.sample_rate)
        return template

    def _rates(self, ref: FloatArray, after: FloatArray) -> tuple[float, float] | None:
        """The step rate heard in each span, Hz (None: not heard in both)."""
        sr = self.tuned.sample_rate
        rates = [step_rate_hz(seg, sr) for seg in (ref, after)]
        if not all(math.isfinite(r) for r in rates):
            return None
        jump = self.p.max_rate_jump
        if abs(rates[1] / rates[0] - 1.0) > jump:
            # no drift moves the rate that far in a few tenths of a second: one estimate took a multiple of the rate
            # (or a fraction); the rate heard over both spans decides, each estimate held near it
            both = step_rate_hz(np.concatenate((ref, after)), sr)
            if not math.isfinite(both):
                return None
            lo, hi = (1.0 - jump) * both, (1.0 + jump) * both
            rates = [step_rate_hz(seg, sr, lo, hi) for seg in (ref, after)]
            if not all(math.isfinite(r) for r in rates):
                return None
        return rates[0], rates[1]

    def _spans(self, fire_end: int, samples: Samples) -> _Spans | None:
        """The stepping before the fire and the span after it, at their rates: the continuum's change."""
        tu, p = self.tuned, self.p
        sr = tu.sample_rate
        gap, span = int(p.gap_s * sr), int(p.ref_s * sr)
        # a fire soon after the stream began has less stepping before it: what there is, if at least half the span
        start = max(fire_end - gap - span, 0)
        ref = samples(start, fire_end - gap) if fire_end - gap - start >= span // 2 else None
        after = samples(fire_end, fire_end + int(p.after_s * sr))
        if ref is None or after is None:
            return None
        frame = self.spectra.continuum_frame * tu.frame
        if min(ref.size, after.size) < frame + tu.frame:
            return None
        rates = self._rates(ref, after)
        if rates is None:
            return None
        levels = tuple(
            np.percentile(
                continuum_levels_db(seg, sr, frame, tu.frame, tu.edges_hz, r, self.spectra), 100 * self.quantile, axis=0
            )
            for seg, r in zip((ref, after), rates, strict=True)
        )
        spread = np.asarray(tu.continuum_spread_db, dtype=np.float64)
        y = levels[1] - levels[0]
        sig = np.asarray(tu.continuum_signature_db, dtype=np.float64)
        ok = np.isfinite(y) & np.isfinite(spread) & np.isfinite(sig)
        if ok.sum() < 3:
            return None
        w = 1.0 / spread[ok] ** 2
        gain = float(np.sum(w * y[ok]) / np.sum(w))
        shape = float(np.sqrt(np.mean(((y[ok] - gain) / spread[ok]) ** 2)))
        moved = abs(rates[1] / rates[0] - 1.0)
        return _Spans((levels[0], levels[1]), rates, moved, gain, shape, ok, w, spread)

    def _reference_was_stop(self, s: _Spans) -> bool:
        """A fire late into a stop compares the stop with itself: did the stepping before already sound like it?"""
        tu = self.tuned
        if tu.continuum_levels_db is None:
            return False
        ref_level = np.asarray(tu.continuum_levels_db, dtype=np.float64)
        sig = np.asarray(tu.continuum_signature_db, dtype=np.float64)
        ok2 = s.ok & np.isfinite(ref_level)
        fit = (
            gain_and_signature(s.levels[0][ok2] - ref_level[ok2], sig[ok2], s.spread[ok2], self.start)
            if ok2.sum() >= 3
            else None
        )
        return not (fit is None or fit[0] < self.p.ref_max_b)

    def _relearned(self, end: int, at: int, samples: Samples, s: _Spans) -> FloatArray | None:
        """The template learned anew from the end of the span, if its continuum is still the stepping's.

        A stop that began inside the span changed it there: then the frames before the fire,
        stale as they are (the next fire, at once, is flagged: when the stop began inside the
        span is not known).
        """
        tu, p = self.tuned, self.p
        sr = tu.sample_rate
        frame = self.spectra.continuum_frame * tu.frame
        n_late = max(1, int(p.relearn_s * sr / tu.hop))
        late = samples(end + tu.frame - int(p.relearn_s * sr), end + 1)
        lo = at - n_late
        if late is not None and late.size >= frame + tu.frame:
            r1 = s.rates[1]
            rate = step_rate_hz(late, sr, (1.0 - p.max_rate_jump) * r1, (1.0 + p.max_rate_jump) * r1)
            if math.isfinite(rate):
                C = continuum_levels_db(late, sr, frame, tu.frame, tu.edges_hz, rate, self.spectra)
                z = (np.percentile(C, 100 * self.quantile, axis=0) - s.levels[0])[s.ok]
                g2 = float(np.sum(s.w * z) / np.sum(s.w))
                shape = float(np.sqrt(np.mean(((z - g2) / s.spread[s.ok]) ** 2)))
                if not (abs(g2) < p.max_gain_db and shape < p.max_shape):
                    lo = at - self.after_frames - self.chunk  # the stop began inside the span: the frames before
        hi = lo + (n_late if lo >= at - n_late else self.chunk)
        since = [lv[max(lo - f0, 0) : max(hi - f0, 0)] for f0, lv in self._recent_v]
        since = [lv for lv in since if lv.shape[0]]
        if not since:
            return None
        return np.asarray(np.percentile(np.concatenate(since), 100 * self.quantile, axis=0), dtype=np.float64)
