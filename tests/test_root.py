"""The one root finder (socbjax.DampedNewton through optimistix.root_find): convergence,
globalisation, honest failure statuses, and derivatives by the implicit function theorem
(optx.ImplicitAdjoint) against closed forms, dense and sparse, forward and reverse."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import socbjax as sj


def _solve(fn, y0, solver=None, args=None, adjoint=None):
    solver = sj.DampedNewton() if solver is None else solver
    adjoint = optx.ImplicitAdjoint(linear_solver=solver.linear_solver) if adjoint is None else adjoint
    return optx.root_find(fn, solver, y0, args, adjoint=adjoint, throw=False, max_steps=4096)


def test_converges_quadratically_under_jit():
    def fn(x, _):
        return jnp.array([x[0] ** 2 + x[1] ** 2 - 4.0, jnp.exp(x[0]) + x[1] - 1.0])

    sol = jax.jit(lambda x0: _solve(fn, x0))(jnp.array([1.0, -1.0]))
    assert sol.result == optx.RESULTS.successful and sol.state.result == sj.RESULTS.successful
    np.testing.assert_allclose(fn(sol.value, None), 0.0, atol=1e-12)
    assert 3 <= int(sol.state.iterations) < 10


def test_line_search_globalises_arctan():
    """Undamped Newton diverges on arctan from x0 = 3 (|x| grows every step); damped does not."""
    sol = _solve(lambda x, _: jnp.arctan(x), jnp.array([3.0]))
    assert sol.state.result == sj.RESULTS.successful and abs(float(sol.value[0])) < 1e-12
    undamped = optx.root_find(lambda x, _: jnp.arctan(x), optx.Newton(rtol=1e-12, atol=1e-12), jnp.array([3.0]),
                              throw=False, max_steps=20)
    assert not np.isfinite(float(undamped.value[0])) or abs(float(undamped.value[0])) > 1.0


@pytest.mark.parametrize(
    "fn, y0, expected",
    [
        (lambda x, _: x**2 + 1.0, jnp.array([0.5]), ("line_search_failed", "max_iterations", "singular")),
        (lambda x, _: jnp.sqrt(x - 10.0), jnp.array([1.0]), ("nonfinite",)),
    ],
    ids=["no-root", "nan-residual"],
)
def test_failures_are_statuses_not_answers(fn, y0, expected):
    sol = _solve(fn, y0, sj.DampedNewton(max_iterations=30))
    result = sol.state.result
    assert result != sj.RESULTS.successful
    assert any(result == getattr(sj.RESULTS, e) for e in expected)
    assert np.all(np.isfinite(np.asarray(sol.value))) or expected == ("nonfinite",)


def _chain(n=40):
    """A nonlinear chain 3x_i − x_{i−1} − x_{i+1} + 0.5 sin x_i − b_i = 0 (tree-structured J)."""
    b = jnp.linspace(0.1, 1.0, n)

    def fn(x, args):
        lap = 3 * x - jnp.concatenate([jnp.zeros(1), x[:-1]]) - jnp.concatenate([x[1:], jnp.zeros(1)])
        return lap + 0.5 * jnp.sin(x) - args * b

    return fn, jnp.zeros(n)


def test_sparse_and_dense_linear_solvers_agree_and_report_the_determinant_sign():
    fn, x0 = _chain()
    sparse = sj.ColouredSparseLU.probe(lambda x: fn(x, 1.0), x0)
    assert 3 <= sparse.n_colors <= 4  # tridiagonal: at least three colours, greedy needs at most four, whatever n
    results = {}
    for name, inner in (("dense", sj.DenseLU()), ("sparse", sparse)):
        sol = jax.jit(lambda x, a, inner=inner: _solve(fn, x, sj.DampedNewton(linear_solver=inner), a))(x0, 1.0)
        assert sol.state.result == sj.RESULTS.successful
        J = np.asarray(jax.jacfwd(lambda x: fn(x, 1.0))(sol.value))
        assert float(sol.state.sign) == np.sign(np.linalg.det(J))
        results[name] = np.asarray(sol.value)
    np.testing.assert_allclose(results["sparse"], results["dense"], atol=1e-13)


def _root(a, b, inner=None, guess=1.0):
    """x with x³ + a x − b + 0.1 x_{i−1} = 0 (lower-bidiagonal coupling: J not diagonal)."""
    def F(x, args):
        aa, bb = args
        return x**3 + aa * x - bb + jnp.concatenate([jnp.zeros(1), 0.1 * x[:-1]])

    solver = sj.DampedNewton(atol=1e-13, linear_solver=sj.DenseLU() if inner is None else inner)
    sol = _solve(F, jnp.full(b.shape[0], guess), solver, (a, b))
    return sol.value, sol.state.iterations


def _exact_derivatives(x, a):
    """dx/db and dx/da from differentiating F(x, a, b) = 0 by hand: J = diag(3x² + a) + 0.1 L."""
    J = np.diag(3 * x**2 + a) + np.diag(np.full(x.size - 1, 0.1), -1)
    return np.linalg.inv(J), -np.linalg.solve(J, x)


def _bidiagonal_solver(n):
    rows = np.concatenate([np.arange(n), np.arange(1, n)])
    cols = np.concatenate([np.arange(n), np.arange(n - 1)])
    order = np.lexsort((rows, cols))
    return sj.ColouredSparseLU.from_pattern(rows[order], cols[order], n)


@pytest.mark.parametrize("kind", ["dense", "sparse"])
def test_implicit_derivatives_equal_the_closed_form(kind):
    a, b = 2.0, jnp.array([0.5, 1.0, 3.0, -2.0])
    inner = sj.DenseLU() if kind == "dense" else _bidiagonal_solver(4)
    x, iterations = _root(a, b, inner)
    assert int(iterations) >= 3
    dx_db, dx_da = _exact_derivatives(np.asarray(x), a)
    np.testing.assert_allclose(jax.jacfwd(lambda bb: _root(a, bb, inner)[0])(b), dx_db, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(jax.jacrev(lambda bb: _root(a, bb, inner)[0])(b), dx_db, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(jax.grad(lambda aa: jnp.sum(_root(aa, b, inner)[0]))(a), dx_da.sum(), rtol=1e-10)


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


def test_vmap_of_grad_matches_the_closed_form():
    b = jnp.array([0.5, 1.0, 3.0])
    a_values = jnp.array([1.0, 2.0, 5.0])
    batched = jax.jit(jax.vmap(jax.grad(lambda q: jnp.sum(_root(q, b)[0]))))(a_values)
    for a, g in zip(a_values, batched):
        x = np.asarray(_root(float(a), b)[0])
        assert float(g) == pytest.approx(_exact_derivatives(x, float(a))[1].sum(), rel=1e-10)
