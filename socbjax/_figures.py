"""Figures of a compression path (matplotlib, Agg backend): force–compression curve with
loading and unloading, network snapshots, strand-end force curves (paper Fig. 7c) and the
strand-end force scatter (Fig. 7d).  Every function returns its Figure; ``save_figures``
writes PNGs atomically.  Units: µm, pN."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._result import CompressionResult  # noqa: E402

__all__ = ["plot_force_curve", "plot_snapshots", "plot_end_forces", "plot_strand_forces", "save_figures", "regime_steps"]


def _axes(ax, projection=None):
    if ax is not None:
        return ax.figure, ax
    fig = plt.figure(figsize=(6.4, 4.8))
    return fig, fig.add_subplot(111, projection=projection)


def plot_force_curve(result: CompressionResult, ax=None):
    """Probe force (pN, compressive positive) against probe displacement (µm)."""
    fig, ax = _axes(ax)
    load, unload = result.loading, result.unloading
    ax.plot(result.displacement[load], result.force[load], "-", color="C0", label="loading")
    if unload.any():
        ax.plot(result.displacement[unload], result.force[unload], "--", color="C3", label="unloading")
    bad = ~result.stable
    if bad.any():
        ax.plot(result.displacement[bad], result.force[bad], "o", mfc="none", color="k", ms=5, label="unstable (det J sign)")
    for p in result.limit_points:
        ax.annotate(p.kind.replace("_", " "), (p.displacement, p.force), textcoords="offset points", xytext=(4, 6), fontsize=7)
        ax.plot([p.displacement], [p.force], "v" if "max" in p.kind else "^", color="C2", ms=6)
    ax.set_xlabel("probe displacement (µm)")
    ax.set_ylabel("probe force (pN, compressive +)")
    ax.set_title("force–compression")
    ax.legend(fontsize=8)
    return fig


def regime_steps(result: CompressionResult) -> list[int]:
    """Four loading steps for snapshots/scatter: early ('pre-stress', 5 % of the peak
    displacement), mid-rise (half the peak displacement), the force peak, and the largest
    displacement (post-peak / collapse)."""
    idx = np.flatnonzero(result.phase <= 1)
    u, F = result.displacement[idx], result.force[idx]
    peak = int(np.argmax(F))
    picks = [np.argmin(np.abs(u - 0.05 * u[peak])), np.argmin(np.abs(u[: peak + 1] - 0.5 * u[peak])), peak, int(np.argmax(u))]
    return sorted({int(idx[k]) for k in picks})


def plot_snapshots(result: CompressionResult, steps=None, ax=None):
    """Network shapes (segments as straight lines between nodes) at ``steps`` (default
    :func:`regime_steps`); probe nodes as squares, strand ends on the surface as circles."""
    net = result.network
    steps = regime_steps(result) if steps is None else [int(s) for s in steps]
    fig, ax = _axes(ax, "3d" if net.dim == 3 else None)
    seg = np.asarray(net.segments)
    for colour, k in enumerate(steps):
        pos = result.positions[k]
        lines = np.stack([pos[seg[:, 0]], pos[seg[:, 1]]], axis=1)
        for j, line in enumerate(lines):
            label = f"u = {result.displacement[k]:.3g} µm, F = {result.force[k]:.3g} pN" if j == 0 else None
            ax.plot(*line.T, color=f"C{colour}", lw=1.0, label=label)
        probe = np.asarray(net.probe)
        ax.plot(*pos[probe].T, "s", color=f"C{colour}", ms=5)
        ax.plot(*pos[result.end_nodes].T, "o", color=f"C{colour}", ms=3, mfc="none")
    names = ["x (µm)", "y (µm)", "z (µm)"][: net.dim]
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    if net.dim == 3:
        ax.set_zlabel(names[2])
        ax.invert_zaxis()  # probe on top, surface below
    else:
        ax.set_aspect("equal")
        ax.invert_yaxis()
    ax.legend(fontsize=7, loc="best")
    ax.set_title("network snapshots")
    return fig


def plot_end_forces(result: CompressionResult, steps=None, ax=None):
    """Paper Fig. 7d: axial force on every strand end (pN, compressive +) at ``steps``
    (default :func:`regime_steps`); x is the strand-end index."""
    steps = regime_steps(result) if steps is None else [int(s) for s in steps]
    fig, ax = _axes(ax)
    x = np.arange(result.end_forces.shape[1])
    for marker, k in zip("osD^v<>", steps):
        ax.plot(x, result.end_forces[k], marker, mfc="none", ls="none", label=f"u = {result.displacement[k]:.3g} µm")
    ax.axhline(0.0, color="0.7", lw=0.8)
    ax.set_xlabel("strand end (index)")
    ax.set_ylabel("end force (pN, compressive +)")
    ax.set_title("strand-end forces")
    ax.legend(fontsize=8)
    return fig


def plot_strand_forces(result: CompressionResult, strands=None, ax=None):
    """Paper Fig. 7c: probe force and strand-end force curves against displacement (loading);
    default strand ends: the 6 with the largest force range."""
    fig, ax = _axes(ax)
    load = result.phase <= 1
    u = result.displacement[load]
    ax.plot(u, result.force[load], "k-", lw=2, label="probe")
    ends = result.end_forces[load]
    if strands is None:
        strands = np.argsort(-(ends.max(axis=0) - ends.min(axis=0)))[:6] if ends.size else []
    for j in strands:
        ax.plot(u, ends[:, j], lw=1, label=f"end {j} (node {result.end_nodes[j]})")
    ax.set_xlabel("probe displacement (µm)")
    ax.set_ylabel("force (pN, compressive +)")
    ax.set_title("probe and strand-end forces (loading)")
    ax.legend(fontsize=7)
    return fig


def _save_atomic(fig, path: Path) -> Path:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".png")
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=130, bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
        plt.close(fig)
    return path


def save_figures(result: CompressionResult, out_dir, *, steps=None) -> list[Path]:
    """Write force_curve.png, snapshots.png, strand_forces.png, end_forces.png into
    ``out_dir`` (created if needed); returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = {
        "force_curve": plot_force_curve(result),
        "snapshots": plot_snapshots(result, steps),
        "strand_forces": plot_strand_forces(result),
        "end_forces": plot_end_forces(result, steps),
    }
    return [_save_atomic(fig, out / f"{name}.png") for name, fig in figures.items()]
