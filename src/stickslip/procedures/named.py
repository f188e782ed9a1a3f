"""Named positions of a device: keep where the joints are under a name, and go back there.

A named position is the three kept joint positions (rad, rad, m) at the moment it was
saved, kept per device in the store beside the positions themselves (key ``"named"``).
:func:`go_to` drives back joint by joint with :func:`stickslip.procedures.move.move` (the
tracked step scale, the journal), joint 3 first when it must retract and last when it
must extend, so the tip is drawn back before the arm swings and pushed out only once it
points where it should. A rig file (issue 32) will hold named positions in the rig's
frame; these are per device.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from ..calibration import Calibration
from ..clock import now_utc
from ..devices.base import Controller, device_key
from ..devices.positions import StateStore, load_state
from ..joints import JOINTS
from ..units import format_position
from .move import MoveRefused, MoveRequest, MoveResult, MoveStore, move

__all__ = [
    "NAME_PATTERN", "GoToResult", "NamedPosition", "delete_position", "go_to", "once", "positions", "safe_order",
    "save_position",
]

NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9 _.\-]{0,39}$"
"""A position's name: 1 to 40 letters, digits, spaces, ``_``, ``.`` or ``-``, beginning with a letter or digit."""

_KEY = "named"
_MAX = 200


@dataclass(frozen=True)
class NamedPosition:
    """A saved position: ``q`` (rad, rad, m) and when it was saved (UTC ISO)."""

    name: str
    q: tuple[float, float, float]
    saved_at: str

    def as_dict(self) -> dict[str, object]:
        """JSON shape (SI), with each joint in display units."""
        return {
            "name": self.name, "q": list(self.q), "saved_at": self.saved_at,
            "display": [format_position(v, j) for j, v in zip((1, 2, 3), self.q, strict=True)],
        }


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not re.match(NAME_PATTERN, name):
        raise ValueError(
            f"position name {name!r} must be 1-40 letters, digits, spaces, _ . or -, beginning with a letter or digit"
        )
    return name


def _read(store: StateStore, key: str) -> dict[str, Any]:
    raw = store.get_state(key, _KEY)
    if not raw:
        return {}
    if not isinstance(raw, dict):
        raise ValueError(f"the named positions of {key} are unreadable (not an object)")
    return raw


def positions(store: StateStore, device: str) -> list[NamedPosition]:
    """The named positions of ``device``, by name. ``ValueError`` if the kept ones are unreadable."""
    out = []
    for name, entry in sorted(_read(store, device_key(device)).items()):
        try:
            q = tuple(float(v) for v in entry["q"])
            out.append(NamedPosition(str(name), (q[0], q[1], q[2]), str(entry.get("saved_at", ""))))
        except (KeyError, TypeError, ValueError, IndexError):
            raise ValueError(f"the named position {name!r} of {device_key(device)} is unreadable") from None
    return out


def save_position(store: StateStore, device: str, name: str) -> NamedPosition:
    """Keep the device's current positions under ``name`` (replacing one of that name).

    :class:`~.move.MoveRefused` if a joint's position is uncertain (an uncertain position
    is not a place to come back to); ``ValueError`` for a bad name or too many positions.
    """
    _check_name(name)
    key = device_key(device)
    state = load_state(store, key)
    for j in (1, 2, 3):
        problem = state.uncertainty_problem(j)
        if problem:
            raise MoveRefused(f"cannot save {name!r}: {problem}")
    named = _read(store, key)
    if name not in named and len(named) >= _MAX:
        raise ValueError(f"{key} already has {_MAX} named positions: delete one first")
    q = (state.positions[1], state.positions[2], state.positions[3])
    saved = NamedPosition(name, q, now_utc().isoformat(timespec="seconds"))
    named[name] = {"q": list(q), "saved_at": saved.saved_at}
    store.set_state(key, _KEY, named)
    return saved


def delete_position(store: StateStore, device: str, name: str) -> None:
    """Forget the named position ``name``; ``KeyError`` if there is none."""
    key = device_key(device)
    named = _read(store, key)
    if name not in named:
        raise KeyError(f"{key} has no position named {name!r}")
    del named[name]
    store.set_state(key, _KEY, named)


@dataclass(frozen=True)
class GoToResult:
    """What :func:`go_to` did: the position, and one move result per joint that moved (in the order driven)."""

    position: NamedPosition
    moves: tuple[MoveResult, ...]

    def failure(self) -> str | None:
        """The line of the move a device error stopped (the joints after it were not moved), else ``None``."""
        for m in self.moves:
            f = m.failure()
            if f is not None:
                return f
        return None

    def as_dict(self) -> dict[str, object]:
        """JSON shape: the position and each move (``stickslip move --json``'s shape)."""
        return {"position": self.position.as_dict(), "moves": [m.as_dict() for m in self.moves]}


def safe_order(q_from: Sequence[float], q_to: Sequence[float]) -> tuple[int, ...]:
    """The order to reach a position saved without one (rad, rad, m): joint 3 first when it retracts, else last.

    The tip is drawn back before the arm swings and pushed out only once it points where
    it should (:func:`go_to`, and a rig's saved positions: :func:`stickslip.procedures.arms.position_of`).
    """
    return (3, 1, 2) if q_to[2] < q_from[2] else (1, 2, 3)


def once(ready: Callable[[], None]) -> Callable[[], None]:
    """``ready`` called at the first call only: the ``ready`` of a sequence of moves, each of which calls it, and
    called once more after the last so that a sequence with no move calls it too."""
    started = False

    def first() -> None:
        nonlocal started
        if not started:
            started = True
            ready()

    return first


def go_to(
    store: MoveStore,
    device: str,
    name: str,
    calibration: Calibration,
    *,
    burst: int = 1000,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = lambda: None,
    opener: Callable[[str], Controller] | None = None,
    tolerance: float = 1e-9,
) -> GoToResult:
    """Drive ``device`` back to its position ``name``, one joint at a time (see the module docstring).

    Joints already within ``tolerance`` (rad or m) are not moved. Each move refuses as
    :func:`~.move.move` does (an uncertain joint, a joint the calibration lacks); the first
    move that a device error stops ends the run, the joints after it unmoved. ``KeyError``
    if there is no such position.
    """
    found = {p.name: p for p in positions(store, device)}
    if name not in found:
        raise KeyError(f"{device_key(device)} has no position named {name!r}")
    target = found[name]
    state = load_state(store, device_key(device))
    order = safe_order([state.positions[j] for j in (1, 2, 3)], target.q)
    for j in order:
        if j not in {jj for jj, _ in calibration.models} and abs(target.q[j - 1] - state.positions[j]) > tolerance:
            raise MoveRefused(f"going to {name!r} moves joint {j}, and the calibration has no model of it")
    first = once(ready)
    moves: list[MoveResult] = []
    for j in order:
        state = load_state(store, device_key(device))
        if abs(target.q[j - 1] - state.positions[j]) <= tolerance and j not in state.uncertain:
            continue
        q_to = min(max(target.q[j - 1], JOINTS[j].lower), JOINTS[j].upper)
        result = move(store, MoveRequest(device, j, to=q_to, burst=burst), calibration, warn=warn, ready=first,
                      opener=opener)
        moves.append(result)
        if result.outcome.error is not None:
            break
    first()
    return GoToResult(target, tuple(moves))
