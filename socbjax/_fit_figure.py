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
    chi2, noise = getattr(result, "chi2_reduced", float("nan")), getattr(result, "noise", float("nan"))
    if np.isfinite(chi2):
        lines.append(f"χ²_red = {chi2:.3g}" + (f" (noise {noise:.3g} pN)" if np.isfinite(noise) else ""))
    top.text(0.98, 0.80, "\n".join(lines), transform=top.transAxes, ha="right", va="top", fontsize="small",
             bbox={"boxstyle": "round,pad=0.35", "fc": "white", "ec": "0.75", "alpha": 0.9})
    head = f"{title}: " if title else ""
    method = _OPTIMIZERS.get(result.optimizer, result.optimizer)
    top.set_title(f"{head}{result.model} model fitted by {method}" + ("" if result.identifiable else " — NOT IDENTIFIABLE")
                  + ("" if result.converged else " — NOT CONVERGED")
                  + (" — MISFIT" if getattr(result, "misfit", False) else ""), fontsize="medium")
    bottom.axhline(0.0, color="0.6", lw=0.8)
    bottom.plot(c, result.residuals, ".", color="C3")
    bottom.set_xlabel("compression (µm)")
    bottom.set_ylabel("model − data (pN)")
    return fig


def save_fit_figure(result: FitResult, path, *, dpi: int = 150, title: str | None = None) -> Path:
    """Write :func:`plot_fit` as a PNG at ``path``, atomically; returns the path."""
    fig = plot_fit(result, title=title)
    return atomic_path(Path(path).expanduser(), lambda tmp: fig.savefig(tmp, format="png", dpi=dpi, bbox_inches="tight"))


# ----------------------------------------------------------------------------- batch summary
_STIFFNESS_UNIT = "pN·µm²"


def _bins(values: np.ndarray, log: bool, extra: tuple = ()) -> np.ndarray:
    """Histogram bin edges covering ``values`` (and the reference ``extra`` values)."""
    span = np.concatenate([values, np.asarray(extra, float)])
    lo, hi = float(span.min()), float(span.max())
    n = int(np.clip(np.ceil(np.sqrt(values.size)) * 2, 6, 24))
    if log:
        lo, hi = np.log10(lo), np.log10(hi)
        pad = max(0.1 * (hi - lo), 0.15)
        return 10.0 ** np.linspace(lo - pad, hi + pad, n + 1)
    pad = 0.1 * (hi - lo) if hi > lo else max(abs(hi) * 0.1, 1e-12)
    return np.linspace(lo - pad, hi + pad, n + 1)


