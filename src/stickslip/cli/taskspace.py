"""Task-space commands: ``reach`` (a straight tip move) and ``jog`` (teleoperation from the keyboard).

The tip is in the base frame before the base tilt (docs/design.md §9), metres inside;
on the command line coordinates take units (``--by 20um,-10um,5um``). Positions are
kept per device in the database exactly as for ``move`` and ``where``.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ..devices.base import DeviceError, command_url, device_key
from ..units import UnitError, bare_number_problem, format_position, parse_length
from . import app
from ._common import (
    angle_option,
    calibration_file,
    db_option,
    device_url,
    fail,
    flush_warnings,
    geometry_setting,
    length_option,
    max_age_setting,
    open_store,
    print_json,
    say,
    user_errors,
    warn,
    warn_later,
)
from .camera import (
    CAMERA_CALIBRATION_HELP,
    CAMERA_LOOP_HELP,
    CAMERA_TIP_HELP,
    camera_errors,
    camera_loop,
    run_seen,
)
from .rig import rig_arm

if TYPE_CHECKING:
    from .. import kinematics as kin
    from ..procedures.reach import ReachResult
    from ..rig import Arm

_DEVICE_HELP = (
    "Controller URL: sim://, mm3a:///dev/ttyUSB0, mm3a+socket://host:port, anc300://host[:7230] "
    "(its password from $STICKSLIP_ANC300_PASSWORD; default: device in the config file, else sim://)."
)
_GEOMETRY_HELP = (
    "OFFSET,LENGTH of the arm: joint-1 axis to joint-2 axis, joint-2 axis to the tip at q3 = 0 "
    "(default: the geometry table of the config file, else 0mm,21mm; measure yours, see docs/taskspace.md)."
)
_CAL_HELP = "Calibration JSON (from `stickslip calibrate`; default: calibration in the config file)."


def parse_point(text: str, what: str) -> tuple[float, float, float]:
    """``"X,Y,Z"`` lengths with their units (``20um,-10um,5um``; 0 needs none) to metres."""
    from ..procedures.reach import MAX_TIP_M

    parts = text.split(",")
    if len(parts) != 3:
        fail(f"{what} {text!r}: write three lengths X,Y,Z, e.g. 20um,-10um,5um")
    out = []
    for axis, part in zip("XYZ", parts, strict=True):
        bare = bare_number_problem(part, "length")
        if bare is not None:
            fail(f"{what} {axis}: {bare}")
        try:
            v = parse_length(part)
        except (UnitError, ArithmeticError, ValueError) as e:
            fail(f"{what} {axis} = {part.strip()!r}: {e}")
        if not math.isfinite(v) or abs(v) > MAX_TIP_M:
            fail(f"{what} {axis} = {part.strip()!r} is not a length within {MAX_TIP_M:g} m")
        out.append(v)
    return (out[0], out[1], out[2])


def parse_geometry(text: str | None) -> kin.Geometry:
    """``--geometry OFFSET,LENGTH`` to a :class:`~stickslip.kinematics.Geometry`.

    Without the option: the config file's ``[geometry]``, else the default (0mm,21mm).
    """
    return geometry_setting(text).value


def _um(v: tuple[float, float, float] | list[float]) -> str:
    return "(" + ", ".join(f"{x * 1e6:.2f}" for x in v) + ") µm"


def _miss(d: float) -> str:
    """A distance from the target: nm below a micrometre, µm above ('391403 nm' is 391.4 µm)."""
    return f"{d * 1e9:.0f} nm" if d < 1e-6 else f"{d * 1e6:.3g} µm" if d < 1e-3 else f"{d * 1e3:.4g} mm"


@app.command()
def reach(
    calibration: Path | None = typer.Option(None, "--calibration", "-c", help=_CAL_HELP),
    to: str | None = typer.Option(
        None, "--to", metavar="<x,y,z>", help="Tip target X,Y,Z in the base frame (lengths): 21mm,0,50um."
    ),
    by: str | None = typer.Option(
        None, "--by", metavar="<x,y,z>", help="Tip displacement DX,DY,DZ (lengths): 20um,-10um,5um."
    ),
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP),
    q1: float | None = typer.Option(None, "--q1", parser=angle_option, help="Record q1 (angle) first."),
    q2: float | None = typer.Option(None, "--q2", parser=angle_option, help="Record q2 (angle) first."),
    q3: float | None = typer.Option(None, "--q3", parser=length_option, help="Record q3 (length) first."),
    theta: float | None = typer.Option(None, "--theta", parser=angle_option, help="Record the base tilt theta."),
    psi: float | None = typer.Option(None, "--psi", parser=angle_option, help="Record the base tilt psi."),
    geometry: str | None = typer.Option(None, "--geometry", help=_GEOMETRY_HELP),
    segment: float = typer.Option(
        "10um", "--segment", parser=length_option, help="Longest segment of the line, a length from 10nm to 1mm.",
    ),
    burst: int = typer.Option(1000, "--burst", min=1, max=65535, help="Most steps per burst."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Plan and print; send nothing, keep nothing."),
    from_unreferenced: bool = typer.Option(
        False, "--from-unreferenced",
        help="Plan from joints never referenced (positions assumed); without it they are refused on a real "
        "controller, with the commands that reference them.",
    ),
    trust_calibration: bool = typer.Option(
        False, "--trust-calibration",
        help="Use a calibration that does not record its device, or was made on the simulator, on a real "
        "controller (refused without it: its step sizes may be another arm's).",
    ),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print the plan as JSON (metres, radians)."),
    camera: str | None = typer.Option(None, "--camera", help=CAMERA_LOOP_HELP),
    camera_tip: str | None = typer.Option(None, "--camera-tip", metavar="<x,y>", help=CAMERA_TIP_HELP),
    camera_calibration: Path | None = typer.Option(
        None, "--camera-calibration", metavar="<file>", help=CAMERA_CALIBRATION_HELP
    ),
    rig_file: Path | None = typer.Option(
        None, "--rig", help="Rig file (docs/rig.md): the arm's controller, calibration and geometry come from it, "
        "and the whole line is checked against the rig's envelope first.",
    ),
    arm: str | None = typer.Option(None, "--arm", help="Arm of the rig (default: its first arm)."),
) -> None:
    """Move the tip in a straight line to a point or by a displacement (task space).

    The tip is in the base frame before the base tilt (x along the outstretched arm at
    q1 = 0, z up the joint-1 axis), from the positions kept for the device (see
    `stickslip where`); --q1 --q2 --q3 --theta --psi record a new pose first.

    The line is cut into segments (at most --segment, and at most 2 % of the move but not under 50 nm);
    each segment's joint increments come from the inverse kinematics and its steps from
    the calibrated models in the current pose, scaled by each joint's step scale learned
    from measured positions (stickslip observe), as move plans, joints 1, 2, 3 in that
    order, rounding remainders carried to the next segment.

    A target out of reach or a line near joint 1's axis (a singular pose) is refused
    before any step is sent. Without --dry-run the positions are kept after every burst,
    as for `move`.

    With --rig FILE (and --arm NAME) the line, as driven, is checked against the
    rig's keep-out volumes, soft limits and other arms before a step is sent.

    Example: stickslip reach -c cal.json -d mm3a:///dev/ttyUSB0 --by 20um,-10um,5um
    """
    if (by is None) == (to is None):
        fail("give exactly one of --by and --to")
    point = parse_point(to if to is not None else str(by), "--to" if to is not None else "--by")
    geom = parse_geometry(geometry)
    in_rig = rig_arm(rig_file, arm, device, geometry, calibration, db)
    if in_rig is not None:
        device, geom, calibration, db = in_rig.device, in_rig.geometry, in_rig.calibration, in_rig.database
    device = device_url(device)
    from ..calibration import Calibration
    from ..motion.reach import borrow_joint1
    from ..procedures.move import DeviceBusy, PoseUpdate
    from ..procedures.reach import ReachRequest
    from ..procedures.reach import reach as reach_line

    with user_errors(KeyError):
        cal, borrowed = borrow_joint1(Calibration.load(calibration_file(calibration)))
    with user_errors():
        device_key(device)
    request = ReachRequest(
        device, to=point if to is not None else None, by=point if to is None else None, geometry=geom,
        segment=float(segment), burst=burst, pose=PoseUpdate(q1, q2, q3, theta, psi),
        max_age_days=0 if dry_run else max_age_setting(None).value, dry_run=dry_run,
        from_unreferenced=from_unreferenced, trust_calibration=trust_calibration,
        joints=None if in_rig is None else in_rig.joints, stage=None if in_rig is None else in_rig.stage,
        state_key=None if in_rig is None else in_rig.state_key,
    )
    if camera_tip is not None and camera is None:
        fail("--camera-tip goes with --camera")
    if camera_calibration is not None and camera is None:
        fail("--camera-calibration goes with --camera")
    if camera is not None and dry_run:
        fail("--dry-run plans without moving: the camera closes the loop of a move (drop one of them)")
    if camera is not None:  # the closed loop: stickslip.procedures.closed_loop
        run_seen("reach", request, cal, camera, camera_tip, db, json_out, borrowed, rig_arm=in_rig,
                 camera_calibration=camera_calibration)
        return
    with open_store(db) as store, user_errors(DeviceBusy, KeyError, DeviceError):
        if in_rig is not None:
            request = dataclasses.replace(request, guard=in_rig.guard(store))
        result = reach_line(store, request, cal, borrowed, warn=warn_later, ready=flush_warnings,
                            opener=None if in_rig is None else in_rig.stoppable(store))
    failure = result.failure()
    if failure is not None:
        fail(failure)
    _print_plan(result, json_out, None if in_rig is None else in_rig.rig.arm(in_rig.arm))


def _print_plan(result: ReachResult, json_out: bool, arm: Arm | None = None) -> None:
    """``reach``'s output; with a rig's ``arm``, also its name and the tip in the rig frame (its mount's pose)."""
    plan = result.plan
    rig_frame = None
    if arm is not None:
        rig_frame = {k: [float(v) for v in arm.tip(q)] for k, q in (("start", plan.q_start), ("end", plan.q_end))}
    if json_out:
        extra = {} if arm is None else {"arm": arm.name, "rig_frame": rig_frame}
        print_json({**extra, **result.as_dict()})
        return
    n1, n2, n3 = plan.total_steps
    verb = "moved" if result.moved else "plan"
    say(f"{verb}: tip {_um(plan.tip_start)} -> {_um(plan.target)}")
    say(
        f"  {plan.length * 1e6:.2f} µm in {len(plan.segments)} segment(s); steps |joint 1| {n1}, |joint 2| {n2}, "
        f"|joint 3| {n3}"
    )
    say(f"predicted end {_um(plan.tip_end)}, {_miss(plan.end_error)} from the target")
    q = plan.q_end
    js = result.state.joints  # the arm's: a stage's joints in µm
    say(
        f"  joints q1 = {format_position(q[0], js[1])}, q2 = {format_position(q[1], js[2])}, "
        f"q3 = {format_position(q[2], js[3])}"
    )
    if rig_frame is not None:
        a, b = (", ".join(f"{x * 1e6:.2f}" for x in rig_frame[k]) for k in ("start", "end"))
        say(f"  rig frame: ({a}) -> ({b}) µm")
    if result.sim_true is not None:
        true_tip = [float(v) for v in plan.tip_of(result.sim_true)]
        err = math.dist(true_tip, plan.target)
        say(f"simulator's true tip {_um(true_tip)}, {_miss(err)} from the target")


# ---------------------------------------------------------------- jog: the terminal part


def _need_terminal() -> None:
    """Refuse jog (one line, exit 2) when stdin is no terminal (POSIX: Windows reads the console itself)."""
    import sys

    if sys.platform != "win32" and not sys.stdin.isatty():
        fail("jog needs a terminal: its keys are read from stdin, which is not a terminal here")


def _ready_to_jog() -> None:
    """The input is checked and the session about to start: a missing terminal is its last refusal, so it comes
    before the queued warnings (a command that fails prints only its error)."""
    if getattr(_Keys, "reads_the_terminal", False):  # a key source that stands in for the terminal needs none
        _need_terminal()
    flush_warnings()


class _Keys:
    """Raw key input from the terminal: POSIX ``termios``/``tty`` (cbreak) or Windows ``msvcrt``."""

    reads_the_terminal = True

    def __init__(self) -> None:
        import sys

        self._saved: Any = None
        self._fd = -1
        if sys.platform == "win32":  # pragma: no cover - exercised on Windows only
            return
        import termios
        import tty

        _need_terminal()
        self._fd = sys.stdin.fileno()
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)  # keys at once, no echo; Ctrl-C still interrupts

    def read(self, timeout: float) -> list[str]:
        """Key names typed within ``timeout`` seconds."""
        from ..procedures.jog import parse_keys

        if self._fd < 0:  # pragma: no cover - Windows
            import msvcrt
            import time

            end = time.monotonic() + timeout
            data = b""
            while time.monotonic() < end:
                while msvcrt.kbhit():  # type: ignore[attr-defined]  # msvcrt exists on Windows only
                    data += msvcrt.getch()  # type: ignore[attr-defined]  # same
                if data:
                    break
                time.sleep(0.01)
            return parse_keys(data)
        import os
        import select

        ready, _, _ = select.select([self._fd], [], [], timeout)
        if not ready:
            return []
        return parse_keys(os.read(self._fd, 256))

    def close(self) -> None:
        if self._saved is not None:
            import termios

            termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            self._saved = None


