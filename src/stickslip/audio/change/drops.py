"""Drops below the stepping's floor: the evidence no added sound can fake.

Interference only adds sound (a voice, a knock, a second instrument, a radio), so a
sub-band that is *lower* than the stepping's floor (:mod:`.template`) is evidence only a
change of the joint's own sound gives. Two rules read it, per frame (:class:`DropCheck`):

* **the drops in proportion**: a frame the fit calls the stop (hot) counts only if, averaged
  over ``judge_frames`` frames, it also shows its share of the drops the stop's signature
  has (each capped at ``cap`` spreads), at least ``ratio`` of its stop-likeness ``a`` (and
  ``min_share``, less ``se_slack`` standard errors), on the sub-bands nothing was added to.
  A voice over the sub-bands the stop lifts keeps ``a`` up but shows no drops. Judged only
  where the signature's drops are informative (``informative`` spreads, RMS-summed). At
  another step rate the sub-bands the tuned signature lowers may hold: a frame the signature
  predicted at the heard rate explains well (residual within ``pred_drops_rho`` of
  ``residual_max``) may show the predicted signature's drops instead. Where the rate was
  heard near the commanded one (told: the controller's clock, not a guess) and the predicted
  signature lowers nothing worth checking (its drops under ``informative``), the stop at
  this rate cannot show drops at all: such a frame is *unasked* (``pred_unasked``), not
  hot; the hold may fire on it, and the confirmation, which counts only hot frames, asks
  the joint's lines to affirm the stop (:mod:`stickslip.audio.confirm.clocked`).
* **the drop channel** (tunings with ``drop_threshold``): a lasting drop below the floor in
  any sub-bands, averaged over ``frames`` frames (:class:`DropMeter`: *broad*, the median
  sub-band; *local*, the RMS of the drops) counts as a stop whatever the signature: a
  quieter, a duller or a spectral stop the tuning never saw is heard. Armed ``arm_s`` after
  the template was learned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..paramfield import param
from .fit import FIT, FitParams
from .tuned import TunedTemplate

__all__ = ["DROPS", "DropCheck", "DropMeter", "DropParams", "drops_shown", "drops_tail", "window_sums"]

FloatArray = NDArray[np.float64]
Tail = tuple[FloatArray, FloatArray]


@dataclass(frozen=True)
class DropParams:
    """The drops' two rules: the drops in proportion, and the drop channel."""

    frames: int = param(8, "frames", "the drop channel averages this many frames (21 ms at 48 kHz, as the hold)")
    arm_s: float = param(0.35, "s", "the drop channel is armed this long after the template was learned")
    informative: float = param(
        2.0, "spreads", "a signature whose drops add up to this (RMS-summed) is checked for them"
    )
    min_share: float = param(0.15, "", "a hot frame must show at least this share of the signature's drops ...")
    ratio: float = param(
        0.45, "of a", "... and this share of its stop-likeness (a capped at 1): rises and drops come together"
    )
    cap: float = param(3.0, "spreads", "a sub-band's expected drop is capped here: a noise floor fills deeper holes")
    se_slack: float = param(
        0.5, "standard errors", "the share asked is lowered by this many of its standard errors (weak signatures)"
    )
    judge_frames: int = param(4, "frames", "the drops shown are averaged over this many frames: no delay to the stop")
    excess: float = param(
        2.0, "spreads", "a sub-band this far over the floor has sound added: it cannot show a drop, and is not asked"
    )
    pred_drops_rho: float | None = param(
        0.5,
        "residual_max",
        "a frame the predicted signature explains within this may show its drops instead (None: tuned only)",
    )
    pred_unasked: bool = param(
        True,
        "",
        "at a rate told, where that signature has no drops worth checking, such a frame may fire, not hot: lines judge",
    )

    @property
    def lag_frames(self) -> float:
        """The drop channel's average delays a drop by this many frames: given back to its onset."""
        return (self.frames - 1) / 2


DROPS = DropParams()


