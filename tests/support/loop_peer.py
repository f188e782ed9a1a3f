"""A second microscope over the simulated arm, for the closed loop: ``peercam://``.

Independent of the simulated microscope (``simcam://``) and of the projection the closed
loop uses (``stickslip.vision.view``): the tip comes from the simulator's true joints
through the arm composed by rotations (:func:`hidden_arm.tip_of`), is seen from straight
above with the image's y down (pixel ``x = cx + X / s``, ``y = cy - Y / s``), and is drawn
by the other renderer (:mod:`vision_peer`: a hyperboloid needle, pillbox blur, Poisson
and read noise, per-column gain, 12-bit counts). Options: ``pixel`` (e.g. ``1um``),
``size`` (``WxH``), ``seed``, ``look`` (``brightfield`` or ``sem``), ``occluder``
(``X,Y,R`` px: an opaque particle the tip passes under), ``tilt`` (degrees: the microscope
leans about the world's y axis, the scene turned by scipy's rotation before the same
top-down drop of the height: a view the loop's kinematic straight-down Jacobian gets wrong).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from hidden_arm import tip_of
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation
from vision_peer import _background, _render

from stickslip import kinematics as kin
from stickslip.units import parse_length
from stickslip.vision.camera import CameraError, CameraInfo, camera_options, register_camera
from stickslip.vision.frame import Frame, as_image

G = kin.DEFAULT_GEOMETRY


class PeerCamera:
    """The other renderer looking straight down at ``device`` (a simulator that knows its true joints)."""

    def __init__(self, device: Any, pixel_m: float, size: tuple[int, int], seed: int, look: str,
                 occluder: tuple[float, float, float] | None, url: str, tilt_deg: float = 0.0):
        self.device = device
        self.pixel_m = pixel_m
        self.w, self.h = size
        self.look = look
        self.occluder = occluder
        self.url = url
        self.turn = Rotation.from_euler("y", tilt_deg, degrees=True)
        self.rng = np.random.default_rng([seed, 30])
        self.bg = _background("grains" if look == "sem" else "spots", self.h, self.w, self.rng, [])
        self.gain = 1.0 + self.rng.normal(0.0, 0.01, self.w)
        home = tip_of((0.0, -math.pi / 2, 0.0), G.offset, G.length)
        self.home = home
        self.centre = (0.6 * self.w, 0.5 * self.h)
        self.t = 0.0

    def _q(self) -> tuple[float, float, float]:
        return (float(self.device.position(1)), float(self.device.position(2)), float(self.device.position(3)))

    def true_tip(self) -> tuple[float, float]:
        """The tip's true pixel (x right, y down)."""
        p = self.turn.apply(tip_of(self._q(), G.offset, G.length) - self.home)
        return (self.centre[0] + float(p[0]) / self.pixel_m, self.centre[1] - float(p[1]) / self.pixel_m)

    @property
    def info(self) -> CameraInfo:
        return CameraInfo(self.url, "peer microscope (tests)", self.pixel_m)

    def grab(self) -> Frame:
        q1 = self._q()[0]
        phi = math.atan2(math.sin(q1), -math.cos(q1))  # back along the shaft, image y down
        img: NDArray[np.uint16] = _render(self.h, self.w, self.look, self.bg, self.true_tip(), phi, 6.0,
                                          math.radians(8.0), 0.8, self.occluder, 300.0, self.gain, self.rng)
        self.t += 0.1
        return Frame(as_image(img), self.t, self.pixel_m, self.url)

    def close(self) -> None:
        pass


def open_peer(url: str, device: Any = None) -> PeerCamera:
    """``peercam://?pixel=1um&size=256x256&occluder=150,128,12``."""
    if device is None or not hasattr(device, "position"):
        raise CameraError("peercam:// looks at the simulated arm: give -d sim://")
    _, opts = camera_options(url, {"pixel", "size", "seed", "look", "occluder", "tilt"})
    pixel = parse_length(opts.get("pixel", "1um"))
    w, _, h = opts.get("size", "256x256").partition("x")
    occ = None
    if "occluder" in opts:
        x, y, r = (float(v) for v in opts["occluder"].split(","))
        occ = (x, y, r)
    return PeerCamera(device, pixel, (int(w), int(h or w)), int(opts.get("seed", "0")),
                      opts.get("look", "brightfield"), occ, url, float(opts.get("tilt", "0")))


def register() -> None:
    """Make ``peercam://`` URLs open this camera."""
    register_camera("peercam", open_peer)
