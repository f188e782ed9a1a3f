"""Per-frame spectra: band levels, sub-band levels and the continuum between the step clock's lines.

A frame is ``frame`` samples under a periodic Hann window, every ``hop`` samples; frame
``i`` covers samples ``[i*hop, i*hop + frame)``. Its one-sided power spectrum is scaled so
that the bins sum to the mean square (white noise of variance s^2 sums to ``10 log10 s^2``
dB over all bands). Levels are dB re full scale (dBFS). Units: Hz, samples, dB.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sfft

from ..paramfield import param

__all__ = [
    "FramePowers",
    "SpectraParams",
    "SubbandLevels",
    "band_bins",
    "band_levels_db",
    "continuum_levels_db",
    "frame_power_spectra",
    "frame_powers32",
    "levels_from_frames",
    "subband_bins",
    "subband_edges",
    "subband_levels_db",
    "window",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SpectraParams:
    """How the per-frame features are measured."""

    power_floor: float = param(
        1e-20, "full scale^2", "added to every power before its log: silence is -200 dB, not -inf"
    )
    sample_limit: float = param(
        1e15, "full scale", "larger samples, NaN and infinities are clipped to it: their squares stay finite"
    )
    line_guard_bins: float = param(
        4.0,
        "bins",
        "the continuum is the bins farther than this from every line (a Blackman-Harris main lobe is +-4 bins)",
    )
    continuum_frame: int = param(
        4, "detector frames", "the continuum's frames are this many times the detector's: finer bins, steadier levels"
    )


SPECTRA = SpectraParams()


def window(frame: int) -> tuple[FloatArray, float]:
    """Periodic Hann window and the scale that makes one-sided bins sum to the mean square."""
    w = np.hanning(frame + 1)[:-1]
    return w, 2.0 / (frame * float(np.sum(w**2)))


def band_bins(band_hz: tuple[float, float], sample_rate: int, frame: int) -> tuple[int, int]:
    """The rfft bins ``[i0, i1)`` of ``band_hz`` (Hz) in ``frame``-sample frames (at least one bin)."""
    lo, hi = band_hz
    freqs = np.fft.rfftfreq(frame, 1 / sample_rate)
    i0 = int(np.searchsorted(freqs, lo, side="left"))
    i1 = int(np.searchsorted(freqs, hi, side="right"))
    return i0, max(i1, i0 + 1)


def frame_power_spectra(samples: NDArray[Any], frame: int, hop: int) -> FloatArray:
    """Per-frame one-sided power spectra (frames x bins), scaled so bins sum to mean square."""
    x = np.asarray(samples, dtype=np.float64)
    if x.size < frame:
        return np.zeros((0, frame // 2 + 1))
    frames = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    w, scale = window(frame)
    spec = sfft.rfft(frames * w, axis=1)
    p = (spec.real**2 + spec.imag**2) * scale
    p[:, 0] *= 0.5
    if frame % 2 == 0:
        p[:, -1] *= 0.5
    return np.asarray(p, dtype=np.float64)


def band_levels_db(
    samples: NDArray[Any],
    sample_rate: int,
    frame: int,
    hop: int,
    band_hz: tuple[float, float],
    reference_hz: tuple[float, float] | None = None,
    p: SpectraParams = SPECTRA,
) -> FloatArray:
    """Band level per frame, dBFS (see :func:`frame_power_spectra`); minus the reference band's if given."""
    ps = frame_power_spectra(samples, frame, hop)
    i0, i1 = band_bins(band_hz, sample_rate, frame)
    level = 10 * np.log10(ps[:, i0:i1].sum(axis=1) + p.power_floor)
    if reference_hz is not None:
        r0, r1 = band_bins(reference_hz, sample_rate, frame)
        level -= 10 * np.log10(ps[:, r0:r1].sum(axis=1) + p.power_floor)
    return np.asarray(level, dtype=np.float64)


