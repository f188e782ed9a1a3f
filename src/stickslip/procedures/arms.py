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
from dataclasses import dataclass, replace

from ..calibration import Calibration
from ..devices.base import Controller, open_device
from ..devices.positions import DeviceState, StateStore, load_state
from ..rig import NamedPosition, Rig
from ..rig.guard import Guard, mapped
from ..rig.secrets import controller_url
from ..units import format_position
from . import named
from .move import MoveRefused, MoveRequest, MoveResult, MoveStore, check_envelope_path, move
from .named import once, safe_order
from .rigstop import stoppable

__all__ = [
    "ArmState", "arm_opener", "arm_states", "go_to", "go_to_position", "guard_for", "opener_for", "position_of",
    "on_store", "safe_order",
]


def guard_for(store: StateStore, rig: Rig, arm: str | None) -> Guard:
    """The envelope of ``arm`` (the rig's first for ``None``): the rig, and every other arm's kept pose; an arm
    uncertain, in flight or claimed by a move is unknown, and kept from over its box: each joint anywhere between
    its kept value, its uncertain bounds and its claim. Its ``fresh`` reads them again."""
    me = rig.arm(arm)
    others: dict[str, list[float]] = {}
    unknown: dict[str, str] = {}
    swept: dict[str, list[tuple[float, float]]] = {}
    for other in rig.arms:
        if other.name != me.name:
            s = load_state(store, rig.state_key(other.name), other.joint_specs())
            others[other.name] = [s.positions[j] for j in (1, 2, 3)]
            if s.claim:  # a move of it has claimed its range ("mark, then check"), from its start to its end
                j = min(s.claim)
                lo, hi = (format_position(v, s.spec(j)) for v in s.claim[j])
                unknown[other.name] = f"a move of it claims its joint {j} between {lo} and {hi} until it ends"
            elif s.uncertain:  # a burst interrupted (or in flight): anywhere over its bounds
                j = min(s.uncertain)
                lo, hi = (format_position(v, s.spec(j)) for v in s.uncertain[j])
                unknown[other.name] = f"its joint {j} is in flight or uncertain, between {lo} and {hi}"
            if other.name in unknown:
                swept[other.name] = [_hull(s.positions[j], s.uncertain.get(j), s.claim.get(j)) for j in (1, 2, 3)]
    return Guard(rig, me.name, others, unknown, fresh=lambda: guard_for(store, rig, me.name), swept=swept)


def on_store(guard: Guard | None, store: StateStore) -> Guard | None:
    """``guard`` built again from ``store`` (the other arms as kept now, its ``fresh`` reading ``store``): what a
    front end that keeps a guard for many moves (a Bluesky axis, ``guard=``) checks each move with, in the
    thread that moves (an SQLite store is per thread). A guard with no ``fresh`` (built by hand) as it is."""
    if guard is None or guard.fresh is None:
        return guard
    return guard_for(store, guard.rig, guard.arm)


def _hull(q: float, *ranges: tuple[float, float] | None) -> tuple[float, float]:
    """The least range (rad or m) holding ``q`` and each of ``ranges``."""
    values = [q, *(v for r in ranges if r is not None for v in r)]
    return min(values), max(values)


def opener_for(
    rig: Rig, arm: str | None, opener: Callable[[str], Controller] | None = None
) -> Callable[[str], Controller]:
    """Opens ``arm``'s controller: the URL with its password added (from its source), joints mapped to channels."""
    a = rig.arm(arm)
    inner = opener or open_device

    def open_arm(_url: str) -> Controller:
        return inner(controller_url(a))

    return mapped(open_arm, a)


