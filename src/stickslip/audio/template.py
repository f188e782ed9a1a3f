"""The spectral-template change detector: an end stop is a lasting departure from stepping.

While a joint steps, its sound has a steady spectral signature: per frame (``frame``
samples every ``hop``), the level of each of ``B`` sub-bands spanning the stepping
sound's band, ``v_b`` in dB. The detector keeps a *running template* ``T_b`` of that
signature (the median of the first frames, then an exponential average with time
constant ``tau_s``, frozen while the sound departs from it) and reads every frame as a
departure ``d_b = v_b - T_b`` (dB). Because the template follows the input, a microphone
gain, a distance or a step rate that differs from the tuning recording's cancels.

Tuning measured the end stop's own departure, the *signature* ``delta_b`` (dB per
sub-band: positive where the stop is louder, negative where it is quieter, so louder,
quieter, duller and brighter stops are all one case), and the frame-to-frame spread
``sigma_b`` of stepping. Each frame is fitted as ``d = a * delta + e`` by weighted least
squares (weights ``1 / sigma_b**2``), trimmed: the ``trim`` sub-bands that fit worst are
dropped and the fit repeated, so a voice or a fan that covers a few sub-bands does not
move ``a``. Two numbers come out per frame:

* ``a``, the *stop-likeness*: 0 while stepping, 1 at a stop like the tuning's;
* ``rho``, the root-mean-square of the kept residuals in units of ``sigma_b``: how
  unlike *both* stepping and the stop the frame is (a knock, a door slam).

A frame is *hot* when ``a >= threshold`` and ``rho <= residual_max``. The detector
fires when ``hold`` of the last ``hold + max_dips`` frames were hot, the current one
included, and the current ``a`` has not decayed below ``decay_ratio`` of the largest in
that window (a transient rings down, a stop does not). It then stays latched until ``a``
has stayed below ``threshold - hysteresis`` for ``release_s`` (the template goes on
following), or, once latched for :data:`RELEASE_AFTER_S` and not held by a confirmation,
until over the last ``release_s`` at least :data:`RELEASE_SHARE` of the frames sounded
like stepping again rather than like the stop that fired (:class:`Release`,
:meth:`TemplateState._stepping_again`); then it learns its template anew from them.

A tuning that holds the training recording's fine continuum spectra (round 11a) lets the
detector predict the stop's signature at the step rate it hears, at the warm-up and
whenever it learns its template anew (:mod:`.rate_signature`): within 1-12 % of the
tuning's rate each frame is fitted on that signature too, and the larger ``a`` counts
(with its residual) where the prediction explains the frame (:meth:`TemplateState._hear_rate`);
where it explains the frame well, the predicted signature's drops may pass the drops' check
the tuned ones fail (round 12b, :data:`PRED_DROPS_RHO`).

Where sound was added to the stepping since the floor's window began (the template stands
:data:`MASK_ADDED` spreads over the floor, and no sub-band fell as far), the signatures are
fitted as the stop can show over it (:func:`masked_signature`, session 29).

Two judgements read the *continuum* between the step clock's lines
(:func:`continuum_levels_db`), which a change of the step rate does not move as it moves
the sub-band levels (tunings that recorded their step rate): whether listening began at
the stop (:meth:`TemplateState._started_at_stop`), and whether a fire was the template
gone stale with a drifting rate (:meth:`TemplateState._stale_check`).

Everything that changes the detector's state happens at frame boundaries counted from
the stream start (the template is updated every :data:`CHUNK` frames), so the events do
not depend on how the stream is cut into blocks.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .rate_signature import MIN_SIGNATURE_RMS, RATE_MIN_CHANGE, RATE_WINDOW, SignaturePredictor

__all__ = [
    "CHUNK",
    "QUANTILE",
    "RELEASE_AFTER_S",
    "RELEASE_C",
    "RELEASE_SHARE",
    "RELEASE_SILENT_DB",
    "Release",
    "TemplateParams",
    "TemplateState",
    "continuum_levels_db",
    "fit_departure",
    "masked_signature",
    "subband_edges",
    "subband_levels_db",
]

#: template update period and warm-up unit, frames
CHUNK = 64
#: the template tracks this quantile of the stepping levels: interference only adds sound, so a
#: low quantile follows the stepping sound under intermittent speech, knocks or a second instrument
QUANTILE = 0.3
#: a chunk whose median residual exceeds this many times ``residual_max`` re-learns the template
STALE_RESIDUAL = 2.0
#: a relearned template this much louder in every sub-band is a new level, not a sound added, dB
STALE_ALL_UP_DB = 3.0
#: residual allowance per unit of fitted departure (see :func:`fit_departure`)
RESIDUAL_SLOPE = 0.35
_FLOOR = 1e-20
_CLIP_DB = 40.0
#: the continuum: frequency bins farther than this many bins from every harmonic of the step rate
#: (a 4-term Blackman-Harris window's main lobe is +-4 bins wide; its sidelobes are 92 dB down, so a line
#: 40 dB over the continuum does not leak into it, as a Hann window's -31 dB sidelobes would)
LINE_GUARD_BINS = 4.0
#: the continuum is measured in frames this many times the detector's (finer bins: more of them between the
#: lines, and a steadier level), every detector frame
CONTINUUM_FRAME = 4
#: listening that starts at the stop, judged on the continuum (see :meth:`TemplateState._started_at_stop`):
#: the stop must explain at least this much of the tuning's signature ...
START_MIN_B = 0.7
#: ... and leave at most this share of what a gain change alone leaves
START_MAX_RATIO = 0.4
#: the levels' verdict "the stop" counts, where the tuning holds the continuum, only where the continuum's fit also
#: gives the stop at least this share of its signature (round 10a: a reverberant room or a step rate 1-4 % off colours
#: the stepping's levels like a damped or shifted stop, b 0.95-2.1, while its continuum says b -0.1-0.02)
START_LEVELS_CONTINUUM_B = 0.5
#: the continuum's verdict "the stop" does not count by itself where the levels give the stop less than this share of
#: its signature (session 27: under a strictly periodic drive tone, slips that jitter less than the tuning's - 3-6
#: against 15 us - lower the continuum where they dominate, the shape a stop that silences the slips has: the
#: continuum called stepping a stop at 950, 1000 and 1050 Hz while the levels gave b -0.08 to 0.05)
START_CONTINUUM_LEVELS_B = 0.25
#: a fire whose continuum did not change is a stale template (the step rate moved), not a stop: the continuum over
#: this long after the fire, s, ...
STALE_AFTER_S = 0.3
#: ... against the continuum over this long of the stepping before it (at least half of it), s, ...
STALE_REF_S = 0.3
#: ... that ends this long before the fire, s (the stop's onset is a hold before the fire)
STALE_GAP_S = 0.06
#: ... judged only where the step rate heard moved by at least this share between the two (a template goes stale
#: with the rate; where the rate stayed, the fire stands and confirmation judges it) ...
STALE_MIN_RATE_CHANGE = 0.01
#: ... and by at most this share (a larger jump is an estimate that took a multiple or a fraction of the rate)
STALE_MAX_RATE_JUMP = 0.1
#: ... and is unchanged when it moved by less than this in level, dB (a quieter stop: 7-8 dB on the generators), ...
STALE_MAX_GAIN_DB = 3.0
#: ... and by less than this in shape (RMS over sub-bands after the level, in the continuum's spreads)
STALE_MAX_SHAPE = 1.1
#: a fire this soon after a stale-template verdict may be a stop that began inside the judged span or at its end:
#: its onset is uncertain, s
STALE_UNCERTAIN_S = 0.3
#: the template learned anew from the levels of this much of the end of the judged span, s (the latest rate) ...
STALE_RELEARN_S = 0.15
#: ... and the stepping before the fire did not already sound like the stop (a late fire: the stop began before the
#: reference span), judged as at the start (:data:`START_MIN_B`) at this share of the signature
STALE_REF_MAX_B = 0.5

#: a latched detector re-arms when, over the last ``release_s``, at least this share of the frames sounded like
#: stepping again (:meth:`TemplateState._stepping_again`). Not "every frame below half the threshold": stepping's
#: ``a`` wobbles (on joint P of the battery a stepping frame passes half the threshold about once in 20), so that
#: almost never came and the next stop in the same stream was not heard
RELEASE_SHARE = 0.8
#: ... counted only once the detector has been latched this long, s: a stop lasts as long as the joint steps into it
#: (a traverse steps on for ``confirm_s``, 0.5 s); a fire on a voice that ends sooner is the confirmation's to reject
#: (:mod:`.confirm`), and re-arming inside its window let the voice fire again and again (joint P under babble:
#: 1 -> 14 confirmed false alarms in 6 min)
RELEASE_AFTER_S = 0.5
#: the stop's own sound is the median of this many frames after the fire
STOP_ROWS = 8
#: a frame sounds like stepping again when its departure from the template, projected on the stop's own departure,
#: is under this share of it ...
RELEASE_C = 0.5
#: ... and its median sub-band is no more than this far under the template, dB (silence after a stop is not stepping)
RELEASE_SILENT_DB = 10.0

FloatArray = NDArray[np.float64]


class Release:
    """When a latched detector re-arms: a sliding window of ``frames`` frames (``release_s``).

    Each frame is pushed with its levels and whether it sounded like stepping again;
    :meth:`push` says True once the window is full and at least :data:`RELEASE_SHARE` of
    it did. :meth:`stepping_rows` gives those frames' levels (the template is learned
    anew from them).
    """

    def __init__(self, frames: int) -> None:
        self.frames = max(1, int(frames))
        self.reset()

    def reset(self) -> None:
        self._flags: list[bool] = []
        self._rows: list[FloatArray | None] = []
        self._start = 0
        self.count = 0

    def push(self, stepping: bool, row: FloatArray | None = None) -> bool:
        self._flags.append(stepping)
        self._rows.append(row)
        self.count += stepping
        if len(self._flags) - self._start > self.frames:
            self.count -= self._flags[self._start]
            self._rows[self._start] = None
            self._start += 1
            if self._start > 4 * self.frames:  # keep the lists short
                del self._flags[: self._start]
                del self._rows[: self._start]
                self._start = 0
        n = len(self._flags) - self._start
        return n >= self.frames and self.count >= RELEASE_SHARE * n

    def stepping_rows(self) -> list[FloatArray]:
        """The levels of the window's frames that sounded like stepping (those pushed with a row)."""
        return [
            r
            for f, r in zip(self._flags[self._start :], self._rows[self._start :], strict=True)
            if f and r is not None
        ]


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