_KEY_HELP = (
    "keys: arrows or A/D, W/S: -x/+x, +y/-y; PgUp/PgDn or R/F: +z/-z; space: stop",
    "1-7: speed; m: single-step; b: base/image frame; [ ]: turn image frame; q: quit",
)


def _status_lines(s: Any) -> list[str]:
    """The live display's lines, each at most 80 characters (the message may be longer: it is cut to fit)."""
    lines = ["tip (predicted, base frame) x y z: " + " ".join(f"{v * 1e6:+10.2f}" for v in s.tip) + " µm"]
    for j in (1, 2, 3):
        q, lim = s.q[j - 1], s.to_limits[j - 1]
        if s.kinds[j - 1] == "prismatic":
            shown, left = f"{q * 1e6:10.2f} µm ", f"{lim * 1e6:.2f} µm"
        else:
            shown, left = f"{math.degrees(q):10.4f} deg", f"{math.degrees(lim):.4f} deg"
        seen = f" {s.sources[j - 1]}" if s.sources[j - 1] else ""
        lines.append(f"joint {j}: {shown}  to its nearer limit {left}  sent {s.sent[j - 1]:+d}{seen}")
    mode = f"single-step {s.speed * 1e6:g} µm/press" if s.single_step else f"speed {s.speed * 1e6:g} µm/s"
    frame = f"image frame ({math.degrees(s.image_angle):+.0f} deg)" if s.image_frame else "base frame"
    rates = " ".join(f"{r:+.0f}" for r in s.rates)
    lines.append(f"{mode} | {frame} | steps/s {rates}")
    lines.append(s.message or "")
    lines.extend(_KEY_HELP)
    return lines


