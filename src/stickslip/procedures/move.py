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

import math
import numbers
import os
import socket
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

from .. import kinematics as kin
from ..calibration import Calibration
from ..calibration.update import STEP_NOISE
from ..clock import now_utc
from ..devices.base import (
    Controller,
    DeviceError,
    DrivenElsewhere,
    KnowsTruePosition,
    PoseSettable,
    StepsUncertain,
    check_device_url,
    command_url,
    device_key,
    open_device,
    redact_text,
    url_scheme,
)
from ..devices.identity import open_checked
from ..devices.positions import DeviceState, StateStore, load_state, save_state, where_set_command
from ..joints import JointSet, JointSpec
from ..motion.planning import Planner
from ..motion.tracking import (
    SCALE_CORRELATION,
    SCALE_WALK,
    JointTrack,
    joint_sigma_model,
    scaled_calibration,
    track_for,
)
from ..processes import holder_running
from ..rig.envelope import EnvelopeViolation, SigmaGrowth
from ..rig.guard import Guard
from ..units import format_position, position_display_unit
from .conditions import calibration_device_problem, usage_warnings

__all__ = [
    "DeviceBusy",
    "Interrupted",
    "LockStore",
    "MoveOutcome",
    "MoveRefused",
    "MoveRequest",
    "MoveResult",
    "MoveStore",
    "PoseUpdate",
    "TargetOutOfRange",
    "TrackedPlan",
    "check_envelope",
    "check_envelope_path",
    "claim_and_check",
    "claimed",
    "joint_line",
    "device_lock",
    "holder_text",
    "drive",
    "exact_positions",
    "failure_text",
    "kept_after_interrupt",
    "mark_claim",
    "move",
    "plan_tracked",
    "reference_commands",
    "reference_problem",
    "release_claim",
    "sharing_controller",
    "step_joint",
    "steps_to_stop",
    "settle",
    "grow_track",
    "sigma_growth",
    "simulates",
    "target_of",
    "track_fields",
    "tracked_calibration",
    "where_line",
    "with_kept_positions",
    "within_stops",
]


class DeviceBusy(RuntimeError):
    """Another process holds the device's lock (the message names it)."""


class MoveRefused(ValueError):
    """A move that cannot be planned from the kept state (the message says why); nothing was sent."""


class TargetOutOfRange(MoveRefused):
    """The target lies outside the joint's range (the message names both, in display units)."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C stopped a workflow that drives a device: ``what`` it was, and the ``state`` kept after it.

    A :class:`KeyboardInterrupt`, so code that knows nothing of it still sees Ctrl-C. The
    journal was saved before every burst: ``state`` (read back from the store) says where
    each joint stands, exactly or uncertain with bounds (:func:`where_line`).
    """

    def __init__(self, what: str, state: DeviceState | None):
        super().__init__(what)
        self.what = what
        self.state = state


def where_line(state: DeviceState) -> str:
    """Where each joint of ``state`` stands, for one line: ``joint 3 12 µm (set)``, or uncertain with bounds."""
    parts = []
    for j in (1, 2, 3):
        if j in state.uncertain:
            lo, hi = state.uncertain[j]
            parts.append(f"joint {j} uncertain, {format_position(lo, state.spec(j))} to "
                         f"{format_position(hi, state.spec(j))}")
        else:
            parts.append(f"joint {j} {format_position(state.positions[j], state.spec(j))} ({state.sources[j]})")
    for j, (lo, hi) in sorted(state.claim.items()):  # kept until the move ends: a move running, or one killed
        parts.append(f"claimed by a move: joint {j} {format_position(lo, state.spec(j))} to "
                     f"{format_position(hi, state.spec(j))}")
    return "; ".join(parts)


def kept_after_interrupt(store: StateStore, key: str, state: DeviceState) -> DeviceState:
    """The state as stored after Ctrl-C (what the next command will read), else the one in memory."""
    try:
        return load_state(store, key)
    except (OSError, ValueError):
        return state


class LockStore(Protocol):
    """What :func:`device_lock` needs (``stickslip.storage.Store`` implements it)."""

    def acquire_lock(self, device: str, holder: dict[str, Any]) -> dict[str, Any] | None: ...

    def release_lock(self, device: str, pid: int) -> None: ...


def holder_text(holder: dict[str, Any]) -> str:
    """``pid P on HOST since T`` of a lock's holder, ``?`` for a field a hand-edited or older row lacks."""
    pid, host, since = (holder.get(k) for k in ("pid", "host", "since"))
    shown = ["?" if v is None or v == "" else redact_text(str(v))[:80] for v in (pid, host, since)]
    return f"pid {shown[0]} on {shown[1]} since {shown[2]}"


