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
from typing import Any

import numpy as np

from ..devices.base import Controller, DeviceInfo
from .envelope import SigmaGrowth, check_path, safe_fraction
from .model import Arm, Rig

__all__ = ["Guard", "mapped"]


@dataclass(frozen=True)
class Guard:
    """A rig's envelope for one arm: ``others`` are the other arms' kept poses (rad, rad, m) by name."""

    rig: Rig
    arm: str
    others: Mapping[str, Sequence[float]] = field(default_factory=dict)

    def check(self, path: Sequence[Sequence[float]], q_sd: Sequence[float] | SigmaGrowth = (0.0, 0.0, 0.0)) -> None:
        """Refuse ``path`` (poses, rad or m) if it leaves the envelope (:func:`~.envelope.check_path`).

        ``q_sd``: each joint's σ (rad, rad, m) all along, or as it grows along the path.
        """
        check_path(self.rig, self.arm, np.asarray(path, dtype=float), q_sd=q_sd, others=dict(self.others))

    def check_joint(self, q: Sequence[float], joint: int, q_to: float, q_sd: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Refuse a move of ``joint`` from pose ``q`` to ``q_to`` (rad or m) that leaves the envelope."""
        end = list(q)
        end[joint - 1] = q_to
        self.check([list(q), end], q_sd)

    def reachable(self, q: Sequence[float], joint: int, q_to: float, q_sd: Sequence[float] = (0.0, 0.0, 0.0)) -> float:
        """How far toward ``q_to`` joint ``joint`` may go from ``q`` within the envelope (rad or m): a jog's stop."""
        end = list(q)
        end[joint - 1] = q_to
        frac, _ = safe_fraction(self.rig, self.arm, np.asarray([list(q), end], dtype=float), q_sd=q_sd,
                                others=dict(self.others))
        return float(q[joint - 1] + frac * (q_to - q[joint - 1]))


class _Mapped:
    """A controller whose joint ``j`` is the arm's channel with its sign."""

    def __init__(self, inner: Controller, arm: Arm) -> None:
        self._inner = inner
        self._map = {j.number: (j.channel, j.sign) for j in arm.joints}

    @property
    def info(self) -> DeviceInfo:
        return self._inner.info

    def set_frequency(self, joint: int, hz: float) -> None:
        self._inner.set_frequency(self._map[joint][0], hz)

    def frequency(self, joint: int) -> float:
        return self._inner.frequency(self._map[joint][0])

    def step(self, joint: int, n: int) -> None:
        channel, sign = self._map[joint]
        self._inner.step(channel, sign * n)

    def stop(self, joint: int | None = None) -> None:
        self._inner.stop(None if joint is None else self._map[joint][0])

    def settings(self) -> dict[str, object]:
        return self._inner.settings()

    def close(self) -> None:
        self._inner.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


def mapped(opener: Callable[[str], Controller], arm: Arm) -> Callable[[str], Controller]:
    """An opener whose controllers drive ``arm``'s channels with their signs (``opener`` itself for 1, 2, 3 all +)."""
    if all(j.channel == j.number and j.sign == 1 for j in arm.joints):
        return opener

    def open_mapped(url: str) -> Controller:
        return _Mapped(opener(url), arm)

    return open_mapped
