"""Did listening begin at the stop? The template learned in the warm-up, compared with the tuning's stepping.

A recording that starts mid-traverse, already at the stop, teaches the detector the stop's
sound as its "stepping" template: it would never fire. At the end of the warm-up the
template is compared with the tuning's stepping, two ways:

* *levels*: the template minus the tuning's stepping levels is fitted as a gain offset
  (the same in every sub-band) plus ``b`` times the stop's signature
  (:func:`gain_and_signature`); ``b`` at or above the threshold (and ``levels_min_b``), the
  stop explaining most of what a gain change leaves (``levels_clear``), a small residual:
  the stop. Good only at the tuning's step rate: at another rate the lines of the click
  train fall elsewhere on narrow modes, and the levels move by several spreads.
* *continuum* (tunings that recorded their step rate): the same fit on the power between
  the step clock's lines (:func:`~stickslip.audio.features.spectra.continuum_levels_db`, at
  the rate heard in the warm-up), which the rate does not move: ``b`` at least ``min_b``
  and at most ``max_ratio`` of the gain-only residual left.

Where the tuning holds the continuum, the levels alone are not enough: the continuum must
give the stop at least ``levels_continuum_b`` of its signature too (a reverberant room, or
a rate a few per cent off, colours the stepping's levels as a damped or shifted stop does).
Nor is the continuum alone enough where the levels give the stop less than
``continuum_levels_b`` (slips that jitter less than the tuning's lower the continuum the
way a stop that silences them does). The stop: the detector fires at once, its onset the
start of listening, and takes ``T - b * delta`` as the stepping template. A signature that
is a gain change only (a uniformly quieter stop) cannot be told from a gain change this
way and is taken as stepping.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..features.spectra import SPECTRA, SpectraParams, continuum_levels_db
from ..paramfield import param
from .fit import FIT, FitParams
from .tuned import TunedTemplate

__all__ = ["START", "StartParams", "gain_and_signature", "start_shift"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class StartParams:
    """When listening is judged to have begun at the stop."""

    min_b: float = param(0.7, "signatures", "the continuum's fit must give the stop this much of its signature ...")
    max_ratio: float = param(
        0.4, "", "... and leave at most this share of what a gain change alone leaves, to show the stop by itself"
    )
    levels_continuum_b: float = param(
        0.5, "signatures", "the levels' verdict counts only where the continuum gives the stop this much too"
    )
    continuum_levels_b: float = param(
        0.25, "signatures", "the continuum's verdict counts alone only where the levels give the stop this much"
    )
    levels_min_b: float = param(0.6, "signatures", "the levels show the stop clearly with b at least this ...")
    levels_clear: float = param(0.25, "", "... leaving at most this share of the gain-only sum of squares ...")
    levels_rms: float = param(2.0, "spreads", "... and a residual RMS under this (plus what a stop of size b may have)")
    silent_db: float = param(-150.0, "dBFS", "a template this low somewhere is digital silence: not judged")
    gain_only: float = param(
        1.0, "spreads", "a signature whose shape (less its mean) has an RMS under this is a gain: undecidable"
    )


START = StartParams()


def gain_and_signature(
    y: FloatArray, delta: FloatArray, sigma: FloatArray, p: StartParams = START
) -> tuple[float, float, float, float] | None:
    """Fit ``y = c + b * delta`` weighted by ``1/sigma**2``: ``b``, the residual's RMS (spreads) and the sums of
    squares left by the fit and by a gain alone; None where the signature is (nearly) a gain change."""
    w = 1.0 / sigma**2
    X = np.stack((np.ones_like(delta), delta), axis=1)
    A = X.T @ (X * w[:, None])
    if np.linalg.cond(A) > 1e6:
        return None
    shape = delta - float(np.sum(w * delta) / np.sum(w))
    if float(np.sqrt(np.mean((shape / sigma) ** 2))) < p.gain_only:
        return None  # the stop is (nearly) a gain change: undecidable from levels alone
    c, b = np.linalg.solve(A, X.T @ (w * y))
    r_gain = (y - float(np.sum(w * y) / np.sum(w))) / sigma
    r_both = (y - X @ np.array([c, b])) / sigma
    ss_both = float(np.sum(r_both**2))
    return float(b), float(np.sqrt(np.mean(r_both**2))), ss_both, float(np.sum(r_gain**2))


class _Start:
    """One judgement: the template learned, the tuning, the warm-up's samples."""

    def __init__(
        self,
        template: FloatArray,
        tuned: TunedTemplate,
        head: FloatArray | None,
        head_rate: Callable[[], float],
        quantile: float,
        p: StartParams,
        fit: FitParams,
        spectra: SpectraParams,
    ) -> None:
        self.template, self.tuned, self.head, self.head_rate = template, tuned, head, head_rate
        self.quantile, self.p, self.fit, self.spectra = quantile, p, fit, spectra
        self.delta = np.asarray(tuned.signature_db, dtype=np.float64)
        self.sigma = np.asarray(tuned.spread_db, dtype=np.float64)

    def levels_fit(self) -> tuple[float, float, float, float] | None:
        """The template less the tuning's stepping, fitted as a gain plus ``b`` times the signature."""
        if self.tuned.stepping_levels_db is None:
            return None
        y = self.template - np.asarray(self.tuned.stepping_levels_db)
        return gain_and_signature(y, self.delta, self.sigma, self.p)

    def by_levels(self) -> float | None:
        """``b`` when the levels show the stop clearly from the start, else None."""
        fit = self.levels_fit()
        if fit is None:
            return None
        b, rms_both, ss_both, ss_gain = fit
        # demand a clear case: the stop explains most of what a gain change leaves, and fits well
        clear = ss_both <= self.p.levels_clear * ss_gain
        slope = self.fit.residual_slope
        fits = rms_both <= self.p.levels_rms + slope * b * float(np.sqrt(np.mean((self.delta / self.sigma) ** 2)))
        return b if b >= max(self.tuned.threshold, self.p.levels_min_b) and clear and fits else None

    def levels_deny_stop(self) -> bool:
        """Do the levels give the stop less than ``continuum_levels_b`` of its signature (False: they cannot tell)?"""
        fit = self.levels_fit()
        return fit is not None and fit[0] < self.p.continuum_levels_b

    def by_continuum(self) -> bool | None:
        """The continuum's verdict: True (the stop by itself), False (not by itself, but the levels' verdict may
        stand), None (the levels' verdict may not stand either)."""
        tu = self.tuned
        if (
            tu.step_rate_hz is None
            or tu.continuum_levels_db is None
            or tu.continuum_signature_db is None
            or tu.continuum_spread_db is None
        ):
            return False  # an older tuning: the levels judge alone
        if self.head is None:
            return None
        rate = self.head_rate()
        if not math.isfinite(rate):
            return None
        frame = self.spectra.continuum_frame * tu.frame
        C = continuum_levels_db(self.head, tu.sample_rate, frame, tu.frame, tu.edges_hz, rate, self.spectra)
        ok = np.isfinite(C).all(axis=0) if C.shape[0] else np.zeros(C.shape[1], dtype=bool)
        ref = np.asarray(tu.continuum_levels_db, dtype=np.float64)
        sig = np.asarray(tu.continuum_signature_db, dtype=np.float64)
        spread = np.asarray(tu.continuum_spread_db, dtype=np.float64)
        ok &= np.isfinite(ref) & np.isfinite(sig) & np.isfinite(spread)
        if ok.sum() < 3:
            return None
        T = np.percentile(C[:, ok], 100 * self.quantile, axis=0)
        fit = gain_and_signature(T - ref[ok], sig[ok], spread[ok], self.p)
        if fit is None:
            return None
        b, _, ss_both, ss_gain = fit
        if b >= max(tu.threshold, self.p.min_b) and ss_both <= self.p.max_ratio * ss_gain:
            return True
        return False if b >= self.p.levels_continuum_b else None


def start_shift(
    template: FloatArray | None,
    tuned: TunedTemplate,
    head: FloatArray | None,
    head_rate: Callable[[], float],
    quantile: float,
    p: StartParams = START,
    fit: FitParams = FIT,
    spectra: SpectraParams = SPECTRA,
) -> float | None:
    """How many signatures the template learned in the warm-up is the stop, or None: listening began at stepping.

    ``head`` are the warm-up's samples and ``head_rate`` gives the step rate heard in them
    (Hz, NaN: none); ``quantile`` is the template's. See the module docstring.
    """
    if template is None or float(np.min(template)) <= p.silent_db:
        return None
    judge = _Start(template, tuned, head, head_rate, quantile, p, fit, spectra)
    b_lev = judge.by_levels()
    b_con = judge.by_continuum()
    if b_con is None:
        return None  # the continuum contradicts the levels, or neither shows the stop
    if b_lev is None and not b_con:
        return None
    if b_lev is None and judge.levels_deny_stop():
        return None  # the lines say stepping: the continuum moved with the slips' jitter, not a stop
    return 1.0 if b_lev is None else b_lev
