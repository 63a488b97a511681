"""Figures (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._shape import filament_curve  # noqa: E402

__all__ = ["plot_shapes", "plt"]


def plot_shapes(ax, items, *, plane=(0, 1)):
    """Draw filament shapes on ``ax``.

    ``items``: iterable of (label, solution, network, style dict).  SOCB solutions are drawn
    as the smooth curve of their angle polynomials, with nodes marked.
    """
    i, j = plane
    for label, solution, network, style in items:
        curve = filament_curve(solution, network)
        xy = np.concatenate([c for c in curve], axis=0)
        (line,) = ax.plot(xy[:, i], xy[:, j], label=label, **style)
        nodes = np.asarray(solution.positions)
        ax.plot(nodes[:, i], nodes[:, j], "o", ms=4, color=line.get_color())
    ax.set_aspect("equal")
    ax.set_xlabel("x (µm)")
    ax.set_ylabel("y (µm)")
    return ax