@contextmanager
def device_lock(store: LockStore, device: str) -> Iterator[dict[str, Any]]:
    """Hold ``device``'s lock for the ``with`` block; :class:`DeviceBusy` if another process has it."""
    pid = os.getpid()
    me: dict[str, Any] = {"pid": pid, "host": socket.gethostname(), "since": now_utc().isoformat(timespec="seconds")}
    holder = store.acquire_lock(device, me)
    if holder is not None and holder.get("pid") == pid and holder.get("host") == me["host"]:
        raise DeviceBusy(
            f"{device} is being driven by this same process, through another link to it (since "
            f"{holder.get('since')}; two StickSlipAxis on one URL?): give the arm's axes one DeviceLink "
            f"(StickSlipManipulator does); do not unlock it while that move runs"
        )
    if holder is not None:
        way_out = (  # --unlock refuses a holder known to run here (stickslip.processes): do not advise it
            "it is still running on this computer: wait for it to finish, or end it" if holder_running(holder)
            else f"wait for it to finish, or if that process is gone, release the lock with "
                 f"`stickslip where -d {command_url(device)} --unlock`"
        )
        raise DeviceBusy(
            f"{device} is being driven by another stickslip process ({holder_text(holder)}); {way_out}"
        )
    try:
        yield me
    except BaseException:
        try:
            store.release_lock(device, pid)
        except OSError:  # the store failed already (a disk still full): its error, not this one, says what was kept
            pass  # the row names this process; once it has ended it is taken over (where --unlock elsewhere)
        raise
    store.release_lock(device, pid)


class MoveStore(LockStore, StateStore, Protocol):
    """What :func:`move` needs of a store: the device lock and the kept state (``stickslip.storage.Store``)."""


@dataclass
class MoveOutcome:
    """What a :func:`drive` did: steps sent and confirmed, the bursts, the device error if any."""

    sent: int = 0
    bursts: list[int] = field(default_factory=list)
    error: str | None = None


DRIVER_FAILURES: tuple[type[Exception], ...] = (OSError, ValueError, RuntimeError, LookupError, ArithmeticError)
"""What a driver's ``step`` may raise of its own, beside :class:`DeviceError` (a port's OSError, a parser's
ValueError or IndexError, a third-party backend's RuntimeError): a failed burst, ended and said as one."""


def drive(
    dev: Controller,
    state: DeviceState,
    joint: int,
    steps: int,
    burst: int,
    reckon: Callable[[int], float],
    save: Callable[[DeviceState], None],
    source: str = "dead-reckoned",
) -> MoveOutcome:
    """Send ``steps`` (signed) to ``joint`` in bursts of at most ``burst``, journalling each.

    ``reckon(n)`` is the dead-reckoned position (rad or m) after ``n`` signed steps from
    the start, kept with ``source`` (``"assumed"`` for a start never referenced);
    ``save(state)`` stores the state (one transaction). A :class:`DeviceError`, or one of
    :data:`DRIVER_FAILURES` from the driver's ``step`` (its own failure), stops the loop and
    is returned in the outcome with the joint left *uncertain* over the failed burst; any
    other exception (Ctrl-C, a front end's stop) propagates with the journal saved.
    A :class:`~stickslip.devices.base.StepsUncertain` narrows that: its ``made`` steps
    are kept as dead-reckoned, the joint is uncertain only up to ``at_most`` (up to its
    end stop if ``None``: a channel may still be driving; over its whole range for a
    :class:`~stickslip.devices.base.DrivenElsewhere`), or not at all if they agree.
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
                state.set_position(joint, reckon(out.sent), source)
            else:  # nothing certainly made: back to the confirmed position, then widen below
                state.set_position(joint, state.positions[joint], state.sources[joint])
            if isinstance(e, DrivenElsewhere):  # another program drives it, either way: anywhere in its range
                spec = state.spec(joint)
                state.mark_uncertain(joint, spec.lower, spec.upper, "another program drove it during a move")
            elif e.at_most is None:
                spec = state.spec(joint)
                state.intend(joint, spec.upper if sign > 0 else spec.lower)
            elif e.at_most != e.made:
                state.intend(joint, reckon(out.sent - e.made + e.at_most))
            save(state)
            return out
        except DeviceError as e:
            out.error = str(e)
            return out
        except DRIVER_FAILURES as e:  # a driver's unforeseen failure (a third-party backend's RuntimeError, an
            # OSError of its port, a parser's ValueError) after some bursts is a failed burst too: the move ends
            # saying what moved and what is uncertain, not with a traceback or a bare "Input/output error" that
            # reads as nothing moved. Other exceptions (a front end's stop signal, Ctrl-C) pass, journal saved.
            out.error = f"the device's driver failed ({type(e).__name__}: {redact_text(str(e)) or 'no message'})"
            return out
        out.sent += n
        out.bursts.append(n)
        state.set_position(joint, reckon(out.sent), source)
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
    spec = state.spec(joint)
    for name, v in (("by", by), ("to", to)):  # by="0.5deg" was "could not convert string to float", by="0.01" taken
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise TypeError(f"{name} = {v!r} must be a number in {spec.unit} (SI; stickslip.units parses '0.5deg')")
        if not math.isfinite(v):
            raise ValueError(f"{name} = {v!r} must be a finite number in {spec.unit}")
    q_from = state.positions[joint]
    q_to = to if to is not None else q_from + float(by or 0.0)
    if not spec.contains(q_to):
        slip = spec.unit_slip(q_to) if to is not None else None  # JSON and Python numbers are SI: -60 meant as deg
        raise TargetOutOfRange(
            f"the target {format_position(q_to, spec)} is outside joint {joint}'s range "
            f"[{format_position(spec.lower, spec)}, {format_position(spec.upper, spec)}] "
            f"(from {format_position(q_from, spec)}); positions are in {position_display_unit(spec)}"
            + (f" ({slip})" if slip else "")
        )
    return q_from, min(max(q_to, spec.lower), spec.upper)


def within_stops(joint: int | JointSpec, q: float) -> float:
    """``q`` (rad or m) held within ``joint``'s end stops (the MM3A's joint, or an arm's own spec): where dead
    reckoning past a stop leaves the joint.

    A planned move rounds to whole steps, so its predicted end may lie up to half a step
    beyond its target; when the target is an end stop that is beyond the stop, where the
    joint cannot be (its slider slips at the stop). The kept position is then the stop;
    its σ stays what the track says (the stop was not heard, only predicted).
    """
    spec = kin.joint_spec(joint) if isinstance(joint, int) else joint
    return float(min(max(float(q), spec.lower), spec.upper))


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
    assumed : bool
        Planned from a position never referenced (``--from-unreferenced``): the end is kept
        as ``"assumed"``, not known.
    from_uncertain : tuple of 2 floats or None
        The bounds (rad or m) of an uncertain start planned from its last confirmed
        position (``--from-unreferenced``); the end stays uncertain, the bounds moved along.
    spec : JointSpec or None
        The arm's joint when it is not the MM3A's (a rig file's arm); ``None``: the MM3A's.
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
    assumed: bool = False
    from_uncertain: tuple[float, float] | None = None
    spec: JointSpec | None = None

    def position_after(self, n_signed: int, q_start: float | None = None) -> float:
        """The dead-reckoned position (rad or m) after ``n_signed`` steps from ``q_start`` (default: the start).

        Held at the joint's end stops (:func:`within_stops`): steps that would carry it past
        a stop slip there.
        """
        q0 = self.q_from if q_start is None else q_start
        spec = self.spec or self.joint
        return within_stops(spec, Planner(self.calibration, spec, self.pose).position_after(q0, n_signed))

    def bounds_after(self, n_signed: int) -> tuple[float, float] | None:
        """Where an uncertain start's bounds are after ``n_signed`` steps (rad or m); ``None`` for a known start."""
        if self.from_uncertain is None:
            return None
        lo, hi = (self.position_after(n_signed, q) for q in self.from_uncertain)
        return (min(lo, hi), max(lo, hi))


