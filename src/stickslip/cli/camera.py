"""``stickslip camera``: see the tip: locate it in recorded frames, calibrate the camera against the arm, grab a frame.

The workflows live in the library (:func:`stickslip.vision.locate.locate`,
:func:`stickslip.procedures.camera.calibrate_camera`); these commands parse, call one and
print. Pixel convention: x to the right, y down, the centre of the top-left pixel at (0, 0).
"""

from __future__ import annotations

import dataclasses
import math
import re
import unicodedata
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ..devices.base import DeviceError, PoseSettable, device_key, open_device
from . import app
from ._common import (
    OneLineErrors,
    console,
    db_option,
    device_url,
    err_console,
    fail,
    open_store,
    print_json,
    say,
    user_errors,
    warn,
)
from ._output import styled

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ..devices.base import Controller
    from ..kinematics import Pose
    from ..procedures.camera import CameraCalibrationResult
    from ..storage import Store
    from ..vision.camera import Camera
    from ..vision.locate import Located

PIXELS = "Pixels: x to the right, y down, the centre of the top-left pixel at (0, 0)."

camera_app = typer.Typer(
    name="camera",
    cls=OneLineErrors,
    no_args_is_help=True,
    rich_markup_mode="rich",
    help=(
        "See the tip: track it in microscope frames, measure step sizes with the camera.\n\n"
        "Cameras are URLs like devices: simcam:// (a simulated microscope over sim://), files://frames/*.png, "
        "video://run.avi, opencv://0; each takes pixel=0.5um. " + PIXELS + " See docs/vision.md."
    ),
)
app.add_typer(camera_app, name="camera", rich_help_panel="Drive a manipulator")

_CAMERA_HELP = (
    "Camera URL: simcam://?look=sem (the simulated microscope; needs -d sim://), files://FOLDER, video://FILE, "
    "opencv://0; pixel=0.5um gives the pixel size."
)
_DEVICE_HELP = "Controller URL: sim://, mm3a:///dev/ttyUSB0, anc300://host (default: the config file's, else sim://)."


_DECIMAL = re.compile(r"\s*[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|(?i:nan|inf|infinity))\s*")
"""A plain decimal number, or nan/inf for the finite check to name (Python's float() also takes 1_0 for 10
and Arabic-Indic digits)."""


def _pixel(text: str, what: str) -> tuple[float, float]:
    """``"X,Y"`` as two finite pixel coordinates."""
    parts = unicodedata.normalize("NFKC", text).split(",")  # full-width digits, as the unit parser takes them
    try:
        if len(parts) != 2 or not all(_DECIMAL.fullmatch(p) for p in parts):
            raise ValueError
        x, y = float(parts[0]), float(parts[1])
    except ValueError:
        fail(f"{what} {text!r}: write X,Y in pixels, e.g. 240.5,131 ({PIXELS})")
    if not (math.isfinite(x) and math.isfinite(y)):
        fail(f"{what} {text!r}: the pixel must be finite")
    return x, y


