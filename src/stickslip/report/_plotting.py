"""The panel grid every multi-panel figure uses (matplotlib through :mod:`stickslip.plotting`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..plotting import pyplot

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

LINE_STYLES = ("-", "--", "-.", ":")
"""Line styles cycled beside the colours: series told apart by more than hue."""

AxesArray = NDArray[np.object_]
"""A 2-D array of matplotlib Axes, ``[row, column]``."""


def panel_grid(nrows: int, ncols: int, ax: Axes | Any | None, width: float = 5.5, height: float = 4.2) -> AxesArray:
    """A ``(nrows, ncols)`` array of Axes: new ones in a new figure, or ``ax`` checked for its size."""
    if ax is None:
        plt = pyplot()
        _fig, axes = plt.subplots(
            nrows, ncols, figsize=(width * ncols, height * nrows), squeeze=False, constrained_layout=True
        )
        return np.asarray(axes, dtype=object)
    axes = np.asarray(ax, dtype=object).reshape(-1)
    if axes.size != nrows * ncols:
        raise ValueError(f"this figure needs {nrows} x {ncols} Axes, got {axes.size}")
    return axes.reshape(nrows, ncols)


def key(value: float, tol: float) -> float:
    """``value`` rounded to a multiple of ``tol``: poses typed by hand still group together."""
    return round(value / tol) * tol


ANGLE_TOL = 1e-3
"""rad: two angles closer than this are one pose."""
LENGTH_TOL = 1e-5
"""m: two extensions q3 closer than this are one pose."""
