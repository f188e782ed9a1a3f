"""Device commands: ``move`` (a planned move, in bursts) and ``where`` (dead-reckoned positions).

Positions are kept per device in the database (``--db``, default ``$STICKSLIP_DB``, the config file or
the user's data directory) under the device URL without its query options, so every
invocation continues from where the last one left the arm. A ``sim://`` device is
opened at the kept positions (each invocation starts a fresh simulator). The workflows
are :func:`stickslip.procedures.move.move` and :func:`stickslip.procedures.where.where`;
these commands parse, call them and print.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ..devices.base import DeviceError, command_url, device_key
from ..joints import JointSet, joint_spec
from ..units import (
    UnitError,
    bare_number_problem,
    format_position,
    format_spread,
    parse_angle,
    parse_length,
    step_scale,
)
from . import app
from ._common import (
    angle_option,
    calibration_file,
    db_option,
    device_url,
    fail,
    flush_warnings,
    length_option,
    max_age_setting,
    open_store,
    print_json,
    say,
    user_errors,
    warn,
    warn_later,
)
from .camera import CAMERA_CALIBRATION_HELP, CAMERA_LOOP_HELP, CAMERA_TIP_HELP, run_seen

if TYPE_CHECKING:
    from ..procedures.move import MoveResult, PoseUpdate
    from ..procedures.where import WhereResult

_Q1 = "Record q1 (angle: -30deg, -pi/6) first."
_Q2 = "Record q2 (angle: -90deg, -pi/2) first."
_Q3 = "Record q3 (length: 2mm, 0) first."
_THETA = "Record the base tilt theta (angle)."
_PSI = "Record the base tilt psi (angle)."
_DEVICE_HELP = (
    "Controller URL: sim://, mm3a:///dev/ttyUSB0, mm3a+socket://host:port, anc300://host[:7230] "
    "(its password from $STICKSLIP_ANC300_PASSWORD; default: device in the config file, else sim://)."
)


def _parse_joint_value(joint: int, text: str, what: str, joints: JointSet | None = None) -> float:
    """A position or displacement of ``joint`` with its unit: a length for a prismatic joint, an angle for a rotary.

    ``joints``: the arm's (a rig file's), the MM3A's by default (joint 3 a length,
    joints 1 and 2 angles). A bare number (other than 0) is refused with a did-you-mean
    for that joint.
    """
    spec = joint_spec(joint, joints)
    rotary = spec.rotary
    bare = bare_number_problem(text, "angle" if rotary else "length", spec.span)
    if bare is not None:
        fail(f"{what}: {bare}")
    try:
        v = parse_angle(text) if rotary else parse_length(text)
    except (UnitError, ArithmeticError, ValueError, TypeError) as e:
        kind = "an angle (e.g. 2deg, 40urad)" if rotary else "a length (e.g. 30um, 1.5mm)"
        fail(f"{what}: {e}; joint {joint} takes {kind}")
    if not math.isfinite(v):
        fail(f"{what}: {text!r} is not a finite value")
    return v


def _position_or_stop(joint: int, text: str, what: str, joints: JointSet | None = None) -> float:
    """A position of ``joint`` (rad or m) from ``text``: a value with its unit, or ``min``/``max`` (an end stop)."""
    spec = joint_spec(joint, joints)
    word = text.strip().lower()
    if word in ("min", "lower"):
        return spec.lower
    if word in ("max", "upper"):
        return spec.upper
    return _parse_joint_value(joint, text, what, joints)


RAW_BURST = 20000
"""Steps per burst of raw steps (``--steps``): fewer round trips; a device error still ends it within one burst."""

_STEPS = re.compile(r"^\s*([-+]?\d+)\s*steps?\s*$")


@app.command()
def move(
    joint: int = typer.Option(..., "--joint", "-j", min=1, max=3, help="Joint to move: 1, 2 or 3."),
    by: str | None = typer.Option(
        None, "--by", metavar="<length|angle|steps>",
        help="Move by: 30um, -0.5mm (joint 3); 2deg, -500urad (joints 1, 2); 100steps (raw steps, as --steps).",
    ),
    to: str | None = typer.Option(
        None, "--to", metavar="<length|angle>",
        help="Move to this position (units as --by); 'min'/'max' = an end stop's position, planned as any other "
        "(not driven into the stop, nor referenced there: raw --steps and where --set do that).",
    ),
    steps: int | None = typer.Option(
        None, "--steps", metavar="<steps>",
        help="Send this many raw steps (signed): no calibration, no plan. The joint is then uncertain "
        "until referenced: drive it into a stop, then `stickslip where --set J=min`.",
    ),
    calibration: Path | None = typer.Option(
        None, "--calibration", "-c",
        help="Calibration JSON (from `stickslip calibrate`; default: calibration in the config file).",
    ),
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP),
    from_unreferenced: bool = typer.Option(
        False, "--from-unreferenced",
        help="Plan from a position never referenced (assumed) or uncertain (its last confirmed value). "
        "Without it such a joint is refused on a real controller, with the commands that reference it.",
    ),
    trust_calibration: bool = typer.Option(
        False, "--trust-calibration",
        help="Use a calibration that does not record its device, or was made on the simulator, on a real "
        "controller (refused without it: its step sizes may be another arm's).",
    ),
    q1: float | None = typer.Option(None, "--q1", parser=angle_option, help=_Q1),
    q2: float | None = typer.Option(None, "--q2", parser=angle_option, help=_Q2),
    q3: float | None = typer.Option(None, "--q3", parser=length_option, help=_Q3),
    theta: float | None = typer.Option(None, "--theta", parser=angle_option, help=_THETA),
    psi: float | None = typer.Option(None, "--psi", parser=angle_option, help=_PSI),
    burst: int | None = typer.Option(
        None, "--burst", min=1, max=65535, metavar="<steps>",
        help="Most steps per burst (the position is kept after each). Default 1000; raw --steps 20000 (the "
        "joint is uncertain until referenced anyway).",
    ),
    max_age: int | None = typer.Option(
        None, "--max-age", min=0, max=36500, metavar="<days>",
        help="Warn when the calibration is more than this many days old (default $STICKSLIP_MAX_AGE_DAYS, "
        "else max_age_days in the config file, else 0).",
    ),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print steps, bursts, end as JSON."),
    camera: str | None = typer.Option(None, "--camera", help=CAMERA_LOOP_HELP),
    camera_tip: str | None = typer.Option(None, "--camera-tip", metavar="<x,y>", help=CAMERA_TIP_HELP),
    camera_calibration: Path | None = typer.Option(
        None, "--camera-calibration", metavar="<file>", help=CAMERA_CALIBRATION_HELP
    ),
    rig_file: Path | None = typer.Option(
        None, "--rig", help="Rig file (docs/rig.md): the arm's controller and calibration come from it, and the "
        "move is checked against the rig's envelope first.",
    ),
    arm: str | None = typer.Option(None, "--arm", help="Arm of the rig (default: its first arm)."),
) -> None:
    """Move a joint by a distance or to a position, with the calibrated step-size model.

    The pose is the one kept for the device (see `stickslip where`); --q1 --q2 --q3
    --theta --psi record a new pose first. Steps come from the calibration's model in
    that pose (exact for rotary joints), scaled by the day's step scale learned from
    measured positions (stickslip observe). They are sent in bursts; the dead-reckoned
    position and its standard deviation are kept after every burst.

    A joint never referenced (its position assumed) or left uncertain is refused on a
    real controller: reference it first (raw --steps into its lower stop, then
    `stickslip where --set J=min`), or pass --from-unreferenced.

    Every amount takes its unit (30um, 2deg, 100steps); a bare number other than 0 is
    refused.

    With --rig FILE (and --arm NAME) the arm's controller and calibration come from
    the rig file, and the planned move is checked against the rig's keep-out volumes,
    soft limits and other arms before a step is sent (refused, exit 2, naming the
    obstacle and its closest point).

    Example: stickslip move -d mm3a:///dev/ttyUSB0 -c cal.json --joint 3 --by 30um
    """
    raw = _raw_steps(by, to, steps)
    if camera_calibration is not None and camera is None:
        fail("--camera-calibration goes with --camera")
    if rig_file is not None:
        from ..procedures.move import PoseUpdate

        _move_in_rig(rig_file, arm, device, joint, by, to, raw, calibration, burst, db, json_out,
                     from_unreferenced, trust_calibration, camera, camera_tip, camera_calibration,
                     pose=PoseUpdate(q1, q2, q3, theta, psi), max_age_days=max_age_setting(max_age).value)
        return
    if arm is not None:
        fail("--arm names an arm of a rig: give --rig FILE too")
    device = device_url(device)
    with user_errors():
        device_key(device)  # a URL that names no device is refused before the database is opened
    if raw is not None:
        if camera is not None or camera_tip is not None:
            fail("--camera closes the loop of a planned move (--by LENGTH or --to), not of raw steps")
        _step_raw(device, joint, raw, burst or RAW_BURST, db, json_out)
        return
    from ..calibration import Calibration
    from ..procedures.move import DeviceBusy, MoveRequest, PoseUpdate
    from ..procedures.move import move as move_joint

    with user_errors(KeyError):
        cal = Calibration.load(calibration_file(calibration))
    request = MoveRequest(
        device, joint,
        by=None if by is None else _parse_joint_value(joint, by, "--by"),
        to=None if to is None else _position_or_stop(joint, to, "--to"),
        burst=burst or 1000, pose=PoseUpdate(q1, q2, q3, theta, psi), max_age_days=max_age_setting(max_age).value,
        from_unreferenced=from_unreferenced, trust_calibration=trust_calibration,
    )
    if camera_tip is not None and camera is None:
        fail("--camera-tip goes with --camera")
    if camera is not None:  # the closed loop: stickslip.procedures.closed_loop
        run_seen("move", request, cal, camera, camera_tip, db, json_out, camera_calibration=camera_calibration)
        return
    with open_store(db) as store, user_errors(DeviceBusy, KeyError, DeviceError):
        result = move_joint(store, request, cal, warn=warn_later, ready=flush_warnings)
    failure = result.failure()
    if failure is not None:
        fail(failure)
    if json_out:
        print_json(result.as_dict())
        return
    _print_move(result)


def _move_in_rig(rig_file: Path, arm: str | None, device: str | None, joint: int, by: str | None, to: str | None,
                 raw: int | None, calibration: Path | None, burst: int | None, db: str | None, json_out: bool,
                 from_unreferenced: bool, trust_calibration: bool, camera: str | None = None,
                 camera_tip: str | None = None, camera_calibration: Path | None = None, *,
                 pose: PoseUpdate | None = None, max_age_days: int = 0) -> None:
    """``move --rig FILE --arm NAME``: the arm's device, calibration and envelope from the rig file.

    With ``--camera`` the closed loop checks the whole path and each leg against the envelope.
    """
    from ..calibration import Calibration
    from ..procedures.arms import guard_for, opener_for
    from ..procedures.move import DeviceBusy, MoveRequest, PoseUpdate
    from ..procedures.move import move as move_joint
    from ..procedures.rigstop import stoppable
    from .rig import load, rig_database

    if device is not None:
        fail("give --device or --rig, not both (the rig file names each arm's controller)")
    if raw is not None:
        fail("raw --steps bypass the envelope: give them with --device, not --rig")
    rig = load(rig_file)
    with user_errors(KeyError):
        a = rig.arm(arm)
    cal_path = calibration or (rig_file.parent / a.calibration if a.calibration else None)
    with user_errors(KeyError):
        cal = Calibration.load(calibration_file(cal_path))
    if camera_tip is not None and camera is None:
        fail("--camera-tip goes with --camera")
    if camera is not None:  # the closed loop, each leg checked against the envelope
        from .camera import run_seen
        from .rig import rig_arm

        seen = MoveRequest(
            a.controller, joint, by=None if by is None else _parse_joint_value(joint, by, "--by"),
            to=None if to is None else _position_or_stop(joint, to, "--to"), burst=burst or 1000,
            from_unreferenced=from_unreferenced, trust_calibration=trust_calibration, pose=pose or PoseUpdate(),
            max_age_days=max_age_days,
        )
        ra = rig_arm(rig_file, a.name, None, None, cal_path, db)
        run_seen("move", seen, cal, camera, camera_tip, ra.database if ra else db, json_out, rig_arm=ra,
                 camera_calibration=camera_calibration)
        return
    joints = a.joint_specs()
    with open_store(rig_database(db, rig)) as store, user_errors(DeviceBusy, KeyError, DeviceError):
        request = MoveRequest(
            a.controller, joint,
            by=None if by is None else _parse_joint_value(joint, by, "--by", joints),
            to=None if to is None else _position_or_stop(joint, to, "--to", joints),
            burst=burst or 1000, guard=guard_for(store, rig, a.name), from_unreferenced=from_unreferenced,
            trust_calibration=trust_calibration, joints=joints, state_key=rig.state_key(a.name),
            pose=pose or PoseUpdate(), max_age_days=max_age_days,
        )
        opener = stoppable(opener_for(rig, a.name), store, rig, a.name)  # the rig's STOP, pressed on a page
        result = move_joint(store, request, cal, warn=warn_later, ready=flush_warnings, opener=opener)
    failure = result.failure()
    if failure is not None:
        fail(failure)
    if json_out:
        print_json({"arm": a.name, **result.as_dict()})
        return
    say(f"arm {a.name!r}")
    _print_move(result)


def _where_arms(rig_file: Path, db: str | None, json_out: bool) -> None:
    """``where --rig FILE``: every arm's kept positions (the devices are not opened)."""
    from ..procedures.arms import arm_states
    from ..procedures.move import where_line
    from .rig import load, rig_database

    rig = load(rig_file)
    with open_store(rig_database(db, rig)) as store, user_errors():
        states = arm_states(store, rig)
    if json_out:
        print_json({"rig": rig.name, "arms": [
            {"arm": s.arm, "device": s.device, "q": [s.state.positions[j] for j in (1, 2, 3)],
             "units": [s.state.spec(j).unit for j in (1, 2, 3)],
             "sources": [s.state.sources[j] for j in (1, 2, 3)],
             "claim": {str(j): list(b) for j, b in sorted(s.state.claim.items())}} for s in states]})
        return
    for s in states:
        say(f"arm {s.arm!r} on {s.device}: {where_line(s.state)}")
        if s.state.claim:  # the other arms are refused near it until the move ends or the arm is referenced
            j = min(s.state.claim)
            say(f"  the other arms are kept from its claim until its move ends; if none runs (its process was "
                f"killed), reference it: stickslip where --rig {command_url(str(rig_file))} --arm {command_url(s.arm)} "
                f"--set {j}=...",
                indent="    ")


