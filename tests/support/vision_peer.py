"""A second, independent microscope renderer: the images the tip tracker was NOT designed on.

Written before the tracker was tuned, from another view of the imaging than the
simulated microscope (:mod:`stickslip.sim.camera`), and never tuned to afterwards:

* **the needle** is a hyperboloid of revolution (a field-emission tip: a paraboloid of
  apex radius ``W / 2`` blending into a cone of half-angle ``alpha``), not a cone with a
  rounded cap; its *tip* is the needle's extreme end point. It is drawn at twice the
  resolution and averaged 2 × 2 (area coverage), not by a clipped distance;
* **defocus** is a pillbox (the geometric image of a defocused aperture, radius
  ``2 sigma`` for the same second moment), not a Gaussian;
* **SEM contrast**: secondary-electron yield ``1 / cos(t)^0.8`` of the surface tilt ``t``
  (the edges brighter), times a side detector that sees surfaces facing it better
  (``1 + 0.35 n_x'``): one edge brighter than the other; a granular (Voronoi cell)
  substrate. **Bright field**: a dark needle whose edge rings with a bright Fresnel
  fringe, over fibres, spots or a real micrograph;
* **noise**: Poisson counts at ``photons`` per pixel at full brightness, Gaussian read
  noise, per-column gain (fixed pattern), quantised to 12 bits in a 16-bit integer image;
* **real micrographs** as backgrounds where scikit-image is installed (its shipped
  ``cell.png``, a cell in phase contrast, and ``ihc.png``, a stained tissue section);
* **motion**: the tip wanders (a random walk with jumps), the needle turns by a few
  degrees about a pivot far up its shaft, and the whole image drifts slowly; some frames
  put the tip out of the field, under an opaque particle (occluded) or far out of focus.

Each frame comes with its truth (:class:`PeerFrame`): the tip's pixel (x right, y down,
the centre of the top-left pixel at (0, 0)) and what the frame is: ``"visible"``,
``"out"`` (the tip beyond the field's edge), ``"occluded"`` or ``"defocused"``.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, signal

__all__ = ["PeerFrame", "PeerSequence", "peer_sequence", "peer_benchmark", "real_micrographs", "KINDS"]

KINDS = ("visible", "out", "occluded", "defocused")

FAR_DEFOCUS = 7.0
"""Blur (sigma, pixels) at and beyond which a frame counts as far out of focus."""

EDGE_IN = 8.0
"""A visible tip stays at least this far inside the field (pixels)."""

EDGE_OUT = 12.0
"""A tip out of the field is at least this far beyond its edge (pixels)."""


@dataclass(frozen=True)
class PeerFrame:
    """One rendered frame and its truth.

    Attributes
    ----------
    image : ndarray of uint16, shape (h, w)
        12-bit data in a 16-bit image.
    tip : tuple of float
        The tip's extreme end, pixels ``(x, y)``.
    kind : str
        ``"visible"``, ``"out"``, ``"occluded"`` or ``"defocused"``.
    blur : float
        The needle's defocus blur, sigma in pixels (pillbox radius ``2 blur``).
    """

    image: NDArray[np.uint16]
    tip: tuple[float, float]
    kind: str
    blur: float


@dataclass(frozen=True)
class PeerSequence:
    """A sequence of frames of one needle, look and background."""

    frames: list[PeerFrame]
    width_px: float
    look: str
    background: str
    photons: float


def real_micrographs() -> list[NDArray[np.float64]]:
    """scikit-image's shipped micrographs (``cell.png``, ``ihc.png``) as grey float images; empty without it."""
    spec = importlib.util.find_spec("skimage")
    if spec is None or not spec.submodule_search_locations:
        return []
    from PIL import Image

    folder = Path(list(spec.submodule_search_locations)[0]) / "data"
    out = []
    for name in ("cell.png", "ihc.png"):
        p = folder / name
        if p.exists():
            with Image.open(p) as im:
                out.append(np.asarray(im.convert("L"), dtype=float) / 255.0)
    return out


# ---------------------------------------------------------------------------- backgrounds


