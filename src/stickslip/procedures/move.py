"""A planned move of one joint: plan from the kept state with the day's step scale, drive in bursts, keep.

:func:`move` is the workflow behind ``stickslip move`` (and what a web page or a camera
loop calls): under the device's lock it reads the kept state, records a new pose if
given, plans the steps with the calibration scaled by the joint's tracked step scale
(:mod:`stickslip.motion.tracking`, learned from ``stickslip observe``), sends them in
bursts and keeps the dead-reckoned position and its growing uncertainty.
:func:`plan_tracked` and :func:`settle` are its two halves for a front end that holds
its own controller (the Bluesky axes).

A move of ``N`` steps is sent in bursts (:func:`drive`). Before each burst the joint is
journalled as *in flight* between its last confirmed position and the burst's intended
end (:meth:`~stickslip.devices.positions.DeviceState.intend`, saved); after the
controller confirms the burst, the dead-reckoned end is saved and the mark cleared. A
link drop, a crash or Ctrl-C between the two leaves the joint *uncertain* with bounds,
which ``stickslip where`` shows and ``stickslip move`` refuses to plan from until the
joint is re-referenced. So the stored position is exact (to the model) or marked, never
silently wrong.

:func:`device_lock` makes sure one process drives a device at a time: a lock row in
the database names the holder (pid, host, since); a second process is refused with
that name. The lock is portable (SQLite transactions, no ``fcntl``).
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

from .. import kinematics as kin
from ..calibration import Calibration
from ..clock import now_utc
from ..devices.base import (
    Controller,
    DeviceError,
    KnowsTruePosition,
    PoseSettable,
    StepsUncertain,
    device_key,
    open_device,
)
from ..devices.positions import DeviceState, StateStore, load_state, save_state
from ..motion.planning import Planner
from ..motion.tracking import JointTrack, joint_sigma_model, scaled_calibration, track_for
from ..units import format_position, position_display_unit
from .conditions import usage_warnings

__all__ = [
    "DeviceBusy",
    "LockStore",
    "MoveOutcome",
    "MoveRefused",
    "MoveRequest",
    "MoveResult",
    "MoveStore",
    "PoseUpdate",
    "TargetOutOfRange",
    "TrackedPlan",
    "device_lock",
    "drive",
    "failure_text",
    "move",
    "plan_tracked",
    "settle",
    "target_of",
    "track_fields",
]


class DeviceBusy(RuntimeError):
    """Another process holds the device's lock (the message names it)."""


class MoveRefused(ValueError):
    """A move that cannot be planned from the kept state (the message says why); nothing was sent."""


class TargetOutOfRange(MoveRefused):
    """The target lies outside the joint's range (the message names both, in display units)."""


class LockStore(Protocol):
    """What :func:`device_lock` needs (``stickslip.storage.Store`` implements it)."""

    def acquire_lock(self, device: str, holder: dict[str, Any]) -> dict[str, Any] | None: ...

    def release_lock(self, device: str, pid: int) -> None: ...


@contextmanager
def device_lock(store: LockStore, device: str) -> Iterator[dict[str, Any]]:
    """Hold ``device``'s lock for the ``with`` block; :class:`DeviceBusy` if another process has it."""
    pid = os.getpid()
    me: dict[str, Any] = {"pid": pid, "host": socket.gethostname(), "since": now_utc().isoformat(timespec="seconds")}
    holder = store.acquire_lock(device, me)
    if holder is not None:
        raise DeviceBusy(
            f"{device} is being driven by another stickslip process (pid {holder.get('pid')} on "
            f"{holder.get('host')} since {holder.get('since')}); wait for it to finish, or if that "
            f"process is gone, release the lock with `stickslip where -d {device} --unlock`"
        )
    try:
        yield me
    finally:
        store.release_lock(device, pid)


class MoveStore(LockStore, StateStore, Protocol):
    """What :func:`move` needs of a store: the device lock and the kept state (``stickslip.storage.Store``)."""


@dataclass
class MoveOutcome:
    """What a :func:`drive` did: steps sent and confirmed, the bursts, the device error if any."""

    sent: int = 0
    bursts: list[int] = field(default_factory=list)
    error: str | None = None


