"""A straight tip move: the workflow behind ``stickslip reach`` (:func:`reach`), and its driving loop.

:func:`reach` plans the line from the kept pose (:func:`plan_from_state`) and, under the
device's lock, drives it (:func:`drive_reach`): the segments of a
:class:`~stickslip.motion.reach.ReachPlan`, joint by joint.

Each joint's steps in a segment go through :func:`stickslip.procedures.move.drive`
(the write-ahead journal: *in flight* before a burst, the dead-reckoned end after it),
so a straight move has exactly the safety of single-joint moves: the positions are kept
after every burst, and a link drop, crash or Ctrl-C leaves the joint being stepped
*uncertain* with bounds, never silently wrong. The caller holds the device lock
(:func:`stickslip.procedures.move.device_lock`).

The dead reckoning inside a segment is the planner's own (:class:`stickslip.motion.reach.JointStepper`
in the pose of that moment), so the kept positions after each segment are the plan's
predicted ``q``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from .. import kinematics as kin
from ..calibration import Calibration
from ..devices.base import Controller, DeviceError, KnowsTruePosition, PoseSettable, device_key, open_device
from ..devices.identity import open_checked
from ..devices.positions import DeviceState, StateStore, load_state, save_state, where_set_command
from ..motion.reach import JointStepper, ReachPlan, plan_reach
from ..rig.guard import Guard
from .conditions import calibration_device_problem, usage_warnings
from .move import (
    Interrupted,
    MoveRefused,
    MoveStore,
    PoseUpdate,
    claimed,
    device_lock,
    drive,
    exact_positions,
    grow_track,
    kept_after_interrupt,
    reference_problem,
    sharing_controller,
    simulates,
    tracked_calibration,
    with_kept_positions,
)

__all__ = [
    "BORROWED_JOINT1",
    "MAX_TIP_M",
    "ReachOutcome",
    "ReachRequest",
    "ReachResult",
    "check_referenced",
    "drive_reach",
    "joint_path",
    "plan_from_state",
    "reach",
    "referenced_state",
]

Vec3 = tuple[float, float, float]

MAX_TIP_M = 1.0
"""The largest tip target or displacement a reach takes, per axis, m: a thousand times any arm's reach, so a
value beyond it is a typing error (a target farther overflowed the inverse kinematics)."""

BORROWED_JOINT1 = (
    "joint 1 is not in this calibration: its steps are planned with joint 2's parameters and joint 1's own "
    "gravity load (the paper: the same actuator); for accurate moves across the arm's plane calibrate joint 1: "
    "stickslip traverse --joint 1 both ways with --q2 -90deg at --theta 0 and -90deg, each at --q3 0 and 12mm, "
    "appended to the table (-a), then stickslip calibrate the table (docs/taskspace.md)"
)
"""The warning of a move that steps joint 1 with joint 2's parameters (``motion.reach.borrow_joint1``)."""


@dataclass
class ReachOutcome:
    """What :func:`drive_reach` did.

    Attributes
    ----------
    segments_done : int
        Segments completed (all joints confirmed).
    sent : list of int
        Signed steps confirmed per joint (1, 2, 3) over the whole move.
    error : str or None
        The device error that stopped the move, if any.
    joint : int or None
        The joint being stepped when it stopped.
    """

    segments_done: int = 0
    sent: list[int] = field(default_factory=lambda: [0, 0, 0])
    error: str | None = None
    joint: int | None = None


