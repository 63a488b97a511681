"""The matplotlib figures socbjax returns: :func:`new_figure` (no pyplot, no backend change).

Library figures are plain :class:`matplotlib.figure.Figure` objects with an Agg canvas, so they
never touch pyplot's global state or the user's backend.  Such a figure is not registered with
pyplot, so ``plt.show()`` does not show it and Jupyter's inline backend only shows it once pyplot
has drawn something; :class:`DisplayFigure` therefore renders itself for IPython
(``_repr_png_``): the last value of a notebook cell, or ``display(fig)``, shows the image.
"""

from __future__ import annotations

import io

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["DisplayFigure", "new_figure"]


class DisplayFigure(Figure):
    """A :class:`~matplotlib.figure.Figure` that IPython/Jupyter displays as a PNG."""

    def _repr_png_(self) -> bytes:
        buffer = io.BytesIO()
        self.savefig(buffer, format="png", dpi=100, bbox_inches="tight")
        return buffer.getvalue()


def new_figure(figsize: tuple[float, float], *, layout: str | None = "constrained") -> DisplayFigure:
    """A new figure of ``figsize`` inches with an Agg canvas (ready for ``savefig``)."""
    fig = DisplayFigure(figsize=figsize, layout=layout)
    FigureCanvasAgg(fig)
    return fig