def plan_tracked(
    calibration: Calibration,
    state: DeviceState,
    joint: int,
    q_to: float,
    *,
    from_unreferenced: bool = False,
    assumed: bool | None = None,
) -> TrackedPlan:
    """Plan a move of ``joint`` to ``q_to`` (rad or m) from ``state`` with its tracked step scale.

    :class:`MoveRefused` if the joint's position is uncertain (an interrupted move),
    unless ``from_unreferenced``: then the move is planned from its last confirmed
    position and its bounds move along (:attr:`TrackedPlan.from_uncertain`). ``KeyError``
    if the calibration lacks the joint or direction; ``ValueError`` if the kept track is
    unreadable. Whether a joint never referenced may be planned from is the caller's
    check (:func:`reference_problem`); ``assumed`` says whether its end is then kept as
    assumed (default: its source is ``default`` or ``assumed``; the simulator's positions
    are exact, so a caller that knows it drives one passes ``False``).
    """
    problem = state.uncertainty_problem(joint)
    if problem and not from_unreferenced:
        raise MoveRefused(problem)
    track, note = track_for(state.track.get(joint), calibration, joint)
    scaled = scaled_calibration(calibration, joint, {d: track.scale_of(d) for d in "+-"})
    q_from = state.positions[joint]
    spec = state.spec(joint)
    own = None if spec is kin.joint_spec(joint) else spec  # an arm's own joint (a rig file's), else the MM3A's
    plan = Planner(scaled, spec, state.pose).plan(q_from, q_to)
    return TrackedPlan(
        joint, q_from, q_to, int(plan.signed_steps), within_stops(spec, plan.q_end_predicted), scaled, state.pose,
        track, note,
        joint_sigma_model(calibration, joint, state.pose),  # the model error in this pose (docs/models.md §4)
        assumed=state.sources[joint] in ("default", "assumed") if assumed is None else assumed,
        from_uncertain=state.uncertain.get(joint), spec=own,
    )


def tracked_calibration(calibration: Calibration, state: DeviceState) -> Calibration:
    """``calibration`` with each joint's steps scaled by its kept track's step scale, as :func:`plan_tracked` plans one.

    For the moves of several joints at once (a reach, a tip move): planned and dead-reckoned
    with the scale ``observe`` taught, as a ``move`` of each joint would be. A joint without a
    track, or whose track was learnt with another calibration (:func:`track_for`), keeps scale 1.
    ``ValueError`` if a kept track is unreadable.
    """
    scaled = calibration
    for joint in sorted(state.track):
        track, _ = track_for(state.track.get(joint), calibration, joint)
        scaled = scaled_calibration(scaled, joint, {d: track.scale_of(d) for d in "+-"})
    return scaled


