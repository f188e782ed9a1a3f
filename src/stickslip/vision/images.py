"""Reading image files into frames: PNG, TIFF (8, 16 or 32 bit; grey or colour), and what Pillow reads.

The libraries are optional (the ``vision`` extra) and imported when a file is read:

* **TIFF** through tifffile (every sample type, floats with their NaN, stacks told apart
  from colour), as a viewer shows it (:func:`_as_shown`: a palette looked up, an inverted
  grey turned over); a TIFF compressed with a codec tifffile needs ``imagecodecs`` for (LZW,
  JPEG), or in CMYK, YCbCr or CIELab, is read by Pillow instead, which has those built in;
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
import re
import stat
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..units import LENGTH_UNITS
from .frame import MAX_PIXELS, ImageError, as_image

__all__ = [
    "MAX_FILE_BYTES", "IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "Stated", "read_image", "read_image_stated", "write_png",
    "missing_extra",
]

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


@dataclass(frozen=True)
class Stated:
    """What an image file states about its pixels that :func:`read_image` does not apply.

    Attributes
    ----------
    orientation : int
        The EXIF (or TIFF) orientation tag, 1..8; 1 (also when absent) means "as stored". The pixels
        are always read as stored: a viewer that applies another orientation shows other coordinates.
    pixel_m : tuple of float or None
        The pixel size (x, y) the file states, m: TIFF resolution tags with a unit (inch, cm) or OME
        ``PhysicalSizeX/Y``; ``None`` when it states none. Never used as the frame's pixel size.
    pixel_from : str
        Where ``pixel_m`` comes from: ``"TIFF resolution tags"`` or ``"OME metadata"``.
    """

    orientation: int = 1
    pixel_m: tuple[float, float] | None = None
    pixel_from: str = ""


def read_image(path: str | os.PathLike[str]) -> NDArray[np.float64]:
    """The grey ``float64`` image in a file (see :func:`~.frame.as_image` for the conversion).

    Raises :class:`ImageError` for a missing, empty, corrupt, truncated or oversized file, a
    stack of images, NaN in a float image, or a missing optional package (the message says
    which to install).
    """
    return read_image_stated(path)[0]


def read_image_stated(path: str | os.PathLike[str]) -> tuple[NDArray[np.float64], Stated]:
    """:func:`read_image`'s image and what the file states about its pixels (:class:`Stated`), pixels as stored."""
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
        return _read_with_opencv(p, "a 16-bit colour PNG (Pillow would cut it to 8 bits)"), Stated()
    return _read_with_pillow(p)


def _png_is_16bit_colour(head: bytes) -> bool:
    """Whether a PNG's header (IHDR) says 16 bits per sample in colour (types 2 RGB, 4 grey+alpha, 6 RGBA)."""
    if len(head) < 26 or head[12:16] != b"IHDR":
        return False
    bit_depth, colour_type = head[24], head[25]
    return bit_depth == 16 and colour_type in (2, 4, 6)


def _read_tiff(p: Path) -> tuple[NDArray[np.float64], Stated]:
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
            stated = _tiff_stated(tif, page)
            shape = tuple(int(v) for v in page.shape)
            if not shape or int(np.prod(shape, dtype=np.int64)) > 4 * MAX_PIXELS:
                raise ImageError(f"{p}: {shape} pixels is more than a frame may have")
            try:
                data = page.asarray()
            except ValueError as e:
                if "imagecodecs" in str(e):  # LZW, JPEG, ...: Pillow has them built in
                    return _read_with_pillow(p)[0], stated
                raise
            data = _as_shown(p, page, data)
            if data is None:  # CMYK, YCbCr, CIELab, ...: Pillow turns them into RGB, or says why not
                return _read_with_pillow(p)[0], stated
    except ImageError:
        raise
    except MemoryError:
        raise ImageError(f"{p}: not a readable TIFF (it asks for more memory than there is)") from None
    except Exception as e:  # noqa: BLE001  - tifffile raises many kinds on a damaged file
        raise ImageError(f"{p}: not a readable TIFF ({_reason(e)})") from None
    return as_image(data, str(p)), stated


_MINISWHITE, _MINISBLACK, _RGB, _PALETTE = 0, 1, 2, 3
"""TIFF PhotometricInterpretation values: inverted grey, grey, RGB, palette."""


def _as_shown(p: Path, page: Any, data: NDArray[Any]) -> NDArray[Any] | None:
    """A TIFF page's samples as the picture a viewer shows; ``None`` for an interpretation left to Pillow.

    Grey and RGB are the samples; an inverted grey (MinIsWhite: 0 is white) is turned over by the type's
    largest value; a palette image's indices become their colour map's RGB (16 bits). Read raw, these were
    another picture (a palette's index / 255, an inverted grey) with nothing said. Samples stored planar
    (samples first) are put last; a grey page's extra samples (alpha, other channels) are not its grey, nor an
    RGB page's beyond the third its colour."""
    photometric = int(page.photometric)
    spp = int(page.samplesperpixel)
    if spp > 1 and data.ndim == 3 and int(page.planarconfig) == 2 and data.shape[0] == spp:
        data = np.moveaxis(data, 0, -1)  # planar (samples first): as a contiguous page's
    if spp > 1 and data.ndim == 3 and data.shape[-1] == spp:
        if photometric in (_MINISWHITE, _MINISBLACK, _PALETTE):
            data = data[..., 0]
        elif photometric == _RGB:
            data = data[..., :3]
    if photometric in (_MINISBLACK, _RGB):
        return data
    if photometric == _MINISWHITE:
        if data.dtype == bool:
            return ~data
        if np.issubdtype(data.dtype, np.unsignedinteger):
            return np.iinfo(data.dtype).max - data
        raise ImageError(f"{p}: an inverted grey TIFF (MinIsWhite) of {data.dtype} samples has no white level to "
                         "turn it over by: save it as ordinary grey (BlackIsZero)")
    if photometric == _PALETTE:
        cmap = page.colormap
        if cmap is None or data.ndim != 2 or not np.issubdtype(data.dtype, np.unsignedinteger):
            raise ImageError(f"{p}: a palette TIFF without a colour map for its {data.dtype} samples")
        cmap = np.asarray(cmap, dtype=np.uint16).reshape(3, -1)
        if int(data.max()) >= cmap.shape[1]:
            raise ImageError(f"{p}: a palette index of {int(data.max())} beyond the {cmap.shape[1]} colours of its "
                             "colour map (a damaged file)")
        return np.moveaxis(np.take(cmap, data, axis=1), 0, -1)
    return None


