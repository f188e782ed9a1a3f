"""What a reader sees of a matplotlib figure: whether a text is drawn whole inside it."""

from __future__ import annotations

from typing import Any


def inside_figure(text: Any) -> bool:
    """Whether a drawn text's box lies within its figure (nothing clipped at the edge); draws the canvas first."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = text.get_figure()
    if not isinstance(fig.canvas, FigureCanvasAgg):  # a Figure pyplot does not manage: drawn as savefig draws it
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    box = text.get_window_extent(fig.canvas.get_renderer())
    w, h = fig.bbox.width + 0.5, fig.bbox.height + 0.5
    return bool(box.x0 >= -0.5 and box.y0 >= -0.5 and box.x1 <= w and box.y1 <= h)
