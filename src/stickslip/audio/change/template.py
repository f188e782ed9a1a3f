"""The running template of the stepping sound, and its floor: what a frame's departure is measured from.

While a joint steps, its sound has a steady spectral signature: per frame, the level of
each sub-band, ``v_b`` in dB. :class:`RunningTemplate` keeps a template ``T_b`` of it: the
low quantile of the first frames (the warm-up), then every :attr:`TemplateParams.chunk`
frames an exponential average towards the low quantile of the frames that were not
stop-like (time constant ``tau_s`` of the tuning), frozen while the sound departs from it.
Interference only adds sound, so a low quantile follows the stepping under intermittent
speech, knocks or a second instrument. A chunk whose median residual says the frames fit
neither stepping nor the stop (listening began in silence, the microphone moved) learns the
template anew from that chunk's levels.

The *floor* is per sub-band the lowest template of the last ``floor_chunks`` updates: the
drops a stop shows are measured from it (:mod:`.drops`). Where the template stands
``mask_added`` spreads over the floor in some sub-bands and fell that far in none, sound was
*added* to the stepping there (:attr:`RunningTemplate.added_db`): the stop's signature is
then fitted as it can show over it (:func:`~.fit.masked_signature`). A step rate that
drifts moves the lines of the stepping's own sound off some modes and onto others: it
lifts some sub-bands and lowers others, and is not taken for added sound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..paramfield import param

__all__ = ["TEMPLATE", "RunningTemplate", "TemplateParams"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TemplateParams:
    """How the stepping template is learned, followed, and its floor kept."""

    chunk: int = param(
        64, "frames", "the template is updated every this many frames (and learned over whole chunks at first)"
    )
    quantile: float = param(
        0.3, "", "the template is this quantile of the levels: interference only adds sound, a low one ignores it"
    )
    quiet: float = param(
        0.3, "thresholds", "frames whose stop-likeness is under this are stepping: the template follows them"
    )
    stale_residual: float = param(
        2.0, "residual_max", "a chunk whose median residual exceeds this fits nothing: the template is learned anew"
    )
    stale_all_up_db: float = param(
        3.0, "dB", "a template learned anew this much louder in every sub-band is a new level: the floor restarts"
    )
    floor_chunks: int = param(
        8, "chunks", "the floor is the lowest template of this many updates (1.4 s at 48 kHz): a voice lifts it not"
    )
    alone_reached_db: float = param(
        1.0, "dB", "the joint's own level under sound added from the start is dropped once the template is this near it"
    )
    mask_added: float | None = param(
        2.0,
        "spreads",
        "a template this far over the floor (none as far under) holds added sound: the signature is masked there",
    )


TEMPLATE = TemplateParams()


class RunningTemplate:
    """The stepping template ``T_b`` and its floor (see the module docstring).

    Parameters
    ----------
    tau_s : float
        The tuning's time constant of the exponential average, s.
    hop : int
        The detector's hop, samples.
    sample_rate : int
        Samples per second, Hz.
    p : TemplateParams
    """

    def __init__(self, tau_s: float, hop: int, sample_rate: int, p: TemplateParams = TEMPLATE) -> None:
        self.p = p
        self.tau_s, self.hop, self.sample_rate = tau_s, hop, sample_rate
        self.reset()

    def reset(self) -> None:
        """Forget the template, the floor and everything gathered."""
        #: the template, dB per sub-band (None until the first chunk is heard)
        self.template: FloatArray | None = None
        self._warm: list[FloatArray] = []
        self._acc_list: list[FloatArray] = []
        self._acc_n = 0
        self._chunk_rho: list[FloatArray] = []
        self._chunk_v: list[FloatArray] = []
        self._floors: list[FloatArray] = []
        #: the floor, dB per sub-band (None until the template is learned)
        self.floor: FloatArray | None = None
        #: the sound added per sub-band to the latest template, dB over the floor (None: nothing added)
        self.added_db: FloatArray | None = None
        #: the stream samples (ends of the chunk) at which a template that fitted nothing was learned anew
        self.relearned: list[int] = []
        #: the joint's own level under the first template where sound was added from the start, dB per sub-band
        #: (:mod:`.added`): a lower bound of the floor until the template comes down to it (None: none)
        self.joint_alone: FloatArray | None = None

    # --- the warm-up ----------------------------------------------------------------------------
    def warm(self, v: FloatArray) -> None:
        """Keep the levels ``v`` (frames x bands) of warm-up frames."""
        self._warm.append(v.copy())

    def learn_warm(self) -> FloatArray:
        """The template from the warm-up's frames so far; returns their levels (frames x bands)."""
        warm = np.concatenate(self._warm)
        self.template = np.percentile(warm, 100 * self.p.quantile, axis=0)
        return warm

    def end_warm(self) -> None:
        """The warm-up is over: its frames are no longer kept."""
        self._warm = []

    # --- following the stepping -----------------------------------------------------------------
    def gather(self, d: FloatArray, quiet: NDArray[np.bool_], rho: FloatArray, v: FloatArray) -> None:
        """Keep a piece's departures of the frames that were not stop-like (``quiet``), its residuals and levels."""
        if quiet.any():
            self._acc_list.append(d[quiet])
            self._acc_n += int(quiet.sum())
        self._chunk_rho.append(rho)
        self._chunk_v.append(v)

    def relearn_if_stale(self, latched: bool, residual_max: float) -> FloatArray | None:
        """At a chunk's end: learn the template anew where the chunk fitted nothing; the old template, or None."""
        if not (self._chunk_rho and not latched and self.template is not None):
            return None
        rho_all = np.concatenate(self._chunk_rho)
        mid = rho_all.size // 2
        stale = float(np.partition(rho_all, mid)[mid]) > self.p.stale_residual * residual_max
        if not (rho_all.size >= self.p.chunk // 2 and stale):
            return None
        old = self.template
        self.template = np.percentile(np.concatenate(self._chunk_v), 100 * self.p.quantile, axis=0)
        self._acc_n = 0
        return old

    def note_relearned(self, end: int) -> None:
        """The template was learned anew at stream sample ``end`` (the latest few are all anyone asks about)."""
        self.relearned = [*self.relearned[-15:], end]

    def follow(self, latched: bool) -> bool:
        """At a chunk's end: move towards the low quantile of the frames gathered; True if the template moved."""
        self._chunk_rho, self._chunk_v = [], []
        moved = False
        if self._acc_n and self.template is not None and not latched:
            acc = np.concatenate(self._acc_list)
            k = int(self.p.quantile * (acc.shape[0] - 1))
            q = np.partition(acc, k, axis=0)[k]
            alpha = 1.0 - math.exp(-self._acc_n * self.hop / self.sample_rate / self.tau_s)
            self.template = self.template + alpha * q
            moved = True
        return moved

    def clear_gathered(self, chunk: bool = False) -> None:
        """Forget the departures gathered (and, with ``chunk``, the chunk's residuals and levels)."""
        self._acc_list, self._acc_n = [], 0
        if chunk:
            self._chunk_rho, self._chunk_v = [], []

    def set_joint_alone(self, alone: FloatArray, scale: FloatArray) -> None:
        """Sound was added from the start: ``alone`` (dB per sub-band) caps the floor (:mod:`.added`)."""
        self.joint_alone = np.asarray(alone, dtype=np.float64)
        if self.template is not None and self.floor is not None:
            self._floors = self._floors[:-1]  # the latest template again, now with the bound
            self.set_floor(scale)

    def set_levels(self, template: FloatArray) -> None:
        """Take ``template`` (dB per sub-band) as the template."""
        self.template = template

    # --- the floor ------------------------------------------------------------------------------
    def set_floor(self, scale: FloatArray, reset: bool = False) -> None:
        """Remember the template just updated: the floor, and the sound added (``scale``: 1 / spread, per dB)."""
        if self.template is None:
            return
        self._floors = ([] if reset else self._floors[-(self.p.floor_chunks - 1) :]) + [self.template.copy()]
        kept = np.stack(self._floors)
        self.floor = np.min(kept, axis=0)
        if reset:
            self.joint_alone = None
        elif self.joint_alone is not None:
            if bool(np.all(self.template <= self.joint_alone + self.p.alone_reached_db)):
                self.joint_alone = None  # the added sound stopped: the template came down to the joint's own level
            else:
                self.floor = np.minimum(self.floor, self.joint_alone)
        self.added_db = None
        if self.p.mask_added is not None:
            added = self.template - self.floor
            lifted = added * scale >= self.p.mask_added
            fell = (np.max(kept, axis=0) - self.template) * scale
            if float(fell.max()) < self.p.mask_added and bool(lifted.any()):
                self.added_db = np.where(lifted, added, 0.0)