def _voronoi(h: int, w: int, rng: np.random.Generator) -> NDArray[np.float64]:
    n = int(h * w / 900)
    pts = rng.uniform(0, 1, (n, 2)) * (h, w)
    levels = rng.uniform(-1, 1, n)
    yy, xx = np.mgrid[0:h, 0:w]
    from scipy.spatial import cKDTree

    _, idx = cKDTree(pts).query(np.stack([yy.ravel(), xx.ravel()], 1))
    cells = levels[idx].reshape(h, w)
    boundaries = ndimage.gaussian_gradient_magnitude(cells, 0.7)
    return np.asarray(cells * 0.5 - np.clip(boundaries, 0, 1) * 0.8, dtype=float)


def _fibres(h: int, w: int, rng: np.random.Generator) -> NDArray[np.float64]:
    img = np.zeros((h, w))
    yy, xx = np.mgrid[0:h, 0:w]
    for _ in range(rng.integers(6, 16)):
        a = rng.uniform(0, math.pi)
        c = rng.uniform(0, 1, 2) * (w, h)
        d = np.abs(-(xx - c[0]) * math.sin(a) + (yy - c[1]) * math.cos(a))
        width = rng.uniform(0.8, 4.0)
        img -= rng.uniform(0.3, 1.0) * np.exp(-0.5 * (d / width) ** 2)
    return img


def _spots(h: int, w: int, rng: np.random.Generator) -> NDArray[np.float64]:
    img = np.zeros((h, w))
    n = rng.integers(20, 120)
    ys, xs = rng.integers(0, h, n), rng.integers(0, w, n)
    img[ys, xs] = rng.uniform(-40, 40, n)
    img = ndimage.gaussian_filter(img, rng.uniform(1.0, 3.0))
    yy, xx = np.mgrid[0:h, 0:w]
    gx, gy = rng.uniform(-1, 1, 2)
    return np.asarray(np.clip(img, -1.5, 1.5) + 0.6 * (gx * xx / w + gy * yy / h), dtype=float)


def _background(
    kind: str, h: int, w: int, rng: np.random.Generator, real: list[NDArray[np.float64]]
) -> NDArray[np.float64]:
    """A background texture, zero mean, about unit contrast, ``(h, w)``."""
    if kind == "grains":
        img = _voronoi(h, w, rng)
    elif kind == "fibres":
        img = _fibres(h, w, rng)
    elif kind == "spots":
        img = _spots(h, w, rng)
    else:
        src = real[int(kind[-1])]
        big = np.pad(src, ((0, h), (0, w)), mode="symmetric")  # mirrored: no seam where the copies meet
        y0, x0 = rng.integers(0, src.shape[0]), rng.integers(0, src.shape[1])
        img = big[y0 : y0 + h, x0 : x0 + w] - float(np.mean(src))
        img = img / (np.std(src) * 2.0 + 1e-9)
    return img - float(np.mean(img))


# ---------------------------------------------------------------------------- the needle


