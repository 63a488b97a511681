"""The lineax solvers of socbjax: DenseLU and the colour-compressed ColouredSparseLU
(solutions, transposed solves and determinant signs against numpy; patterns and colourings
against dense Jacobians), and the Bordered solver of path following."""

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import pytest
import scipy.sparse as sp

import socbjax as sj


def solve(solver, fn, x, rhs, transpose=False):
    """X = J⁻¹ rhs (J⁻ᵀ if transpose) for rhs [n, k] and sign(det J), through the lineax
    solver interface (init, transpose, compute), several right-hand sides under vmap."""
    operator = lx.JacobianLinearOperator(lambda y, _: fn(y), x)
    state = solver.init(operator, {})
    if transpose:
        state, _ = solver.transpose(state, {})
    X, _, stats = jax.vmap(lambda b: solver.compute(state, b, {}), out_axes=(1, None, 0))(rhs.T)
    return X, stats["sign"][0]


def prepare(fn, x):
    return sj.ColouredSparseLU.probe(fn, x)


def tree_function(m: int, b: int = 6, seed: int = 0, flip=()):
    """Residual x [m b] -> [m b] on a random tree of m blocks of size b (dense blocks, nonlinear).

    Block i depends on itself and its tree neighbours; the rows in ``flip`` change sign.
    """
    rng = np.random.default_rng(seed)
    parent = np.array([i - 1 if rng.random() < 0.7 else rng.integers(0, i) for i in range(1, m)], int)
    child = np.arange(1, m)
    dst, src = np.concatenate([child, parent]), np.concatenate([parent, child])
    M = jnp.asarray(4.0 * np.eye(b) + 0.4 * rng.standard_normal((m, b, b)))
    W = jnp.asarray(0.3 * rng.standard_normal((dst.size, b, b)))
    s = np.ones(m * b)
    s[list(flip)] = -1.0
    s = jnp.asarray(s)

    def fn(x):
        X = x.reshape(m, b)
        own = jnp.einsum("mij,mj->mi", M, X) + 0.3 * jnp.sin(X) * jnp.exp(0.1 * X.sum(1, keepdims=True))
        cpl = jnp.einsum("eij,ej->ei", W, jnp.sin(X[src])) * (1 + 0.2 * jnp.cos(X[dst].sum(1, keepdims=True)))
        return s * (own + jax.ops.segment_sum(cpl, dst, m)).reshape(-1)

    return fn


def point(n, seed=1):
    return jnp.asarray(np.random.default_rng(seed).standard_normal(n))


@pytest.fixture(scope="module")
def case():
    fn = tree_function(60)  # n = 360
    x = point(360)
    return fn, x, prepare(fn, x)


def test_pattern_equals_dense_nonzeros(case):
    fn, _, solver = case
    J = np.asarray(jax.jacfwd(fn)(point(360, seed=7)))
    rows, cols = solver.rows.a, solver.cols.a
    dense = np.zeros_like(J, bool)
    dense[rows, cols] = True
    np.testing.assert_array_equal(dense, J != 0)
    assert rows.size == np.count_nonzero(J)
    key = cols.astype(np.int64) * J.shape[0] + rows
    assert np.all(np.diff(key) > 0)  # CSC order
    np.testing.assert_array_equal(solver.indptr.a, np.concatenate([[0], np.cumsum((J != 0).sum(0))]))


def _sequential_greedy(rows, cols, n, seed):
    """Reference: one column at a time, same largest-first order as color_columns."""
    A = sp.csc_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    G = (A.T @ A).tolil()
    G.setdiag(0)
    G = G.tocsr()
    G.eliminate_zeros()
    degree = np.diff(G.indptr)
    order = np.lexsort((np.random.default_rng(seed).permutation(n), -degree))
    colors = np.full(n, -1)
    for j in order:
        used = set(colors[G.indices[G.indptr[j]:G.indptr[j + 1]]].tolist())
        colors[j] = next(c for c in range(n) if c not in used)
    return colors