@camera_app.command("locate")
def locate_cmd(
    frames: list[str] = typer.Argument(
        ..., help="Frames: image files (PNG, TIFF; 8 or 16 bit; grey or colour), folders, globs, or one video file."
    ),
    tip: str = typer.Option(
        ..., "--tip",
        help="The tip in the first frame, X,Y in pixels; the needle is learnt there, so start with a frame in focus. "
        + PIXELS,
    ),
    json_out: bool = typer.Option(False, "--json", help="Print a JSON list: one object per frame, in order."),
) -> None:
    """Find the tip in every frame, from where it is in the first.

    Each frame gets a sub-pixel position and a score (0..1, the correlation with the tip
    as first seen), or a refusal with its reason: out of the field, occluded, out of
    focus, or lost. A refused tip is looked for again in the next frames. A position is
    never a guess: a frame the tracker cannot vouch for is refused.

    Pixels: x to the right, y down, the centre of the top-left pixel at (0, 0).

    With --json: [{"frame": ..., "x": ..., "y": ..., "score": ...}, {"frame": ..., "lost": "reason"}, ...].

    Every frame is read and checked first: a bad file (corrupt, truncated, a stack, NaN
    pixels, another size than the first) exits 2 with its name and nothing printed.

    A first frame whose needle edges read blurred by more than 1.6 px gets one warning line
    on stderr ("the first frame looks out of focus"): the needle is learnt from the first
    frame, and one out of focus costs every later fix; start the frames where the tip is in
    focus. The frames are tracked as without it (same output, exit 0).

    Frames are read as stored: a file whose EXIF orientation is not 1 (a viewer turns it) gets
    one warning line, as does a TIFF that states a pixel size (not used: the answers are pixels).

    Example: stickslip camera locate frames/*.png --tip 307,256 --json
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from ..vision.camera import CameraError
    from ..vision.frame import ImageError
    from ..vision.locate import locate
    from ..vision.template import TemplateError

    at = _pixel(tip, "--tip")
    with Progress(TextColumn("locating"), BarColumn(), MofNCompleteColumn(),  # 0/? until the frames are counted
                  console=err_console, transient=True, disable=not err_console.is_terminal) as bar:
        task = bar.add_task("locate", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total or None)

        try:
            found = locate(frames, at, progress=progress)
        except (ImageError, CameraError, TemplateError) as e:
            fail(str(e))
    _warn_focus(found)
    _warn_stated(found)
    if json_out:
        print_json([f.as_dict() for f in found])
        return
    _print_located(found)


def _warn_focus(found: list[Located]) -> None:
    """One warning line when the first frame's needle edges read blurred over ``TrackerParams.focus_warn`` px."""
    from ..vision.template import TrackerParams

    focus = found[0].focus if found else None
    if focus is not None and focus.sigma > TrackerParams().focus_warn:
        warn(f"the first frame looks out of focus (the needle's edge blurred by about {focus.sigma:.1f} px): "
             "the tip is tracked best from a frame in focus; start the frames there")


_ORIENTATIONS = {2: "mirrored left to right", 3: "turned 180°", 4: "mirrored top to bottom",
                 5: "mirrored and turned 90°", 6: "turned 90° clockwise", 7: "mirrored and turned 90°",
                 8: "turned 90° counter-clockwise"}


def _warn_stated(found: list[Located]) -> None:
    """One warning line for a frame whose file states an orientation other than 1 (pixels are read as stored),
    one for a file that states a pixel size (not used)."""
    stated_pixel = found[0].stated_pixel if found else None
    if stated_pixel is not None:
        warn(stated_pixel_line(*stated_pixel) + ": camera locate answers in pixels; where a size is needed, "
             "a camera URL takes it: files://FOLDER?pixel=0.5um")
    turned = found[0].turned if found else None
    if turned is not None:
        name, stated = turned
        how = _ORIENTATIONS.get(stated.orientation, "turned")
        warn(f"{name} states orientation {stated.orientation} (a viewer shows it {how}): the frames are read as "
             "stored, so --tip and every answer are in stored pixels (x right, y down from the stored top-left "
             "pixel), not as a viewer that turns the image shows them")


def stated_pixel_line(name: str, stated: Any) -> str:
    """``NAME states a pixel of ... (where), not used``: the start of the line for a file's stated pixel size."""
    x, y = stated.pixel_m
    size = f"{x * 1e6:.4g} µm" if math.isclose(x, y, rel_tol=1e-6) else (
        f"{x * 1e6:.4g} x {y * 1e6:.4g} µm (not square: a frame's pixel size is one number)")
    return (f"{name} states a pixel of {size} ({stated.pixel_from}); it is not used (a scanner's 72 dpi is "
            "not a microscope's pixel)")


def _print_located(found: list[Located]) -> None:
    from rich.table import Table

    t = Table(title=f"tip in {len(found)} frames (px; x right, y down)")
    for col in ("frame", "x", "y", "score", "refused"):
        t.add_column(col, justify="right" if col in ("x", "y", "score") else "left")
    for f in found:
        if f.fix is not None:
            t.add_row(f.frame, f"{f.fix.x:.2f}", f"{f.fix.y:.2f}", f"{f.fix.score:.3f}", "")
        else:
            t.add_row(f.frame, "", "", "", f"{f.lost}")
    console.print(t)
    lost = sum(1 for f in found if f.fix is None)
    if lost:
        console.print(f"{lost} of {len(found)} frames refused (--json gives each reason)", highlight=False)


