"""The simulated microscope (``simcam://``): what a camera over the simulated arm sees.

It renders the tip of the arm it looks at from the arm's **true** joint positions
(:class:`~stickslip.devices.base.KnowsTruePosition`; the base tilt from the simulator's
pose) through the tip's forward kinematics (:func:`stickslip.kinematics.tip`) and a
:class:`~stickslip.vision.view.View`:

* the needle: a cone of half-angle ``taper`` ending in a rounded apex of radius
  ``tip_radius``, along the arm's axis (joint 3's), projected into the image; the tip is
  the needle's extreme end (the kinematic tip);
* two looks: ``optical`` (bright field: a bright, vignetted background, the needle dark
  where it absorbs the light) and ``sem`` (secondary electrons: a darker background, the
  needle bright, brightest at its edges where the surface turns away from the beam, a
  brightness gradient across the field and line-by-line scan noise);
* focus: the needle's image is blurred by a Gaussian whose width grows with its distance
  from the focal plane (``dof``: the defocus that adds one pixel of blur); or, with
  ``defocus="disc"``, by geometric optics' blur circle of the same variance (:func:`defocus_kernel`);
* a textured substrate with debris, in the focal plane, drifting slowly across the field
  (``drift``, px/s on the arm's virtual clock, plus a small random walk);
* shot noise: Poisson counts with ``photons`` at full brightness.

The field is fixed to the rig: the tip of the outstretched arm is seen at
``(0.6 w, 0.5 h)`` and in focus; ``centre=tip`` centres and focuses it on the tip as it is
when the camera opens (a user who finds the tip first), ``centre=X,Y,Z`` on a point of
the base frame (with units). The truth is at hand for tests:
:meth:`SimCamera.true_tip` (pixel, depth).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, signal, special

from .. import kinematics as kin
from ..devices.base import Controller, KnowsTruePosition, VirtualClock, redact_url
from ..units import UnitError, parse_typed
from ..vision.camera import CameraError, CameraInfo, camera_options, pixel_option
from ..vision.frame import PIXEL_SIZE_RANGE, Frame
from ..vision.view import View, project

__all__ = ["SimCamera", "SimCamSettings", "SimScene", "LobedParticle", "Flake", "Droplet", "open_url", "LOOKS", "ENDS",
           "DEFOCUS", "defocus_kernel"]

LOOKS = ("optical", "sem")
"""The simulated microscope's looks."""

ENDS = ("cone", "paraboloid")
"""The simulated needle's ends (:class:`SimCamSettings`'s ``end``)."""

DEFOCUS = ("gaussian", "disc")
"""The simulated needle's defocus blurs (:class:`SimCamSettings`'s ``defocus``)."""


@dataclass(frozen=True)
class SimCamSettings:
    """What the simulated microscope is like.

    Attributes
    ----------
    look : str
        ``"optical"`` (bright field) or ``"sem"``.
    width, height : int
        Frame size, pixels.
    pixel_size_m : float
        Pixel size in the object plane, m.
    view : View
        Orientation of the camera in the world.
    photons : float
        Mean photon (electron) count of a pixel at full brightness: shot noise.
    dof_m : float
        Defocus that adds one pixel of blur (Gaussian sigma), m.
    blur_px : float
        Blur of the needle in focus (sigma), pixels.
    tip_radius_m : float
        Radius of the needle's rounded apex, m.
    taper : float
        Half-angle of the needle's cone, rad.
    end : str
        The needle's end: ``"cone"`` (a cone ending in a spherical cap of radius
        ``tip_radius``, the default) or ``"paraboloid"`` (a blunt, etched end: a paraboloid
        whose apex has the radius of curvature ``tip_radius``, so its radius grows as
        ``sqrt(2 R s)`` at ``s`` behind the apex, joining the cone where their slopes meet).
    defocus : str
        The shape of the needle's blur: ``"gaussian"`` (the default; an SEM's beam out of focus
        is close to one) or ``"disc"`` (bright field: geometric optics images a point out of
        focus as a uniform blur circle; :func:`defocus_kernel`, of the same variance as the
        Gaussian it replaces, its rim softened by ``rim_px``).
    rim_px : float
        With ``defocus="disc"``: the Gaussian (sigma, px) that softens the blur circle's rim
        (diffraction, the lens's aberrations); part of the blur's variance.
    drift_px_s : float
        Speed of the slow drift of the whole image, pixels per second (of the arm's clock).
    debris : int
        Number of dust particles on the substrate.
    seed : int
        Seeds the substrate, the debris, the drift's direction and the noise.
    """

    look: str = "optical"
    width: int = 512
    height: int = 512
    pixel_size_m: float = 0.5e-6
    view: View = View()
    photons: float = 300.0
    dof_m: float = 4e-6
    blur_px: float = 0.7
    tip_radius_m: float = 1.0e-6
    taper: float = math.radians(8.0)
    end: str = "cone"
    defocus: str = "gaussian"
    rim_px: float = 0.5
    drift_px_s: float = 0.02
    debris: int = 40
    seed: int = 0

    def __post_init__(self) -> None:
        """The simcam:// URL's bounds on the lengths and the angle, for settings made in Python too (a unit slip:
        taper=8 meant as degrees was a cone of 8 rad, pixel_size_m=0.5 meant as µm a pixel of half a metre)."""
        for name, (lo, hi, unit) in _UNIT_RANGES.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not lo <= float(v) <= hi:
                raise ValueError(f"SimCamSettings: {name} = {v!r} must be a number in [{lo:g}, {hi:g}] {unit}")