def test_colouring_valid_small_and_greedy(case):
    solver = case[2]
    rows, cols, colors = solver.rows.a, solver.cols.a, solver.colors.a
    n = solver.n
    assert colors.shape == (n,) and colors.min() == 0 and solver.n_colors == colors.max() + 1
    # no row holds two columns of one colour: each (row, colour) pair occurs at most once
    pairs = rows.astype(np.int64) * solver.n_colors + colors[cols]
    assert np.unique(pairs).size == pairs.size
    max_row_nnz = np.bincount(rows, minlength=n).max()
    assert max_row_nnz <= solver.n_colors <= 1.5 * max_row_nnz
    np.testing.assert_array_equal(colors, _sequential_greedy(rows, cols, n, seed=0))


def test_colouring_of_irregular_pattern():
    rng = np.random.default_rng(3)
    n = 400
    A = (sp.random(n, n, density=0.01, random_state=4) + sp.eye(n)).tocsc()
    A.sort_indices()
    rows, cols = A.indices.astype(np.int32), np.repeat(np.arange(n), np.diff(A.indptr)).astype(np.int32)
    colors = sj.ColouredSparseLU.from_pattern(rows, cols, n, seed=int(rng.integers(100))).colors.a
    pairs = rows.astype(np.int64) * (colors.max() + 1) + colors[cols]
    assert np.unique(pairs).size == pairs.size


def test_from_pattern_matches_probe(case):
    solver = case[2]
    again = sj.ColouredSparseLU.from_pattern(solver.rows.a, solver.cols.a, solver.n)
    assert again == solver and hash(again) == hash(solver)


@pytest.mark.parametrize("transpose", [False, True])
def test_sparse_and_dense_solve_match_numpy(case, transpose):
    fn, x, solver = case
    J = np.asarray(jax.jacfwd(fn)(x))
    rhs = jnp.asarray(np.random.default_rng(2).standard_normal((x.size, 3)))
    ref = np.linalg.solve(J.T if transpose else J, np.asarray(rhs))
    for s in (solver, sj.DenseLU()):
        X, sign = jax.jit(lambda x, r, s=s: solve(s, fn, x, r, transpose))(x, rhs)
        assert X.shape == rhs.shape and X.dtype == jnp.float64
        assert np.max(np.abs(X - ref)) <= 1e-10 * np.max(np.abs(ref))
        assert sign == np.linalg.slogdet(J)[0]


@pytest.mark.parametrize("flip", [(), (0,), (5, 140), (1, 2, 3)])
def test_determinant_sign(flip):
    fn = tree_function(25, flip=flip)
    x = point(150, seed=5)
    sign_ref = np.linalg.slogdet(np.asarray(jax.jacfwd(fn)(x)))[0]
    assert sign_ref == (-1.0) ** len(flip)  # the unflipped J (4 I + small) has det > 0
    rhs = jnp.ones((150, 1))
    for s in (prepare(fn, x), sj.DenseLU()):
        for transpose in (False, True):
            sign = jax.jit(lambda x, s=s, t=transpose: solve(s, fn, x, rhs, t)[1])(x)
            assert float(sign) == sign_ref


def test_singular_and_nonfinite_give_nan_and_zero_sign():
    g = tree_function(10)
    x = point(60)
    rhs = jnp.ones((60, 2))
    for fn in (lambda x: g(x.at[3].set(0.0)),  # zero column: structurally singular
               lambda x: g(x).at[7].set(0.0)):  # zero row
        # (a numerically singular J, e.g. two equal rows, leaves a rounding-size pivot, as in LAPACK)
        solver = prepare(fn, x)
        X, sign = jax.jit(lambda x, s=solver, fn=fn: solve(s, fn, x, rhs))(x)
        assert np.all(np.isnan(X)) and sign == 0.0
        assert jax.jit(lambda x, fn=fn: solve(sj.DenseLU(), fn, x, rhs)[1])(x) == 0.0
    solver = prepare(g, x)
    X, sign = jax.jit(lambda x: solve(solver, g, x, rhs))(x.at[0].set(jnp.nan))
    assert np.all(np.isnan(X)) and sign == 0.0


