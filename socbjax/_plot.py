"""Deformed shapes on matplotlib axes (no global backend changes, no pyplot state): the smooth
SOCB curve between nodes, for single solutions and for many recorded steps of a path.

SOCB's nodes carry the whole C²-continuous angle field, so the shape between two nodes is a
curve, not a chord: every drawing here evaluates :func:`socbjax._curve.filament_curve`.  For
the steps of a :class:`socbjax.CompressionResult` the curve is evaluated for all requested
steps at once (``jax.vmap``, compiled once per network topology, point count and number of
steps), not in a Python loop per step.  Units: µm.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.patches import Circle
from matplotlib.colors import ListedColormap
from matplotlib.ticker import MaxNLocator

from ._curve import filament_curve

__all__ = ["AXIS_NAMES", "DISPLACEMENT_CMAP", "chain_index", "common_limits", "draw_contacts", "draw_planes", "draw_reference", "draw_state",
           "has_contact", "obstacle_points",
           "drawn_axes", "label_offsets", "line_segments", "plot_shapes", "polylines", "step_curves", "style_axes"]

AXIS_NAMES = ("x", "y", "z")
# A coordinate whose spread over every node and step is below this fraction of the largest
# spread is constant: a 3D result lying in a coordinate plane is drawn as the planar
# problem it is (2D axes), not as a flat 3D picture.
PLANAR_TOLERANCE = 1e-9
# Node dots are drawn on networks up to this many segments; on larger ones they hide the curves.
MAX_SEGMENTS_WITH_NODES = 60
# viridis without its bright yellow end, which vanishes on white and light-grey panes
DISPLACEMENT_CMAP = ListedColormap(matplotlib.colormaps["viridis"](np.linspace(0.0, 0.85, 256)), name="viridis_dark")


def plot_shapes(ax, items, *, plane=(0, 1), points_per_segment: int = 24):
    """Draw filament shapes on ``ax``.

    ``items``: iterable of (label, solution, style dict).  SOCB solutions are drawn as the
    smooth curve of their angle polynomials (:meth:`socbjax.Solution.curve`), jointed ones as
    their rigid bars, with nodes marked.  ``plane``: the two coordinates drawn (µm).
    """
    i, j = plane
    for label, solution, style in items:
        xy = solution.curve(points_per_segment).polyline()
        (line,) = ax.plot(xy[:, i], xy[:, j], label=label, **style)
        nodes = np.asarray(solution.positions)
        ax.plot(nodes[:, i], nodes[:, j], "o", ms=4, color=line.get_color())
    ax.set_aspect("equal")
    ax.set_xlabel(f"{AXIS_NAMES[i]} (µm)")
    ax.set_ylabel(f"{AXIS_NAMES[j]} (µm)")
    return ax


@eqx.filter_jit
def _curve_positions(network, positions, tangents, moments, forces, twists, points: int):
    """[K, S, P, d] curve points of K equilibria of one network (``points`` is static);
    ``twists`` [K, N] the frame angles of a twisting network ([K, 0] otherwise)."""

    def one(p, t, m, f, psi):
        psi = psi if network.twisting else None
        return filament_curve(network, p, t, m, f, points_per_segment=points, twists=psi).positions

    return jax.vmap(one)(positions, tangents, moments, forces, twists)


def step_curves(result, steps, points_per_segment: int = 12) -> np.ndarray:
    """The smooth SOCB curve of ``result`` at ``steps``: [len(steps), S, P, d] points (µm),
    both end nodes of each segment included.  One compiled, vmapped evaluation for all steps
    (the batch is padded to a multiple of 8 so that up to 8 snapshots share one program)."""
    steps = np.asarray(steps, dtype=int)
    batch = 8 * -(-len(steps) // 8)
    rows = np.concatenate([steps, np.full(batch - len(steps), steps[-1])])
    take = lambda a: jnp.asarray(np.asarray(a, dtype=float)[rows])
    twists = take(result.twists)
    if not result.records_frame_angles:  # a format-3 file
        if np.any(np.asarray(result.network.natural_curvature) != 0):
            raise ValueError("this result of a curved twisting network has no material-frame angles (read from a "
                             "file of format 3 or older), which its smooth curves need; re-run the compression")
        twists = jnp.zeros(twists.shape[:1] + (result.network.n_nodes,))  # straight rods: ψ does not enter the curve
    pts = _curve_positions(result.network, take(result.positions), take(result.tangents), take(result.moments),
                           take(result.segment_forces), twists, int(points_per_segment))
    return np.asarray(pts)[: len(steps)]


def chain_index(segments: np.ndarray, points: int) -> np.ndarray:
    """Indices into a flattened [S·P] curve array (P points per segment, plus one appended
    NaN row at index S·P) that trace the segments as polylines: consecutive segments sharing
    a node join, the shared node taken once (as the next segment's start point, the node
    itself), a NaN row separates polylines."""
    chains: list[list[int]] = []
    previous_end = None
    for k, (a, b) in enumerate(np.asarray(segments, dtype=int).tolist()):
        if a == previous_end:
            chains[-1].append(k)
        else:
            chains.append([k])
        previous_end = b
    out: list[np.ndarray] = []
    for chain in chains:
        if out:
            out.append(np.array([len(segments) * points]))
        out.extend(k * points + np.arange(points - 1) for k in chain[:-1])
        out.append(chain[-1] * points + np.arange(points))
    return np.concatenate(out) if out else np.zeros(0, dtype=int)


def drawn_axes(result) -> tuple[int, ...]:
    """The coordinates to draw a result in: (0, 1) for a 2D network; for a 3D network whose
    nodes and tangents keep one coordinate constant at every recorded step (a planar problem
    built in 3D), the other two; otherwise (0, 1, 2)."""
    if result.network.dim == 2:
        return (0, 1)
    pos = np.asarray(result.positions, dtype=float).reshape(-1, 3)
    tan = np.asarray(result.tangents, dtype=float).reshape(-1, 3)
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(tan))):
        return (0, 1, 2)
    span = np.ptp(pos, axis=0)
    scale = max(float(span.max()), 1e-300)
    flat = [c for c in range(3) if span[c] <= PLANAR_TOLERANCE * scale and np.abs(tan[:, c]).max() <= PLANAR_TOLERANCE]
    if not flat:
        return (0, 1, 2)
    return tuple(c for c in range(3) if c != flat[-1])


def polylines(curves: np.ndarray, index: np.ndarray) -> np.ndarray:
    """[len(index), d] points of one step's curve [S, P, d] traced along ``index``
    (:func:`chain_index`), NaN rows between polylines."""
    flat = curves.reshape(-1, curves.shape[-1])
    return np.vstack([flat, np.full((1, flat.shape[1]), np.nan)])[index]


def line_segments(points: np.ndarray, values: np.ndarray):
    """Consecutive point pairs of a NaN-separated polyline ``points`` [M, d] as [M', 2, d]
    segments (for a Line/Line3DCollection) and the mean of ``values`` [M] on each."""
    ok = np.all(np.isfinite(points), axis=1)
    pair = ok[:-1] & ok[1:]
    segments = np.stack([points[:-1][pair], points[1:][pair]], axis=1)
    return segments, 0.5 * (values[:-1][pair] + values[1:][pair])


def _node_chain(segments: np.ndarray) -> np.ndarray:
    """Node indices tracing the segments as polylines (consecutive segments sharing a node
    join), −1 between polylines (indexes an appended NaN row)."""
    order: list[int] = []
    previous_end = None
    for a, b in np.asarray(segments).tolist():
        if a != previous_end:
            if order:
                order.append(-1)
            order.append(a)
        order.append(b)
        previous_end = b
    return np.asarray(order, dtype=int)


def draw_reference(ax, network, coords) -> None:
    """The as-built network (straight, stress-free segments: its chords are exact), grey dashed."""
    ref = np.asarray(network.positions, float)[:, list(coords)]
    lines = np.vstack([ref, np.full((1, len(coords)), np.nan)])[_node_chain(network.segments)]
    (line,) = ax.plot(*lines.T, "--", color="0.7", lw=1.0, zorder=2)
    line.set_gid("as_built")


def draw_planes(ax, network, displacement: float, gap: float, coords, extent) -> None:
    """The surface (plane h = ``gap`` of the farthest opposing support) and the probe plane
    (h = ``displacement``), h measured from the probe nodes' reference position along the probe
    direction (µm), as lines across ``extent`` ([2, 2] lower/upper corner); 2D drawings whose
    plane contains the probe direction only."""
    direction = np.asarray(network.probe_direction, float)[list(coords)]
    probe = np.flatnonzero(np.asarray(network.probe))
    if probe.size == 0 or np.linalg.norm(direction) < 0.99 or not np.isfinite(gap):
        return
    origin = np.asarray(network.positions, float)[probe][:, list(coords)].mean(axis=0)
    across = np.array([-direction[1], direction[0]])
    corners = np.array([[x, y] for x in extent[:, 0] for y in extent[:, 1]]) @ across
    for height, colour, gid in ((gap, "0.55", "surface"), (displacement, "0.1", "probe_plane")):
        ends = origin + height * direction + np.outer([corners.min(), corners.max()], across)
        (line,) = ax.plot(*ends.T, "-", color=colour, lw=2.5, solid_capstyle="butt", zorder=1)
        line.set_gid(gid)


def draw_state(ax, network, positions, end_nodes, curve, index, coords, colour, *, label=None, moved=None, norm=None):
    """One equilibrium on ``ax``: the smooth curve [S, P, c] traced along ``index`` (gid
    "shape"; coloured by ``moved`` [S, P], the displacement from the settled start in µm,
    with ``norm`` and :data:`DISPLACEMENT_CMAP` when given, else in ``colour``), node dots on
    small networks, probe nodes as filled squares and strand ends as hollow circles."""
    pos = np.asarray(positions, dtype=float)[:, list(coords)]
    points = polylines(curve, index)
    segments, values = line_segments(points, polylines(moved[..., None], index)[:, 0]) if moved is not None else ([], [])
    if len(segments) == 0:  # one colour (or nothing finite to colour)
        (line,) = ax.plot(*points.T, "-", color=colour, lw=1.4, label=label, zorder=3)
    elif len(coords) == 3:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        line = ax.add_collection3d(Line3DCollection(segments, cmap=DISPLACEMENT_CMAP, norm=norm, lw=1.1))
    else:
        line = ax.add_collection(LineCollection(segments, cmap=DISPLACEMENT_CMAP, norm=norm, lw=1.4, zorder=3))
    if len(segments):
        line.set_array(values)
        colour = "0.2"  # markers in neutral grey beside the colour map
    line.set_gid("shape")
    if network.n_segments <= MAX_SEGMENTS_WITH_NODES:
        ax.plot(*pos.T, ".", ls="none", color=colour, ms=3.5, zorder=4)
    probe = np.flatnonzero(np.asarray(network.probe))
    ends = np.asarray(end_nodes, dtype=int)
    if probe.size:
        ax.plot(*pos[probe].T, "s", ls="none", color=colour, mec="k", ms=6, zorder=5)
    if ends.size:
        ax.plot(*pos[ends].T, "o", ls="none", mfc="white", mec=colour, ms=5, zorder=5)
    return line


def style_axes(ax, coords, limits) -> None:
    """Axis labels with units, common ``limits`` and equal aspect, few ticks (3 on 3D axes,
    with small labels close to their axes, so that the y and z tick labels stay apart)."""
    three_d = len(coords) == 3
    for name, c, (lo, hi) in zip("xyz", coords, limits):
        getattr(ax, f"set_{name}label")(f"{AXIS_NAMES[c]} (µm)", fontsize=8, labelpad=1 if three_d else 2)
        getattr(ax, f"set_{name}lim")(lo, hi)
        getattr(ax, f"{name}axis").set_major_locator(MaxNLocator(3 if three_d else 5))
    ax.tick_params(labelsize=7, pad=0 if three_d else 2)
    if three_d:
        ax.set_box_aspect(np.maximum([hi - lo for lo, hi in limits], 1e-3 * max(hi - lo for lo, hi in limits)))
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.pane.set_facecolor((0.97, 0.97, 0.97, 1.0))
    else:
        ax.set_aspect("equal", adjustable="box")


def common_limits(points: np.ndarray, margin: float = 0.06) -> list[tuple[float, float]]:
    """(low, high) per coordinate of the finite rows of ``points`` [M, c], padded by
    ``margin`` of the largest extent (µm)."""
    points = points[np.all(np.isfinite(points), axis=1)]
    if points.size == 0:
        return [(-1.0, 1.0)] * points.shape[1]
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = margin * max(float(np.max(hi - lo)), 1e-9)
    return [(float(a), float(b)) for a, b in zip(lo - pad, hi + pad)]


def label_offsets(ax, anchors, labels, defaults, size: float, width_fraction: float) -> list[float]:
    """Vertical offsets (points) of labels 5 points right of their ``anchors`` (data): the
    ``defaults``, or where a label would overlap an earlier one (in path order), first the
    other side of the curve, then one line further away at a time.  Estimated without a
    layout pass (which costs more than the rest of the figure): label boxes from the
    character count, the axes at ``width_fraction`` of the figure's width, a lower bound of
    its width after the layout, so that the estimate errs towards separating."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    width, height = ax.figure.get_size_inches() * 72 * [width_fraction, ax.get_position().height]  # points
    h = 1.3 * size
    step = h + 1.5  # one line and a gap
    placed: list[tuple[float, float, float, float]] = []
    out = []
    for (u, force), label, default in zip(anchors, labels, defaults):
        x, y = (u - x0) / (x1 - x0 or 1.0) * width, (force - y0) / (y1 - y0 or 1.0) * height
        w = 0.62 * size * len(label)
        flipped = 8.0 if default < 0 else -8.0 - h  # the same gap on the other side of the marker
        candidates = [default, flipped] + [o + k * (step if o > 0 else -step) for k in range(1, 7) for o in (default, flipped)]
        for dy in candidates:
            box = (x + 5, y + dy, x + 5 + w, y + dy + h)
            if not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed):
                break
        placed.append(box)
        out.append(dy)
    return out


