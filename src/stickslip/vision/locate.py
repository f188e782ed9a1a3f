"""``stickslip camera locate``'s workflow: the tip in each frame of a recording, from its pixel in the first.

:func:`locate` reads every frame (so a bad file is refused before anything is reported),
tracks the tip through them (:class:`~.track.TipTracker`) and returns one
:class:`Located` per frame, in order: a fix with its score, or a refusal with its reason.
The first frame's answer also carries how blurred the needle is there (:attr:`Located.focus`,
:func:`~.focus.first_frame_focus`): a tip learnt out of focus is tracked worse in every later frame.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from .camera import CameraEnded
from .files import FileCamera, open_frames
from .focus import Focus, first_frame_focus
from .frame import Frame, ImageError
from .images import Stated
from .track import Fix, Lost, TipTracker, TrackerParams

__all__ = ["Located", "locate", "locate_frames"]


@dataclass(frozen=True)
class Located:
    """The answer for one frame.

    Attributes
    ----------
    frame : str
        The frame's file (or ``video frame k``).
    fix : Fix or None
        The tip, px, with its score (the first frame: the tip given, score 1).
    lost : str or None
        Why there is no fix (one of :data:`~.track.REASONS`).
    detail : str
        What the tracker saw.
    focus : Focus or None
        The first frame only: how blurred the needle's shaft edges are there (``focus.sigma``, px;
        :func:`~.focus.first_frame_focus`), ``None`` where they cannot be read (and on every later frame).
        Above :attr:`~.template.TrackerParams.focus_warn` px, ``camera locate`` warns. Not in :meth:`as_dict`.
    turned : tuple of (str, Stated) or None
        The first frame only: the first file of the sequence that states an EXIF/TIFF orientation other
        than 1 (its name, what it states). Its pixels (and ``fix``) are as stored, not as a viewer turns
        them. Not in :meth:`as_dict`.
    stated_pixel : tuple of (str, Stated) or None
        The first frame only: the first file that states a pixel size (TIFF resolution tags with a unit,
        OME ``PhysicalSizeX/Y``), which is not used. Not in :meth:`as_dict`.
    """

    frame: str
    fix: Fix | None = None
    lost: str | None = None
    detail: str = ""
    focus: Focus | None = None
    turned: tuple[str, Stated] | None = None
    stated_pixel: tuple[str, Stated] | None = None

    def as_dict(self) -> dict[str, object]:
        """``{"frame", "x", "y", "score"}`` for a fix (px, 0..1), ``{"frame", "lost"}`` for a refusal."""
        if self.fix is not None:
            return {"frame": self.frame, "x": self.fix.x, "y": self.fix.y, "score": self.fix.score}
        return {"frame": self.frame, "lost": self.lost}


def locate_frames(
    frames: Sequence[Frame], tip: tuple[float, float], params: TrackerParams = TrackerParams(),
    progress: Callable[[int], None] | None = None,
) -> list[Located]:
    """The tip in each of ``frames`` (all of one size) from its pixel ``tip`` (x, y) in the first.

    Raises :class:`~.template.TemplateError` when nothing trackable stands at ``tip``.
    """
    if not frames:
        raise ImageError("no frames")
    tracker = TipTracker(frames[0], tip, params)
    out = [_first(frames[0], tip, tracker)]
    for k, f in enumerate(frames[1:], start=1):
        r = tracker.update(f)
        if isinstance(r, Lost):
            out.append(Located(f.source, None, r.reason, r.detail))
        else:
            out.append(Located(f.source, r))
        if progress is not None:
            progress(k)
    return out


def locate(
    names: Sequence[str | os.PathLike[str]], tip: tuple[float, float], params: TrackerParams = TrackerParams(),
    progress: Callable[[int, int], None] | None = None,
) -> list[Located]:
    """The tip in each frame that ``names`` mean (image files, folders, globs, or one video).

    Every frame is read and checked before the first is tracked (a first pass that keeps
    nothing, so a long recording is never held in memory; the second reads the files the
    first named, whatever a folder or glob matches by then): a corrupt, truncated or
    missing file, an empty folder, frames of mixed sizes, a stack or NaN pixels raise
    :class:`~.frame.ImageError` (a video that cannot be opened :class:`~.camera.CameraError`)
    with nothing tracked. ``progress(done, total)`` is called as frames are checked and
    tracked (``total`` is 0 while the number of frames is not known).
    """
    n = 0
    camera = open_frames(names)
    paths = getattr(camera, "paths", None)  # the files named once: a folder written into meanwhile changes nothing
    turned = stated_pixel = None
    try:
        while True:
            try:
                camera.grab()
            except CameraEnded:
                break
            n += 1
            if progress is not None:
                progress(n, 0)
        turned, stated_pixel = getattr(camera, "turned", None), getattr(camera, "stated_pixel", None)
    finally:
        camera.close()
    if n == 0:  # a video that opens and gives none (files named are never none: frame_paths refuses that)
        raise ImageError(f"{', '.join(os.fspath(x) for x in names[:3])}: the recording has no frames")
    camera = open_frames(names) if paths is None else FileCamera(paths)
    try:
        first = camera.grab()
        tracker = TipTracker(first, tip, params)
        out = [replace(_first(first, tip, tracker), turned=turned, stated_pixel=stated_pixel)]
        for k in range(1, n):
            f = camera.grab()
            r = tracker.update(f)
            out.append(Located(f.source, None, r.reason, r.detail) if isinstance(r, Lost) else Located(f.source, r))
            if progress is not None:
                progress(n + k, 2 * n)
    finally:
        camera.close()
    return out


def _first(first: Frame, tip: tuple[float, float], tracker: TipTracker) -> Located:
    """The first frame's answer: the tip given (score 1) and the needle's focus there (read beside the tracker,
    which never sees it)."""
    p = tracker.params
    focus = first_frame_focus(first.image, (float(tip[0]), float(tip[1])), tracker.template.shaft,
                              p.focus_from, p.focus_length)
    return Located(first.source, Fix(float(tip[0]), float(tip[1]), 1.0, 0.0), focus=focus)