@pytest.mark.parametrize("kind", ["dense", "sparse"])
def test_newton_with_each_solver(kind):
    g = tree_function(50)
    x_star = point(300, seed=11)
    target = g(x_star)

    def fn(x):
        return g(x) - target

    x0 = x_star + 0.2 * point(300, seed=12)
    inner = sj.DenseLU() if kind == "dense" else prepare(fn, x0)
    newton = sj.DampedNewton(atol=1e-13, linear_solver=inner)
    sol = jax.jit(lambda x0: optx.root_find(lambda y, _: fn(y), newton, x0, throw=False))(x0)
    assert sol.state.result == sj.RESULTS.successful and int(sol.state.iterations) < 20
    assert np.max(np.abs(sol.value - x_star)) < 1e-10


def test_filter_jit_argument_and_vmap(case):
    fn, x, solver = case
    traces = []

    @eqx.filter_jit
    def batched(s, xs, rhs):
        traces.append(1)
        return jax.vmap(lambda x: solve(s, fn, x, rhs))(xs)

    xs = jnp.stack([x, point(360, seed=3), point(360, seed=4)])
    rhs = jnp.asarray(np.random.default_rng(6).standard_normal((360, 2)))
    X, signs = batched(solver, xs, rhs)
    batched(prepare(fn, x), xs, rhs)  # equal static data: no retrace
    assert len(traces) == 1 and X.shape == (3, 360, 2) and signs.shape == (3,)
    for i in range(3):
        J = np.asarray(jax.jacfwd(fn)(xs[i]))
        ref = np.linalg.solve(J, np.asarray(rhs))
        assert np.max(np.abs(X[i] - ref)) <= 1e-10 * np.max(np.abs(ref))
        assert signs[i] == np.linalg.slogdet(J)[0]


def test_auto_choice_and_bordered_solver():
    small, large = sj.make_model(sj.cantilever(5, dim=2)), sj.make_model(sj.cantilever(400, dim=2))
    assert isinstance(sj.linear_solver_for(small, "auto"), sj.DenseLU)
    assert isinstance(sj.linear_solver_for(large, "auto"), sj.ColouredSparseLU)  # 2,398 unknowns > 1,500
    assert isinstance(sj.linear_solver_for(large, "dense"), sj.DenseLU)
    with pytest.raises(ValueError, match="linear_solver"):
        sj.linear_solver_for(small, "cholesky")
    # Bordered: [[J, c], [aᵀ, b]] solved by elimination equals the dense augmented solve
    fn = tree_function(8)
    x = point(48, seed=2)
    c, a, b = point(48, seed=3), point(48, seed=4), 0.7
    J = np.asarray(jax.jacfwd(fn)(x))
    aug = np.block([[J, np.asarray(c)[:, None]], [np.asarray(a)[None, :], np.array([[b]])]])
    operator = lx.JacobianLinearOperator(lambda y, _: jnp.concatenate([fn(y[:-1]) + y[-1] * c, (a @ y[:-1] + b * y[-1])[None]]),
                                         jnp.concatenate([x, jnp.zeros(1)]))
    for inner in (sj.DenseLU(), prepare(fn, x)):
        solver = sj.Bordered(inner)
        rhs = point(49, seed=5)
        sol = lx.linear_solve(operator, rhs, solver, options={"border": (a, jnp.asarray(b))})
        np.testing.assert_allclose(sol.value, np.linalg.solve(aug, np.asarray(rhs)), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(sol.stats["tangent"], np.linalg.solve(J, np.asarray(c)), rtol=1e-10, atol=1e-12)
        assert float(sol.stats["sign"]) == np.linalg.slogdet(J)[0]


@pytest.mark.slow
def test_large_tree_n2000():
    fn = tree_function(334, seed=2)  # n = 2004
    x = point(2004, seed=8)
    solver = prepare(fn, x)
    J = np.asarray(jax.jacfwd(fn)(x))
    assert solver.nnz == np.count_nonzero(J)
    assert solver.n_colors <= 1.5 * np.count_nonzero(J, axis=1).max()
    rhs = jnp.asarray(np.random.default_rng(9).standard_normal((2004, 4)))
    for transpose in (False, True):
        X, sign = jax.jit(lambda x, r, t=transpose: solve(solver, fn, x, r, t))(x, rhs)
        ref = np.linalg.solve(J.T if transpose else J, np.asarray(rhs))
        assert np.max(np.abs(X - ref)) <= 1e-10 * np.max(np.abs(ref))
        assert sign == np.linalg.slogdet(J)[0]
