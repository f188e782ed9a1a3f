"""Dead-reckoned joint positions and the configured pose of each device, kept between runs.

The MM3A's joints have no sensors: where a joint is comes from where it was last put
(an end stop, or a pose the user entered) plus the model's prediction for every step
sent since. This module keeps that per device URL:

* ``positions``: ``q1, q2, q3`` (rad, rad, m), each with its *source*: ``"default"``
  (never set: the outstretched pose is assumed), ``"set"`` (the user put it there, e.g.
  at an end stop), ``"dead-reckoned"`` (moved by the model since), ``"observed"`` (a
  measured position), ``"seen"`` (tracked by the camera in a closed-loop move) or
  ``"assumed"`` (moved by the model from a position never
  referenced: still not known). A joint is *referenced* when its source is ``set``,
  ``dead-reckoned``, ``observed`` or ``seen``;
* ``tilt``: the base tilt ``theta, psi`` (rad) the device is set up with;
* ``uncertain``: the write-ahead journal of a move. Before a burst is sent the joint is
  recorded as *in flight* between its last confirmed position and the burst's intended
  end (:meth:`DeviceState.intend`); when the controller confirms the burst the new
  position is recorded and the mark cleared. A link drop or a crash in between leaves
  the joint *uncertain* with those bounds, never silently wrong, until it is
  re-referenced (:meth:`DeviceState.set_position` with source ``"set"``); ``why`` says
  what left it so (a move, a traverse or raw steps interrupted or sent);
* ``claim``: the whole range a move of this arm is about to sweep (per joint, its bounds
  over the planned path), journalled before the move reads the rig's other arms and kept
  until it ends ("mark, then check": :func:`stickslip.procedures.move.claim_and_check`).
  The other arms of a rig are refused while it is there; the arm's own planning ignores
  it. A re-reference (:meth:`DeviceState.set_position` with ``"set"``) clears a claim left
  by a process that ended without clearing it;
* ``track``: per joint, the Kalman state of its dead reckoning (the day's step scale and
  the covariance of position and scale, :class:`stickslip.motion.tracking.JointTrack` as JSON),
  which ``stickslip move`` propagates and ``stickslip observe`` updates with a measured
  position (source ``"observed"``).

Where it is kept is injected (this layer sits below :mod:`stickslip.storage`): any
object with ``set_state(device, key, value)`` / ``get_state(device, key, default)``
— the :class:`stickslip.storage.Store` — or, without a database, a
:class:`JsonStateFile`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from .. import kinematics as kin
from ..joints import JointSet, JointSpec, tilt_problem
from ..records import atomic_write_text, check_version, dumps_json, json_kind, loads_json, read_json
from ..units import format_position
from .base import command_url, device_key

__all__ = [
    "where_set_command",
    "StateStore",
    "JsonStateFile",
    "DeviceState",
    "SOURCES",
    "REFERENCED",
    "load_state",
    "save_state",
    "UnreadableState",
    "device_key",
]

class UnreadableState(ValueError):
    """The kept positions of a device cannot be read (not JSON, an entry of the wrong type, a tilt outside
    [-pi, pi]: a hand edit, a bad sector, an older release's checks). Recording positions anew
    (``stickslip where --set``) replaces them; a record of a newer release is a plain ``ValueError``, never
    replaced. ``what``: what cannot be read, without the way out the message adds."""

    def __init__(self, what: str) -> None:
        super().__init__(f"{what}; record them anew with `stickslip where --set J=VALUE` for this device (the joints "
                         "not set are then unreferenced)")
        self.what = what


SOURCES = ("default", "set", "dead-reckoned", "observed", "seen", "assumed")
REFERENCED = ("set", "dead-reckoned", "observed", "seen")
"""The sources of a position that was put somewhere known (not assumed)."""


class StateStore(Protocol):
    """Where per-device state lives (``stickslip.storage.Store`` implements it)."""

    def set_state(self, device: str, key: str, value_json: Any) -> None: ...

    def get_state(self, device: str, key: str, default: Any = None) -> Any: ...


class JsonStateFile:
    """Per-device state in one JSON file ``{device: {key: value}}``, replaced atomically."""

    def __init__(self, path: str | os.PathLike[str]):
        self.path = Path(path).expanduser()

    def _read(self) -> dict[str, dict[str, Any]]:
        if not self.path.exists():
            return {}
        data = read_json(self.path, "device state")  # strict: a key twice, not JSON, a FIFO: refused naming it
        if not isinstance(data, dict):
            raise ValueError(f"{self.path}: expected a JSON object of devices")
        return data

    def get_state(self, device: str, key: str, default: Any = None) -> Any:
        """The value stored under ``key`` for ``device``, or ``default``."""
        return self._read().get(device, {}).get(key, default)

    def set_state(self, device: str, key: str, value_json: Any) -> None:
        """Store ``value_json`` (JSON text or a JSON-serialisable object) for ``device``.

        A NaN or an infinity is refused (``ValueError``), the file left as it was: written, it
        made the file, every device's state in it, unreadable.
        """
        value = loads_json(value_json, f"the state {key!r} of {device}") if isinstance(value_json, str) else value_json
        data = self._read()
        data.setdefault(device, {})[key] = value
        text = dumps_json(data, str(self.path), indent=2)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.path, text)


@dataclass
class DeviceState:
    """Where a device's joints are believed to be, and how its base is tilted.

    Attributes
    ----------
    device : str
        The device URL.
    positions : dict
        ``{1: q1 (rad), 2: q2 (rad), 3: q3 (m)}``.
    sources : dict
        ``{joint: source}``, one of :data:`SOURCES`.
    theta, psi : float
        Base tilt, rad.
    """

    device: str
    positions: dict[int, float] = field(default_factory=dict)
    sources: dict[int, str] = field(default_factory=dict)
    theta: float = 0.0
    psi: float = 0.0
    uncertain: dict[int, tuple[float, float]] = field(default_factory=dict)
    track: dict[int, dict[str, Any]] = field(default_factory=dict)
    """``{joint: JointTrack JSON}``: step scale and position covariance (stickslip.motion.tracking)."""
    why: dict[int, str] = field(default_factory=dict)
    """``{joint: what left it uncertain}`` ("a move was interrupted", "a traverse was interrupted", ...)."""
    claim: dict[int, tuple[float, float]] = field(default_factory=dict)
    """``{joint: (lo, hi)}`` (rad or m): the range a move of this arm claimed before it read the other arms of its
    rig, kept until it ends; the other arms are refused while it is there (see the module docstring)."""
    joints: JointSet = field(default_factory=lambda: kin.JOINTS, compare=False, repr=False)
    """The arm's joints (kinds, ranges): the MM3A's, or an arm's of a rig file. Not stored."""

    @classmethod
    def default(cls, device: str, joints: JointSet | None = None) -> DeviceState:
        """Each joint at its ``home`` (the MM3A outstretched, ``q2 = -pi/2``), level base, nothing known."""
        js = kin.JOINTS if joints is None else joints
        return cls(device, {j: js[j].home for j in (1, 2, 3)}, dict.fromkeys((1, 2, 3), "default"), joints=js)

    def spec(self, joint: int) -> JointSpec:
        """The :class:`~stickslip.joints.JointSpec` of ``joint`` on this arm; ``ValueError`` for no such joint."""
        return kin.joint_spec(joint, self.joints)

    @property
    def pose(self) -> kin.Pose:
        """The pose these positions and this tilt make (joints rad, rad, m; tilt rad)."""
        q = self.positions
        return kin.Pose(q[1], q[2], q[3], self.theta, self.psi)

    def set_position(self, joint: int, q: float, source: str = "set") -> None:
        """Record ``q`` (rad or m) for ``joint``; ``ValueError`` outside its end stops."""
        spec = self.spec(joint)
        q = float(q)
        if spec.range_problem(f"q{spec.number}", q):
            shown = format_position(q, spec) if math.isfinite(q) else repr(q)
            slip = spec.unit_slip(q)  # a Python or JSON number is SI: q2 = -90 meant as degrees
            raise ValueError(
                f"q{spec.number} = {shown} is outside joint {spec.number}'s range "
                f"[{format_position(spec.lower, spec)}, {format_position(spec.upper, spec)}]"
                + (f" ({slip})" if slip else "")
            )
        if source not in SOURCES:
            raise ValueError(f"source must be one of {SOURCES}, got {source!r}")
        self.positions[spec.number] = min(max(q, spec.lower), spec.upper)
        self.sources[spec.number] = source
        self.uncertain.pop(spec.number, None)
        self.why.pop(spec.number, None)
        if source == "set":  # put there by hand: known exactly, scale kept; a claim a move left behind is gone
            self.claim.clear()
            if spec.number in self.track:
                _exact_position(self.track[spec.number])

    def referenced(self, joint: int) -> bool:
        """Whether ``joint`` was put somewhere known (set, observed, or moved by the model since), not uncertain."""
        return joint not in self.uncertain and self.sources.get(joint) in REFERENCED

    def intend(self, joint: int, q_intended: float, why: str = "a move was interrupted") -> None:
        """Journal a burst about to be sent: ``joint`` is in flight to ``q_intended`` (rad or m).

        Until :meth:`set_position` records the confirmed end, the joint is *uncertain*
        between its last confirmed position and ``q_intended``; ``why`` is what a person
        is told if it stays so.
        """
        spec = self.spec(joint)
        q = min(max(float(q_intended), spec.lower), spec.upper)
        confirmed = self.positions[spec.number]
        self.mark_uncertain(joint, min(confirmed, q), max(confirmed, q), why)

    def mark_uncertain(self, joint: int, lo: float, hi: float, why: str) -> None:
        """Record that ``joint`` lies somewhere in ``[lo, hi]`` (rad or m, clipped to its range), and why."""
        spec = self.spec(joint)
        lo, hi = (min(max(float(v), spec.lower), spec.upper) for v in (lo, hi))
        self.uncertain[spec.number] = (min(lo, hi), max(lo, hi))
        self.why[spec.number] = why

    def claim_path(self, path: list[list[float]]) -> None:
        """Claim the range over ``path`` (poses, rad or m) of each joint it moves, with the joint's uncertain
        bounds if it has them: where this arm may be until the move ends (:attr:`claim`)."""
        for j in (1, 2, 3):
            values = [float(p[j - 1]) for p in path]
            if max(values) > min(values):
                lo, hi = self.uncertain.get(j, (self.positions[j], self.positions[j]))
                self.claim[j] = (min(lo, *values), max(hi, *values))

    def bounds(self, joint: int) -> tuple[float, float]:
        """Where ``joint`` may be (rad or m): its uncertain bounds, its position if referenced, else its whole range."""
        if joint in self.uncertain:
            return self.uncertain[joint]
        if self.referenced(joint):
            return (self.positions[joint], self.positions[joint])
        spec = self.spec(joint)
        return (spec.lower, spec.upper)

    def uncertainty_problem(self, joint: int) -> str | None:
        """Why ``joint``'s position cannot be planned from (``None`` if it can)."""
        if joint not in self.uncertain:
            return None
        lo, hi = self.uncertain[joint]
        why = self.why.get(joint, "a move was interrupted")
        return (
            f"joint {joint}'s position is uncertain ({why}): between {format_position(lo, self.spec(joint))} and "
            f"{format_position(hi, self.spec(joint))}; re-reference it at an end stop first, e.g. "
            f"`{where_set_command(self.device, joint)}` after driving it to the lower stop"
        )

    def set_tilt(self, theta: float | None = None, psi: float | None = None) -> None:
        """Record the base tilt (rad, each within [-pi, pi]); ``None`` keeps a value."""
        for name, v in (("theta", theta), ("psi", psi)):
            if v is None:
                continue
            if problem := tilt_problem(name, v):
                raise ValueError(problem)
            setattr(self, name, float(v))

    def to_json(self) -> dict[str, Any]:
        """The JSON shape kept in the store (SI units), format :data:`STATE_VERSION`."""
        return {
            "version": STATE_VERSION,
            "positions": {str(j): self.positions[j] for j in sorted(self.positions)},
            "sources": {str(j): self.sources[j] for j in sorted(self.sources)},
            "theta": self.theta,
            "psi": self.psi,
            "uncertain": {str(j): list(b) for j, b in sorted(self.uncertain.items())},
            "why": {str(j): w for j, w in sorted(self.why.items()) if j in self.uncertain},
            "track": {str(j): t for j, t in sorted(self.track.items())},
        } | ({"claim": {str(j): list(b) for j, b in sorted(self.claim.items())}} if self.claim else {})


def _exact_position(track: dict[str, Any]) -> None:
    """Zero the position's variance and its covariances in a kept track's JSON ``P`` (any square size)."""
    p = track.get("P")
    if isinstance(p, list) and p and all(isinstance(r, list) and len(r) == len(p) for r in p):
        for k in range(len(p)):
            p[0][k] = 0.0
            p[k][0] = 0.0


def _cap_position(track: dict[str, Any], ceiling: float) -> None:
    """A kept track's JSON ``P`` with the position's σ capped at ``ceiling`` (the span), as the filter caps it.

    :meth:`stickslip.motion.tracking.JointTrack.cap_position` on the JSON (this layer sits below the filter's).
    """
    p = track.get("P")
    if isinstance(p, list) and p and all(isinstance(r, list) and len(r) == len(p) for r in p):
        v = p[0][0]
        if isinstance(v, (int, float)) and not isinstance(v, bool) and v > ceiling * ceiling > 0.0:
            _exact_position(track)
            p[0][0] = ceiling * ceiling


_KEY = "positions"
STATE_VERSION = 1
"""Format of the stored positions: a state of a newer stickslip (a higher version) is refused, not guessed at."""


def load_state(store: StateStore, device: str, joints: JointSet | None = None) -> DeviceState:
    """The stored state of ``device`` (the default state if none was stored), an arm of ``joints`` (the MM3A's)."""
    state = DeviceState.default(device, joints)
    raw = store.get_state(device, _KEY)
    if not raw:
        return state
    if isinstance(raw, str):
        try:
            raw = loads_json(raw, f"the stored positions of {device}")
        except ValueError as e:
            raise UnreadableState(str(e)) from None
    check_version(raw, f"the stored positions of {device}", "device state", STATE_VERSION)
    try:
        _read_state(state, raw)
    except (TypeError, ValueError, AttributeError, OverflowError) as e:
        raise UnreadableState(f"the stored positions of {device} are unreadable: {e}") from None
    return state


def _read_state(state: DeviceState, raw: Any) -> None:
    """Fill ``state`` from its stored JSON; ``ValueError`` naming the entry that is not what it must be.

    A finite position outside its joint's range (kept by another arm's rig file, or written by hand) is not
    used as if it were known: the joint is uncertain over its whole range until it is referenced again; a
    claim past a stop claims the joint's whole range, one given high to low is put in order.
    """
    if not isinstance(raw, dict):
        raise ValueError("not an object")
    for j, q in _entries(raw, "positions"):
        state.positions[_stored_joint(state, j)] = _stored_number(q, f"q{j}")
    for j, src in _entries(raw, "sources"):
        state.sources[_stored_joint(state, j)] = str(src)
    state.set_tilt(_stored_number(raw.get("theta", 0.0), "theta"), _stored_number(raw.get("psi", 0.0), "psi"))
    for j, b in _entries(raw, "uncertain"):
        if not isinstance(b, list) or len(b) != 2:
            raise ValueError(f"the uncertain bounds of joint {j} are {b!r}, not a pair of numbers")
        state.uncertain[_stored_joint(state, j)] = (_stored_number(b[0], f"q{j}"), _stored_number(b[1], f"q{j}"))
    for j, b in _entries(raw, "claim"):
        if not isinstance(b, list) or len(b) != 2:
            raise ValueError(f"the claimed range of joint {j} is {b!r}, not a pair of numbers")
        state.claim[_stored_joint(state, j)] = (_stored_number(b[0], f"q{j}"), _stored_number(b[1], f"q{j}"))
    for j, w in _entries(raw, "why"):
        state.why[_stored_joint(state, j)] = str(w)
    for j, t in _entries(raw, "track"):
        if not isinstance(t, dict):
            raise ValueError(f"track of joint {j} is not an object")
        state.track[_stored_joint(state, j)] = t
        _cap_position(t, state.spec(int(j)).span)  # kept before the cap: 58 m on a 12 mm joint
    for joint, (lo, hi) in list(state.claim.items()):  # hand-edited: in order, and never past the joint's stops
        spec = state.spec(joint)
        inside = spec.contains(lo) and spec.contains(hi)
        state.claim[joint] = (min(lo, hi), max(lo, hi)) if inside else (spec.lower, spec.upper)
    for joint in sorted(state.positions):
        spec = state.spec(joint)
        for q in (state.positions[joint], *state.uncertain.get(joint, ())):
            problem = spec.range_problem(f"q{joint}", q)
            if problem:
                state.positions[joint] = min(max(state.positions[joint], spec.lower), spec.upper)
                state.mark_uncertain(joint, spec.lower, spec.upper, f"the stored {problem}")
                break


def _entries(raw: dict[str, Any], name: str) -> list[tuple[str, Any]]:
    """The ``(joint, value)`` pairs of the object ``raw[name]`` (none if it is missing or null)."""
    value = raw.get(name) or {}
    if not isinstance(value, dict):
        raise ValueError(f"{name} is {json_kind(value)}, not an object")
    return list(value.items())


def _stored_joint(state: DeviceState, key: str) -> int:
    if not (str(key).isascii() and str(key).isdigit()):
        raise ValueError(f"{key!r} is not a joint number")
    return state.spec(int(key)).number


def _stored_number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} is {value!r}, not a number")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v):
        raise ValueError(f"{name} is {value!r}, not a finite number")
    return v


def save_state(store: StateStore, state: DeviceState) -> None:
    """Store ``state`` under its device URL."""
    store.set_state(state.device, _KEY, state.to_json())


def where_set_command(device: str, joint: int, value: str = "min") -> str:
    """The ``stickslip where`` line that sets ``joint`` of ``device`` to ``value`` (a stop, or a position).

    It names the device: without ``-d`` the line would set the default device's joint (the config's,
    else ``sim://``), not the one a message is about.
    """
    return f"stickslip where -d {command_url(device)} --set {joint}={value}"
