"""A level meter of the band the stop detector listens to, for ``stickslip record``.

A broadband meter mostly shows the room (hum, fans, speech); what matters while you
record a joint into its stop is the level of the band where the *stepping* is heard,
the band :func:`~stickslip.audio.tuning.tune` will build its template over. The meter
learns that band from the first ``learn_s`` of the recording (the joint is stepping
then) with :func:`~stickslip.audio.tuning.stepping_band`, or takes it from a tuning,
and then shows the band's level in dBFS (the mean square the band contributes,
``10 log10``; a full-scale sine is -3 dBFS), labelled with the band in Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .features.spectra import SPECTRA, frame_power_spectra
from .sources.guard import block_problem
from .tuning import stepping_band
from .tuningfile import TUNING_FILE, default_frame

__all__ = ["BandMeter", "MeterReading"]

_FLOOR = SPECTRA.power_floor


@dataclass(frozen=True)
class MeterReading:
    """One reading: ``level_db`` (dBFS) of ``band_hz`` (low, high Hz), or broadband while the band is learned."""

    level_db: float
    band_hz: tuple[float, float] | None

    def line(self, width: int = 40) -> str:
        """The reading as one terminal line: level, unit, band and a bar from -90 to 0 dBFS."""
        n = int(max(0.0, min(float(width), (self.level_db + 90.0) / 90.0 * width)))
        where = (
            f"in {self.band_hz[0]:.0f}-{self.band_hz[1]:.0f} Hz"
            if self.band_hz is not None
            else "broadband (learning the stepping band)"
        )
        return f"{self.level_db:6.1f} dBFS {where} |{'#' * n}{' ' * (width - n)}|"


class BandMeter:
    """Level of the stepping band, block by block.

    Parameters
    ----------
    sample_rate : int
        Sample rate of the blocks, Hz.
    band_hz : (float, float), optional
        The band to show, Hz (e.g. a tuning's ``band_hz``). Default: learned from the
        first ``learn_s`` of input.
    learn_s : float
        Input to learn the stepping band from, s (the joint must be stepping then).
    """

    def __init__(self, sample_rate: int, band_hz: tuple[float, float] | None = None, learn_s: float = 0.5) -> None:
        if (problem := TUNING_FILE.rate_problem(int(sample_rate))) is not None:
            raise ValueError(problem.replace("sample rate", "sample_rate", 1))
        if not 0.05 <= learn_s <= 10:
            raise ValueError(f"learn_s {learn_s} s is outside 0.05-10 s")
        self.sample_rate = int(sample_rate)
        self.frame = default_frame(self.sample_rate)
        self.band_hz = None if band_hz is None else (float(band_hz[0]), float(band_hz[1]))
        self._learn_n = int(learn_s * self.sample_rate)
        self._seen: list[NDArray[np.float64]] = []
        self._seen_n = 0
        self._tail = np.zeros(0)

    def feed(self, block: ArrayLike) -> MeterReading:
        """The level of ``block`` (mono samples, full scale 1): in the band once known, else broadband."""
        x = np.nan_to_num(np.asarray(block, dtype=np.float64).reshape(-1))
        if self.band_hz is None and self._seen_n < self._learn_n:
            self._seen.append(x)
            self._seen_n += x.size
            if self._seen_n >= self._learn_n:
                self._learn()
        # blocks shorter than a frame are measured with the samples before them
        y = x if x.size >= self.frame else np.concatenate((self._tail, x))[-self.frame :]
        self._tail = y[-self.frame :].copy()
        if self.band_hz is None or y.size < self.frame:
            return MeterReading(10 * math.log10(float(np.mean(y**2)) + _FLOOR) if y.size else -200.0, None)
        p = frame_power_spectra(y, self.frame, self.frame // 2).mean(axis=0)
        f = np.fft.rfftfreq(self.frame, 1 / self.sample_rate)
        inside = (f >= self.band_hz[0]) & (f <= self.band_hz[1])
        return MeterReading(10 * math.log10(float(p[inside].sum()) + _FLOOR), self.band_hz)

    def _learn(self) -> None:
        x = np.concatenate(self._seen)
        self._seen = []
        if block_problem(x) is not None:  # nothing to learn from yet: keep showing broadband, try again
            self._seen_n = 0
            return
        self.band_hz = stepping_band(x, self.sample_rate, self.frame, self.frame // 4)
