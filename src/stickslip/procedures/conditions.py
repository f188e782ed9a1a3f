"""The conditions a calibration is made with, read off a device, and the warnings when a
calibration is used under other ones (another device, frequency, amplitude or an old day).

A calibration holds for the device and drive settings it was measured with: the step size
of a stick-slip joint depends on the stepping frequency and the drive amplitude as much as on
the load. :func:`conditions_of` reads them off a controller when traverses are measured;
:func:`usage_warnings` compares them with the controller a move is about to drive.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import replace

from ..calibration import Calibration, Conditions
from ..clock import stale_message
from ..devices.base import Controller, device_key, redact_url, url_scheme

__all__ = ["calibration_device_problem", "conditions_of", "usage_warnings"]


def _voltage(dev: Controller, joint: int) -> float | None:
    """The drive amplitude of ``joint`` in V where the controller reports one in volts."""
    volts = dev.settings().get("voltage_v")
    if isinstance(volts, dict):
        v = volts.get(str(joint))
        if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v):
            return float(v)
    return None


def _common(values: Iterable[float | None]) -> float | None:
    """The one value all joints share, or ``None`` when they differ or one is unknown."""
    vals = list(values)
    if not vals or any(v is None for v in vals):
        return None
    first = vals[0]
    return first if all(v == first for v in vals) else None


def conditions_of(
    dev: Controller, url: str, joints: Iterable[int] = (1, 2, 3), temperature_c: float | None = None
) -> Conditions:
    """What ``dev`` (opened from ``url``) drives ``joints`` with now.

    The frequency (Hz) and amplitude (V) are recorded only when every joint listed shares
    them (one calibration covers the joints); ``device`` is the URL without options or secrets.
    """
    js = list(joints)
    return Conditions(
        device=device_key(url),
        frequency_hz=_common(float(dev.frequency(j)) for j in js),
        amplitude_v=_common(_voltage(dev, j) for j in js),
        temperature_c=temperature_c,
    )


def usage_warnings(
    cal: Calibration, dev: Controller | None, url: str, joint: int, max_age_days: int = 0
) -> list[str]:
    """Warnings for using ``cal`` to drive ``joint`` of ``dev`` (opened from ``url``).

    One line each: the calibration is older than ``max_age_days`` (see
    :func:`stickslip.clock.stale_message`), or it was made on another device, at another
    stepping frequency or amplitude. ``dev`` may be ``None`` (not opened): only the age and
    the device identity are checked then.
    """
    out: list[str] = []
    stale = stale_message(cal.day, max_age_days=max_age_days)
    if stale:
        out.append(stale)
    now = Conditions(device=device_key(url))
    if dev is not None:
        now = conditions_of(dev, url, (joint,))
    then = cal.conditions
    if then.device:  # a calibration written before keys were canonical (sim://?seed=0 is sim://)
        try:
            then = replace(then, device=device_key(then.device))
        except ValueError:
            pass  # a malformed key compares as written
    diffs = then.differences(now)
    if diffs:
        out.append(
            "the calibration was made under other conditions (" + "; ".join(diffs) + "): "
            "its step sizes may not hold here; recalibrate on this device and settings"
        )
    return out


def _simulated(key: str) -> bool:
    try:
        return url_scheme(key) in ("sim", "sim+physics")
    except ValueError:
        return False


def calibration_device_problem(cal: Calibration, url: str) -> str | None:
    """Why ``cal`` must not plan moves on the controller at ``url`` unless the user says so (``None`` if it may).

    A calibration holds for the arm its traverses were measured on. On a real controller
    one that does not record its device (made from a table that did not say, e.g. the
    README tour's ``calibrate measurements.csv`` without a database that holds its rows)
    or that was made on the simulator is refused, with the reason; a calibration of
    another real device is only warned about (:func:`usage_warnings`). The simulator
    takes any calibration.
    """
    if _simulated(url):
        return None
    made_on = cal.conditions.device
    here = redact_url(url)
    if made_on is None:
        return (
            f"the calibration does not record the device its traverses came from (made from a table that did not "
            f"say), so its step sizes may be another arm's: recalibrate on {here}, or record the device "
            f"(stickslip calibrate MEAS.csv --device URL), or pass --trust-calibration to use it anyway"
        )
    if _simulated(made_on):
        return (
            f"the calibration was made on the simulator ({made_on}), not on {here}: its step sizes are the "
            "simulated arm's; calibrate this arm (docs/howto/day-one.md), or pass --trust-calibration to use "
            "it anyway"
        )
    return None