def arm_opener(rig: Rig, arm: str | None, inner: Callable[[str], Controller]) -> Callable[[str], Controller]:
    """Opens ``arm``'s controller at the URL it is given (its options kept, e.g. ``realtime=1``), with the arm's
    password added and its joints mapped to channels (what a server that owns the arm opens it with)."""
    a = rig.arm(arm)

    def open_arm(url: str) -> Controller:
        return inner(controller_url(replace(a, controller=url)))

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
    """Reach the named position ``name`` of ``arm`` (the rig file's, or one saved for it: :func:`position_of`),
    joint by joint in its order.

    The whole path (one straight joint move after another, in the position's order) is
    checked against the envelope before the first step; then each joint is moved by
    :func:`~.move.move` (which checks its own stretch again). :class:`~.move.MoveRefused`
    naming the obstacle; ``KeyError`` for an unknown arm or position. A device error
    ends the run (the joints after it unmoved): the last result's ``failure()``.
    ``from_unreferenced`` and ``trust_calibration`` go to each move (:class:`~.move.MoveRequest`).
    """
    a = rig.arm(arm)
    target = position_of(store, rig, a.name, name)
    return go_to_position(store, rig, a.name, target, calibration, burst=burst, warn=warn, ready=ready, opener=opener,
                          tolerance=tolerance, from_unreferenced=from_unreferenced,
                          trust_calibration=trust_calibration)


def position_of(store: StateStore, rig: Rig, arm: str | None, name: str) -> NamedPosition:
    """The named position ``name`` of ``arm``: the rig file's, else one saved for the arm (``stickslip serve``,
    :mod:`.named`) with its :func:`safe_order` from the kept pose. ``KeyError`` naming both sets otherwise."""
    a = rig.arm(arm)
    try:
        return rig.position(a.name, name)
    except KeyError as e:
        saved = {p.name: p for p in named.positions(store, a.controller)}
        if name not in saved:
            also = ", ".join(saved) or "none"
            raise KeyError(f"{e.args[0]}; saved for it: {also}") from None
    state = load_state(store, rig.state_key(a.name), a.joint_specs())
    q = saved[name].q
    return NamedPosition(name, a.name, q, safe_order([state.positions[j] for j in (1, 2, 3)], q))


def go_to_position(
    store: MoveStore,
    rig: Rig,
    arm: str | None,
    target: NamedPosition,
    calibration: Calibration,
    *,
    burst: int = 1000,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = lambda: None,
    opener: Callable[[str], Controller] | None = None,
    tolerance: float = 1e-9,
    from_unreferenced: bool = False,
    trust_calibration: bool = False,
    device: str | None = None,
) -> tuple[MoveResult, ...]:
    """Reach ``target`` (a rig file's named position, or one saved and given its order) as :func:`go_to` does.

    ``device`` is the URL the moves open, and ``opener`` then opens it as it is (a server
    gives its own URL and its controller, already mapped to the arm's channels); without
    it, the arm's controller through :func:`opener_for`, which sends no further burst once the rig's STOP is
    pressed on another arm's page (:func:`~.rigstop.stoppable`; a server's own controller reads it itself).
    """
    a = rig.arm(arm)
    name = target.name
    state = load_state(store, rig.state_key(a.name), a.joint_specs())
    guard = guard_for(store, rig, a.name)
    q = [state.positions[j] for j in (1, 2, 3)]
    path = [list(q)]
    for j in target.order:
        goal = target.q[j - 1]
        if goal is not None and abs(goal - q[j - 1]) > tolerance:
            q[j - 1] = goal
            path.append(list(q))
    try:
        check_envelope_path(guard, state, path, calibration)
    except MoveRefused as e:
        raise MoveRefused(f"going to {name!r}: {e}") from None
    results: list[MoveResult] = []
    first = once(ready)
    for before, after in zip(path[:-1], path[1:], strict=True):
        j = next(i + 1 for i in range(3) if before[i] != after[i])
        request = MoveRequest(device or a.controller, j, to=after[j - 1], burst=burst,
                              guard=guard_for(store, rig, a.name), from_unreferenced=from_unreferenced,
                              trust_calibration=trust_calibration, joints=a.joint_specs(),
                              state_key=rig.state_key(a.name))
        result = move(store, request, calibration, warn=warn, ready=first,
                      opener=opener if device is not None else stoppable(opener_for(rig, a.name, opener), store, rig,
                                                                          a.name))
        results.append(result)
        if result.outcome.error is not None:
            break
    first()
    return tuple(results)
