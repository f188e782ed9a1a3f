"""A measured position into a joint's dead reckoning: the Kalman update behind ``stickslip observe``.

The kept state of each joint (``stickslip where``) carries the Kalman state of its dead
reckoning (:class:`stickslip.motion.tracking.JointTrack`): a move widens the position's
uncertainty; a measured position (a microscope image, an end stop reached) narrows it
and, through the correlation the moves built up, corrects the day's step scale, which
the next move plans with (docs/models.md §7).

A measurement far from the kept position (more than :data:`MAX_INNOVATION` standard
deviations of the difference) is refused unless forced: a wrong reading or a slipped
joint would otherwise teach the filter a wrong step scale. Forced, it re-references the
position and leaves the step scale as it was (the steps did not take the joint there). A joint left uncertain by an
interrupted move, or one no move has tracked yet, is re-referenced by the measurement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from ..devices.base import device_key
from ..devices.positions import StateStore, load_state, save_state, where_set_command
from ..joints import JOINTS
from ..motion.tracking import JointTrack
from ..units import format_position, format_spread
from .move import LockStore, device_lock

__all__ = [
    "DEFAULT_SIGMA",
    "MAX_INNOVATION",
    "InnovationTooLarge",
    "Observation",
    "ObserveResult",
    "ObserveStore",
    "observe",
]

DEFAULT_SIGMA = {3: 1e-6, 2: 50e-6, 1: 50e-6}
"""Standard deviation assumed for a measured position when none is given (m, rad, rad)."""

MAX_INNOVATION = 5.0
"""A measurement further than this many standard deviations from the kept position is refused
(a wrong reading or a slipped joint would otherwise teach the filter a wrong step scale)."""


class InnovationTooLarge(ValueError):
    """The measured position is further from the kept one than :data:`MAX_INNOVATION` standard deviations."""


class ObserveStore(LockStore, StateStore, Protocol):
    """What :func:`observe` needs of a store: the device lock and the kept state (``stickslip.storage.Store``)."""


@dataclass(frozen=True)
class Observation:
    """A measured position of one joint.

    Attributes
    ----------
    joint : int
    q : float
        The measured position, rad or m (within the joint's range).
    sd : float or None
        Its standard deviation, rad or m (``None``: 0 at an end stop, else :data:`DEFAULT_SIGMA`).
    at_stop : bool
        The joint was found at an end stop (``q`` is that stop): exact.
    force : bool
        Use the measurement even if it is more than :data:`MAX_INNOVATION` standard deviations away.
    """

    joint: int
    q: float
    sd: float | None = None
    at_stop: bool = False
    force: bool = False

    def __post_init__(self) -> None:
        """``ValueError`` (one line) for a measurement that cannot be used: ``q`` outside the joint's range (it
        was clamped onto the stop and kept), ``sd`` not finite, negative or wider than the joint's whole range
        (its square overflowed), ``at_stop`` away from both stops (an exact position where no stop is)."""
        spec = JOINTS.get(self.joint)
        if spec is None:
            raise ValueError(f"joint {self.joint!r}: the MM3A's joints are 1, 2 and 3")
        bad = spec.range_problem("the measured position", float(self.q))
        if bad is not None:
            raise ValueError(bad)
        if self.sd is not None and not (math.isfinite(self.sd) and 0.0 <= self.sd <= spec.span):
            raise ValueError(f"the measurement's standard deviation {self.sd:.6g} {spec.unit} is not 0 to the joint's "
                             f"range ({spec.span:.6g} {spec.unit}): a wider one says nothing of where it is")
        if self.at_stop and not any(abs(self.q - s) <= 1e-5 * spec.span for s in (spec.lower, spec.upper)):
            raise ValueError(f"at_stop: the measured position {format_position(self.q, self.joint)} is not an end "
                             f"stop of joint {self.joint} ({format_position(spec.lower, self.joint)} or "
                             f"{format_position(spec.upper, self.joint)})")

    @property
    def sigma(self) -> float:
        """The standard deviation used, rad or m."""
        if self.sd is not None:
            return self.sd
        return 0.0 if self.at_stop else DEFAULT_SIGMA[self.joint]


@dataclass(frozen=True)
class ObserveResult:
    """What :func:`observe` did (SI units): the kept position before, the measurement, the update.

    ``q_sd_before`` is ``None`` and ``innovation_sigmas`` ``None`` when the measurement
    re-referenced the joint (it was uncertain, or never tracked).
    """

    device: str
    joint: int
    q_before: float
    q_sd_before: float | None
    q_measured: float
    sigma: float
    q: float
    q_sd: float
    step_scale_before: float
    step_scale: float
    step_scale_sd: float
    re_referenced: bool
    was_uncertain: bool
    innovation_sigmas: float | None

    @property
    def forced(self) -> bool:
        """The measurement was used although it lay more than :data:`MAX_INNOVATION` standard deviations away."""
        return self.innovation_sigmas is not None and self.innovation_sigmas > MAX_INNOVATION

    def as_dict(self) -> dict[str, object]:
        """The JSON shape of ``stickslip observe --json``."""
        return {
            "device": self.device, "joint": self.joint, "unit": JOINTS[self.joint].unit,
            "q_before": self.q_before, "q_sd_before": self.q_sd_before, "q_measured": self.q_measured,
            "sigma": self.sigma, "q": self.q, "q_sd": self.q_sd, "step_scale_before": self.step_scale_before,
            "step_scale": self.step_scale, "step_scale_sd": self.step_scale_sd, "re_referenced": self.re_referenced,
            "innovation_sigmas": self.innovation_sigmas,
        }


def _gate(obs: Observation, q_before: float, sd_before: float, device: str) -> float:
    """The innovation in standard deviations; :class:`InnovationTooLarge` beyond the gate unless forced."""
    joint, sd = obs.joint, obs.sigma
    s_pred = math.sqrt(sd_before**2 + sd**2)
    diff = abs(obs.q - q_before)
    if s_pred == 0.0:  # both exact: the same position agrees, another cannot be weighed
        if diff <= 1e-9 * JOINTS[joint].span:
            return 0.0
        if not obs.force:
            raise InnovationTooLarge(
                f"the measured position {format_position(obs.q, joint)} is not the kept "
                f"{format_position(q_before, joint)}, and both are exact (an end stop, or a position set): "
                f"check the reading (units, which joint); if the joint was moved by hand, re-reference it "
                f"({where_set_command(device, joint, 'VALUE')}) or pass --force to use it"
            )
        return math.inf
    sigmas = diff / s_pred
    if sigmas > MAX_INNOVATION and not obs.force:
        raise InnovationTooLarge(
            f"the measured position {format_position(obs.q, joint)} is {sigmas:.3g} standard "
            f"deviations from the kept {format_position(q_before, joint)} (σ {format_spread(sd_before, joint)}): "
            "check the reading (units, which joint); if the joint slipped or was moved by hand, "
            f"re-reference it ({where_set_command(device, joint, 'VALUE')}) or pass --force to use it"
        )
    return sigmas


def observe(store: ObserveStore, device: str, obs: Observation) -> ObserveResult:
    """Feed ``obs`` into the kept track of its joint on ``device``, holding the device's lock.

    Raises :class:`InnovationTooLarge` (nothing kept), ``ValueError`` for an unreadable
    kept state, :class:`~stickslip.procedures.move.DeviceBusy` if another process drives it.
    """
    key = device_key(device)
    joint, spec = obs.joint, JOINTS[obs.joint]
    with device_lock(store, key):
        state = load_state(store, key)
        q_before = state.positions[joint]
        was_uncertain = joint in state.uncertain
        raw = state.track.get(joint)
        track = JointTrack.from_json(raw) if raw is not None else JointTrack()
        sd_before, scale_before = track.sd, track.scale
        re_reference = was_uncertain or raw is None
        sigmas: float | None = None
        if re_reference:  # an interrupted move, or no move tracked: the measurement re-references the joint
            track.reset_position(obs.sigma)
            q_new = obs.q
        else:
            sigmas = _gate(obs, q_before, sd_before, device)
            if sigmas > MAX_INNOVATION:  # forced: a reading the filter cannot explain (a slip, a hand) sets the
                track.reset_position(obs.sigma)  # position; the steps did not get it there: it teaches no scale
                q_new = obs.q
            else:
                q_new = track.observe(q_before, obs.q, obs.sigma)
        q_new = min(max(q_new, spec.lower), spec.upper)
        state.set_position(joint, q_new, "observed")
        state.track[joint] = track.to_json()
        save_state(store, state)
    return ObserveResult(
        key, joint, q_before, None if re_reference else sd_before, obs.q, obs.sigma, q_new, track.sd, scale_before,
        track.scale, track.scale_sd, re_reference, was_uncertain, sigmas,
    )
