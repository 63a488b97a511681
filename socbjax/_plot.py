"""Deformed shapes of static solutions on a matplotlib axes (no global backend changes)."""

from __future__ import annotations

import numpy as np

__all__ = ["plot_shapes"]


def plot_shapes(ax, items, *, plane=(0, 1), points_per_segment: int = 24):
    """Draw filament shapes on ``ax``.

    ``items``: iterable of (label, solution, style dict).  SOCB solutions are drawn as the
    smooth curve of their angle polynomials (:meth:`socbjax.Solution.curve`), jointed ones as
    their rigid bars, with nodes marked.
    """
    i, j = plane
    for label, solution, style in items:
        xy = solution.curve(points_per_segment).polyline()
        (line,) = ax.plot(xy[:, i], xy[:, j], label=label, **style)
        nodes = np.asarray(solution.positions)
        ax.plot(nodes[:, i], nodes[:, j], "o", ms=4, color=line.get_color())
    ax.set_aspect("equal")
    ax.set_xlabel("x (µm)")
    ax.set_ylabel("y (µm)")
    return ax
