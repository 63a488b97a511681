"""Figure of a fit: data, fitted model curve and residuals (pN against µm of compression).

Drawn on matplotlib's Agg canvas (no pyplot, no window); :func:`save_fit_figure` writes the
PNG atomically.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ._fit import FitResult
from ._io import atomic_path

__all__ = ["plot_fit", "save_fit_figure"]


def plot_fit(result: FitResult, *, title: str | None = None) -> Figure:
    """Two panels: data points and the fitted curve (top), residuals model − data (bottom),
    with the fitted values ± standard errors in the legend; ``title`` prefixes the title."""
    fig = Figure(figsize=(6.4, 5.6), layout="constrained")
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    c = result.compression
    top.plot(c, result.force, "o", ms=3, color="0.45", label="data")
    label = ", ".join(f"{n} = {result.values[n]:.4g} ± {result.standard_errors[n]:.2g} {result.units[n]}" for n in result.names)
    top.plot(c, result.model_force, "-", color="C0", lw=2, label=f"fit: {label}")
    top.set_ylabel("force (pN)")
    top.legend(fontsize="small", loc="best")
    head = f"{title}: " if title else ""
    top.set_title(f"{head}{result.model} fit ({result.optimizer}), rms {result.rms:.3g} pN"
                  + ("" if result.identifiable else " — NOT IDENTIFIABLE"), fontsize="medium")
    bottom.axhline(0.0, color="0.6", lw=0.8)
    bottom.plot(c, result.residuals, ".", color="C3")
    bottom.set_xlabel("compression (µm)")
    bottom.set_ylabel("model − data (pN)")
    return fig


def save_fit_figure(result: FitResult, path, *, dpi: int = 150, title: str | None = None) -> Path:
    """Write :func:`plot_fit` as a PNG at ``path``, atomically; returns the path."""
    fig = plot_fit(result, title=title)
    return atomic_path(Path(path).expanduser(), lambda tmp: fig.savefig(tmp, format="png", dpi=dpi, bbox_inches="tight"))