_UNIT_RANGES: dict[str, tuple[float, float, str]] = {
    "pixel_size_m": (PIXEL_SIZE_RANGE[0], PIXEL_SIZE_RANGE[1], "m"),
    "dof_m": (1e-8, 1e-2, "m"),
    "tip_radius_m": (0.0, 1e-4, "m"),
    "taper": (math.radians(0.5), math.radians(45.0), "rad"),
}
"""What :func:`open_url` accepts for each length and angle of :class:`SimCamSettings` (SI)."""


class SimCamera:
    """A simulated microscope looking at a simulated arm (a :class:`~stickslip.vision.camera.Camera`).

    Parameters
    ----------
    device : Controller
        The arm; it must know its true joint positions (the simulator does).
    settings : SimCamSettings
        The look, size, pixel size, view, noise, focus and drift.
    geometry : Geometry
        The arm's tip geometry (offset, length), m.
    centre_base : array_like or "tip", optional
        The point (base frame, m) seen in focus at pixel ``(0.6 w, 0.5 h)``; default:
        the tip in the outstretched pose (``q = (0, -pi/2, 0)``), so every camera opened
        on the arm sees the same field; ``"tip"``: the tip when the camera opens.
    url : str
        For :attr:`info`.
    """

    def __init__(
        self,
        device: Controller,
        settings: SimCamSettings = SimCamSettings(),
        geometry: kin.Geometry = kin.DEFAULT_GEOMETRY,
        centre_base: Any = None,
        url: str = "simcam://",
    ) -> None:
        if not isinstance(device, KnowsTruePosition):
            raise CameraError(
                "simcam:// looks at a simulated arm and needs one that knows its true position: use it with -d sim://"
            )
        if settings.look not in LOOKS:
            raise ValueError(f"look={settings.look!r}: the simulated microscope has the looks {', '.join(LOOKS)}")
        self.device = device
        self.settings = settings
        self.geometry = geometry
        self._url = url
        s = settings
        self.centre_px = (0.6 * s.width, 0.5 * s.height)
        if centre_base is None:  # where the tip is in the outstretched pose: the same field every time
            centre_base = kin.tip((0.0, -math.pi / 2, 0.0), geometry)
        elif isinstance(centre_base, str) and centre_base == "tip":  # centred on the tip as it is now
            centre_base = self._tip_base()
        self.centre_base = np.asarray(centre_base, dtype=float).reshape(3)
        self.scene = SimScene(settings)
        self._rng = self.scene.rng
        self._drift_dir = self.scene.drift_dir
        self._walk = np.zeros(2)
        self._t_last: float | None = None
        self._t_own = 0.0

    # ---------------------------------------------------------------- the truth

    def _pose(self) -> kin.Pose:
        pose = getattr(self.device, "pose", None)
        dev: Any = self.device
        q = [float(dev.position(j)) for j in (1, 2, 3)]
        if isinstance(pose, kin.Pose):
            return kin.Pose(q[0], q[1], q[2], pose.theta, pose.psi)
        return kin.Pose(q[0], q[1], q[2])

    def _tip_base(self) -> NDArray[np.float64]:
        p = self._pose()
        return np.asarray(kin.tip((p.q1, p.q2, p.q3), self.geometry), dtype=float)

    def _time(self) -> float:
        if isinstance(self.device, VirtualClock):
            return float(self.device.clock_s)
        self._t_own += 0.05
        return self._t_own

    def drift_px(self, t: float) -> NDArray[np.float64]:
        """The image drift at time ``t`` (s of the arm's clock) without its random walk, pixels ``(x, y)``."""
        v = self.settings.drift_px_s
        return np.array([math.cos(self._drift_dir), math.sin(self._drift_dir)]) * v * t

    def true_tip(self) -> tuple[NDArray[np.float64], float]:
        """``((x, y), depth)``: where the tip is seen now, pixels (drift included), and m behind the focal plane."""
        pose = self._pose()
        u, depth = project(self._tip_base(), self.settings.view, self.settings.pixel_size_m, self.centre_base,
                           self.centre_px, pose.theta, pose.psi)
        return u + self.drift_px(self._time()) + self._walk, float(depth)

    # ---------------------------------------------------------------- Camera protocol

    @property
    def info(self) -> CameraInfo:
        """``"simulated microscope (optical|sem)"``, pixel size, frame size and the settings."""
        s = self.settings
        return CameraInfo(
            redact_url(self._url), f"simulated microscope ({s.look})", s.pixel_size_m,
            {"shape": (s.height, s.width), "look": s.look, "view": s.view.as_dict(), "photons": s.photons,
             "seed": s.seed},
        )

    def grab(self) -> Frame:
        """Render what the camera sees now (the arm's true pose, time and drift)."""
        t = self._time()
        if self._t_last is not None and t > self._t_last:
            self._walk += self._rng.normal(0.0, 0.02 * math.sqrt(t - self._t_last), 2)
        self._t_last = t
        image = self.render(t)
        return Frame(image, t, self.settings.pixel_size_m, f"{redact_url(self._url)} t={t:.3f}s")

    def close(self) -> None:
        """Nothing to release."""

    # ---------------------------------------------------------------- rendering

    def render(self, t: float) -> NDArray[np.float64]:
        """The noisy frame at time ``t`` (s), grey values in [0, 1]."""
        s = self.settings
        pose = self._pose()
        shift = self.drift_px(t) + self._walk
        tip_px, depth = project(self._tip_base(), s.view, s.pixel_size_m, self.centre_base, self.centre_px,
                                pose.theta, pose.psi)
        axis = kin.arm_axis(pose.q1, pose.q2)  # the needle points along joint 3's axis, base frame
        back, _ = project(self._tip_base() - 50e-6 * np.asarray(axis), s.view, s.pixel_size_m, self.centre_base,
                          self.centre_px, pose.theta, pose.psi)
        direction = back - tip_px  # from the apex back along the shaft, pixels per 50 µm
        foreshortening = float(np.hypot(*direction)) / (50e-6 / s.pixel_size_m)
        sigma = math.hypot(s.blur_px, abs(depth) / s.dof_m)
        return self.scene.render(tip_px + shift, direction, sigma, shift, foreshortening)


