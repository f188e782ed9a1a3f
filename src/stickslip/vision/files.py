"""Recorded and live cameras: image files, a video file, and a live camera through OpenCV.

* :class:`FileCamera` (``files://PATTERN``) gives the frames of a list of image files in
  order; :func:`frame_paths` expands what a user names (files, folders, globs) into that
  list, refusing an empty folder or a pattern that matches nothing.
* :class:`VideoCamera` (``video://FILE``) and :class:`OpenCVCamera` (``opencv://N``) use
  OpenCV (``opencv-python-headless``, the ``opencv`` extra), imported only when one is
  opened: without it, opening one says what to install.

All frames of one camera must have one size: a frame of another size is refused naming
both sizes.
"""

from __future__ import annotations

import glob
import math
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ..devices.base import Controller, redact_url
from ..records import natural_order
from .camera import CameraEnded, CameraError, CameraInfo, camera_options, pixel_option
from .frame import Frame, ImageError, as_image
from .images import IMAGE_SUFFIXES, VIDEO_SUFFIXES, Stated, _check_file, read_image_stated

__all__ = [
    "FileCamera",
    "VideoCamera",
    "OpenCVCamera",
    "frame_paths",
    "name_order",
    "is_video",
    "open_frames",
    "open_files_url",
    "location_path",
    "open_video_url",
    "open_opencv_url",
]

MAX_FILES = 1_000_000
"""Most files a sequence may have."""


