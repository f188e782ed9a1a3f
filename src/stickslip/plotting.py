"""One way into matplotlib for every plot the package draws.

Plots are drawn only when asked for (``.plot(ax=None)`` on a result object returns the
Axes, on a figure pyplot does not manage, so nothing is shown implicitly); matplotlib
is an optional extra (``stickslip[plot]``) imported here, lazily, and switched to the
non-interactive Agg backend on a machine without a display, so a plot made in a script
or a test never tries to open a window.
"""

from __future__ import annotations

import os
import sys
from types import ModuleType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["axes", "has_display", "pyplot"]


def has_display() -> bool:
    """Whether a window could be shown (Windows, macOS, or an X11/Wayland display)."""
    return sys.platform in ("win32", "darwin") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def pyplot() -> ModuleType:
    """``matplotlib.pyplot``, on the Agg backend when there is no display.

    Raises
    ------
    ImportError
        With the install hint, if matplotlib is missing.
    """
    try:
        import matplotlib

        if "matplotlib.pyplot" not in sys.modules and not has_display():
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'stickslip[plot]'") from e
    return plt


def axes(ax: Axes | None = None, figsize: tuple[float, float] = (6.0, 4.0)) -> Axes:
    """``ax`` if given, else the Axes of a new figure of ``figsize`` inches."""
    if ax is not None:
        return ax
    try:
        from matplotlib.figure import Figure
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'stickslip[plot]'") from e
    # a Figure pyplot does not manage: returned, never shown implicitly (a notebook shows
    # ``ax.figure`` when asked; a script saves it with ``ax.figure.savefig``)
    # constrained: labels and rotated ticks fit inside the figure (the demo's parameter names were cut off)
    out: Axes = Figure(figsize=figsize, layout="constrained").subplots()
    return out