def _bins(edges: tuple[float, ...] | list[float], sample_rate: int, frame: int) -> NDArray[np.intp]:
    freqs = np.fft.rfftfreq(frame, 1 / sample_rate)
    idx = np.searchsorted(freqs, np.asarray(edges, dtype=np.float64), side="left")
    return np.asarray(idx, dtype=np.intp)


def window(frame: int) -> tuple[FloatArray, float]:
    """Periodic Hann window and the scale that makes one-sided bins sum to the mean square."""
    w = np.hanning(frame + 1)[:-1]
    return w, 2.0 / (frame * float(np.sum(w**2)))


def levels_from_frames(frames: FloatArray, w: FloatArray, scale: float, idx: NDArray[np.intp]) -> FloatArray:
    """Sub-band levels (frames x bands), dB, of windowed frames; ``idx`` are bin edges.

    Single precision FFTs in cache-sized chunks: the levels are good to far better than
    0.01 dB, and this is most of the detector's cost.
    """
    from scipy import fft as sfft

    n = frames.shape[0]
    nb = idx.size - 1
    out = np.empty((n, nb))
    w32 = w.astype(np.float32)
    lo, hi = int(idx[0]), int(idx[-1])
    starts = (idx[:-1] - lo).astype(np.intp)
    for f0 in range(0, n, 1024):
        seg = np.asarray(frames[f0 : f0 + 1024], dtype=np.float32) * w32
        spec = sfft.rfft(seg, axis=1)[:, lo:hi]
        p = spec.real**2 + spec.imag**2
        band = np.add.reduceat(p, starts, axis=1, dtype=np.float64) * scale
        empty = idx[1:] <= idx[:-1]
        if empty.any():
            band[:, empty] = 0.0
        out[f0 : f0 + 1024] = 10 * np.log10(band + _FLOOR)
    return out


def subband_levels_db(
    samples: NDArray[np.floating] | FloatArray,
    sample_rate: int,
    frame: int,
    hop: int,
    edges: tuple[float, ...] | list[float],
) -> FloatArray:
    """Sub-band levels of every frame of a recording (frames x bands), dBFS.

    Frame ``i`` covers samples ``[i*hop, i*hop + frame)``.
    """
    x = np.asarray(samples, dtype=np.float64)
    idx = _bins(edges, sample_rate, frame)
    nb = len(edges) - 1
    if x.size < frame:
        return np.zeros((0, nb))
    w, scale = window(frame)
    view = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    out = np.empty((view.shape[0], nb))
    for f0 in range(0, view.shape[0], 4096):
        out[f0 : f0 + 4096] = levels_from_frames(view[f0 : f0 + 4096], w, scale, idx)
    return out


def continuum_levels_db(
    samples: NDArray[np.floating] | FloatArray,
    sample_rate: int,
    frame: int,
    hop: int,
    edges: tuple[float, ...] | list[float],
    rate_hz: float,
) -> FloatArray:
    """Sub-band levels of the *continuum* between the step clock's lines, per frame (frames x bands), dB.

    A click train at ``rate_hz`` puts its power on lines at the rate's multiples; which of a
    narrow mode's frequencies a line samples depends on the rate, so a sub-band's level
    moves by many dB when the rate changes (a line enters or leaves the sub-band). Between
    the lines lies the continuum the steps' irregularity makes (their timing jitter and
    amplitude), shaped by the same modes at every rate. Per frame (4-term Blackman-Harris
    window) and sub-band: the mean power of the bins farther than :data:`LINE_GUARD_BINS` bins from every multiple of
    ``rate_hz``, in dB (a power per bin: another rate changes it by the same factor in
    every sub-band, a gain). NaN where a sub-band has no such bin.
    """
    x = np.asarray(samples, dtype=np.float64)
    nb = len(edges) - 1
    if x.size < frame or not rate_hz > 0:
        return np.full((0, nb), np.nan)
    f = np.fft.rfftfreq(frame, 1 / sample_rate)
    bin_hz = sample_rate / frame
    off = np.abs(f - np.round(f / rate_hz) * rate_hz) > LINE_GUARD_BINS * bin_hz
    idx = _bins(edges, sample_rate, frame)
    from scipy.signal import get_window

    w = np.asarray(get_window("blackmanharris", frame, fftbins=True), dtype=np.float64)
    scale = 2.0 / (frame * float(np.sum(w**2)))
    view = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    spec = np.fft.rfft(view * w, axis=1)
    p = (spec.real**2 + spec.imag**2) * scale
    out = np.full((view.shape[0], nb), np.nan)
    for b in range(nb):
        sel = np.zeros(f.size, dtype=bool)
        sel[idx[b] : idx[b + 1]] = True
        sel &= off
        if sel.any():
            out[:, b] = 10 * np.log10(p[:, sel].mean(axis=1) + _FLOOR)
    return out


def fit_departure(d: FloatArray, delta: FloatArray, sigma: FloatArray, trim: int) -> tuple[FloatArray, FloatArray]:
    """Stop-likeness ``a`` and residual ``rho`` of departures ``d`` (frames x bands, dB).

    Weighted least squares ``d = a * delta + e`` (weights ``1/sigma**2``), then the same
    with the ``trim`` bands of each frame that have the most unexplained *excess* dropped
    (interference adds sound; a band whose expected rise is missing is evidence against a
    stop and is never dropped). ``rho`` is the RMS of the kept residuals in units of
    ``sigma``, less :data:`RESIDUAL_SLOPE` times the signature's RMS (in units of ``sigma``)
    times ``a``: the residual a stop of that size may have (another step rate moves the
    lines of its sound).
    """
    return _Fitter(delta, sigma, trim)(d)


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
    joint P under a second instrument ringing where the stop's largest drop is: heard by the
    late path alone, 0.56 s after the stop).

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


class _Fitter:
    """:func:`fit_departure` with the signature's constants computed once."""

    def __init__(self, delta: FloatArray, sigma: FloatArray, trim: int) -> None:
        self.inv_sigma = 1.0 / np.asarray(sigma, dtype=np.float64)
        self.g = np.asarray(delta, dtype=np.float64) * self.inv_sigma
        self.g2 = self.g**2
        self.gg = float(self.g2.sum())
        self.slope = RESIDUAL_SLOPE * float(np.sqrt(np.mean(self.g2)))
        self.trim = int(trim)

    def __call__(self, d: FloatArray) -> tuple[FloatArray, FloatArray]:
        g = self.g
        z = np.clip(d, -_CLIP_DB, _CLIP_DB) * self.inv_sigma
        a = (z @ g) / self.gg
        if self.trim > 0:
            r = z - a[:, None] * g
            if self.trim == 1:
                kth = r.max(axis=1, keepdims=True)
            else:
                kth = -np.partition(-r, self.trim - 1, axis=1)[:, self.trim - 1 : self.trim]
            keep = r < kth  # ties (rare) drop one band more
            keep |= ~keep.any(axis=1, keepdims=True)  # all tied (a constant input): keep every band
            zk = z * keep
            a = (zk @ g) / np.maximum(keep @ self.g2, 1e-12)
            res = zk - (a[:, None] * g) * keep
            rho = np.sqrt(np.einsum("ij,ij->i", res, res) / keep.sum(axis=1))
        else:
            res = z - a[:, None] * g
            rho = np.sqrt(np.einsum("ij,ij->i", res, res) / z.shape[1])
        rho = rho - self.slope * np.maximum(a, 0.0)
        return a, rho


