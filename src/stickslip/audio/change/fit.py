"""Each frame fitted to the stop's signature: the stop-likeness ``a`` and the residual ``rho``.

A frame's departure from the stepping template, ``d_b = v_b - T_b`` (dB per sub-band), is
fitted as ``d = a * delta + e`` by weighted least squares (weights ``1 / sigma_b**2``,
``delta`` the stop's signature and ``sigma`` the stepping's spread, both from the tuning),
trimmed: the ``trim`` sub-bands with the most unexplained excess are dropped and the fit
repeated, so a voice or a fan that covers a few sub-bands does not move ``a``. ``a`` is 0
while stepping and 1 at a stop like the tuning's; ``rho`` is how unlike both the frame is
(a knock, a door slam), in spreads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..paramfield import param

__all__ = ["FIT", "FitParams", "Fitter", "fit_departure", "masked_signature"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FitParams:
    """How a frame is fitted to the stop's signature."""

    residual_slope: float = param(
        0.35,
        "per unit of a",
        "residual a stop of size a may have, per spread of the signature's RMS (another rate moves its lines)",
    )
    clip_db: float = param(40.0, "dB", "departures are clipped to +-this: a knock's 60 dB does not dominate the fit")


FIT = FitParams()


class Fitter:
    """:func:`fit_departure` for one signature, its constants computed once."""

    def __init__(self, delta: FloatArray, sigma: FloatArray, trim: int, p: FitParams = FIT) -> None:
        self.inv_sigma = 1.0 / np.asarray(sigma, dtype=np.float64)
        self.g = np.asarray(delta, dtype=np.float64) * self.inv_sigma
        self.g2 = self.g**2
        self.gg = float(self.g2.sum())
        self.slope = p.residual_slope * float(np.sqrt(np.mean(self.g2)))
        self.trim = int(trim)
        self.clip_db = p.clip_db

    def __call__(self, d: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``a`` and ``rho`` of the departures ``d`` (frames x bands, dB)."""
        g = self.g
        z = np.minimum(np.maximum(d, -self.clip_db), self.clip_db)  # np.clip's values, without its wrappers' cost
        z *= self.inv_sigma
        # row by row (einsum), not a matrix product: BLAS rounds a row differently by the number of rows with it,
        # and a frame's a would depend on the block it came in
        a = np.einsum("ij,j->i", z, g) / self.gg
        if self.trim > 0:
            r = z - a[:, None] * g
            if self.trim == 1:
                kth = r.max(axis=1, keepdims=True)
            else:
                neg = -r
                neg.partition(self.trim - 1, axis=1)  # in place: np.partition's copy and wrappers spared
                kth = -neg[:, self.trim - 1 : self.trim]
            keep = r < kth  # ties (rare) drop one band more
            keep |= ~keep.any(axis=1, keepdims=True)  # all tied (a constant input): keep every band
            zk = z * keep
            a = np.einsum("ij,j->i", zk, g) / np.maximum(np.einsum("ij,j->i", keep, self.g2), 1e-12)
            res = zk - (a[:, None] * g) * keep
            rho = np.sqrt(np.einsum("ij,ij->i", res, res) / keep.sum(axis=1))
        else:
            res = z - a[:, None] * g
            rho = np.sqrt(np.einsum("ij,ij->i", res, res) / z.shape[1])
        rho = rho - self.slope * np.maximum(a, 0.0)
        return a, rho


def fit_departure(
    d: FloatArray, delta: FloatArray, sigma: FloatArray, trim: int, p: FitParams = FIT
) -> tuple[FloatArray, FloatArray]:
    """Stop-likeness ``a`` and residual ``rho`` of departures ``d`` (frames x bands, dB).

    Weighted least squares ``d = a * delta + e`` (weights ``1/sigma**2``), then the same
    with the ``trim`` bands of each frame that have the most unexplained *excess* dropped
    (interference adds sound; a band whose expected rise is missing is evidence against a
    stop and is never dropped). ``rho`` is the RMS of the kept residuals in units of
    ``sigma``, less ``residual_slope`` times the signature's RMS (in units of ``sigma``)
    times ``a``: the residual a stop of that size may have (another step rate moves the
    lines of its sound).
    """
    return Fitter(delta, sigma, trim, p)(d)


def masked_signature(delta: FloatArray, added_db: FloatArray) -> FloatArray:
    """The stop's signature as it can show over a template that holds sound added to the stepping, dB per sub-band.

    The stop changes the stepping's own sound only. In a sub-band where something else (a
    second instrument, a fan, a radio) lifted the template ``added_db`` dB above the
    stepping's level, the stepping is the share ``w = 10**(-added_db / 10)`` of the
    template's power, and a stop that multiplies the stepping's power by
    ``g = 10**(delta / 10)`` moves the template's level by

        delta_shown = 10 * log10(1 + w * (g - 1))          dB

    ``delta`` where nothing was added, towards 0 as the added sound dominates: a rise of
    15 dB under an instrument 8 dB over the stepping shows as 7.7 dB, a drop of 5 dB under
    sound 6 dB over it as -0.8 dB. Fitting the tuned ``delta`` there asks the frame for a
    change the stepping cannot make, and a stop is heard late or not at all (the battery's
    joint P under a second instrument ringing where the stop's largest drop is: heard 0.56 s
    after the stop, by the late path alone, without it).

    Parameters
    ----------
    delta : array (B,)
        The tuned (or rate-predicted) signature, dB per sub-band.
    added_db : array (B,)
        The sound added per sub-band, dB above the stepping's level (0 where none), >= 0.
    """
    w = 10.0 ** (-np.asarray(added_db, dtype=np.float64) / 10.0)
    g = 10.0 ** (np.asarray(delta, dtype=np.float64) / 10.0)
    return np.asarray(10.0 * np.log10(1.0 + w * (g - 1.0)), dtype=np.float64)
