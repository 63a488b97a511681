"""implicit_root: derivatives of roots by the implicit function theorem, checked against
closed-form derivatives of an algebraic root and against the Newton path's independence."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj
from socbjax._linear import DenseJacobianSolver, SparseJacobianSolver


def _solver(kind, n):
    if kind == "dense":
        return DenseJacobianSolver()
    rows = np.concatenate([np.arange(n), np.arange(1, n)])
    cols = np.concatenate([np.arange(n), np.arange(n - 1)])
    order = np.lexsort((rows, cols))
    return SparseJacobianSolver.from_pattern(rows[order], cols[order], n)


def _root(a, b, kind="dense", guess=1.0):
    """x with x³ + a x − b + 0.1 (x shifted by one) = 0, componentwise but coupled through a
    lower-bidiagonal term, so the Jacobian is not diagonal."""
    n = b.shape[0]

    def F(x):
        coupling = jnp.concatenate([jnp.zeros(1), 0.1 * x[:-1]])
        return x**3 + a * x - b + coupling

    x, iterations, residual = sj.implicit_root(F, jnp.full(n, guess), _solver(kind, n), atol=1e-13)
    return x, iterations, residual


def _exact_derivatives(x, a):
    """dx/db and dx/da from differentiating F(x, a, b) = 0 by hand: J = diag(3x² + a) + 0.1 L."""
    n = x.size
    J = np.diag(3 * x**2 + a) + np.diag(np.full(n - 1, 0.1), -1)
    return np.linalg.inv(J), -np.linalg.solve(J, x)


@pytest.mark.parametrize("kind", ["dense", "sparse"])
def test_root_derivatives_equal_the_closed_form(kind):
    a, b = 2.0, jnp.array([0.5, 1.0, 3.0, -2.0])
    x, iterations, residual = _root(a, b, kind)
    assert float(residual) < 1e-12 and int(iterations) >= 3
    dx_db, dx_da = _exact_derivatives(np.asarray(x), a)
    np.testing.assert_allclose(jax.jacfwd(lambda bb: _root(a, bb, kind)[0])(b), dx_db, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(jax.jacrev(lambda bb: _root(a, bb, kind)[0])(b), dx_db, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(jax.grad(lambda aa: jnp.sum(_root(aa, b, kind)[0]))(a), dx_da.sum(), rtol=1e-10)


def test_derivative_does_not_depend_on_the_newton_path():
    """The iterations are not differentiated: warm starts that take different numbers of
    Newton iterations give the same derivative to rounding."""
    a, b = 2.0, jnp.array([0.5, 1.0, 3.0])
    grads, counts = [], []
    for guess in (0.9, 3.0):
        grads.append(jax.grad(lambda aa, g=guess: jnp.sum(_root(aa, b, guess=g)[0]))(a))
        counts.append(int(_root(a, b, guess=guess)[1]))
    assert counts[0] != counts[1]
    assert float(grads[0]) == pytest.approx(float(grads[1]), rel=1e-12)


def test_vmap_over_parameters_matches_separate_solves():
    b = jnp.array([0.5, 1.0, 3.0])
    a_values = jnp.array([1.0, 2.0, 5.0])
    batched = jax.vmap(lambda aa: jax.grad(lambda q: jnp.sum(_root(q, b)[0]))(aa))(a_values)
    for a, g in zip(a_values, batched):
        x = np.asarray(_root(float(a), b)[0])
        assert float(g) == pytest.approx(_exact_derivatives(x, float(a))[1].sum(), rel=1e-10)


@pytest.mark.slow
def test_gradients_of_a_1000_segment_chain_with_the_sparse_solver():
    """d(tip)/d(EI) and d(tip)/d(P) of a 1,000-segment cantilever (6,004 unknowns) through the
    coloured sparse Jacobian + SuperLU (transposed solve for reverse mode), under jit: equal
    to central finite differences of full re-solves, and to the exact scaling identity
    EI ∂/∂EI = −P ∂/∂P (the shape depends on P L²/EI only)."""
    from jax.flatten_util import ravel_pytree

    import equinox as eqx

    length, EI, P = 10.0, 1.0, 0.02  # P L²/EI = 2
    net = sj.cantilever(n_nodes=1001, length=length, EI=EI, dim=2)
    disc = sj.make_model(net)
    linsolver = sj.prepare_jacobian_solver(disc, "sparse")
    assert isinstance(linsolver, SparseJacobianSolver)
    start = sj.solve(net, {-1: [0.0, -P]}, linear_solver="sparse")
    x_star, unravel = ravel_pytree(start.state)
    frames = disc.frames(start.state)
    atol = sj.default_atol(net)

    @jax.jit
    def tip_y(theta):  # theta = (EI, P)
        model = sj.make_model(eqx.tree_at(lambda n: n.EI, net, jnp.full_like(net.EI, theta[0])))
        loads = jnp.zeros_like(net.positions).at[-1, 1].set(-theta[1])
        x, _, residual = sj.implicit_root(lambda y: model.residual(unravel(y), loads, frames), x_star, linsolver, atol=atol)
        return unravel(x).positions[-1, 1], residual

    theta = jnp.array([EI, P])
    (value, residual), grad = jax.value_and_grad(tip_y, has_aux=True)(theta)
    assert float(residual) <= atol
    np.testing.assert_allclose(float(value), float(start.positions[-1, 1]), atol=1e-10)

    def resolved(EI_, P_):
        return float(sj.solve(sj.cantilever(n_nodes=1001, length=length, EI=EI_, dim=2), {-1: [0.0, -P_]}).positions[-1, 1])

    h = 1e-4
    fd = np.array([(resolved(EI * (1 + h), P) - resolved(EI * (1 - h), P)) / (2 * h * EI),
                   (resolved(EI, P * (1 + h)) - resolved(EI, P * (1 - h))) / (2 * h * P)])
    np.testing.assert_allclose(np.asarray(grad), fd, rtol=1e-6)
    np.testing.assert_allclose(EI * float(grad[0]), -P * float(grad[1]), rtol=1e-9)
