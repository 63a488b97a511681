"""Figures of a compression path: force–displacement curve with loading and unloading,
network snapshots, strand-end forces against displacement (paper Fig. 7c) and the strand-end
force distribution at four stages of loading (paper Fig. 7d).  Units: µm, pN.

Figures are drawn with matplotlib's Agg canvas (``matplotlib.figure.Figure`` + ``FigureCanvasAgg``),
not through pyplot: nothing opens a window, the global backend is left alone and figures need
no ``plt.close``.  Every ``plot_*`` function draws into ``ax`` when given (a 3D axes for 3D
snapshots) and returns the Figure; :func:`save_figures` writes PNGs atomically.  Shapes are
the smooth SOCB curves between nodes (:mod:`socbjax._plot`), planar results on 2D axes.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, MaxNLocator

from ._io import atomic_path
from ._mplfigure import new_figure
from ._plot import (
    DISPLACEMENT_CMAP,
    MAX_SEGMENTS_WITH_NODES,
    chain_index,
    common_limits,
    draw_contacts,
    has_contact,
    obstacle_points,
    draw_planes,
    draw_reference,
    draw_state,
    drawn_axes,
    label_offsets,
    step_curves,
    style_axes,
)
from ._probe import probe_gap
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

_LIMIT_MARKERS = {"force_maximum": "v", "force_minimum": "^", "fold": "D", "bifurcation": "*", "surface_crossing": "X"}
_LIMIT_TEXT = {"force_maximum": "max", "force_minimum": "min", "fold": "fold", "bifurcation": "bifurcation",
               "surface_crossing": "crossing"}
_STEP_MARKERS = "osD^v<>ph"
_PHASE_NAMES = ("settled start", "loading", "unloading")
_PHASE_COLOURS = ("k", "C0", "C3")
POINTS_PER_SEGMENT = 12  # curve points per segment in snapshots: smooth at figure size, cheap for 500 segments


def _new_axes(ax, three_d: bool = False, figsize=(6.4, 4.8)):
    """(figure, axes): ``ax`` and its figure, or a new Agg figure with one axes."""
    if ax is not None:
        if three_d and getattr(ax, "name", "") != "3d":
            raise ValueError("a 3D network needs a 3D axes: fig.add_subplot(projection='3d')")
        return ax.figure, ax
    fig = _figure(figsize)
    return fig, fig.add_subplot(projection="3d" if three_d else None)


def _figure(figsize) -> Figure:
    return new_figure(figsize)


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


def _number(values, x) -> str:
    """``x`` to 3 significant digits, round-off noise (below 1e-6 of the path's range) as 0."""
    return f"{0.0 if abs(x) <= 1e-6 * np.max(np.abs(values)) else x:.3g}"


def _step_label(result: CompressionResult, k: int) -> str:
    """"u = … µm, F = … pN" of step ``k``."""
    return f"u = {_number(result.displacement, result.displacement[k])} µm, F = {_number(result.force, result.force[k])} pN"


def _phase_name(result: CompressionResult, k: int) -> str:
    phase = int(np.asarray(result.phase)[k])
    return _PHASE_NAMES[phase] if 0 <= phase < len(_PHASE_NAMES) else f"phase {phase}"


def _loading_peak(result: CompressionResult) -> int:
    """The step of the largest force on loading (phase ≤ 1; the whole path if none)."""
    force = np.where(np.asarray(result.phase) <= 1, np.asarray(result.force, float), -np.inf)
    return int(np.argmax(force)) if np.isfinite(force).any() else int(np.argmax(result.force))


def snapshot_steps(result: CompressionResult) -> list[int]:
    """Default snapshot steps, in path order: the start, the peak loading force, the loading step
    nearest half the largest displacement, the largest displacement, the unloading step
    nearest half of it and the end (each once); with fewer than four distinct steps the set
    is topped up to four with the steps farthest (in index) from those already chosen."""
    _check_steps(result, [0])
    k = result.n_steps
    u = np.asarray(result.displacement, dtype=float)
    top = int(np.argmax(u))
    chosen = [0, _loading_peak(result), int(np.argmin(np.abs(u[: top + 1] - 0.5 * u[top]))), top]
    if top + 1 < k:  # unloading: the way back
        chosen.append(top + 1 + int(np.argmin(np.abs(u[top + 1:] - 0.5 * u[top]))))
    chosen = list(dict.fromkeys(chosen + [k - 1]))
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


def _initial_jump(result: CompressionResult):
    """(u₀, F_top, Δu) of the near-vertical force rise at the start of loading, or None: the
    force reaches F_top ≥ 30 % of the loading peak within 1 % of the loading travel."""
    idx = np.flatnonzero(np.asarray(result.phase) <= 1)
    u, F = np.asarray(result.displacement, float)[idx], np.asarray(result.force, float)[idx]
    if idx.size < 2 or not (np.all(np.isfinite(u)) and np.all(np.isfinite(F))) or np.ptp(u) <= 0 or F.max() <= 0:
        return None
    near = u - u[0] <= 0.01 * np.ptp(u)
    top = float(F[near].max())
    if top < 0.3 * F.max() or top - F[0] < 0.3 * F.max():
        return None
    reached = int(np.argmax(F >= F[0] + 0.9 * (top - F[0])))
    return float(u[0]), top, float(u[reached] - u[0])


def _annotate_jump(ax, result: CompressionResult) -> None:
    """Explain the vertical segment at u ≈ 0 (why the force jumps with no displacement)."""
    jump = _initial_jump(result)
    if jump is None:
        return
    u0, top, du = jump
    text = (f"vertical rise at u ≈ 0: the probe meets the network settled under its\n"
            f"small perturbation loads; the nearly straight strands cannot shorten\n"
            f"without buckling, so F jumps from 0 to {top:.3g} pN (≈ their buckling load)\n"
            f"within Δu = {du:.1g} µm")
    if result.unloading.any():
        u_end = float(np.asarray(result.displacement)[-1])
        text += (f"; unloading stops at u = {u_end:.2g} µm, as the strands\nstraighten again: the drop back to 0 there "
                 "is too steep for any step size")
    ann = ax.annotate(text, xy=(u0, 0.5 * top), xycoords="data", xytext=(0.08, 0.05), textcoords="axes fraction",
                      fontsize=7, ha="left", va="bottom", color="0.2",
                      arrowprops={"arrowstyle": "->", "color": "0.35", "lw": 0.8, "shrinkB": 2},
                      bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": "0.7", "lw": 0.6, "alpha": 0.9})
    ann.set_gid("initial_jump")
    ann.set_in_layout(False)


def _limit_label(p) -> str:
    return f"{_LIMIT_TEXT.get(p.kind, p.kind)} {p.force:.3g} pN" + (" (unloading)" if p.phase == "unloading" else "")


def _annotate_limit_points(ax, result: CompressionResult, width_fraction: float) -> None:
    """One marker artist per kind (legend entry) and one text label per limit point (gid
    "limit_point"; minima below the curve, the others above, moved apart by
    :func:`socbjax._plot.label_offsets`), each with a short leader from its marker to the label's nearest
    corner; head room above the data keeps the labels of maxima inside the axes."""
    points = list(result.limit_points)
    if not points:
        return
    for kind in dict.fromkeys(p.kind for p in points):
        mine = [p for p in points if p.kind == kind]
        ax.plot([p.displacement for p in mine], [p.force for p in mine], _LIMIT_MARKERS.get(kind, "X"), ls="none",
                color="C2" if kind != "surface_crossing" else "0.3", ms=7, mec="k", mew=0.5, label=kind.replace("_", " "))
    ax.autoscale_view()
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + 0.12 * (hi - lo))
    size = 7.0  # points
    labels = [_limit_label(p) for p in points]
    offsets = label_offsets(ax, [(p.displacement, p.force) for p in points], labels,
                             [-8.0 - 1.3 * size if p.kind == "force_minimum" else 8.0 for p in points], size, width_fraction)
    for p, label, dy in zip(points, labels, offsets):
        ann = ax.annotate(label, (p.displacement, p.force), textcoords="offset points", xytext=(5, dy), fontsize=size,
                          va="bottom", arrowprops={"arrowstyle": "-", "color": "0.5", "lw": 0.5, "shrinkA": 0, "shrinkB": 3,
                                                   "relpos": (0.0, 1.0 if dy < 0 else 0.0)})
        ann.set_gid("limit_point")
        ann.set_in_layout(False)  # inside the axes: the layout must not shrink the axes for it


def plot_force_curve(result: CompressionResult, ax=None) -> Figure:
    """Probe force F (pN, compressive positive) against probe displacement u (µm).

    The settled start (black dot), loading (phase 1, solid blue), unloading (phase 2, from the
    last loading step, dashed red); steps flagged unstable (``~result.stable``: sign(det J)
    differs from the start's) as hollow black circles; limit points as markers per kind, each
    labelled once with its kind and force; the path beyond the first surface crossing shaded;
    the near-vertical rise at u ≈ 0 explained; with contact, the number of contacts carrying
    force per step on a second (right) axis.  Legend entries in path order, outside the axes.
    """
    own = ax is None
    fig, ax = _new_axes(ax, figsize=(7.6, 4.6))
    u, F = np.asarray(result.displacement), np.asarray(result.force)
    loading, unloading = result.loading, result.unloading
    ax.plot(u[:1], F[:1], "o", color="k", ms=4, label="settled start (probe free, F = 0)")
    ax.plot(u[loading], F[loading], "-", color="C0", lw=1.5, label="loading")
    if unloading.any():
        ax.plot(u[unloading], F[unloading], "--", color="C3", lw=1.5, label="unloading")
    unstable = ~np.asarray(result.stable, bool)
    if unstable.any():
        ax.plot(u[unstable], F[unstable], "o", ls="none", mfc="none", mec="k", ms=5, label="unstable (sign det J flipped)")
    contact = has_contact(result)
    if contact:  # contacts carrying force per step, on a second axis
        twin = ax.twinx()
        twin.step(u, np.asarray(result.contact_count), where="mid", color="0.45", lw=1.0, zorder=1)
        twin.set_ylabel("contacts carrying force", color="0.35")
        twin.tick_params(axis="y", colors="0.35")
        twin.set_ylim(bottom=0)
        twin.yaxis.get_major_locator().set_params(integer=True)
        ax.plot([], [], color="0.45", lw=1.0, label="contact count (right axis)")
    crossing = result.first_crossing
    if crossing is not None:  # computed without contact: mark where the path stops being physical
        ax.axvspan(crossing.displacement, float(np.nanmax(u)), color="0.88", zorder=0,
                   label="beyond the first surface/probe crossing\n(computed without contact: not physical)")
    _annotate_limit_points(ax, result, 0.55 if own else ax.get_position().width)  # own figure: the legend takes ≤ 45 %
    _annotate_jump(ax, result)
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("probe force F (pN, compressive +)")
    ax.set_title("force–displacement")
    handles, names = ax.get_legend_handles_labels()
    # path order: start, loading, the events as they occur, unloading; then the flags
    rank = {"settled start (probe free, F = 0)": 0, "loading": 1, "unloading": 3}
    kinds = [p.kind.replace("_", " ") for p in result.limit_points]
    key = [(rank.get(n, 2 if n in kinds else 4), kinds.index(n) if n in kinds else 0) for n in names]
    order = sorted(range(len(names)), key=lambda i: key[i])
    ax.legend([handles[i] for i in order], [names[i] for i in order], fontsize=8, loc="upper left",
              bbox_to_anchor=(1.16 if contact else 1.02, 1.0), borderaxespad=0.0)
    return fig


def _snapshot_legend(fig, result, three_d: bool) -> None:
    """One legend for all panels, below them."""
    phases = np.asarray(result.phase)
    handles = [] if three_d else [Line2D([], [], color=c, lw=1.4, label=name)
                                  for j, (name, c) in enumerate(zip(_PHASE_NAMES, _PHASE_COLOURS)) if (phases == j).any()]
    if not three_d:
        handles.append(Line2D([], [], color="0.7", lw=1.0, ls="--", label="as built"))
    if result.network.n_segments <= MAX_SEGMENTS_WITH_NODES:
        handles.append(Line2D([], [], color="0.3", marker=".", ms=5, ls="none", label="nodes"))
    handles.append(Line2D([], [], color="0.5", marker="s", mec="k", ls="none", label="probe nodes"))
    handles.append(Line2D([], [], color="0.3", marker="o", mfc="white", ls="none", label="strand ends"))
    if not three_d:
        handles.append(Line2D([], [], color="0.1", lw=2.5, label="probe plane"))
        handles.append(Line2D([], [], color="0.55", lw=2.5, label="surface"))
    if has_contact(result):
        handles.append(Line2D([], [], color="C3", marker="x", mew=1.5, ls="none", label="contacts"))
        obstacles = result.parameters.get("contact", {})
        if not three_d and (obstacles.get("planes") or obstacles.get("spheres")):
            handles.append(Line2D([], [], color="0.35", lw=2.0, label="obstacles"))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 5), fontsize=8, frameon=False)