def is_video(path: str | os.PathLike[str]) -> bool:
    """Whether a file name ends like a video (:data:`~.images.VIDEO_SUFFIXES`)."""
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def frame_paths(names: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The image files that ``names`` mean, in order.

    Each name is a file (taken as it is, whatever its name ends in), a folder (its image files,
    :data:`~.images.IMAGE_SUFFIXES`, in name order) or a glob pattern (``*``, ``?``,
    ``[``: its matching image files, in name order). A folder and a glob take the same files:
    those named like images; anything else they hold or match (``Thumbs.db``, ``.DS_Store``,
    ``notes.txt``) is skipped, and one that leaves nothing is refused. Name order reads runs of digits as numbers
    (:func:`name_order`: ``f2.png`` before ``f10.png``). :class:`ImageError` for a name
    that is nothing, an empty folder or a pattern matching no file.
    """
    out: list[Path] = []
    for name in names:
        try:
            out += _named_frames(os.fspath(name))
        except OSError as e:  # a name the system refuses (too long, a loop of links): no frame it could name
            raise ImageError(f"{os.fspath(name)[:80]!r}: cannot look at it ({e.strerror or e})") from None
        if len(out) > MAX_FILES:
            raise ImageError(f"more than {MAX_FILES} frames named")
    if not out:
        raise ImageError("no frames named")
    return out


def _named_frames(text: str) -> list[Path]:
    """The image files one name means (:func:`frame_paths`), in name order (:func:`name_order`)."""
    p = Path(text)
    if p.is_dir():
        found = sorted((q for q in p.iterdir() if q.suffix.lower() in IMAGE_SUFFIXES and q.is_file()), key=name_order)
        if not found:
            raise ImageError(f"{p}: the folder has no image files ({', '.join(IMAGE_SUFFIXES)})")
        return found
    if p.exists() or not any(c in text for c in "*?["):
        return [p]
    named = [Path(m) for m in _glob(text)]
    matches = sorted((m for m in named if m.is_file()), key=name_order)
    if not matches:
        folders = sorted((m for m in named if m.is_dir()), key=name_order)
        if folders:  # 'run*' meant as the runs' frames: say what it matched, not only what it did not
            raise ImageError(f"{text}: the pattern matches {len(folders)} folder(s) ({folders[0]}"
                             f"{', ...' if len(folders) > 1 else ''}) and no file: name a folder to read its "
                             f"images, or match the files in them ({os.path.join(text, '*.png')})")
        raise ImageError(f"{text}: no file matches the pattern")
    images = [m for m in matches if m.suffix.lower() in IMAGE_SUFFIXES]  # as a folder: Thumbs.db is not a frame
    if not images:
        raise ImageError(f"{text}: the pattern matches {len(matches)} files ({matches[0].name}, ...) but no image "
                         f"file ({', '.join(IMAGE_SUFFIXES)}); name a file to read it whatever its name ends in")
    return images


def _glob(text: str) -> list[str]:
    """The names a glob ``text`` matches, its folders taken as written where they exist.

    A lab's folder is often named ``Messungen [2026]``: ``Messungen [2026]/*.png`` globs the
    frames in that folder (``[2026]`` read as a character class matched nothing). The longest
    leading run of whole folder names that exists is escaped; only if that matches nothing is
    ``text`` globbed as written (a ``[ab]`` meant as a class where no such folder is).
    """
    parts = text.replace(os.altsep or os.sep, os.sep).split(os.sep)
    for k in range(len(parts) - 1, 0, -1):
        folder = os.sep.join(parts[:k]) or os.sep
        if not os.path.isdir(folder):
            continue
        if any(c in folder for c in "*?["):
            found = glob.glob(os.path.join(glob.escape(folder), *parts[k:]))
            if found:
                return found
        break
    return glob.glob(text)


def name_order(path: Path) -> tuple[tuple[tuple[int, int | str], ...], str]:
    """The sort key of a frame's path: runs of digits compare as numbers (``f2`` before ``f10``), the rest as text.

    A camera or script that numbers its frames without leading zeros (``f1.png`` ... ``f10.png``)
    would otherwise be tracked out of order (``f1, f10, f11, f2``) with each frame given
    another frame's time (:func:`stickslip.records.natural_order`). Zero-padded names keep their
    order; two names equal as numbers (``f01``, ``f1``) fall back to the path's text.
    """
    return natural_order(str(path)), str(path)


class FileCamera:
    """A recorded sequence of image files as a camera: each ``grab()`` reads the next file.

    Parameters
    ----------
    paths : sequence of path
        The files, in order (see :func:`frame_paths`).
    fps : float
        Frames per second the sequence was taken at: frame ``k`` has time ``k / fps``, s.
    pixel_size_m : float, optional
        Pixel size in the object plane, m.
    url : str
        For :attr:`info`.
    """

    def __init__(
        self, paths: Sequence[str | os.PathLike[str]], fps: float = 1.0, pixel_size_m: float | None = None,
        url: str = "files://",
    ) -> None:
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps = {fps!r} must be a positive number of frames per second")
        self.paths = [Path(p) for p in paths]
        if not self.paths:
            raise ImageError("no frames named")
        self.fps = float(fps)
        self.pixel_size_m = pixel_size_m
        self._url = url
        self._next = 0
        self._shape: tuple[int, int] | None = None
        self.turned: tuple[str, Stated] | None = None
        """The first frame read whose file states an orientation other than 1 (its name, what it states):
        its pixels are read as stored, not turned as a viewer shows them."""
        self.stated_pixel: tuple[str, Stated] | None = None
        """Without ``pixel_size_m``: the first frame read whose file states a pixel size (not used)."""

    @property
    def info(self) -> CameraInfo:
        """``"image files"``, the number of files and the frame size once known."""
        return CameraInfo(
            redact_url(self._url), "image files", self.pixel_size_m, {"files": len(self.paths), "shape": self._shape}
        )

    def __len__(self) -> int:
        return len(self.paths)

    def grab(self) -> Frame:
        """The next file's frame; :class:`CameraEnded` after the last, :class:`ImageError` for a bad file."""
        if self._next >= len(self.paths):
            raise CameraEnded(f"the {len(self.paths)} frames of {redact_url(self._url)} are used up")
        k = self._next
        self._next += 1
        p = self.paths[k]
        image, stated = read_image_stated(p)
        if stated.orientation != 1 and self.turned is None:
            self.turned = (str(p), stated)
        if stated.pixel_m is not None and self.pixel_size_m is None and self.stated_pixel is None:
            self.stated_pixel = (str(p), stated)
        shape = (int(image.shape[0]), int(image.shape[1]))
        if self._shape is None:
            self._shape = shape
        elif shape != self._shape:
            raise ImageError(
                f"{p}: {shape[1]} x {shape[0]} pixels, but the frames before it are "
                f"{self._shape[1]} x {self._shape[0]}: all frames of a sequence must have one size"
            )
        return Frame(image, k / self.fps, self.pixel_size_m, str(p))

    def close(self) -> None:
        """Nothing to release (files are read one at a time)."""


def _cv2(what: str) -> Any:
    try:
        import cv2
    except ImportError:
        raise CameraError(
            f"{what} needs OpenCV, which is not installed: pip install 'stickslip[opencv]' "
            "(the opencv-python-headless package)"
        ) from None
    _quiet_opencv(cv2)
    return cv2


def _quiet_opencv(cv2: Any) -> None:
    """OpenCV's own warnings off stderr (``[ WARN:0] ... can't open camera by index`` before stickslip's one line
    saying the same); its errors still show."""
    log = getattr(getattr(cv2, "utils", None), "logging", None)
    if log is not None and hasattr(log, "setLogLevel"):
        log.setLogLevel(log.LOG_LEVEL_ERROR)


class _CaptureCamera:
    """Frames from an OpenCV ``VideoCapture`` (a video file or a live camera)."""

    model = "OpenCV capture"

    def __init__(self, capture: Any, url: str, pixel_size_m: float | None, recorded: bool) -> None:
        self._cap = capture
        self._url = url
        self.pixel_size_m = pixel_size_m
        self._recorded = recorded
        self._k = 0
        self._shape: tuple[int, int] | None = None
        self._t0: float | None = None

    @property
    def info(self) -> CameraInfo:
        return CameraInfo(redact_url(self._url), self.model, self.pixel_size_m, {"shape": self._shape})

    def grab(self) -> Frame:
        ok, data = self._cap.read()
        if not ok or data is None:
            if self._recorded:
                if self._k == 0:
                    raise CameraEnded(f"{redact_url(self._url)} has no frames (an empty video, or one OpenCV cannot "
                                      "decode)")
                raise CameraEnded(f"{redact_url(self._url)} has no more frames (after {self._k})")
            raise CameraError(f"{redact_url(self._url)} delivered no frame (disconnected or in use?)")
        if data.ndim == 3 and data.shape[2] in (3, 4):
            data = data[:, :, [2, 1, 0]]  # OpenCV keeps BGR
        source = f"{redact_url(self._url)} frame {self._k}"
        image = as_image(data, source)
        shape = (int(image.shape[0]), int(image.shape[1]))
        if self._shape is None:
            self._shape = shape
        elif shape != self._shape:
            raise ImageError(
                f"{source}: {shape[1]} x {shape[0]} pixels after frames of {self._shape[1]} x {self._shape[0]}"
            )
        t = self._time()
        self._k += 1
        return Frame(image, t, self.pixel_size_m, source)

    def _time(self) -> float:
        if self._recorded:
            ms = float(self._cap.get(0))  # CAP_PROP_POS_MSEC: the time stamp of the frame just read
            fps = float(self._cap.get(5))  # CAP_PROP_FPS
            if math.isfinite(ms) and ms > 0:
                return ms / 1000.0
            return self._k / fps if math.isfinite(fps) and fps > 0 else float(self._k)
        import time

        now = time.monotonic()
        if self._t0 is None:
            self._t0 = now
        return now - self._t0

    def close(self) -> None:
        try:
            self._cap.release()
        except Exception:  # noqa: BLE001  - releasing a broken capture must not hide the first error
            pass


class VideoCamera(_CaptureCamera):
    """The frames of a video file (OpenCV); times from the file's time stamps, s."""

    model = "video file"

    def __init__(self, path: str | os.PathLike[str], pixel_size_m: float | None = None, url: str | None = None):
        p = Path(path)
        try:
            _check_file(p)
        except ImageError as e:
            raise CameraError(str(e)) from None
        cv2 = _cv2(f"reading the video {p}")
        cap = cv2.VideoCapture(str(p))
        if not cap.isOpened():
            cap.release()
            raise CameraError(f"{p}: not a readable video (damaged, or a codec OpenCV lacks)")
        super().__init__(cap, url or f"video://{p}", pixel_size_m, recorded=True)


class OpenCVCamera(_CaptureCamera):
    """A live camera through OpenCV's ``VideoCapture(index)``; times from the monotonic clock, s."""

    model = "live camera (OpenCV)"

    def __init__(self, index: int = 0, pixel_size_m: float | None = None, url: str | None = None,
                 width: int | None = None, height: int | None = None):
        cv2 = _cv2(f"the live camera {index}")
        cap = cv2.VideoCapture(int(index))
        if not cap.isOpened():
            cap.release()
            raise CameraError(f"camera {index} does not open (not connected, or in use by another program)")
        if width:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, int(width))
        if height:
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, int(height))
        super().__init__(cap, url or f"opencv://{index}", pixel_size_m, recorded=False)