def settle(state: DeviceState, plan: TrackedPlan, outcome: MoveOutcome) -> None:
    """Keep what a driven ``plan`` did: the planned end if it completed, the grown uncertainty if it sent steps.

    A start never referenced ends ``"assumed"``; an uncertain start stays uncertain, its
    bounds moved by the steps sent (and widened over a burst that failed).
    """
    joint = plan.joint
    moved = plan.bounds_after(outcome.sent)
    if outcome.error is None:
        state.set_position(joint, plan.q_end, "assumed" if plan.assumed else "dead-reckoned")
    if moved is not None:
        lo, hi = moved
        if joint in state.uncertain:  # a failed burst: it may be anywhere it could have gone
            lo, hi = min(lo, state.uncertain[joint][0]), max(hi, state.uncertain[joint][1])
        state.mark_uncertain(joint, lo, hi, "moved from an uncertain position")
        return
    if outcome.sent and joint not in state.uncertain and not plan.assumed:  # the uncertainty grows with the move
        delta = state.positions[joint] - plan.q_from
        plan.track.predict(delta, outcome.sent, plan.pose, joint, plan.sigma_model, ceiling=state.spec(joint).span)
        state.track[joint] = plan.track.to_json()


def grow_track(
    state: DeviceState, joint: int, q_from: float, sent: int, calibration: Calibration, pose: kin.Pose,
    assumed: bool, seen: set[int],
) -> bool:
    """Grow ``joint``'s Kalman track over ``sent`` steps driven from ``q_from`` (rad or m), as :func:`settle` does.

    For the moves driven without a :class:`TrackedPlan` (a reach's segments, a jog's
    ticks): the displacement is the kept position's change; ``pose`` the kept pose the
    steps were planned in. The model's error in a new pose is added at the joint's first
    move in a new pose of the reach or jog session only (``seen``: the joints that had it, updated), as
    :class:`~stickslip.rig.envelope.SigmaGrowth` predicts: one bias over a path's nearby
    poses. Nothing for an uncertain joint or an ``assumed`` start (never referenced), as
    for a move. Returns whether the track changed (the caller saves it).
    """
    if sent == 0 or joint in state.uncertain or assumed:
        return False
    track, _ = track_for(state.track.get(joint), calibration, joint)
    model = 0.0 if joint in seen else joint_sigma_model(calibration, joint, pose)
    before = track.pose
    track.predict(state.positions[joint] - q_from, sent, pose, joint, model, ceiling=state.spec(joint).span)
    if before is not None and track.pose != before:  # a new pose: its error was added now
        seen.add(joint)
    state.track[joint] = track.to_json()
    return True


def steps_to_stop(joint: int, calibration: Calibration | None = None, spec: JointSpec | None = None) -> int:
    """Steps that surely drive ``joint`` from anywhere into an end stop: 1.2 x its range over its smallest step.

    The smallest step is the calibration's constant step of either direction, else the
    joint's nominal step (:attr:`~stickslip.joints.JointSpec.small_step`: a rig file's
    ``step``, else :data:`~stickslip.joints.NOMINAL_STEP` of its kind); rounded up to a
    thousand. At the stop the slider slips: the steps beyond it do no harm (a traverse
    steps into its stop the same way). ``spec``: the arm's joint (default the MM3A's).
    """
    spec = spec or kin.joint_spec(joint)
    steps = [v for (j, _), v in (calibration.constant_steps.items() if calibration else ()) if j == joint and v > 0]
    small = min(steps) if steps else spec.small_step
    return int(math.ceil(1.2 * spec.span / small / 1000.0)) * 1000


def simulates(dev: Controller, state: DeviceState) -> bool:
    """Whether ``dev`` is the simulator and its arm (an MM3A) stands for ``state``'s arm.

    The simulator is placed at the kept positions and knows its true joints; an arm whose
    joints are not the MM3A's kind (a rig file's ``xyz`` stage) is not what it simulates,
    so neither is used for it (its positions are dead-reckoned as on a real controller).
    """
    return isinstance(dev, PoseSettable) and all(state.spec(j).step_model == "paper" for j in (1, 2, 3))


def exact_positions(dev: Controller, state: DeviceState, joint: int) -> bool:
    """Whether a move of ``joint`` on ``dev`` starts from a known position: referenced, or on the simulator.

    A simulator is placed at the kept positions (:class:`~stickslip.devices.base.PoseSettable`),
    so they are exact there (:func:`simulates`); on a real controller a position never
    referenced is assumed.
    """
    return simulates(dev, state) or state.sources[joint] not in ("default", "assumed")


def is_simulator(url: str) -> bool:
    """Whether ``url`` opens the simulator, which is placed at the kept positions (so they are exact)."""
    return url_scheme(url) in ("sim", "sim+physics")


def reference_commands(
    device: str, joint: int, calibration: Calibration | None = None, spec: JointSpec | None = None
) -> str:
    """The two commands that reference ``joint``: raw steps into its lower stop, then ``where --set J=min``.

    ``ValueError`` for a URL that could never open (:func:`~stickslip.devices.base.check_device_url`): advice
    to type a command with it would only fail next (``anc300://H?axes=1,1,2``).
    """
    check_device_url(device)
    n = steps_to_stop(joint, calibration, spec)  # (command_url and where_set_command redact the URL)
    return (
        f"`stickslip move -d {command_url(device)} --joint {joint} --steps -{n}` (into its lower stop: more steps "
        f"than its range; the slider slips at the stop), then `{where_set_command(device, joint)}`"
    )


