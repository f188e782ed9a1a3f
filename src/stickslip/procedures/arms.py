"""Several arms in one rig (docs/rig.md): which device an arm is, its envelope, its named positions.

An arm's positions and journal are kept under its controller's device key
(:func:`stickslip.devices.base.device_key`), as for any device, or, when two arms of the
rig share a controller (each on its own channels), under ``KEY#arm=NAME``
(:meth:`stickslip.rig.Rig.state_key`). The lock is the controller's: moves of arms on
different controllers may run at once (each holds only its own lock); two arms on one
controller move one after the other. :func:`guard_for` builds the arm's envelope from the rig and the
other arms' kept poses; :func:`go_to` reaches a rig file's named position joint by
joint in its order, after checking the whole path.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..calibration import Calibration
from ..devices.base import Controller, open_device
from ..devices.positions import DeviceState, StateStore, load_state
from ..rig import Rig
from ..rig.envelope import EnvelopeViolation
from ..rig.guard import Guard, mapped
from ..rig.secrets import controller_url
from .move import MoveRefused, MoveRequest, MoveResult, MoveStore, move, track_fields

__all__ = ["ArmState", "arm_states", "go_to", "guard_for", "opener_for"]


def guard_for(store: StateStore, rig: Rig, arm: str | None) -> Guard:
    """The envelope of ``arm`` (the rig's first for ``None``): the rig, and every other arm's kept pose."""
    me = rig.arm(arm)
    others = {}
    for other in rig.arms:
        if other.name != me.name:
            s = load_state(store, rig.state_key(other.name), other.joint_specs())
            others[other.name] = [s.positions[j] for j in (1, 2, 3)]
    return Guard(rig, me.name, others)


def opener_for(
    rig: Rig, arm: str | None, opener: Callable[[str], Controller] | None = None
) -> Callable[[str], Controller]:
    """Opens ``arm``'s controller: the URL with its password added (from its source), joints mapped to channels."""
    a = rig.arm(arm)
    inner = opener or open_device

    def open_arm(_url: str) -> Controller:
        return inner(controller_url(a))

    return mapped(open_arm, a)


@dataclass(frozen=True)
class ArmState:
    """One arm of a rig and its kept state (``where`` for every arm)."""

    arm: str
    device: str
    state: DeviceState


def arm_states(store: StateStore, rig: Rig) -> list[ArmState]:
    """Every arm's kept state, in the rig's order."""
    return [ArmState(a.name, rig.state_key(a.name), load_state(store, rig.state_key(a.name), a.joint_specs()))
            for a in rig.arms]


def go_to(
    store: MoveStore,
    rig: Rig,
    arm: str | None,
    name: str,
    calibration: Calibration,
    *,
    burst: int = 1000,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = lambda: None,
    opener: Callable[[str], Controller] | None = None,
    tolerance: float = 1e-9,
    from_unreferenced: bool = False,
    trust_calibration: bool = False,
) -> tuple[MoveResult, ...]:
    """Reach the rig file's named position ``name`` of ``arm``, joint by joint in its order.

    The whole path (one straight joint move after another, in the position's order) is
    checked against the envelope before the first step; then each joint is moved by
    :func:`~.move.move` (which checks its own stretch again). :class:`~.move.MoveRefused`
    naming the obstacle; ``KeyError`` for an unknown arm or position. A device error
    ends the run (the joints after it unmoved): the last result's ``failure()``.
    ``from_unreferenced`` and ``trust_calibration`` go to each move (:class:`~.move.MoveRequest`).
    """
    a = rig.arm(arm)
    target = rig.position(a.name, name)
    state = load_state(store, rig.state_key(a.name), a.joint_specs())
    guard = guard_for(store, rig, a.name)
    q = [state.positions[j] for j in (1, 2, 3)]
    path = [list(q)]
    for j in target.order:
        goal = target.q[j - 1]
        if goal is not None and abs(goal - q[j - 1]) > tolerance:
            q[j - 1] = goal
            path.append(list(q))
    sd = [track_fields(state, j)["sd"] or 0.0 for j in (1, 2, 3)]
    try:
        guard.check(path, sd)
    except EnvelopeViolation as e:
        raise MoveRefused(f"going to {name!r}: refused by the rig's envelope: {e}") from None
    results: list[MoveResult] = []
    started = False

    def once() -> None:
        nonlocal started
        if not started:
            started = True
            ready()

    for before, after in zip(path[:-1], path[1:], strict=True):
        j = next(i + 1 for i in range(3) if before[i] != after[i])
        request = MoveRequest(a.controller, j, to=after[j - 1], burst=burst, guard=guard_for(store, rig, a.name),
                              from_unreferenced=from_unreferenced, trust_calibration=trust_calibration,
                              joints=a.joint_specs(), state_key=rig.state_key(a.name))
        result = move(store, request, calibration, warn=warn, ready=once, opener=opener_for(rig, a.name, opener))
        results.append(result)
        if result.outcome.error is not None:
            break
    once()
    return tuple(results)