def _raw_steps(by: str | None, to: str | None, steps: int | None) -> int | None:
    """The raw steps asked for (``--steps N`` or ``--by Nsteps``), ``None`` for a planned move; one of the three."""
    if (by is not None) + (to is not None) + (steps is not None) != 1:
        fail("give exactly one of --by, --to and --steps")
    if to is not None and _STEPS.match(to):
        fail(f"--to {to}: a target is a position (30um, 2deg, min); raw steps go with --by Nsteps or --steps N")
    m = _STEPS.match(by) if by is not None else None
    n = int(m.group(1)) if m else steps
    if n == 0:
        fail("--steps: 0 steps moves nothing")
    from ..measurements.rows import MAX_STEPS

    if n is not None and abs(n) > MAX_STEPS:  # 1e22 steps ran for ever (the simulator: 2e6 steps/s)
        fail(f"--steps: {n:+d} is more than {MAX_STEPS:.0e} steps (over any joint's full range)")
    return n


def _step_raw(device: str, joint: int, steps: int, burst: int, db: str | None, json_out: bool) -> None:
    """``move --steps N``: raw steps through the procedure, then what is known about the joint now."""
    from ..procedures.move import DeviceBusy, sent_text, step_joint

    with open_store(db) as store, user_errors(DeviceBusy, DeviceError):
        result = step_joint(store, device, joint, steps, burst=burst, ready=flush_warnings)
    lo, hi = result.state.bounds(joint)
    if result.outcome.error is not None:
        fail(
            f"{result.outcome.error}; {sent_text(result.outcome.sent, steps, 'raw steps')}; joint {joint} is "
            f"uncertain, {format_position(lo, joint)} to {format_position(hi, joint)}"
        )
    if json_out:
        print_json(result.as_dict())
        return
    say(f"joint {joint}: {steps:+d} raw steps sent in {len(result.outcome.bursts)} burst(s)")
    say(f"its position is uncertain: {format_position(lo, joint)} to {format_position(hi, joint)}")
    from ..devices.positions import where_set_command

    say(f"at the stop, reference it: {where_set_command(device, joint, 'min' if steps < 0 else 'max')}")


