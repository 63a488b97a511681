"""Dense and colour-compressed sparse Jacobian solvers (socbjax._linear)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

from socbjax import _linear as L


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
    return fn, x, L.SparseJacobianSolver().prepare(fn, x)


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
    colors = L.color_columns(rows, cols, n, seed=int(rng.integers(100)))
    pairs = rows.astype(np.int64) * (colors.max() + 1) + colors[cols]
    assert np.unique(pairs).size == pairs.size


def test_from_pattern_matches_prepare(case):
    solver = case[2]
    again = L.SparseJacobianSolver.from_pattern(solver.rows.a, solver.cols.a, solver.n)
    assert again == solver and hash(again) == hash(solver)


def test_permutation_sign():
    rng = np.random.default_rng(0)
    for n in (1, 2, 5, 17, 64):
        for _ in range(5):
            p = rng.permutation(n)
            assert L._perm_sign(p) == round(np.linalg.det(np.eye(n)[p]))


@pytest.mark.parametrize("transpose", [False, True])
def test_sparse_and_dense_solve_match_numpy(case, transpose):
    fn, x, solver = case
    J = np.asarray(jax.jacfwd(fn)(x))
    rhs = jnp.asarray(np.random.default_rng(2).standard_normal((x.size, 3)))
    ref = np.linalg.solve(J.T if transpose else J, np.asarray(rhs))
    for s in (solver, L.DenseJacobianSolver().prepare(fn, x)):
        X, sign = jax.jit(lambda x, r, s=s: s.solve(fn, x, r, transpose=transpose))(x, rhs)
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
    for s in (L.SparseJacobianSolver().prepare(fn, x), L.DenseJacobianSolver()):
        for transpose in (False, True):
            sign = jax.jit(lambda x, s=s, t=transpose: s.solve(fn, x, rhs, transpose=t)[1])(x)
            assert float(sign) == sign_ref


def test_singular_and_nonfinite_give_nan_and_zero_sign():
    g = tree_function(10)
    x = point(60)
    rhs = jnp.ones((60, 2))
    for fn in (lambda x: g(x.at[3].set(0.0)),  # zero column: structurally singular
               lambda x: g(x).at[7].set(0.0)):  # zero row
        # (a numerically singular J, e.g. two equal rows, leaves a rounding-size pivot, as in LAPACK)
        solver = L.SparseJacobianSolver().prepare(fn, x)
        X, sign = jax.jit(lambda x, s=solver, fn=fn: s.solve(fn, x, rhs))(x)
        assert np.all(np.isnan(X)) and sign == 0.0
        assert jax.jit(lambda x, fn=fn: L.DenseJacobianSolver().solve(fn, x, rhs)[1])(x) == 0.0
    solver = L.SparseJacobianSolver().prepare(g, x)
    X, sign = jax.jit(lambda x: solver.solve(g, x, rhs))(x.at[0].set(jnp.nan))
    assert np.all(np.isnan(X)) and sign == 0.0


def _newton(solver, fn, x0, iters=20):
    def body(c):
        x, k, _ = c
        dx, _ = solver.solve(fn, x, fn(x)[:, None])
        return x - dx[:, 0], k + 1, jnp.max(jnp.abs(dx))

    return jax.lax.while_loop(lambda c: (c[1] < iters) & (c[2] > 1e-13), body, (x0, 0, jnp.inf))


@pytest.mark.parametrize("kind", ["dense", "sparse"])
def test_newton_in_while_loop(kind):
    g = tree_function(50)
    x_star = point(300, seed=11)
    target = g(x_star)

    def fn(x):
        return g(x) - target

    x0 = x_star + 0.2 * point(300, seed=12)
    solver = L.jacobian_solver(kind, 300).prepare(fn, x0)
    x, k, _ = jax.jit(lambda x0: _newton(solver, fn, x0))(x0)
    assert int(k) < 20 and np.max(np.abs(x - x_star)) < 1e-10


def test_filter_jit_argument_and_vmap(case):
    fn, x, solver = case
    traces = []

    @eqx.filter_jit
    def solve(s, xs, rhs):
        traces.append(1)
        return jax.vmap(lambda x: s.solve(fn, x, rhs))(xs)

    xs = jnp.stack([x, point(360, seed=3), point(360, seed=4)])
    rhs = jnp.asarray(np.random.default_rng(6).standard_normal((360, 2)))
    X, signs = solve(solver, xs, rhs)
    solve(L.SparseJacobianSolver().prepare(fn, x), xs, rhs)  # equal static data: no retrace
    assert len(traces) == 1 and X.shape == (3, 360, 2) and signs.shape == (3,)
    for i in range(3):
        J = np.asarray(jax.jacfwd(fn)(xs[i]))
        ref = np.linalg.solve(J, np.asarray(rhs))
        assert np.max(np.abs(X[i] - ref)) <= 1e-10 * np.max(np.abs(ref))
        assert signs[i] == np.linalg.slogdet(J)[0]


def test_factory_and_unprepared():
    assert isinstance(L.jacobian_solver("auto", 1500), L.DenseJacobianSolver)
    assert isinstance(L.jacobian_solver("auto", 1501), L.SparseJacobianSolver)
    assert isinstance(L.jacobian_solver("dense", 10**5), L.DenseJacobianSolver)
    assert isinstance(L.jacobian_solver("sparse", 10), L.SparseJacobianSolver)
    with pytest.raises(ValueError):
        L.jacobian_solver("cholesky", 10)
    with pytest.raises(ValueError, match="prepare"):
        L.SparseJacobianSolver().solve(jnp.sin, jnp.ones(3), jnp.ones((3, 1)))


@pytest.mark.slow
def test_large_tree_n2000():
    fn = tree_function(334, seed=2)  # n = 2004
    x = point(2004, seed=8)
    solver = L.SparseJacobianSolver().prepare(fn, x)
    J = np.asarray(jax.jacfwd(fn)(x))
    assert solver.nnz == np.count_nonzero(J)
    assert solver.n_colors <= 1.5 * np.count_nonzero(J, axis=1).max()
    rhs = jnp.asarray(np.random.default_rng(9).standard_normal((2004, 4)))
    for transpose in (False, True):
        X, sign = jax.jit(lambda x, r, t=transpose: solver.solve(fn, x, r, transpose=t))(x, rhs)
        ref = np.linalg.solve(J.T if transpose else J, np.asarray(rhs))
        assert np.max(np.abs(X - ref)) <= 1e-10 * np.max(np.abs(ref))
        assert sign == np.linalg.slogdet(J)[0]