def _view(tilt: str | None, azimuth: str | None, roll: str | None) -> Any:
    from ..units import UnitError, bare_number_problem, parse_angle
    from ..vision.view import View

    vals = []
    for name, text in (("--view-tilt", tilt), ("--view-azimuth", azimuth), ("--view-roll", roll)):
        if text is None:
            vals.append(0.0)
            continue
        bare = bare_number_problem(text, "angle")
        if bare is not None:
            fail(f"{name} {bare}")
        try:
            vals.append(parse_angle(text))
        except (UnitError, ValueError, ArithmeticError) as e:
            fail(f"{name} {text!r}: {e} (an angle: 30deg, -pi/6)")
    try:
        return View(*vals)
    except ValueError as e:
        fail(str(e))


@camera_app.command("calibrate")
def calibrate_cmd(
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP),
    camera: str = typer.Option(..., "--camera", help=_CAMERA_HELP),
    tip: str | None = typer.Option(
        None, "--tip", help="The tip now, X,Y in pixels (default: found by stepping a joint back and forth). " + PIXELS
    ),
    auto_joint: int = typer.Option(1, "--auto-joint", min=1, max=3, help="Joint stepped to find the tip (no --tip)."),
    auto_steps: int = typer.Option(20, "--auto-steps", min=1, max=10000, help="Steps it makes (and back)."),
    joints: str = typer.Option("3,1,2", "--joints", help="Joints to measure, in order: 3,1,2."),
    max_steps: int = typer.Option(
        200, "--max-steps", min=20, max=100000,
        help="Most steps each way (fewer if the tip would leave a third of the field).",
    ),
    view_tilt: str | None = typer.Option(
        None, "--view-tilt",
        help="Optical axis from the vertical, an angle in 0-90deg: 0 (looking down, the default), 52deg.",
    ),
    view_azimuth: str | None = typer.Option(
        None, "--view-azimuth",
        help="Direction the optical axis leans to, an angle from the world x axis towards y (default 0).",
    ),
    view_roll: str | None = typer.Option(
        None, "--view-roll", help="The image's turn about the optical axis, an angle (default 0)."
    ),
    output: Path | None = typer.Option(
        None, "--output", "-o", help="Write the step sizes (CSV, for stickslip calibrate --step-sizes)."
    ),
    jacobian: Path | None = typer.Option(
        None, "--jacobian", help="Write the measured image Jacobian (JSON, for move/reach/jog "
        "--camera-calibration): px per step of each joint and direction, and px per m or rad by the "
        "calibration's steps (-c; run it right after stickslip calibrate).",
    ),
    calibration: Path | None = typer.Option(
        None, "--calibration", "-c",
        help="With --jacobian: the step calibration that turns px per step into px per m or rad "
        "(default: the config file's).",
    ),
    day: str | None = typer.Option(None, "--day", help="Session label of the rows (default: today)."),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print the fits, step sizes and refusals as JSON (SI, px)."),
) -> None:
    """Calibrate the camera against the manipulator: each joint's image motion and step size at this pose.

    Each joint is stepped out and back in short moves (a probe, then moves of at most 16
    px, up to --max-steps each way) while the tip is tracked; the image Jacobian (px per
    step, each direction) is fitted with its residuals, and with the camera's pixel size
    (pixel= in its URL) and the arm's kinematics gives the step size at this pose. A joint
    is refused, with the reason, when the tip is lost, when its motion is not linear in
    its steps (an end stop, a slip), or when it moves the tip along the optical axis (from
    straight above: joint 2 in the outstretched pose).

    The rows (-o) are step sizes measured at a pose (method camera): stickslip calibrate
    --step-sizes fits them beside traverses, weighted by their uncertainty.

    --jacobian FILE keeps the measured image Jacobian for the closed loop (move, reach,
    jog --camera-calibration FILE): the px per step of each joint and direction, and
    the px per m or rad they make with the step calibration (-c) at this pose. The
    camera's tilt then needs no stating; the steps' error at this moment does enter:
    measure right after stickslip calibrate.

    Example: stickslip camera calibrate -d sim:// --camera "simcam://?pixel=0.5um" -o steps.csv
    """
    from ..clock import today_label
    from ..devices.positions import load_state, save_state
    from ..measurements import write_step_sizes
    from ..procedures.camera import calibrate_camera, dead_reckon
    from ..procedures.move import DeviceBusy, device_lock
    from ..records import atomic_group

    url = device_url(device)
    at = _pixel(tip, "--tip") if tip is not None else None
    order = _joint_order(joints)
    view = _view(view_tilt, view_azimuth, view_roll)
    label = day if day is not None else today_label()
    steps_cal = _jacobian_steps(jacobian, calibration, order)
    with user_errors():
        key = device_key(url)
    with open_store(db) as store, user_errors(DeviceBusy):
        with device_lock(store, key):
            with user_errors():
                state = load_state(store, key)

            def measure(dev: Controller, cam: Camera, progress: Callable[[int, int], None]) -> CameraCalibrationResult:
                with user_errors():  # both opened: the joints about to step are kept uncertain first
                    _journal_camera_calibration(store, key, order if at is not None else (*order, auto_joint))
                return calibrate_camera(
                    dev, cam, state.pose, order, tip=at, view=view, day=label, auto_joint=auto_joint,
                    auto_steps=auto_steps, max_steps=max_steps, progress=progress,
                )

            result = _with_device_and_camera(url, camera, state.pose, measure)
            with user_errors():
                dead_reckon(state, result)  # where the measured joints ended, by the steps the camera saw
                save_state(store, state)
    if not result.rows:
        reasons = "; ".join(r.refused or f"joint {r.joint}: no step size" for r in result.joints)
        fail(f"no step size measured: {reasons}")
    against: dict[int, tuple[float, float]] = {}
    with atomic_group():  # the step sizes and the Jacobian of one run, or neither (a full disk half-way)
        if output is not None:
            with user_errors():
                write_step_sizes(output, list(result.rows))
        if jacobian is not None and steps_cal is not None:
            against = _write_jacobian(result, steps_cal, camera, jacobian, view, key)
    if json_out:
        extra: dict[str, object] = {}
        if jacobian is not None:
            extra["jacobian"] = {
                "file": str(jacobian),
                "against_view": {str(j): {"length_ratio": r if math.isfinite(r) else None,
                                          "angle_deg": a if math.isfinite(a) else None}
                                 for j, (r, a) in against.items()},
            }
        print_json({**result.as_dict(), "device": key, "output": str(output) if output else None, **extra})
        return
    _print_calibration(result, output)
    if jacobian is not None:
        _print_against(jacobian, against)


