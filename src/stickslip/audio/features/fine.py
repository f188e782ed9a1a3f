"""The stop's line-level signature predicted at another step rate, from the tuning's fine continuum.

A stepping joint's sound is a click train: its power lies on lines at the step rate ``r``
and its multiples, and the detector's sub-band levels (:mod:`.spectra`) are sums of those
lines as the arm's modes shape them. At another rate the lines sample the modes
elsewhere, so the stop's signature ``delta_b`` (dB per sub-band), learned at the tuning's
rate ``r0``, is no longer what the stop does to the levels.

The steps' irregularity (timing jitter, amplitude scatter) puts a *continuum* between the
lines, shaped by the same transfer function ``|H(f)|**2`` as the lines. The training
recording's fine continuum spectrum (Welch, ``segment_s`` segments, ~5.9 Hz bins,
the bins within ``guard_bins`` of the tuning's lines interpolated across; :class:`FineParams`), of
stepping and of the stop, is therefore ``|H|**2`` of each up to a factor. The line level
of sub-band ``b`` at rate ``r`` is

``L_b(r) = sum_k R_b(k r) C(k r)``

with ``R_b(f)`` the sub-band's level of a unit line at ``f`` through the detector's Hann
frame (leakage included) and ``C`` the fine continuum (power per bin). The signature at
the heard rate ``r`` is the tuned one plus the change the lines' move predicts:

``delta_b(r) = delta_b + [10 log10(L_b^stop(r) / L_b^step(r)) - 10 log10(L_b^stop(r0) / L_b^step(r0))]``

(no change in a sub-band no line reaches, at ``r`` or at ``r0``). At ``r = r0`` the
bracket is exactly 0. Units: Hz for frequencies and rates, dB for levels and signatures.
See docs/audio.md, "Another step rate than the tuning's".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sfft

from ..paramfield import param

__all__ = [
    "FINE",
    "FineParams",
    "FineSignature",
    "SignaturePredictor",
    "fine_range_hz",
    "fine_segment",
    "fine_spectrum_db",
    "signature_predictor",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FineParams:
    """The fine continuum spectrum a tuning keeps, and the line model that predicts a signature from it."""

    segment_s: float = param(
        8192 / 48_000, "s", "Welch segment: 5.86 Hz bins at 48 kHz, finer than the arms' narrow modes"
    )
    guard_bins: float = param(
        4.0, "bins", "bins this near a multiple of the tuning's rate hold its lines: interpolated across"
    )
    margin_bins: int = param(
        4, "detector bins", "the spectrum reaches this far beyond the sub-bands (a Hann frame's line leaks 2 bins)"
    )
    reach: float = param(
        0.05, "of a unit line's level", "a sub-band the lines reach less than this is not predicted (1.5 inside)"
    )
    power_floor: float = param(1e-30, "full scale^2 per Hz", "added to every power before its log")


FINE = FineParams()


def fine_segment(sample_rate: int, p: FineParams = FINE) -> int:
    """The Welch segment of the fine spectrum, samples: the power of two nearest ``segment_s``."""
    return int(2 ** round(math.log2(p.segment_s * sample_rate)))


def fine_spectrum_db(
    x: NDArray[np.floating] | FloatArray,
    sample_rate: int,
    rate_hz: float,
    lo_hz: float,
    hi_hz: float,
    p: FineParams = FINE,
) -> tuple[float, float, FloatArray] | None:
    """The fine continuum spectrum of ``x`` over ``lo_hz``..``hi_hz``: (first bin, Hz; bin width, Hz; levels, dB).

    Welch's average of 4-term Blackman-Harris periodograms (:func:`fine_segment` samples,
    half overlapping), as a power spectral density (full scale 1: dB re 1/Hz); the bins
    within ``guard_bins`` of a multiple of ``rate_hz`` are the step clock's lines
    and are replaced by the straight line (in power) between their neighbours. None when
    ``x`` is shorter than one segment or no rate is given.
    """
    from scipy.signal import welch

    n = fine_segment(sample_rate, p)
    v = np.asarray(x, dtype=np.float64)
    if v.size < n or not (math.isfinite(rate_hz) and rate_hz > 0):
        return None
    f, psd = welch(v, sample_rate, window="blackmanharris", nperseg=n, noverlap=n // 2)
    bin_hz = float(sample_rate) / n
    line = np.abs(f - np.round(f / rate_hz) * rate_hz) <= p.guard_bins * bin_hz
    psd = np.asarray(psd, dtype=np.float64).copy()
    if (~line).sum() >= 2:
        psd[line] = np.interp(f[line], f[~line], psd[~line])
    i0 = max(int(math.floor(lo_hz / bin_hz)), 0)
    i1 = min(int(math.ceil(hi_hz / bin_hz)) + 1, f.size)
    if i1 - i0 < 2:
        return None
    return float(f[i0]), bin_hz, np.asarray(10 * np.log10(psd[i0:i1] + p.power_floor), dtype=np.float64)


def fine_range_hz(
    edges_hz: tuple[float, ...] | list[float], sample_rate: int, frame: int, p: FineParams = FINE
) -> tuple[float, float]:
    """The span the fine spectrum must cover for sub-bands ``edges_hz`` heard in ``frame``-sample frames, Hz."""
    m = p.margin_bins * sample_rate / frame
    return max(float(edges_hz[0]) - m, 0.0), min(float(edges_hz[-1]) + m, sample_rate / 2)


class SignaturePredictor:
    """The signature at a heard step rate (see the module docstring).

    Parameters
    ----------
    sample_rate, frame : int
        The detector's sample rate (Hz) and frame (samples, periodic Hann).
    edges_hz : sequence of float
        Its sub-band edges, Hz.
    signature_db : sequence of float
        The tuned signature ``delta_b``, dB.
    rate0_hz : float
        The step rate the tuning heard, Hz.
    fine_start_hz, fine_bin_hz : float
        Frequency of the fine spectra's first bin and their bin width, Hz.
    fine_stepping_db, fine_stopped_db : sequence of float
        The training recording's fine continuum spectra of stepping and of the stop, dB.
    """

    def __init__(
        self,
        sample_rate: int,
        frame: int,
        edges_hz: tuple[float, ...] | list[float],
        signature_db: tuple[float, ...] | list[float] | FloatArray,
        rate0_hz: float,
        fine_start_hz: float,
        fine_bin_hz: float,
        fine_stepping_db: tuple[float, ...] | list[float] | FloatArray,
        fine_stopped_db: tuple[float, ...] | list[float] | FloatArray,
        p: FineParams = FINE,
    ) -> None:
        self.p = p
        self.delta = np.asarray(signature_db, dtype=np.float64)
        self.rate0 = float(rate0_hz)
        cs = np.asarray(fine_stepping_db, dtype=np.float64)
        cp = np.asarray(fine_stopped_db, dtype=np.float64)
        self.f = np.asarray(float(fine_start_hz) + float(fine_bin_hz) * np.arange(cs.size), dtype=np.float64)
        self.c_step = 10 ** (cs / 10)
        self.c_stop = 10 ** (cp / 10)
        self.sample_rate, self.frame = int(sample_rate), int(frame)
        self.edges = tuple(float(e) for e in edges_hz)
        self._l0 = self._levels(self.rate0)

    def _levels(self, rate: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per sub-band: the stepping's and the stop's line levels at ``rate``, and the lines' summed response."""
        f = self.f
        k0 = max(1, int(math.ceil(f[0] / rate)))
        k1 = int(math.floor(f[-1] / rate))
        if k1 < k0:
            z = np.zeros(len(self.edges) - 1)
            return z, z.copy(), z.copy()
        lines = np.asarray(np.arange(k0, k1 + 1) * rate, dtype=np.float64)
        # a few tens of lines: their response computed, not looked up in a table
        R = _line_response(self.sample_rate, self.frame, self.edges, lines)
        return R @ np.interp(lines, f, self.c_step), R @ np.interp(lines, f, self.c_stop), R.sum(axis=1)

    def correction_db(self, rate_hz: float) -> FloatArray:
        """What the lines' move from the tuning's rate to ``rate_hz`` does to the stop's signature, dB per sub-band."""
        s0, p0, c0 = self._l0
        s1, p1, c1 = self._levels(float(rate_hz))
        tiny, reach = self.p.power_floor, self.p.reach
        corr = 10 * np.log10((p1 + tiny) / (s1 + tiny)) - 10 * np.log10((p0 + tiny) / (s0 + tiny))
        return np.asarray(np.where((c0 > reach) & (c1 > reach), corr, 0.0), dtype=np.float64)

    def predict(self, rate_hz: float) -> FloatArray:
        """The stop's signature at step rate ``rate_hz``, dB per sub-band (the tuned one at the tuning's rate)."""
        if float(rate_hz) == self.rate0:
            return self.delta.copy()
        return np.asarray(self.delta + self.correction_db(rate_hz), dtype=np.float64)