def open_frames(names: Sequence[str | os.PathLike[str]], fps: float = 1.0,
                pixel_size_m: float | None = None) -> FileCamera | VideoCamera:
    """A camera over what the user names: one video file, or image files, folders and globs."""
    if len(names) == 1 and is_video(names[0]) and not Path(names[0]).is_dir():
        return VideoCamera(names[0], pixel_size_m)
    videos = [n for n in names if is_video(n)]
    if videos:
        raise ImageError(f"{os.fspath(videos[0])}: a video file goes alone, not among other frames")
    return FileCamera(frame_paths(names), fps, pixel_size_m, "files://" + ",".join(os.fspath(n) for n in names[:3]))


def _number(opts: dict[str, str], key: str, url: str, default: float) -> float:
    text = opts.get(key)
    if text is None:
        return default
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{key}={text!r} in {redact_url(url)!r} is not a number") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{key}={text!r} in {redact_url(url)!r} must be a positive number")
    return v


_DRIVE = re.compile(r"/([A-Za-z]:[/\\].*)", re.DOTALL)


def location_path(location: str, windows: bool = os.name == "nt") -> str:
    """The path a ``files://`` or ``video://`` location names: ``~`` expanded; on Windows
    ``/C:/frames`` (of ``files:///C:/frames``, as ``file:///`` URLs write a drive) is ``C:/frames``.

    ``files://C:\\frames\\*.png`` and a relative ``files://frames/*.png`` are taken as written.
    """
    m = _DRIVE.fullmatch(location) if windows else None
    text = m.group(1) if m else location
    return os.path.expanduser(text) if text.startswith("~") else text


