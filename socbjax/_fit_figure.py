"""Figure of a fit: data, fitted model curve and residuals (pN against µm of compression).

Drawn on matplotlib's Agg canvas (no pyplot, no window); :func:`save_fit_figure` writes the
PNG atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ._fit import FitResult
from ._io import atomic_path
from ._mplfigure import new_figure

__all__ = ["plot_fit", "save_fit_figure"]

_OPTIMIZERS = {"lm": "Levenberg–Marquardt", "adam": "Adam", "lbfgs": "L-BFGS"}
_UNITS = {"deg": "°", "1": ""}


def _value(result: FitResult, name: str, error: bool = True) -> str:
    """"name = value ± error unit", the name spelt out and degrees as °."""
    unit = _UNITS.get(result.units.get(name, "1"), " " + result.units.get(name, ""))
    spread = f" ± {result.standard_errors[name]:.2g}" if error else ""
    return f"{name.replace('_', ' ')} = {result.values[name]:.4g}{spread}{unit}"


def plot_fit(result: FitResult, *, title: str | None = None) -> Figure:
    """Two panels: the data points and the model at the fitted values, evaluated at the data's
    compressions (top; the fitted values ± Gauss–Newton standard errors, the fixed values and
    R² in a box), and the residuals model − data (bottom); ``title`` prefixes the title."""
    fig = new_figure((6.6, 5.6))
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    c = np.asarray(result.compression)
    top.plot(c, result.force, "o", ms=3.5, color="0.45", label="data")
    # the model is known at the data's compressions only: a line through markers, not a smooth curve
    top.plot(c, result.model_force, "-", color="C0", lw=1.8, marker=".", ms=4, label="model at the fitted values")
    top.set_ylabel("force (pN)")
    top.legend(fontsize="small", loc="upper right")
    lines = [_value(result, n) for n in result.names]
    fixed = [n for n in result.values if n not in result.names]
    if fixed:
        lines.append("fixed: " + ", ".join(_value(result, n, error=False) for n in fixed))
    lines.append(f"R² = {result.r_squared:.3f}, rms {result.rms:.3g} pN, {len(c)} points")
    top.text(0.98, 0.80, "\n".join(lines), transform=top.transAxes, ha="right", va="top", fontsize="small",
             bbox={"boxstyle": "round,pad=0.35", "fc": "white", "ec": "0.75", "alpha": 0.9})
    head = f"{title}: " if title else ""
    method = _OPTIMIZERS.get(result.optimizer, result.optimizer)
    top.set_title(f"{head}{result.model} model fitted by {method}" + ("" if result.identifiable else " — NOT IDENTIFIABLE")
                  + ("" if result.converged else " — NOT CONVERGED"), fontsize="medium")
    bottom.axhline(0.0, color="0.6", lw=0.8)
    bottom.plot(c, result.residuals, ".", color="C3")
    bottom.set_xlabel("compression (µm)")
    bottom.set_ylabel("model − data (pN)")
    return fig


def save_fit_figure(result: FitResult, path, *, dpi: int = 150, title: str | None = None) -> Path:
    """Write :func:`plot_fit` as a PNG at ``path``, atomically; returns the path."""
    fig = plot_fit(result, title=title)
    return atomic_path(Path(path).expanduser(), lambda tmp: fig.savefig(tmp, format="png", dpi=dpi, bbox_inches="tight"))
