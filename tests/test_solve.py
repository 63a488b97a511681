"""The public solve API: loads, results, statuses, loud failures."""

import numpy as np
import pytest

import socbjax as sj


@pytest.fixture(scope="module")
def net2():
    return sj.cantilever(3, dim=2)


def test_negative_index_equals_positive(net2):
    a = sj.solve(net2, {-1: [0.0, 1.0]})
    b = sj.solve(net2, {2: [0.0, 1.0]})
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-14)


def test_array_forces_equal_dict_forces(net2):
    arr = np.zeros((3, 2))
    arr[-1] = [0.3, 1.0]
    np.testing.assert_allclose(sj.solve(net2, arr).positions, sj.solve(net2, {-1: [0.3, 1.0]}).positions, atol=1e-14)


def test_solution_fields(net2):
    sol = sj.solve(net2, {-1: [0.0, 1.0]})
    assert sol.converged and sol.result == sj.RESULTS.successful
    assert sol.positions.shape == (3, 2) and sol.angles.shape == (3,) and sol.curvatures.shape == (3,)
    assert float(sol.residual_norm) <= 1e-12 and float(sol.load_factor) == 1.0
    # free end: zero curvature; clamp: reaction balances the load; base moment = r_tip × F
    assert abs(float(sol.curvatures[-1])) < 1e-10
    np.testing.assert_allclose(sol.reactions[0], [0.0, -1.0], atol=1e-10)
    tip = np.asarray(sol.positions[-1])
    assert abs(float(sol.moments[0]) - tip[0] * 1.0) < 1e-10
    assert "converged=True" in repr(sol)


def test_force_scales_with_EI():
    """Same shape when force and EI scale together (units: pN and pN·µm²)."""
    a = sj.solve(sj.cantilever(4, dim=2), {-1: [0.0, 2.0]})
    b = sj.solve(sj.cantilever(4, dim=2, EI=0.071), {-1: [0.0, 2.0 * 0.071]})
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-12)
    np.testing.assert_allclose(np.asarray(b.moments), 0.071 * np.asarray(a.moments), atol=1e-12)


@pytest.mark.parametrize(
    "forces, match",
    [
        ({5: [0.0, 1.0]}, "node 5"),
        ({-4: [0.0, 1.0]}, "node -4"),
        ({-1: [0.0, 1.0, 0.0]}, "2 components"),
        ({-1: [0.0, float("nan")]}, "NaN"),
        ({-1: [float("inf"), 0.0]}, "NaN or infinite"),
        (np.zeros((2, 2)), "shape"),
    ],
)
def test_bad_forces(net2, forces, match):
    with pytest.raises(ValueError, match=match):
        sj.solve(net2, forces)


def test_bad_model_and_network(net2):
    with pytest.raises(ValueError, match="unknown model"):
        sj.solve(net2, {-1: [0.0, 1.0]}, model="fem")
    with pytest.raises(TypeError, match="Network"):
        sj.solve("not a network", {-1: [0.0, 1.0]})


def test_perfect_column_past_buckling_fails_loudly():
    """Axial load beyond π²/4 on a perfect column: no equilibrium continues the path."""
    net = sj.column(3, dim=2)
    with pytest.raises(sj.ConvergenceError, match="critical point"):
        sj.solve(net, {-1: [-3.0, 0.0]})
    sol = sj.solve(net, {-1: [-3.0, 0.0]}, throw=False)
    assert not sol.converged and sol.result == sj.RESULTS.critical_point
    assert 0.0 < float(sol.load_factor) < 1.0
    assert float(sol.load_factor) * 3.0 <= np.pi**2 / 4 * 1.001
    assert np.all(np.isfinite(np.asarray(sol.positions)))


