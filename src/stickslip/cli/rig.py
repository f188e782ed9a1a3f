"""Rig commands: ``rig check`` (what a rig file holds, and a picture) and ``rig go`` (a named position).

A rig file (docs/rig.md) names the arms, their controllers, keep-out volumes and named
positions; ``move`` and ``where`` take ``--rig FILE`` (and ``--arm NAME``) too. The
workflows are :mod:`stickslip.procedures.arms`; these commands parse, call them and print.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from ..devices.base import DeviceError, redact_url
from . import app
from ._common import (
    OneLineErrors,
    calibration_file,
    db_option,
    fail,
    flush_warnings,
    open_store,
    say,
    user_errors,
    warn_later,
)

if TYPE_CHECKING:
    from ..devices.base import Controller
    from ..devices.positions import StateStore
    from ..joints import JointSet
    from ..kinematics import Geometry, Stage
    from ..rig import Rig
    from ..rig.guard import Guard

rig_app = typer.Typer(
    name="rig",
    cls=OneLineErrors,
    no_args_is_help=True,
    rich_markup_mode="rich",
    help=(
        "A rig as a file: several arms, keep-out volumes, named positions (docs/rig.md).\n\n"
        "move and where take --rig FILE --arm NAME; every planned path is checked against "
        "the rig's envelope before a step is sent."
    ),
)
app.add_typer(rig_app, name="rig", rich_help_panel="Drive a manipulator")

RIG_HELP = "Rig file (TOML, docs/rig.md): the arm's controller, calibration and envelope come from it."
ARM_HELP = "Arm of the rig to drive (default: the rig's first arm)."


def load(path: Path) -> Rig:
    """The rig file at ``path``, or a one-line error (exit 2)."""
    from ..rig import load_rig

    with user_errors():
        return load_rig(path)


def rig_database(db: str | None, rig: Rig) -> str | None:
    """The database of a command given ``--rig``: ``--db`` wins, else the rig file's ``database``.

    ``None`` when neither names one: then ``$STICKSLIP_DB``, the config file's and the
    data folder's, as for any command (:func:`~._common.database_setting`).
    """
    return db if db is not None and str(db) != "" else rig.database


@dataclass(frozen=True)
class RigArm:
    """What ``--rig FILE --arm NAME`` gives a command: the arm's device, kinematics, calibration, database, envelope.

    ``joints`` are the arm's joints (kinds, ranges: :meth:`stickslip.rig.Arm.joint_specs`);
    ``stage`` an ``xyz`` arm's kinematics (``None`` for an ``mm3a``, whose ``geometry`` counts);
    ``database`` the rig's (:func:`rig_database`: ``--db`` wins); ``state_key`` where the arm's
    positions are kept (:meth:`stickslip.rig.Rig.state_key`).
    """

    rig: Rig
    arm: str
    device: str
    geometry: Geometry
    calibration: Path | None
    opener: Callable[[str], Controller]
    joints: JointSet
    stage: Stage | None
    database: str | None
    state_key: str

    def guard(self, store: StateStore) -> Guard:
        """The arm's envelope, with the other arms where ``store`` keeps them."""
        from ..procedures.arms import guard_for

        return guard_for(store, self.rig, self.arm)

    def stoppable(self, store: StateStore) -> Callable[[str], Controller]:
        """The arm's opener, whose controllers send no further burst once the rig's STOP is pressed for another arm
        (a server's page: :func:`stickslip.procedures.rigstop.stoppable`)."""
        from ..procedures.rigstop import stoppable

        return stoppable(self.opener, store, self.rig, self.arm)