def reference_problem(
    state: DeviceState, joint: int, device: str, calibration: Calibration | None = None, from_uncertain: bool = True
) -> str | None:
    """Why a planned move of ``joint`` needs ``--from-unreferenced`` (``None`` if it does not).

    A joint whose position is uncertain, or was never referenced (its position assumed),
    is not planned from on a real controller; the reason names the commands that
    reference it. The simulator is placed at the kept positions, so they are never made
    up there (an uncertain joint is refused there too, by :func:`plan_tracked`).
    ``from_uncertain``: whether the option may plan from an uncertain position (a
    single-joint move) or not (a tip move: it needs all three joints known).
    """
    simulated = is_simulator(device) and all(state.spec(j).step_model == "paper" for j in (1, 2, 3))
    if simulated or state.referenced(joint):
        return None
    spec = state.spec(joint)
    how = reference_commands(device, joint, calibration, spec)
    if joint in state.uncertain:
        lo, hi = state.uncertain[joint]
        why = state.why.get(joint, "a move was interrupted")
        option = (
            f"; or pass --from-unreferenced to plan from {format_position(state.positions[joint], spec)} "
            "(it stays uncertain)" if from_uncertain else ""
        )
        return (
            f"joint {joint}'s position is uncertain ({why}): between {format_position(lo, spec)} and "
            f"{format_position(hi, spec)}; reference it: {how}{option}"
        )
    return (
        f"joint {joint} was never referenced: its position {format_position(state.positions[joint], spec)} is "
        f"assumed, not known; reference it: {how}; or pass --from-unreferenced to plan from the assumed position"
    )


def sent_text(sent: int, steps: int, what: str = "steps", unknown: bool = True) -> str:
    """How much of a move a device error let through: the confirmed count, and (``unknown``) that the burst under
    way when it failed may have moved the joint in part (its steps are not counted, the kept bounds cover them)."""
    return f"{sent} of {steps:+d} {what} confirmed" + (" (the burst under way may have moved the joint in part)"
                                                     if unknown else "")


def failure_text(state: DeviceState, joint: int, error: str, sent: int, steps: int) -> str:
    """One line for a move a device error stopped: what was sent, and what the kept position now is."""
    spec = state.spec(joint)
    if joint in state.uncertain:
        lo, hi = state.uncertain[joint]
        kept = (
            f"joint {joint}'s position is now uncertain, between {format_position(lo, spec)} "
            f"and {format_position(hi, spec)}; re-reference it ({where_set_command(state.device, joint)} "
            f"at the lower stop) before the next move"
        )
    else:
        kept = f"joint {joint}'s dead-reckoned position {format_position(state.positions[joint], spec)} is kept"
    return f"{error}; {sent_text(sent, steps, unknown=joint in state.uncertain)}; {kept}"


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


def sigma_growth(state: DeviceState, calibration: Calibration | None = None) -> SigmaGrowth:
    """Each joint's position σ along a planned path as its Kalman track predicts it.

    The :class:`~stickslip.rig.envelope.SigmaGrowth` a path is checked with.

    From the kept tracks (the position's and the step scales' covariance); with
    ``calibration``, a joint's track as a move with it would use it (:func:`track_for`: a
    fresh one where none is kept or it was learned with another calibration), its steps
    (the larger constant step of its two directions) and its model error. Without one, a
    joint with no track keeps σ 0 and its nominal step (:attr:`~stickslip.joints.JointSpec.small_step`).
    A joint whose position is uncertain (``state.uncertain``: planned from its last value with
    ``--from-unreferenced``) has the farthest it may be from that value added to its σ, so
    ``n_sigma`` ≥ 1 σ margins cover where it may be (its tip σ is the Jacobian's, at least the
    chord a rotary joint turns).
    """
    P, steps, models, poses = [], [], [], []
    for j in (1, 2, 3):
        raw = state.track.get(j)
        track: JointTrack | None = None
        try:
            if calibration is not None and j in {jj for jj, _ in calibration.models}:
                track, _ = track_for(raw, calibration, j)
            elif raw is not None:
                track = JointTrack.from_json(raw)
        except ValueError:
            track = None
        r0, r1, r2 = ((0.0, 0.0, 0.0),) * 3 if track is None else (
            (float(r[0]), float(r[1]), float(r[2])) for r in track.P)
        if j in state.uncertain:  # known only within bounds: the farthest it may be from its kept value is one σ
            lo, hi = state.uncertain[j]
            far = max(state.positions[j] - lo, hi - state.positions[j], 0.0)
            r0 = (r0[0] + far * far, r0[1], r0[2])
        P.append((r0, r1, r2))
        known = [v for (jj, _), v in (calibration.constant_steps.items() if calibration else ()) if jj == j and v > 0]
        steps.append(max(known) if known else state.spec(j).small_step)
        models.append(joint_sigma_model(calibration, j) if calibration is not None and track is not None else 0.0)
        pose = track.pose if track is not None else None
        poses.append(None if pose is None else (float(pose[0]), float(pose[1]), float(pose[2])))
    return SigmaGrowth(
        tuple(P), (steps[0], steps[1], steps[2]), STEP_NOISE, SCALE_WALK, (models[0], models[1], models[2]),
        SCALE_CORRELATION, tuple(poses),
    )


