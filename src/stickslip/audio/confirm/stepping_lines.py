"""The stepping's lines across the listening: one model of the joint's own clicks, read at each fire.

Off the tuning's rate (the rate told) the tuned stop's signature is not what a stop does on the step
clock's lines, but a stop still changes the joint's own clicks, while sound added out of step with the
clock leaves their level in phase as it was. A fire's window judged against the half second before it
alone fails where that half second was itself not the stepping (music, speech lifting the levels:
stop-like, or the stop heard late). So the stepping's lines are modelled across the whole listening:
per sub-band, the level in phase with the clock followed (dB, :mod:`~stickslip.audio.features.lockin`)
of its lines, over every ``span_s`` of the stream accepted as stepping
(:meth:`.clocked.ClockedCheck.model_stepping`: its lines held ``model_min_share`` of their power in
phase, and, once the model judges, sat within ``model_max_z`` of it), as an exponentially forgotten mean
and spread (forgetting time ``model_tau_s``). At a fire, each piece of the window is read the same way;
the RMS over the sub-bands whose lines were locked of ``z = (L - mean) / spread`` (spread floored at
``model_floor_db``), the least over the pieces, says whether the lines were still the stepping's after
the fire: under ``model_max_z`` the fire is not a stop. Read only once the model holds
``model_min_spans`` (weight) of stepping; until then the per-fire vetoes judge.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: per line of a stretch: its power in phase with the clock followed, and its power in all
InPhase = Callable[[FloatArray], tuple[FloatArray, FloatArray]]


class SteppingLines:
    """Per sub-band, the level in phase of the joint's lines over the stepping accepted so far (see the module)."""

    def __init__(
        self,
        in_phase: InPhase,
        lines: dict[int, list[int]],
        ks: Sequence[int],
        tau_s: float,
        min_locked: float,
    ) -> None:
        #: per line ``ks`` of a stretch: power in phase, power in all (at the model's rate)
        self.in_phase, self.lines, self.ks = in_phase, lines, list(ks)
        self._at = {k: j for j, k in enumerate(self.ks)}  # where each line is in ``in_phase``'s arrays
        self.tau_s, self.min_locked = tau_s, min_locked
        n = len(lines)
        self.bands = sorted(lines)
        self.weight = 0.0  # the spans modelled, each forgotten by exp(-age / tau_s)
        self.mean, self.sq = np.zeros(n), np.zeros(n)  # the weighted mean level (dB) and mean square deviation
        self.locked = np.zeros(n)  # the weighted mean share of the lines' power in phase
        self.last_s = math.nan

    def locked_bands(self) -> list[int]:
        """The sub-bands whose lines held ``min_locked`` of their power in phase over the stepping modelled."""
        return [b for b, share in zip(self.bands, self.locked, strict=True) if share >= self.min_locked]

    def _powers(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Per sub-band: its lines' power in phase over ``x`` and their power in all."""
        l1, w1 = self.in_phase(x)
        held = np.array([sum(float(l1[self._at[k]]) for k in self.lines[i]) for i in self.bands])
        whole = np.array([sum(float(w1[self._at[k]]) for k in self.lines[i]) for i in self.bands])
        return held, whole

    def levels(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Per sub-band: the level in phase of its lines over ``x`` (dB re 1; -inf: none) and its locked share."""
        held, whole = self._powers(x)
        with np.errstate(divide="ignore", invalid="ignore"):
            return 10.0 * np.log10(held), np.where(whole > 0.0, held / whole, 0.0)

    def in_step(self, x: FloatArray) -> tuple[float, float, float]:
        """Over the locked sub-bands: the mean share of their lines' power in phase over ``x``, the model's own mean
        share over the stepping modelled, and how far their power out of phase over ``x`` rose over the stepping's
        (dB; the model's from its mean level and share) (NaN: no sub-band locked). At an end stop the joint steps on
        into it: its lines stay in step and only their level moves (a stop that lowers them into the room's noise
        lowers the share, but adds nothing out of phase); sound of another kind on them adds power out of phase."""
        on = self.locked >= self.min_locked
        if not on.any():
            return math.nan, math.nan, math.nan
        held, whole = self._powers(x)
        share = np.where(whole > 0.0, held / np.where(whole > 0.0, whole, 1.0), 0.0)
        was = float(np.sum(10.0 ** (self.mean[on] / 10.0) * (1.0 - self.locked[on]) / self.locked[on]))
        out = float(np.sum(whole[on] - held[on]))
        with np.errstate(divide="ignore"):
            added = 10.0 * math.log10(out / was) if was > 0.0 and out > 0.0 else (math.inf if out > 0.0 else -math.inf)
        return float(np.mean(share[on])), float(np.mean(self.locked[on])), added

    def add(self, level: FloatArray, share: FloatArray, t_s: float) -> None:
        """A stretch's levels (dB) and locked shares, of stepping accepted that ended at ``t_s`` (s), into the model."""
        if not np.all(np.isfinite(level)):
            return
        if math.isfinite(self.last_s):
            f = math.exp(-max(0.0, t_s - self.last_s) / self.tau_s) if self.tau_s > 0.0 else 0.0
            self.weight *= f
        self.last_s = t_s
        w = self.weight + 1.0
        d = level - self.mean
        self.mean = self.mean + d / w
        self.sq = (self.weight * self.sq + self.weight / w * d**2) / w  # West's weighted update
        self.locked = self.locked + (share - self.locked) / w
        self.weight = w

    def z_of(self, level: FloatArray, min_weight: float, floor_db: float) -> float:
        """The RMS over the locked sub-bands of ``level`` (dB per sub-band) against the model, in spreads (each
        floored at ``floor_db``); NaN where the model holds under ``min_weight`` spans or no sub-band was locked."""
        on = self.locked >= self.min_locked
        if self.weight < min_weight or not on.any():
            return math.nan
        spread = np.sqrt(self.sq[on] * self.weight / max(self.weight - 1.0, 1e-9) + floor_db**2)
        d = np.where(np.isfinite(level[on]), level[on] - self.mean[on], -60.0)  # lines gone: far off
        return float(np.sqrt(np.mean((d / spread) ** 2)))

    def z(self, pieces: Sequence[FloatArray], min_weight: float, floor_db: float) -> float:
        """:meth:`z_of` each piece of a window, the least over them (NaN: none, or the model not ready): where the
        lines were the stepping's in any piece after the fire, the joint stepped on after it, and the fire did not
        begin a stop (a stop that began later, more than a piece after it, fires again)."""
        if not pieces:
            return math.nan
        return float(np.min([self.z_of(self.levels(x)[0], min_weight, floor_db) for x in pieces]))