def open_files_url(url: str, device: Controller | None = None) -> FileCamera:
    """``files://PATTERN[?fps=F&pixel=SIZE]``: a folder, a glob or a file (several joined by ``,``)."""
    location, opts = camera_options(url, {"fps", "pixel"})
    if not location:
        raise ValueError(f"{redact_url(url)!r} names no files: write files://FOLDER or files://frames/*.png")
    names: Iterable[str] = (location_path(n) for n in _split_names(location))
    return FileCamera(frame_paths(list(names)), _number(opts, "fps", url, 1.0), pixel_option(opts, url), url)


def _split_names(location: str) -> list[str]:
    """The names a ``files://`` location joins with ``,``; the whole location if it names a file or folder as it
    stands (``files://Messungen 1,2/*.png``: a folder whose name holds a comma, as labs name runs)."""
    whole = location_path(location)
    if "," in location and (os.path.exists(whole) or (any(c in whole for c in "*?[") and bool(_glob(whole)))):
        return [location]
    return location.split(",")


def open_video_url(url: str, device: Controller | None = None) -> VideoCamera:
    """``video://FILE[?pixel=SIZE]``."""
    location, opts = camera_options(url, {"pixel"})
    if not location:
        raise ValueError(f"{redact_url(url)!r} names no file: write video://run.avi")
    return VideoCamera(location_path(location), pixel_option(opts, url), url)


MAX_CAMERA_INDEX = 2**31 - 1
"""The largest camera number OpenCV's ``VideoCapture`` takes (a C ``int``; a larger one was its overload error)."""


def open_opencv_url(url: str, device: Controller | None = None) -> OpenCVCamera:
    """``opencv://N[?pixel=SIZE&width=W&height=H]``: camera number ``N`` (default 0)."""
    location, opts = camera_options(url, {"pixel", "width", "height"})
    text = location.strip("/") or "0"
    digits = text.lstrip("0") or "0"
    if not (text.isascii() and text.isdigit()) or len(digits) > 10 or int(digits) > MAX_CAMERA_INDEX:
        raise ValueError(f"{redact_url(url)[:80]!r}: the camera number {text[:20]!r} must be 0, 1, ... "
                         f"(at most {MAX_CAMERA_INDEX})")
    w = int(_number(opts, "width", url, 0)) if "width" in opts else None
    h = int(_number(opts, "height", url, 0)) if "height" in opts else None
    return OpenCVCamera(int(text), pixel_option(opts, url), url, w, h)