def _print_move(result: MoveResult) -> None:
    """``move``'s lines for a person: the move, its planned end with its σ, the simulator's true end."""
    from ..procedures.move import track_fields

    p = result.plan
    joint = p.joint
    spec = result.state.spec(joint)  # the arm's joint: units from its kind
    tf = track_fields(result.state, joint)
    say(
        f"joint {joint}: {format_position(p.q_from, spec)} -> {format_position(p.q_to, spec)}, "
        f"{p.steps:+d} steps in {len(result.outcome.bursts)} burst(s)"
    )
    spread = (
        f" (σ {format_spread(tf['sd'], spec)}, step scale x{tf['step_scale'] or 1.0:.4f})"
        if tf["sd"] is not None else ""
    )
    kept = "assumed end" if result.state.sources.get(joint) == "assumed" else "planned end"
    say(f"{kept} {format_position(p.q_end, spec)}{spread}")
    if result.sim_true_end is not None:
        err = result.sim_true_end - p.q_end
        k, unit = step_scale(spec)  # nm / µrad; a miss of a micrometre or more in µm (as the σ above)
        if abs(err * k) < 1000:
            shown = f"{err * k:+.1f} {unit}"
        else:  # a miss of a micrometre or a milliradian or more: in the position's own unit
            shown = f"{math.degrees(err):+.3f} deg" if spec.rotary else f"{err * 1e6:+.2f} µm"
        say(f"simulator's true end {format_position(result.sim_true_end, spec)} ({shown})")