def drive(
    dev: Controller,
    state: DeviceState,
    joint: int,
    steps: int,
    burst: int,
    reckon: Callable[[int], float],
    save: Callable[[DeviceState], None],
) -> MoveOutcome:
    """Send ``steps`` (signed) to ``joint`` in bursts of at most ``burst``, journalling each.

    ``reckon(n)`` is the dead-reckoned position (rad or m) after ``n`` signed steps from
    the start; ``save(state)`` stores the state (one transaction). A :class:`DeviceError`
    stops the loop and is returned in the outcome with the joint left *uncertain* over
    the failed burst; any other exception (Ctrl-C) propagates with the journal saved.
    A :class:`~stickslip.devices.base.StepsUncertain` narrows that: its ``made`` steps
    are kept as dead-reckoned, the joint is uncertain only up to ``at_most`` (up to its
    end stop if ``None``: a channel may still be driving), or not at all if they agree.
    """
    out = MoveOutcome()
    if burst < 1:
        raise ValueError(f"burst must be >= 1 step, got {burst}")
    sign = 1 if steps > 0 else -1
    while out.sent != steps:
        n = sign * min(burst, abs(steps - out.sent))
        state.intend(joint, reckon(out.sent + n))
        save(state)  # write-ahead: intended before it is sent
        try:
            dev.step(joint, n)
        except StepsUncertain as e:
            out.error = str(e)
            if e.made:
                out.sent += e.made
                out.bursts.append(e.made)
                state.set_position(joint, reckon(out.sent), "dead-reckoned")
            else:  # nothing certainly made: back to the confirmed position, then widen below
                state.set_position(joint, state.positions[joint], state.sources[joint])
            if e.at_most is None:
                spec = kin.joint_spec(joint)
                state.intend(joint, spec.upper if sign > 0 else spec.lower)
            elif e.at_most != e.made:
                state.intend(joint, reckon(out.sent - e.made + e.at_most))
            save(state)
            return out
        except DeviceError as e:
            out.error = str(e)
            return out
        out.sent += n
        out.bursts.append(n)
        state.set_position(joint, reckon(out.sent), "dead-reckoned")
        save(state)  # done: the controller confirmed the burst
    return out


# ---------------------------------------------------------------- planning from the kept state


@dataclass(frozen=True)
class PoseUpdate:
    """Joint positions and base tilt to record before planning (rad, rad, m; rad, rad); ``None`` keeps one."""

    q1: float | None = None
    q2: float | None = None
    q3: float | None = None
    theta: float | None = None
    psi: float | None = None

    def apply(self, state: DeviceState) -> list[str]:
        """Record the given values in ``state`` (source ``"set"``); the names changed. ``ValueError`` out of range."""
        changed = []
        for j, v in ((1, self.q1), (2, self.q2), (3, self.q3)):
            if v is not None:
                state.set_position(j, v, "set")
                changed.append(f"q{j}")
        state.set_tilt(self.theta, self.psi)
        return changed + [n for n, v in (("theta", self.theta), ("psi", self.psi)) if v is not None]


def target_of(state: DeviceState, joint: int, by: float | None = None, to: float | None = None) -> tuple[float, float]:
    """``(q_from, q_to)`` of a move of ``joint`` by ``by`` or to ``to`` (rad or m) from its kept position.

    :class:`TargetOutOfRange` if the target lies outside the joint's range.
    """
    if (by is None) == (to is None):
        raise ValueError("give exactly one of by and to")
    spec = kin.joint_spec(joint)
    q_from = state.positions[joint]
    q_to = to if to is not None else q_from + float(by or 0.0)
    if not spec.contains(q_to):
        raise TargetOutOfRange(
            f"the target {format_position(q_to, joint)} is outside joint {joint}'s range "
            f"[{format_position(spec.lower, joint)}, {format_position(spec.upper, joint)}] "
            f"(from {format_position(q_from, joint)}); positions are in {position_display_unit(joint)}"
        )
    return q_from, min(max(q_to, spec.lower), spec.upper)


@dataclass(frozen=True)
class TrackedPlan:
    """A move of one joint planned with the day's tracked step scale.

    Attributes
    ----------
    joint : int
    q_from, q_to : float
        Kept start and target, rad or m.
    steps : int
        Signed steps to send.
    q_end : float
        Predicted end, rad or m (within half a step of ``q_to``).
    calibration : Calibration
        The calibration with the joint's steps scaled by the tracked step scale of each direction.
    pose : Pose
        The kept pose the move is planned in.
    track : JointTrack
        The joint's Kalman state (updated by :func:`settle`).
    note : str or None
        Why the track started again (a scale learned with another calibration), if it did.
    sigma_model : float
        The joint's relative model error (1), the track's process noise for a new pose.
    """

    joint: int
    q_from: float
    q_to: float
    steps: int
    q_end: float
    calibration: Calibration
    pose: kin.Pose
    track: JointTrack
    note: str | None
    sigma_model: float

    def position_after(self, n_signed: int) -> float:
        """The dead-reckoned position (rad or m) after ``n_signed`` steps from the start."""
        return float(Planner(self.calibration, self.joint, self.pose).position_after(self.q_from, n_signed))