def rig_arm(rig_file: Path | None, arm: str | None, device: str | None, geometry: str | None,
            calibration: Path | None, db: str | None = None) -> RigArm | None:
    """``--rig``/``--arm`` read, checked against ``--device``/``--geometry`` (exit 2); ``None`` without a rig."""
    if rig_file is None:
        if arm is not None:
            fail("--arm names an arm of a rig: give --rig FILE too")
        return None
    if device is not None:
        fail("give --device or --rig, not both (the rig file names each arm's controller)")
    if geometry is not None:
        fail("give --geometry or --rig, not both (the rig file gives each arm's geometry)")
    from ..kinematics import DEFAULT_GEOMETRY
    from ..procedures.arms import opener_for

    rig = load(rig_file)
    with user_errors(KeyError):
        a = rig.arm(arm)
    cal = calibration or (rig_file.parent / a.calibration if a.calibration else None)
    return RigArm(rig, a.name, a.controller, a.geometry or DEFAULT_GEOMETRY, cal, opener_for(rig, a.name),
                  a.joint_specs(), a.stage(), rig_database(db, rig), rig.state_key(a.name))


def _joint_text(kind: str, v: float) -> str:
    return f"{math.degrees(v):.2f} deg" if kind == "rotary" else f"{v * 1e3:.3f} mm"


@rig_app.command("check")
def check(
    path: Path = typer.Argument(..., help="The rig file.", metavar="FILE"),
    out: Path | None = typer.Option(None, "--output", "-o", help="Draw the rig into this PNG (two views)."),
    db: str | None = db_option(" The arms are drawn at their kept poses (the rig file's database too)."),
) -> None:
    """List what a rig file holds (arms, joints, volumes, named positions) and draw it.

    Each arm is drawn at its kept pose when --db is given, else at its home pose.
    A file with a problem exits 2 with one line naming the file, line and key; so does
    a file whose drawn poses break the envelope (an arm within a volume's margin or too
    near another arm), after listing each problem and drawing the rig.

    Example: stickslip rig check lab.toml -o rig.png
    """
    from ..procedures.arms import arm_states

    if out is not None and out.suffix.lower() != ".png":  # matplotlib added .png, or drew another format
        fail(f"-o {out}: rig check draws a PNG: name it .png")
    rig = load(path)
    say(f"rig {rig.name!r}: {len(rig.arms)} arm(s), {len(rig.volumes)} volume(s), "
        f"{len(rig.positions)} named position(s); arms kept {rig.arm_distance * 1e6:.0f} µm apart, "
        f"margins widened by {rig.n_sigma:g} σ")
    poses = {a.name: a.home for a in rig.arms}
    db = rig_database(db, rig)
    if db is not None:
        with open_store(db) as store:
            for s in arm_states(store, rig):
                poses[s.arm] = (s.state.positions[1], s.state.positions[2], s.state.positions[3])
    for a in rig.arms:
        tip = a.tip(poses[a.name]) * 1e3
        say(f"arm {a.name!r} ({a.kind}) on {redact_url(a.controller)}; tip at "
            f"({tip[0]:.2f}, {tip[1]:.2f}, {tip[2]:.2f}) mm")
        for j in a.joints:
            soft = "" if j.limits == (j.lower, j.upper) else (
                f", soft {_joint_text(j.kind, j.limits[0])} to {_joint_text(j.kind, j.limits[1])}")
            say(f"joint {j.number} {j.kind} on channel {j.channel}{' reversed' if j.sign < 0 else ''}: "
                f"{_joint_text(j.kind, j.lower)} to {_joint_text(j.kind, j.upper)}{soft}; "
                f"stops {', '.join(j.stops) or 'none'}", indent="    ")
    for v in rig.volumes:
        say(f"volume {v.name!r}: {v.shape}, margin {v.margin * 1e6:.0f} µm")
    for p in rig.positions:
        arm = rig.arm(p.arm)
        parts = [f"q{j} {_joint_text(arm.joint(j).kind, p.q[j - 1] or 0.0)}" for j in p.order]
        say(f"position {p.name!r} of {p.arm!r}: " + ", then ".join(parts))
    problems = _problems(rig, poses)
    for line in problems:
        say(f"problem: {line}")
    if not problems:
        say("no problem found at the drawn poses")
    if out is not None:
        from ..rig.draw import draw

        with user_errors():
            draw(rig, poses, out)
        say(f"drawn: {out}", keep=(out,))
    if problems:  # a check that found something says so to a script too (after drawing it: the picture shows where)
        fail(f"{path}: the drawn poses break the envelope ({len(problems)} problem(s) above)")


