"""The template made again from the first frame and the next few fitted ones: its own noise averaged down.

The tracker's template is the first frame's window, with that frame's noise in it. The fit
reads a noisy template as sharper than the frames (its Laplacian, the blur term's column,
correlates with the template's own noise), and a round end's fix then lands ahead of the tip:
on the own renderer with nothing but shot noise the blur term reads 1.5 to 3.9 px² of blur the
frames do not have, and sequences' fixes lie up to 1.4 px ahead of the tip, while the same
frames against the noise-free template lie within 0.1 px of it on average (docs/vision-log.md,
"Where the position error comes from").

:class:`TemplateAverage` keeps the first frame's window and, for each of the next
:attr:`~.template.TrackerParams.average_frames` fixes fitted with the sharp copy (a tip in about
the first frame's focus), the frame's pixels at the template's, turned back by the fit's turn
and brought to the first frame's brightness and contrast over the template's weights; their
mean is the new template's window. The frames were placed by fits against the noisy template,
so the mean carries those fits' offset: :func:`anchor` fits the averaged template to the first
frame, where the tip is known, and the template's apex moves by what that fit says.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from .refine import Steepest, refine
from .sampling import Patch
from .template import TipTemplate, _window

__all__ = ["TemplateAverage", "anchor"]

FloatArray = NDArray[np.float64]


class TemplateAverage:
    """The windows the new template is averaged from (see the module docstring).

    Parameters
    ----------
    image : ndarray
        The first frame.
    tip : tuple of float
        The tip in it, px.
    template : TipTemplate
        What was learnt from it (its window's size, apex and weights).
    frames : int
        How many fitted frames are averaged with the first, 1.
    """

    def __init__(self, image: FloatArray, tip: tuple[float, float], template: TipTemplate, frames: int) -> None:
        h = template.half
        win, inside = _window(image, int(round(tip[0])), int(round(tip[1])), h)
        self.first = image
        self.tip = (float(tip[0]), float(tip[1]))
        self.frames = frames
        self._win0: FloatArray | None = win if inside.all() else None  # near the edge: not averaged
        self._weights = np.sqrt(template.weights.ravel())
        n = 2 * h + 1
        yy, xx = np.mgrid[0:n, 0:n].astype(float)
        self._r = (xx - template.apex[0], yy - template.apex[1])
        self._sum = np.zeros((n, n))
        self.count = 0

    @property
    def open(self) -> bool:
        """Whether frames are still taken."""
        return self._win0 is not None and self.count < self.frames

    def add(self, image: FloatArray, x: float, y: float, theta: float) -> FloatArray | None:
        """Take ``image``'s pixels at the template's, the tip at ``(x, y)`` (px) turned by ``theta`` (rad); the
        averaged window once the last frame is in, else ``None``. A window reaching past the frame is not taken."""
        if self._win0 is None or self.count >= self.frames:
            return None
        c, s = math.cos(theta), math.sin(theta)
        rx, ry = self._r
        xs, ys = c * rx - s * ry + x, s * rx + c * ry + y
        if not (xs.min() >= 0 and ys.min() >= 0 and xs.max() <= image.shape[1] - 1 and ys.max() <= image.shape[0] - 1):
            return None
        back = ndimage.map_coordinates(image, [ys, xs], order=1)
        # the first frame's brightness and contrast, over the template's weights
        design = np.stack([back.ravel(), np.ones(back.size)], axis=1) * self._weights[:, None]
        (gain, offset), *_ = np.linalg.lstsq(design, self._win0.ravel() * self._weights, rcond=None)
        if not (math.isfinite(gain) and gain > 0):
            return None
        self._sum += gain * back + offset
        self.count += 1
        if self.count < self.frames:
            return None
        return np.asarray((self._win0 + self._sum) / (self.count + 1), dtype=float)


def anchor(first: Patch, steep: Steepest, tip: tuple[float, float], correlation: float, limit: float
           ) -> tuple[float, float] | None:
    """How far the template's apex must move (window px, x and y) for the template ``steep`` (the averaged sharp
    copy) to put the first frame's tip where it is: ``steep`` fitted to the first frame's patch ``first`` from the
    tip ``tip`` (px). ``None`` when the fit does not settle or says more than ``limit`` px."""
    ref = refine(first, steep, tip, 0.0, correlation=correlation)
    dx, dy = tip[0] - ref.x, tip[1] - ref.y
    if not (ref.converged and math.hypot(dx, dy) <= limit):
        return None
    c, s = math.cos(ref.theta), math.sin(ref.theta)
    return c * dx + s * dy, -s * dx + c * dy
