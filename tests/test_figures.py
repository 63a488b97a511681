"""Figures of a compression path on hand-built results: the right artists, labels with
units, default step choices, smooth SOCB curves, planar results on 2D axes, one label per
limit point, atomic PNG output, no pyplot windows."""

import dataclasses
import os

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text

import socbjax as sj
from socbjax import CompressionResult, LimitPoint

N_LOAD = 31  # settle step + 30 loading steps, u = 0.02 j µm


def path_result(dim=3, E=8, unload=True, N=4, planar=False, jump=False):
    """Force rises linearly to a peak at step 16 (u = 0.32 µm, F = 1 pN), falls to a trough
    at step 24, rises again to step 30; 10 unloading steps follow if ``unload``.  The column
    bows in y (and, in 3D unless ``planar``, in z).  ``jump``: the force reaches 0.9 pN at
    step 1, 1e-9 µm from the start (the vertical rise of a real compression)."""
    j = np.arange(N_LOAD)
    u = 0.02 * j
    F = np.where(j <= 16, j / 16, np.where(j <= 24, 1 - 4 * (u - 0.32), 0.36 + 0.5 * (u - 0.48)))
    if jump:
        u, F = u.copy(), F.copy()
        u[1], F[1:16] = 1e-9, np.linspace(0.9, 0.99, 15)
    phase = np.where(j == 0, 0, 1)
    if unload:
        u_back = np.linspace(0.6, 0.06, 11)[1:]
        u, F = np.concatenate([u, u_back]), np.concatenate([F, 0.7 * u_back])
        phase = np.concatenate([phase, np.full(10, 2)])
    K, S = len(u), N - 1
    net = sj.probe_network(sj.column(N, dim=dim))
    ref = np.asarray(net.positions)
    bulge = np.zeros((N, dim))
    bulge[:, 1] = np.sin(np.pi * np.arange(N) / (N - 1))
    if dim == 3 and not planar:
        bulge[:, 2] = 0.5 * bulge[:, 1]
    positions = ref[None] + u[:, None, None] * bulge[None]
    weights = np.linspace(0.1, 1.0, E)  # end j's force range grows with j
    return CompressionResult(
        displacement=u,
        force=F,
        converged=np.ones(K, bool),
        stable=~((np.arange(K) > 16) & (np.arange(K) <= 24)),
        phase=phase,
        positions=positions,
        tangents=np.broadcast_to(np.asarray(net.tangents), (K, N, dim)).copy(),
        moments=np.zeros((K, N, 3) if dim == 3 else (K, N)),
        segment_forces=np.zeros((K, S, dim)),
        twists=np.zeros((K, 0)),
        end_nodes=np.arange(E) % N,
        end_forces=F[:, None] * weights[None, :],
        iterations=np.full(K, 3),
        limit_points=(
            LimitPoint("force_maximum", 16, 0.32, 1.0, "loading"),
            LimitPoint("force_minimum", 24, 0.48, 0.36, "loading"),
        ),
        result=sj.RESULTS.successful,
        network=net,
    )


@pytest.fixture(autouse=True)
def no_pyplot_figures():
    before = plt.get_fignums()
    yield
    assert plt.get_fignums() == before  # nothing registered with pyplot: no windows
    plt.close("all")


def labels(ax):
    return [line.get_label() for line in ax.get_lines() if not line.get_label().startswith("_")]