def _jacobian_steps(jacobian: Path | None, calibration: Path | None, order: list[int]) -> Any:
    """The step calibration that scales ``--jacobian`` (``-c``), with the output path checked first (or ``None``).

    It must model every joint of ``order`` (each measured joint is scaled by its steps): refused before anything
    moves. A calibration without joint 1 ended a whole run in a ``KeyError`` traceback (exit 1), after the step
    sizes had been written and before the Jacobian was."""
    if jacobian is None:
        if calibration is not None:
            fail("--calibration goes with --jacobian (it scales the measured image Jacobian)")
        return None
    from ..calibration import Calibration
    from ..records import writable_target
    from ._common import calibration_file

    with user_errors():
        writable_target(jacobian, "--jacobian")
        cal = Calibration.load(calibration_file(calibration))
    if missing := [j for j in order if j not in cal.joints]:
        fail(f"--calibration models joint(s) {', '.join(map(str, cal.joints))}, not joint(s) "
             f"{', '.join(map(str, missing))} of --joints: --jacobian scales each measured joint by its steps "
             "(calibrate them, or measure --joints without them); nothing was moved")
    return cal


def _write_jacobian(
    result: CameraCalibrationResult, steps_cal: Any, camera: str, jacobian: Path, view: Any, device: str
) -> dict[int, tuple[float, float]]:
    """Write the measured image Jacobian; each joint's motion against the stated view's (length ratio, angle)."""
    from ..vision.jacobian import measured_jacobian
    from ..vision.view import base_to_image

    fits = [f for jr in result.joints if jr.refused is None for f in jr.fits]
    if not result.pixel_size_m:
        fail("--jacobian needs the camera's pixel size (pixel= in its URL): nothing written")
    with user_errors():
        measured = measured_jacobian(fits, result.pose, result.tip, steps_cal, camera, float(result.pixel_size_m),
                                     device)
        measured.save(jacobian)
    pose = result.pose
    return measured.against(base_to_image(view, float(result.pixel_size_m), pose.theta, pose.psi))