def test_below_buckling_perfect_column_stays_straight():
    sol = sj.solve(sj.column(3, dim=2), {-1: [-2.0, 0.0]})
    np.testing.assert_allclose(sol.positions[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(sol.segment_forces, [[-2.0, 0.0]] * 2, atol=1e-12)


# ----------------------------------------------------------------- sparse Jacobian solver
@pytest.mark.slow
def test_sparse_and_dense_agree_on_a_branched_3d_network():
    net = sj.dendritic_outcrop(generations=3, gap=30.0, dim=3, seed=2)  # root clamped, tips free
    rng = np.random.default_rng(0)
    forces = 0.02 * rng.normal(size=(net.n_nodes, 3))
    dense = sj.solve(net, forces, settings=sj.PathSettings(linear_solver="dense"))
    sparse = sj.solve(net, forces, settings=sj.PathSettings(linear_solver="sparse"))
    assert dense.converged and sparse.converged
    assert int(sparse.steps) == int(dense.steps) and int(sparse.iterations) == int(dense.iterations)
    np.testing.assert_allclose(sparse.positions, dense.positions, atol=1e-11)
    moved = np.abs(np.asarray(dense.positions) - np.asarray(net.positions)).max()
    assert moved > 0.05  # a real deflection, not the trivial state


@pytest.mark.slow
def test_long_chain_sparse_matches_exact_elastica():
    """3,000 segments, P L²/EI = 2: the residual's round-off floor (ε max|r|/ℓ ≈ 7e-13) is
    above 1e-12 here, so default_atol raises the tolerance; the tip still matches the exact
    elastica (diffrax shooting) to the solver's accuracy."""
    from socbjax.testing import elastica_tip_deflection

    length, EI, n_seg = 10.0, 1.0, 3000
    net = sj.cantilever(n_nodes=n_seg + 1, length=length, EI=EI, dim=2)
    assert float(sj.default_atol(net)) > 1e-12
    sol = sj.solve(net, {-1: [0.0, 2.0 * EI / length**2]})  # "auto" -> sparse at 18,004 unknowns
    dx, dy = elastica_tip_deflection(2.0)
    tip = np.asarray(sol.positions[-1]) / length
    assert sol.converged
    assert abs(1.0 - tip[0] - dx) < 1e-9 and abs(tip[1] - dy) < 1e-9


def test_default_atol():
    assert float(sj.default_atol(sj.cantilever(5, dim=2))) == 1e-12
    floor = float(sj.default_atol(sj.cantilever(10001, length=10.0, dim=2)))
    assert 2e-11 < floor < 5e-11  # 16 ε · 10 µm / 1 nm


@pytest.mark.slow
def test_too_tight_tolerance_on_a_long_chain_names_the_round_off_floor():
    net = sj.cantilever(n_nodes=3001, length=10.0, dim=2)
    with pytest.raises(sj.ConvergenceError, match="round-off floor"):
        sj.solve(net, {-1: [0.0, 0.02]}, settings=sj.PathSettings(atol=1e-14, linear_solver="sparse"))


@pytest.mark.slow  # suite time; in the default suite: transposed sparse solves and jit/vmap: tests/test_linear.py
def test_gradients_of_a_1000_segment_chain_with_the_sparse_solver():
    """d(tip)/d(EI) and d(tip)/d(P) of a 1,000-segment cantilever (6,004 unknowns) through the
    coloured sparse Jacobian + SuperLU (transposed solve for reverse mode), under jit: equal
    to central finite differences of full re-solves, and to the exact scaling identity
    EI ∂/∂EI = −P ∂/∂P (the shape depends on P L²/EI only)."""
    import jax
    import jax.numpy as jnp

    length, EI, P = 10.0, 1.0, 0.02  # P L²/EI = 2
    settings = sj.PathSettings(linear_solver="sparse")

    def tip_y(EI_, P_):
        net = sj.cantilever(n_nodes=1001, length=length, EI=EI_, dim=2)
        return sj.solve(net, {-1: jnp.stack([0.0, -P_])}, settings=settings).positions[-1, 1]

    value, grad = jax.jit(jax.value_and_grad(tip_y, argnums=(0, 1)))(EI, P)
    h = 1e-4
    fd = np.array([(float(tip_y(EI * (1 + h), P)) - float(tip_y(EI * (1 - h), P))) / (2 * h * EI),
                   (float(tip_y(EI, P * (1 + h))) - float(tip_y(EI, P * (1 - h)))) / (2 * h * P)])
    np.testing.assert_allclose(np.asarray(grad), fd, rtol=1e-6)
    np.testing.assert_allclose(EI * float(grad[0]), -P * float(grad[1]), rtol=1e-9)