def has_contact(result) -> bool:
    """Whether ``result`` was computed with contact obstacles (it has contact slots)."""
    return result.contact_points is not None and np.shape(result.contact_points)[1] > 0


def draw_contacts(ax, result, k: int, coords, label=None) -> None:
    """The contact points of step k that carry force, as red crosses, and (planar drawings)
    the contact's own planes and spheres (``result.parameters["contact"]``), hatched grey."""
    if not has_contact(result):
        return
    obstacles = result.parameters.get("contact", {})
    if len(coords) == 2:
        span = 1e3 * (1.0 + float(np.abs(np.asarray(result.positions)).max()))  # beyond any axis limits
        for plane in obstacles.get("planes", []):
            p, n = np.asarray(plane["point_um"])[list(coords)], np.asarray(plane["normal"])[list(coords)]
            along = np.array([-n[1], n[0]])
            ax.plot(*np.stack([p - span * along, p + span * along]).T, color="0.35", lw=2.0, zorder=1, scalex=False,
                    scaley=False)
        for sphere in obstacles.get("spheres", []):
            c = np.asarray(sphere["center_um"])[list(coords)]
            ax.add_patch(Circle(c, max(sphere["radius_um"], 0.0), color="0.35", zorder=1))
            ax.plot(*c, "o", color="0.35", ms=3, zorder=1)
    forces = np.asarray(result.contact_forces[k])
    points = np.asarray(result.contact_points[k])[np.linalg.norm(forces, axis=-1) > 0][:, list(coords)]
    if points.size:
        ax.plot(*points.T, "x", color="C3", ms=6, mew=1.5, ls="none", zorder=5, label=label)


def obstacle_points(result, coords) -> np.ndarray:
    """[M, len(coords)] points that the drawing of ``result``'s contact planes and spheres
    needs inside the axis limits (plane points; sphere centers; none without contact)."""
    obstacles = result.parameters.get("contact", {}) if has_contact(result) else {}
    points = [p["point_um"] for p in obstacles.get("planes", [])] + [o["center_um"] for o in obstacles.get("spheres", [])]
    return np.asarray(points, float).reshape(-1, len(result.network.positions[0]))[:, list(coords)]