def _print_against(jacobian: Path, against: dict[int, tuple[float, float]]) -> None:
    say(f"image Jacobian written to {jacobian} (move, reach, jog --camera-calibration)", keep=(jacobian,))
    for j, (r, a) in against.items():
        seen = (f"{100 * r:.1f} % of the stated view's length, turned {a:.1f} deg" if math.isfinite(r)
                else "seen where the stated view sees nothing")
        console.print(f"  joint {j}: {seen}", highlight=False)


def _joint_order(joints: str) -> list[int]:
    """``--joints``: each of 1, 2, 3 at most once, in the order given."""
    try:
        order = [int(j) for j in joints.split(",")]
        if not order or any(j not in (1, 2, 3) for j in order) or len(set(order)) != len(order):
            raise ValueError
    except ValueError:
        fail(f"--joints {joints!r}: write the joints to measure, e.g. 3,1 (each of 1, 2, 3 once)")
    return order


def _journal_camera_calibration(store: Store, key: str, joints: Sequence[int]) -> None:
    """The joints the calibration steps, kept uncertain in the store first (procedures.camera.mark_stepped)."""
    from ..devices.positions import load_state, save_state
    from ..procedures.camera import mark_stepped

    journal = load_state(store, key)
    mark_stepped(journal, joints)
    save_state(store, journal)