def _problems(rig: Rig, poses: dict[str, tuple[float, float, float]]) -> list[str]:
    """Each arm's pose checked against the envelope (a path of one pose)."""
    from ..rig import EnvelopeViolation, check_path

    out = []
    for a in rig.arms:
        others = {n: q for n, q in poses.items() if n != a.name}
        try:
            check_path(rig, a.name, [poses[a.name]], others=others)
        except EnvelopeViolation as e:
            out.append(str(e))
    return out


@rig_app.command("stop")
def stop_rig(
    rig_file: Path = typer.Option(..., "--rig", help=RIG_HELP),
    db: str | None = db_option(),
) -> None:
    """Press the rig's STOP from a terminal: every arm's motion ends before its next burst.

    The same STOP as an arm's page (docs/rig.md): every control room of the rig and every
    `move`, `reach`, `jog` and `rig go` on one of its arms reads it before each burst (at most
    0.2 s apart) and sends no further burst; the burst under way is finished, so each position
    stays exact. A motion started after the press is not stopped by it. It needs the rig's
    database (the rig file's `database`, or --db), which the motions read.

    Example: stickslip rig stop --rig lab.toml
    """
    from ..procedures.rigstop import press

    rig = load(rig_file)
    with open_store(rig_database(db, rig)) as store, user_errors():
        count = press(store, rig, None)
    say(f"rig {rig.name!r}: STOP pressed (press {count}): every arm's motion ends before its next burst")


@rig_app.command("go")
def go(
    name: str = typer.Argument(
        ..., help="The named position: a position table of the rig file, else one saved for the arm (stickslip serve).",
        metavar="NAME",
    ),
    rig_file: Path = typer.Option(..., "--rig", help=RIG_HELP),
    arm: str | None = typer.Option(None, "--arm", help=ARM_HELP),
    calibration: Path | None = typer.Option(
        None, "--calibration", "-c", help="Calibration JSON (default: the arm's in the rig file, else the config's)."
    ),
    db: str | None = db_option(),
    from_unreferenced: bool = typer.Option(
        False, "--from-unreferenced", help="Plan from positions never referenced (as move's option)."
    ),
    trust_calibration: bool = typer.Option(
        False, "--trust-calibration", help="Use a calibration that does not record this device (as move's option)."
    ),
) -> None:
    """Reach a named position of the rig file (or one saved for the arm), one joint at a time in its order.

    The whole path (each joint in the position's order, e.g. joint 3 retracted first)
    is checked against the rig's envelope before the first step; a path that would
    enter a volume or come too near another arm is refused (exit 2) naming the obstacle.

    Example: stickslip rig go park --rig lab.toml --arm left
    """
    from ..calibration import Calibration
    from ..procedures.arms import go_to
    from ..procedures.move import DeviceBusy

    rig = load(rig_file)
    with user_errors(KeyError):
        a = rig.arm(arm)
    cal_path = calibration or (rig_file.parent / a.calibration if a.calibration else None)
    with user_errors(KeyError):
        cal = Calibration.load(calibration_file(cal_path))
    with open_store(rig_database(db, rig)) as store, user_errors(DeviceBusy, KeyError, DeviceError):
        results = go_to(store, rig, a.name, name, cal, warn=warn_later, ready=flush_warnings,
                        from_unreferenced=from_unreferenced, trust_calibration=trust_calibration)
    for r in results:
        f = r.failure()
        if f is not None:
            fail(f)
        p = r.plan
        say(f"arm {a.name!r} joint {p.joint}: {_joint_text(a.joint(p.joint).kind, p.q_from)} -> "
            f"{_joint_text(a.joint(p.joint).kind, p.q_end)}, {p.steps:+d} steps")
    say(f"arm {a.name!r} at {name!r}" if results else f"arm {a.name!r} is at {name!r} already")
