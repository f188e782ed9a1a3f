"""A third, independent generator of occlusions over a needle's tip: scenes neither renderer makes.

Written before the tracker's change for the blunt chord (issue 30) and never tuned to afterwards.
The two renderers (:mod:`vision_own`, :mod:`vision_peer`) draw a cone or a hyperboloid, blurred
by a Gaussian or a pillbox, with discs, lobed grains, flakes or beads over the tip. This one
takes another view of each part:

* **the needle** is a *power-law* silhouette, half-width ``a s^p`` at ``s`` px behind its end
  (``p`` from 0.35, blunter than a paraboloid, to 0.8, nearly a cone), or a *truncated* cone (a
  broken needle: a flat end with rounded corners); partly transparent (transmission 0.02 to
  0.25), drawn by area coverage on a 3 x 3 sub-pixel grid;
* **the optics**: a transmitted-light image (the background's light times the needle's and the
  occluder's transmissions), an uneven illumination (a tilted plane and a vignette) over a
  smooth random texture; the point spread is a *Moffat* profile (heavy tails, ``beta`` 2 to 4)
  or a defocus *ring* (an annulus and its centre), never a Gaussian nor a pillbox;
* **noise**: Gaussian read noise on a multiplicative speckle (a gamma law), a few hot pixels;
* **the occluders**, over the tip for 1 to 3 frames (``cause``): ``fibre`` (a long fibre or a
  second needle's shaft crossing the tip at any angle, 0.3 to 1.2 tip widths thick, partly
  transparent), ``droplet`` (a disc with a bright refracting rim and a dark band inside it, its
  middle clear), ``particle`` (an opaque ellipse drifting across the blunt end, its centre
  ahead of the tip), ``shadow`` (a soft-edged shadow over the tip: the tip stays visible, its
  contrast lower);
* **motion**: the tip wanders (steps and jumps), the needle turns a few degrees, and it slides
  along its own axis.

Each frame comes with its truth (:class:`SceneFrame`): the tip (the silhouette's extreme end
point, px, x right, y down, the centre of the top-left pixel at (0, 0)), whether it is
``"occluded"`` (an occluder of transmission 0.6 or less lies over the tip's point; a shadow
leaves the tip visible) or ``"visible"``, and the cause.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, signal

__all__ = ["SceneFrame", "SceneSequence", "scene_sequence", "scene_benchmark", "CAUSES"]

FloatArray = NDArray[np.float64]

CAUSES = ("fibre", "droplet", "particle", "shadow")

SUB = 3
"""Sub-pixels a side for the area coverage."""

EDGE_IN = 20.0
"""A tip stays at least this far inside the field, px."""


@dataclass(frozen=True)
class SceneFrame:
    """One frame and its truth: the image (grey, 0..1), the tip (px), ``"visible"`` or ``"occluded"``,
    what lies over the tip (``""``, or one of :data:`CAUSES`)."""

    image: FloatArray
    tip: tuple[float, float]
    kind: str
    cause: str = ""


@dataclass(frozen=True)
class SceneSequence:
    """The frames of one needle: its width 4 px behind its end (px), its shape, its optics."""

    frames: list[SceneFrame]
    width_px: float
    shape: str
    psf: str


def _grid(size: int) -> tuple[FloatArray, FloatArray]:
    """Sub-pixel centres (x, y) of a ``size`` x ``size`` field, shape ``(size * SUB, size * SUB)``."""
    c = (np.arange(size * SUB) + 0.5) / SUB - 0.5
    return np.meshgrid(c, c)


def _down(a: FloatArray) -> FloatArray:
    """Area mean over each pixel's sub-pixels."""
    n = a.shape[0] // SUB
    return np.asarray(a.reshape(n, SUB, n, SUB).mean(axis=(1, 3)), dtype=float)


def _needle(gx: FloatArray, gy: FloatArray, tip: tuple[float, float], angle: float, shape: str,
            a: float, p: float, corner: float) -> NDArray[np.bool_]:
    """The needle's silhouette: ``s`` px behind its end (along ``angle``, the direction from the tip up the
    shaft) its half-width is ``a s^p`` (``power``) or ``a + s tan(p)`` with corners rounded by ``corner``
    (``truncated``)."""
    ux, uy = math.cos(angle), math.sin(angle)
    dx, dy = gx - tip[0], gy - tip[1]
    s = dx * ux + dy * uy
    t = np.abs(-dx * uy + dy * ux)
    if shape == "power":
        return (s >= 0) & (t <= a * np.maximum(s, 0.0) ** p)
    half = a + np.maximum(s, 0.0) * math.tan(p)
    inside = (s >= 0) & (t <= half)
    # rounded corners: within `corner` of the end, outside the corner's circle is cut
    cut = (s < corner) & (t > a - corner) & ((s - corner) ** 2 + (t - (a - corner)) ** 2 > corner**2)
    return inside & ~cut