def plan_tracked(calibration: Calibration, state: DeviceState, joint: int, q_to: float) -> TrackedPlan:
    """Plan a move of ``joint`` to ``q_to`` (rad or m) from ``state`` with its tracked step scale.

    :class:`MoveRefused` if the joint's position is uncertain (an interrupted move);
    ``KeyError`` if the calibration lacks the joint or direction; ``ValueError`` if the
    kept track is unreadable.
    """
    problem = state.uncertainty_problem(joint)
    if problem:
        raise MoveRefused(problem)
    track, note = track_for(state.track.get(joint), calibration, joint)
    scaled = scaled_calibration(calibration, joint, {d: track.scale_of(d) for d in "+-"})
    q_from = state.positions[joint]
    plan = Planner(scaled, joint, state.pose).plan(q_from, q_to)
    return TrackedPlan(
        joint, q_from, q_to, int(plan.signed_steps), float(plan.q_end_predicted), scaled, state.pose, track, note,
        joint_sigma_model(calibration, joint),
    )


def settle(state: DeviceState, plan: TrackedPlan, outcome: MoveOutcome) -> None:
    """Keep what a driven ``plan`` did: the planned end if it completed, the grown uncertainty if it sent steps."""
    joint = plan.joint
    if outcome.error is None:
        state.set_position(joint, plan.q_end, "dead-reckoned")
    if outcome.sent and joint not in state.uncertain:  # the position's uncertainty grows with the move
        delta = state.positions[joint] - plan.q_from
        plan.track.predict(delta, outcome.sent, plan.pose, joint, plan.sigma_model)
        state.track[joint] = plan.track.to_json()


def failure_text(state: DeviceState, joint: int, error: str, sent: int, steps: int) -> str:
    """One line for a move a device error stopped: what was sent, and what the kept position now is."""
    if joint in state.uncertain:
        lo, hi = state.uncertain[joint]
        kept = (
            f"joint {joint}'s position is now uncertain, between {format_position(lo, joint)} "
            f"and {format_position(hi, joint)}; re-reference it (stickslip where --set {joint}=min "
            f"at the lower stop) before the next move"
        )
    else:
        kept = f"joint {joint}'s dead-reckoned position {format_position(state.positions[joint], joint)} is kept"
    return f"{error}; sent {sent} of {steps} steps; {kept}"


def track_fields(state: DeviceState, joint: int) -> dict[str, float | None]:
    """``sd`` (m or rad) of the kept position and the learned ``step_scale`` (1) of a joint, ``None`` if untracked."""
    raw = state.track.get(joint)
    if raw is None:
        return {"sd": None, "step_scale": None, "step_scale_sd": None}
    try:
        t = JointTrack.from_json(raw)
    except ValueError:
        return {"sd": None, "step_scale": None, "step_scale_sd": None}
    return {"sd": t.sd, "step_scale": t.scale, "step_scale_sd": t.scale_sd}


# ---------------------------------------------------------------- the whole move


@dataclass(frozen=True)
class MoveRequest:
    """A move of one joint on one device.

    Attributes
    ----------
    device : str
        Controller URL (``sim://``, ``mm3a:///dev/ttyUSB0``, ...).
    joint : int
    by, to : float or None
        The displacement or the target, rad or m: exactly one.
    burst : int
        Most steps per burst (1..65535).
    pose : PoseUpdate
        Positions and tilt to record first.
    max_age_days : int
        A calibration older than this is warned about (:func:`~.conditions.usage_warnings`).
    """

    device: str
    joint: int
    by: float | None = None
    to: float | None = None
    burst: int = 1000
    pose: PoseUpdate = PoseUpdate()
    max_age_days: int = 0


