"""The camera panel's seam: a frame to show and the tip's pixel position, from any camera.

The page shows the camera when the server has a :class:`CameraFeed`: an encoded frame
(PNG here) and, when a tracker follows the tip, the tip's pixel position. Pixel
convention (as :mod:`stickslip.vision` writes it): ``x`` to the right, ``y`` down, the
centre of the top-left pixel at ``(0, 0)``. The planned path is drawn over the frame
where the feed can project rig coordinates (m) into pixels (a camera calibrated against
the arm); otherwise the page draws the path in its own plot only.

:class:`FrameFeed` makes a feed of any camera with ``grab()`` returning a frame with a
2-D grey ``image`` (values in [0, 1]): :class:`stickslip.vision.Camera` is one.
"""

from __future__ import annotations

import struct
import threading
import zlib
from collections.abc import Callable, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

__all__ = ["CameraFeed", "FrameFeed", "TipPixel", "png_grey"]

TipPixel = tuple[float, float, float | None]
"""``(x, y, sd)``: the tip's pixel position and its standard deviation, px (``sd`` None if unknown)."""


@runtime_checkable
class CameraFeed(Protocol):
    """What the camera panel needs: the newest frame, encoded, and where the tip is in it."""

    def frame(self) -> tuple[bytes, str, tuple[int, int]]:
        """The newest frame: encoded bytes, their media type (``image/png``), ``(width, height)`` px."""
        ...

    def tip(self) -> TipPixel | None:
        """The tracked tip in the newest frame, px (``None``: not tracked, or lost)."""
        ...

    def to_pixels(self, points_m: Sequence[Sequence[float]]) -> list[tuple[float, float]] | None:
        """Rig coordinates (m, base frame) to pixels, or ``None`` when the camera is not calibrated to the arm."""
        ...

    def close(self) -> None:
        """Release the camera."""
        ...


def png_grey(image: NDArray[np.floating[Any]] | NDArray[np.integer[Any]]) -> bytes:
    """An 8-bit grey PNG of ``image`` (2-D; floats in [0, 1] scaled to 0-255 and clipped, integers taken as 0-255).

    A minimal encoder (signature, IHDR, one zlib IDAT, IEND; filter 0 on every row), so that
    the server needs no imaging library. ``ValueError`` for anything but a non-empty 2-D array.
    """
    a = np.asarray(image)
    if a.ndim != 2 or a.size == 0:
        raise ValueError(f"a grey frame is a non-empty 2-D array, got shape {a.shape}")
    if np.issubdtype(a.dtype, np.floating):
        b = np.clip(np.nan_to_num(a, nan=0.0) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    else:
        b = np.clip(a, 0, 255).astype(np.uint8)
    h, w = b.shape
    raw = b"".join(b"\x00" + b[r].tobytes() for r in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)  # 8-bit, grey, deflate, filter 0, no interlace
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


class FrameFeed:
    """A :class:`CameraFeed` of any camera whose ``grab()`` returns a frame with a 2-D grey ``image``.

    Parameters
    ----------
    camera : object
        Has ``grab()`` (a frame with ``.image``, values in [0, 1]) and ``close()``.
    tip_of : callable, optional
        The tip in a frame, ``(x, y, sd)`` px, or ``None`` (a tracker).
    project : callable, optional
        Rig coordinates (m) to pixels (a camera calibrated against the arm).
    """

    def __init__(
        self,
        camera: Any,
        tip_of: Callable[[Any], TipPixel | None] | None = None,
        project: Callable[[Sequence[Sequence[float]]], list[tuple[float, float]]] | None = None,
    ):
        self.camera = camera
        self._tip_of = tip_of
        self._project = project
        self._lock = threading.Lock()
        self._tip: TipPixel | None = None

    def frame(self) -> tuple[bytes, str, tuple[int, int]]:
        """Grab a frame, track the tip in it, and encode it as PNG.

        A camera that fails (lost, or a recording used up) raises its error and forgets the
        tip it tracked: :meth:`tip` then says ``None``, not where the tip was.
        """
        with self._lock:
            try:
                f = self.camera.grab()
            except BaseException:
                self._tip = None
                raise
            image = np.asarray(f.image)
            self._tip = self._tip_of(f) if self._tip_of is not None else None
        return png_grey(image), "image/png", (int(image.shape[1]), int(image.shape[0]))

    def tip(self) -> TipPixel | None:
        """The tip tracked in the last frame grabbed."""
        with self._lock:
            return self._tip

    def to_pixels(self, points_m: Sequence[Sequence[float]]) -> list[tuple[float, float]] | None:
        """Rig coordinates to pixels, when a projection was given."""
        return None if self._project is None else self._project(points_m)

    def close(self) -> None:
        """Close the camera."""
        self.camera.close()