def subband_edges(lo_hz: float, hi_hz: float, sample_rate: int, frame: int, per_octave: float = 3.0) -> list[float]:
    """Edges of log-spaced sub-bands from ``lo_hz`` to ``hi_hz``, each at least two bins wide, Hz."""
    bin_hz = sample_rate / frame
    edges = [float(lo_hz)]
    step = 2 ** (1 / per_octave)
    while edges[-1] < hi_hz:
        nxt = max(edges[-1] * step, edges[-1] + 2 * bin_hz)
        if hi_hz - nxt < 2 * bin_hz:
            nxt = hi_hz
        edges.append(float(min(nxt, hi_hz)))
    return [round(e, 1) for e in edges]


def subband_bins(edges: tuple[float, ...] | list[float], sample_rate: int, frame: int) -> NDArray[np.intp]:
    """The rfft bin of each sub-band edge (a bin belongs to the sub-band its frequency is at or above the edge of)."""
    freqs = np.fft.rfftfreq(frame, 1 / sample_rate)
    idx = np.searchsorted(freqs, np.asarray(edges, dtype=np.float64), side="left")
    return np.asarray(idx, dtype=np.intp)


class SubbandLevels:
    """Sub-band levels (frames x bands), dB, of frames: :func:`levels_from_frames` with its constants made once.

    A detector fed live blocks of a few frames calls it hundreds of times a second; the
    window in single precision, the bins' starts and the empty sub-bands are computed here
    once, not per block.
    """

    def __init__(self, w: FloatArray, scale: float, idx: NDArray[np.intp], p: SpectraParams = SPECTRA) -> None:
        self.w32 = np.asarray(w, dtype=np.float32)
        self.scale = scale
        self.lo, self.hi = int(idx[0]), int(idx[-1])
        self.starts = (idx[:-1] - self.lo).astype(np.intp)
        empty = idx[1:] <= idx[:-1]
        self.empty = empty if empty.any() else None
        self.nb = idx.size - 1
        self.power_floor = p.power_floor

    def __call__(self, frames: NDArray[Any]) -> FloatArray:
        n = frames.shape[0]
        out = np.empty((n, self.nb))
        for f0 in range(0, n, 1024):  # frame_powers32 and _bands inline: a live block of a few frames comes often
            seg = np.multiply(frames[f0 : f0 + 1024], self.w32, dtype=np.float32)  # each cast to float32, then x
            spec = sfft.rfft(seg, axis=1)[:, self.lo : self.hi]
            power = spec.real**2
            power += spec.imag**2
            band = np.add.reduceat(power, self.starts, axis=1, dtype=np.float64) * self.scale
            if self.empty is not None:
                band[:, self.empty] = 0.0
            band += self.power_floor
            np.log10(band, out=band)
            np.multiply(band, 10, out=out[f0 : f0 + 1024])
        return out

    def from_powers(self, powers: NDArray[np.float32]) -> FloatArray:
        """The levels from the frames' powers of the bins ``[lo, hi)`` (:func:`frame_powers32`): the same floats."""
        n = powers.shape[0]
        out = np.empty((n, self.nb))
        for f0 in range(0, n, 1024):
            self._bands(np.ascontiguousarray(powers[f0 : f0 + 1024]), out[f0 : f0 + 1024])
        return out

    def powers(self, x: FloatArray, hop: int, kept: FramePowers) -> NDArray[np.float32]:
        """The powers of the bins these levels read, of the frames of a whole stream ``x``, from ``kept``."""
        return kept(x, self.w32.size, hop, self.w32, self.lo, self.hi)

    def _bands(self, power: NDArray[np.float32], out: FloatArray) -> None:
        band = np.add.reduceat(power, self.starts, axis=1, dtype=np.float64) * self.scale
        if self.empty is not None:
            band[:, self.empty] = 0.0
        band += self.power_floor
        np.log10(band, out=band)
        np.multiply(band, 10, out=out)