def _with_device_and_camera(
    url: str, camera: str, pose: Pose,
    measure: Callable[[Controller, Camera, Callable[[int, int], None]], CameraCalibrationResult],
) -> CameraCalibrationResult:
    """Open the device (a simulator placed at ``pose``) and the camera, ``measure`` with a progress bar, close both."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from ..vision.acquire import AcquireError
    from ..vision.camera import CameraError, open_camera
    from ..vision.frame import ImageError
    from ..vision.jacobian import JacobianError
    from ..vision.template import TemplateError

    try:
        dev = open_device(url)
    except (DeviceError, ValueError) as e:
        fail(str(e))
    try:
        if isinstance(dev, PoseSettable):  # the simulator: start where the positions say
            dev.set_pose(*pose)
        try:
            cam = open_camera(camera, dev)
        except (CameraError, ValueError) as e:
            fail(str(e))
        try:
            columns = (TextColumn("moving and tracking"), BarColumn(), MofNCompleteColumn())
            with Progress(*columns, console=err_console, transient=True, disable=not err_console.is_terminal) as bar:
                task = bar.add_task("camera", total=None)

                def progress(done: int, total: int) -> None:
                    bar.update(task, completed=done, total=total)

                return measure(dev, cam, progress)
        except (AcquireError, TemplateError, JacobianError, ImageError, CameraError, DeviceError, ValueError) as e:
            fail(str(e))
        finally:
            cam.close()
    finally:
        try:
            dev.close()
        except DeviceError:
            pass


def _print_calibration(result: CameraCalibrationResult, output: Path | None) -> None:
    from rich.table import Table

    from ..units import format_step

    t = Table(title=f"camera calibration at the kept pose (tip at {result.tip[0]:.1f}, {result.tip[1]:.1f} px)")
    for col in ("joint", "dir", "px/step", "step size", "± (1 sd)", "steps", "in image"):
        t.add_column(col, justify="left" if col in ("joint", "dir") else "right")
    for jr in result.joints:
        for f, s in zip(jr.fits, jr.step_sizes, strict=False):
            t.add_row(str(jr.joint), s.direction, f"{math.hypot(*f.jacobian):.3f}", format_step(s.gamma, jr.joint),
                      f"{100 * s.sigma / s.gamma:.2f} %", str(s.steps), f"{100 * s.visibility:.0f} %")
    console.print(t)
    for n in result.notes:
        say(f"note: {n}")  # wrapped at spaces, later lines indented: a path or a number is never cut
    for jr in result.joints:
        if jr.refused:
            console.print(styled("refused:", "yellow"), jr.refused, highlight=False)
    if output is not None:
        say(f"{len(result.rows)} step sizes written to {output} (stickslip calibrate --step-sizes)", keep=(output,))


@camera_app.command("grab")
def grab_cmd(
    camera: str = typer.Option(..., "--camera", help=_CAMERA_HELP),
    output: Path = typer.Option(..., "--output", "-o", help="Write the frame here (a .png file, 16-bit grey)."),
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP + " Only simcam:// needs it."),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print the frame's size, time and pixel size as JSON."),
) -> None:
    """Take one frame from a camera and save it as a 16-bit grey PNG.

    A PNG holds grey values 0 to 1: a frame outside them (a float TIFF in counts, a signed one's negatives) is
    refused, nothing written, rather than clipped.

    For simcam:// the arm is the device's kept pose (stickslip where), and the simulator's
    true tip is printed too (sim_true_tip, px), as move prints the simulator's true end.

    Example: stickslip camera grab -d sim:// --camera "simcam://?pixel=0.5um" -o frame.png
    """
    from ..vision.camera import CameraError, camera_scheme, open_camera
    from ..vision.frame import ImageError
    from ..vision.images import write_png

    if output.suffix.lower() != ".png":  # PNG data under a .tif or .jpg name misleads every other reader
        fail(f"-o {output}: camera grab writes a 16-bit grey PNG: name it .png")
    with user_errors():
        scheme = camera_scheme(camera)
    dev = None
    truth: list[float] | None = None
    try:
        if scheme == "simcam":
            from ..devices.positions import load_state

            url = device_url(device)
            with user_errors():
                key = device_key(url)
            with open_store(db) as store:
                with user_errors():
                    state = load_state(store, key)
            try:
                dev = open_device(url)
            except (DeviceError, ValueError) as e:
                fail(str(e))
            if isinstance(dev, PoseSettable):
                dev.set_pose(*state.pose)
        try:
            cam = open_camera(camera, dev)
            frame = cam.grab()
            true_tip = getattr(cam, "true_tip", None)
            if callable(true_tip):
                truth = [float(v) for v in true_tip()[0]]
            cam.close()
        except (CameraError, ImageError, ValueError) as e:
            fail(str(e))
    finally:
        if dev is not None:
            dev.close()
    with user_errors():
        write_png(output, frame.image)
    h, w = frame.shape
    info = {"output": str(output), "width": w, "height": h, "time_s": frame.time_s,
            "pixel_size_m": frame.pixel_size_m, "sim_true_tip": truth}
    if json_out:
        print_json(info)
        return
    px = f", pixel {frame.pixel_size_m * 1e6:g} µm" if frame.pixel_size_m else ""
    say(f"{w} x {h} px{px} at t = {frame.time_s:.3f} s -> {output}", keep=(output,))
    if truth is not None:
        console.print(f"simulator's true tip: {truth[0]:.2f}, {truth[1]:.2f} px", highlight=False)


# ---------------------------------------------------------------- the closed loop (move, reach --camera)

CAMERA_LOOP_HELP = (
    "Close the loop with this camera (it must know its pixel size: simcam://?pixel=1um with -d sim://, "
    "opencv://0?pixel=0.5um): the tip is tracked after each short leg, the position and the day's step scale "
    "corrected, until the tip is within 1 px or 0.5 µm (the larger) of the target. See docs/vision.md."
)
CAMERA_CALIBRATION_HELP = (
    "With --camera: the image Jacobian 'stickslip camera calibrate --jacobian' measured with this camera "
    "(JSON): the loop turns pixels into joint motion with it instead of the straight-down view's. A file "
    "of another camera URL or pixel size is refused."
)
CAMERA_TIP_HELP = (
    "With --camera: the tip's pixel now, X,Y (default: found by stepping joint 3 back and forth). " + PIXELS
)


def camera_errors() -> tuple[type[BaseException], ...]:
    """What opening a camera and learning the tip may raise: one ``error:`` line each (imported when used)."""
    from ..vision.acquire import AcquireError
    from ..vision.camera import CameraError
    from ..vision.frame import ImageError
    from ..vision.jacobian import JacobianError
    from ..vision.template import TemplateError

    return (CameraError, AcquireError, ImageError, JacobianError, TemplateError)


def camera_loop(camera: str | None, tip: str | None, calibration: Path | None = None) -> Any:
    """The :class:`~stickslip.procedures.closed_loop.CameraLoop` of ``--camera``, ``--camera-tip`` and
    ``--camera-calibration`` (or ``None``)."""
    if camera is None:
        if tip is not None:
            fail("--camera-tip goes with --camera")
        if calibration is not None:
            fail("--camera-calibration goes with --camera")
        return None
    from ..devices.base import redact_url
    from ..procedures.closed_loop import CameraLoop
    from ..vision.jacobian import MeasuredJacobian

    at = _pixel(tip, "--camera-tip") if tip is not None else None
    with user_errors():
        jac = None if calibration is None else MeasuredJacobian.load(calibration)
        if jac is not None and redact_url(camera) != jac.camera:
            jac.check_camera(camera, jac.pixel_size_m)  # the URL's one line
        return CameraLoop(camera, tip=at, jacobian=jac)


def run_seen(kind: str, request: Any, calibration: Any, camera: str, tip: str | None, db: str | None,
             json_out: bool, borrowed: bool = False, rig_arm: Any = None,
             camera_calibration: Path | None = None) -> None:
    """``move``/``reach`` with ``--camera``: call the closed loop, print what it did, exit 2 if it stopped short.

    With ``rig_arm`` (``--rig``, :class:`~.rig.RigArm`) the arm's envelope checks the whole
    path and every leg, and its controller is opened through the rig (password, channels).
    """
    from ..procedures.closed_loop import move_seen, reach_seen
    from ..procedures.move import DeviceBusy
    from ._common import flush_warnings, warn_later

    if rig_arm is not None and rig_arm.stage is not None:
        fail(f"--camera with arm {rig_arm.arm!r}: the closed loop plans an MM3A's joints, and this arm is a "
             "stage (xyz); move it without the camera")
    if rig_arm is not None and rig_arm.state_key != device_key(rig_arm.device):
        fail(f"--camera with arm {rig_arm.arm!r}: it shares its controller with another arm, and the closed loop "
             "keeps positions per controller; move it without the camera")
    loop = camera_loop(camera, tip, camera_calibration)
    with open_store(db) as store, user_errors(DeviceBusy, KeyError, DeviceError, *camera_errors()):
        opener = None
        if rig_arm is not None:
            request = dataclasses.replace(request, guard=rig_arm.guard(store))
            opener = rig_arm.stoppable(store)
        if kind == "move":
            result = move_seen(store, request, calibration, loop, warn=warn_later, ready=flush_warnings,
                               opener=opener)
        else:
            if borrowed:
                from ..procedures.reach import BORROWED_JOINT1

                warn_later(BORROWED_JOINT1)
            result = reach_seen(store, request, calibration, loop, warn=warn_later, ready=flush_warnings,
                                opener=opener)
    if json_out:
        print_json({"camera": result.as_dict()})
    else:
        _print_seen(result)
    if not result.reached:
        fail(f"the closed loop stopped: {result.reason}")


def _print_seen(result: Any) -> None:
    from ..kinematics import tip as tip_of
    from ..units import format_position

    say_ = console.print
    tol = result.tolerance * 1e6
    state = "reached" if result.reached else "stopped"
    if result.looks:
        used = [j for j in result.looks[-1].seen if j not in result.state.uncertain]  # a disputed fix is not used
        how = "the seen tip" if used else "the tip, dead-reckoned (not seen at the last look),"
        say_(f"{state}: {how} {result.error * 1e6:.2f} µm from the target (tolerance {tol:.2g} µm)",
             highlight=False)
    elif result.reached:
        say_(f"reached without moving: the kept positions are at the target (tolerance {tol:.2g} µm)",
             highlight=False)
    else:
        say_(f"{state} before the first look (tolerance {tol:.2g} µm)", highlight=False)
    say_(f"  {len(result.looks)} leg(s) looked at, {result.corrections} correction(s)", highlight=False)
    for j in (1, 2, 3):
        src = result.state.sources[j]
        if j in result.state.uncertain:
            lo, hi = result.state.uncertain[j]
            src = f"uncertain: between {format_position(lo, j)} and {format_position(hi, j)}"
        say_(f"  joint {j} {format_position(result.state.positions[j], j)} ({src})", highlight=False)
    scales = result.looks[-1].step_scale if result.looks else {}
    if scales:
        say_("  step scale " + ", ".join(f"joint {j} x{s:.4f}" for j, s in sorted(scales.items())), highlight=False)
    if result.sim_true is not None:
        err = math.dist(tip_of(result.sim_true, result.geometry), result.target)
        say_(f"  simulator's true tip {err * 1e6:.2f} µm from the target", highlight=False)