def drive_reach(
    dev: Controller,
    state: DeviceState,
    plan: ReachPlan,
    calibration: Calibration,
    save: Callable[[DeviceState], None],
    burst: int = 1000,
    on_segment: Callable[[int, DeviceState], None] | None = None,
    *,
    scale_tracks: bool = True,
) -> ReachOutcome:
    """Send ``plan``'s segments to ``dev``, joint 1, then 2, then 3 in each, journalling every burst.

    ``state`` must hold the plan's start (its positions are updated as the arm moves, dead-reckoned with each
    joint's tracked step scale as :func:`plan_from_state` planned);
    ``save(state)`` stores it (one transaction); ``on_segment(k, state)`` is called
    after segment ``k`` (0-based) is done. A :class:`~stickslip.devices.base.DeviceError`
    stops the move and is returned in the outcome; any other exception propagates with
    the journal saved. ``scale_tracks=False``: ``calibration`` already holds the step scales the
    plan was made with (the closed loop's camera-corrected one), it is stepped as it is.
    """
    start = tuple(state.positions[j] for j in (1, 2, 3))
    if any(abs(a - b) > 1e-12 * max(1.0, abs(b)) for a, b in zip(start, plan.q_start, strict=True)):
        raise ValueError(f"the device's kept positions {start} are not the plan's start {plan.q_start}")
    out = ReachOutcome()
    seen: set[int] = set()  # the joints whose track has had the new pose's model error
    # as plan_from_state planned: the kept positions are the plan's
    stepping = tracked_calibration(calibration, state) if scale_tracks else calibration
    for k, seg in enumerate(plan.segments):
        for j in (1, 2, 3):
            n = seg.steps[j - 1]
            if n == 0:
                continue
            stepper = JointStepper(stepping, state.spec(j), state.pose, plan.step_model)
            q_from = state.positions[j]

            def reckon(m: int, stepper: JointStepper = stepper, q_from: float = q_from) -> float:
                return stepper.position_after(q_from, m)

            source = "dead-reckoned" if exact_positions(dev, state, j) else "assumed"
            assumed, pose = state.sources[j] in ("default", "assumed"), state.pose
            moved = drive(dev, state, j, n, burst, reckon, save, source)
            out.sent[j - 1] += moved.sent
            if moved.error is None and grow_track(state, j, q_from, moved.sent, calibration, pose, assumed, seen):
                save(state)  # the σ grown as a move's (docs/models.md §7)
            if moved.error is not None:
                out.error, out.joint = moved.error, j
                return out
        out.segments_done = k + 1
        if on_segment is not None:
            on_segment(k, state)
    return out


def joint_path(plan: ReachPlan) -> list[list[float]]:
    """The poses a reach passes through as driven: in each segment joint 1, then 2, then 3 (rad or m)."""
    q = list(plan.q_start)
    path = [list(q)]
    for seg in plan.segments:
        for j in (1, 2, 3):
            if seg.steps[j - 1]:
                q[j - 1] = float(seg.q[j - 1])
                path.append(list(q))
    return path


# ---------------------------------------------------------------- the whole move


@dataclass(frozen=True)
class ReachRequest:
    """A straight tip move on one device.

    Attributes
    ----------
    device : str
        Controller URL.
    to, by : tuple of 3 floats or None
        The tip's target or displacement, base frame before the tilt, m: exactly one.
    geometry : Geometry
        The arm's offset and length.
    segment : float
        Longest segment of the line, m.
    burst : int
        Most steps per burst.
    pose : PoseUpdate
        Positions and tilt to record first.
    max_age_days : int
        A calibration older than this is warned about.
    dry_run : bool
        Plan only: no lock, nothing sent, nothing kept.
    from_unreferenced : bool
        Plan from joints never referenced (their positions assumed); without it they are
        refused on a real controller. Uncertain joints are always refused.
    trust_calibration : bool
        Use a calibration without its device, or the simulator's, on a real controller.
    guard : Guard or None
        A rig's envelope for this arm: the whole line, as driven (:func:`joint_path`), is
        checked against it before a step is sent.
    joints : JointSet or None
        The arm's joints (a rig file's arm: :meth:`stickslip.rig.Arm.joint_specs`); the MM3A's by default.
    stage : Stage or None
        A Cartesian arm's kinematics (a rig file's ``xyz`` arm, :meth:`stickslip.rig.Arm.stage`):
        ``to``/``by`` are then in its base frame and ``geometry`` is not used.
    state_key : str or None
        The key the arm's positions are kept under (:meth:`stickslip.rig.Rig.state_key`); the device's by default.
    """

    device: str
    to: Vec3 | None = None
    by: Vec3 | None = None
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY
    segment: float = 10e-6
    burst: int = 1000
    pose: PoseUpdate = PoseUpdate()
    max_age_days: int = 0
    dry_run: bool = False
    from_unreferenced: bool = False
    trust_calibration: bool = False
    guard: Guard | None = None
    joints: kin.JointSet | None = None
    stage: kin.Stage | None = None
    state_key: str | None = None