def legend(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def by_gid(ax, gid):
    return [a for a in (*ax.texts, *ax.get_lines(), *ax.collections) if a.get_gid() == gid]


def test_force_curve_loading_unloading_unstable_and_limit_points():
    fig = sj.plot_force_curve(path_result())
    assert isinstance(fig, Figure)
    (ax,) = fig.axes
    assert legend(ax) == ["settled start (probe free, F = 0)", "loading", "force maximum", "force minimum", "unloading",
                          "unstable (sign det J flipped)"]  # path order, then the flags
    start, loading, unloading = ax.get_lines()[:3]
    assert len(start.get_xdata()) == 1 and len(loading.get_xdata()) == N_LOAD and len(unloading.get_xdata()) == 11
    assert loading.get_color() != unloading.get_color()
    assert len(ax.get_lines()[3].get_xdata()) == 8  # the unstable steps 17..24
    assert sorted(t.get_text() for t in by_gid(ax, "limit_point")) == ["max 1 pN", "min 0.36 pN"]
    assert "µm" in ax.get_xlabel() and "pN" in ax.get_ylabel()
    assert not by_gid(ax, "initial_jump")  # a linear rise is no jump

    result = path_result(unload=False)
    result.stable[:] = True
    result = dataclasses.replace(result, limit_points=())
    ax = sj.plot_force_curve(result).axes[0]
    assert labels(ax) == ["settled start (probe free, F = 0)", "loading"] and len(ax.texts) == 0


def test_each_limit_point_labelled_once_and_labels_apart():
    """Close limit points (a loading and an unloading minimum 0.01 µm apart, as the unit mesh
    has them) get one label each, and the rendered labels do not overlap."""
    points = (LimitPoint("force_maximum", 16, 0.32, 1.0, "loading"), LimitPoint("force_minimum", 24, 0.48, 0.36, "loading"),
              LimitPoint("force_minimum", 33, 0.47, 0.361, "unloading"), LimitPoint("fold", 34, 0.46, 0.362, "unloading"))
    fig = sj.plot_force_curve(dataclasses.replace(path_result(), limit_points=points))
    ax = fig.axes[0]
    texts = by_gid(ax, "limit_point")
    assert [t.get_text() for t in texts] == ["max 1 pN", "min 0.36 pN", "min 0.361 pN (unloading)", "fold 0.362 pN (unloading)"]
    assert [t.xy for t in texts] == [(p.displacement, p.force) for p in points]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [Text.get_window_extent(t, renderer) for t in texts]  # the text, without its leader line
    assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
    frame = ax.get_window_extent(renderer)
    assert all(frame.y0 <= b.y0 and b.y1 <= frame.y1 for b in boxes)  # inside the axes: clear of the title
    assert legend(ax).count("force minimum") == 1


def test_force_jump_at_zero_displacement_explained():
    result = path_result(2, jump=True)
    ax = sj.plot_force_curve(result).axes[0]
    (note,) = by_gid(ax, "initial_jump")
    text = note.get_text()
    assert "perturbation" in text and "buckling" in text and "from 0 to 0.9 pN" in text and "unloading stops" in text
    assert note.xy[0] == pytest.approx(0.0) and note.xy[1] == pytest.approx(0.45)  # the arrow points at the vertical segment


def test_force_curve_draws_into_given_axes():
    fig = Figure()
    ax = fig.add_subplot()
    assert sj.plot_force_curve(path_result(), ax=ax) is fig
    assert len(ax.get_lines()) == 6  # start, loading, unloading, unstable, two limit-point kinds


def test_force_curve_shades_the_path_beyond_a_surface_crossing():
    crossing = LimitPoint("surface_crossing", 28, 0.56, 0.4, "loading")
    result = dataclasses.replace(path_result(2), limit_points=path_result(2).limit_points + (crossing,),
                                 result=sj.RESULTS.surface_crossed)
    ax = sj.plot_force_curve(result).axes[0]
    assert any(name.startswith("beyond the first surface/probe crossing") for name in legend(ax))
    assert [t.get_text() for t in by_gid(ax, "limit_point")][-1] == "crossing 0.4 pN"


@pytest.mark.parametrize("dim", [2, 3])
def test_snapshots_small_multiples_in_path_order(dim):
    result = path_result(dim)
    fig = sj.plot_snapshots(result)
    panels = [ax for ax in fig.axes if ax.get_title()]
    # start, half the largest u on loading (15), peak (16), largest u (30), half on unloading (36), end
    steps = [int(ax.get_title().split(",")[0].split()[1]) for ax in panels]
    assert steps == [0, 15, 16, 30, 36, 40]
    assert [ax.get_title().split("\n")[0] for ax in panels][:3] == ["step 0, settled start", "step 15, loading",
                                                                  "step 16, loading, peak force"]
    assert panels[0].get_title().split("\n")[1] == "u = 0 µm, F = 0 pN"
    assert panels[-1].get_title().startswith("step 40, unloading")
    assert all(ax.name == ("3d" if dim == 3 else "rectilinear") for ax in panels)
    assert all(len(by_gid(ax, "shape")) == 1 for ax in panels)
    if dim == 2:  # shared axes, equal aspect, labels with units on the outer panels
        assert all(ax.get_shared_x_axes().joined(panels[0], ax) and ax.get_shared_y_axes().joined(panels[0], ax)
                   for ax in panels)
        assert all(ax.get_aspect() == 1.0 for ax in panels)
        assert panels[3].get_xlabel() == "x (µm)" and panels[0].get_ylabel() == "y (µm)"
        assert all(by_gid(ax, "surface") and by_gid(ax, "probe_plane") for ax in panels)
        names = [t.get_text() for t in fig.legends[0].get_texts()]
        assert names[:3] == ["settled start", "loading", "unloading"] and "strand ends" in names
    else:  # one limit for every panel, a colour bar for the displacement from the start
        assert all(ax.get_xlim() == panels[0].get_xlim() and ax.get_zlim() == panels[0].get_zlim() for ax in panels)
        assert {ax.get_zlabel() for ax in panels} == {"z (µm)"}
        assert any("displacement from the settled start (µm)" in ax.get_ylabel() for ax in fig.axes if not ax.get_title())


def test_snapshots_explicit_steps_sorted_and_checked():
    result = path_result(2, unload=False)
    fig = sj.plot_snapshots(result, steps=[-1, 0, 5, 5])
    assert [ax.get_title().split(",")[0] for ax in fig.axes] == ["step 0", "step 5", "step 30"]
    with pytest.raises(IndexError, match="0..30"):
        sj.plot_snapshots(result, steps=[31])
    with pytest.raises(ValueError, match="3D axes"):
        sj.plot_snapshots(path_result(3), ax=Figure().add_subplot())


def test_planar_results_drawn_on_2d_axes():
    """A 2D result, and a 3D one that never leaves the x–y plane, get 2D axes only."""
    for result in (path_result(2), path_result(3, planar=True)):
        fig = sj.plot_snapshots(result)
        assert {ax.name for ax in fig.axes} == {"rectilinear"}
        assert all(line.get_xydata().shape[1] == 2 for line in by_gid(fig.axes[0], "shape"))
    overlay = sj.plot_snapshots(path_result(3, planar=True), ax=Figure().add_subplot())  # 2D axes accepted
    assert overlay.axes[0].get_xlabel() == "x (µm)" and overlay.axes[0].get_ylabel() == "y (µm)"


def test_shape_is_the_smooth_socb_curve():
    """The drawn shape has many more vertices than the network has nodes and they are the
    points of Solution.curve (the shared node of consecutive segments once)."""
    result = path_result(2)
    fig = sj.plot_snapshots(result, steps=[20], points_per_segment=9)
    (line,) = by_gid(fig.axes[0], "shape")
    drawn = line.get_xydata()
    assert len(drawn) > 2 * result.network.n_nodes
    curve = np.asarray(result.solution(20).curve(points_per_segment=9).positions)  # [S, 9, 2]
    expected = np.concatenate([c[:-1] for c in curve[:-1]] + [curve[-1]])  # a chain: each joint once, the node itself
    np.testing.assert_allclose(drawn, expected, rtol=0, atol=1e-12)

    result3 = path_result(3)
    (shape,) = by_gid(sj.plot_snapshots(result3, steps=[20]).axes[0], "shape")
    pairs = np.asarray(shape._segments3d)  # a Line3DCollection keeps its 3D segments (consecutive curve points) here
    assert pairs.shape == (result3.network.n_segments * 11, 2, 3)
    segments = pairs.reshape(-1, 3)
    curve3 = np.asarray(result3.solution(20).curve(points_per_segment=12).positions).reshape(-1, 3)
    assert np.abs(segments[:, None, :] - curve3[None]).min(axis=1).max() < 1e-12


def test_snapshots_overlay_into_given_axes_in_path_order():
    result = path_result(2)
    fig = Figure()
    ax = fig.add_subplot()
    assert sj.plot_snapshots(result, steps=[30, 0, 16], ax=ax) is fig
    assert [name.split(",")[0] for name in legend(ax)] == ["step 0", "step 16", "step 30"]
    assert len(by_gid(ax, "shape")) == 3


def test_end_forces_at_loading_regimes():
    result = path_result()
    ax = sj.plot_end_forces(result).axes[0]
    markers = [line for line in ax.get_lines() if line.get_linestyle() == "None"]
    assert len(markers) == 4 and len({line.get_marker() for line in markers}) == 4
    assert all(len(line.get_xdata()) == 8 for line in markers)
    np.testing.assert_array_equal(markers[2].get_ydata(), result.end_forces[16])
    names = [t.get_text() for t in ax.figure.legends[0].get_texts()]
    assert [name.split(":")[0] for name in names] == ["pre-stress", "linear", "peak", "collapse"]
    assert names[2].startswith("peak: step 16, u = 0.32 µm")
    assert "index" not in ax.get_xlabel() and ax.get_xlabel() == "strand end on the surface (node number)"
    assert [t.get_text() for t in ax.get_xticklabels()] == [str(n) for n in result.end_nodes]  # real node numbers
    assert "pN" in ax.get_ylabel()
    ax = sj.plot_end_forces(result, steps=[10, 5]).axes[0]
    assert len([line for line in ax.get_lines() if line.get_linestyle() == "None"]) == 2


def test_loading_regimes_without_post_peak_steps():
    result = path_result(unload=False)
    keep = np.arange(17)
    names = ("displacement", "force", "converged", "stable", "phase", "positions", "end_forces", "iterations")
    result = dataclasses.replace(result, **{name: getattr(result, name)[keep] for name in names})
    ax = sj.plot_end_forces(result).axes[0]
    assert [t.get_text().split(":")[0] for t in ax.figure.legends[0].get_texts()] == ["pre-stress", "linear", "peak"]


def test_strand_forces_default_and_chosen():
    result = path_result()
    ax = sj.plot_strand_forces(result).axes[0]
    assert len(ax.get_lines()) == 7
    assert labels(ax)[0] == "probe" and labels(ax)[1] == "strand end at node 3"  # end 7: the largest range first
    assert all(len(line.get_xdata()) == N_LOAD for line in ax.get_lines())  # loading only
    assert "µm" in ax.get_xlabel() and "pN" in ax.get_ylabel()
    assert len(sj.plot_strand_forces(result, strands=[0, 2]).axes[0].get_lines()) == 3
    assert len(sj.plot_strand_forces(path_result(E=1)).axes[0].get_lines()) == 2
    with pytest.raises(IndexError, match="end_nodes"):
        sj.plot_strand_forces(result, strands=[8])


def test_save_figures_writes_four_pngs(tmp_path):
    out = tmp_path / "a" / "figures"
    paths = sj.save_figures(path_result(2), out)
    names = ["force_curve.png", "snapshots.png", "end_forces.png", "strand_forces.png"]
    assert [p.name for p in paths] == names and all(p.parent == out for p in paths)
    for p in paths:
        data = p.read_bytes()
        assert len(data) > 1000 and data[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(os.listdir(out)) == sorted(names)
    assert len(sj.save_figures(path_result(3), out, steps=[0, 20])) == 4


def test_save_figures_failure_leaves_previous_pngs(tmp_path, monkeypatch):
    paths = sj.save_figures(path_result(2), tmp_path)
    before = [p.read_bytes() for p in paths]

    def broken(self, *args, **kwargs):
        raise RuntimeError("renderer failed (simulated)")

    monkeypatch.setattr(Figure, "savefig", broken)
    with pytest.raises(RuntimeError, match="simulated"):
        sj.save_figures(path_result(2), tmp_path)
    monkeypatch.undo()
    assert [p.read_bytes() for p in paths] == before
    assert not [name for name in os.listdir(tmp_path) if name.endswith(".tmp")]
