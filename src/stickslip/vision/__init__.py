"""Seeing the tip: cameras, tip tracking, and the camera against the manipulator (docs/vision.md).

An optional part of stickslip (``pip install 'stickslip[vision]'`` for image files;
``[opencv]`` adds video files and live cameras). Pixel convention everywhere: ``x`` to
the right, ``y`` down, the centre of the top-left pixel at ``(0, 0)``.

* :mod:`.frame`    a :class:`Frame` and the one conversion of pixel data into it
* :mod:`.images`   reading PNG and TIFF files (8/16/32 bit, grey or colour)
* :mod:`.camera`   the :class:`Camera` protocol and camera URLs (``simcam://``, ``files://``,
  ``video://``, ``opencv://``)
* :mod:`.files`    image-file sequences, video files, live OpenCV cameras
* :mod:`.view`     how a camera looks at the rig (optical axis, image axes, projection)
"""

from .camera import Camera, CameraEnded, CameraError, CameraInfo, open_camera, register_camera
from .frame import Frame, ImageError, as_image
from .view import TOP_VIEW, View

__all__ = [
    "Camera",
    "CameraEnded",
    "CameraError",
    "CameraInfo",
    "Frame",
    "ImageError",
    "TOP_VIEW",
    "View",
    "as_image",
    "open_camera",
    "register_camera",
]