@dataclass(frozen=True)
class ReachResult:
    """What :func:`reach` did: the plan, what was sent, the kept state, the simulator's true joints (SI)."""

    device: str
    plan: ReachPlan
    outcome: ReachOutcome
    state: DeviceState
    moved: bool
    sim_true: tuple[float, float, float] | None = None

    def failure(self) -> str | None:
        """One line for a move a device error stopped: where it stopped and what is kept; else ``None``."""
        out = self.outcome
        if out.error is None:
            return None
        j = out.joint or 0
        if j in self.state.uncertain:
            kept = (
                f"joint {j}'s position is now uncertain; re-reference it "
                f"({where_set_command(self.state.device, j)} at the lower stop) before the next move"
            )
        else:
            kept = "the dead-reckoned positions are kept"
        return (
            f"{out.error}; stopped in segment {out.segments_done + 1} of {len(self.plan.segments)} "
            f"(steps sent per joint: {out.sent}); {kept}"
        )

    def as_dict(self) -> dict[str, object]:
        """The JSON shape of ``stickslip reach --json`` (metres, radians)."""
        out: dict[str, object] = dict(self.plan.as_dict())
        if self.sim_true is not None:
            tip = [float(v) for v in self.plan.tip_of(self.sim_true)]
            out["sim_true"] = {"q": list(self.sim_true), "tip": tip}
        return out


def check_referenced(
    state: DeviceState, device: str = "sim://", calibration: Calibration | None = None, from_unreferenced: bool = False
) -> None:
    """:class:`MoveRefused` unless every joint of ``state`` may be planned from: a tip move needs all three known.

    An uncertain joint (an interrupted move) is always refused; one never referenced
    (its position assumed) on a real controller unless ``from_unreferenced``
    (:func:`~.move.reference_problem` names the commands that reference it).
    """
    for j in sorted((1, 2, 3), key=lambda j: j not in state.uncertain):  # an uncertain joint is said first
        problem = reference_problem(state, j, device, calibration, from_uncertain=False)
        if problem and (j in state.uncertain or not from_unreferenced):
            raise MoveRefused(problem)
        problem = state.uncertainty_problem(j)
        if problem:
            raise MoveRefused(problem)


def referenced_state(
    store: StateStore,
    device: str,
    pose: PoseUpdate,
    calibration: Calibration | None = None,
    from_unreferenced: bool = False,
    joints: kin.JointSet | None = None,
    key: str | None = None,
) -> DeviceState:
    """The kept state of ``device`` (an arm of ``joints``, the MM3A's by default) with ``pose`` recorded.

    :class:`MoveRefused` unless it may be planned from. ``key``: where its positions are
    kept (:meth:`stickslip.rig.Rig.state_key`), the device's key by default.
    """
    state = load_state(store, key or device_key(device), joints)
    pose.apply(state)
    check_referenced(state, device, calibration, from_unreferenced)
    return state


def plan_from_state(
    calibration: Calibration, borrowed: bool, state: DeviceState, request: ReachRequest, warn: Callable[[str], None]
) -> ReachPlan:
    """The straight line of ``request`` from the kept pose; ``warn`` says when joint 1 borrows joint 2's parameters.

    Each joint's steps are planned with its kept track's step scale (:func:`~.move.tracked_calibration`:
    what ``observe`` taught), as :func:`drive_reach` dead-reckons them. ``KeyError`` if a joint or direction
    the line needs is not calibrated; ``ValueError``
    (:class:`~stickslip.kinematics.OutOfReach`, :class:`~stickslip.kinematics.SingularPose`)
    if the line cannot be made.
    """
    geom, seg = request.geometry, request.segment
    stage, joints = request.stage, request.joints
    calibration = tracked_calibration(calibration, state)  # each joint's step scale, as a move of it plans
    if request.to is not None:
        plan = plan_reach(calibration, state.pose, to=request.to, geometry=geom, segment=seg, stage=stage,
                          joints=joints)
    else:
        plan = plan_reach(calibration, state.pose, by=request.by, geometry=geom, segment=seg, stage=stage,
                          joints=joints)
    if borrowed and plan.total_steps[0]:
        warn(BORROWED_JOINT1)
    return plan