class _Screen:
    """The live status display: redrawn in place (rich ``Live``), one row per line at any width.

    Every line is cut to the terminal's width rather than wrapped (a wrapped line would
    make the redraw miss it, and the screen scroll on every update); at 80 columns and
    more nothing but an over-long message is cut.
    """

    def __init__(self) -> None:
        from ._output import SafeConsole

        self._console = SafeConsole()
        self._live: Any = None
        self._shown: list[str] = []

    def _frame(self, lines: list[str]) -> Any:
        from rich.console import Group
        from rich.text import Text

        return Group(*(Text(line, no_wrap=True, overflow="ellipsis") for line in lines))

    def show(self, status: Any) -> None:
        lines = _status_lines(status)
        if lines == self._shown:
            return
        self._shown = lines
        if self._live is None:
            from rich.live import Live

            self._live = Live(  # our console writes to sys.stdout itself: no redirection of it into the Live
                self._frame(lines),
                console=self._console,
                auto_refresh=False,
                redirect_stdout=False,
                redirect_stderr=False,
            )
            self._live.start(refresh=True)
        else:
            self._live.update(self._frame(lines), refresh=True)

    def close(self) -> None:
        """End the display (the last frame stays on the screen)."""
        if self._live is not None:
            self._live.stop()
            self._live = None


