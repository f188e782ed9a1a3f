"""How a camera looks at the rig: its optical axis and image axes in the world, and the projection.

The world frame is the one the base tilt is measured in (docs/design.md §2: z up). A
:class:`View` turns the camera that looks straight down (optical axis ``v = -z``, image
``x`` along world ``x``, image ``y`` down the page along world ``-y``) by ``roll`` about
its optical axis, then tilts the optical axis by ``tilt`` from the vertical towards the
azimuth ``azimuth`` (from world ``x`` towards ``y``). A point ``p`` (world, m) then lands
at pixel

    u = c + (1 / s) · P · (p - p_c)          (docs/design.md §10)

where ``P`` (2 × 3) holds the image axes as rows, ``s`` is the pixel size (m), ``p_c`` the
point seen at pixel ``c``; ``v · (p - p_c)`` is its distance behind the focal plane (m).
The tip's motion along ``v`` shows only as focus, never as pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..kinematics import rotation_base
from .frame import PIXEL_SIZE_RANGE

__all__ = ["View", "TOP_VIEW", "image_axes", "project", "base_to_image"]


def _rz(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True)
class View:
    """A camera's orientation in the world.

    Parameters
    ----------
    tilt : float
        Angle of the optical axis from the vertical, rad, in [0, pi/2]. 0: looking
        straight down (an upright optical microscope); an SEM column over a tilted stage
        looks at the rig at the stage's tilt.
    azimuth : float
        Direction the optical axis leans to, rad, from world x towards world y, in [-2 pi, 2 pi].
    roll : float
        Rotation of the image about the optical axis, rad, in [-2 pi, 2 pi] (more than a full
        turn is refused: an angle in degrees).
    """

    tilt: float = 0.0
    azimuth: float = 0.0
    roll: float = 0.0

    def __post_init__(self) -> None:
        for name in ("tilt", "azimuth", "roll"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"view {name} = {v!r} must be a finite angle in radians")
            object.__setattr__(self, name, float(v))
        if not 0.0 <= self.tilt <= math.pi / 2 + 1e-12:
            raise ValueError(f"view tilt = {math.degrees(self.tilt):.4g} deg must be in [0, 90] deg")
        for name in ("azimuth", "roll"):  # roll = 90 meant as degrees was 90 rad (a roll of 116.6 deg), silently
            v = getattr(self, name)
            if not -2.0 * math.pi <= v <= 2.0 * math.pi:
                raise ValueError(f"view {name} = {v:.6g} rad is more than a full turn: radians, not degrees "
                                 f"({v:.6g} deg is {math.radians(v):.6g} rad)")

    def axes(self) -> NDArray[np.float64]:
        """Rows: image ``x``, image ``y`` (down) and the optical axis ``v`` (away from the camera), world frame."""
        straight_down = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
        turn = _rz(self.azimuth) @ _ry(-self.tilt) @ _rz(self.roll)
        return np.asarray(straight_down @ turn.T, dtype=float)

    def as_dict(self) -> dict[str, float]:
        """``{"tilt": rad, "azimuth": rad, "roll": rad}``."""
        return {"tilt": self.tilt, "azimuth": self.azimuth, "roll": self.roll}


TOP_VIEW = View()
"""Looking straight down, image x along world x."""


def image_axes(view: View, theta: float = 0.0, psi: float = 0.0) -> NDArray[np.float64]:
    """The camera's axes (rows: image x, image y, optical axis) in the arm's base frame.

    The base is tilted by ``theta`` and ``psi`` (rad) in the world (``rotation_base``);
    the camera is not.
    """
    return np.asarray(view.axes() @ rotation_base(theta, psi), dtype=float)


def _pixel(pixel_size_m: float) -> float:
    """``pixel_size_m`` as a float in :data:`~.frame.PIXEL_SIZE_RANGE`, or ValueError (0.5 meant as µm was a
    half-metre pixel: every point projected onto the centre; 0 divided by zero)."""
    s = float(pixel_size_m)
    lo, hi = PIXEL_SIZE_RANGE
    if not (math.isfinite(s) and lo <= s < hi):
        raise ValueError(f"pixel_size_m = {pixel_size_m!r} must be a pixel size in [{lo:g}, {hi:g}) m "
                         "(0.5 µm is 0.5e-6)")
    return s


def project(
    p_base: ArrayLike, view: View, pixel_size_m: float, centre_base: ArrayLike, centre_px: tuple[float, float],
    theta: float = 0.0, psi: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(u, depth)``: pixel ``(x, y)`` and depth behind the focal plane (m) of base-frame points ``p_base`` (m).

    ``pixel_size_m``: the pixel's size in the object plane, m, in [1 pm, 1 cm) (else ``ValueError``).

    ``centre_base`` is the point (base frame, m) seen at pixel ``centre_px`` in focus.
    """
    A = image_axes(view, theta, psi)
    d = np.asarray(p_base, dtype=float) - np.asarray(centre_base, dtype=float)
    uvw = d @ A.T
    u = uvw[..., :2] / _pixel(pixel_size_m) + np.asarray(centre_px, dtype=float)
    return np.asarray(u, dtype=float), np.asarray(uvw[..., 2], dtype=float)


def base_to_image(view: View, pixel_size_m: float, theta: float = 0.0, psi: float = 0.0) -> NDArray[np.float64]:
    """The 2 × 3 matrix ``P / s``: pixels per metre of a base-frame displacement (``s = pixel_size_m``, m, in
    [1 pm, 1 cm), else ``ValueError``; the base tilt ``theta``, ``psi`` in rad)."""
    return np.asarray(image_axes(view, theta, psi)[:2] / _pixel(pixel_size_m), dtype=float)