def _panel_grid(n: int, limits, three_d: bool):
    """(rows, columns, figure size in inches) of ``n`` snapshot panels."""
    ncols = min(n, 3)
    nrows = -(-n // ncols)
    if three_d:
        return nrows, ncols, (4.0 * ncols + 1.0, 3.8 * nrows + 0.9)
    tall = (limits[1][1] - limits[1][0]) / max(limits[0][1] - limits[0][0], 1e-12)
    return nrows, ncols, (3.0 * ncols, (float(np.clip(3.0 * tall, 1.4, 4.5)) + 0.6) * nrows + 0.9)


def _small_multiples(result, steps, curves, start, index, coords) -> Figure:
    """One panel per step, shared axes, titles in path order; 2D panels coloured by phase
    with the as-built network, surface and probe plane, 3D ones coloured by the displacement
    from the settled start (the shape changes are hard to see in a 3D perspective)."""
    net, three_d = result.network, len(coords) == 3
    nodes = np.asarray(result.positions, float)[steps][..., list(coords)].reshape(-1, len(coords))
    limits = common_limits(np.concatenate([curves.reshape(-1, len(coords)), nodes, obstacle_points(result, coords)]))
    nrows, ncols, size = _panel_grid(len(steps), limits, three_d)
    fig = _figure(size)
    if three_d:  # constrained layout does not see the z labels of 3D axes: leave room for them
        fig.get_layout_engine().set(wspace=0.12, w_pad=0.1, hspace=0.1, h_pad=0.15)
    moved = np.linalg.norm(curves - start[None], axis=-1)  # same σ on the same segment: the same material point
    norm = Normalize(0.0, max(float(np.nanmax(moved)) if np.isfinite(moved).any() else 0.0, 1e-12))
    gap, first = probe_gap(net) if np.any(np.asarray(net.probe)) else np.inf, None
    for j, k in enumerate(steps):
        share = {} if three_d or first is None else {"sharex": first, "sharey": first}
        ax = fig.add_subplot(nrows, ncols, j + 1, **({"projection": "3d"} if three_d else share))
        first = first or ax
        phase = int(np.asarray(result.phase)[k])
        if not three_d:
            draw_reference(ax, net, coords)
            draw_planes(ax, net, float(result.displacement[k]), gap, coords, np.array(limits).T)
        draw_state(ax, net, result.positions[k], result.end_nodes, curves[j], index, coords,
                   _PHASE_COLOURS[phase] if 0 <= phase < len(_PHASE_COLOURS) else "C4",
                   moved=moved[j] if three_d else None, norm=norm)
        draw_contacts(ax, result, k, coords)
        style_axes(ax, coords, limits)
        peak = ", peak force" if k == _loading_peak(result) else ""
        ax.set_title(f"step {k}, {_phase_name(result, k)}{peak}\n{_step_label(result, k)}", fontsize=8)
    if not three_d:  # shared axes: tick labels on the outer panels only (bottom: no panel below)
        for j, ax in enumerate(fig.axes):
            bottom, left = j + ncols >= len(steps), j % ncols == 0
            ax.tick_params(labelbottom=bottom, labelleft=left)
            ax.set_xlabel(ax.get_xlabel() if bottom else "")
            ax.set_ylabel(ax.get_ylabel() if left else "")
    else:
        fig.colorbar(ScalarMappable(norm=norm, cmap=DISPLACEMENT_CMAP), ax=fig.axes, shrink=0.6, pad=0.04,
                     label="displacement from the settled start (µm)")
    what = "coloured by displacement" if three_d else "coloured by phase"
    fig.suptitle(f"network shapes in path order (smooth SOCB curves between nodes, {what})", fontsize=10)
    _snapshot_legend(fig, result, three_d)
    return fig


def plot_snapshots(result: CompressionResult, steps=None, ax=None, *, points_per_segment: int = POINTS_PER_SEGMENT) -> Figure:
    """Network shapes (µm) at ``steps`` (default :func:`snapshot_steps`), in path order, each
    drawn as the smooth SOCB curve between its nodes (``points_per_segment`` points per
    segment; node dots on networks of up to 60 segments, probe nodes as filled squares, strand
    ends, ``result.end_nodes``, as hollow circles).

    Without ``ax``: small multiples, one panel per step, shared axes and equal aspect, titled
    "step k, phase" and "u = … µm, F = … pN".  Planar panels are coloured by phase and show
    the as-built network (grey, dashed), the surface and the probe plane at that step; 3D
    panels are coloured by each point's displacement from the settled start (colour bar, µm).
    With ``ax``: all steps overlaid on it, one colour per step, the legend in path order.  With
    contact, the contact points that carry force are red crosses.  A
    planar result (2D, or 3D with one coordinate constant throughout) is drawn on 2D axes, a
    spatial one on 3D axes (``ax`` must then be 3D)."""
    net = result.network
    steps = snapshot_steps(result) if steps is None else sorted(dict.fromkeys(_check_steps(result, steps)))
    coords = drawn_axes(result)
    P = int(points_per_segment)
    curves = step_curves(result, [0] + steps, P)[..., list(coords)]  # row 0: the settled start
    index = chain_index(np.asarray(net.segments), P)
    if ax is None:
        return _small_multiples(result, steps, curves[1:], curves[0], index, coords)
    fig, ax = _new_axes(ax, len(coords) == 3)
    for colour, k, curve in zip(_colours(len(steps)), steps, curves[1:]):
        draw_state(ax, net, result.positions[k], result.end_nodes, curve, index, coords, colour,
                   label=f"step {k}, {_phase_name(result, k)}: {_step_label(result, k)}")
        draw_contacts(ax, result, k, coords)
    nodes = np.asarray(result.positions, float)[steps][..., list(coords)].reshape(-1, len(coords))
    style_axes(ax, coords, common_limits(np.concatenate([curves[1:].reshape(-1, len(coords)), nodes])))
    ax.set_title("network shapes (smooth SOCB curves)")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    return fig


def _end_ticks(ax, end_nodes) -> None:
    """x ticks at strand-end positions 0..E−1 labelled with their node numbers: every end up
    to 40 ends (turned upright beyond 12 so that they do not overlap), else a subset."""
    nodes = np.asarray(end_nodes, dtype=int)
    if len(nodes) <= 40:
        ax.set_xticks(np.arange(len(nodes)), [str(n) for n in nodes], rotation=90 if len(nodes) > 12 else 0)
        ax.tick_params(axis="x", labelsize=7 if len(nodes) > 12 else 9)
        return
    ax.xaxis.set_major_locator(MaxNLocator(nbins=12, integer=True))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{nodes[round(x)]}" if 0 <= round(x) < len(nodes)
                                               and abs(x - round(x)) < 1e-9 else ""))