@dataclass(frozen=True)
class TemplateParams:
    """What the template detector needs (a view of :class:`~stickslip.audio.detector.Tuning`)."""

    sample_rate: int
    frame: int
    hop: int
    edges_hz: tuple[float, ...]
    signature_db: tuple[float, ...]
    spread_db: tuple[float, ...]
    threshold: float
    residual_max: float
    hold_frames: int
    max_dips: int
    release_frames: int
    hysteresis: float
    decay_ratio: float
    tau_s: float
    warmup_chunks: int
    trim: int
    onset_lag_s: float
    stepping_levels_db: tuple[float, ...] | None = None
    drop_threshold: tuple[float, float] | None = None
    step_rate_hz: float | None = None
    continuum_levels_db: tuple[float, ...] | None = None
    continuum_signature_db: tuple[float, ...] | None = None
    continuum_spread_db: tuple[float, ...] | None = None
    fine_start_hz: float | None = None
    fine_bin_hz: float | None = None
    fine_stepping_db: tuple[float, ...] | None = None
    fine_stopped_db: tuple[float, ...] | None = None


@dataclass
class Decision:
    """One fired event, in the template detector's own terms."""

    end_sample: int
    cross_t_s: float
    a: float
    #: the stop may have begun before ``cross_t_s``: it fired soon after a fire judged a stale template, and may have
    #: begun inside that fire's span (see :meth:`TemplateState._stale_check`)
    uncertain: bool = False