@dataclass(frozen=True)
class LobedParticle:
    """A dust grain of a few overlapping discs (a lobed outline), lying over the needle.

    Real dust is rarely a disc: grains clump, and a clump's outline is a few rounded lobes.
    Its body is as opaque as its ``level`` says and its outline as sharp as ``blur``
    (a grain lying a little above the focal plane is softer than the substrate).

    Parameters
    ----------
    discs : tuple of (x, y, r)
        The lobes' centres and radii, px; the grain is their union.
    level : float
        Its brightness as a share of the illumination: bright field, what it lets through
        (the needle lets through about 0.15 of the ground's); SEM, its yield (the needle's
        body is about 0.45).
    blur : float
        The Gaussian sigma of its outline, px.
    """

    discs: tuple[tuple[float, float, float], ...]
    level: float
    blur: float = 0.0


@dataclass(frozen=True)
class Flake:
    """A flat flake with rounded corners lying over the needle: an opaque chip, not a clump.

    Chips of a broken coating or a cleaved crystal are flat and straight-sided; a flake the
    tip has picked up sits on it and moves with it. Its outline is a convex polygon grown
    by ``rounding`` (every point within ``rounding`` of the polygon: straight sides joined
    by arcs), lying closer to the objective than the needle's end, so it is as sharp as
    ``blur`` says whatever the needle's focus.

    Parameters
    ----------
    corners : tuple of (x, y)
        The polygon's corners, px, in order around it (convex).
    rounding : float
        How far the outline lies outside the polygon, px (the corners' radius).
    level : float
        Its brightness as a share of the illumination, as :class:`LobedParticle`'s.
    blur : float
        The Gaussian sigma of its outline, px.
    """

    corners: tuple[tuple[float, float], ...]
    rounding: float
    level: float
    blur: float = 0.0


@dataclass(frozen=True)
class Droplet:
    """A transparent droplet (a sessile spherical cap) over the needle: it refracts what lies under it.

    A drop of water, oil or a glycerol film clinging to the tip is a plano-convex lens.
    Seen from above, a point under it at ``rho`` from its middle is seen displaced outwards
    by the cap's local prism: its thickness ``t`` times the surface's slope times
    ``1 - 1/n`` (paraxial), so the image under it is magnified, most in the middle of a
    hemisphere (by ``n``) and not at all at the contact line where ``t`` falls to zero. Where
    the surface is steep the light leaves the objective's aperture (a dark rim) or is
    gathered by it (a bright one); ``rim`` scales the brightness of the outer ``rim_width``.

    Parameters
    ----------
    centre : (x, y)
        The contact disc's middle, px.
    radius : float
        The contact disc's radius, px.
    contact_angle : float
        The cap's contact angle, rad (pi/2: a hemisphere).
    index : float
        The liquid's refractive index (water 1.33, glycerol 1.47).
    rim : float
        The rim's brightness as a share of what it covers (1: no rim; below: dark; above: bright).
    rim_width : float
        The rim's width inside the contact line, px.
    """

    centre: tuple[float, float]
    radius: float
    contact_angle: float
    index: float = 1.33
    rim: float = 1.0
    rim_width: float = 1.5

    def __post_init__(self) -> None:
        if not (self.radius > 0 and 0 < self.contact_angle < math.pi and self.index >= 1.0 and self.rim >= 0
                and self.rim_width > 0):
            raise ValueError(
                f"a droplet needs radius > 0 px, 0 < contact_angle < pi rad, index >= 1, rim >= 0 and rim_width > 0 "
                f"px; got {self.radius:g}, {self.contact_angle:g}, {self.index:g}, {self.rim:g}, {self.rim_width:g}"
            )


