"""Repeated solves with new parameter values or loads reuse the compiled code: counted with
JAX's public trace event (jax.monitoring; a cache hit does not trace, so it does not count)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj


def test_solve_new_EI_lengths_and_forces_do_not_retrace(traces):
    tips = []
    for k, (EI, length, load) in enumerate([(1.0, 1.0, 2.0), (2.5, 1.0, 2.0), (2.5, 1.7, 0.5), (0.3, 0.4, 3.0)]):
        sol = sj.solve(sj.cantilever(n_nodes=5, length=length, EI=EI, dim=2), {-1: [0.0, load * EI / length**2]})
        tips.append(np.asarray(sol.positions[-1]) / length)
        if k == 0:
            first = len(traces)
    assert first > 0 and len(traces) == first, traces[first:]
    # PL²/EI is the only parameter of the scaled shape: runs 1 and 2 agree (a real solve each time)
    np.testing.assert_allclose(tips[1], tips[0], atol=1e-12)
    # a new topology must trace again: the counter is live
    sj.solve(sj.cantilever(n_nodes=6, dim=2), {-1: [0.0, 1.0]})
    assert len(traces) > first


def test_sparse_solve_new_parameters_do_not_retrace(traces):
    settings = sj.PathSettings(linear_solver="sparse")
    for k, EI in enumerate([1.0, 3.0, 0.2]):
        sj.solve(sj.cantilever(n_nodes=401, length=10.0, EI=EI, dim=2), {-1: [0.0, 0.01 * EI]}, settings=settings)
        if k == 0:
            first = len(traces)
    assert first > 0 and len(traces) == first, traces[first:]


def test_compress_new_EI_perturbation_displacement_and_steps_do_not_retrace(traces):
    forces = []
    runs = [(1.0, 1e-3, 0.3, 0.05), (2.0, 2e-3, 0.3, 0.05), (0.5, 1e-2, 0.2, 0.02)]  # EI, imperfection, u, max step
    for k, (EI, perturbation, u, step) in enumerate(runs):
        net = sj.column(n_nodes=5, length=1.0, EI=EI, supports=("clamped", "pinned"), dim=2)
        result = sj.compress(net, u, perturbation=perturbation, settings=sj.PathSettings(max_step=step, initial_step=0.01))
        forces.append(result.force[-1] / EI)
        if k == 0:
            first = len(traces)
    assert first > 0 and len(traces) == first, traces[first:]
    # F ∝ EI when the imperfection scales with EI too: runs 0 and 1 are a real re-solve
    assert abs(forces[1] - forces[0]) <= 1e-8 * abs(forces[0])


def test_sampled_compress_at_new_depths_and_samples_does_not_retrace(traces):
    """compress(at=...) eagerly at a new depth (each curve of a fit or batch has its own) and
    new sample values runs the program of the first call; a sample's force does not depend on
    the depth (the same loading branch)."""
    net = sj.column(4, supports=("pinned", "pinned"), dim=2, EI=0.071)
    first_force = np.asarray(sj.compress(net, 0.2, at=[0.05, 0.1, 0.15]).force)
    first = len(traces)
    again = np.asarray(sj.compress(net, 0.25, at=[0.05, 0.1, 0.15]).force)
    sj.compress(net.replace(EI=net.EI * 2), 0.3, at=[0.1, 0.2, 0.3])
    assert first > 0 and len(traces) == first, traces[first:]
    np.testing.assert_allclose(again, first_force, rtol=1e-9)


def test_a_fit_of_a_new_curve_runs_the_first_fits_program(traces):
    """sj.fit compiles its residuals and Jacobian once for a model, free names and data size:
    the next curve (another EI, depth and contact start, so other points touch) adds no
    trace.  Noise-free curves: each fit recovers its own EI."""
    model = sj.ColumnModel(3, supports=("pinned", "pinned"), dim=2)
    curves = []
    for EI, c in ((0.071, np.linspace(0.02, 0.2, 10)), (0.15, np.linspace(-0.02, 0.25, 10))):
        u = np.maximum(c, 1e-6)
        F = np.asarray(sj.compress(model.network({"EI": EI}), float(u.max()), at=u).force)
        curves.append((EI, c, np.where(c > 0, F, 0.0)))
    fitted = [sj.fit((curves[0][1], curves[0][2]), model, free="EI", initial={"EI": 0.05})]
    first = len(traces)
    fitted.append(sj.fit((curves[1][1], curves[1][2]), model, free="EI", initial={"EI": 0.05}))
    assert first > 0 and len(traces) == first, traces[first:]
    for (EI, _, _), result in zip(curves, fitted, strict=True):
        assert result.converged and result.values["EI"] == pytest.approx(EI, rel=1e-6), result.summary()


def test_jitted_user_function_of_a_network_traces_once(traces):
    """A network is a pytree of values with a static topology: jax.jit of a user function
    of it traces once for all values, and again only for a new topology."""
    f = jax.jit(lambda net: sj.solve(net, {-1: jnp.array([0.0, 1.0])}).positions[-1])
    a = f(sj.cantilever(4, dim=2, EI=1.0))
    first = len(traces)
    b = f(sj.cantilever(4, dim=2, EI=2.0))
    assert len(traces) == first, traces[first:]
    assert float(b[1]) < float(a[1])  # stiffer: less deflection
