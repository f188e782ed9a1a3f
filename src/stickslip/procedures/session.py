"""One audio-timed traverse on a device, and keeping it: the workflow behind
``stickslip traverse`` (:func:`traverse`; what a calibration day repeats).

:func:`traverse` holds the device's lock, journals the joint as *uncertain* over its whole
range before it moves (a traverse that is interrupted, or hears no stop, leaves it so,
never at a made-up position), measures, records the row and re-references the joint at
the stop it reached, and appends the row to a table if asked.
:func:`traverse_on_device` places the arm where it can be placed (the simulator), listens
with the device's own microphone where it has one (the simulator) or the sound card
otherwise, and counts the steps between the end stops (:func:`~.traverse.measure_traverse`).
:func:`record_traverse` stores the row and, since the joint now rests at an end stop,
re-references the joint's kept position there (and keeps the pose options the user gave as the arm's pose).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from .. import kinematics as kin
from ..audio.confirm import CONFIRM_S
from ..audio.detector import Tuning, detector_for
from ..devices.base import Controller, DeviceError, HasMicrophone, PoseSettable, VirtualClock, device_key, open_device
from ..devices.identity import open_checked
from ..devices.positions import DeviceState, StateStore, load_state, save_state, where_set_command
from ..measurements import Traverse, measurements_to_csv
from ..records import MAX_TABLE_BYTES, atomic_write_text, read_text_bounded
from ..units import format_quantity, position_display_unit
from .move import Interrupted, LockStore, device_lock, kept_after_interrupt, track_fields
from .traverse import TraverseError, TraverseResult, check_burst_steps, measure_traverse

__all__ = [
    "RowNotAppended",
    "StepRateWarning",
    "TraverseRequest",
    "TraverseStore",
    "append_row",
    "check_append_target",
    "pose_not_given",
    "record_traverse",
    "POSE_NAMES",
    "traverse",
    "traverse_on_device",
]


class StepRateWarning(UserWarning):
    """The joint steps more than 5 % away from the rate its tuning was made at (a stop may be heard late)."""


def _warn(message: str) -> None:
    warnings.warn(message, StepRateWarning, stacklevel=3)


class TraverseStore(StateStore, Protocol):
    """What :func:`record_traverse` needs of a store (``stickslip.storage.Store`` is one)."""

    def add_traverse(self, t: Traverse, device: str = ..., how: str = ...) -> int: ...


class LockedTraverseStore(TraverseStore, LockStore, Protocol):
    """What :func:`traverse` needs of a store: the rows, the kept state and the device lock."""


class RowNotAppended(ValueError):
    """The traverse was measured (and stored, if a store was given) but its row could not be appended to the table."""


def traverse_on_device(
    ctrl: Controller,
    joint: int,
    direction: str,
    pose: kin.Pose,
    day: str,
    tuning: Tuning,
    *,
    audio_input: str | int | None = None,
    burst_steps: int = 2000,
    progress: bool | Callable[[int, float], None] = True,
    confirm_s: float = CONFIRM_S,
    serial_port: str | None = None,
    on_warning: Callable[[str], None] = _warn,
    before_motion: Callable[[], None] | None = None,
) -> TraverseResult:
    """Measure one traverse of ``joint`` in ``direction`` on ``ctrl``, timed by the tuned limit switch.

    Parameters
    ----------
    pose : Pose
        The other joints (rad, rad, m) and the base tilt (rad). A controller that can be
        placed (:class:`~stickslip.devices.base.PoseSettable`) is placed there; on a real
        arm the user has set it.
    tuning : Tuning
        The joint's limit-switch tuning.
    audio_input : str or int, optional
        Sound-card input for a controller without a microphone of its own (``ValueError``
        for the simulator, which hears itself: it would be taken and not used).
    progress : bool or callable
        ``True`` shows a progress bar; a callable gets ``(steps, device_s)`` after every
        burst (:func:`~.traverse.measure_traverse`).
    confirm_s : float
        How long a stop must persist before it is taken, s (see
        :func:`~.traverse.measure_traverse`; 0: the detector's first fire).
    serial_port : str, optional
        Listen to a vibration sensor that sends one ASCII sample per line on this serial
        port, at the tuning's sample rate (:class:`~stickslip.audio.sources.vibration.SerialSamples`;
        a vacuum chamber, where no air carries the sound), instead of a sound card. The
        tuning must have been made from the same sensor.
    on_warning : callable
        Gets a warning, before the joint moves, when the controller steps more than
        ``TuningFileParams.step_rate_tolerance`` away from the rate the
        tuning was made at (:meth:`~stickslip.audio.tuningfile.Tuning.step_rate_problem`).
        Default: a :class:`StepRateWarning` (Python's ``warnings``).
    before_motion : callable, optional
        Called once the listening source is open, before the first step (the write-ahead journal:
        a sound card or sensor that does not open leaves the kept position as it was).
    """
    hears_itself = isinstance(ctrl, HasMicrophone) and isinstance(ctrl, VirtualClock)  # the simulator
    if hears_itself and audio_input is not None:
        raise ValueError(
            f"--input {audio_input}: a sound card listens to a real controller; the simulator hears itself"
        )
    rate_problem = tuning.step_rate_problem(float(ctrl.frequency(joint)), f"joint {joint} steps")
    if rate_problem is not None:
        on_warning(rate_problem)
    if isinstance(ctrl, PoseSettable):
        ctrl.set_pose(**{k: v for k, v in pose._asdict().items() if k != f"q{joint}"})
    t0 = 0.0  # a live source starts now
    close: Callable[[], None] | None = None  # what to close after, for a source this opened
    mic: Any = None  # a sound card: it may drop audio
    if serial_port is not None:
        from ..audio.sources.vibration import SerialSamples

        src = SerialSamples(serial_port, sample_rate=int(tuning.sample_rate))
        blocks: Any = src.blocks()
        close = src.close
    elif isinstance(ctrl, HasMicrophone) and isinstance(ctrl, VirtualClock):  # hears_itself, narrowed for mypy
        t0 = float(ctrl.clock_s)
        blocks = ctrl.microphone()
    else:
        from ..audio.sources import Microphone

        mic = Microphone(sample_rate=int(tuning.sample_rate), device=audio_input).start()
        blocks, close = mic.blocks(), mic.stop
    try:
        if before_motion is not None:
            before_motion()
        result = measure_traverse(
            ctrl, joint, direction, detector=detector_for(tuning, t0), audio_blocks=blocks,
            pose=pose, day=day, burst_steps=burst_steps, progress=progress, confirm_s=confirm_s,
        )
    finally:
        if close is not None:
            close()
    dropped = int(getattr(mic, "overflows", 0) or 0)
    if dropped:
        # the stream's time is its samples counted: what the card dropped makes the stop's time, and so the count,
        # early by that much, and nothing says how much was lost
        raise TraverseError(
            f"joint {joint}: the sound card dropped audio {dropped} time{'s' if dropped != 1 else ''} during the "
            "traverse (input overflow), so the stop's time and the step count would be off by what was lost; "
            "nothing recorded: close other programs that use the sound card and measure again"
        )
    return result


POSE_NAMES = ("q1", "q2", "q3", "theta", "psi")
"""The names of a traverse's pose (:attr:`TraverseRequest.keep_pose` takes them)."""


def record_traverse(
    store: TraverseStore, device_url: str, row: Traverse, how: str = "audio", keep_pose: tuple[str, ...] = ()
) -> int:
    """Store ``row`` for the device and re-reference its joint at the end stop it reached; returns the id.

    ``keep_pose``: the names of the row's pose (:data:`POSE_NAMES`) the user set the arm to for this traverse; each
    is kept as the arm's pose (the other joints ``"set"`` there, the tilt), as ``stickslip where --set`` would. The
    traversed joint's own entry is its start, not kept: the joint rests at the end stop.
    """
    key = device_key(device_url)
    tid = store.add_traverse(row, device=key, how=how)
    state = load_state(store, key)
    for name in keep_pose:
        if name not in POSE_NAMES:
            raise ValueError(f"keep_pose: {name!r} is not one of {POSE_NAMES}")
        if name in ("theta", "psi"):
            state.set_tilt(**{name: float(getattr(row, name))})
        elif name != f"q{row.joint}":
            state.set_position(int(name[1]), float(getattr(row, name)), "set")
    state.set_position(row.joint, row.end, "set")
    save_state(store, state)
    return tid


POSE_TOLERANCE = {"rotary": math.radians(0.5), "prismatic": 10e-6}
"""How far (rad, m) a pose option left at its default may be from the arm's kept pose before a traverse says so:
finer than a pose set by hand or by eye, coarser than a kept position's rounding."""


def pose_not_given(state: DeviceState, request: TraverseRequest) -> list[str]:
    """A warning for each pose option the user left at its default (``request.defaulted``) whose default is
    further than :data:`POSE_TOLERANCE` (and 3 σ of a tracked position) from where the arm is kept: the row would
    record a pose the arm is not in. Joints kept ``default`` or uncertain say nothing (nothing is known of them)."""
    lines = []
    for name in request.defaulted:
        if name not in POSE_NAMES or name in request.keep_pose or name == f"q{request.joint}":
            continue
        told = float(getattr(request.pose, name))
        if name in ("theta", "psi"):
            kept, tol, unit = float(getattr(state, name)), POSE_TOLERANCE["rotary"], "deg"
        else:
            j = int(name[1])
            if state.sources.get(j) == "default" or j in state.uncertain:
                continue
            joint_spec = state.spec(j)
            sd = track_fields(state, j)["sd"] or 0.0
            kept, tol = state.positions[j], max(POSE_TOLERANCE[joint_spec.kind], 3.0 * sd)
            unit = position_display_unit(joint_spec)
        if abs(told - kept) > tol:
            lines.append(f"--{name} not given: the row records {name} = {format_quantity(told, unit, 6)} (the "
                         f"default), but the arm is kept at {format_quantity(kept, unit, 6)}: give --{name} with the "
                         "pose the arm is in")
    return lines


def check_append_target(path: Path) -> str:
    """What is in the table ``row`` s will be appended to ("" if new or empty); ``ValueError`` if it is not one.

    A file whose first line is not the measurement table's header (design.md §7) is
    refused rather than have rows in our column order appended to columns of another.
    """
    if not path.exists():
        return ""
    old = read_text_bounded(path, "measurement table", MAX_TABLE_BYTES)  # a FIFO or device: refused, never opened
    if not old.strip():
        return ""
    header = measurements_to_csv([]).split("\n", 1)[0]
    first = old.lstrip().split("\n", 1)[0].strip()
    if [c.strip() for c in first.split(",")] != header.split(","):
        raise ValueError(
            f"{path} is not a measurement table to append to: its first line is {first[:80]!r}, "
            f"not the header {header!r} (give a new file)"
        )
    return old


def append_row(path: Path, row: Traverse) -> None:
    """Append ``row`` to a measurement table (design.md §7), writing the header if the file is new or empty.

    The table is rewritten through a temporary file: a failed write leaves it as it was,
    never with half a row. A last row without its line end gets one first.
    """
    old = check_append_target(path)
    text = measurements_to_csv([row])
    if old:
        text = old + ("" if old.endswith("\n") else "\n") + text.split("\n", 1)[1]
    atomic_write_text(path, text)


@dataclass(frozen=True)
class TraverseRequest:
    """One traverse to measure.

    Attributes
    ----------
    device : str
        Controller URL.
    joint : int
    direction : str
        ``"+"`` (lower stop to upper) or ``"-"``.
    pose : Pose
        The other joints (rad, rad, m) and the base tilt (rad).
    day : str
        Session label.
    tuning : Tuning
        The joint's limit-switch tuning.
    audio_input, serial_port : optional
        Sound-card input, or a vibration sensor's serial port (:func:`traverse_on_device`).
    burst : int
        Steps per burst between checks of the limit switch.
    confirm_s : float
        How long a stop must persist before it is taken, s.
    append : Path or None
        Measurement table to append the row to.
    keep_pose : tuple of str
        The names of ``pose`` the user set the arm to (:data:`POSE_NAMES`): kept as the arm's pose after the
        traverse (:func:`record_traverse`). Default none: the kept pose is left as it was.
    defaulted : tuple of str
        The names of ``pose`` left at a default the caller did not choose (a command's options not given): each
        further from the kept pose than :data:`POSE_TOLERANCE` is warned about before the joint moves
        (:func:`pose_not_given`). Default none: a caller that gives the whole pose (a day's design) is not warned.
    """

    device: str
    joint: int
    direction: str
    pose: kin.Pose
    day: str
    tuning: Tuning
    audio_input: str | int | None = None
    serial_port: str | None = None
    burst: int = 2000
    confirm_s: float = CONFIRM_S
    append: Path | None = None
    keep_pose: tuple[str, ...] = ()
    defaulted: tuple[str, ...] = ()


def traverse(
    store: LockedTraverseStore | None,
    request: TraverseRequest,
    *,
    progress: bool | Callable[[int, float], None] = True,
    on_warning: Callable[[str], None] = _warn,
    opener: Callable[[str], Controller] | None = None,
) -> TraverseResult:
    """Measure one traverse on ``request.device`` and keep it; the joint ends referenced at the stop reached.

    With a ``store`` the device's lock is held, the joint is journalled uncertain over its
    whole range before it moves (so an interrupted or failed traverse leaves it uncertain,
    and ``stickslip where`` says so), the row is stored and the joint re-referenced at the
    end stop. Raises :class:`~.traverse.TraverseError`, :class:`~stickslip.devices.base.DeviceError`,
    ``ValueError``, :class:`~.move.Interrupted` (Ctrl-C, with the kept state) and
    :class:`RowNotAppended` (measured and stored, but not appended: the message has the row).
    """
    if request.append is not None:
        check_append_target(request.append)  # before the joint moves: a traverse takes a while
    check_burst_steps(request.burst)  # a bad burst is refused before the joint is journalled
    if store is None:
        result = _measure(request, progress, on_warning, opener)
    else:
        key = device_key(request.device)
        with device_lock(store, key):
            state = load_state(store, key)
            spec = kin.joint_spec(request.joint)
            for line in pose_not_given(state, request):
                on_warning(line)

            def journal() -> None:  # write-ahead, once the device is open: the joint may be anywhere until the stop
                state.mark_uncertain(request.joint, spec.lower, spec.upper, "a traverse did not finish")
                save_state(store, state)

            try:
                result = _measure(request, progress, on_warning, _checked(store, opener, state), journal)
            except KeyboardInterrupt:
                what = f"traverse of joint {request.joint}{request.direction}"
                raise Interrupted(what, kept_after_interrupt(store, key, state)) from None
            try:
                record_traverse(store, request.device, result.traverse, how="audio", keep_pose=request.keep_pose)
            except OSError as e:  # measured, and the database refused it (a full disk): the row is not lost
                raise _measured_not_stored(e, request, result.traverse) from None
    if request.append is not None:
        try:
            append_row(request.append, result.traverse)
        except (OSError, ValueError) as e:
            stored = "it is stored in the database; " if store is not None else ""
            line = measurements_to_csv([result.traverse]).split("\n")[1]
            raise RowNotAppended(
                f"the traverse was measured but not appended to {request.append} ({e}); {stored}its row: {line}"
            ) from None
    return result


def _checked(
    store: StateStore, opener: Callable[[str], Controller] | None, state: DeviceState
) -> Callable[[str], Controller]:
    """``opener`` (default :func:`open_device`) with the controller's identity checked against ``state``'s kept one
    (:func:`~stickslip.devices.identity.open_checked`): another controller at the URL is refused, nothing sent."""
    def checked(url: str) -> Controller:
        return open_checked(store, url, opener or open_device, state)

    return checked


def _measured_not_stored(e: OSError, request: TraverseRequest, row: Traverse) -> OSError:
    """``e`` (the database refused a measured row: a full disk) with the row, appended to the table if one is asked.

    The traverse took minutes of a rig's time: its row was lost with the one line that said the
    write failed. The joint stays as journalled before it moved: uncertain between its stops.
    """
    line = measurements_to_csv([row]).split("\n")[1]
    table = ""
    if request.append is not None:
        try:
            append_row(request.append, row)
            table = f"it is appended to {request.append}; "
        except (OSError, ValueError) as a:
            table = f"nor appended to {request.append} ({a}); "
    text = (f"{e}; the traverse was measured but not stored, joint {request.joint} is kept uncertain between its "
            f"stops (reference it at the stop it rests on: {where_set_command(request.device, request.joint)} at the "
            f"lower, =max at the upper); {table}its row: {line}")
    return type(e)(text) if type(e).__init__ is OSError.__init__ and len(e.args) == 1 else OSError(text)


def _measure(
    request: TraverseRequest,
    progress: bool | Callable[[int, float], None],
    on_warning: Callable[[str], None],
    opener: Callable[[str], Controller] | None,
    journal: Callable[[], None] | None = None,
) -> TraverseResult:
    """Open the device, measure the traverse (:func:`traverse_on_device`, which calls ``journal()`` once it
    listens, before the first step: the joint kept uncertain before it moves), close it. A device or a sound card
    that does not open leaves the kept position as it was."""
    ctrl = (opener or open_device)(request.device)
    try:
        return traverse_on_device(
            ctrl, request.joint, request.direction, request.pose, request.day, request.tuning,
            audio_input=request.audio_input, serial_port=request.serial_port, burst_steps=request.burst,
            progress=progress, confirm_s=request.confirm_s, on_warning=on_warning, before_motion=journal,
        )
    finally:
        try:
            ctrl.close()
        except DeviceError:
            pass
