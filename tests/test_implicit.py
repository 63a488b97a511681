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