def check_envelope(
    guard: Guard | None, state: DeviceState, joint: int, q_to: float, calibration: Calibration | None = None
) -> None:
    """The planning step's one call into a rig's envelope: :class:`MoveRefused` naming the obstacle, else nothing.

    The move of ``joint`` from the kept pose to ``q_to`` (rad or m), with each joint's σ
    as its Kalman track predicts it along the move as the margin (:func:`sigma_growth`,
    :func:`stickslip.rig.envelope.check_path`); no guard, no check.
    """
    check_envelope_path(guard, state, joint_line(state, joint, q_to), calibration)


def joint_line(state: DeviceState, joint: int, q_to: float) -> list[list[float]]:
    """The path of a move of ``joint`` from the kept pose to ``q_to`` (rad or m): its two ends."""
    q = [state.positions[j] for j in (1, 2, 3)]
    end = list(q)
    end[joint - 1] = q_to
    return [q, end]


def check_envelope_path(
    guard: Guard | None, state: DeviceState, path: Sequence[Sequence[float]], calibration: Calibration | None = None
) -> None:
    """A whole planned path (poses, rad or m) against a rig's envelope: :class:`MoveRefused`, else nothing.

    The σ margin grows along the path as the joints' Kalman tracks predict
    (:func:`sigma_growth`).
    """
    if guard is None:
        return
    try:
        guard.check(path, sigma_growth(state, calibration))
    except EnvelopeViolation as e:
        raise MoveRefused(f"refused by the rig's envelope: {e}") from None


@contextmanager
def claimed(
    store: StateStore, state: DeviceState, guard: Guard | None, path: Sequence[Sequence[float]],
    calibration: Calibration | None = None, *, check: Callable[[Guard | None], None] | None = None,
) -> Iterator[None]:
    """Check ``path`` against a rig's envelope by "mark, then check" (:func:`claim_and_check`, ``check`` its
    check), and keep the claim for the ``with`` block (the move: every burst's save keeps it, so the gap between
    one burst's "done" and the next one's mark is covered); it is cleared from the store when the block ends,
    however it ends."""
    claim_and_check(store, state, guard, path, calibration, check=check)
    try:
        yield
    finally:
        if state.claim:
            release_claim(store, state)


def claim_and_check(
    store: StateStore, state: DeviceState, guard: Guard | None, path: Sequence[Sequence[float]],
    calibration: Calibration | None = None, *, check: Callable[[Guard | None], None] | None = None,
    widen: bool = False,
) -> None:
    """A path of a rig's arm checked by "mark, then check": :class:`MoveRefused`, else the range claimed.

    ``path`` is checked against ``guard`` as it is; then the range each joint sweeps along it is
    journalled as this arm's claim (:meth:`DeviceState.claim_path`, one transaction, nothing else
    of ``state`` written) *before* the other arms are read again (``guard.fresh``) and the path checked
    against them. Of two moves of a rig started at once, each writes its claim before it reads,
    so at least one sees the other's (both may be refused: safe). A refused path's claim is taken
    back in one transaction, so it blocks nobody. No guard (or one with no ``fresh``): the plain check.

    ``check(guard)`` checks the path (default :func:`check_envelope_path`; the closed loop's legs give
    their own margin and refusal). ``widen``: a part of a move that holds its claim already (a closed
    loop's leg): the claim is widened to hold ``path`` too (written first when it grows), then the other
    arms are read again and ``path`` checked against them; a refusal takes the whole claim back.
    """
    def checked(g: Guard | None) -> None:
        if check is None:
            check_envelope_path(g, state, path, calibration)
        else:
            check(g)

    if guard is None or guard.fresh is None:
        checked(guard)
        return
    before = dict(state.claim) if widen else {}
    if before:  # a leg of a move that holds its claim: its range added to the claim, never put in its place
        state.claim_path([list(p) for p in path])
        for j, (lo, hi) in before.items():
            a, b = state.claim.get(j, (lo, hi))
            state.claim[j] = (min(a, lo), max(b, hi))
        if state.claim != before:
            _store_claim(store, state)
    else:
        checked(guard)
        mark_claim(store, state, path)
        if not state.claim:
            return
    try:
        checked(guard.fresh())
    except BaseException:
        release_claim(store, state)
        raise


def mark_claim(store: StateStore, state: DeviceState, path: Sequence[Sequence[float]]) -> None:
    """Claim the range ``path`` (poses, rad or m) sweeps in place of the claim ``state`` holds, and write it (one
    transaction) before the other arms are read: what a jog's tick does ("mark, then check", taken back by
    :func:`release_claim`); a path that moves no joint claims nothing."""
    state.claim.clear()
    state.claim_path([list(p) for p in path])
    if state.claim:
        _store_claim(store, state)


def _store_claim(store: StateStore, state: DeviceState) -> None:
    """Write ``state``'s claim into the kept state (read back: what ``state`` changed but did not save stays
    unsaved, e.g. a pose update of a move that may yet be refused)."""
    kept = load_state(store, state.device, state.joints)
    kept.claim = dict(state.claim)
    save_state(store, kept)


def release_claim(store: StateStore, state: DeviceState) -> None:
    """Take back ``state``'s claim, in memory and in the store (one transaction). A store that cannot be written
    leaves it there: the other arms stay refused (safe) until this arm moves again or is re-referenced."""
    state.claim.clear()
    try:
        kept = load_state(store, state.device, state.joints)
        if kept.claim:
            kept.claim.clear()
            save_state(store, kept)
    except (OSError, ValueError):
        pass


