"""A camera frame and the one conversion of pixel data into it (the edge of the vision layer).

Pixel convention, everywhere in :mod:`stickslip.vision`: ``x`` to the right (the
column), ``y`` down (the row), the centre of the top-left pixel at ``(0, 0)``; so pixel
``image[row, col]`` has its centre at ``(x, y) = (col, row)`` and the image covers
``-0.5 <= x < width - 0.5``. Sizes are in metres per pixel.

Pixel data of any source (8- or 16-bit integers, floats, grey or colour) is converted
once, by :func:`as_image`, into a 2-D ``float64`` array: integers scaled to [0, 1] by
their type's largest value, colour to luminance (Rec. 709 weights), floats kept as they
are. What cannot be one grey image (a stack of images, NaN or infinity, an empty or
absurdly large array) is refused with :class:`ImageError` naming the source and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Frame",
    "ImageError",
    "as_image",
    "MIN_SIDE",
    "MAX_PIXELS",
    "PIXEL_SIZE_RANGE",
    "LUMINANCE",
]

MIN_SIDE = 16
"""Smallest width or height of a frame, pixels: a tip needs room around it."""

MAX_PIXELS = 64 * 1024 * 1024
"""Largest frame, pixels (64 Mpx, 512 MiB as float64): anything bigger is refused before it is decoded."""

MAX_VALUE = 1e100
"""Largest pixel value, in magnitude (grey units): the tracker sums squares of pixels over a window, which
overflows float64 near 1e154; no camera's count, nor any physical unit a float image is written in, is near it."""

PIXEL_SIZE_RANGE = (1e-12, 1e-2)
"""Smallest and largest pixel size in the object plane, m: 1 pm to 1 cm (a microscope's pixel is nanometres to
micrometres; a ``pixel=1e-300um`` would make a px per m of 1e306 that the closed loop divides by)."""

LUMINANCE = (0.2126, 0.7152, 0.0722)
"""Weights of red, green and blue in the grey value of a colour frame (Rec. 709)."""


class ImageError(ValueError):
    """Pixel data that cannot be one grey frame (the message names the source and the reason)."""


@dataclass(frozen=True, eq=False)
class Frame:
    """One image from a camera.

    Attributes
    ----------
    image : ndarray of float64, shape (height, width)
        Grey values, finite (integers scaled to [0, 1]; see :func:`as_image`).
    time_s : float
        When it was taken, s (the camera's clock: a file sequence counts frames at its
        ``fps``, a video uses its time stamps, the simulated camera the arm's virtual clock).
    pixel_size_m : float or None
        Size of a pixel in the object plane, m; ``None`` when the camera does not know it.
    source : str
        Where it came from (a file name, or a camera URL without secrets), for messages.
    """

    image: NDArray[np.float64]
    time_s: float = 0.0
    pixel_size_m: float | None = None
    source: str = ""

    def __post_init__(self) -> None:
        img = self.image
        if not isinstance(img, np.ndarray) or img.ndim != 2 or img.dtype != np.float64:
            raise ImageError(f"{self.source or 'frame'}: a frame is a 2-D float64 array (use as_image)")
        if not math.isfinite(self.time_s):
            raise ImageError(f"{self.source or 'frame'}: time {self.time_s!r} s is not finite")
        lo, hi = PIXEL_SIZE_RANGE
        if self.pixel_size_m is not None and not (math.isfinite(self.pixel_size_m) and lo <= self.pixel_size_m < hi):
            raise ImageError(
                f"{self.source or 'frame'}: pixel size {self.pixel_size_m!r} m must be in [1 pm, 1 cm) "
                "(a microscope's pixel is nanometres to micrometres)"
            )

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``, pixels."""
        h, w = self.image.shape
        return int(h), int(w)


def as_image(data: object, source: str = "image") -> NDArray[np.float64]:
    """One grey ``float64`` image of any pixel array; :class:`ImageError` when there is no such image.

    Parameters
    ----------
    data : array_like
        ``(h, w)`` grey, ``(h, w, 1)``, ``(h, w, 2)`` (grey and alpha: the alpha is
        dropped), ``(h, w, 3)`` or ``(h, w, 4)`` colour (RGB, RGBA: luminance with
        :data:`LUMINANCE`). Unsigned and signed integers are divided by their type's
        largest value, booleans become 0 and 1, floats are kept.
    source : str
        Names the data in messages (a file name).

    Raises
    ------
    ImageError
        For another shape (a stack of images: ``(n, h, w)``), a side under
        :data:`MIN_SIDE` or more than :data:`MAX_PIXELS` pixels, a non-numeric type, or
        a pixel that is NaN or infinite, or beyond :data:`MAX_VALUE` in magnitude (its
        position is named, ``x, y``).
    """
    a = np.asarray(data)
    if a.dtype == bool:  # 0 and 1 (a 1-bit TIFF), not 1/255 as a uint8 would scale it
        a = a.astype(np.float64)
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise ImageError(f"{source}: pixels of type {a.dtype} are not grey or colour values")
    if a.ndim == 3 and a.shape[2] in (1, 2, 3, 4):
        channels = a.shape[2]
    elif a.ndim == 2:
        channels = 0
    elif a.ndim == 3:
        raise ImageError(
            f"{source}: a stack of {a.shape[0]} images of {a.shape[2]} x {a.shape[1]} pixels "
            "(3-D data): give one image per file"
        )
    else:
        raise ImageError(f"{source}: {a.ndim}-D pixel data of shape {a.shape}: a frame is one 2-D image")
    h, w = int(a.shape[0]), int(a.shape[1])
    if min(h, w) < MIN_SIDE:
        raise ImageError(f"{source}: {w} x {h} pixels is smaller than {MIN_SIDE} x {MIN_SIDE}")
    if h * w > MAX_PIXELS:
        raise ImageError(f"{source}: {w} x {h} pixels is more than the {MAX_PIXELS // 2**20} Mpx a frame may have")
    if np.issubdtype(a.dtype, np.integer):
        scale = 1.0 / float(np.iinfo(a.dtype).max)
        f = a.astype(np.float64) * scale
    else:
        f = a.astype(np.float64, copy=True)
    if channels in (1, 2):
        f = f[:, :, 0]
    elif channels in (3, 4):
        f = f[:, :, 0] * LUMINANCE[0] + f[:, :, 1] * LUMINANCE[1] + f[:, :, 2] * LUMINANCE[2]
    peak = float(np.max(np.abs(f)))  # NaN when any pixel is NaN
    if not math.isfinite(peak):
        bad = np.argwhere(~np.isfinite(f))
        y, x = (int(v) for v in bad[0])
        what = "NaN" if math.isnan(float(f[y, x])) else "infinite"
        raise ImageError(f"{source}: {len(bad)} pixel(s) are NaN or infinite (the first, at x={x}, y={y}, is {what})")
    if peak > MAX_VALUE:
        y, x = (int(v) for v in np.unravel_index(int(np.argmax(np.abs(f))), f.shape))
        raise ImageError(f"{source}: a pixel of {float(f[y, x]):.8g} (at x={x}, y={y}) is beyond the ±{MAX_VALUE:g} "
                         "a frame's values may have (no camera records it; the tracker's sums would overflow)")
    return np.ascontiguousarray(f, dtype=np.float64)