class FineSignature(Protocol):
    """What a predictor is built from: a tuning's sub-bands and signature, its step rate and fine spectra
    (a :class:`~stickslip.audio.tuningfile.Tuning`, or the template detector's view of one)."""

    @property
    def sample_rate(self) -> int: ...
    @property
    def frame(self) -> int: ...
    @property
    def edges_hz(self) -> Sequence[float] | None: ...
    @property
    def signature_db(self) -> Sequence[float] | None: ...
    @property
    def step_rate_hz(self) -> float | None: ...
    @property
    def fine_start_hz(self) -> float | None: ...
    @property
    def fine_bin_hz(self) -> float | None: ...
    @property
    def fine_stepping_db(self) -> Sequence[float] | None: ...
    @property
    def fine_stopped_db(self) -> Sequence[float] | None: ...


def signature_predictor(tu: FineSignature, p: FineParams = FINE) -> SignaturePredictor | None:
    """The predictor of ``tu``'s signature at other step rates; None where ``tu`` lacks its step rate, fine
    spectra, sub-bands or signature (tunings made before they were stored)."""
    edges, sig, rate0 = tu.edges_hz, tu.signature_db, tu.step_rate_hz
    start, width, stepping, stopped = tu.fine_start_hz, tu.fine_bin_hz, tu.fine_stepping_db, tu.fine_stopped_db
    if edges is None or sig is None or rate0 is None or start is None or width is None:
        return None
    if stepping is None or stopped is None:
        return None
    return SignaturePredictor(tu.sample_rate, tu.frame, list(edges), list(sig), rate0, start, width,
                              list(stepping), list(stopped), p)