def sharing_controller(store: StateStore, guard: Guard | None) -> list[DeviceState]:
    """The kept states of the rig's other arms on ``guard``'s arm's controller (a rig file's two stacks on one MCS2,
    each under ``KEY#arm=NAME``), for :func:`~stickslip.devices.identity.open_checked`: another controller found
    at that URL leaves theirs uncertain too, so this arm's envelope is not checked against positions another
    controller's arms were kept at. None without a rig (the controller's lock, held, keeps them still)."""
    if guard is None:
        return []
    me = guard.rig.arm(guard.arm)
    key = device_key(me.controller)
    return [load_state(store, guard.rig.state_key(o.name), o.joint_specs())
            for o in guard.rig.arms if o.name != me.name and device_key(o.controller) == key]


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
    from_unreferenced : bool
        Plan from a position never referenced (assumed) or uncertain (the last confirmed);
        without it such a joint is refused on a real controller (:func:`reference_problem`).
    trust_calibration : bool
        Use a calibration that does not record its device, or was made on the simulator,
        on a real controller (refused without it:
        :func:`~.conditions.calibration_device_problem`).
    guard : Guard or None
        A rig's envelope for this arm (:mod:`stickslip.rig`): the planned move is checked
        against it before a step is sent (:func:`check_envelope`).
    joints : JointSet or None
        The arm's joints (kinds, ranges, nominal steps: :meth:`stickslip.rig.Arm.joint_specs`);
        ``None``: the MM3A's (:data:`stickslip.joints.JOINTS`).
    state_key : str or None
        The key the arm's positions and journal are kept under (:meth:`stickslip.rig.Rig.state_key`:
        two arms on one controller); ``None``: the device's key. The lock is the device's either way.
    """

    device: str
    joint: int
    by: float | None = None
    to: float | None = None
    burst: int = 1000
    pose: PoseUpdate = PoseUpdate()
    max_age_days: int = 0
    from_unreferenced: bool = False
    trust_calibration: bool = False
    guard: Guard | None = None
    joints: JointSet | None = None
    state_key: str | None = None


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
            "q_from": p.q_from, "q_to": p.q_to, "q_end_predicted": p.q_end, "unit": self.state.spec(p.joint).unit,
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
    lock = device_key(request.device)
    key = request.state_key or lock
    joint = request.joint
    made_on = calibration_device_problem(calibration, request.device)
    if made_on and not request.trust_calibration:
        raise MoveRefused(made_on)
    with device_lock(store, lock):
        state = load_state(store, key, request.joints)
        try:
            request.pose.apply(state)
            problem = reference_problem(state, joint, request.device, calibration)
            if problem and not request.from_unreferenced:
                raise MoveRefused(problem)
            _, q_to = target_of(state, joint, request.by, request.to)
            plan = plan_tracked(
                calibration, state, joint, q_to, from_unreferenced=request.from_unreferenced,
                assumed=problem is not None and joint not in state.uncertain,
            )
            with claimed(store, state, request.guard, joint_line(state, joint, plan.q_to), calibration):
                if plan.note:
                    warn(plan.note)
                save_state(store, state)  # the recorded pose, even if nothing moves
                if not plan.steps:
                    for w in usage_warnings(calibration, None, request.device, joint, request.max_age_days):
                        warn(w)
                    ready()
                    return MoveResult(key, plan, MoveOutcome(), state)
                outcome, true_end = _drive_opened(
                    store, request, calibration, state, plan, warn, ready, opener or open_device
                )
        except KeyboardInterrupt:
            raise Interrupted(f"move of joint {joint}", kept_after_interrupt(store, key, state)) from None
        except OSError as e:  # the store failed mid-move (a full disk): bursts may have been sent
            raise with_kept_positions(e, store, key, f"the move of joint {joint}") from None
    return MoveResult(key, plan, outcome, state, true_end)


def with_kept_positions(e: OSError, store: StateStore, key: str, what: str) -> OSError:
    """``e`` (a store that could not be written mid-move) with where each joint stands as kept, read back.

    Its own words ("nothing of this change was stored") are of the one write that failed:
    bursts sent before it moved the joint, and the journal (written before each burst) keeps
    it exact or uncertain with bounds. A message that cannot be extended is ``e`` as it was.
    """
    if type(e).__init__ is not OSError.__init__ or len(e.args) != 1:
        return e
    try:
        kept = where_line(load_state(store, key))
    except (OSError, ValueError):
        kept = "see `stickslip where`"
    return type(e)(f"{e}; {what} stopped at that write; as kept now: {kept}")


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
    """Open the device (its identity checked: :func:`~stickslip.devices.identity.open_checked`), send ``plan`` in
    bursts, keep the state; the outcome and the simulator's true end."""
    dev = open_checked(store, request.device, opener, state, *sharing_controller(store, request.guard))
    try:
        for w in usage_warnings(calibration, dev, request.device, plan.joint, request.max_age_days):
            warn(w)
        ready()  # the input is good: say so before driving
        if simulates(dev, state):  # the simulator: start where the positions say
            assert isinstance(dev, PoseSettable)
            dev.set_pose(*plan.pose)
        def save(st: DeviceState) -> None:
            if plan.from_uncertain is not None:  # in flight from an uncertain start: anywhere it could reach
                lo, hi = plan.from_uncertain
                to = plan.bounds_after(plan.steps) or (lo, hi)
                st.mark_uncertain(plan.joint, min(lo, to[0]), max(hi, to[1]), "a move from an uncertain position")
            save_state(store, st)

        source = "assumed" if plan.assumed else "dead-reckoned"
        outcome = drive(dev, state, plan.joint, plan.steps, request.burst, plan.position_after, save, source)
        settle(state, plan, outcome)
        if outcome.error is None or state.track.get(plan.joint) is not None:
            save_state(store, state)
        true_end = None
        if outcome.error is None and isinstance(dev, KnowsTruePosition) and simulates(dev, state):
            true_end = float(dev.position(plan.joint))
        return outcome, true_end
    finally:
        try:
            dev.close()
        except DeviceError:
            pass