def _info_line(info: dict[str, Any]) -> str | None:
    """One line of a device's dialect, version, frequencies (Hz) and active profile, if it says."""
    parts = []
    if info.get("dialect"):
        parts.append(f"{info['dialect']} dialect")
    if info.get("version"):
        parts.append(f"firmware {info['version']}")
    hz = info.get("frequency_hz")
    if isinstance(hz, dict) and hz:
        if info.get("frequency_sent", True):
            sent = ""
        elif info.get("dialect") == "console":
            sent = " (sent before this session's first burst; the controller's present values cannot be read)"
        else:
            sent = " (assumed until a speed is set)"
        parts.append("stepping " + ", ".join(f"{c} {f:g} Hz" for c, f in hz.items()) + sent)
    if info.get("active_profile") is not None:
        values = info.get("active_profile_values") or []
        parts.append(f"active speed profile {info['active_profile']} ({' '.join(values)})")
    return "; ".join(parts) or None


@app.command()
def where(
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP),
    set_: list[str] = typer.Option(
        None, "--set", help="Reset a joint at a known point: 3=0, 3=min, 2=max, 1=-30deg."
    ),
    q1: float | None = typer.Option(None, "--q1", parser=angle_option, help=_Q1),
    q2: float | None = typer.Option(None, "--q2", parser=angle_option, help=_Q2),
    q3: float | None = typer.Option(None, "--q3", parser=length_option, help=_Q3),
    theta: float | None = typer.Option(None, "--theta", parser=angle_option, help=_THETA),
    psi: float | None = typer.Option(None, "--psi", parser=angle_option, help=_PSI),
    db: str | None = db_option(),
    offline: bool = typer.Option(
        False, "--offline", help="Do not open the device: only show the kept positions."
    ),
    unlock: bool = typer.Option(
        False, "--unlock", help="Release the device's lock left by a process that is gone."
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the positions as JSON (SI units)."),
    rig_file: Path | None = typer.Option(
        None, "--rig", help="Rig file (docs/rig.md): list the kept positions of every arm (or of --arm).",
    ),
    arm: str | None = typer.Option(None, "--arm", help="Arm of the rig: its device is the one shown or reset."),
) -> None:
    """Show (or reset) the dead-reckoned joint positions and base tilt kept for a device.

    Source: default (never referenced: the outstretched pose assumed), set, dead-reckoned,
    observed (stickslip observe), seen (tracked by the camera: move, reach, jog with
    --camera), assumed (moved from a position never referenced), or uncertain (a move,
    raw steps or a traverse left it between the bounds shown, and why). A joint moved
    since it was set shows its standard deviation (σ) and the step scale learned from
    observations.

    --set J=min (or max, or a position with its unit) references a joint at an end stop:
    after a traverse, a crash or a manual move, and on day one (raw steps into the stop
    first: stickslip move --steps). It clears an uncertainty and the position's σ.

    The positions are kept, not measured: stickslip reads no joint sensor (a SmarAct
    positioner's neither), so a kept position holds only while nothing else moves the
    arm. After the controller's own software or hand control moved it between commands,
    or, on a NanoControl or an ANC300 (which cannot say which controller they are),
    another controller or arm was connected under this URL, reference the joints again
    (--set): stickslip cannot tell. A controller switched off and on between two commands
    changes nothing kept (the positions are stickslip's, not the controller's).

    The positions are kept for the controller that answered: a SmarAct MCS2 says its serial
    number, an MCS its system id. A command that finds another one at the URL (two
    controllers that swapped network addresses or serial ports) sends nothing, marks every
    joint uncertain over its whole range ("another controller answers at this URL") and
    asks for --set. Write a serial port as its /dev/serial/by-id/ link, which names the
    same adapter after a reboot; for a /dev/ttyUSB0-style name where warns.

    Without --set or a pose option the device is opened to say whether it answers
    (--offline skips that); a device that does not answer exits 2. A NanoControl
    also reports its dialect (console or legacy), firmware version, stepping
    frequencies and active speed profile (in --json: "info").

    With --rig FILE every arm of the rig is listed (kept positions, the device not
    opened); with --arm NAME too, that arm's device is the one shown or reset.

    Example: stickslip where -d mm3a:///dev/ttyUSB0 --set 3=min --set 2=max
    """
    from ..procedures.move import PoseUpdate

    if rig_file is not None and device is not None:
        fail("give --device or --rig, not both (the rig file names each arm's controller)")
    if rig_file is None and arm is not None:
        fail("--arm names an arm of a rig: give --rig FILE too")
    joints: JointSet | None = None
    key: str | None = None
    if rig_file is not None:
        from .rig import load, rig_database

        rig = load(rig_file)
        acts = bool(set_) or unlock or any(v is not None for v in (q1, q2, q3, theta, psi))
        if arm is None and acts and len(rig.arms) > 1:  # listing every arm, they were dropped unsaid
            fail("--set, --q1 ... --psi and --unlock act on one arm's device: give --arm NAME (the rig's arms: "
                 f"{', '.join(a.name for a in rig.arms)})")
        if arm is None and not acts:
            _where_arms(rig_file, db, json_out)
            return
        with user_errors(KeyError):
            device = rig.arm(arm).controller
            joints = rig.arm(arm).joint_specs()
            key = rig.state_key(arm)
        db = str(rig_database(db, rig)) if db is None and rig.database else db
    from ..procedures.move import DeviceBusy
    from ..procedures.where import DeviceUnreachable, ReferenceRefused
    from ..procedures.where import where as kept_positions

    device = device_url(device)
    with user_errors():
        device_key(device)
    items = list(set_ or [])
    references = [_reference(item, joints) for item in items]
    with open_store(db) as store, user_errors(DeviceUnreachable, DeviceBusy):
        try:
            result = kept_positions(
                store, device, references=references, pose=PoseUpdate(q1, q2, q3, theta, psi), offline=offline,
                unlock=unlock, joints=joints, key=key, hold_lock=True,
            )
        except ReferenceRefused as e:
            fail(f"--set {items[e.index]}: {e}")
    if result.replaced is not None:  # on stderr, so --json's document is the same
        warn(f"{result.replaced}: replaced by what was recorded now; the joints not set are unreferenced")
    if json_out:
        print_json(result.as_dict())
        return
    _print_where(result)


