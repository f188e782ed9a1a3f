"""Device commands: ``move`` (a planned move, in bursts) and ``where`` (dead-reckoned positions).

Positions are kept per device in the database (``--db``, default ``$STICKSLIP_DB``, the config file or
the user's data directory) under the device URL without its query options, so every
invocation continues from where the last one left the arm. A ``sim://`` device is
opened at the kept positions (each invocation starts a fresh simulator).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ..devices.base import DeviceError, KnowsTruePosition, PoseSettable, device_key, open_device
from ..joints import JOINTS, joint_spec
from ..units import UnitError, format_position, parse_angle, parse_length, position_display_unit, step_scale
from . import app
from ._common import (
    DB_HELP,
    angle_option,
    calibration_file,
    console,
    device_url,
    fail,
    flush_warnings,
    lazy_import,
    length_option,
    max_age_setting,
    open_store,
    print_json,
    user_errors,
    warn_later,
)
from ._output import styled

if TYPE_CHECKING:
    from .. import kinematics as kin
    from ..calibration import Calibration
    from ..devices.positions import DeviceState, load_state, save_state
else:  # numpy loads when a command first needs it, not for --help
    kin = lazy_import("stickslip.kinematics")
    _positions = lazy_import("stickslip.devices.positions")

    def load_state(*args, **kwargs):
        return _positions.load_state(*args, **kwargs)

    def save_state(*args, **kwargs):
        return _positions.save_state(*args, **kwargs)

_Q1 = "Record q1 (angle: -30deg, 0.1) first."
_Q2 = "Record q2 (angle: -90deg, -pi/2) first."
_Q3 = "Record q3 (length: 2mm, 0) first."
_THETA = "Record the base tilt theta (angle)."
_PSI = "Record the base tilt psi (angle)."
_DEVICE_HELP = (
    "Controller URL: sim://, mm3a:///dev/ttyUSB0, mm3a+socket://host:port, anc300://host[:7230] "
    "(its password from $STICKSLIP_ANC300_PASSWORD; default: device in the config file, else sim://)."
)


def _parse_joint_value(joint: int, text: str, what: str) -> float:
    """A position or displacement of ``joint``: a length for joint 3, an angle for 1 and 2."""
    rotary = joint_spec(joint).rotary
    try:
        v = parse_angle(text) if rotary else parse_length(text)
    except (UnitError, ArithmeticError, ValueError, TypeError) as e:
        kind = "an angle (e.g. 2deg, 40urad)" if rotary else "a length (e.g. 30um, 1.5mm)"
        fail(f"{what}: {e}; joint {joint} takes {kind}")
    if not math.isfinite(v):
        fail(f"{what}: {text!r} is not a finite value")
    return v


def _apply_pose_options(
    state: DeviceState, q1: float | None, q2: float | None, q3: float | None, theta: float | None, psi: float | None
) -> list[str]:
    changed = []
    for j, v in ((1, q1), (2, q2), (3, q3)):
        if v is not None:
            with user_errors():
                state.set_position(j, v, "set")
            changed.append(f"q{j}")
    with user_errors():
        state.set_tilt(theta, psi)
    changed += [n for n, v in (("theta", theta), ("psi", psi)) if v is not None]
    return changed


def _plan(
    cal: Calibration, joint: int, q_from: float, q_to: float, pose: kin.Pose
) -> tuple[int, float, Callable[[int], float]]:
    """``(steps (signed int), q_end_predicted, dead_reckon(n) -> q)`` from stickslip.motion.planning."""
    from ..motion.planning import dead_reckon, plan_move

    plan = plan_move(cal, joint, q_from, q_to, pose)
    steps = int(plan.signed_steps)

    def reckon(n_signed: int) -> float:
        return float(dead_reckon(cal, joint, q_from, n_signed, pose))

    return steps, float(plan.q_end_predicted), reckon


def _state_rows(state: DeviceState) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    for j in (1, 2, 3):
        spec = JOINTS[j]
        rows.append(
            {
                "joint": j,
                "q": state.positions[j],
                "unit": spec.unit,
                "display": format_position(state.positions[j], j),
                "source": "uncertain" if j in state.uncertain else state.sources[j],
                "uncertain": list(state.uncertain[j]) if j in state.uncertain else None,
                **_track_fields(state, j),
            }
        )
    return rows


def _track_fields(state: DeviceState, joint: int) -> dict[str, float | None]:
    """``sd`` (m or rad) of the position and the learned ``step_scale`` (1) of a joint, ``None`` if untracked."""
    from ..motion.tracking import JointTrack

    raw = state.track.get(joint)
    if raw is None:
        return {"sd": None, "step_scale": None, "step_scale_sd": None}
    try:
        t = JointTrack.from_json(raw)
    except ValueError:
        return {"sd": None, "step_scale": None, "step_scale_sd": None}
    return {"sd": t.sd, "step_scale": t.scale, "step_scale_sd": t.scale_sd}


def _sd_text(sd: float, joint: int) -> str:
    """A position's spread for a person: µm (joint 3); µrad (joints 1, 2), in degrees from 1 mrad (1.37e+05 µrad
    told nobody it was 7.85 deg)."""
    if not joint_spec(joint).rotary:
        return f"{sd * 1e6:.3g} µm"
    return f"{sd * 1e6:.3g} µrad" if abs(sd) < 1e-3 else f"{math.degrees(sd):.3g} deg"


def _degree_hint(joint: int, text: str | None) -> str:
    """For a bare number on a rotary joint: ``"; a bare number is radians: did you mean 5deg?"``."""
    if not joint_spec(joint).rotary or text is None:
        return ""
    try:
        float(text.strip())
    except ValueError:
        return ""
    return f"; a bare number is radians: did you mean {text.strip()}deg?"


def _target(joint: int, state: DeviceState, by: str | None, to: str | None) -> tuple[float, float]:
    spec = JOINTS[joint]
    q_from = state.positions[joint]
    if to is not None:
        word = to.strip().lower()
        if word in ("min", "lower"):
            q_to = spec.lower
        elif word in ("max", "upper"):
            q_to = spec.upper
        else:
            q_to = _parse_joint_value(joint, to, "--to")
    else:
        q_to = q_from + _parse_joint_value(joint, by or "", "--by")
    if not spec.contains(q_to):
        unit = position_display_unit(joint)
        fail(
            f"the target {format_position(q_to, joint)} is outside joint {joint}'s range "
            f"[{format_position(spec.lower, joint)}, {format_position(spec.upper, joint)}] "
            f"(from {format_position(q_from, joint)}); positions are in {unit}"
            + _degree_hint(joint, to if to is not None else by)
        )
    return q_from, min(max(q_to, spec.lower), spec.upper)


def _move_locked(
    store: Any,
    key: str,
    device: str,
    cal: Any,
    joint: int,
    by: str | None,
    to: str | None,
    burst: int,
    pose_opts: tuple[float | None, ...],
    drive: Callable[..., Any],
    max_age: int = 0,
) -> tuple[Any, DeviceState, int, float, float, float, float | None]:
    """The part of `move` that runs holding the device lock: plan from the kept state, drive."""
    from ..procedures.conditions import usage_warnings
    from ..procedures.move import MoveOutcome

    with user_errors():
        state = load_state(store, key)
    _apply_pose_options(state, *pose_opts)
    problem = state.uncertainty_problem(joint)
    if problem:
        fail(problem)
    q_from, q_to = _target(joint, state, by, to)
    pose = state.pose
    from ..motion.tracking import joint_sigma_model, scaled_calibration, track_for

    with user_errors():  # the day's step scale learned from observations (stickslip observe)
        track, note = track_for(state.track.get(joint), cal, joint)
    if note:
        warn_later(note)
    with user_errors(KeyError):
        steps, q_end, reckon = _plan(
            scaled_calibration(cal, joint, {d: track.scale_of(d) for d in "+-"}), joint, q_from, q_to, pose
        )
    with user_errors():
        save_state(store, state)  # the recorded pose, even if nothing moves
    outcome, sim_true = MoveOutcome(), None
    if not steps:
        for w in usage_warnings(cal, None, device, joint, max_age):
            warn_later(w)
        flush_warnings()
    if steps:
        try:
            dev = open_device(device)
        except (DeviceError, ValueError) as e:
            fail(str(e))
        try:
            for w in usage_warnings(cal, dev, device, joint, max_age):
                warn_later(w)
            flush_warnings()  # the input is good: say it before driving
            if isinstance(dev, PoseSettable):  # the simulator: start where the positions say
                dev.set_pose(*pose)

            def save(st: DeviceState) -> None:
                with user_errors():
                    save_state(store, st)

            outcome = drive(dev, state, joint, steps, burst, reckon, save)
            if outcome.error is None:
                state.set_position(joint, q_end, "dead-reckoned")
            if outcome.sent and joint not in state.uncertain:  # the position's uncertainty grows with the move
                track.predict(state.positions[joint] - q_from, outcome.sent, pose, joint, joint_sigma_model(cal, joint))
                state.track[joint] = track.to_json()
            if outcome.error is None or state.track.get(joint) is not None:
                save(state)
            if outcome.error is None:
                if isinstance(dev, KnowsTruePosition):
                    sim_true = float(dev.position(joint))
        finally:
            try:
                dev.close()
            except DeviceError:
                pass
    return outcome, state, steps, q_from, q_to, q_end, sim_true


@app.command()
def move(
    joint: int = typer.Option(..., "--joint", "-j", min=1, max=3, help="Joint to move: 1, 2 or 3."),
    by: str | None = typer.Option(
        None, "--by", help="Move by: 30um, -0.5mm (joint 3); 2deg, -500urad (joints 1, 2)."
    ),
    to: str | None = typer.Option(
        None, "--to", help="Move to this position (same units as --by); 'min'/'max' = an end stop."
    ),
    calibration: Path | None = typer.Option(
        None, "--calibration", "-c",
        help="Calibration JSON (from `stickslip calibrate`; default: calibration in the config file).",
    ),
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP),
    q1: float | None = typer.Option(None, "--q1", parser=angle_option, help=_Q1),
    q2: float | None = typer.Option(None, "--q2", parser=angle_option, help=_Q2),
    q3: float | None = typer.Option(None, "--q3", parser=length_option, help=_Q3),
    theta: float | None = typer.Option(None, "--theta", parser=angle_option, help=_THETA),
    psi: float | None = typer.Option(None, "--psi", parser=angle_option, help=_PSI),
    burst: int = typer.Option(1000, "--burst", min=1, max=65535, help="Steps per burst."),
    max_age: int | None = typer.Option(
        None, "--max-age", min=0, max=36500,
        help="Warn when the calibration is more than this many days old (default $STICKSLIP_MAX_AGE_DAYS, "
        "else max_age_days in the config file, else 0).",
    ),
    db: Path | None = typer.Option(None, "--db", help=DB_HELP),
    json_out: bool = typer.Option(False, "--json", help="Print steps, bursts, end as JSON."),
) -> None:
    """Move a joint by a distance or to a position, with the calibrated step-size model.

    The pose is the one kept for the device (see `stickslip where`).

    --q1 --q2 --q3 --theta --psi record a new pose first.

    Steps come from the calibration's model in that pose (exact for rotary joints).

    They are sent in bursts; the dead-reckoned position is kept after every burst.

    The steps use the day's step scale learned from measured positions (stickslip
    observe), and the position's standard deviation grows with the move.

    Example: stickslip move -d mm3a:///dev/ttyUSB0 -c cal.json --joint 3 --by 30um
    """
    if (by is None) == (to is None):
        fail("give exactly one of --by and --to")
    from ..calibration import Calibration

    device = device_url(device)
    with user_errors(KeyError):
        cal = Calibration.load(calibration_file(calibration))
    with user_errors():
        key = device_key(device)
    days = max_age_setting(max_age).value
    spec = JOINTS[joint]
    from ..procedures.move import DeviceBusy, device_lock, drive

    with open_store(db) as store, user_errors(DeviceBusy):
        with device_lock(store, key):
            outcome, state, steps, q_from, q_to, q_end, sim_true = _move_locked(
                store, key, device, cal, joint, by, to, burst, (q1, q2, q3, theta, psi), drive, days
            )
    if outcome.error is not None:
        if joint in state.uncertain:
            lo, hi = state.uncertain[joint]
            kept = (
                f"joint {joint}'s position is now uncertain, between {format_position(lo, joint)} "
                f"and {format_position(hi, joint)}; re-reference it (stickslip where --set {joint}=min "
                f"at the lower stop) before the next move"
            )
        else:
            kept = f"joint {joint}'s dead-reckoned position {format_position(state.positions[joint], joint)} is kept"
        fail(f"{outcome.error}; sent {outcome.sent} of {steps} steps; {kept}")
    bursts = outcome.bursts
    result = {
        "device": key,
        "joint": joint,
        "direction": "+" if steps >= 0 else "-",
        "steps": abs(steps),
        "steps_signed": steps,
        "bursts": bursts,
        "q_from": q_from,
        "q_to": q_to,
        "q_end_predicted": q_end,
        "unit": spec.unit,
    }
    tf = _track_fields(state, joint)  # the position's standard deviation and the step scale the move used
    if tf["sd"] is not None:
        result.update({"q_sd": tf["sd"], "step_scale": tf["step_scale"], "step_scale_sd": tf["step_scale_sd"]})
    if sim_true is not None:
        result["sim_true_end"] = sim_true
    if json_out:
        print_json(result)
        return
    console.print(
        f"joint {joint}: {format_position(q_from, joint)} -> {format_position(q_to, joint)}: "
        f"{steps:+d} steps in {len(bursts)} burst(s); planned end {format_position(q_end, joint)}"
        + (f" ± {_sd_text(tf['sd'], joint)} (step scale x{tf['step_scale'] or 1.0:.4f})"
           if tf["sd"] is not None else ""),
        highlight=False,
    )
    if sim_true is not None:
        err = sim_true - q_end
        k, unit = step_scale(joint)  # nm / µrad; a miss of a micrometre or more in µm (as the ± above)
        if abs(err * k) < 1000:
            shown = f"{err * k:+.1f} {unit}"
        else:  # a miss of a micrometre or a milliradian or more: in the position's own unit
            shown = f"{math.degrees(err):+.3f} deg" if joint_spec(joint).rotary else f"{err * 1e6:+.2f} µm"
        console.print(
            f"simulator's true end {format_position(sim_true, joint)} ({shown})", highlight=False
        )


def _probe(device: str) -> dict[str, Any]:
    """Open ``device`` and close it again: what it says about itself, or ``fail`` naming why it does not answer.

    ``{"model": ..., **info.extra}``: for a NanoControl the dialect, firmware version,
    stepping frequencies and active speed profile (docs/devices/nanocontrol.md).
    """
    try:
        dev = open_device(device)
    except (DeviceError, ValueError, OSError) as e:
        fail(f"the device does not answer: {e} (use --offline to see the kept positions only)")
    try:
        info = dev.info
        return {"model": str(info.model), **{str(k): v for k, v in info.extra.items()}}
    except (DeviceError, ValueError, OSError) as e:
        fail(f"the device does not answer: {e} (use --offline to see the kept positions only)")
    finally:
        try:
            dev.close()
        except (DeviceError, OSError):
            pass


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
    db: Path | None = typer.Option(None, "--db", help=DB_HELP),
    offline: bool = typer.Option(
        False, "--offline", help="Do not open the device: only show the kept positions."
    ),
    unlock: bool = typer.Option(
        False, "--unlock", help="Release the device's lock left by a process that is gone."
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the positions as JSON (SI units)."),
) -> None:
    """Show (or reset) the dead-reckoned joint positions and base tilt kept for a device.

    Source: default (never set; outstretched pose assumed), set, dead-reckoned,
    observed (stickslip observe), or uncertain (a move was interrupted: the bounds are
    shown; re-reference with --set). A joint moved since it was set shows ± its standard
    deviation and the step scale learned from observations.

    Reset a joint at an end stop after a traverse, a crash or a manual move.

    Without --set or a pose option the device is opened to say whether it answers
    (--offline skips that); a device that does not answer exits 2. A NanoControl
    also reports its dialect (console or legacy), firmware version, stepping
    frequencies and active speed profile (in --json: "info").

    Example: stickslip where -d mm3a:///dev/ttyUSB0 --set 3=min --set 2=max
    """
    device = device_url(device)
    with user_errors():
        key = device_key(device)
    with open_store(db) as store:
        if unlock:
            with user_errors():
                store.set_state(key, "lock", "null")
        with user_errors():
            state = load_state(store, key)
        changed = _apply_pose_options(state, q1, q2, q3, theta, psi)
        for item in set_ or []:
            j_text, sep, value = item.partition("=")
            if not sep or j_text.strip() not in ("1", "2", "3"):
                fail(f"--set {item!r}: write JOINT=VALUE, e.g. 3=0, 3=min, 2=-90deg")
            j = int(j_text)
            spec = JOINTS[j]
            word = value.strip().lower()
            if word in ("min", "lower"):
                q = spec.lower
            elif word in ("max", "upper"):
                q = spec.upper
            else:
                q = _parse_joint_value(j, value, f"--set {item}")
            try:
                state.set_position(j, q, "set")
            except ValueError as e:
                fail(f"--set {item}: {e}{_degree_hint(j, value)}")
            changed.append(f"q{j}")
        if changed:
            with user_errors():
                save_state(store, state)
    info = None if (changed or offline) else _probe(device)
    answers = info["model"] if info else None
    rows = _state_rows(state)
    if json_out:
        print_json(
            {"device": key, "joints": rows, "theta": state.theta, "psi": state.psi, "answers": answers,
             "info": info}
        )
        return
    console.print(styled(key, "bold"), *([f"(answers: {answers})"] if answers else []), highlight=False)
    line = _info_line(info) if info else None
    if line:
        console.print(f"  {line}", highlight=False)
    for r, j in zip(rows, (1, 2, 3), strict=True):
        extra = ""
        tf = _track_fields(state, j)
        if tf["sd"] is not None and j not in state.uncertain:
            extra = f", ± {_sd_text(tf['sd'], j)}, step scale x{tf['step_scale'] or 1.0:.4f}"
        if j in state.uncertain:
            lo, hi = state.uncertain[j]
            extra = f", between {format_position(lo, j)} and {format_position(hi, j)}"
        console.print(
            f"  joint {j}: {r['display']:>14}  ({r['source']}{extra})", highlight=False
        )
    console.print(
        f"  tilt: theta = {math.degrees(state.theta):.4g} deg, "
        f"psi = {math.degrees(state.psi):.4g} deg",
        highlight=False,
    )