# ---------------------------------------------------------------- raw steps, no calibration


@dataclass(frozen=True)
class StepResult:
    """What :func:`step_joint` did: the steps sent (signed, per burst), the kept state, a device error if any."""

    device: str
    joint: int
    steps: int
    outcome: MoveOutcome
    state: DeviceState

    def as_dict(self) -> dict[str, object]:
        """The JSON shape of ``stickslip move --steps N --json`` (SI units)."""
        lo, hi = self.state.bounds(self.joint)
        return {
            "device": self.device, "joint": self.joint, "steps_signed": self.steps, "sent": self.outcome.sent,
            "bursts": list(self.outcome.bursts), "uncertain": [lo, hi], "unit": self.state.spec(self.joint).unit,
            "error": self.outcome.error,
        }


def step_joint(
    store: MoveStore,
    device: str,
    joint: int,
    steps: int,
    *,
    burst: int = 1000,
    ready: Callable[[], None] = _nothing,
    opener: Callable[[str], Controller] | None = None,
    joints: JointSet | None = None,
) -> StepResult:
    """Send ``steps`` raw signed steps to ``joint``: no calibration, no plan (a first check, a drive into a stop).

    Without a model the steps move the joint by an unknown amount, so the joint is kept
    *uncertain*: from where it may have been (its bounds, :meth:`DeviceState.bounds`) to
    its end stop in the direction stepped, journalled before the first burst (once the device
    has opened: one that cannot be opened leaves the joint as it was). Reference it
    afterwards (``stickslip where --set J=min`` at the lower stop).
    """
    if steps == 0:
        raise ValueError("--steps must not be 0")
    key = device_key(device)
    with device_lock(store, key):
        state = load_state(store, key, joints)
        state.spec(joint)  # an unknown joint is refused before the device opens
        try:
            dev = open_checked(store, device, opener or open_device, state)  # one not opened was sent nothing
            try:
                _towards_stop(state, joint, steps, f"{steps:+d} raw steps were sent")
                save_state(store, state)  # write-ahead: uncertain before anything is sent
                ready()
                if isinstance(dev, PoseSettable):  # the simulator: start where the positions say
                    dev.set_pose(*state.pose)
                out = _send_raw(dev, joint, steps, burst)
            finally:
                try:
                    dev.close()
                except DeviceError:
                    pass
        except KeyboardInterrupt:
            what = f"{steps:+d} raw steps of joint {joint}"
            raise Interrupted(what, kept_after_interrupt(store, key, state)) from None
    return StepResult(key, joint, steps, out, state)


def _send_raw(dev: Controller, joint: int, steps: int, burst: int) -> MoveOutcome:
    """Send ``steps`` (signed) in bursts of at most ``burst``; a device error ends the loop and is kept."""
    out = MoveOutcome()
    sign = 1 if steps > 0 else -1
    while out.sent != steps:
        n = sign * min(burst, abs(steps - out.sent))
        try:
            dev.step(joint, n)
        except DeviceError as e:
            out.error = str(e)
            break
        out.sent += n
        out.bursts.append(n)
    return out


@contextmanager
def driven_towards_stop(
    store: MoveStore, device: str, joint: int, sign: int, why: str, joints: JointSet | None = None
) -> Iterator[DeviceState]:
    """Hold ``device``'s lock while the caller steps ``joint`` towards its end stop (``sign`` +1: upper) unplanned.

    What ``stickslip record`` needs on a real controller: the joint is driven by an unknown
    amount (into its stop, or short of it), so it is kept *uncertain* from where it may have
    been to that stop, saved before the caller sends a step (``why`` is what ``where`` says),
    as :func:`step_joint` does; :class:`DeviceBusy` while another process drives the device.
    """
    key = device_key(device)
    with device_lock(store, key):
        state = load_state(store, key, joints)
        _towards_stop(state, joint, sign, why)
        save_state(store, state)  # write-ahead: uncertain before anything is sent
        yield state


def _towards_stop(state: DeviceState, joint: int, sign: int, why: str) -> None:
    """Keep ``joint`` uncertain from where it may be (its bounds) to its end stop on the side of ``sign`` (> 0: upper):
    stepped by an amount no model gives (raw steps, a drive into the stop)."""
    spec = state.spec(joint)
    lo, hi = state.bounds(joint)
    state.mark_uncertain(joint, *((lo, spec.upper) if sign > 0 else (spec.lower, hi)), why)
