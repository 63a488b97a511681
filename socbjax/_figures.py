"""Figures of a compression path: force–displacement curve with loading and unloading,
network snapshots, strand-end forces against displacement (paper Fig. 7c) and the strand-end
force distribution at four stages of loading (paper Fig. 7d).  Units: µm, pN.

Figures are drawn with matplotlib's Agg canvas (``matplotlib.figure.Figure`` + ``FigureCanvasAgg``),
not through pyplot: nothing opens a window, the global backend is left alone and figures need
no ``plt.close``.  Every ``plot_*`` function draws into ``ax`` when given (a 3D axes for 3D
snapshots) and returns the Figure; :func:`save_figures` writes PNGs atomically.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from ._io import atomic_path
from ._result import CompressionResult

__all__ = [
    "loading_regimes",
    "plot_end_forces",
    "plot_force_curve",
    "plot_snapshots",
    "plot_strand_forces",
    "save_figures",
    "snapshot_steps",
]

_LIMIT_MARKERS = {"force_maximum": "v", "force_minimum": "^", "fold": "D", "bifurcation": "*"}
_STEP_MARKERS = "osD^v<>ph"


def _new_axes(ax, three_d: bool = False):
    """(figure, axes): ``ax`` and its figure, or a new Agg figure with one axes."""
    if ax is not None:
        if three_d and getattr(ax, "name", "") != "3d":
            raise ValueError("a 3D network needs a 3D axes: fig.add_subplot(projection='3d')")
        return ax.figure, ax
    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot(projection="3d" if three_d else None)


def _colours(n: int) -> list:
    if n <= 10:
        return [f"C{i}" for i in range(n)]
    return list(matplotlib.colormaps["viridis"](np.linspace(0.0, 0.9, n)))


def _check_steps(result: CompressionResult, steps) -> list[int]:
    """Steps as non-negative indices (negative ones count from the end)."""
    k = result.n_steps
    if k == 0:
        raise ValueError("the result has no recorded steps to plot")
    out = []
    for s in np.atleast_1d(np.asarray(steps)).tolist():
        if int(s) != s or not -k <= s < k:
            raise IndexError(f"step {s!r} is not a recorded step (0..{k - 1})")
        out.append(int(s) % k)
    return out


def _step_label(result: CompressionResult, k: int) -> str:
    """"u = … µm, F = … pN", with round-off noise (below 1e-6 of the path's range) shown as 0."""

    def number(values, x):
        return f"{0.0 if abs(x) <= 1e-6 * np.max(np.abs(values)) else x:.3g}"

    return f"u = {number(result.displacement, result.displacement[k])} µm, F = {number(result.force, result.force[k])} pN"


def snapshot_steps(result: CompressionResult) -> list[int]:
    """Default snapshot steps, in path order: the start, the peak force, the largest
    displacement and the end; where these coincide (no unloading) the set is topped up to
    four with the steps farthest (in index) from those already chosen."""
    _check_steps(result, [0])
    k = result.n_steps
    chosen = list(dict.fromkeys([0, int(np.argmax(result.force)), int(np.argmax(result.displacement)), k - 1]))
    while len(chosen) < min(4, k):
        distance = np.min(np.abs(np.arange(k)[:, None] - np.array(chosen)[None, :]), axis=1)
        chosen.append(int(np.argmax(distance)))
    return sorted(chosen)


def loading_regimes(result: CompressionResult) -> dict[str, int]:
    """Up to four loading steps (phase ≤ 1), from the force curve, as ``{name: step}``.

    With F₀ the force at the first loading step and F_p the peak (largest) loading force:
    "pre-stress" is the first step whose force rise F − F₀ reaches 10 % of F_p − F₀;
    "linear" the step before the peak whose rise is closest to 50 %; "peak" the peak;
    "collapse" the step of least force after the peak (omitted if the peak is the last
    loading step).  If the force never rises above F₀, "pre-stress" is the first step.
    Steps that coincide are listed once, under the first name.
    """
    _check_steps(result, [0])
    idx = np.flatnonzero(result.phase <= 1)
    if idx.size == 0:
        raise ValueError("the result has no loading steps (phase ≤ 1)")
    F = np.asarray(result.force[idx], dtype=float)
    p = int(np.argmax(F))
    rise = F[: p + 1] - F[0]
    top = rise[-1]
    picks = {
        "pre-stress": int(np.argmax(rise >= 0.1 * top)) if top > 0 else 0,
        "linear": int(np.argmin(np.abs(rise - 0.5 * top))) if top > 0 else 0,
        "peak": p,
    }
    if p + 1 < F.size:
        picks["collapse"] = p + 1 + int(np.argmin(F[p + 1 :]))
    regimes: dict[str, int] = {}
    for name, j in picks.items():
        if int(idx[j]) not in regimes.values():
            regimes[name] = int(idx[j])
    return regimes


def plot_force_curve(result: CompressionResult, ax=None) -> Figure:
    """Probe force F (pN, compressive positive) against probe displacement u (µm).

    Loading (phase ≤ 1) solid blue, unloading (phase 2, from the last loading step) dashed red;
    steps flagged unstable (``~result.stable``: sign(det J) differs from the start's) as
    hollow black circles; limit points as markers per kind, annotated with their kind.
    """
    fig, ax = _new_axes(ax)
    u, F = np.asarray(result.displacement), np.asarray(result.force)
    loading, unloading = result.loading, result.unloading
    ax.plot(u[loading], F[loading], "-", color="C0", lw=1.5, label="loading")
    if unloading.any():
        ax.plot(u[unloading], F[unloading], "--", color="C3", lw=1.5, label="unloading")
    unstable = ~np.asarray(result.stable, bool)
    if unstable.any():
        ax.plot(u[unstable], F[unstable], "o", ls="none", mfc="none", mec="k", ms=5, label="unstable (sign det J flipped)")
    crossing = result.first_crossing
    if crossing is not None:  # no contact model yet: mark where the path stops being physical
        ax.axvspan(crossing.displacement, float(u.max()), color="0.88", zorder=0,
                   label="nodes beyond surface/probe (no contact model)")
    kinds = list(dict.fromkeys(p.kind for p in result.limit_points))
    for kind in kinds:
        points = [p for p in result.limit_points if p.kind == kind]
        marker = _LIMIT_MARKERS.get(kind, "X")
        ax.plot([p.displacement for p in points], [p.force for p in points], marker, ls="none", color="C2", ms=7,
                label=kind.replace("_", " "))
        for p in points:
            ax.annotate(kind.replace("_", " "), (p.displacement, p.force), textcoords="offset points",
                        xytext=(4, 6), fontsize=7)
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("probe force F (pN, compressive +)")
    ax.set_title("force–displacement")
    ax.legend(fontsize=8)
    return fig


def _chain_order(segments: np.ndarray) -> np.ndarray:
    """Node indices tracing the segments as polylines (consecutive segments sharing a node
    join), −1 between polylines (indexes an appended NaN row)."""
    order: list[int] = []
    previous_end = None
    for a, b in segments.tolist():
        if a != previous_end:
            if order:
                order.append(-1)
            order.append(a)
        order.append(b)
        previous_end = b
    return np.asarray(order, dtype=int)


def plot_snapshots(result: CompressionResult, steps=None, ax=None) -> Figure:
    """Network shapes (µm) at ``steps`` (default :func:`snapshot_steps`), one colour per step,
    each segment drawn as the straight chord between its nodes (``positions[k][segments]``);
    probe nodes as filled squares, strand ends (``result.end_nodes``) as hollow circles.
    3D axes for a 3D network (``ax`` must then be 3D), 2D otherwise; equal aspect."""
    net = result.network
    steps = snapshot_steps(result) if steps is None else _check_steps(result, steps)
    three_d = net.dim == 3
    fig, ax = _new_axes(ax, three_d)
    order = _chain_order(np.asarray(net.segments))
    probe = np.flatnonzero(np.asarray(net.probe))
    ends = np.asarray(result.end_nodes, dtype=int)
    for j, (colour, k) in enumerate(zip(_colours(len(steps)), steps)):
        pos = np.asarray(result.positions[k], dtype=float)
        lines = np.vstack([pos, np.full((1, net.dim), np.nan)])[order]
        ax.plot(*lines.T, "-", color=colour, lw=1.2, label=_step_label(result, k))
        if probe.size:
            ax.plot(*pos[probe].T, "s", ls="none", color=colour, mec="k", ms=6, label=None if j else "probe nodes")
        if ends.size:
            ax.plot(*pos[ends].T, "o", ls="none", mfc="none", mec=colour, ms=5, label=None if j else "strand ends")
    ax.set_xlabel("x (µm)")
    ax.set_ylabel("y (µm)")
    if three_d:
        ax.set_zlabel("z (µm)")
        ax.set_aspect("equal")
    else:
        ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("network shapes")
    handles, names = ax.get_legend_handles_labels()
    first = [i for i, name in enumerate(names) if name.startswith("u = ")]  # steps, then markers
    order = first + [i for i in range(len(names)) if i not in first]
    ax.legend([handles[i] for i in order], [names[i] for i in order], fontsize=7, loc="upper left",
              bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    return fig


def plot_end_forces(result: CompressionResult, steps=None, ax=None) -> Figure:
    """Paper Fig. 7d: the axial force (pN, compressive positive) on every strand end against
    the strand-end index 0..E−1 (into ``result.end_nodes``), one marker per step.  Default
    steps: the loading regimes of :func:`loading_regimes` (pre-stress, linear, peak, collapse)."""
    if steps is None:
        labelled = [(f"{name}: ", k) for name, k in loading_regimes(result).items()]
    else:
        labelled = [("", k) for k in _check_steps(result, steps)]
    fig, ax = _new_axes(ax)
    x = np.arange(result.end_forces.shape[1])
    markers = itertools.cycle(_STEP_MARKERS)
    for colour, marker, (name, k) in zip(_colours(len(labelled)), markers, labelled):
        ax.plot(x, result.end_forces[k], marker, ls="none", mfc="none", mec=colour, ms=6,
                label=name + _step_label(result, k))
    ax.axhline(0.0, color="0.6", lw=0.8, zorder=0)
    ax.set_xlim(-0.5, max(len(x), 1) - 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("strand end (index into end_nodes)")
    ax.set_ylabel("end force (pN, compressive +)")
    ax.set_title("strand-end forces")
    ax.legend(fontsize=8)
    return fig


def plot_strand_forces(result: CompressionResult, strands=None, ax=None) -> Figure:
    """Paper Fig. 7c: the probe force and strand-end forces (pN, compressive positive) against
    probe displacement (µm) over the loading steps (phase ≤ 1).  ``strands``: strand-end
    indices into ``result.end_nodes`` (default: the 6 with the largest force range)."""
    loading = result.loading
    u = np.asarray(result.displacement)[loading]
    ends = np.asarray(result.end_forces)[loading]
    n_ends = ends.shape[1]
    if strands is None:
        span = np.ptp(ends, axis=0) if ends.size else np.zeros(n_ends)
        strands = np.argsort(-span, kind="stable")[:6]
    strands = [int(j) for j in np.atleast_1d(np.asarray(strands, dtype=int))]
    if any(not 0 <= j < n_ends for j in strands):
        raise IndexError(f"strand-end indices {strands} outside 0..{n_ends - 1} (indices into result.end_nodes)")
    fig, ax = _new_axes(ax)
    ax.plot(u, np.asarray(result.force)[loading], "-", color="k", lw=2.0, label="probe")
    for colour, j in zip(_colours(len(strands)), strands):
        ax.plot(u, ends[:, j], "-", color=colour, lw=1.0, label=f"end {j} (node {int(result.end_nodes[j])})")
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("force (pN, compressive +)")
    ax.set_title("probe and strand-end forces (loading)")
    ax.legend(fontsize=7)
    return fig


def save_figures(result: CompressionResult, out_dir, *, steps=None, dpi: int = 150) -> list[Path]:
    """Write force_curve.png, snapshots.png, end_forces.png and strand_forces.png into
    ``out_dir`` (created with its parents if needed), each atomically (temporary file, then
    ``os.replace``); returns their paths.  ``steps`` is passed to :func:`plot_snapshots` and
    :func:`plot_end_forces`."""
    out = Path(out_dir).expanduser()
    out.mkdir(parents=True, exist_ok=True)
    makers = {
        "force_curve": lambda: plot_force_curve(result),
        "snapshots": lambda: plot_snapshots(result, steps),
        "end_forces": lambda: plot_end_forces(result, steps),
        "strand_forces": lambda: plot_strand_forces(result),
    }
    paths = []
    for name, make in makers.items():
        fig = make()

        def write(tmp: Path, fig=fig) -> None:
            fig.savefig(tmp, format="png", dpi=dpi, bbox_inches="tight")

        paths.append(atomic_path(out / f"{name}.png", write))
    return paths