@app.command()
def jog(
    calibration: Path | None = typer.Option(None, "--calibration", "-c", help=_CAL_HELP),
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP),
    q1: float | None = typer.Option(None, "--q1", parser=angle_option, help="Record q1 (angle) first."),
    q2: float | None = typer.Option(None, "--q2", parser=angle_option, help="Record q2 (angle) first."),
    q3: float | None = typer.Option(None, "--q3", parser=length_option, help="Record q3 (length) first."),
    theta: float | None = typer.Option(None, "--theta", parser=angle_option, help="Record the base tilt theta."),
    psi: float | None = typer.Option(None, "--psi", parser=angle_option, help="Record the base tilt psi."),
    geometry: str | None = typer.Option(None, "--geometry", help=_GEOMETRY_HELP),
    image_angle: float = typer.Option(
        "0", "--image-angle", parser=angle_option, help="Image frame's turn about z0 (angle; keys [ ] change it)."
    ),
    speed: int = typer.Option(4, "--speed", min=1, max=7, help="Speed preset 1-7: 0.1, 0.3, 1, 3, 10, 30, 100 µm/s."),
    max_rate: float = typer.Option(
        1000.0, "--max-rate", min=1.0, max=20000.0, help="Most steps per second of any joint (also the controller's)."
    ),
    hold: float = typer.Option(
        0.5, "--hold", min=0.0, max=10.0, help="Seconds a direction key keeps moving without a repeat (0: until space)."
    ),
    from_unreferenced: bool = typer.Option(
        False, "--from-unreferenced",
        help="Plan from joints never referenced (positions assumed); without it they are refused on a real "
        "controller, with the commands that reference them.",
    ),
    trust_calibration: bool = typer.Option(
        False, "--trust-calibration",
        help="Use a calibration that does not record its device, or was made on the simulator, on a real "
        "controller (refused without it: its step sizes may be another arm's).",
    ),
    db: str | None = db_option(),
    camera: str | None = typer.Option(
        None, "--camera", help="A camera that looks at the tip (pixel= in its URL): the joints it sees are shown "
        "and kept as seen, their step scales corrected as the tip moves.",
    ),
    camera_tip: str | None = typer.Option(None, "--camera-tip", metavar="<x,y>", help=CAMERA_TIP_HELP),
    camera_calibration: Path | None = typer.Option(
        None, "--camera-calibration", metavar="<file>", help=CAMERA_CALIBRATION_HELP
    ),
    rig_file: Path | None = typer.Option(
        None, "--rig", help="Rig file (docs/rig.md): the arm's controller, calibration and geometry come from it, "
        "and the tip stops at the rig's envelope.",
    ),
    arm: str | None = typer.Option(None, "--arm", help="Arm of the rig (default: its first arm)."),
) -> None:
    """Steer the tip from the keyboard (teleoperation in task space).

    Arrow keys or W/A/S/D move the tip along x and y, PgUp/PgDn or R/F along z, in the
    base frame or in an image frame turned about z0 to match the microscope (b toggles,
    [ and ] turn it by 15 deg). Keys 1-7 pick the speed (0.1 to 100 µm/s); m toggles
    single-step mode, where each press moves the tip by the preset's distance
    (0.1 to 100 µm); space stops at once; q quits.

    With --camera the tip is looked at each time it has moved 8 px or stopped: the
    joints the camera sees are shown and kept as seen (docs/vision.md).

    The tip velocity becomes joint velocities through the inverse Jacobian and step
    rates through the calibrated step sizes in the current pose, capped at --max-rate
    (all joints slowed together, so the direction is kept). The predicted tip, the
    joints and their distance to the end stops are shown live; positions are kept after
    every burst, as for `move`. Motion stops near an end stop or joint 1's axis.

    With --rig FILE (and --arm NAME) motion also stops before a step that would leave
    the rig's envelope (volumes, soft limits, other arms).

    Example: stickslip jog -c cal.json -d mm3a:///dev/ttyUSB0 --speed 5
    """
    from ..calibration import Calibration
    from ..motion.reach import borrow_joint1
    from ..procedures.jog import JogRequest
    from ..procedures.jog import jog as jog_session
    from ..procedures.move import DeviceBusy, PoseUpdate
    from ..procedures.reach import BORROWED_JOINT1

    geom = parse_geometry(geometry)
    if rig_file is not None and camera is not None:
        fail("jog --camera with --rig: a jog's camera is not used in a rig yet (use one of them)")
    in_rig = rig_arm(rig_file, arm, device, geometry, calibration, db)
    if in_rig is not None:
        device, geom, calibration, db = in_rig.device, in_rig.geometry, in_rig.calibration, in_rig.database
    device = device_url(device)
    with user_errors(KeyError):
        cal, borrowed = borrow_joint1(Calibration.load(calibration_file(calibration)))
    if borrowed:
        warn_later(BORROWED_JOINT1)
    with user_errors():
        device_key(device)
    request = JogRequest(
        device, geom, float(image_angle), speed, max_rate, hold, PoseUpdate(q1, q2, q3, theta, psi),
        max_age_setting(None).value, from_unreferenced, trust_calibration,
        camera_loop(camera, camera_tip, camera_calibration),
    )
    screen = _Screen()
    try:
        with open_store(db) as store, user_errors(DeviceBusy, DeviceError, *(camera_errors() if camera else ())):
            if in_rig is not None:
                request = dataclasses.replace(request, guard=in_rig.guard(store), joints=in_rig.joints,
                                              stage=in_rig.stage, state_key=in_rig.state_key)
            result = jog_session(
                store, request, cal, keys=_Keys, show=screen.show, warn=warn_later, ready=_ready_to_jog,
                opener=None if in_rig is None else in_rig.stoppable(store),
            )
    finally:
        screen.close()
    if result.error is not None:
        fail(f"{result.error}; the session ended; positions are kept (see `stickslip where`)")
    s = result.status
    say(f"jog ended: tip {_um(s.tip)}; steps sent per joint {s.sent}")
    say(f"positions kept for {result.device}")
    if result.state.uncertain:  # Ctrl-C in the middle of a burst
        joints = ", ".join(str(j) for j in sorted(result.state.uncertain))
        warn(
            f"joint(s) {joints} were interrupted mid-burst and are uncertain: re-reference them at the lower stop "
            f"(stickslip where -d {command_url(result.device)} --set J=min for each)"
        )