class DropMeter:
    """How far the sound has *dropped* below the stepping template, averaged over :data:`DROP_FRAMES` frames.

    Interference only adds sound, so a lasting drop below the stepping template is
    evidence no voice, knock or second instrument can fake: a quieter, a duller or a
    spectral stop (energy leaves a sub-band) is heard whatever the tuning learned.
    Per frame, from the departures ``z_b = d_b / sigma_b`` (spreads) averaged over the
    last :data:`DROP_FRAMES` frames, ``m_b``, two statistics (spreads, >= 0):

    * *broad*: ``-median_b m_b``, the bulk of the sub-bands dropped together (a quieter
      stop, or every stepping mode weaker while the stop rings in one band);
    * *local*: ``sqrt(mean_b min(m_b, 0)**2)``, a few sub-bands dropped far (a duller or
      a spectral stop).

    The average costs (``DROP_FRAMES`` - 1) / 2 hops of latency, which :data:`DROP_LAG_FRAMES`
    gives back to the onset.
    """

    def __init__(self, n_bands: int, frames: int | None = None) -> None:
        self.nb = int(n_bands)
        self.frames = int(frames or DROP_FRAMES)
        self.reset()

    def reset(self) -> None:
        """Forget the frames averaged so far."""
        self._tail = np.zeros((0, self.nb))

    def __call__(self, z: FloatArray) -> FloatArray:
        """The departures ``z`` (frames x bands, spreads) averaged over the last ``frames`` frames."""
        w = self.frames
        zz = np.concatenate((self._tail, z)) if self._tail.size else z
        c = np.concatenate((np.zeros((1, self.nb)), np.cumsum(zz, axis=0)))
        k = np.arange(zz.shape[0] - z.shape[0], zz.shape[0]) + 1  # rows of zz ending each new frame
        lo = np.maximum(k - w, 0)
        self._tail = zz[max(len(zz) - (w - 1), 0) :].copy()
        return np.asarray((c[k] - c[lo]) / (k - lo)[:, None], dtype=np.float64)

    @staticmethod
    def drops(m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Broad and local drop (spreads, >= 0) of averaged departures ``m`` (frames x bands)."""
        nb = m.shape[1]
        half = (nb - 1) // 2, nb // 2
        part = np.partition(m, half, axis=1)
        broad = np.maximum(-0.5 * (part[:, half[0]] + part[:, half[1]]), 0.0)
        neg = np.minimum(m, 0.0)
        local = np.sqrt(np.einsum("ij,ij->i", neg, neg) / nb)
        return broad, local


#: frames averaged by :class:`DropMeter` (21 ms at 48 kHz, as the hold)
DROP_FRAMES = 8
#: the drop channel is armed this long after the warm-up, s (the template then has followed the stream)
DROP_ARM_S = 0.35
#: a signature whose drops add up to this many spreads (RMS-summed) is informative about them ...
NEG_INFORMATIVE = 2.0
#: ... and a frame then counts as the stop only if, averaged over NEG_FRAMES, it shows this share of those drops
NEG_MIN = 0.15
#: ... and at least this share of its own stop-likeness ``a`` (capped at 1): the stop's rises and its drops
#: come together; a voice or a radio lifts the rising sub-bands while the others show only their wobble
NEG_RATIO = 0.45
#: ... with each sub-band's expected drop capped at this many spreads (a noise floor fills deeper holes)
NEG_CAP = 3.0
#: ... less this many standard errors of the share shown (a weak drop signature shows its share only noisily)
SE_SLACK = 0.5
#: frames averaged for that check (a short average: it must not delay the stop)
NEG_FRAMES = 4
#: a sub-band this many spreads above the floor has something added to it: it cannot show a drop, and the
#: check judges the drops on the other sub-bands; with less than NEG_INFORMATIVE left, the frame is not the stop
NEG_EXCESS = 2.0
#: drops are measured from the *floor*: per sub-band the lowest template of the last this many updates
#: (64 frames each: 1.4 s at 48 kHz). Interference only adds sound, so a template a voice or a radio
#: lifted is not the stepping's level, and the pause after a word is not a drop
FLOOR_CHUNKS = 8
#: the stop's signature is fitted as it can show over sound added to the stepping (:func:`masked_signature`) in
#: sub-bands where the template stands this many spreads above the floor, provided that no sub-band's template fell as
#: far below its highest over the floor's updates: added sound only lifts, while a step rate that drifts moves the
#: lines of the stepping's own sound off some modes and onto others (the battery's clock drifting +-10 % lifted one
#: sub-band 12 dB over the floor and lowered others). None: the tuned signature alone, as before session 29
MASK_ADDED: float | None = NEG_EXCESS
#: a frame the signature predicted at the heard rate (:meth:`TemplateState._hear_rate`) fits as the stop (its ``a`` at
#: the threshold) with its residual within this share of ``residual_max`` passes the drops' check if the predicted
#: signature's drops show in proportion, where the tuned signature's do not (round 12b): at another rate the sub-bands
#: the tuned signature lowers may hold or rise (the lines sample the modes elsewhere). Half the limit: a frame the
#: prediction explains well, not one it only tolerates (measured: 0.5 and 1.0 gave the same outcomes on 407 of 408
#: recordings). None: the tuned drops alone
PRED_DROPS_RHO: float | None = 0.5
#: the average's delay, frames: given back to a drop-fired onset
DROP_LAG_FRAMES = (DROP_FRAMES - 1) / 2


def _drops_terms(
    zs: FloatArray, clear: NDArray[np.bool_], gn: FloatArray, gg: float, tail: tuple[FloatArray, FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """The drops' check's per-frame terms after ``tail``: (drops shown, information left), as shares of ``gg``."""
    num = np.concatenate((tail[0], (np.maximum(zs, -NEG_CAP) * clear) @ gn / gg))
    den = np.concatenate((tail[1], clear.astype(np.float64) @ (gn * gn) / gg))
    return num, den


def _drops_tail(
    zs: FloatArray, clear: NDArray[np.bool_], gn: FloatArray, tail: tuple[FloatArray, FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """The tail :func:`_drops_shown` would leave, without the verdicts (a piece where none can matter)."""
    k = NEG_FRAMES - 1
    gg = float(gn @ gn)
    if gg <= 0.0:
        return tail
    num, den = _drops_terms(zs[-k:], clear[-k:], gn, gg, tail)
    keep = max(num.size - k, 0)
    return num[keep:], den[keep:]


def _drops_shown(
    zs: FloatArray,
    clear: NDArray[np.bool_],
    gn: FloatArray,
    info_sig: float,
    a: FloatArray,
    tail: tuple[FloatArray, FloatArray],
) -> tuple[NDArray[np.bool_], tuple[FloatArray, FloatArray]]:
    """Per frame: whether the drops of signature ``gn`` (spreads, each capped at :data:`NEG_CAP`) show in proportion.

    ``zs`` are the frames' levels below the floor (spreads), ``clear`` the sub-bands without an excess (a band
    something was added to cannot show a drop), ``info_sig`` the signature's drop information in the tuning's
    spreads, ``a`` the frames' stop-likeness and ``tail`` the last :data:`NEG_FRAMES` - 1 frames' (shown, information)
    terms. The drops shown, as a share of the signature's, averaged over :data:`NEG_FRAMES` frames, must reach
    :data:`NEG_RATIO` of ``a`` (at least :data:`NEG_MIN`, less :data:`SE_SLACK` standard errors) on sub-bands holding
    at least :data:`NEG_INFORMATIVE` spreads of drops. Returns the verdicts and the new tail.
    """
    gg = float(gn @ gn)
    if gg <= 0.0:
        return np.zeros(a.size, dtype=bool), tail
    num, den = _drops_terms(zs, clear, gn, gg, tail)
    cn = np.concatenate(([0.0], np.cumsum(num)))
    cd = np.concatenate(([0.0], np.cumsum(den)))
    k = np.arange(num.size - a.size, num.size) + 1
    lo = np.maximum(k - NEG_FRAMES, 0)
    info = (cd[k] - cd[lo]) / (k - lo)  # share of the signature's drop information left
    shown_avg = (cn[k] - cn[lo]) / np.maximum(cd[k] - cd[lo], 1e-12)
    judged = info * info_sig >= NEG_INFORMATIVE**2
    # the share shown is measured with noise: one spread per sub-band and frame gives a standard error of
    # 1 / sqrt(frames x drops' information); a weak drop signature is not held to the share it cannot show
    se = 1.0 / np.sqrt(np.maximum((cd[k] - cd[lo]) * gg, 1e-12))
    need = np.maximum(NEG_MIN, NEG_RATIO * np.clip(a, 0.0, 1.0) - SE_SLACK * se)
    keep = max(num.size - (NEG_FRAMES - 1), 0)
    return judged & (shown_avg >= need), (num[keep:], den[keep:])


class TemplateState:
    """The streaming state of the template detector (see the module docstring).

    :meth:`process` takes the sub-band levels of consecutive frames and their end-sample
    indices and returns the decisions that fired.
    """

    def __init__(self, p: TemplateParams, t0_s: float = 0.0) -> None:
        self.p = p
        #: set to a list to collect every frame's stop-likeness (NaN while warming up)
        self.trace: list[float] | None = None
        #: set to a list to collect every frame's hot flag (stop-like by the fit or the drop channel; False
        #: while warming up); read-only evidence for a confirmation that watches the frames after a fire
        self.hot_trace: list[bool] | None = None
        self.delta = np.asarray(p.signature_db, dtype=np.float64)
        self.sigma = np.asarray(p.spread_db, dtype=np.float64)
        self._fit = _Fitter(self.delta, self.sigma, p.trim)
        # whether the stop's drops are worth checking is the tuning's to say (its spreads, each drop capped at
        # NEG_CAP): a noisy warm-up (a voice while the template was learned) must not switch the check off
        gt = np.maximum(np.minimum(self.delta, 0.0) * self._fit.inv_sigma, -NEG_CAP)
        self._drop_info_tuned = float(gt @ gt)
        self._drop = DropMeter(self.delta.size)
        #: the warm-up's samples from the stream start (:attr:`head_samples` of them), for the start-at-the-stop
        #: judgement on the continuum; the stream's owner (:class:`~stickslip.audio.detector.StopDetector`) sets it
        self.head: FloatArray | None = None
        #: the stream's samples ``[lo, hi)`` (absolute indices from the stream start), or None where they are gone;
        #: set by the stream's owner for the stale-template check (see :meth:`_stale_check`)
        self.samples: Callable[[int, int], FloatArray | None] | None = None
        #: per stale-template check: (the fire's end sample, the rate's relative change, the continuum's level change
        #: dB and shape change (spreads), judged stale)
        self.stale_log: list[tuple[int, float, float, float, bool]] = []
        self._after_frames = max(CHUNK + 1, int(math.ceil(STALE_AFTER_S * p.sample_rate / p.hop)))
        self._checks = p.continuum_signature_db is not None and p.continuum_spread_db is not None
        #: the tuning holds the fine spectra: the stop's signature is predicted at the step rate heard whenever the
        #: template is learned (:meth:`_hear_rate`) and fitted beside the tuned one
        self.predicts = (
            p.step_rate_hz is not None
            and p.fine_start_hz is not None
            and p.fine_bin_hz is not None
            and p.fine_stepping_db is not None
            and p.fine_stopped_db is not None
        )
        self._predictor: SignaturePredictor | None = None  # built at the first rate that needs it
        self.reset(t0_s)

    def reset(self, t0_s: float = 0.0) -> None:
        """Forget the template, the warm-up's samples and every decision."""
        self.head = None
        self.t0 = float(t0_s)
        self.frame_no = 0
        self.template: FloatArray | None = None
        self._warm: list[FloatArray] = []
        self._acc_list: list[FloatArray] = []
        self._acc_n = 0
        self._chunk_rho: list[FloatArray] = []
        self._chunk_v: list[FloatArray] = []
        self.mask = 0
        self.recent: list[float] = []
        self.latched = False
        self.below = 0
        self.release = Release(self.p.release_frames)
        self._stop_rows: list[FloatArray] = []  # the first frames after a fire (departures from the template)
        self._latched_frames = 0  # frames heard since the latest fire
        self.held = False  # set by a confirming wrapper while it judges the latest fire: no re-arming by itself
        self._min_latch = int(math.ceil(RELEASE_AFTER_S * self.p.sample_rate / self.p.hop))
        self._stop_e: FloatArray | None = None  # the stop's own departure (their median), weighted and scaled
        self.prev_a = -math.inf
        self.cross_t = math.nan
        self.last_a = 0.0
        self.last_rho = 0.0
        self._pending: list[Decision] = []
        self._drop_scale = self._fit.inv_sigma
        self.arm_sample = 0
        self._drop.reset()
        self._neg_tail: tuple[FloatArray, FloatArray] = (np.zeros(0), np.zeros(0))
        self._neg_tail_p: tuple[FloatArray, FloatArray] = (np.zeros(0), np.zeros(0))
        self._floors: list[FloatArray] = []
        self.floor: FloatArray | None = None
        #: the fits in use: on the tuned signature and the rate-predicted one, masked where sound was added to the
        #: template (:meth:`_mask`); ``_fit`` and ``_fit_rate`` where nothing was
        self._fit_now: _Fitter = self._fit
        self._fit_rate_now: _Fitter | None = None
        #: the sound added per sub-band to the latest template, dB (None: nothing added)
        self.added_db: FloatArray | None = None
        self._check: tuple[int, int] | None = None  # (frame at which to check, the fire's end sample)
        self._uncertain_until = -1  # a fire ending before this sample follows a stale-template verdict closely
        #: the stream samples (ends of the chunk) at which a template that fitted nothing was learned anew
        self.relearned: list[int] = []
        self._recent_v: list[tuple[int, FloatArray]] = []  # (first frame index, levels) of the latest frames
        self._head_rate: float | None = None  # the step rate heard in the warm-up's samples (once), Hz
        #: the fit on the signature predicted at the heard step rate, beside the tuned one (None: the tuned alone)
        self._fit_rate: _Fitter | None = None
        self._pred_delta: FloatArray | None = None  # the signature predicted at the heard rate (with _fit_rate)
        #: per hearing of the step rate (:meth:`_hear_rate`): (the stream sample it was heard up to, the rate heard, Hz
        #: (NaN: none), whether the predicted signature is fitted from there on)
        self.rate_log: list[tuple[int, float, bool]] = []

    def unlatch(self) -> None:
        """Re-arm: forget the latest fire and listen again from the next frame (a confirmation rejected it, or the
        stop is over); the template is kept."""
        self.latched = False
        self.held = False
        self.below = 0
        self.release.reset()
        self._stop_rows, self._stop_e, self._latched_frames = [], None, 0
        self.mask = 0
        self.recent = []

    def _latch(self) -> None:
        """A stop fired (or listening began at it): latched, its release window and its own sound to learn anew."""
        self.latched = True
        self.below = 0
        self.release.reset()
        self._stop_rows, self._stop_e, self._latched_frames = [], None, 0

    def _release_scan(self, v: FloatArray) -> int | None:
        """While latched: push the frames ``v`` (levels, dB) into the release window; the index of the re-arming frame.

        The template is frozen while latched, so each frame's departure is known before the
        frames are judged: the piece is cut at the frame that re-arms, and the frames after
        it are heard with the template learned anew (:meth:`_relearn_after_stop`).
        """
        assert self.template is not None
        d = v - self.template
        for k in range(v.shape[0]):
            if self._latch_frame(d[k], v[k]):
                return k
        return None

    def _latch_frame(self, d: FloatArray, v: FloatArray) -> bool:
        """One latched frame (its departure ``d`` and levels ``v``, dB): whether the detector re-arms at it."""
        self._latched_frames += 1
        stepping = self._stepping_again(d)
        return self._latched_frames > self._min_latch and self.release.push(stepping, v) and not self.held

    def _relearn_after_stop(self, end: int) -> None:
        """A stop ended: re-arm, and learn the template anew from the release window's stepping frames.

        The template was frozen while the detector was latched, and what follows a stop is
        a new stretch of stepping (the joint reversed, or a new traverse at another rate):
        its level is the release window's frames that sounded like stepping (at least
        :data:`RELEASE_SHARE` of them). The floor starts anew from it: a floor kept from
        before the stop is the old stepping's, and hid the next stop's drops (the fourth
        generator's arm 3: the next stop heard 27-109 ms late); a template kept from before
        the stop fired on stepping 4 % faster after it.
        """
        p = self.p
        rows = self.release.stepping_rows()
        self.unlatch()
        if len(rows) < p.release_frames // 2:
            return
        self.template = np.percentile(np.stack(rows), 100 * QUANTILE, axis=0)
        self._set_floor(reset=True)
        # what was gathered this chunk was measured against the old template
        self._acc_list, self._acc_n = [], 0
        self._chunk_rho, self._chunk_v = [], []
        self._drop.reset()
        self._neg_tail = (np.zeros(0), np.zeros(0))
        # a new stretch of stepping, perhaps at another rate: hear it over the release window
        self._hear_rate_over(end, p.release_frames * p.hop + p.frame)

    def _set_floor(self, reset: bool = False) -> None:
        """Remember the template just updated; the floor is the lowest of the last :data:`FLOOR_CHUNKS`."""
        if self.template is None:
            return
        self._floors = ([] if reset else self._floors[-(FLOOR_CHUNKS - 1) :]) + [self.template.copy()]
        kept = np.stack(self._floors)
        self.floor = np.min(kept, axis=0)
        self.added_db = None
        if MASK_ADDED is not None:
            scale = self._drop_scale
            added = self.template - self.floor
            lifted = added * scale >= MASK_ADDED
            fell = (np.max(kept, axis=0) - self.template) * scale
            if float(fell.max()) < MASK_ADDED and bool(lifted.any()):
                self.added_db = np.where(lifted, added, 0.0)
        self._mask()

    def _mask(self) -> None:
        """The fits for the latest template: the signatures masked by the sound added to it (:attr:`added_db`)."""
        p = self.p
        if self.added_db is None:
            self._fit_now, self._fit_rate_now = self._fit, self._fit_rate
            return
        self._fit_now = _Fitter(masked_signature(self.delta, self.added_db), self.sigma, p.trim)
        self._fit_rate_now = None
        if self._pred_delta is not None:
            self._fit_rate_now = _Fitter(masked_signature(self._pred_delta, self.added_db), self.sigma, p.trim)

    @property
    def warming(self) -> bool:
        """True until the template has been learned from the first frames."""
        return self.template is None or self.frame_no < self.p.warmup_chunks * CHUNK

    def process(self, v: FloatArray, ends: NDArray[np.int64]) -> list[Decision]:
        """Consume the levels ``v`` (frames x bands, dB) of the next frames; ends are sample indices."""
        out: list[Decision] = []
        i = 0
        n = v.shape[0]
        while i < n:
            room = CHUNK - self.frame_no % CHUNK
            if self._check is not None and self._check[0] > self.frame_no:
                room = min(room, self._check[0] - self.frame_no)
            j = min(n, i + room)
            cut = None
            if self.latched and not self.warming and self.template is not None:
                cut = self._release_scan(v[i:j])
                if cut is not None:
                    j = i + cut + 1
            out += self._segment(v[i:j], ends[i:j])
            self.frame_no += j - i
            i = j
            if cut is not None:
                self._relearn_after_stop(int(ends[j - 1]))
            if self._check is not None and self.frame_no >= self._check[0]:
                self._stale_check(int(ends[j - 1]))
            if self.frame_no % CHUNK == 0:
                self._chunk_done(int(ends[j - 1]))
                out += self._pending
                self._pending = []
        return out

    def _chunk_done(self, end: int) -> None:
        p = self.p
        if self.frame_no <= p.warmup_chunks * CHUNK:
            warm = np.concatenate(self._warm)
            self.template = np.percentile(warm, 100 * QUANTILE, axis=0)
            self._set_floor(reset=True)
            if self.frame_no == p.warmup_chunks * CHUNK:
                # the drop channel judges drops in the larger of the tuning's and this stream's spreads
                live = 1.4826 * np.median(np.abs(warm - np.median(warm, axis=0)), axis=0)
                self._drop_scale = 1.0 / np.maximum(self.sigma, live)
                self._warm = []
                self.arm_sample = end + int(DROP_ARM_S * p.sample_rate)
                if self.predicts:
                    self._hear_rate(self._heard_head_rate(), end)
                self._started_at_stop(end)
            return
        if self._chunk_rho and not self.latched and self.template is not None:
            rho_all = np.concatenate(self._chunk_rho)
            mid = rho_all.size // 2
            if rho_all.size >= CHUNK // 2 and float(np.partition(rho_all, mid)[mid]) > STALE_RESIDUAL * p.residual_max:
                old = self.template
                self.template = np.percentile(np.concatenate(self._chunk_v), 100 * QUANTILE, axis=0)
                # a new level in every sub-band (listening began in silence, the microphone moved closer): the
                # floor starts anew; a rise in some sub-bands only is a sound added (a loud voice): the floor keeps
                # the stepping's level, or the pause after the voice would look like a stop's drops
                self._set_floor(reset=bool(np.min(self.template - old) > STALE_ALL_UP_DB))
                self.relearned = [*self.relearned[-15:], end]  # for the confirming detector (confirm.py: a stop the
                # template learned); the latest few are all it asks about
                self._hear_rate_over(end, CHUNK * p.hop + p.frame)
                self._acc_n = 0
                self.arm_sample = end + int(DROP_ARM_S * p.sample_rate)
                self._drop.reset()
                self._neg_tail = (np.zeros(0), np.zeros(0))
                self._neg_tail_p = (np.zeros(0), np.zeros(0))
        self._chunk_rho, self._chunk_v = [], []
        if self._acc_n and self.template is not None and not self.latched:
            acc = np.concatenate(self._acc_list)
            k = int(QUANTILE * (acc.shape[0] - 1))
            q = np.partition(acc, k, axis=0)[k]
            alpha = 1.0 - math.exp(-self._acc_n * p.hop / p.sample_rate / p.tau_s)
            self.template = self.template + alpha * q
            self._set_floor()
        self._acc_list = []
        self._acc_n = 0

    def _heard_head_rate(self) -> float:
        """The step rate heard in the warm-up's samples :attr:`head`, Hz (NaN: none), heard once."""
        if self._head_rate is None:
            from .stepclock import step_rate_hz

            self._head_rate = math.nan if self.head is None else step_rate_hz(self.head, self.p.sample_rate)
        return self._head_rate

    def _hear_rate_over(self, end: int, n: int) -> None:
        """:meth:`_hear_rate` over the stream's last ``n`` samples up to sample ``end`` (where they are kept)."""
        if not self.predicts:
            return
        x = None if self.samples is None else self.samples(end + 1 - n, end + 1)
        if x is None:
            self._hear_rate(math.nan, end)
            return
        from .stepclock import step_rate_hz

        self._hear_rate(step_rate_hz(x, self.p.sample_rate), end)

    def _hear_rate(self, rate: float, end: int) -> None:
        """The template was learned (at ``end``) from stepping heard at ``rate``, Hz: which signatures to fit.

        Where the rate is within :data:`~stickslip.audio.rate_signature.RATE_WINDOW` of the
        tuning's and differs from it by more than
        :data:`~stickslip.audio.rate_signature.RATE_MIN_CHANGE`, each frame is fitted on
        the tuned signature and on the one predicted at ``rate``
        (:class:`~stickslip.audio.rate_signature.SignaturePredictor`), and the larger
        stop-likeness is taken with its residual; otherwise (no rate heard, the tuning's
        rate, a rate far off: a multiple heard) on the tuned one alone, as before. The
        drops' check also passes a frame the predicted fit hears as the stop with its
        residual within :data:`PRED_DROPS_RHO` of ``residual_max`` whose predicted drops
        show in proportion (round 12b); the release's projection and the start-at-the-stop
        judgement keep the tuned signature.
        """
        p = self.p
        self._fit_rate = None
        self._pred_delta = None
        self._neg_tail_p = (np.zeros(0), np.zeros(0))
        used = False
        r0 = p.step_rate_hz
        if r0 is not None and math.isfinite(rate) and RATE_MIN_CHANGE < abs(rate / r0 - 1.0) <= RATE_WINDOW:
            pred = self.predictor().predict(rate)
            if float(np.sqrt(np.mean((pred / self.sigma) ** 2))) >= MIN_SIGNATURE_RMS:
                self._fit_rate = _Fitter(pred, self.sigma, p.trim)
                self._pred_delta = pred
                used = True
        self._mask()
        self.rate_log.append((int(end), float(rate), used))

    def predictor(self) -> SignaturePredictor:
        """The tuning's signature predictor (built at the first rate that needs it); needs :attr:`predicts`."""
        if self._predictor is None:
            p = self.p
            assert (
                p.step_rate_hz is not None
                and p.fine_start_hz is not None
                and p.fine_bin_hz is not None
                and p.fine_stepping_db is not None
                and p.fine_stopped_db is not None
            )
            self._predictor = SignaturePredictor(
                p.sample_rate,
                p.frame,
                p.edges_hz,
                self.delta,
                p.step_rate_hz,
                p.fine_start_hz,
                p.fine_bin_hz,
                p.fine_stepping_db,
                p.fine_stopped_db,
            )
        return self._predictor

    @property
    def head_samples(self) -> int:
        """How many samples from the stream start the warm-up's frames span (what :attr:`head` must hold)."""
        return (self.p.warmup_chunks * CHUNK - 1) * self.p.hop + self.p.frame

    def _started_at_stop(self, end: int) -> None:
        """Was the stop there from the start? Compare the learned template with the tuning's stepping.

        Two views, either enough:

        * *levels*: the first frames' template ``T`` minus the tuning's stepping levels is
          fitted as a gain offset (the same in every sub-band) plus ``b`` times the stop's
          signature; ``b`` at or above the threshold, the stop explaining three quarters of
          what a gain change leaves, and a small residual: the stop. Good only at the
          tuning's step rate: at another rate the lines of the click train fall elsewhere on
          narrow modes, and the levels move by several spreads per sub-band.
        * *continuum* (tunings that recorded their step rate): the same fit on the power
          between the step clock's lines (:func:`continuum_levels_db`, the stream's rate
          heard in :attr:`head` by :func:`~stickslip.audio.stepclock.step_rate_hz`), which
          the rate does not move: ``b`` at least :data:`START_MIN_B` (and the threshold) and
          at most :data:`START_MAX_RATIO` of the gain-only residual left.

        Nor is the continuum alone where the levels give the stop less than
        :data:`START_CONTINUUM_LEVELS_B` of its signature (:meth:`_levels_deny_stop`): the
        continuum between the lines is the slips' jitter and scatter, which can change from
        day to day; under a strictly periodic drive tone less jitter lowers the continuum
        where the slips dominate, the shape a stop that silences the slips has.

        Where the tuning holds the continuum, the levels alone are not enough (round 10a): the
        continuum's fit must give the stop at least :data:`START_LEVELS_CONTINUUM_B` of its
        signature too. A reverberant room's tail, or a step rate a few per cent off the
        tuning's, colours the stepping's levels the way a damped or shifted stop does (the
        fifth generator's strongest room: the levels' ``b`` 0.95-2.1 on stepping 1.9-2.3 s
        before the stop, the continuum's -0.1-0.02, or a continuum signature that is a gain
        change only, which cannot tell).

        The stop: the detector fires at once (onset: the start of listening) and takes
        ``T - b * delta`` (``b`` of the levels, at least 1) as the stepping template. A
        signature that is a gain change only (a uniformly quieter stop) cannot be told from
        a gain change this way and is taken as stepping.
        """
        p = self.p
        if self.template is None or float(np.min(self.template)) <= -150.0:
            return
        b_lev = self._start_by_levels()
        b_con = self._start_by_continuum()
        if b_con is None:
            return  # the continuum contradicts the levels, or neither shows the stop
        if b_lev is None and not b_con:
            return
        if b_lev is None and self._levels_deny_stop():
            return  # the lines say stepping: the continuum moved with the slips' jitter, not a stop
        shift = 1.0 if b_lev is None else b_lev
        self.template = self.template - shift * self.delta
        self._set_floor(reset=True)
        self._latch()
        self._pending.append(Decision(int(end), self.t0 + p.onset_lag_s, float(shift)))  # onset: the start

    def _stale_check(self, end: int) -> None:
        """Did the continuum change at the latest fire? If not, the template was stale: learn it anew, un-latch.

        A click train's lines move across narrow modes as the step rate moves, and the
        sub-band levels with them, faster than the template follows (a rate drifting 10 %
        over 2 s): the levels depart from the template while the sound's continuum between
        the lines (:func:`continuum_levels_db`), which the rate does not move, stays as it
        was. A stop changes it, in level (a quieter stop) or shape. :data:`STALE_AFTER_S`
        after the fire, the continuum since the fire is compared with the stepping's before
        it (:data:`STALE_REF_S` ending :data:`STALE_GAP_S` before the fire), each at the
        step rate heard in it. The fire was a stale template where the rate moved by
        :data:`STALE_MIN_RATE_CHANGE` or more, the level by less than
        :data:`STALE_MAX_GAIN_DB` and the shape by less than :data:`STALE_MAX_SHAPE` (the
        RMS over sub-bands of what is left after the level, in the tuning's continuum
        spreads), and the stepping before it did not already sound like the stop
        (:data:`STALE_REF_MAX_B`). The template is then the low quantile of the levels of
        the last :data:`STALE_RELEARN_S` (of the frames before the fire where that no longer
        sounds like stepping), the detector listens again (a confirming detector sees the
        stop-likeness gone, and drops the fire), and a fire in the next
        :data:`STALE_UNCERTAIN_S` is flagged uncertain. No verdict (the fire stands) when the
        detector is no longer latched, the samples are gone, no rate is heard, or fewer than
        three sub-bands can be judged.
        """
        assert self._check is not None
        at, fire_end = self._check
        self._check = None
        p = self.p
        if not self.latched or self.samples is None or self.template is None:
            return
        sr = p.sample_rate
        gap, span = int(STALE_GAP_S * sr), int(STALE_REF_S * sr)
        # a fire soon after the stream began has less stepping before it: what there is, if at least half the span
        start = max(fire_end - gap - span, 0)
        ref = self.samples(start, fire_end - gap) if fire_end - gap - start >= span // 2 else None
        after = self.samples(fire_end, fire_end + int(STALE_AFTER_S * sr))
        if ref is None or after is None:
            return
        from .stepclock import step_rate_hz

        frame = CONTINUUM_FRAME * p.frame
        if min(ref.size, after.size) < frame + p.frame:
            return
        rates = [step_rate_hz(seg, sr) for seg in (ref, after)]
        if not all(math.isfinite(r) for r in rates):
            return
        if abs(rates[1] / rates[0] - 1.0) > STALE_MAX_RATE_JUMP:
            # no drift moves the rate that far in a few tenths of a second: one estimate took a multiple of the rate
            # (or a fraction); the rate heard over both spans decides, each estimate held near it
            both = step_rate_hz(np.concatenate((ref, after)), sr)
            if not math.isfinite(both):
                return
            lo, hi = (1.0 - STALE_MAX_RATE_JUMP) * both, (1.0 + STALE_MAX_RATE_JUMP) * both
            rates = [step_rate_hz(seg, sr, lo, hi) for seg in (ref, after)]
            if not all(math.isfinite(r) for r in rates):
                return
        levels = [
            np.percentile(continuum_levels_db(seg, sr, frame, p.frame, p.edges_hz, r), 100 * QUANTILE, axis=0)
            for seg, r in zip((ref, after), rates, strict=True)
        ]
        moved = abs(rates[1] / rates[0] - 1.0)
        spread = np.asarray(p.continuum_spread_db, dtype=np.float64)
        y = levels[1] - levels[0]
        ok = np.isfinite(y) & np.isfinite(spread) & np.isfinite(np.asarray(p.continuum_signature_db, dtype=np.float64))
        if ok.sum() < 3:
            return
        w = 1.0 / spread[ok] ** 2
        gain = float(np.sum(w * y[ok]) / np.sum(w))
        shape = float(np.sqrt(np.mean(((y[ok] - gain) / spread[ok]) ** 2)))
        stale = moved >= STALE_MIN_RATE_CHANGE and abs(gain) < STALE_MAX_GAIN_DB and shape < STALE_MAX_SHAPE
        if stale and p.continuum_levels_db is not None:
            # a fire late into a stop compares the stop with itself: was the reference already the stop?
            ref_level = np.asarray(p.continuum_levels_db, dtype=np.float64)
            sig = np.asarray(p.continuum_signature_db, dtype=np.float64)
            ok2 = ok & np.isfinite(ref_level)
            fit = (
                self._gain_and_signature(levels[0][ok2] - ref_level[ok2], sig[ok2], spread[ok2])
                if ok2.sum() >= 3
                else None
            )
            stale = fit is None or fit[0] < STALE_REF_MAX_B
        self.stale_log.append((fire_end, moved, gain, shape, stale))
        if not stale:
            return
        # learn the template anew from the end of the span, if its continuum is still the stepping's: a stop that began
        # inside the span changed it there (then the frames before the fire, stale as they are, and the next fire,
        # at once, is flagged: when the stop began inside the span is not known)
        n_late = max(1, int(STALE_RELEARN_S * sr / p.hop))
        late = self.samples(end + p.frame - int(STALE_RELEARN_S * sr), end + 1)
        lo = at - n_late
        if late is not None and late.size >= frame + p.frame:
            rate = step_rate_hz(
                late, sr, (1.0 - STALE_MAX_RATE_JUMP) * rates[1], (1.0 + STALE_MAX_RATE_JUMP) * rates[1]
            )
            if math.isfinite(rate):
                C = continuum_levels_db(late, sr, frame, p.frame, p.edges_hz, rate)
                z = (np.percentile(C, 100 * QUANTILE, axis=0) - levels[0])[ok]
                g2 = float(np.sum(w * z) / np.sum(w))
                if not (
                    abs(g2) < STALE_MAX_GAIN_DB
                    and float(np.sqrt(np.mean(((z - g2) / spread[ok]) ** 2))) < STALE_MAX_SHAPE
                ):
                    lo = at - self._after_frames - CHUNK  # the stop began inside the span: the frames before the fire
        hi = lo + (n_late if lo >= at - n_late else CHUNK)
        since = [lv[max(lo - f0, 0) : max(hi - f0, 0)] for f0, lv in self._recent_v]
        since = [lv for lv in since if lv.shape[0]]
        if not since:
            return
        self.template = np.percentile(np.concatenate(since), 100 * QUANTILE, axis=0)
        # a fire soon after may be a stop that began inside the span, or at its end (a few tens of ms of it hardly move
        # the end's continuum, but enter the template learned from it and delay the crossing): its onset is uncertain
        self._uncertain_until = end + int(STALE_UNCERTAIN_S * sr)
        self._set_floor(reset=True)
        self.unlatch()
        self.prev_a = -math.inf
        self._acc_list, self._acc_n = [], 0
        self._drop.reset()
        self._neg_tail = (np.zeros(0), np.zeros(0))
        self.arm_sample = end + int(DROP_ARM_S * sr)
        self._hear_rate_over(end, int(STALE_RELEARN_S * sr) + p.frame)

    @staticmethod
    def _gain_and_signature(
        y: FloatArray, delta: FloatArray, sigma: FloatArray
    ) -> tuple[float, float, float, float] | None:
        """Fit ``y = c + b * delta`` weighted by ``1/sigma**2``: ``b``, the residual's RMS (spreads) and the
        sums of squares left by the fit and by a gain alone; None where the signature is (nearly) a gain change."""
        w = 1.0 / sigma**2
        X = np.stack((np.ones_like(delta), delta), axis=1)
        A = X.T @ (X * w[:, None])
        if np.linalg.cond(A) > 1e6:
            return None
        shape = delta - float(np.sum(w * delta) / np.sum(w))
        if float(np.sqrt(np.mean((shape / sigma) ** 2))) < 1.0:
            return None  # the stop is (nearly) a gain change: undecidable from levels alone
        c, b = np.linalg.solve(A, X.T @ (w * y))
        r_gain = (y - float(np.sum(w * y) / np.sum(w))) / sigma
        r_both = (y - X @ np.array([c, b])) / sigma
        ss_both = float(np.sum(r_both**2))
        return float(b), float(np.sqrt(np.mean(r_both**2))), ss_both, float(np.sum(r_gain**2))

    def _levels_fit(self) -> tuple[float, float, float, float] | None:
        """The first frames' levels less the tuning's stepping, fitted as a gain plus ``b`` times the signature
        (:meth:`_gain_and_signature`); None where the tuning has no stepping levels or the signature is a gain."""
        p = self.p
        if p.stepping_levels_db is None or self.template is None:
            return None
        return self._gain_and_signature(self.template - np.asarray(p.stepping_levels_db), self.delta, self.sigma)

    def _start_by_levels(self) -> float | None:
        """``b`` when the levels show the stop clearly from the start (see :meth:`_started_at_stop`), else None."""
        fit = self._levels_fit()
        if fit is None:
            return None
        b, rms_both, ss_both, ss_gain = fit
        # demand a clear case: the stop explains most of what a gain change leaves, and fits well
        clear = ss_both <= 0.25 * ss_gain
        fits = rms_both <= 2.0 + RESIDUAL_SLOPE * b * float(np.sqrt(np.mean((self.delta / self.sigma) ** 2)))
        return b if b >= max(self.p.threshold, 0.6) and clear and fits else None

    def _levels_deny_stop(self) -> bool:
        """Do the first frames' levels give the stop less than :data:`START_CONTINUUM_LEVELS_B` of its signature?

        The same fit as :meth:`_start_by_levels` (:meth:`_levels_fit`), without its demands on
        the fit's quality (at another step rate the levels move by several spreads). False
        where the signature is (nearly) a gain change: the levels cannot tell.
        """
        fit = self._levels_fit()
        return fit is not None and fit[0] < START_CONTINUUM_LEVELS_B

    def _start_by_continuum(self) -> bool | None:
        """The continuum's verdict on the start (see :meth:`_started_at_stop`).

        True: it shows the stop by itself. False: not by itself, but the levels' verdict may
        stand (the tuning holds no continuum; or the continuum gives the stop at least
        :data:`START_LEVELS_CONTINUUM_B` of its signature). None: the levels' verdict may not
        stand either (the continuum gives the stop less, cannot be measured, or cannot tell
        the stop from a gain change).
        """
        p = self.p
        head = self.head
        if (
            p.step_rate_hz is None
            or p.continuum_levels_db is None
            or p.continuum_signature_db is None
            or p.continuum_spread_db is None
        ):
            return False  # an older tuning: the levels judge alone, as before
        if head is None:
            return None
        rate = self._heard_head_rate()
        if not math.isfinite(rate):
            return None
        C = continuum_levels_db(head, p.sample_rate, CONTINUUM_FRAME * p.frame, p.frame, p.edges_hz, rate)
        ok = np.isfinite(C).all(axis=0) if C.shape[0] else np.zeros(C.shape[1], dtype=bool)
        ref = np.asarray(p.continuum_levels_db, dtype=np.float64)
        sig = np.asarray(p.continuum_signature_db, dtype=np.float64)
        spread = np.asarray(p.continuum_spread_db, dtype=np.float64)
        ok &= np.isfinite(ref) & np.isfinite(sig) & np.isfinite(spread)
        if ok.sum() < 3:
            return None
        T = np.percentile(C[:, ok], 100 * QUANTILE, axis=0)
        fit = self._gain_and_signature(T - ref[ok], sig[ok], spread[ok])
        if fit is None:
            return None
        b, _, ss_both, ss_gain = fit
        if b >= max(p.threshold, START_MIN_B) and ss_both <= START_MAX_RATIO * ss_gain:
            return True
        return False if b >= START_LEVELS_CONTINUUM_B else None

    def _segment(self, v: FloatArray, ends: NDArray[np.int64]) -> list[Decision]:
        p = self.p
        if self.frame_no < p.warmup_chunks * CHUNK or self.template is None:
            self._warm.append(v.copy())
            if self.trace is not None:
                self.trace.extend([math.nan] * v.shape[0])
            if self.hot_trace is not None:
                self.hot_trace.extend([False] * v.shape[0])
            return []
        if self._checks:
            self._recent_v.append((self.frame_no, v))
            while self._recent_v and self._recent_v[0][0] + self._recent_v[0][1].shape[0] < (
                self.frame_no - self._after_frames - CHUNK
            ):
                self._recent_v.pop(0)
        d = v - self.template
        a, rho = self._fit_now(d)
        pred_drops: NDArray[np.bool_] | None = None
        if self._fit_rate_now is not None:
            # the signature predicted at the heard rate too: the larger stop-likeness, with its residual, where the
            # prediction explains the frame (its residual within residual_max); a frame it does not explain is no
            # evidence of the stop, and would hold up the stop-likeness a confirmation watches after a fire that the
            # tuned fit made (round 11a: a fifth-generator arm confirmed 41 ms early that way)
            a2, rho2 = self._fit_rate_now(d)
            use = (a2 > a) & (rho2 <= p.residual_max)
            a, rho = np.where(use, a2, a), np.where(use, rho2, rho)
            if PRED_DROPS_RHO is not None:
                # the predicted fit hears the stop and explains the frame well (whichever fit's a is the larger)
                pred_drops = (a2 >= p.threshold) & (rho2 <= PRED_DROPS_RHO * p.residual_max)
        hot = (a >= p.threshold) & (rho <= p.residual_max)
        lag = np.zeros(a.size)
        quiet = a < 0.3 * p.threshold
        # drops, in spreads, below the floor (the lowest recent template: see FLOOR_CHUNKS)
        floor = self.template if self.floor is None else self.floor
        zs = np.clip(v - floor, -_CLIP_DB, _CLIP_DB) * self._drop_scale
        m = self._drop(zs)
        # the sub-bands the stop lowers must be lower: no voice or second instrument can fake a drop
        # a drop deeper than NEG_CAP spreads counts as NEG_CAP: the room's own noise fills the deepest holes
        # (a fan 10 dB below the stepping caps a 20 dB drop at 10), so their depth is no evidence
        gn = np.maximum(np.minimum(self.delta, 0.0) * self._drop_scale, -NEG_CAP)
        gg_tuned = self._drop_info_tuned
        if gg_tuned >= NEG_INFORMATIVE**2:
            # per frame, judged on the sub-bands without an excess (a band something was added to cannot show
            # a drop): the drops shown, as a share of the signature's, averaged over NEG_FRAMES frames
            clear = zs <= NEG_EXCESS
            # the verdicts matter only where the fit is hot; elsewhere only the last frames are kept for the average
            if hot.any():
                shown, self._neg_tail = _drops_shown(zs, clear, gn, gg_tuned, a, self._neg_tail)
            else:
                shown, self._neg_tail = hot, _drops_tail(zs, clear, gn, self._neg_tail)
            if self._pred_delta is not None and PRED_DROPS_RHO is not None:
                # at another rate the sub-bands the tuned signature lowers may hold or rise (round 11b): a frame the
                # predicted fit took and explains well may show the predicted signature's drops instead (round 12b);
                # the tuned verdict stands everywhere else, so this check never withholds what it passed before
                gp = np.maximum(np.minimum(self._pred_delta, 0.0) * self._drop_scale, -NEG_CAP)
                ask = hot & ~shown & (False if pred_drops is None else pred_drops)
                if ask.any():
                    gpi = np.maximum(np.minimum(self._pred_delta, 0.0) * self._fit.inv_sigma, -NEG_CAP)
                    shown_p, self._neg_tail_p = _drops_shown(zs, clear, gp, float(gpi @ gpi), a, self._neg_tail_p)
                    shown = shown | (ask & shown_p)
                else:
                    self._neg_tail_p = _drops_tail(zs, clear, gp, self._neg_tail_p)
            hot &= shown
        if p.drop_threshold is not None:
            # a lasting drop below the template, in any sub-bands: a stop unlike the tuned one; armed
            # once the template has followed the stream for DROP_ARM_S (the warm-up's is rough)
            b = np.zeros(a.size)
            # either statistic reaches its threshold only where some sub-band dropped that far
            near = (m.min(axis=1) <= -min(p.drop_threshold)) & ((ends - self.arm_sample) >= 0)
            if near.any():
                broad, local = DropMeter.drops(m[near])
                b[near] = np.maximum(broad / p.drop_threshold[0], local / p.drop_threshold[1])
            by_drop = (b >= 1.0) & ~hot
            a = np.where(by_drop, p.threshold * b, a)
            lag = np.where(by_drop, DROP_LAG_FRAMES * p.hop / p.sample_rate, 0.0)
            hot |= by_drop
        self.last_a, self.last_rho = float(a[-1]), float(rho[-1])
        if self.trace is not None:
            self.trace.extend(a.tolist())
        if self.hot_trace is not None:
            self.hot_trace.extend(hot.tolist())
        # the template follows every frame that is not stop-like (the low quantile taken per chunk
        # ignores knocks and voices); a chunk that fits neither stepping nor the stop at all means
        # the template is stale (listening began in silence, the microphone moved): learn it anew
        if quiet.any():
            self._acc_list.append(d[quiet])
            self._acc_n += int(quiet.sum())
        self._chunk_rho.append(rho)
        self._chunk_v.append(v)
        if not self.latched and self.mask == 0 and not hot.any():
            self.prev_a = float(a[-1])
            return []
        return self._decide(a, hot, ends, lag, d, v)

    def _stepping_again(self, d: FloatArray) -> bool:
        """Whether a latched frame (its departure ``d`` from the frozen template, dB) sounds like stepping again.

        Judged against the stop's *own* sound, the median of the first :data:`STOP_ROWS`
        frames after the fire, not against the threshold: after a stop the joint may step
        at another rate or the other way, which the frozen template does not know (4 % of
        rate shows as drops and rises of a few spreads), while the stop's departure is the
        change that fired. The frame's departure, projected on the stop's (weighted by the
        stepping's spreads), must be under :data:`RELEASE_C` of it, and the frame not
        :data:`RELEASE_SILENT_DB` under the template (silence after the stop is no stepping).
        """
        if self._stop_e is None:
            self._stop_rows.append(d)
            if len(self._stop_rows) < STOP_ROWS:
                return False
            e = np.median(np.stack(self._stop_rows), axis=0)
            self._stop_rows = []
            w = self._fit.inv_sigma**2
            if float((e * w) @ e) < 1.0:  # the stop departed by less than a spread in all: judge by the tuned signature
                e = self.delta
            # weighted, and scaled so that the projection of the stop's own departure is 1
            self._stop_e = e * w / max(float((e * w) @ e), 1e-12)
        return float(d @ self._stop_e) < RELEASE_C and float(np.median(d)) > -RELEASE_SILENT_DB

    def _decide(
        self,
        a: FloatArray,
        hot: NDArray[np.bool_],
        ends: NDArray[np.int64],
        lag: FloatArray,
        d: FloatArray,
        v: FloatArray,
    ) -> list[Decision]:
        p = self.p
        sr, H = p.sample_rate, p.hop
        full = (1 << (p.hold_frames + p.max_dips)) - 1
        window_n = p.hold_frames + p.max_dips
        out: list[Decision] = []
        rel = p.threshold - p.hysteresis
        prev = self.prev_a
        fired_here = False
        for k, (ai, hi, end, li) in enumerate(zip(a.tolist(), hot.tolist(), ends.tolist(), lag.tolist(), strict=True)):
            if self.latched:
                # the quiet release: a stayed below the re-arm level for release_s; the template then goes on
                # following (what a confirming wrapper relies on while it judges a fire on interference)
                if ai < rel:
                    self.below += 1
                    if self.below >= p.release_frames:
                        self.unlatch()
                else:
                    self.below = 0
                if fired_here and self.latched:  # a frame after a fire in this piece (a piece that began latched
                    # was scanned by process): it cannot end the stop, the window is longer than a piece, but counts
                    self._latch_frame(d[k], v[k])
            else:
                if hi and (
                    self.mask == 0 or (not self.mask & 1 and self.mask.bit_count() < max(1, p.hold_frames // 2))
                ):
                    # the latest upward crossing that starts a run (a lone earlier hot frame is forgotten)
                    t_end = self.t0 + end / sr
                    if math.isfinite(prev) and prev < p.threshold and ai > prev:
                        frac = (p.threshold - prev) / (ai - prev)
                        self.cross_t = float(t_end - (1 - frac) * H / sr) - li
                    else:
                        self.cross_t = t_end - li
                self.mask = ((self.mask << 1) | int(hi)) & full
                self.recent = (self.recent + [ai])[-window_n:]
                if hi and self.mask.bit_count() >= p.hold_frames and ai >= p.decay_ratio * max(self.recent):
                    self._latch()
                    fired_here = True
                    out.append(Decision(int(end), self.cross_t, float(ai), uncertain=end < self._uncertain_until))
                    if self._checks and self.samples is not None:
                        self._check = (self.frame_no + k + 1 + self._after_frames, int(end))
                if self.mask == 0:
                    self.recent = []
            prev = ai
        self.prev_a = prev
        return out