@dataclass(frozen=True)
class MoveResult:
    """What :func:`move` did (SI units).

    Attributes
    ----------
    device : str
        The device's key (URL without options or secrets).
    plan : TrackedPlan
    outcome : MoveOutcome
        Steps sent, the bursts, the device error that stopped it (``None`` if it completed).
    state : DeviceState
        The kept state after the move.
    sim_true_end : float or None
        The simulator's true end position (rad or m); ``None`` on a real controller.
    """

    device: str
    plan: TrackedPlan
    outcome: MoveOutcome
    state: DeviceState
    sim_true_end: float | None = None

    def failure(self) -> str | None:
        """The one line of a move a device error stopped (:func:`failure_text`), else ``None``."""
        if self.outcome.error is None:
            return None
        return failure_text(self.state, self.plan.joint, self.outcome.error, self.outcome.sent, self.plan.steps)

    def as_dict(self) -> dict[str, object]:
        """The JSON shape of ``stickslip move --json`` (SI units)."""
        p = self.plan
        out: dict[str, object] = {
            "device": self.device, "joint": p.joint, "direction": "+" if p.steps >= 0 else "-",
            "steps": abs(p.steps), "steps_signed": p.steps, "bursts": list(self.outcome.bursts),
            "q_from": p.q_from, "q_to": p.q_to, "q_end_predicted": p.q_end, "unit": kin.joint_spec(p.joint).unit,
        }
        tf = track_fields(self.state, p.joint)
        if tf["sd"] is not None:
            out.update({"q_sd": tf["sd"], "step_scale": tf["step_scale"], "step_scale_sd": tf["step_scale_sd"]})
        if self.sim_true_end is not None:
            out["sim_true_end"] = self.sim_true_end
        return out


def _nothing() -> None:
    pass


def move(
    store: MoveStore,
    request: MoveRequest,
    calibration: Calibration,
    *,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = _nothing,
    opener: Callable[[str], Controller] | None = None,
) -> MoveResult:
    """Move one joint as ``request`` says, holding the device's lock; the kept state is saved after every burst.

    ``warn(message)`` gets each warning (the track restarted, the calibration's age or
    conditions); ``ready()`` is called once the input is checked, just before the first
    burst (a command prints its warnings there). Refusals raise before anything is sent:
    :class:`DeviceBusy`, :class:`MoveRefused` (:class:`TargetOutOfRange`), ``KeyError`` (a
    joint or direction not calibrated), ``ValueError``, :class:`DeviceError` (the device
    cannot be opened). A device error during the move is returned in the result's
    ``outcome`` (:meth:`MoveResult.failure`), the joint kept honest. ``opener(url)`` opens
    the controller (default :func:`~stickslip.devices.base.open_device`).
    """
    key = device_key(request.device)
    joint = request.joint
    with device_lock(store, key):
        state = load_state(store, key)
        request.pose.apply(state)
        problem = state.uncertainty_problem(joint)
        if problem:
            raise MoveRefused(problem)
        _, q_to = target_of(state, joint, request.by, request.to)
        plan = plan_tracked(calibration, state, joint, q_to)
        if plan.note:
            warn(plan.note)
        save_state(store, state)  # the recorded pose, even if nothing moves
        if not plan.steps:
            for w in usage_warnings(calibration, None, request.device, joint, request.max_age_days):
                warn(w)
            ready()
            return MoveResult(key, plan, MoveOutcome(), state)
        outcome, true_end = _drive_opened(store, request, calibration, state, plan, warn, ready, opener or open_device)
    return MoveResult(key, plan, outcome, state, true_end)


def _drive_opened(
    store: StateStore,
    request: MoveRequest,
    calibration: Calibration,
    state: DeviceState,
    plan: TrackedPlan,
    warn: Callable[[str], None],
    ready: Callable[[], None],
    opener: Callable[[str], Controller],
) -> tuple[MoveOutcome, float | None]:
    """Open the device, send ``plan`` in bursts, keep the state; the outcome and the simulator's true end."""
    dev = opener(request.device)
    try:
        for w in usage_warnings(calibration, dev, request.device, plan.joint, request.max_age_days):
            warn(w)
        ready()  # the input is good: say so before driving
        if isinstance(dev, PoseSettable):  # the simulator: start where the positions say
            dev.set_pose(*plan.pose)
        def save(st: DeviceState) -> None:
            save_state(store, st)

        outcome = drive(dev, state, plan.joint, plan.steps, request.burst, plan.position_after, save)
        settle(state, plan, outcome)
        if outcome.error is None or state.track.get(plan.joint) is not None:
            save_state(store, state)
        true_end = None
        if outcome.error is None and isinstance(dev, KnowsTruePosition):
            true_end = float(dev.position(plan.joint))
        return outcome, true_end
    finally:
        try:
            dev.close()
        except DeviceError:
            pass