def _line_response(
    sample_rate: int, frame: int, edges_hz: tuple[float, ...] | list[float], freqs: FloatArray
) -> FloatArray:
    """``R[b, j]``: sub-band ``b``'s level of a unit cosine at ``freqs[j]`` in a periodic Hann frame (leakage included).

    Normalised so that a line's peak bin is 1 (a line well inside a sub-band sums to 1.5);
    only ratios of levels are used.
    """
    n = int(frame)
    w = np.hanning(n + 1)[:-1]
    t = np.arange(n) / float(sample_rate)
    fb = np.fft.rfftfreq(n, 1.0 / sample_rate)
    idx = np.searchsorted(fb, np.asarray(edges_hz, dtype=np.float64), side="left")
    lo, hi = int(idx[0]), int(idx[-1])
    starts = (idx[:-1] - lo).astype(np.intp)
    nb = idx.size - 1
    out = np.zeros((nb, freqs.size))
    norm = (float(np.sum(w)) / 2) ** 2
    for j0 in range(0, freqs.size, 512):
        fr = freqs[j0 : j0 + 512]
        s = sfft.rfft(w * np.cos(2 * np.pi * fr[:, None] * t[None, :]), axis=1)[:, lo:hi]
        p = s.real**2 + s.imag**2
        if hi > lo:
            band = np.add.reduceat(p, starts, axis=1)
            empty = idx[1:] <= idx[:-1]
            band[:, empty] = 0.0
            out[:, j0 : j0 + 512] = band.T / norm
    return out