def plot_batch_summary(batch) -> Figure:
    """The summary of a :func:`socbjax.fit_batch`: one histogram per fitted parameter across
    the fitted curves (converged and not converged stacked; the median marked; stiffnesses
    on a log axis with the literature EI of actin, 0.071 pN·µm²), and χ²_red per curve
    (R² where this socbjax reports no χ²_red)."""
    from ._batch import ACTIN_EI

    free = list(batch.settings.get("free", []))
    rows = batch.rows
    fitted = [r for r in rows if r["status"] != "failed"]
    n_panels = max(len(free), 1)
    fig = new_figure((max(4.2 * n_panels, 7.5), 6.6))
    grid = fig.add_gridspec(2, n_panels, height_ratios=[3, 2])
    for j, name in enumerate(free):
        ax = fig.add_subplot(grid[0, j])
        unit = batch.units.get(name, "")
        good = np.array([r[name] for r in fitted if r["status"] == "converged" and np.isfinite(r[name])], float)
        other = np.array([r[name] for r in fitted if r["status"] != "converged" and np.isfinite(r[name])], float)
        values = np.concatenate([good, other])
        label = name.replace("_", " ") + (f" ({_UNITS.get(unit, unit).strip() or unit})" if unit not in ("", "1") else "")
        ax.set_xlabel(label)
        ax.set_ylabel("curves")
        if values.size == 0:
            ax.text(0.5, 0.5, "no fitted values", transform=ax.transAxes, ha="center", va="center", color="0.4")
            continue
        stiffness = unit == _STIFFNESS_UNIT and np.all(values > 0)
        extra = (ACTIN_EI,) if stiffness else ()
        edges = _bins(values, stiffness, extra)
        ax.hist([good, other], bins=edges, stacked=True, color=["C0", "0.75"], edgecolor="white",
                label=[f"converged ({good.size})", f"not converged ({other.size})"])
        median = float(np.median(values))
        times = f" ({median / ACTIN_EI:.2g} × actin)" if stiffness else ""
        ax.axvline(median, color="k", lw=1.5, label=f"median {median:.3g}{_UNITS.get(unit, ' ' + unit)}{times}")
        ax.set_title(f"fitted {name.replace('_', ' ')} across {_count(values.size, 'curve')}", fontsize="small")
        if stiffness:
            ax.set_xscale("log")
            ax.axvline(ACTIN_EI, color="C3", lw=1.5, ls="--", label=f"actin filament (literature) {ACTIN_EI} {unit}")
        ax.yaxis.get_major_locator().set_params(integer=True)
        handles, labels = ax.get_legend_handles_labels()
        keep = [i for i, t in enumerate(labels) if not t.startswith("not converged (0)")]
        ax.legend([handles[i] for i in keep], [labels[i] for i in keep], fontsize="x-small", loc="best")
    ax = fig.add_subplot(grid[1, :])
    labels = [_short(r, 40 if len(rows) <= 6 else 24) for r in rows]
    chi2 = np.array([r.get("chi2_reduced", np.nan) for r in rows], float)
    use_chi2 = bool(np.any(np.isfinite(chi2)))
    y = chi2 if use_chi2 else np.array([r.get("r_squared", np.nan) for r in rows], float)
    x = np.arange(len(rows))
    colours = ["C0" if r["status"] == "converged" else "0.75" for r in rows]
    heights = np.where(np.isfinite(y), y, 0.0)
    bars = ax.bar(x, heights, color=colours, edgecolor="0.3", lw=0.5)
    misfit = [bool(r.get("misfit")) for r in rows]
    for bar, flagged in zip(bars, misfit, strict=True):
        if flagged:
            bar.set_hatch("//")
    if any(misfit):
        from matplotlib.patches import Patch

        ax.add_artist(ax.legend([Patch(facecolor="C0", hatch="//", edgecolor="0.3")],
                                ["misfit: the model misses the curve's shape"], fontsize="x-small", loc="upper left"))
    for i, r in enumerate(rows):
        if r["status"] == "failed" or not np.isfinite(y[i]):
            ax.text(i, 0.3, "failed" if r["status"] == "failed" else "n/a", transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", rotation=90, fontsize="x-small", color="C3")
    if use_chi2:
        finite = y[np.isfinite(y) & (y > 0)]
        if finite.size and finite.max() / max(finite.min(), 1e-300) > 30:
            ax.set_yscale("log")
            ax.set_ylim(min(0.5, finite.min() / 2), finite.max() * 30)  # room for the legends above the bars
        elif finite.size:
            ax.set_ylim(0, max(1.0, finite.max()) * 1.35)
        ax.axhline(1.0, color="k", lw=0.8, ls="--", label="χ²_red = 1 (residuals at the noise level)")
        ax.set_ylabel("χ²_red")
        ax.legend(fontsize="x-small", loc="upper right")
    else:
        ax.set_ylabel("R² (no χ²_red reported)")
    ax.set_xticks(x, labels, rotation=30 if len(rows) > 3 else 0, ha="right" if len(rows) > 3 else "center",
                  fontsize="small")
    ax.set_xlim(-0.6, len(rows) - 0.4)
    ax.set_title("goodness of fit per curve (grey: not converged)", fontsize="small")
    counts = (sum(r["status"] == "converged" for r in rows), sum(r["status"] == "not converged" for r in rows),
              sum(r["status"] == "failed" for r in rows))
    dim = batch.settings.get("dim")
    fig.suptitle(f"{batch.settings.get('model', 'model')}{f' ({dim}D)' if dim else ''} fitted to "
                 f"{len(rows)} curve{'s' * (len(rows) != 1)}: {counts[0]} converged, {counts[1]} not converged, "
                 f"{counts[2]} failed", fontsize="medium")
    return fig


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'s' * (n != 1)}"


def _short(row: dict, width: int = 28) -> str:
    name = Path(row["file"]).name + (f" #{row['curve_index']}" if row.get("curve_index") else "")
    return name if len(name) <= width else name[: width - 1] + "…"
