"""Did the joint stop stepping? A pause is not an end stop.

At an end stop the controller goes on stepping: the slider slips against the stop and the
joint still sounds, louder, quieter, duller or only otherwise than before, but never silent.
When the *stepping* stops - a pause between the operator's moves in a recording, a
controller that halted or faulted mid-burst, a cable pulled - the sound falls to the room's,
and the level detector, which compares the sound with the stepping's, calls that a stop:
every sub-band drops, far more than any stop's signature. Taken as the stop, the count would
run to the moment the stepping ceased: silently wrong.

:func:`stepping_stopped` tells the two apart on what follows a fire (the confirmation
window) against the stepping before it:

* the sound in the detector's band fell by ``drop_db`` or more, and by ``margin_db`` more
  than the tuned stop changes it (a tuning whose stop is itself much quieter is given that
  much room), **and**
* no stepping is heard in it: the envelope's lines at the step rate heard before the fire
  and its first multiples stand less than ``lines_db`` above their neighbourhoods,
  averaged (:func:`step_lines_db`; a stop whose slips are muted while the piezo's drive
  still sings keeps its lines).

Both, because each alone also fits some stops: the random arms' duller stops lose up to
19 dB of their first-differenced power (the battery's, fourth to seventh generators' stops
lose 10 dB or less of their in-band power), and a stop that rattles a little off the step
clock (the project's simulator) leaves an envelope line of 3-8 dB in 0.25 s (docs/audio-log.md,
"A pause is not an end stop").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, sosfilt

from ..features.stepclock import band_envelope_spectrum, step_rate_hz
from ..paramfield import param
from ..tuningfile import Tuning

__all__ = [
    "PAUSE",
    "PauseCheck",
    "PauseParams",
    "Stopped",
    "band_filter",
    "band_power",
    "step_lines_db",
    "stepping_stopped",
    "tuned_change_db",
]


@dataclass(frozen=True)
class PauseParams:
    """When a fire that persisted was the stepping stopping (a pause), not an end stop."""

    drop_db: float = param(20.0, "dB", "the window's in-band power fell at least this far below the stepping's ...")
    margin_db: float = param(12.0, "dB", "... and this much further than the tuned stop's own in-band change ...")
    step_lines: int = param(4, "harmonics", "... and the envelope's lines at the first this many multiples of the rate")
    line_tolerance: float = param(0.005, "of the line", "(each looked for this near k x the rate heard before) ...")
    lines_db: float = param(
        10.0, "dB", "... stand less than this above their neighbourhoods, averaged: nothing steps (noise: 8.8 at most)"
    )
    before_quantile: float = param(
        0.3, "", "the stepping's level is this quantile of its 10 ms powers: a knock or a chirp only adds"
    )
    after_quantile: float = param(0.5, "", "the window's level is the median of its 10 ms powers")
    piece_s: float = param(0.01, "s", "the pieces whose powers are ranked")
    min_after_s: float = param(0.1, "s", "a window shorter than this is not judged: nothing contradicts a stop")
    back_db: float = param(
        10.0, "dB", "a piece within this of the stepping's level ends a pause: its lines are judged before it"
    )
    resume_pieces: int = param(
        3, "pieces", "after a pause, restart where this many pieces in a row are the stepping back (a knock is shorter)"
    )
    rise_db: float = param(
        10.0, "dB", "... each within back_db of its level, or this far over the pause's quietest piece (another gain)"
    )


PAUSE = PauseParams()


@dataclass(frozen=True)
class Stopped:
    """Why a fire was the stepping stopping, not an end stop.

    Attributes
    ----------
    drop_db : float
        In-band power of the window against the stepping before the fire, dB (negative: quieter).
    line_db : float
        The step-rate line of the window's envelope above its neighbourhood, dB (-inf: no rate known).
    step_hz : float
        The step rate the line was looked for at, Hz (nan: none known).
    """

    drop_db: float
    line_db: float
    step_hz: float


def band_filter(band_hz: tuple[float, float], sample_rate: float) -> NDArray[np.float64]:
    """Second-order sections of a 4th-order Butterworth band-pass over ``band_hz`` (Hz) at ``sample_rate`` (Hz)."""
    lo, hi = float(band_hz[0]), float(band_hz[1])
    nyq = 0.5 * float(sample_rate)
    lo = min(max(lo, 1.0), 0.9 * nyq)
    hi = min(max(hi, 1.01 * lo), 0.98 * nyq)
    return np.asarray(butter(4, [lo, hi], btype="bandpass", fs=float(sample_rate), output="sos"), dtype=np.float64)


def band_power(
    x: NDArray[np.float64], sos: NDArray[np.float64], sample_rate: float, quantile: float, p: PauseParams = PAUSE
) -> float:
    """The ``quantile`` of the ``piece_s`` powers of ``x`` through the band-pass ``sos`` (full scale 1; nan if short).

    The filter's first half piece is left out (its transient).
    """
    n = max(1, int(round(p.piece_s * sample_rate)))
    if x.size < 2 * n:
        return float("nan")
    y = sosfilt(sos, x)[n // 2 :]
    m = y.size // n
    powers = np.mean(y[: m * n].reshape(m, n) ** 2, axis=1)
    return float(np.quantile(powers, quantile))


def step_lines_db(
    x: NDArray[np.float64],
    sample_rate: float,
    step_hz: float,
    harmonics: int = PAUSE.step_lines,
    tolerance: float = PAUSE.line_tolerance,
) -> float:
    """The envelope's lines at the step rate's first ``harmonics`` multiples above their neighbourhoods, dB, averaged.

    The envelope is the first-differenced signal squared (a click train's, and a periodic
    drive tone's, has lines at the step rate and its multiples). Each line is the largest
    bin within ``tolerance`` of k x ``step_hz`` against the median of the bins from
    k - 0.5 to k + 0.5 times ``step_hz`` outside it. The rate is the one heard just before,
    so the window can be narrow. On white noise the guard's single line at +-3 %
    (:func:`~stickslip.audio.sources.guard.step_line_db`) reads 7.0 dB (median) and 8 dB or more in
    a quarter of 0.5 s windows; four lines at +-0.5 % averaged read 5.4 dB, 7.1 dB at the
    95th percentile and 8.8 dB at most in 600 windows (``tests/test_audio_stopped.py``).
    Needs 20 step periods (else ``inf``: no verdict, something may be stepping).
    """
    sr = float(sample_rate)
    if not (step_hz > 0 and x.size >= 20 * sr / step_hz and step_hz < sr / 4):
        return float("inf")
    f, p = band_envelope_spectrum(x, sr)  # the guard's envelope: the first-differenced signal squared
    got = []
    for k in range(1, harmonics + 1):
        c = k * step_hz
        if c >= sr / 2 - 0.5 * step_hz:
            break
        near = np.abs(f - c) <= max(tolerance * c, 1.01 * (f[1] - f[0]))
        around = (np.abs(f - c) <= 0.5 * step_hz) & ~near
        if near.any() and around.any():
            got.append(10 * np.log10((p[near].max() + 1e-300) / (np.median(p[around]) + 1e-300)))
    return float(np.mean(got)) if got else float("inf")


def tuned_change_db(stepping_levels_db: tuple[float, ...] | None, signature_db: tuple[float, ...] | None) -> float:
    """The tuned stop's change of the in-band power, dB: the sub-bands' stepping levels shifted by the signature.

    0 when the tuning does not say (a band tuning): then only ``drop_db`` applies.
    """
    if not stepping_levels_db or not signature_db or len(stepping_levels_db) != len(signature_db):
        return 0.0
    lv = np.asarray(stepping_levels_db, dtype=np.float64)
    sig = np.asarray(signature_db, dtype=np.float64)
    if not (np.all(np.isfinite(lv)) and np.all(np.isfinite(sig))):
        return 0.0
    p = 10.0 ** ((lv - lv.max()) / 10.0)
    return float(10.0 * np.log10(np.sum(p * 10.0 ** (sig / 10.0)) / np.sum(p)))


def stepping_stopped(
    before_power: float,
    after: NDArray[np.float64],
    sos: NDArray[np.float64],
    sample_rate: float,
    step_hz: float,
    tuned_db: float = 0.0,
    p: PauseParams = PAUSE,
) -> Stopped | None:
    """Was the fire the stepping stopping? A :class:`Stopped` if so, else ``None`` (an end stop may be there).

    Parameters
    ----------
    before_power : float
        In-band power of the stepping before the fire (:func:`band_power` at ``before_quantile``, full
        scale 1).
    after : numpy.ndarray
        The samples after the fire (its confirmation window), full scale 1.
    sos : numpy.ndarray
        The detector's band-pass (:func:`band_filter`).
    sample_rate : float
        Samples per second, Hz.
    step_hz : float
        The step rate heard before the fire, Hz (nan or 0: not known; then the level alone decides).
    tuned_db : float
        The tuned stop's in-band change, dB (:func:`tuned_change_db`).
    """
    if not (math.isfinite(before_power) and before_power > 0.0) or after.size < int(p.min_after_s * sample_rate):
        return None  # too little to tell: nothing contradicts a stop
    pa = band_power(after, sos, sample_rate, p.after_quantile, p)
    drop = 10.0 * math.log10(max(pa, 1e-300) / before_power)
    if drop > min(-p.drop_db, tuned_db - p.margin_db):
        return None
    known = math.isfinite(step_hz) and step_hz > 0.0
    quiet = _until_back(after, sos, sample_rate, before_power, p)
    line = step_lines_db(quiet, sample_rate, step_hz, p.step_lines, p.line_tolerance) if known else -math.inf
    if line >= p.lines_db:
        return None  # something still steps at the rate: a stop that silenced the slips, not the drive
    return Stopped(drop_db=drop, line_db=line, step_hz=step_hz if known else math.nan)


def _until_back(
    after: NDArray[np.float64], sos: NDArray[np.float64], sample_rate: float, before_power: float, p: PauseParams
) -> NDArray[np.float64]:
    """The window up to where the stepping came back (a piece within ``back_db`` of its level), or all of it.

    A pause shorter than the window ends inside it: the stepping that resumes holds the step
    rate's lines, and judged over the whole window they said "something still steps" (a
    0.4 s pause on an accelerometer was reported as the stop). An end stop does not end: its
    window never fell, or never came back.
    """
    n = max(1, int(round(p.piece_s * sample_rate)))
    if after.size < 2 * n:
        return after
    y = sosfilt(sos, after)[n // 2 :]
    m = y.size // n
    level = 10.0 * np.log10(np.maximum(np.mean(y[: m * n].reshape(m, n) ** 2, axis=1), 1e-300) / before_power)
    low = np.flatnonzero(level <= -p.drop_db)
    if low.size == 0:
        return after
    back = np.flatnonzero(level[low[0] :] >= -p.back_db)
    if back.size == 0:
        return after
    end = n // 2 + (low[0] + back[0]) * n  # the first sample of the piece where the stepping is back
    return after[:end] if end >= int(p.min_after_s * sample_rate) else after


class PauseCheck:
    """The pause judgement over a stream: the stepping before a fire, then the fire's window.

    Parameters
    ----------
    tuning : Tuning
        The detector's tuning: its band (the template's span) and the tuned stop's change there.
    p : PauseParams
    """

    def __init__(self, tuning: Tuning, p: PauseParams = PAUSE) -> None:
        self.tuning, self.p = tuning, p
        self.sample_rate = int(tuning.sample_rate)
        edges = tuning.edges_hz if tuning.method == "template" and tuning.edges_hz else tuning.band_hz
        self.sos = band_filter((float(edges[0]), float(edges[-1])), self.sample_rate)
        self.tuned_db = tuned_change_db(tuning.stepping_levels_db, tuning.signature_db)
        self.reset()

    def reset(self) -> None:
        #: in-band power of the stepping before the fire that began the current chain (full scale 1)
        self.before_power = math.nan
        #: its step rate, Hz
        self.before_hz = math.nan

    def hear_before(self, before: NDArray[np.float64], min_samples: float) -> None:
        """The stepping before a fire (``before``; fewer than ``min_samples`` samples: not known)."""
        if before.size < min_samples:
            self.before_power = self.before_hz = math.nan
            return
        sr = self.sample_rate
        self.before_power = band_power(before, self.sos, sr, self.p.before_quantile, self.p)
        hz = step_rate_hz(before, sr)
        tuned = self.tuning.step_rate_hz
        self.before_hz = hz if math.isfinite(hz) else (float(tuned) if tuned else math.nan)

    def stopped(self, after: NDArray[np.float64]) -> Stopped | None:
        """Was the fire whose window is ``after`` the stepping stopping? (:func:`stepping_stopped`)"""
        return stepping_stopped(
            self.before_power, after, self.sos, self.sample_rate, self.before_hz, self.tuned_db, self.p
        )
