"""Repeated solves with new parameter values or loads reuse the compiled code: the traced
functions are counted by wrapping the module globals they call at trace time (a cache hit
does not trace, so it does not count)."""

import numpy as np
import pytest

import socbjax as sj
import socbjax._compress as compress_module
import socbjax._solve as solve_module


@pytest.fixture
def traces(monkeypatch):
    """``wrap(module, name)`` counts the calls of ``module.name`` into ``counts[name]``."""
    counts = {}

    def wrap(module, name):
        original = getattr(module, name)

        def counted(*args, **kwargs):
            counts[name] = counts.get(name, 0) + 1
            return original(*args, **kwargs)

        monkeypatch.setattr(module, name, counted)

    return counts, wrap


def test_solve_new_EI_lengths_and_forces_do_not_retrace(traces):
    counts, wrap = traces
    wrap(solve_module, "load_continuation")
    tips = []
    for k, (EI, length, load) in enumerate([(1.0, 1.0, 2.0), (2.5, 1.0, 2.0), (2.5, 1.7, 0.5), (0.3, 0.4, 3.0)]):
        sol = sj.solve(sj.cantilever(n_nodes=5, length=length, EI=EI, dim=2), {-1: [0.0, load * EI / length**2]})
        tips.append(np.asarray(sol.positions[-1]) / length)
        if k == 0:
            first = counts.get("load_continuation", 0)
    assert first <= 1 and counts.get("load_continuation", 0) == first
    # PL²/EI is the only parameter of the scaled shape: runs 1 and 2 agree (a real solve each time)
    np.testing.assert_allclose(tips[1], tips[0], atol=1e-12)
    # a new shape must trace again: the counter is live
    sj.solve(sj.cantilever(n_nodes=6, dim=2), {-1: [0.0, 1.0]})
    assert counts["load_continuation"] == first + 1


def test_sparse_solve_new_parameters_do_not_retrace(traces):
    counts, wrap = traces
    wrap(solve_module, "load_continuation")
    for k, EI in enumerate([1.0, 3.0, 0.2]):
        sj.solve(sj.cantilever(n_nodes=401, length=10.0, EI=EI, dim=2), {-1: [0.0, 0.01 * EI]}, linear_solver="sparse")
        if k == 0:
            first = counts.get("load_continuation", 0)
    assert first <= 1 and counts.get("load_continuation", 0) == first


def test_compress_new_EI_perturbation_displacement_and_steps_do_not_retrace(traces):
    counts, wrap = traces
    wrap(compress_module, "path_run")
    wrap(compress_module, "path_start")
    forces = []
    runs = [(1.0, 1e-3, 0.3, 0.05), (2.0, 2e-3, 0.3, 0.05), (0.5, 1e-2, 0.2, 0.02)]  # EI, imperfection, u, max step
    for k, (EI, perturbation, u, step) in enumerate(runs):
        net = sj.column(n_nodes=5, length=1.0, EI=EI, supports=("clamped", "pinned"), dim=2)
        result = sj.compress(net, u, perturbation=perturbation, settings=sj.PathSettings(max_step=step, initial_step=0.01))
        forces.append(result.force[-1] / EI)
        if k == 0:
            first = dict(counts)
    assert first and all(v <= 2 for v in first.values()), first
    assert counts == first
    # F ∝ EI when the imperfection scales with EI too: runs 0 and 1 are a real re-solve
    assert abs(forces[1] - forces[0]) <= 1e-8 * abs(forces[0])