def reach(
    store: MoveStore,
    request: ReachRequest,
    calibration: Calibration,
    borrowed: bool = False,
    *,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = lambda: None,
    opener: Callable[[str], Controller] | None = None,
) -> ReachResult:
    """Move the tip in a straight line as ``request`` says (or plan it only, ``dry_run``).

    ``calibration`` has joint 1 (or borrows it: ``borrowed``, :func:`~stickslip.motion.reach.borrow_joint1`).
    ``warn`` gets each warning, ``ready()`` is called before the first burst. Refusals
    raise before anything is sent (:class:`~.move.DeviceBusy`, :class:`~.move.MoveRefused`,
    ``KeyError``, ``ValueError``, :class:`~stickslip.devices.base.DeviceError`); a device
    error during the move is in the result (:meth:`ReachResult.failure`).
    """
    lock = device_key(request.device)
    key = request.state_key or lock
    refs = (calibration, request.from_unreferenced, request.joints, key)
    if request.dry_run:
        state = referenced_state(store, request.device, request.pose, *refs)
        plan = plan_from_state(calibration, borrowed, state, request, warn)
        return ReachResult(key, plan, ReachOutcome(), state, moved=False)
    made_on = calibration_device_problem(calibration, request.device)
    if made_on and not request.trust_calibration:
        raise MoveRefused(made_on)
    with device_lock(store, lock):
        state = referenced_state(store, request.device, request.pose, *refs)
        plan = plan_from_state(calibration, borrowed, state, request, warn)
        with claimed(store, state, request.guard, joint_path(plan), calibration):  # mark, then check
            save_state(store, state)  # the recorded pose, even if nothing moves
            for w in usage_warnings(calibration, None, request.device, 3, request.max_age_days):
                warn(w)
            ready()
            if not any(plan.total_steps):
                return ReachResult(key, plan, ReachOutcome(), state, moved=True)
            try:
                outcome, true_q = _drive_opened(store, request, calibration, state, plan, opener or open_device)
            except KeyboardInterrupt:
                raise Interrupted("a straight tip move", kept_after_interrupt(store, key, state)) from None
            except OSError as e:  # the store failed mid-move (a full disk): bursts may have been sent
                raise with_kept_positions(e, store, key, "the straight tip move") from None
    return ReachResult(key, plan, outcome, state, moved=True, sim_true=true_q)


def _drive_opened(
    store: StateStore,
    request: ReachRequest,
    calibration: Calibration,
    state: DeviceState,
    plan: ReachPlan,
    opener: Callable[[str], Controller],
) -> tuple[ReachOutcome, tuple[float, float, float] | None]:
    """Open the device, drive ``plan``, close; the outcome and the simulator's true joints."""
    dev = open_checked(store, request.device, opener, state, *sharing_controller(store, request.guard))
    try:
        if simulates(dev, state):  # the simulator: start where the positions say
            assert isinstance(dev, PoseSettable)
            dev.set_pose(*state.pose)

        def save(st: DeviceState) -> None:
            save_state(store, st)

        outcome = drive_reach(dev, state, plan, calibration, save, request.burst)
        true_q = None
        if outcome.error is None and isinstance(dev, KnowsTruePosition) and simulates(dev, state):
            q = [float(dev.position(j)) for j in (1, 2, 3)]
            true_q = (q[0], q[1], q[2])
        return outcome, true_q
    finally:
        try:
            dev.close()
        except DeviceError:
            pass