def _reference(item: str, joints: JointSet | None = None) -> tuple[int, float]:
    """``--set J=VALUE`` (VALUE with its unit, or min/max) to ``(joint, q)`` (rad or m) of the arm's ``joints``."""
    j_text, sep, value = item.partition("=")
    if not sep or j_text.strip() not in ("1", "2", "3"):
        fail(f"--set {item!r}: write JOINT=VALUE, e.g. 3=0, 3=min, 2=-90deg")
    j = int(j_text)
    return j, _position_or_stop(j, value, f"--set {item}", joints)


def _print_where(result: WhereResult) -> None:
    """``where``'s lines for a person: the device, what it said, each joint and how it is known, the tilt."""
    from ..procedures.move import track_fields
    from ..procedures.where import state_rows

    state, info = result.state, result.info
    answers = info["model"] if info else None
    say(f"{result.device}" + (f" (answers: {answers})" if answers else ""))
    if result.busy:
        warn(f"not asked whether it answers: {result.busy}")
    from ..procedures.where import port_order_warning

    if (ports := port_order_warning(result.device)) is not None:
        warn(ports)
    line = _info_line(info) if info else None
    if line:
        say(f"  {line}")
    for r, j in zip(state_rows(state), (1, 2, 3), strict=True):
        extra = ""
        tf = track_fields(state, j)
        if tf["sd"] is not None and j not in state.uncertain:
            spread = format_spread(tf["sd"], state.spec(j))
            if tf["sd"] >= state.spec(j).span:  # the ceiling (JointTrack.cap_position): lost, not a σ
                spread = "its whole range (lost: observe or set it)"
            extra = f", σ {spread}, step scale x{tf['step_scale'] or 1.0:.4f}"
        if j in state.uncertain:
            lo, hi = state.uncertain[j]
            extra = f", between {format_position(lo, state.spec(j))} and {format_position(hi, state.spec(j))}"
        say(f"  joint {j}: {r['display']:>14}  ({r['source']}{extra})", indent="    ")
        if j in state.uncertain and j in state.why:
            say(f"  {'':>25}{state.why[j]}")
    for j, (lo, hi) in sorted(state.claim.items()):  # a rig's other arms are kept from it until the move ends
        say(f"  claimed by a move: joint {j} {format_position(lo, state.spec(j))} to "
            f"{format_position(hi, state.spec(j))} (a move running, or one killed: --set a joint clears it)",
            indent="    ")
    say(f"  tilt: theta = {math.degrees(state.theta):.4g} deg, psi = {math.degrees(state.psi):.4g} deg")
