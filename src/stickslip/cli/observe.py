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
from ..units import format_position, format_spread
from . import app
from ._common import db_option, device_url, fail, open_store, print_json, say, user_errors, warn_later
from .devices import _DEVICE_HELP, _parse_joint_value

MAX_INNOVATION = 5.0
"""As :data:`stickslip.procedures.observe.MAX_INNOVATION` (here for --help, without loading numpy)."""


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
        help=f"Take a measurement more than {MAX_INNOVATION:g} standard deviations from the kept position as the "
        "position (re-referenced; the step scale is kept).",
    ),
    device: str | None = typer.Option(None, "--device", "-d", help=_DEVICE_HELP),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print the update as JSON (SI units)."),
) -> None:
    """Feed a measured position of a joint into its dead reckoning (Kalman update).

    The kept position (from `stickslip move`) has a standard deviation that grows with
    every move; a measurement of standard deviation --sigma pulls it towards the
    measured value and corrects the day's step scale that the next `move` plans with.
    An end stop reached (--at min/max) is exact. A joint left uncertain by an
    interrupted move, or one no move has tracked yet, is re-referenced by the measurement.
    A measurement more than 5 standard deviations from the kept position is refused;
    --force sets the position to it and keeps the step scale (a slip or a hand moved the
    joint there, not its steps).

    Example: stickslip observe -d mm3a:///dev/ttyUSB0 --joint 3 --at 1.234mm --sigma 2um
    """
    from ..procedures.move import DeviceBusy
    from ..procedures.observe import Observation
    from ..procedures.observe import observe as update

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
            )
    sd = None
    if sigma is not None:
        sd = _parse_joint_value(joint, sigma, "--sigma")
        if not (math.isfinite(sd) and sd >= 0):
            fail(f"--sigma {sigma}: a standard deviation must be >= 0")
    device = device_url(device)
    with user_errors():
        device_key(device)
    with open_store(db) as store, user_errors(DeviceBusy):
        r = update(store, device, Observation(joint, q_meas, sd, at_stop, force))
    if r.forced:
        warn_later(
            f"the measured position is {r.innovation_sigmas:.3g} standard deviations from the kept one (--force)"
        )
    if json_out:
        print_json(r.as_dict())
        return
    before = ("uncertain (interrupted move)" if r.was_uncertain else "not tracked") if r.re_referenced else (
        f"{format_position(r.q_before, joint)} (σ {format_spread(r.q_sd_before or 0.0, joint)})"
    )
    say(
        f"joint {joint}: kept {before}, measured {format_position(r.q_measured, joint)} "
        f"(σ {format_spread(r.sigma, joint)})"
    )
    say(f"now {format_position(r.q, joint)} (σ {format_spread(r.q_sd, joint)})")
    if r.re_referenced:
        return
    if r.forced:
        say(f"step scale x{r.step_scale:.4f} kept: a reading this far from the kept position sets the position "
            "and teaches no scale (the steps did not take the joint there)")
        return
    say(
        f"step scale x{r.step_scale_before:.4f} -> x{r.step_scale:.4f} (σ {100 * r.step_scale_sd:.2g} %)"
        + ("; the next move plans with it" if r.step_scale != r.step_scale_before else "")
    )