def frame_powers32(
    frames: NDArray[Any], w32: NDArray[np.float32], lo: int = 0, hi: int | None = None
) -> NDArray[np.float32]:
    """Single-precision power of the bins ``[lo, hi)`` of windowed frames (frames x bins; unscaled)."""
    seg = np.multiply(frames, w32, dtype=np.float32)  # each cast to float32, then x
    spec = sfft.rfft(seg, axis=1)[:, lo:hi]
    power: NDArray[np.float32] = spec.real**2
    power += spec.imag**2
    return power


class FramePowers:
    """The single-precision powers of every frame of whole streams, kept by their samples (:meth:`__call__`).

    A tuning runs its candidates over the same few sounds (the recording, its gain changes,
    the interference injected), each a detector fed the whole sound at once, and measures
    parts of the recording that begin where it begins; their frames' spectra are computed
    once here. A sound is known again by equal samples (a few compared first, then all; a
    sound that begins a kept one has the kept one's first frames), never by a hash. At most
    ``max_bytes`` are kept, the latest used.
    """

    def __init__(self, max_bytes: int = 64 << 20) -> None:
        self.max_bytes = int(max_bytes)
        #: (frame, hop, first bin, end bin, samples, powers)
        self._kept: list[tuple[int, int, int, int, FloatArray, NDArray[np.float32]]] = []

    def __call__(
        self, x: FloatArray, frame: int, hop: int, w32: NDArray[np.float32], lo: int = 0, hi: int | None = None
    ) -> NDArray[np.float32]:
        """The powers of the bins ``[lo, hi)`` (:func:`frame_powers32`) of the frames of ``x`` (float64, 1-D)."""
        n = (x.size - frame) // hop + 1 if x.size >= frame else 0
        hi = frame // 2 + 1 if hi is None else hi
        done: NDArray[np.float32] | None = None  # the powers of a kept sound that begins x
        for i, (kf, kh, klo, khi, kx, kp) in enumerate(self._kept):
            if (kf, kh) != (frame, hop) or not klo <= lo <= hi <= khi:
                continue
            if kx.size >= x.size and _begins(kx, x):
                self._kept.append(self._kept.pop(i))
                return kp[:n, lo - klo : hi - klo]
            if kx.size < x.size and _begins(x, kx) and (done is None or kp.shape[0] > done.shape[0]):
                done = kp[:, lo - klo : hi - klo]
        p = np.empty((n, hi - lo), dtype=np.float32)
        n0 = 0 if done is None else done.shape[0]
        if done is not None:
            p[:n0] = done
        frames = np.lib.stride_tricks.sliding_window_view(x[n0 * hop :], frame)[::hop][: n - n0]
        for f0 in range(0, n - n0, 1024):
            p[n0 + f0 : n0 + f0 + 1024] = frame_powers32(frames[f0 : f0 + 1024], w32, lo, hi)
        self._keep((frame, hop, lo, hi), x, p)
        return p

    def _keep(self, key: tuple[int, int, int, int], x: FloatArray, p: NDArray[np.float32]) -> None:
        """Keep ``x``'s powers (and forget the kept ones that begin it over fewer bins: theirs are its first)."""
        size = x.nbytes + p.nbytes
        if size > self.max_bytes:
            return
        frame, hop, lo, hi = key

        def within(k: tuple[int, int, int, int, FloatArray, NDArray[np.float32]]) -> bool:
            return k[:2] == (frame, hop) and lo <= k[2] <= k[3] <= hi and k[4].size <= x.size and _begins(x, k[4])

        self._kept = [k for k in self._kept if not within(k)]
        while self._kept and sum(k[4].nbytes + k[5].nbytes for k in self._kept) + size > self.max_bytes:
            self._kept.pop(0)
        self._kept.append((frame, hop, lo, hi, x.copy(), p))


