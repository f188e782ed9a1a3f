"""``stickslip observe``: feed a measured position into a device's dead reckoning (a Kalman update).

The kept state of each joint (``stickslip where``) carries the Kalman state of its dead
reckoning (:class:`stickslip.motion.tracking.JointTrack`): ``stickslip move`` widens the
position's uncertainty with every move; a measured position (a microscope image, an end
stop reached) narrows it and, through the correlation the moves built up, corrects the
day's step scale, which the next ``move`` plans with (docs/models.md §7).
"""

from __future__ import annotations

import math

import typer

from ..devices.base import device_key
from ..joints import JOINTS
from ..units import format_position
from . import app
from ._common import console, db_option, fail, open_store, print_json, user_errors, warn_later
from .devices import _DEVICE_HELP, _degree_hint, _parse_joint_value, _sd_text

DEFAULT_SIGMA = {3: 1e-6, 2: 50e-6, 1: 50e-6}
"""Standard deviation assumed for a measured position when --sigma is not given (m, rad, rad)."""

MAX_INNOVATION = 5.0
"""A measurement further than this many standard deviations from the kept position is refused
(a wrong reading or a slipped joint would otherwise teach the filter a wrong step scale)."""


@app.command()
def observe(
    joint: int = typer.Option(..., "--joint", "-j", min=1, max=3, help="Joint that was measured: 1, 2 or 3."),
    at: str = typer.Option(
        ..., "--at",
        help="Measured position: 1.234mm (joint 3), -45deg (joints 1, 2); 'min'/'max' = the end stop reached.",
    ),
    sigma: str | None = typer.Option(
        None, "--sigma",
        help="Standard deviation of the measurement: 1um, 50urad (default: 0 at an end stop, else 1um / 50urad).",
    ),
    force: bool = typer.Option(
        False, "--force",
        help=f"Use a measurement more than {MAX_INNOVATION:g} standard deviations from the kept position.",
    ),
    device: str = typer.Option("sim://", "--device", "-d", help=_DEVICE_HELP),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print the update as JSON (SI units)."),
) -> None:
    """Feed a measured position of a joint into its dead reckoning (Kalman update).

    The kept position (from `stickslip move`) has a standard deviation that grows with
    every move; a measurement of standard deviation --sigma pulls it towards the
    measured value and corrects the day's step scale that the next `move` plans with.
    An end stop reached (--at min/max) is exact. A joint left uncertain by an
    interrupted move, or one no move has tracked yet, is re-referenced by the measurement.
    A measurement more than 5 standard deviations from the kept position is refused
    (--force uses it).

    Example: stickslip observe -d mm3a:///dev/ttyUSB0 --joint 3 --at 1.234mm --sigma 2um
    """
    from ..devices.positions import load_state, save_state
    from ..motion.tracking import JointTrack
    from ..procedures.move import DeviceBusy, device_lock

    spec = JOINTS[joint]
    word = at.strip().lower()
    at_stop = word in ("min", "lower", "max", "upper")
    if at_stop:
        q_meas = spec.lower if word in ("min", "lower") else spec.upper
    else:
        q_meas = _parse_joint_value(joint, at, "--at")
        if not spec.contains(q_meas):
            fail(
                f"--at {at}: {format_position(q_meas, joint)} is outside joint {joint}'s range "
                f"[{format_position(spec.lower, joint)}, {format_position(spec.upper, joint)}]"
                + _degree_hint(joint, at)
            )
    if sigma is None:
        sd = 0.0 if at_stop else DEFAULT_SIGMA[joint]
    else:
        sd = _parse_joint_value(joint, sigma, "--sigma")
        if not (math.isfinite(sd) and sd >= 0):
            fail(f"--sigma {sigma}: a standard deviation must be >= 0")
    with user_errors():
        key = device_key(device)
    with open_store(db) as store, user_errors(DeviceBusy):
        with device_lock(store, key):
            with user_errors():
                state = load_state(store, key)
            q_before = state.positions[joint]
            was_uncertain = joint in state.uncertain
            raw = state.track.get(joint)
            with user_errors():
                track = JointTrack.from_json(raw) if raw is not None else JointTrack()
            sd_before = track.sd
            scale_before = track.scale
            re_reference = was_uncertain or raw is None
            if re_reference:  # an interrupted move, or no move tracked: the measurement re-references the joint
                track.reset_position(sd)
                q_new = q_meas
                innovation_sigmas = None
            else:
                s_pred = math.sqrt(sd_before**2 + sd**2)
                innovation_sigmas = abs(q_meas - q_before) / s_pred if s_pred > 0 else math.inf
                if innovation_sigmas > MAX_INNOVATION and not force:
                    fail(
                        f"the measured position {format_position(q_meas, joint)} is {innovation_sigmas:.3g} standard "
                        f"deviations from the kept {format_position(q_before, joint)} ± {_sd_text(sd_before, joint)}: "
                        "check the reading (units, which joint); if the joint slipped or was moved by hand, "
                        f"re-reference it (stickslip where --set {joint}=VALUE) or pass --force to use it"
                    )
                with user_errors():
                    q_new = track.observe(q_before, q_meas, sd)
            q_new = min(max(q_new, spec.lower), spec.upper)
            with user_errors():
                state.set_position(joint, q_new, "observed")
            state.track[joint] = track.to_json()
            with user_errors():
                save_state(store, state)
    if innovation_sigmas is not None and innovation_sigmas > MAX_INNOVATION:
        warn_later(f"the measured position is {innovation_sigmas:.3g} standard deviations from the kept one (--force)")
    result = {
        "device": key,
        "joint": joint,
        "unit": spec.unit,
        "q_before": q_before,
        "q_sd_before": None if re_reference else sd_before,
        "q_measured": q_meas,
        "sigma": sd,
        "q": q_new,
        "q_sd": track.sd,
        "step_scale_before": scale_before,
        "step_scale": track.scale,
        "step_scale_sd": track.scale_sd,
        "re_referenced": re_reference,
        "innovation_sigmas": innovation_sigmas,
    }
    if json_out:
        print_json(result)
        return
    before = ("uncertain (interrupted move)" if was_uncertain else "not tracked") if re_reference else (
        f"{format_position(q_before, joint)} ± {_sd_text(sd_before, joint)}"
    )
    console.print(
        f"joint {joint}: kept {before}; measured {format_position(q_meas, joint)} ± {_sd_text(sd, joint)}"
        f" -> {format_position(q_new, joint)} ± {_sd_text(track.sd, joint)}",
        highlight=False,
    )
    if re_reference:
        return
    console.print(
        f"step scale x{scale_before:.4f} -> x{track.scale:.4f} (± {100 * track.scale_sd:.2g} %)"
        + ("; the next move plans with it" if track.scale != scale_before else ""),
        highlight=False,
    )