def _psf(kind: str, size: float, rng: np.random.Generator) -> FloatArray:
    """A Moffat profile (width ``size`` px, heavy tails) or a defocus ring (radius ``size`` px)."""
    r = int(math.ceil(4 * size)) + 2
    y, x = np.mgrid[-r : r + 1, -r : r + 1].astype(float)
    rr = np.hypot(x, y)
    if kind == "moffat":
        beta = rng.uniform(2.0, 4.0)
        k = (1.0 + (rr / max(size, 0.3)) ** 2) ** (-beta)
    else:
        k = np.exp(-0.5 * ((rr - size) / 0.6) ** 2) + 0.5 * np.exp(-0.5 * (rr / 0.7) ** 2)
    return np.asarray(k / k.sum(), dtype=float)


def _background(size: int, rng: np.random.Generator) -> FloatArray:
    """Light through the empty field: a tilted plane, a vignette and a smooth texture, about 0.7."""
    y, x = np.mgrid[0:size, 0:size].astype(float) / size
    tilt = 1.0 + rng.uniform(-0.15, 0.15) * (x - 0.5) + rng.uniform(-0.15, 0.15) * (y - 0.5)
    cx, cy = rng.uniform(0.3, 0.7, 2)
    vignette = 1.0 - rng.uniform(0.05, 0.25) * ((x - cx) ** 2 + (y - cy) ** 2)
    texture = ndimage.gaussian_filter(rng.normal(0.0, 1.0, (size, size)), rng.uniform(3.0, 9.0))
    texture /= max(float(np.std(texture)), 1e-9)
    return np.asarray(0.7 * tilt * vignette * (1.0 + rng.uniform(0.01, 0.05) * texture), dtype=float)


@dataclass
class _Occluder:
    cause: str
    frames_left: int
    centre: tuple[float, float]
    drift: tuple[float, float]
    size: float
    angle: float
    trans: float
    aspect: float


def _occluder(gx: FloatArray, gy: FloatArray, o: _Occluder) -> tuple[FloatArray, FloatArray]:
    """The occluder's transmission (multiplies the light) and an added glow (a droplet's rim), at sub-pixels."""
    dx, dy = gx - o.centre[0], gy - o.centre[1]
    ca, sa = math.cos(o.angle), math.sin(o.angle)
    along, across = dx * ca + dy * sa, -dx * sa + dy * ca
    ones = np.ones_like(gx)
    if o.cause == "fibre":
        return np.where(np.abs(across) <= 0.5 * o.size, o.trans, 1.0), 0.0 * ones
    if o.cause == "particle":
        inside = (along / o.size) ** 2 + (across / (o.size * o.aspect)) ** 2 <= 1.0
        return np.where(inside, o.trans, 1.0), 0.0 * ones
    r = np.hypot(dx, dy)
    if o.cause == "droplet":
        trans = np.where(r <= o.size, 0.9, 1.0) - 0.6 * np.exp(-0.5 * ((r - 0.8 * o.size) / 1.2) ** 2) * (r <= o.size)
        glow = 0.35 * np.exp(-0.5 * ((r - o.size - 1.0) / 1.0) ** 2)
        return trans, glow
    # shadow: a soft half-plane edge across a large disc
    edge = 1.0 / (1.0 + np.exp(-(o.size - r) / 3.0))
    return 1.0 - (1.0 - o.trans) * edge, 0.0 * ones


def _start_occluder(tip: tuple[float, float], angle: float, width: float, rng: np.random.Generator) -> _Occluder:
    cause = str(rng.choice(CAUSES, p=[0.3, 0.2, 0.35, 0.15]))
    ux, uy = math.cos(angle), math.sin(angle)  # up the shaft
    n = int(rng.integers(1, 4))
    if cause == "fibre":
        off = rng.uniform(-0.3, 0.3) * width
        return _Occluder(cause, n, (tip[0] - off * ux, tip[1] - off * uy), (0.0, 0.0), rng.uniform(0.3, 1.2) * width,
                         angle + math.pi / 2 + rng.uniform(-1.0, 1.0), rng.uniform(0.05, 0.5), 1.0)
    if cause == "particle":
        size = rng.uniform(0.35, 0.9) * width
        ahead = rng.uniform(0.0, 0.7) * size
        side = rng.uniform(-0.4, 0.4) * size
        c = (tip[0] - ahead * ux - side * uy, tip[1] - ahead * uy + side * ux)
        d = rng.normal(0.0, 1.2, 2)
        return _Occluder(cause, n, c, (float(d[0]), float(d[1])), size, rng.uniform(0, math.pi), rng.uniform(0.0, 0.15),
                         rng.uniform(0.6, 1.0))
    if cause == "droplet":
        size = rng.uniform(0.6, 1.4) * width
        off = rng.uniform(-0.4, 0.4) * size
        return _Occluder(cause, n, (tip[0] - off * ux, tip[1] - off * uy), (0.0, 0.0), size, 0.0, 0.9, 1.0)
    return _Occluder(cause, n, (tip[0] + rng.uniform(-10, 10), tip[1] + rng.uniform(-10, 10)), (0.0, 0.0),
                     rng.uniform(25.0, 45.0), 0.0, rng.uniform(0.35, 0.6), 1.0)


