"""Figures of a compression path on hand-built results: the right artists, labels with
units, default step choices, atomic PNG output, no pyplot windows."""

import dataclasses
import os

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

import socbjax as sj
from socbjax import _figures
from socbjax import CompressionResult, LimitPoint

N_LOAD = 31  # settle step + 30 loading steps, u = 0.02 j µm


def path_result(dim=3, E=8, unload=True, N=4):
    """Force rises linearly to a peak at step 16 (u = 0.32 µm, F = 1 pN), falls to a trough
    at step 24, rises again to step 30; 10 unloading steps follow if ``unload``."""
    j = np.arange(N_LOAD)
    u = 0.02 * j
    F = np.where(j <= 16, j / 16, np.where(j <= 24, 1 - 4 * (u - 0.32), 0.36 + 0.5 * (u - 0.48)))
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


def test_force_curve_loading_unloading_unstable_and_limit_points():
    fig = sj.plot_force_curve(path_result())
    assert isinstance(fig, Figure)
    (ax,) = fig.axes
    assert labels(ax) == ["loading", "unloading", "unstable (sign det J flipped)", "force maximum", "force minimum"]
    loading, unloading = ax.get_lines()[:2]
    assert len(loading.get_xdata()) == N_LOAD and len(unloading.get_xdata()) == 11
    assert loading.get_color() != unloading.get_color()
    assert len(ax.get_lines()[2].get_xdata()) == 8  # the unstable steps 17..24
    assert sorted(t.get_text() for t in ax.texts) == ["force maximum", "force minimum"]
    assert "µm" in ax.get_xlabel() and "pN" in ax.get_ylabel()

    result = path_result(unload=False)
    result.stable[:] = True
    result = dataclasses.replace(result, limit_points=())
    ax = sj.plot_force_curve(result).axes[0]
    assert labels(ax) == ["loading"] and len(ax.texts) == 0


def test_force_curve_draws_into_given_axes():
    fig = Figure()
    ax = fig.add_subplot()
    assert sj.plot_force_curve(path_result(), ax=ax) is fig
    assert len(ax.get_lines()) == 5


@pytest.mark.parametrize("dim", [2, 3])
def test_snapshots_default_steps(dim):
    result = path_result(dim)
    assert _figures.snapshot_steps(result) == [0, 16, 30, 40]  # start, peak, max u, end
    fig = sj.plot_snapshots(result)
    (ax,) = fig.axes
    assert ax.name == ("3d" if dim == 3 else "rectilinear")
    assert len(ax.get_lines()) == 4 * 3  # shape, probe node, strand ends per step
    shapes = [line for line in ax.get_lines() if line.get_linestyle() == "-"]
    assert len(shapes) == 4 and len({line.get_color() for line in shapes}) == 4
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[0] == "u = 0 µm, F = 0 pN" and "probe nodes" in legend and "strand ends" in legend
    assert all("µm" in label for label in (ax.get_xlabel(), ax.get_ylabel()))
    if dim == 3:
        assert "µm" in ax.get_zlabel() and ax.get_aspect() == "equal"
    else:
        assert ax.get_aspect() == 1.0


def test_snapshot_steps_topped_up_without_unloading_and_explicit_steps():
    result = path_result(2, unload=False)
    steps = _figures.snapshot_steps(result)
    assert len(steps) == 4 and steps[0] == 0 and 16 in steps and steps[-1] == 30
    ax = sj.plot_snapshots(result, steps=[0, -1]).axes[0]
    assert len(ax.get_lines()) == 6
    with pytest.raises(IndexError, match="0..30"):
        sj.plot_snapshots(result, steps=[31])
    with pytest.raises(ValueError, match="3D axes"):
        sj.plot_snapshots(path_result(3), ax=Figure().add_subplot())


def test_chain_order_joins_consecutive_segments():
    order = _figures._chain_order(np.array([[0, 1], [1, 2], [3, 4], [1, 5]]))
    assert order.tolist() == [0, 1, 2, -1, 3, 4, -1, 1, 5]


def test_end_forces_at_loading_regimes():
    result = path_result()
    regimes = _figures.loading_regimes(result)
    assert regimes == {"pre-stress": 2, "linear": 8, "peak": 16, "collapse": 24}
    ax = sj.plot_end_forces(result).axes[0]
    markers = [line for line in ax.get_lines() if line.get_linestyle() == "None"]
    assert len(markers) == 4 and len({line.get_marker() for line in markers}) == 4
    assert all(len(line.get_xdata()) == 8 for line in markers)
    np.testing.assert_array_equal(markers[2].get_ydata(), result.end_forces[16])
    assert [label.split(":")[0] for label in labels(ax)] == list(regimes)
    assert "pN" in ax.get_ylabel()
    ax = sj.plot_end_forces(result, steps=[5, 10]).axes[0]
    assert len([line for line in ax.get_lines() if line.get_linestyle() == "None"]) == 2


def test_loading_regimes_without_post_peak_steps():
    result = path_result(unload=False)
    keep = np.arange(17)
    names = ("displacement", "force", "converged", "stable", "phase", "positions", "end_forces", "iterations")
    result = dataclasses.replace(result, **{name: getattr(result, name)[keep] for name in names})
    assert _figures.loading_regimes(result) == {"pre-stress": 2, "linear": 8, "peak": 16}


def test_strand_forces_default_and_chosen():
    result = path_result()
    ax = sj.plot_strand_forces(result).axes[0]
    assert len(ax.get_lines()) == 7
    assert labels(ax)[0] == "probe" and labels(ax)[1] == "end 7 (node 3)"  # largest range first
    assert {label.split()[1] for label in labels(ax)[1:]} == {"2", "3", "4", "5", "6", "7"}
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