def _needle_layers(
    h: int, w: int, tip: tuple[float, float], phi: float, W: float, alpha: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Coverage (0..1), the surface tilt's cosine and the across-axis normal sign, at pixel resolution.

    The needle's axis points from the tip back along the shaft at angle ``phi`` (rad,
    from image x towards image y). Rendered at 2× and averaged 2 × 2.
    """
    s = 2
    ys = (np.arange(h * s) + 0.5) / s - 0.5
    xs = (np.arange(w * s) + 0.5) / s - 0.5
    XX, YY = np.meshgrid(xs, ys)
    dx, dy = XX - tip[0], YY - tip[1]
    c, sn = math.cos(phi), math.sin(phi)
    along = dx * c + dy * sn
    across = -dx * sn + dy * c
    R = W / 2.0
    L = np.clip(along, 0.0, None)
    radius = np.sqrt(2.0 * R * L + (L * math.tan(alpha)) ** 2)
    inside = (along >= 0) & (np.abs(across) <= radius)
    rel = np.where(inside, np.abs(across) / np.maximum(radius, 1e-9), 0.0)
    cos_t = np.sqrt(np.clip(1.0 - rel**2, 0.0, 1.0))
    side = np.where(inside, np.sign(across) * rel, 0.0)  # -1 .. 1 across the needle

    def down(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(a.reshape(h, s, w, s).mean(axis=(1, 3)), dtype=float)

    return down(inside.astype(float)), down(np.where(inside, cos_t, 0.0)), down(side)


def _pillbox(sigma: float) -> NDArray[np.float64] | None:
    r = 2.0 * sigma
    if r < 0.5:
        return None
    n = int(math.ceil(r)) + 1
    yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
    k = np.clip(r + 0.5 - np.hypot(xx, yy), 0.0, 1.0)
    return np.asarray(k / k.sum(), dtype=float)


def _blur(a: NDArray[np.float64], kernel: NDArray[np.float64] | None) -> NDArray[np.float64]:
    if kernel is None:
        return a
    return np.asarray(signal.fftconvolve(a, kernel, mode="same"), dtype=float)


def _render(
    h: int, w: int, look: str, bg: NDArray[np.float64], tip: tuple[float, float], phi: float, W: float,
    alpha: float, sigma: float, occluder: tuple[float, float, float] | None, photons: float,
    column_gain: NDArray[np.float64], rng: np.random.Generator,
) -> NDArray[np.uint16]:
    cover, cos_t, side = _needle_layers(h, w, tip, phi, W, alpha)
    kernel = _pillbox(sigma)
    if look == "brightfield":
        base = 0.7 + 0.12 * bg
        fringe = ndimage.gaussian_laplace(cover, 1.2)  # the bright Fresnel fringe at the edge
        trans = 1.0 - 0.75 * _blur(cover, kernel) + 0.6 * _blur(fringe, kernel)
        clean = base * trans
    else:
        base = 0.18 + 0.06 * bg
        c = np.clip(cos_t, 0.15, 1.0)
        sec = np.where(cover > 0, (0.35 / np.maximum(c, 0.15) ** 0.8) * (1.0 + 0.35 * side), 0.0)
        needle = _blur(sec * cover, kernel)
        clean = base * (1.0 - _blur(cover, kernel)) + needle
    if occluder is not None:
        ox, oy, r = occluder
        yy, xx = np.mgrid[0:h, 0:w]
        ang = np.arctan2(yy - oy, xx - ox)
        rr = r * (1.0 + 0.15 * np.sin(3 * ang + ox))
        blob = np.clip(rr + 0.5 - np.hypot(xx - ox, yy - oy), 0.0, 1.0)
        blob = ndimage.gaussian_filter(blob, 0.6)
        level = 0.05 if look == "brightfield" else 0.6
        clean = clean * (1.0 - blob) + level * blob
    yy, xx = np.mgrid[0:h, 0:w]
    illum = 1.0 - 0.2 * (((xx - w * 0.4) / w) ** 2 + ((yy - h * 0.55) / h) ** 2)
    lam = np.clip(clean * illum * column_gain[None, :], 0.0, None) * photons
    counts = rng.poisson(lam) + rng.normal(0.0, 2.0, (h, w))
    data = np.clip(np.round(counts / photons * 3000.0), 0, 4095)
    return np.asarray(data * 16, dtype=np.uint16)


# ---------------------------------------------------------------------------- sequences


def peer_sequence(seed: int, n: int = 50, h: int = 512, w: int = 512, width_px: float | None = None,
                  events: bool = True, max_blur: float = 3.0, min_photons: float = 40.0) -> PeerSequence:
    """``n`` frames of one needle wandering in the field, with its truth.

    ``width_px`` (default: drawn in 3..20) is the apex's diameter ``W``; with ``events``
    some frames put the tip out of the field, under a particle or far out of focus.
    Blur of the other frames is at most ``max_blur`` (sigma, px), noise down to
    ``min_photons`` per pixel at full brightness.
    """
    rng = np.random.default_rng([seed, 20261122])
    real = real_micrographs()
    kinds = ["grains", "fibres", "spots"] + [f"real{i}" for i in range(len(real))]
    look = ["brightfield", "sem"][int(rng.integers(0, 2))]
    background = kinds[int(rng.integers(0, len(kinds)))]
    if look == "sem" and background.startswith("real"):
        background = "grains"
    W = float(width_px if width_px is not None else rng.uniform(3.0, 20.0))
    alpha = math.radians(rng.uniform(4.0, 15.0))
    photons = float(math.exp(rng.uniform(math.log(min_photons), math.log(400.0))))
    margin = 40
    bg_big = _background(background, h + 2 * margin, w + 2 * margin, rng, real)
    column_gain = 1.0 + rng.normal(0.0, 0.01, w)
    drift = rng.normal(0.0, 0.04, 2)  # px per frame
    phi0 = rng.uniform(-math.pi, math.pi)
    pivot_dist = rng.uniform(300.0, 3000.0)
    tip = np.array([rng.uniform(0.25, 0.75) * w, rng.uniform(0.25, 0.75) * h])
    blur = rng.uniform(0.0, max_blur)
    frames: list[PeerFrame] = []
    event: tuple[str, int] | None = None
    offset = np.zeros(2)
    lo = np.array([EDGE_IN, EDGE_IN])
    hi = np.array([w - 1 - EDGE_IN, h - 1 - EDGE_IN])
    for k in range(n):
        # the needle's angle wobbles by a few degrees: it turns about a pivot far up its shaft
        turn = math.radians(3.0) * math.sin(0.13 * k + seed)
        phi = phi0 + turn
        pivot = tip + pivot_dist * np.array([math.cos(phi0), math.sin(phi0)])
        offset += drift
        if event is None and events and k > 2 and rng.random() < 0.08:
            event = (["out", "occluded", "defocused"][int(rng.integers(0, 3))], int(rng.integers(1, 5)))
        kind = "visible"
        occluder = None
        sigma = blur
        apex = tip.copy()
        if event is not None:
            kind, left = event
            if kind == "out":
                # the tip leaves the field across the edge nearest to it
                d = np.array([apex[0], w - 1 - apex[0], apex[1], h - 1 - apex[1]])
                side = int(np.argmin(d))
                beyond = EDGE_OUT + rng.uniform(0.0, 60.0)
                apex = apex.copy()
                if side == 0:
                    apex[0] = -beyond
                elif side == 1:
                    apex[0] = w - 1 + beyond
                elif side == 2:
                    apex[1] = -beyond
                else:
                    apex[1] = h - 1 + beyond
            elif kind == "occluded":
                r = rng.uniform(max(8.0, W), max(14.0, 1.5 * W))
                o = apex + rng.normal(0.0, 0.25 * r, 2)
                occluder = (float(o[0]), float(o[1]), float(r))
            else:
                sigma = rng.uniform(FAR_DEFOCUS, 12.0)
            event = None if left <= 1 else (kind, left - 1)
        # rigid turn about the pivot: the apex moves with it
        rot = turn - math.radians(3.0) * math.sin(0.13 * (k - 1) + seed) if k else 0.0
        rel = apex - pivot
        apex_r = pivot + np.array([rel[0] * math.cos(rot) - rel[1] * math.sin(rot),
                                   rel[0] * math.sin(rot) + rel[1] * math.cos(rot)])
        if kind == "visible" or kind != "out":
            apex_r = np.clip(apex_r, lo, hi)
        m = margin
        ox, oy = offset
        bg = ndimage.shift(bg_big, (oy, ox), order=1, mode="nearest")[m : m + h, m : m + w]
        image = _render(h, w, look, bg, (float(apex_r[0]), float(apex_r[1])), phi, W, alpha, sigma, occluder,
                        photons, column_gain, rng)
        frames.append(PeerFrame(image, (float(apex_r[0]), float(apex_r[1])), kind, float(sigma)))
        if kind != "out":
            tip = apex_r
        # the next position: a random walk with an occasional jump, kept inside the field
        step = rng.normal(0.0, 2.5, 2) if rng.random() > 0.1 else rng.normal(0.0, 15.0, 2)
        tip = np.clip(tip + step + drift, lo, hi)
        blur = float(np.clip(blur + rng.normal(0.0, 0.3), 0.0, max_blur))
    return PeerSequence(frames, W, look, background, photons)


def peer_benchmark(n_frames: int = 500, per_sequence: int = 50, seed: int = 0, size: int = 512) -> list[PeerSequence]:
    """The benchmark's frames: sequences of ``per_sequence`` frames, tip widths spread over 3..20 px."""
    n_seq = max(1, n_frames // per_sequence)
    widths = np.linspace(3.0, 20.0, n_seq)
    return [peer_sequence(seed * 1000 + i, per_sequence, size, size, float(widths[i])) for i in range(n_seq)]
