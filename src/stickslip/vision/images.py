"""Reading image files into frames: PNG, TIFF (8, 16 or 32 bit; grey or colour), and what Pillow reads.

The libraries are optional (the ``vision`` extra) and imported when a file is read:

* **TIFF** through tifffile (every sample type, floats with their NaN, stacks told apart
  from colour); a TIFF compressed with a codec tifffile needs ``imagecodecs`` for (LZW,
  JPEG) is read by Pillow instead, which has those codecs built in;
* **PNG** (and JPEG, BMP, ...) through Pillow, except a 16-bit colour PNG, which Pillow
  would silently cut to 8 bits: that one is read by OpenCV when it is installed, and
  refused with the reason otherwise.

Every file is checked before it is decoded: a regular file (a folder, pipe or device is
refused without being opened), at most :data:`MAX_FILE_BYTES`, at most
:data:`~.frame.MAX_PIXELS` pixels, one image (a multi-page TIFF or an animation is a
stack). Any failure is an :class:`~.frame.ImageError` naming the file and the reason.
"""

from __future__ import annotations

import os
import stat
import struct
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .frame import MAX_PIXELS, ImageError, as_image

__all__ = ["MAX_FILE_BYTES", "IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "read_image", "write_png", "missing_extra"]

MAX_FILE_BYTES = 1024 * 1024 * 1024
"""Largest image file read, bytes (1 GiB)."""

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
"""File name endings taken as still images in a folder (case-insensitive)."""

VIDEO_SUFFIXES = (".avi", ".mp4", ".mov", ".mkv", ".m4v", ".wmv", ".mpg", ".mpeg")
"""File name endings taken as video files (read through OpenCV)."""

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def missing_extra(package: str, what: str, extra: str = "vision") -> ImageError:
    """The error for an optional package that is not installed (``pip install 'stickslip[extra]'``)."""
    return ImageError(f"{what} needs the {package} package: pip install 'stickslip[{extra}]'")


def _check_file(p: Path) -> int:
    """The size of the regular file ``p``, bytes; :class:`ImageError` for anything else."""
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise ImageError(f"{p}: no such file") from None
    except OSError as e:
        raise ImageError(f"{p}: cannot read the file ({e.strerror or e})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ImageError(f"{p}: is a folder, not an image file")
    if not stat.S_ISREG(st.st_mode):
        raise ImageError(f"{p}: not a regular file (a pipe or device?); give an image file")
    if st.st_size == 0:
        raise ImageError(f"{p}: the file is empty")
    if st.st_size > MAX_FILE_BYTES:
        raise ImageError(f"{p}: larger than the {MAX_FILE_BYTES // 2**20} MiB limit for an image file")
    return int(st.st_size)


def read_image(path: str | os.PathLike[str]) -> NDArray[np.float64]:
    """The grey ``float64`` image in a file (see :func:`~.frame.as_image` for the conversion).

    Raises :class:`ImageError` for a missing, empty, corrupt, truncated or oversized file, a
    stack of images, NaN in a float image, or a missing optional package (the message says
    which to install).
    """
    p = Path(path)
    _check_file(p)
    try:
        with open(p, "rb") as f:
            head = f.read(32)
    except OSError as e:
        raise ImageError(f"{p}: cannot read the file ({e.strerror or e})") from None
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return _read_tiff(p)
    if head.startswith(_PNG_MAGIC) and _png_is_16bit_colour(head):
        return _read_with_opencv(p, "a 16-bit colour PNG (Pillow would cut it to 8 bits)")
    return _read_with_pillow(p)


def _png_is_16bit_colour(head: bytes) -> bool:
    """Whether a PNG's header (IHDR) says 16 bits per sample in colour (types 2 RGB, 4 grey+alpha, 6 RGBA)."""
    if len(head) < 26 or head[12:16] != b"IHDR":
        return False
    bit_depth, colour_type = head[24], head[25]
    return bit_depth == 16 and colour_type in (2, 4, 6)


def _read_tiff(p: Path) -> NDArray[np.float64]:
    try:
        import tifffile
    except ImportError:
        raise missing_extra("tifffile", f"{p}: reading a TIFF") from None
    try:
        with tifffile.TiffFile(p) as tif:
            pages = len(tif.pages)
            if pages > 1:
                raise ImageError(f"{p}: a stack of {pages} images (a multi-page TIFF): give one image per file")
            page: Any = tif.pages[0]
            shape = tuple(int(v) for v in page.shape)
            if not shape or int(np.prod(shape, dtype=np.int64)) > 4 * MAX_PIXELS:
                raise ImageError(f"{p}: {shape} pixels is more than a frame may have")
            try:
                data = page.asarray()
            except ValueError as e:
                if "imagecodecs" in str(e):  # LZW, JPEG, ...: Pillow has them built in
                    return _read_with_pillow(p)
                raise
    except ImageError:
        raise
    except MemoryError:
        raise ImageError(f"{p}: not a readable TIFF (it asks for more memory than there is)") from None
    except Exception as e:  # noqa: BLE001  - tifffile raises many kinds on a damaged file
        raise ImageError(f"{p}: not a readable TIFF ({_reason(e)})") from None
    if data.ndim == 3 and data.shape[0] in (3, 4) and data.shape[2] not in (1, 2, 3, 4):
        data = np.moveaxis(data, 0, -1)  # planar colour (samples first)
    return as_image(data, str(p))


def _read_with_pillow(p: Path) -> NDArray[np.float64]:
    try:
        from PIL import Image
    except ImportError:
        raise missing_extra("Pillow", f"{p}: reading an image") from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(p) as im:
                w, h = im.size
                if w * h > MAX_PIXELS:
                    raise ImageError(
                        f"{p}: {w} x {h} pixels is more than the {MAX_PIXELS // 2**20} Mpx a frame may have"
                    )
                n = int(getattr(im, "n_frames", 1) or 1)
                if n > 1:
                    raise ImageError(f"{p}: a stack of {n} images (pages or an animation): give one image per file")
                im.load()
                data = _pillow_array(im)
    except ImageError:
        raise
    except MemoryError:
        raise ImageError(f"{p}: not a readable image (it asks for more memory than there is)") from None
    except Exception as e:  # noqa: BLE001  - Pillow raises many kinds (OSError, SyntaxError, struct.error, ...)
        raise ImageError(f"{p}: not a readable image ({_reason(e)})") from None
    return as_image(data, str(p))


def _pillow_array(im: Any) -> NDArray[Any]:
    """The pixel array of a loaded Pillow image, palette and odd modes made grey or RGB first."""
    mode = str(im.mode)
    if mode in ("P", "PA"):
        im = im.convert("RGBA")
    elif mode in ("CMYK", "YCbCr", "LAB", "HSV"):
        im = im.convert("RGB")
    elif mode == "1":
        im = im.convert("L")
    elif mode.startswith("I;16"):
        return np.asarray(im).astype(np.uint16)
    elif mode == "I":  # 32-bit signed: what Pillow makes of some 16-bit files
        a = np.asarray(im)
        return a.astype(np.uint16) if a.size and a.min() >= 0 and a.max() <= 65535 else a
    return np.asarray(im)


def _read_with_opencv(p: Path, what: str) -> NDArray[np.float64]:
    try:
        import cv2
    except ImportError:
        raise missing_extra("opencv-python-headless", f"{p}: {what}", "opencv") from None
    try:
        raw = np.fromfile(p, dtype=np.uint8)
        data = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
    except Exception as e:  # noqa: BLE001
        raise ImageError(f"{p}: not a readable image ({_reason(e)})") from None
    if data is None:
        raise ImageError(f"{p}: not a readable image (damaged or truncated)")
    if data.ndim == 3 and data.shape[2] in (3, 4):
        data = data[:, :, [2, 1, 0] + ([3] if data.shape[2] == 4 else [])]  # OpenCV keeps BGR
    return as_image(data, str(p))


def _reason(e: BaseException) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    if isinstance(e, struct.error):
        text = f"damaged header: {text}"
    return text[:160]


def write_png(path: str | os.PathLike[str], image: NDArray[np.float64]) -> None:
    """Save a grey image (values in [0, 1]; outside clipped) as a 16-bit PNG, atomically (Pillow)."""
    try:
        from PIL import Image
    except ImportError:
        raise missing_extra("Pillow", f"{path}: writing a PNG") from None
    from ..records import atomic_write

    a = np.asarray(image, dtype=float)
    if a.ndim != 2 or not np.all(np.isfinite(a)):
        raise ImageError(f"{path}: only a finite 2-D grey image can be saved")
    data = np.round(np.clip(a, 0.0, 1.0) * 65535.0).astype(np.uint16)
    im = Image.fromarray(data)
    atomic_write(path, lambda f: im.save(f, format="PNG"), mode="wb")