def _read_with_pillow(p: Path) -> tuple[NDArray[np.float64], Stated]:
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
                stated = Stated(_orientation(im.getexif().get(0x0112)))
    except ImageError:
        raise
    except MemoryError:
        raise ImageError(f"{p}: not a readable image (it asks for more memory than there is)") from None
    except Exception as e:  # noqa: BLE001  - Pillow raises many kinds (OSError, SyntaxError, struct.error, ...)
        raise ImageError(f"{p}: not a readable image ({_reason(e)})") from None
    return as_image(data, str(p)), stated


def _orientation(value: Any) -> int:
    """An orientation tag's value, 1..8; 1 for an absent or meaningless one."""
    try:
        v = int(value)
    except (TypeError, ValueError):
        return 1
    return v if 1 <= v <= 8 else 1


_INCH_M, _CM_M = 0.0254, 0.01
_OME_UNITS = {**LENGTH_UNITS, "cm": _CM_M}  # OME's length units: ours, and a centimetre
_OME_PHYSICAL = re.compile(r'PhysicalSize([XY])(Unit)?="([^"]*)"')


def _tiff_stated(tif: Any, page: Any) -> Stated:
    """A TIFF's orientation tag and the pixel size it states: OME ``PhysicalSizeX/Y`` first, else resolution
    tags with a unit (ResolutionUnit 2 inch, 3 cm; 1 "no unit" states no size)."""
    tags = page.tags
    orientation = _orientation(tags["Orientation"].value) if "Orientation" in tags else 1
    ome = getattr(tif, "ome_metadata", None)
    if isinstance(ome, str):
        found = {(axis, bool(unit)): text for axis, unit, text in _OME_PHYSICAL.findall(ome)}
        sizes = []
        for axis in "XY":
            value, unit = found.get((axis, False)), found.get((axis, True), "µm")
            scale = _OME_UNITS.get(unit)
            size = _positive(value, scale)
            if size is not None:
                sizes.append(size)
        if len(sizes) == 2:
            return Stated(orientation, (sizes[0], sizes[1]), "OME metadata")
    unit_tag = tags["ResolutionUnit"].value if "ResolutionUnit" in tags else 2  # TIFF's default is inch
    unit = {2: _INCH_M, 3: _CM_M}.get(int(unit_tag))
    if unit is not None and "XResolution" in tags and "YResolution" in tags:
        x, y = (_per_unit(tags[k].value) for k in ("XResolution", "YResolution"))
        if x and y:
            return Stated(orientation, (unit / x, unit / y), "TIFF resolution tags")
    return Stated(orientation)


def _positive(text: str | None, scale: float | None) -> float | None:
    """``float(text) * scale`` when both are given and the result is a positive finite number."""
    if text is None or scale is None:
        return None
    try:
        v = float(text) * scale
    except ValueError:
        return None
    return v if np.isfinite(v) and v > 0 else None


def _per_unit(value: Any) -> float:
    """A TIFF RATIONAL tag's value (a (numerator, denominator) pair or a number); 0 when unusable."""
    try:
        v = float(value[0]) / float(value[1]) if isinstance(value, tuple) else float(value)
    except (TypeError, ValueError, ZeroDivisionError, IndexError):
        return 0.0
    return v if np.isfinite(v) and v > 0 else 0.0


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
    """Save a grey image (values in [0, 1]) as a 16-bit PNG, atomically (Pillow).

    :class:`ImageError`, nothing written, for values outside [0, 1] (a float TIFF in counts, a signed image's
    negatives): clipped, they were a PNG all white or all black with nothing said."""
    try:
        from PIL import Image
    except ImportError:
        raise missing_extra("Pillow", f"{path}: writing a PNG") from None
    from ..records import atomic_write

    a = np.asarray(image, dtype=float)
    if a.ndim != 2 or not np.all(np.isfinite(a)):
        raise ImageError(f"{path}: only a finite 2-D grey image can be saved")
    lo, hi = float(a.min()), float(a.max())
    if lo < 0.0 or hi > 1.0:
        raise ImageError(f"{path}: the frame's values run from {lo:.5g} to {hi:.5g} (a float or signed image): "
                         "a 16-bit PNG holds 0 to 1, and clipped they would lose the picture; nothing written")
    data = np.round(a * 65535.0).astype(np.uint16)
    im = Image.fromarray(data)
    atomic_write(path, lambda f: im.save(f, format="PNG"), mode="wb")