def window_sums(x: FloatArray, n: int, w: int) -> FloatArray:
    """The sums over the ``w`` rows of ``x`` that end each of its last ``n`` rows (fewer at its start).

    Each sum is added row by row, oldest first, so a frame's average is the same floating-point
    number whatever pieces the stream came in (a running cumulative sum is rounded from the
    piece's start: its averages differed in the last bit between block sizes).
    """
    pad = max(w - 1 - (x.shape[0] - n), 0)
    if pad:
        x = np.concatenate((np.zeros((pad, *x.shape[1:])), x))
    m = x.shape[0]
    s = x[m - n - (w - 1) : m - (w - 1)].copy()
    for o in range(w - 2, -1, -1):
        s += x[m - n - o : m - o]
    return s


class DropMeter:
    """How far the sound has dropped below the floor, averaged over the last ``frames`` frames (spreads).

    From the departures ``z_b`` (spreads) averaged over the frames, ``m_b``, two statistics
    (spreads, >= 0): *broad*, ``-median_b m_b`` (the bulk of the sub-bands dropped together:
    a quieter stop); *local*, ``sqrt(mean_b min(m_b, 0)**2)`` (a few sub-bands dropped far: a
    duller or a spectral stop). The average costs ``(frames - 1) / 2`` hops of latency,
    which :attr:`DropParams.lag_frames` gives back to the onset.
    """

    def __init__(self, n_bands: int, frames: int | None = None) -> None:
        self.nb = int(n_bands)
        self.frames = int(frames or DROPS.frames)
        self.reset()

    def reset(self) -> None:
        """Forget the frames averaged so far."""
        self._tail = np.zeros((0, self.nb))

    def __call__(self, z: FloatArray) -> FloatArray:
        """The departures ``z`` (frames x bands, spreads) averaged over the last ``frames`` frames."""
        w = self.frames
        zz = np.concatenate((self._tail, z)) if self._tail.size else z
        n = z.shape[0]
        count = np.minimum(np.arange(zz.shape[0] - n, zz.shape[0]) + 1, w)  # the frames averaged (fewer at first)
        out = window_sums(zz, n, w) / count[:, None]
        self._tail = zz[max(len(zz) - (w - 1), 0) :].copy()
        return np.asarray(out, dtype=np.float64)

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


def _terms(zs: FloatArray, clear: NDArray[np.bool_], gn: FloatArray, gg: float, tail: Tail, p: DropParams) -> Tail:
    """The drops' check's per-frame terms after ``tail``: (drops shown, information left), as shares of ``gg``.

    Row by row (einsum), not a matrix product, whose rounding depends on the rows beside each."""
    num = np.concatenate((tail[0], np.einsum("ij,j->i", np.maximum(zs, -p.cap) * clear, gn) / gg))
    den = np.concatenate((tail[1], np.einsum("ij,j->i", clear, gn * gn) / gg))
    return num, den


def drops_tail(zs: FloatArray, clear: NDArray[np.bool_], gn: FloatArray, tail: Tail, p: DropParams = DROPS) -> Tail:
    """The tail :func:`drops_shown` would leave, without the verdicts (a piece where none can matter)."""
    k = p.judge_frames - 1
    gg = float(gn @ gn)
    if gg <= 0.0:
        return tail
    num, den = _terms(zs[-k:], clear[-k:], gn, gg, tail, p)
    keep = max(num.size - k, 0)
    return num[keep:], den[keep:]


def drops_shown(
    zs: FloatArray,
    clear: NDArray[np.bool_],
    gn: FloatArray,
    info_sig: float,
    a: FloatArray,
    tail: Tail,
    p: DropParams = DROPS,
) -> tuple[NDArray[np.bool_], Tail]:
    """Per frame: whether the drops of signature ``gn`` (spreads, each capped at ``cap``) show in proportion.

    ``zs`` are the frames' levels below the floor (spreads), ``clear`` the sub-bands without
    an excess, ``info_sig`` the signature's drop information in the tuning's spreads, ``a``
    the frames' stop-likeness and ``tail`` the last ``judge_frames - 1`` frames' (shown,
    information) terms. The drops shown, as a share of the signature's, averaged over
    ``judge_frames`` frames, must reach ``ratio`` of ``a`` (at least ``min_share``, less
    ``se_slack`` standard errors) on sub-bands holding at least ``informative`` spreads of
    drops. Returns the verdicts and the new tail.
    """
    gg = float(gn @ gn)
    if gg <= 0.0:
        return np.zeros(a.size, dtype=bool), tail
    num, den = _terms(zs, clear, gn, gg, tail, p)
    sn, sd = window_sums(num, a.size, p.judge_frames), window_sums(den, a.size, p.judge_frames)
    count = np.minimum(np.arange(num.size - a.size, num.size) + 1, p.judge_frames)
    info = sd / count  # share of the signature's drop information left
    shown_avg = sn / np.maximum(sd, 1e-12)
    judged = info * info_sig >= p.informative**2
    # the share shown is measured with noise: one spread per sub-band and frame gives a standard error of
    # 1 / sqrt(frames x drops' information); a weak drop signature is not held to the share it cannot show
    se = 1.0 / np.sqrt(np.maximum(sd * gg, 1e-12))
    need = np.maximum(p.min_share, p.ratio * np.clip(a, 0.0, 1.0) - p.se_slack * se)
    keep = max(num.size - (p.judge_frames - 1), 0)
    return judged & (shown_avg >= need), (num[keep:], den[keep:])