class SimScene:
    """What the simulated microscope renders, apart from the arm: substrate, needle, look, noise.

    :class:`SimCamera` places the needle from the arm's pose; tests and benchmarks place it
    directly (:meth:`render`), with particles over it if they like.

    Parameters
    ----------
    settings : SimCamSettings
        The look, size, pixel size, noise, tip radius and taper, debris and seed (the
        view, focus and drift are the camera's).
    """

    margin = 48
    """Substrate beyond each edge of the field, px: room for the drift."""

    def __init__(self, settings: SimCamSettings = SimCamSettings()) -> None:
        s = settings
        if s.look not in LOOKS:
            raise ValueError(f"look={s.look!r}: the simulated microscope has the looks {', '.join(LOOKS)}")
        if s.end not in ENDS:
            raise ValueError(f"end={s.end!r}: the simulated needle ends in one of {', '.join(ENDS)}")
        if s.defocus not in DEFOCUS or not s.rim_px >= 0.0:
            raise ValueError(f"defocus={s.defocus!r}, rim_px={s.rim_px!r}: the needle's blur is one of "
                             f"{', '.join(DEFOCUS)}, its rim >= 0 px")
        self.settings = s
        rng = np.random.default_rng([s.seed, 7])
        self.rng = np.random.default_rng([s.seed, 8])
        m = self.margin
        self.substrate = _substrate(s.height + 2 * m, s.width + 2 * m, s.look, s.debris, rng)
        self.drift_dir = float(rng.uniform(0.0, 2.0 * math.pi))
        yy, xx = np.mgrid[0 : s.height, 0 : s.width]
        self._xx = xx.astype(float)
        self._yy = yy.astype(float)
        r2 = ((xx - s.width / 2) ** 2 + (yy - s.height / 2) ** 2) / ((s.width / 2) ** 2 + (s.height / 2) ** 2)
        if s.look == "optical":
            self.illumination = 1.0 - 0.35 * r2  # vignetting
        else:
            self.illumination = 0.85 + 0.3 * (xx / s.width)  # the detector sees one side better

    def render(self, tip_px: NDArray[np.float64], direction: NDArray[np.float64], sigma: float,
               shift: NDArray[np.float64] | None = None, foreshortening: float = 1.0,
               particles: tuple[tuple[float, float, float], ...] = (),
               lobed: tuple[LobedParticle, ...] = (),
               flakes: tuple[Flake, ...] = (), droplets: tuple[Droplet, ...] = ()) -> NDArray[np.float64]:
        """A noisy frame, grey values in [0, 1].

        Parameters
        ----------
        tip_px : array_like
            The tip (the needle's extreme end), px ``(x, y)``.
        direction : array_like
            From the tip back along the shaft (any length), px.
        sigma : float
            The needle's blur (Gaussian sigma), px; with ``defocus="disc"`` the blur circle of the same
            variance (:func:`defocus_kernel`).
        shift : array_like, optional
            The substrate's drift, px ``(x, y)`` (default none).
        foreshortening : float
            How much shorter the needle looks than it is (1: lying in the image plane).
        particles : tuple of (x, y, r)
            Opaque particles over everything (px): as dark as the needle in bright field,
            as bright as its edges in an SEM.
        lobed : tuple of LobedParticle
            Grains of a few lobes over everything, painted after ``particles``.
        flakes : tuple of Flake
            Flat chips with rounded corners over everything, painted after ``lobed``.
        droplets : tuple of Droplet
            Transparent droplets over everything, refracting what lies under them (last).
        """
        s = self.settings
        tip_px = np.asarray(tip_px, dtype=float)
        shift = np.zeros(2) if shift is None else np.asarray(shift, dtype=float)
        m = self.margin
        bg = ndimage.shift(self.substrate, (float(shift[1]), float(shift[0])), order=1, mode="nearest")
        bg = bg[m : m + s.height, m : m + s.width]
        cover, edge = self._needle(tip_px, np.asarray(direction, dtype=float), foreshortening)
        if s.defocus == "disc" and sigma > max(s.rim_px, 0.3):
            kernel = defocus_kernel(sigma, s.rim_px)
            cover, edge = _convolved(cover, kernel), _convolved(edge, kernel)
        elif sigma > 0.3:
            cover = ndimage.gaussian_filter(cover, sigma, truncate=3.0)
            edge = ndimage.gaussian_filter(edge, sigma, truncate=3.0)
        if s.look == "optical":
            clean = self.illumination * bg * (1.0 - 0.82 * cover)
        else:
            clean = self.illumination * (bg * (1.0 - cover) + 0.45 * cover + 0.5 * edge)
        for px, py, r in particles:
            disc = np.clip(r + 0.5 - np.hypot(self._xx - px, self._yy - py), 0.0, 1.0)
            level = 0.1 if s.look == "optical" else 0.8
            clean = clean * (1.0 - disc) + level * self.illumination * disc
        for grain in lobed:
            clean = self._paint_lobed(clean, grain)
        for flake in flakes:
            clean = self._paint_flake(clean, flake)
        for drop in droplets:
            clean = self._refract(clean, drop)
        lam = np.clip(clean, 0.0, None) * s.photons
        counts = self.rng.poisson(lam).astype(float)
        if s.look == "sem":  # the beam's line-by-line jitter
            counts += self.rng.normal(0.0, 0.005 * s.photons, (s.height, 1))
        return np.asarray(np.clip(counts / s.photons, 0.0, 1.0), dtype=float)

    def _paint_lobed(self, clean: NDArray[np.float64], grain: LobedParticle) -> NDArray[np.float64]:
        """``clean`` with ``grain`` over it: its lobes' coverage (anti-aliased, their union), softened."""
        cover = np.zeros_like(clean)
        for px, py, r in grain.discs:
            cover = np.maximum(cover, np.clip(r + 0.5 - np.hypot(self._xx - px, self._yy - py), 0.0, 1.0))
        if grain.blur > 0.3:
            cover = ndimage.gaussian_filter(cover, grain.blur, truncate=3.0)
        return np.asarray(clean * (1.0 - cover) + grain.level * self.illumination * cover, dtype=float)

    def _paint_flake(self, clean: NDArray[np.float64], flake: Flake) -> NDArray[np.float64]:
        """``clean`` with ``flake`` over it: coverage from the distance to its polygon (anti-aliased)."""
        xx, yy = self._xx, self._yy
        pts = np.asarray(flake.corners, dtype=float)
        nxt = np.roll(pts, -1, axis=0)
        sense = float(np.sign(np.sum(pts[:, 0] * nxt[:, 1] - nxt[:, 0] * pts[:, 1])) or 1.0)
        dist = np.full_like(clean, np.inf)
        inside = np.ones(clean.shape, dtype=bool)
        for (ax, ay), (bx, by) in zip(pts, nxt, strict=True):
            ex, ey = bx - ax, by - ay
            t = np.clip(((xx - ax) * ex + (yy - ay) * ey) / max(ex * ex + ey * ey, 1e-12), 0.0, 1.0)
            dist = np.minimum(dist, np.hypot(xx - ax - t * ex, yy - ay - t * ey))
            inside &= sense * (ex * (yy - ay) - ey * (xx - ax)) >= 0.0  # on the polygon's side of this edge
        signed = np.where(inside, -dist, dist)
        cover = np.clip(flake.rounding + 0.5 - signed, 0.0, 1.0)
        if flake.blur > 0.3:
            cover = ndimage.gaussian_filter(cover, flake.blur, truncate=3.0)
        return np.asarray(clean * (1.0 - cover) + flake.level * self.illumination * cover, dtype=float)

    def _refract(self, clean: NDArray[np.float64], drop: Droplet) -> NDArray[np.float64]:
        """``clean`` seen through ``drop``: each pixel inside its disc shows what lies ``delta(rho)`` nearer its middle.

        ``delta = (1 - 1/n) t(rho) tan(slope) = (1 - 1/n) rho (1 - cos(a) / sqrt(1 - (rho / Rc)^2))`` for a
        cap of contact angle ``a`` and curvature radius ``Rc = R / sin(a)`` (px); the rim's band scales the light.
        """
        cx, cy = drop.centre
        dx, dy = self._xx - cx, self._yy - cy
        rho = np.hypot(dx, dy)
        inside = rho < drop.radius
        rc = drop.radius / math.sin(drop.contact_angle)
        lean = np.sqrt(np.clip(1.0 - (rho / rc) ** 2, 1e-9, None))
        k = np.where(inside, (1.0 - 1.0 / drop.index) * (1.0 - math.cos(drop.contact_angle) / lean), 0.0)
        src = np.array([cy + dy * (1.0 - k), cx + dx * (1.0 - k)])
        seen = ndimage.map_coordinates(clean, src, order=1, mode="nearest")
        band = np.clip((rho - (drop.radius - drop.rim_width)) / max(drop.rim_width, 1e-6), 0.0, 1.0)
        return np.asarray(seen * (1.0 + (drop.rim - 1.0) * np.sin(math.pi * band) ** 2), dtype=float)

    def _needle(self, tip: NDArray[np.float64], direction: NDArray[np.float64],
                foreshortening: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Coverage of the needle (0..1) and its edge brightness (SEM), unblurred.

        A pixel integrates the needle over its area: by the clipped signed distance where
        the needle is wide, and 4 × 4 samples per pixel within 24 px of the tip, where
        it is thinner than a pixel.
        """
        cover, edge = self._needle_at(self._xx, self._yy, tip, direction, foreshortening)
        s = self.settings
        k, box = 4, 24
        x0, x1 = max(0, int(tip[0]) - box), min(s.width, int(tip[0]) + box + 1)
        y0, y1 = max(0, int(tip[1]) - box), min(s.height, int(tip[1]) + box + 1)
        if x1 > x0 and y1 > y0:
            sub = (np.arange(k) + 0.5) / k - 0.5
            xs = (np.arange(x0, x1)[:, None] + sub[None, :]).ravel()
            ys = (np.arange(y0, y1)[:, None] + sub[None, :]).ravel()
            XX, YY = np.meshgrid(xs, ys)
            c, e = self._needle_at(XX, YY, tip, direction, foreshortening, aa=False)
            h, w = y1 - y0, x1 - x0
            cover[y0:y1, x0:x1] = c.reshape(h, k, w, k).mean(axis=(1, 3))
            edge[y0:y1, x0:x1] = e.reshape(h, k, w, k).mean(axis=(1, 3))
        return cover, edge

    def _needle_at(self, xx: NDArray[np.float64], yy: NDArray[np.float64], tip: NDArray[np.float64],
                   direction: NDArray[np.float64], foreshortening: float,
                   aa: bool = True) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Coverage and edge brightness at points ``(xx, yy)`` (px): anti-aliased by distance, or inside/outside."""
        s = self.settings
        n = float(np.hypot(*direction))
        r0 = s.tip_radius_m / s.pixel_size_m
        if n < 1e-9:  # looking along the needle: a disc
            d = np.hypot(xx - tip[0], yy - tip[1])
            cover = np.clip(r0 + 0.5 - d, 0.0, 1.0) if aa else (d <= r0).astype(float)
            return cover, np.zeros_like(cover)
        a = direction / n
        rx, ry = xx - tip[0], yy - tip[1]
        across = np.abs(-rx * a[1] + ry * a[0])
        slope = math.tan(s.taper) / max(foreshortening, 1e-3)  # a foreshortened cone looks blunter
        shank = 40e-6 / s.pixel_size_m  # the needle's shank
        if s.end == "paraboloid":
            radius, sd = _paraboloid(rx * a[0] + ry * a[1], across, r0, slope)
            sd = np.where(radius > shank, across - shank, sd)
            radius = np.minimum(radius, shank)
        else:
            along = rx * a[0] + ry * a[1] - r0  # pixels behind the apex cap's centre (the tip is its extreme end)
            radius = r0 + np.clip(along, 0.0, None) * slope
            radius = np.minimum(radius, shank)
            # signed distance (pixels) to the cone's side, and to the apex's cap behind the tip
            side = across - radius
            cap = np.hypot(np.minimum(along, 0.0), across) - r0
            sd = np.where(along < 0.0, cap, side)
        cover = np.clip(0.5 - sd, 0.0, 1.0) if aa else (sd <= 0.0).astype(float)
        inside = np.clip(across / np.maximum(radius, 1e-6), 0.0, 1.0)
        edge = cover * inside**6  # secondary-electron yield rises where the surface turns from the beam
        return cover, edge


def defocus_kernel(sigma: float, rim: float = 0.0) -> NDArray[np.float64]:
    """Geometric optics' blur circle of a point out of focus, of the variance of a Gaussian of ``sigma`` (px).

    A bright-field objective of numerical aperture NA images a point a distance ``dz`` out of
    its focal plane as a nearly uniform disc (the blur circle) of radius about ``dz NA`` in the
    object plane, its rim softened by diffraction. A uniform disc of radius ``R`` has the
    variance ``R² / 4`` along any line (``R² / 2`` in the plane), so the disc of the variance
    ``sigma²`` of the Gaussian it replaces has ``R = 2 sigma`` (not ``sqrt(2) sigma``: that
    disc has half the Gaussian's variance). The disc is anti-aliased (each pixel its share of
    it, 8 x 8 samples a pixel: the disc integrated over a pixel, which adds a pixel's 1/12 px²)
    and its edge softened by a Gaussian ``rim`` (px; the edge falls as an error function of
    the distance from the circle); both variances add to the disc's, so
    ``R = 2 sqrt(sigma² - rim² - 1/12)`` to first order, made exact (to 0.1 %) by two
    corrections of ``R²`` by the kernel's own variance. Normalised to a sum of 1.
    """
    r2 = 4.0 * max(sigma * sigma - rim * rim - 1.0 / 12.0, 0.0)
    disc = _soft_disc(math.sqrt(r2), rim)
    for _ in range(2):
        if r2 <= 0.0:
            break
        h = disc.shape[0] // 2
        x = np.arange(-h, h + 1)
        r2 = max(r2 + 4.0 * (sigma * sigma - float((disc.sum(axis=0) * x * x).sum())), 0.0)
        disc = _soft_disc(math.sqrt(r2), rim)
    return disc


def _soft_disc(r: float, rim: float) -> NDArray[np.float64]:
    """A disc of radius ``r`` px, its edge falling as an error function of width ``rim`` px, each pixel its mean over
    8 x 8 samples; normalised to a sum of 1."""
    half = int(math.ceil(r + 4.0 * rim + 1.0))
    k = 8
    sub = (np.arange(k) + 0.5) / k - 0.5
    ax = (np.arange(-half, half + 1)[:, None] + sub[None, :]).ravel()
    rho = np.hypot(ax[:, None], ax[None, :])
    n = 2 * half + 1
    if rim > 0.0:  # the rim's fall across the circle (the disc's edge, softened)
        inside = 0.5 * special.erfc((rho - r) / (math.sqrt(2.0) * rim))
    else:
        inside = (rho <= r).astype(float)
    disc = inside.reshape(n, k, n, k).mean(axis=(1, 3))
    if disc.sum() <= 0.0:  # a disc smaller than a sample: a point
        disc[half, half] = 1.0
    return np.asarray(disc / disc.sum(), dtype=float)


def _convolved(image: NDArray[np.float64], kernel: NDArray[np.float64]) -> NDArray[np.float64]:
    """``image`` convolved with the (odd, symmetric) ``kernel``, its edges mirrored as ``gaussian_filter``'s; by FFT."""
    h = kernel.shape[0] // 2
    padded = np.pad(image, h, mode="symmetric")
    return np.asarray(signal.fftconvolve(padded, kernel, mode="valid"), dtype=float)


def _paraboloid(s: NDArray[np.float64], c: NDArray[np.float64], r0: float,
                slope: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A blunt end's radius and signed distance (px) at ``s`` px behind its apex, ``c`` px off its axis.

    An etched needle's end is close to a paraboloid, ``r² = 2 R s`` with ``R`` (``r0``) its
    apex's radius of curvature, which joins the cone of slope ``slope`` where its own slope
    ``R / r`` has fallen to it: at ``r_t = R / slope``, ``s_t = R / (2 slope²)``. The signed
    distance to the paraboloid is its implicit form ``c² - 2 R s`` over that form's gradient
    (first order: exact on the outline, ``|s|`` ahead of the apex on the axis); to the cone,
    ``c - r``.
    """
    r_t = r0 / max(slope, 1e-6)
    s_t = 0.5 * r0 / max(slope, 1e-6) ** 2
    para = np.sqrt(2.0 * r0 * np.clip(s, 0.0, None))
    radius = np.where(s < s_t, para, r_t + (s - s_t) * slope)
    implicit = (c * c - 2.0 * r0 * s) / (2.0 * np.sqrt(c * c + r0 * r0))
    sd = np.where(s < s_t, implicit, c - radius)
    return radius, sd


def _substrate(h: int, w: int, look: str, debris: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """A smooth textured substrate with dust particles, in the focal plane (before illumination)."""
    noise = rng.standard_normal((h, w))
    texture = ndimage.gaussian_filter(noise, 6.0) * 6.0 + ndimage.gaussian_filter(noise, 1.5) * 0.6
    texture = texture / (np.std(texture) + 1e-12)
    yy, xx = np.mgrid[0:h, 0:w]
    dust = np.zeros((h, w))
    for _ in range(debris):
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        r = rng.uniform(1.0, 6.0)
        dust = np.maximum(dust, np.clip(r + 0.5 - np.hypot(xx - cx, yy - cy), 0.0, 1.0) * rng.uniform(0.3, 0.8))
    dust = ndimage.gaussian_filter(dust, 0.8)
    if look == "optical":
        return np.asarray(0.85 + 0.04 * texture - 0.5 * dust, dtype=float)
    return np.asarray(0.25 + 0.05 * texture + 0.35 * dust, dtype=float)


_OPTIONS = frozenset(
    {"look", "seed", "pixel", "size", "photons", "dof", "defocus", "blur", "tip", "taper", "drift", "debris",
     "tilt", "azimuth", "roll", "centre", "geometry"}
)


def open_url(url: str = "simcam://", device: Controller | None = None) -> SimCamera:
    """Open the simulated microscope from ``simcam://?look=sem&seed=1&pixel=0.5um&...``.

    Options: ``look`` (optical, sem), ``seed``, ``pixel`` (pixel size, e.g. 0.5um), ``size``
    (``WxH`` pixels), ``photons`` (at full brightness), ``dof`` (defocus adding one pixel
    of blur, e.g. 4um), ``defocus`` (gaussian, disc: the blur's shape), ``blur`` (in-focus
    blur, pixels), ``tip`` (apex radius, e.g. 0.4um), ``taper`` (cone half-angle, e.g.
    8deg), ``drift`` (px/s), ``debris`` (count),
    ``tilt``, ``azimuth``, ``roll`` (the view, angles), ``centre`` (``tip``, or ``X,Y,Z`` in
    the base frame, lengths), ``geometry`` (``OFFSET,LENGTH`` of the arm). ``device`` is the arm.
    """
    if device is None:
        raise CameraError("simcam:// looks at a simulated arm: give the device too (-d sim://)")
    location, opts = camera_options(url, _OPTIONS)
    if location.strip("/"):
        raise ValueError(f"a simcam:// URL takes only options (e.g. simcam://?look=sem), got {redact_url(url)!r}")
    kw: dict[str, Any] = {}
    try:
        if "look" in opts:
            kw["look"] = opts["look"].strip().lower()
        if "defocus" in opts:
            kw["defocus"] = opts["defocus"].strip().lower()
            if kw["defocus"] not in DEFOCUS:
                raise ValueError(f"defocus={opts['defocus']!r}: the blur's shape is one of {', '.join(DEFOCUS)}")
        if "seed" in opts:
            kw["seed"] = _int(opts["seed"], "seed", 0, 2**31)
        px = pixel_option(opts, url)
        if px is not None:
            kw["pixel_size_m"] = px
        if "size" in opts:
            w_text, _, h_text = opts["size"].lower().partition("x")
            kw["width"] = _int(w_text, "size", 32, 4096)
            kw["height"] = _int(h_text or w_text, "size", 32, 4096)
        for key, name, lo, hi in (("photons", "photons", 1.0, 1e6), ("blur", "blur_px", 0.0, 20.0),
                                  ("drift", "drift_px_s", 0.0, 100.0)):
            if key in opts:
                kw[name] = _float(opts[key], key, lo, hi)
        if "debris" in opts:
            kw["debris"] = _int(opts["debris"], "debris", 0, 10_000)
        for key, name, lo, hi in (("dof", "dof_m", 1e-8, 1e-2), ("tip", "tip_radius_m", 0.0, 1e-4)):
            if key in opts:
                kw[name] = _amount(opts[key], key, "length", lo, hi)
        if "taper" in opts:
            kw["taper"] = _amount(opts["taper"], "taper", "angle", math.radians(0.5), math.radians(45.0))
        view = View(*(_amount(opts.get(k, "0"), k, "angle", -2 * math.pi, 2 * math.pi)
                      for k in ("tilt", "azimuth", "roll")))
        kw["view"] = view
        centre: Any = None
        if opts.get("centre", "").strip().lower() == "tip":
            centre = "tip"
        elif "centre" in opts:
            parts = opts["centre"].split(",")
            if len(parts) != 3:
                raise ValueError("centre: write X,Y,Z with units, e.g. centre=21mm,0,0")
            centre = np.array([_amount(p, "centre", "length", -1.0, 1.0) for p in parts])
        geometry = kin.Geometry.parse(opts["geometry"]) if "geometry" in opts else kin.DEFAULT_GEOMETRY
        settings = SimCamSettings(**kw)
    except (UnitError, ValueError) as e:
        raise ValueError(f"simcam:// {e}") from None
    return SimCamera(device, settings, geometry, centre, url)


def _int(text: str, key: str, lo: int, hi: int) -> int:
    try:
        v = int(text.strip())
    except ValueError:
        raise ValueError(f"{key}={text!r} is not a whole number") from None
    if not lo <= v <= hi:
        raise ValueError(f"{key}={v} must be in {lo}..{hi}")
    return v


def _float(text: str, key: str, lo: float, hi: float) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{key}={text!r} is not a number") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise ValueError(f"{key}={text!r} must be in [{lo:g}, {hi:g}]")
    return v


def _amount(text: str, key: str, kind: str, lo: float, hi: float) -> float:
    """Option ``key``'s length (m) or angle (rad), ``kind``, within ``[lo, hi]``; its unit given, as on the command
    line (``tip=0.4`` could be µm or m, ``tilt=0.5`` would be 28.6 deg): ``ValueError`` naming the option."""
    try:
        v = parse_typed(text, kind)
    except (UnitError, ValueError, ArithmeticError) as e:  # the option named: which one could not be read
        raise ValueError(f"{key}={text!r}: {e}") from None
    if math.isfinite(v) and lo <= v <= hi:
        return v
    if kind == "angle":
        raise ValueError(f"{key}={text!r} must be an angle in [{math.degrees(lo):g}, {math.degrees(hi):g}] deg")
    raise ValueError(f"{key}={text!r} must be a length in [{lo:g}, {hi:g}] m")