def _legend_below(fig, ax, own: bool, ncols: int) -> None:
    """The legend below the axes (the data keep the whole axes); in an ``ax`` given by the
    caller, whose figure may hold other panels, the axes' own legend instead."""
    if own:
        fig.legend(*ax.get_legend_handles_labels(), fontsize=8, loc="outside lower center", ncols=ncols, frameon=False)
    else:
        ax.legend(fontsize=7)


def plot_end_forces(result: CompressionResult, steps=None, ax=None) -> Figure:
    """Paper Fig. 7d: the axial force (pN, compressive positive) on every strand end (the
    surface nodes ``result.end_nodes``, labelled by node number), one marker per step, in path
    order.  Default steps: the loading regimes of :func:`loading_regimes` (pre-stress,
    linear, peak, collapse)."""
    if steps is None:
        labelled = [(f"{name}: ", k) for name, k in loading_regimes(result).items()]
    else:
        labelled = [("", k) for k in sorted(dict.fromkeys(_check_steps(result, steps)))]
    own = ax is None
    fig, ax = _new_axes(ax, figsize=(7.6, 4.2))
    x = np.arange(result.end_forces.shape[1])
    markers = itertools.cycle(_STEP_MARKERS)
    for colour, marker, (name, k) in zip(_colours(len(labelled)), markers, labelled):
        ax.plot(x, result.end_forces[k], marker, ls="none", mfc="none", mec=colour, ms=6,
                label=f"{name}step {k}, {_step_label(result, k)}")
    ax.axhline(0.0, color="0.6", lw=0.8, zorder=0)
    ax.set_xlim(-0.5, max(len(x), 1) - 0.5)
    _end_ticks(ax, result.end_nodes)
    ax.set_xlabel("strand end on the surface (node number)")
    ax.set_ylabel("strand-end force (pN, compressive +)")
    ax.set_title("strand-end forces")
    _legend_below(fig, ax, own, ncols=2)
    return fig


def plot_strand_forces(result: CompressionResult, strands=None, ax=None) -> Figure:
    """Paper Fig. 7c: the probe force and strand-end forces (pN, compressive positive) against
    probe displacement (µm) over the loading steps (phase ≤ 1).  ``strands``: strand-end
    indices into ``result.end_nodes`` (default: the 6 with the largest force range); each
    line is labelled with its surface node."""
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
    own = ax is None
    fig, ax = _new_axes(ax, figsize=(7.6, 4.2))
    ax.plot(u, np.asarray(result.force)[loading], "-", color="k", lw=2.0, label="probe")
    for colour, j in zip(_colours(len(strands)), strands):
        ax.plot(u, ends[:, j], "-", color=colour, lw=1.0, label=f"strand end at node {int(result.end_nodes[j])}")
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("force (pN, compressive +)")
    ax.set_title("probe and strand-end forces (loading)")
    _legend_below(fig, ax, own, ncols=4 if len(strands) > 2 else 3)
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