def _noisy(light: FloatArray, rng: np.random.Generator, read: float, speckle: float) -> FloatArray:
    """Speckle (gamma, mean 1) times the light, read noise, a few hot pixels; clipped to 0..1."""
    k = 1.0 / speckle**2
    img = light * rng.gamma(k, 1.0 / k, light.shape) + rng.normal(0.0, read, light.shape)
    hot = rng.random(light.shape) < 2e-4
    img[hot] = 1.0
    return np.clip(img, 0.0, 1.0)


def _shape(rng: np.random.Generator, width: float) -> tuple[str, float, float, float]:
    """A silhouette (its name, ``a``, ``p``, corner) ``width`` px wide 4 px behind its end."""
    if rng.random() < 0.6:
        p = rng.uniform(0.35, 0.8)
        return "power", 0.5 * width / 4.0**p, p, 0.0
    half = 0.5 * width - 4.0 * math.tan(0.25)
    half = max(half, 2.0)
    return "truncated", half, rng.uniform(0.12, 0.4), rng.uniform(0.3, 0.9) * half


def scene_sequence(seed: int, n: int = 30, size: int = 256, width_px: float | None = None,
                   occlusion_rate: float = 0.15) -> SceneSequence:
    """``n`` frames of one needle with occluders over its tip now and then (``occlusion_rate``: the chance a
    frame starts one), and the truth."""
    rng = np.random.default_rng(seed)
    width = float(width_px if width_px is not None else rng.uniform(6.0, 22.0))
    shape, a, p, corner = _shape(rng, width)
    psf_kind = "moffat" if rng.random() < 0.6 else "ring"
    psf = _psf(psf_kind, rng.uniform(0.6, 1.6) if psf_kind == "moffat" else rng.uniform(1.0, 2.0), rng)
    light0 = _background(size, rng)
    trans = rng.uniform(0.02, 0.25)
    read, speckle = rng.uniform(0.005, 0.03), rng.uniform(0.01, 0.06)
    angle = rng.uniform(0, 2 * math.pi)
    lo, hi = EDGE_IN + 10, size - 1 - EDGE_IN - 10
    tip = (float(rng.uniform(lo, hi)), float(rng.uniform(lo, hi)))
    gx, gy = _grid(size)
    frames: list[SceneFrame] = []
    occ: _Occluder | None = None
    for k in range(n):
        if k > 0:
            step = rng.normal(0.0, 2.5, 2) + (rng.normal(0.0, 10.0, 2) if rng.random() < 0.08 else 0.0)
            slide = rng.normal(0.0, 1.5)
            tip = (float(np.clip(tip[0] + step[0] - slide * math.cos(angle), EDGE_IN, size - 1 - EDGE_IN)),
                   float(np.clip(tip[1] + step[1] - slide * math.sin(angle), EDGE_IN, size - 1 - EDGE_IN)))
            angle += float(rng.normal(0.0, 0.01))
            if occ is None and k > 1 and rng.random() < occlusion_rate:
                occ = _start_occluder(tip, angle, width, rng)
        mask = _needle(gx, gy, tip, angle, shape, a, p, corner)
        t_sub = np.where(mask, trans, 1.0)
        glow = np.zeros_like(t_sub)
        kind, cause = "visible", ""
        if occ is not None:
            t_occ, glow = _occluder(gx, gy, occ)
            t_sub = t_sub * t_occ
            # over the tip: the occluder's transmission at the tip's point
            o_tip = _occluder(np.array([[tip[0]]]), np.array([[tip[1]]]), occ)[0][0, 0]
            cause = occ.cause
            kind = "occluded" if o_tip <= 0.6 and occ.cause != "shadow" else "visible"
            occ.frames_left -= 1
            occ.centre = (occ.centre[0] + occ.drift[0], occ.centre[1] + occ.drift[1])
            if occ.frames_left <= 0:
                occ = None
        light = light0 * _down(t_sub) + 0.7 * _down(glow)
        light = signal.fftconvolve(np.pad(light, psf.shape[0], mode="edge"), psf, mode="same")
        light = light[psf.shape[0] : -psf.shape[0], psf.shape[0] : -psf.shape[0]]
        frames.append(SceneFrame(_noisy(light, rng, read, speckle), tip, kind, cause))
    return SceneSequence(frames, width, shape, psf_kind)


def scene_benchmark(n_frames: int = 300, per_sequence: int = 30, seed: int = 0, size: int = 256,
                    widths: tuple[float, float] = (6.0, 22.0)) -> list[SceneSequence]:
    """Sequences of ``per_sequence`` frames, ``n_frames`` in all, tips ``widths`` px wide (4 px behind the end);
    the first frame of each is never occluded."""
    rng = np.random.default_rng(10_000 + seed)
    out = []
    for i in range(max(1, n_frames // per_sequence)):
        w = float(rng.uniform(*widths))
        out.append(scene_sequence(1000 * seed + i, per_sequence, size, w))
    return out
