"""The one call the procedures make into the envelope, and an arm's channel map.

:class:`Guard` is what a procedure is given for a rig: the rig, the moving arm and the
other arms' kept poses. ``guard.check(q_from, q_sd, path)`` refuses a planned path
(:class:`~.envelope.EnvelopeViolation`) before one step is sent; ``guard.reachable``
says how far a jog may go. :func:`mapped` wraps a controller so that joint ``j`` drives
the arm's channel with its sign (a rig file's ``channel`` and ``sign``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..devices.base import Controller, ControllerProxy
from .envelope import EnvelopeViolation, Refusal, SigmaGrowth, check_path, safe_fraction
from .model import Arm, Rig

__all__ = ["ArmUnknown", "Guard", "mapped"]


class ArmUnknown(EnvelopeViolation):
    """Another arm of the rig may be anywhere over a range (a move in flight or claimed, or one interrupted), and
    the path comes near where it may be (or, its range not known, anywhere): refused until its move ends or it is
    re-referenced."""

    def __init__(self, refusal: Refusal, text: str) -> None:
        super().__init__(refusal)
        self.args = (text,)


_WAIT = ("wait for its move to end, then try again (two moves started at once are both refused), or re-reference "
         "it if no move runs on it")


@dataclass(frozen=True)
class Guard:
    """A rig's envelope for one arm: ``others`` are the other arms' kept poses (rad, rad, m) by name;
    ``unknown`` the other arms whose kept pose is uncertain (in flight, or interrupted) or claimed by a move, with
    why; ``swept`` where each of those may be: per joint (lo, hi), rad or m (an arm unknown with no box here:
    every path is refused)."""

    rig: Rig
    arm: str
    others: Mapping[str, Sequence[float]] = field(default_factory=dict)
    unknown: Mapping[str, str] = field(default_factory=dict)
    fresh: Callable[[], Guard] | None = field(default=None, compare=False, repr=False)
    """Builds this guard again from the store (the other arms as kept now): what a move checks against once it has
    claimed its own range (:func:`stickslip.procedures.move.claim_and_check`); ``None``: this one as it is."""
    swept: Mapping[str, Sequence[tuple[float, float]]] = field(default_factory=dict)

    def _known(self, q: Sequence[float]) -> None:
        """Refuse (:class:`ArmUnknown`) any path from ``q`` while another arm is unknown with no box."""
        for name, why in self.unknown.items():
            if name in self.swept:
                continue
            refusal = Refusal(arm=self.arm, obstacle=f"arm {name}", point=None, distance=0.0,
                              allowed=self.rig.arm_distance, q=(float(q[0]), float(q[1]), float(q[2])), fraction=0.0,
                              undecided=True)
            raise ArmUnknown(refusal, f"arm {self.arm!r}: arm {name!r} may be anywhere along a move ({why}), so no "
                             f"path can be shown clear of it: {_WAIT}")

    def _swept(self) -> dict[str, Sequence[tuple[float, float]]]:
        return {name: box for name, box in self.swept.items() if name in self.unknown}

    def check(self, path: Sequence[Sequence[float]], q_sd: Sequence[float] | SigmaGrowth = (0.0, 0.0, 0.0)) -> None:
        """Refuse ``path`` (poses, rad or m) if it leaves the envelope (:func:`~.envelope.check_path`).

        ``q_sd``: each joint's σ (rad, rad, m) all along, or as it grows along the path. An
        unknown arm with a box is kept from every pose of its box; a path refused for it
        raises :class:`ArmUnknown`, naming it, why, and what to do.
        """
        if len(path):
            self._known(path[0])
        try:
            check_path(self.rig, self.arm, np.asarray(path, dtype=float), q_sd=q_sd, others=dict(self.others),
                       swept=self._swept())
        except EnvelopeViolation as e:
            name = e.refusal.obstacle.removeprefix("arm ")
            if name not in self.unknown or not e.refusal.obstacle.startswith("arm "):
                raise
            detail = e.refusal.message().removeprefix(f"arm {self.arm!r}: ")
            raise ArmUnknown(e.refusal, f"arm {self.arm!r}: arm {name!r} may be anywhere along a move "
                             f"({self.unknown[name]}), and kept from every pose it may take there, {detail}: "
                             f"{_WAIT}") from None

    def check_joint(self, q: Sequence[float], joint: int, q_to: float, q_sd: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Refuse a move of ``joint`` from pose ``q`` to ``q_to`` (rad or m) that leaves the envelope."""
        end = list(q)
        end[joint - 1] = q_to
        self.check([list(q), end], q_sd)

    def reachable(self, q: Sequence[float], joint: int, q_to: float, q_sd: Sequence[float] = (0.0, 0.0, 0.0)) -> float:
        """How far toward ``q_to`` joint ``joint`` may go from ``q`` within the envelope (rad or m): a jog's stop."""
        if any(name not in self.swept for name in self.unknown):
            return float(q[joint - 1])
        end = list(q)
        end[joint - 1] = q_to
        frac, _ = safe_fraction(self.rig, self.arm, np.asarray([list(q), end], dtype=float), q_sd=q_sd,
                                others=dict(self.others), swept=self._swept())
        return float(q[joint - 1] + frac * (q_to - q[joint - 1]))


class _Mapped(ControllerProxy):
    """A controller whose joint ``j`` is the arm's channel with its sign."""

    def __init__(self, inner: Controller, arm: Arm) -> None:
        super().__init__(inner)
        self._map = {j.number: (j.channel, j.sign) for j in arm.joints}

    def set_frequency(self, joint: int, hz: float) -> None:
        self._inner.set_frequency(self._map[joint][0], hz)

    def frequency(self, joint: int) -> float:
        return self._inner.frequency(self._map[joint][0])

    def step(self, joint: int, n: int) -> None:
        channel, sign = self._map[joint]
        self._inner.step(channel, sign * n)

    def stop(self, joint: int | None = None) -> None:
        self._inner.stop(None if joint is None else self._map[joint][0])


def mapped(opener: Callable[[str], Controller], arm: Arm) -> Callable[[str], Controller]:
    """An opener whose controllers drive ``arm``'s channels with their signs (``opener`` itself for 1, 2, 3 all +)."""
    if all(j.channel == j.number and j.sign == 1 for j in arm.joints):
        return opener

    def open_mapped(url: str) -> Controller:
        return _Mapped(opener(url), arm)

    return open_mapped
