"""The camera interface, and opening a camera from a URL in the device URLs' style.

A camera is anything with ``grab()`` (the next :class:`~.frame.Frame`), ``info`` and
``close()``. The URL's scheme picks the backend, as for controllers
(:func:`stickslip.devices.open_device`)::

    simcam://?look=sem&seed=1        a simulated microscope looking at a simulated arm
    files://frames/*.png?fps=10      a sequence of image files (a folder, a glob, one file)
    video://run3.avi                 a video file (OpenCV)
    opencv://0?pixel=0.5um           a live camera (OpenCV's capture, camera number 0)

Every backend takes ``pixel=`` (the pixel size in the object plane: ``0.5um``, ``20nm``);
unknown options are refused, and URLs in messages never carry a secret
(:func:`stickslip.devices.base.redact_url`). Backends register a factory by module path
(:data:`CAMERAS`), imported when first used: this package never imports the simulator,
which registers ``simcam://`` from :mod:`stickslip.sim.camera`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

from ..devices.base import Controller, query_options, redact_text, redact_url
from ..units import UnitError, bare_number_problem, parse_length
from .frame import PIXEL_SIZE_RANGE, Frame

__all__ = [
    "Camera",
    "CameraInfo",
    "CameraError",
    "CameraEnded",
    "CAMERAS",
    "register_camera",
    "open_camera",
    "camera_scheme",
    "camera_options",
    "pixel_option",
]


class CameraError(RuntimeError):
    """A camera could not be opened or did not deliver a frame; the message says which and why."""


class CameraEnded(CameraError):
    """A recorded camera (files, a video) has no more frames."""


@dataclass(frozen=True)
class CameraInfo:
    """What a camera says about itself.

    Attributes
    ----------
    url : str
        The URL it was opened with, without secrets.
    model : str
        Human-readable kind: ``"simulated microscope (SEM)"``, ``"image files"``, ...
    pixel_size_m : float or None
        Pixel size in the object plane, m, if known.
    extra : dict
        Backend details (number of files, frame size, the simulated look, ...).
    """

    url: str
    model: str
    pixel_size_m: float | None = None
    extra: dict[str, object] = field(default_factory=dict)


@runtime_checkable
class Camera(Protocol):
    """A camera: ``grab()`` returns the next frame.

    ``grab()`` raises :class:`CameraError` when no frame comes (a live camera that
    stopped) and :class:`CameraEnded` when a recording has no more frames.
    """

    @property
    def info(self) -> CameraInfo:
        """Kind, URL and pixel size of this camera."""
        ...

    def grab(self) -> Frame:
        """The next frame."""
        ...

    def close(self) -> None:
        """Release the camera (or the open file)."""
        ...


CameraFactory = Callable[[str, "Controller | None"], Camera]

CAMERAS: dict[str, str | CameraFactory] = {
    # scheme -> factory(url, device), or "module:function" imported on first use
    "simcam": "stickslip.sim.camera:open_url",
    "files": "stickslip.vision.files:open_files_url",
    "video": "stickslip.vision.files:open_video_url",
    "opencv": "stickslip.vision.files:open_opencv_url",
}


def register_camera(scheme: str, factory: str | CameraFactory) -> None:
    """Make ``scheme://...`` camera URLs open with ``factory(url, device)``."""
    CAMERAS[scheme] = factory


def camera_scheme(url: str) -> str:
    """The scheme of a camera URL; ``ValueError`` (saying how to write one) when it has none."""
    text = str(url)
    scheme, sep, _ = text.partition("://")
    if not sep or not scheme or not scheme.replace("+", "").isalnum():
        known = ", ".join(f"{s}://" for s in sorted(CAMERAS))
        raise ValueError(f"camera URL {redact_url(text)!r} has no scheme (write one of {known})")
    return scheme.lower()


def open_camera(url: str, device: Controller | None = None) -> Camera:
    """Open the camera a URL names; ``device`` is the arm it looks at (needed by ``simcam://``).

    Raises :class:`CameraError` for an unknown scheme or a camera that cannot be opened,
    ``ValueError`` for a malformed URL or option; messages never contain a secret.
    """
    scheme = camera_scheme(url)
    factory = CAMERAS.get(scheme)
    if factory is None:
        known = ", ".join(f"{s}://" for s in sorted(CAMERAS))
        raise CameraError(f"unknown camera URL scheme {scheme!r} in {redact_url(url)!r} (known: {known})")
    if isinstance(factory, str):
        mod_name, func_name = factory.split(":")
        try:
            module = importlib.import_module(mod_name)
        except ImportError as e:
            raise CameraError(f"the camera backend for {scheme}:// could not be loaded: {e}") from e
        factory = getattr(module, func_name)
    try:
        return factory(url, device)
    except (CameraError, ValueError) as e:
        raise type(e)(redact_text(str(e))) from None  # a message: each URL in it redacted


def camera_options(url: str, known: set[str] | frozenset[str]) -> tuple[str, dict[str, str]]:
    """``(location, options)`` of a camera URL: what stands between ``://`` and ``?``, and the options.

    The location is taken as written (a relative path stays relative: ``files://frames/*.png``).
    Unknown options, and an option given twice, raise ``ValueError`` naming them (and the known ones).
    """
    rest = str(url).partition("://")[2]
    location, _, query = rest.partition("?")
    opts = query_options(query, url, "camera")
    unknown = sorted(set(opts) - set(known))
    if unknown:
        raise ValueError(f"unknown option(s) {unknown} in {redact_url(url)!r} (known: {sorted(known)})")
    return location, opts


def pixel_option(opts: dict[str, str], url: str) -> float | None:
    """The ``pixel=`` option (``0.5um``, ``20nm``), m; ``None`` if absent (empty, or a bare number: refused, as on the
    command line: ``pixel=0.5`` could be µm or m)."""
    text = opts.get("pixel")
    if text is None:
        return None
    if not text.strip():  # not "no pixel size": simcam:// would draw its default, a file camera have none
        raise ValueError(f"pixel={text!r} is empty in {redact_url(url)!r}: write e.g. pixel=0.5um, or leave it out")
    bare = bare_number_problem(text, "length")
    if bare is not None:
        raise ValueError(f"pixel={text!r} in {redact_url(url)!r}: {bare}")
    try:
        v = parse_length(text)
    except (UnitError, ValueError, ArithmeticError) as e:
        raise ValueError(f"pixel={text!r} in {redact_url(url)!r}: {e} (write e.g. pixel=0.5um)") from None
    lo, hi = PIXEL_SIZE_RANGE
    if not lo <= v < hi:
        raise ValueError(f"pixel={text!r} in {redact_url(url)!r} must be a size in [1 pm, 1 cm), e.g. pixel=0.5um")
    return v