def _empty() -> Tail:
    return np.zeros(0), np.zeros(0)


class DropCheck:
    """The drops' two rules over a stream (see the module docstring)."""

    def __init__(self, tuned: TunedTemplate, p: DropParams = DROPS, fit: FitParams = FIT) -> None:
        self.tuned, self.p, self.clip_db = tuned, p, fit.clip_db
        self.delta = np.asarray(tuned.signature_db, dtype=np.float64)
        self.inv_sigma = 1.0 / np.asarray(tuned.spread_db, dtype=np.float64)
        # whether the stop's drops are worth checking is the tuning's to say (its spreads, each drop capped at
        # cap): a noisy warm-up (a voice while the template was learned) must not switch the check off
        gt = np.maximum(np.minimum(self.delta, 0.0) * self.inv_sigma, -p.cap)
        self.info_tuned = float(gt @ gt)
        self.meter = DropMeter(self.delta.size, p.frames)
        self._weights: list[tuple[FloatArray, FloatArray, FloatArray]] = []  # (signature, 1 / spread, drops' weights)
        self.reset()

    def reset(self) -> None:
        """A new stream: the tuning's spreads, not armed."""
        #: 1 / spread per sub-band, dB: the larger of the tuning's and (after the warm-up) this stream's spreads
        self.scale = self.inv_sigma
        #: the stream sample from which the drop channel is armed
        self.arm_sample = 0
        self._told = False  # the predicted signature's rate was heard near the commanded one
        self.restart()

    def restart(self, arm_at: int | None = None) -> None:
        """The template was learned anew: forget the averages (and arm the drop channel at ``arm_at``, if given)."""
        self.meter.reset()
        self._tail, self._tail_p = _empty(), _empty()
        if arm_at is not None:
            self.arm_sample = arm_at

    def arm(self, end: int) -> None:
        """Arm the drop channel ``arm_s`` after stream sample ``end``."""
        self.arm_sample = end + int(self.p.arm_s * self.tuned.sample_rate)

    def forget_predicted(self, told: bool = False) -> None:
        """The predicted signature changed: forget its average; ``told``: its rate was heard near the commanded one
        (only then are frames unasked)."""
        self._tail_p = _empty()
        self._told = told

    def learn_spread(self, warm: FloatArray) -> None:
        """After the warm-up: drops are judged in the larger of the tuning's and the warm-up's spreads."""
        sigma = np.asarray(self.tuned.spread_db, dtype=np.float64)
        live = 1.4826 * np.median(np.abs(warm - np.median(warm, axis=0)), axis=0)
        self.scale = 1.0 / np.maximum(sigma, live)

    def judge(
        self,
        v: FloatArray,
        floor: FloatArray,
        a: FloatArray,
        hot: NDArray[np.bool_],
        ends: NDArray[np.int64],
        pred_delta: FloatArray | None,
        pred_drops: NDArray[np.bool_] | None,
    ) -> tuple[FloatArray, NDArray[np.bool_], FloatArray, NDArray[np.bool_]]:
        """The frames ``v`` (levels, dB) with the fit's ``a`` and ``hot``: ``a``, ``hot`` and onset lags (s) after
        both rules, and the frames *unasked*: held back only by drops the signature predicted at the told rate has
        not (they may fire, but are not hot)."""
        zs = v - floor
        np.maximum(zs, -self.clip_db, out=zs)  # clipped to +-clip_db (np.clip's values, without its wrappers' cost)
        np.minimum(zs, self.clip_db, out=zs)
        zs *= self.scale
        m = self.meter(zs)
        unasked = np.zeros(a.size, dtype=bool)
        if self.info_tuned >= self.p.informative**2:
            shown, unasked = self._in_proportion(zs, a, hot, pred_delta, pred_drops)
            hot &= shown
        a, hot, lag = self._channel(m, a, hot, ends)
        return a, hot, lag, unasked & ~hot

    def _in_proportion(
        self,
        zs: FloatArray,
        a: FloatArray,
        hot: NDArray[np.bool_],
        pred_delta: FloatArray | None,
        pred_drops: NDArray[np.bool_] | None,
    ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """The first rule: per frame, whether the sub-bands the stop lowers are lower, in proportion; and the frames
        held back only by the tuned drops where the signature predicted at this rate has none worth checking."""
        p = self.p
        gn = self._drop_weights(self.delta, self.scale)
        clear = zs <= p.excess
        # the verdicts matter only where the fit is hot; elsewhere only the last frames are kept for the average
        if hot.any():
            shown, self._tail = drops_shown(zs, clear, gn, self.info_tuned, a, self._tail, p)
        else:
            shown, self._tail = hot, drops_tail(zs, clear, gn, self._tail, p)
        if pred_delta is not None and p.pred_drops_rho is not None:
            # at another rate the sub-bands the tuned signature lowers may hold or rise: a frame the predicted fit
            # took and explains well may show the predicted signature's drops instead; the tuned verdict stands
            # everywhere else, so this check never withholds what it passed before
            gp = self._drop_weights(pred_delta, self.scale)
            ask = hot & ~shown & (False if pred_drops is None else pred_drops)
            gpi = np.maximum(np.minimum(pred_delta, 0.0) * self.inv_sigma, -p.cap)
            info_p = float(gpi @ gpi)
            if ask.any() and p.pred_unasked and self._told and info_p < p.informative**2:
                # the stop at this rate lowers nothing worth checking: no drops can be asked of it (as of a tuning
                # whose stop lowers nothing), nor can the levels tell it from added sound: unasked, not hot
                self._tail_p = drops_tail(zs, clear, gp, self._tail_p, p)
                return shown, ask
            if ask.any():
                shown_p, self._tail_p = drops_shown(zs, clear, gp, info_p, a, self._tail_p, p)
                shown = shown | (ask & shown_p)
            else:
                self._tail_p = drops_tail(zs, clear, gp, self._tail_p, p)
        return shown, np.zeros(a.size, dtype=bool)

    def _drop_weights(self, delta: FloatArray, scale: FloatArray) -> FloatArray:
        """A signature's drops in spreads (``scale``: 1 / spread), each capped at ``cap``.

        The signatures and the spreads are new arrays when they change (the template
        learned, the rate heard), never changed in place: the weights of the last two
        (the tuned and the predicted signature) are kept, not made anew per block.
        """
        for d, sc, w in self._weights:
            if d is delta and sc is scale:
                return w
        w = np.maximum(np.minimum(delta, 0.0) * scale, -self.p.cap)
        self._weights = [*self._weights[-1:], (delta, scale, w)]
        return w

    def _channel(
        self, m: FloatArray, a: FloatArray, hot: NDArray[np.bool_], ends: NDArray[np.int64]
    ) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
        """The second rule: a lasting drop in any sub-bands, once armed (tunings with a ``drop_threshold``)."""
        tu = self.tuned
        lag = np.zeros(a.size)
        if tu.drop_threshold is None:
            return a, hot, lag
        # either statistic reaches its threshold only where some sub-band dropped that far
        near = (m.min(axis=1) <= -min(tu.drop_threshold)) & ((ends - self.arm_sample) >= 0)
        if not near.any():  # no frame near: nothing changes
            return a, hot, lag
        b = np.zeros(a.size)
        broad, local = DropMeter.drops(m[near])
        b[near] = np.maximum(broad / tu.drop_threshold[0], local / tu.drop_threshold[1])
        by_drop = (b >= 1.0) & ~hot
        a = np.where(by_drop, tu.threshold * b, a)
        lag = np.where(by_drop, self.p.lag_frames * tu.hop / tu.sample_rate, 0.0)
        hot |= by_drop
        return a, hot, lag
