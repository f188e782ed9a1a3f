"""The signatures each frame is fitted to: the tuned one, the one predicted at the heard step rate, masked.

At another step rate than the tuning's the lines of the click train sample the arm's modes
elsewhere, and the tuned signature is no longer what the stop does to the sub-band levels.
A tuning that holds its fine continuum spectra (:mod:`stickslip.audio.features.fine`)
predicts the signature at the rate heard whenever the template is learned; within
``window`` of the tuning's rate (and more than ``min_change`` from it) each frame is fitted
on both, and the larger stop-likeness counts, with its residual, where the prediction
explains the frame (its residual within ``residual_max``). Where sound was added to the
template (:mod:`.template`), both signatures are fitted as the stop can show over it
(:func:`~.fit.masked_signature`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..features.fine import SignaturePredictor, signature_predictor
from ..paramfield import param
from .fit import FIT, FitParams, Fitter, masked_signature
from .tuned import TunedTemplate

__all__ = ["RATE", "RateFits", "RateParams"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RateParams:
    """When the signature predicted at the heard step rate is fitted beside the tuned one."""

    window: float = param(
        0.12, "of the tuning's rate", "predicted only this near the tuning's rate (farther: a multiple was heard)"
    )
    min_change: float = param(
        0.01, "of the tuning's rate", "and only this far from it (nearer: the rate estimate's noise, p95 0.67 %)"
    )
    min_signature_rms: float = param(
        1.0, "spreads", "a predicted signature weaker than this (RMS over sub-bands) is not fitted: its a is noise"
    )
    commanded_window: float = param(
        0.25,
        "of the tuning's rate",
        "with the commanded rate told, predicted this far: the rate heard near it is no multiple",
    )
    commanded_tol: float = param(
        0.03, "of the commanded rate", "the rate is looked for this near the commanded one (a controller's clock)"
    )


RATE = RateParams()


class RateFits:
    """The fits in use for a stream: on the tuned signature and the rate-predicted one, masked where sound was added."""

    def __init__(self, tuned: TunedTemplate, p: RateParams = RATE, fit: FitParams = FIT) -> None:
        self.tuned, self.p, self.fit_p = tuned, p, fit
        self.delta = np.asarray(tuned.signature_db, dtype=np.float64)
        self.sigma = np.asarray(tuned.spread_db, dtype=np.float64)
        #: the fit on the tuned signature
        self.tuned_fit = Fitter(self.delta, self.sigma, tuned.trim, fit)
        #: the tuning holds the fine spectra: the signature is predicted at the step rate heard
        self.predicts = tuned.has_fine
        self._predictor: SignaturePredictor | None = None  # built at the first rate that needs it
        self.reset()

    def reset(self) -> None:
        """The tuned signature alone, nothing masked; the log forgotten."""
        #: the signature predicted at the heard rate, dB (None: the tuned signature alone)
        self.pred_delta: FloatArray | None = None
        #: whether that rate was heard near the commanded one (the controller's clock, not a guess)
        self.pred_told = False
        self._fit_rate: Fitter | None = None
        self._added: FloatArray | None = None
        self._now: Fitter = self.tuned_fit
        self._rate_now: Fitter | None = None
        #: per hearing of the step rate: (the stream sample it was heard up to, the rate heard, Hz (NaN: none),
        #: whether the predicted signature is fitted from there on)
        self.rate_log: list[tuple[int, float, bool]] = []

    def predictor(self) -> SignaturePredictor:
        """The tuning's signature predictor (built at the first rate that needs it); needs :attr:`predicts`."""
        if self._predictor is None:
            self._predictor = signature_predictor(self.tuned)
            assert self._predictor is not None  # :attr:`predicts` says the tuning holds what it needs
        return self._predictor

    def mask(self, added_db: FloatArray | None) -> None:
        """The fits for the latest template: the signatures masked by the sound added to it (None: nothing)."""
        self._added = added_db
        if added_db is None:
            self._now, self._rate_now = self.tuned_fit, self._fit_rate
            return
        trim = self.tuned.trim
        self._now = Fitter(masked_signature(self.delta, added_db), self.sigma, trim, self.fit_p)
        self._rate_now = None
        if self.pred_delta is not None:
            self._rate_now = Fitter(masked_signature(self.pred_delta, added_db), self.sigma, trim, self.fit_p)

    def hear(self, rate: float, end: int, commanded: bool = False) -> None:
        """The template was learned (at stream sample ``end``) from stepping heard at ``rate``, Hz (NaN: none).

        Within ``window`` of the tuning's rate (``commanded_window`` where the rate was heard
        near the commanded one, ``commanded``) and more than ``min_change`` from it, each
        frame is fitted on the tuned signature and on the one predicted at ``rate``;
        otherwise (no rate heard, the tuning's rate, a rate far off: a multiple heard) on
        the tuned one alone.
        """
        self._fit_rate = None
        self.pred_delta = None
        self.pred_told = False
        used = False
        r0 = self.tuned.step_rate_hz
        window = self.p.commanded_window if commanded else self.p.window
        if r0 is not None and math.isfinite(rate) and self.p.min_change < abs(rate / r0 - 1.0) <= window:
            pred = self.predictor().predict(rate)
            if float(np.sqrt(np.mean((pred / self.sigma) ** 2))) >= self.p.min_signature_rms:
                self._fit_rate = Fitter(pred, self.sigma, self.tuned.trim, self.fit_p)
                self.pred_delta = pred
                self.pred_told = commanded
                used = True
        self.mask(self._added)
        self.rate_log.append((int(end), float(rate), used))

    def fit(
        self, d: FloatArray, pred_drops_rho: float | None
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_] | None]:
        """``a`` and ``rho`` of the departures ``d`` (frames x bands, dB), and where the predicted fit hears the stop
        and explains the frame within ``pred_drops_rho`` of ``residual_max`` (None: no predicted fit, or no rule)."""
        tu = self.tuned
        a, rho = self._now(d)
        pred_drops: NDArray[np.bool_] | None = None
        if self._rate_now is not None:
            # the larger stop-likeness, with its residual, where the prediction explains the frame; a frame it does
            # not explain is no evidence of the stop, and would hold up the stop-likeness a confirmation watches
            # after a fire the tuned fit made (a fifth-generator arm was confirmed 41 ms early that way)
            a2, rho2 = self._rate_now(d)
            use = (a2 > a) & (rho2 <= tu.residual_max)
            a, rho = np.where(use, a2, a), np.where(use, rho2, rho)
            if pred_drops_rho is not None:
                pred_drops = (a2 >= tu.threshold) & (rho2 <= pred_drops_rho * tu.residual_max)
        return a, rho, pred_drops