def _begins(long: FloatArray, short: FloatArray) -> bool:
    """Whether ``long`` begins with the samples ``short`` (a few compared first, then all)."""
    head = long[: short.size]
    step = max(1, short.size // 64)
    return bool(np.array_equal(head[::step], short[::step]) and np.array_equal(head, short))


def levels_from_frames(
    frames: NDArray[Any], w: FloatArray, scale: float, idx: NDArray[np.intp], p: SpectraParams = SPECTRA
) -> FloatArray:
    """Sub-band levels (frames x bands), dB, of windowed frames; ``idx`` are bin edges.

    Single precision FFTs in cache-sized chunks: the levels are good to far better than
    0.01 dB, and this is most of the detector's cost.
    """
    return SubbandLevels(w, scale, idx, p)(frames)


def subband_levels_db(
    samples: NDArray[Any],
    sample_rate: int,
    frame: int,
    hop: int,
    edges: tuple[float, ...] | list[float],
    powers: FramePowers | None = None,
) -> FloatArray:
    """Sub-band levels of every frame of a recording (frames x bands), dBFS; ``powers``: its spectra kept there."""
    x = np.asarray(samples, dtype=np.float64)
    idx = subband_bins(edges, sample_rate, frame)
    nb = len(edges) - 1
    if x.size < frame:
        return np.zeros((0, nb))
    w, scale = window(frame)
    if powers is not None:
        levels = SubbandLevels(w, scale, idx)
        return levels.from_powers(levels.powers(x, hop, powers))
    view = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    out = np.empty((view.shape[0], nb))
    for f0 in range(0, view.shape[0], 4096):
        out[f0 : f0 + 4096] = levels_from_frames(view[f0 : f0 + 4096], w, scale, idx)
    return out


def continuum_levels_db(
    samples: NDArray[Any],
    sample_rate: int,
    frame: int,
    hop: int,
    edges: tuple[float, ...] | list[float],
    rate_hz: float,
    p: SpectraParams = SPECTRA,
) -> FloatArray:
    """Sub-band levels of the *continuum* between the step clock's lines, per frame (frames x bands), dB.

    A click train at ``rate_hz`` puts its power on lines at the rate's multiples; which of a
    narrow mode's frequencies a line samples depends on the rate, so a sub-band's level
    moves by many dB when the rate changes (a line enters or leaves the sub-band). Between
    the lines lies the continuum the steps' irregularity makes (their timing jitter and
    amplitude), shaped by the same modes at every rate. Per frame (4-term Blackman-Harris
    window) and sub-band: the mean power of the bins farther than ``line_guard_bins`` bins
    from every multiple of ``rate_hz``, in dB (a power per bin: another rate changes it by
    the same factor in every sub-band, a gain). NaN where a sub-band has no such bin.
    """
    x = np.asarray(samples, dtype=np.float64)
    nb = len(edges) - 1
    if x.size < frame or not rate_hz > 0:
        return np.full((0, nb), np.nan)
    f = np.fft.rfftfreq(frame, 1 / sample_rate)
    bin_hz = sample_rate / frame
    off = np.abs(f - np.round(f / rate_hz) * rate_hz) > p.line_guard_bins * bin_hz
    idx = subband_bins(edges, sample_rate, frame)
    from scipy.signal import get_window

    w = np.asarray(get_window("blackmanharris", frame, fftbins=True), dtype=np.float64)
    scale = 2.0 / (frame * float(np.sum(w**2)))
    view = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    spec = sfft.rfft(view * w, axis=1)
    power = (spec.real**2 + spec.imag**2) * scale
    out = np.full((view.shape[0], nb), np.nan)
    for b in range(nb):
        sel = np.zeros(f.size, dtype=bool)
        sel[idx[b] : idx[b + 1]] = True
        sel &= off
        if sel.any():
            out[:, b] = 10 * np.log10(power[:, sel].mean(axis=1) + p.power_floor)
    return out
