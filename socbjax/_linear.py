"""Linear-algebra back ends for Newton on large, sparse square systems F: R^n -> R^n.

Both solvers answer the same question at a point x: X = J^{-1} rhs (or J^{-T} rhs) with
J = dF/dx(x) [n, n], rhs [n, k] (or [n]), together with sign(det J) (+1., -1., 0. when
singular) that continuation uses to detect critical points.  Both work inside ``jax.jit``,
``lax.while_loop`` and ``jax.vmap``, and as arguments of ``eqx.filter_jit`` (they hold no
array leaves, only static host data).

* :class:`DenseJacobianSolver`: ``jax.jacfwd`` + dense LU (O(n^2) memory, O(n^3) time).
* :class:`SparseJacobianSolver`: the sparsity pattern of J is found once on the host
  (:meth:`~SparseJacobianSolver.prepare`) by dense probing at two random points, its
  columns are coloured so that no two columns of one colour share a row, and then every
  Jacobian costs one batched JVP over the ``n_colors`` seed vectors (Curtis-Powell-Reid
  compression).  The factorisation is SciPy's SuperLU, reached by ``jax.pure_callback``.
  No gradients flow through the callback; ``transpose=True`` serves adjoint solves.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jax import Array

__all__ = ["SPARSE_THRESHOLD", "DenseJacobianSolver", "SparseJacobianSolver", "color_columns", "jacobian_solver",
           "sparsity_pattern"]

SPARSE_THRESHOLD = 1500  # "auto" picks the sparse solver above this many unknowns


class _Frozen:
    """A read-only numpy array, hashed and compared by content (fit for a static field)."""

    __slots__ = ("_key", "a")

    def __init__(self, a):
        a = np.array(a, copy=True)
        a.setflags(write=False)
        self.a = a
        self._key = (a.shape, a.dtype.str, hashlib.blake2b(a.tobytes(), digest_size=16).digest())

    def __hash__(self) -> int:
        return hash(self._key)

    def __eq__(self, other) -> bool:
        return self is other or (isinstance(other, _Frozen) and self._key == other._key)

    def __repr__(self) -> str:
        return f"_Frozen(shape={self.a.shape}, dtype={self.a.dtype})"


# ----------------------------------------------------------------------------- dense
def _lu_sign(lu: Array, piv: Array) -> Array:
    """sign(det) from LAPACK-style ``lu`` [n, n] and row-swap pivots ``piv`` [n]; 0 if singular."""
    swaps = jnp.sum(piv != jnp.arange(piv.shape[-1]), axis=-1)
    sign = jnp.prod(jnp.sign(jnp.diagonal(lu, axis1=-2, axis2=-1)), axis=-1) * (1 - 2 * (swaps % 2))
    return jnp.where(jnp.isfinite(sign), sign, 0).astype(lu.dtype)


class DenseJacobianSolver(eqx.Module):
    """J = ``jax.jacfwd(fn)(x)`` and ``jax.scipy.linalg.lu_factor`` / ``lu_solve``."""

    def prepare(self, fn: Callable, x_example) -> DenseJacobianSolver:
        """Nothing to precompute; returns self."""
        return self

    def solve(self, fn: Callable, x: Array, rhs: Array, *, transpose: bool = False) -> tuple[Array, Array]:
        """X = J^{-1} rhs (J^{-T} rhs if ``transpose``), J = dfn/dx(x) [n, n], rhs [n, k] or [n].

        Returns (X like rhs, sign(det J) as a float scalar: +1, -1, or 0 when singular).
        """
        lu, piv = jax.scipy.linalg.lu_factor(jax.jacfwd(fn)(x))
        X = jax.scipy.linalg.lu_solve((lu, piv), rhs.astype(lu.dtype), trans=1 if transpose else 0)
        return X, _lu_sign(lu, piv)


# ------------------------------------------------------------------- sparsity, colours
def sparsity_pattern(fn: Callable, x_example, *, seed: int = 0, chunk: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Exact nonzero pattern of J = dfn/dx, host side.

    J is probed column by column (``chunk`` unit vectors per batched JVP, one compilation)
    at two points x_example + N(0, 1) noise; an entry belongs to the pattern if it is
    nonzero (or NaN) at either point.  Returns (rows, cols), int32 arrays [nnz] in CSC order
    (sorted by column, then row).
    """
    x0 = np.asarray(x_example)
    n, dtype = x0.size, x0.dtype
    chunk = int(min(chunk, n))
    pts = jnp.asarray(x0.reshape(1, n) + np.random.default_rng(seed).standard_normal((2, n)), dtype)

    @jax.jit
    def probe(start):  # -> bool [chunk, n]: [column - start, row]
        unit = (start + jnp.arange(chunk)[:, None] == jnp.arange(n)[None, :]).astype(dtype)
        jac_t = jax.vmap(lambda p: jax.vmap(lambda e: jax.jvp(fn, (p,), (e,))[1])(unit))(pts)
        return jnp.any(jac_t != 0, axis=0)

    rows, cols = [], []
    for start in range(0, n, chunk):
        c, r = np.nonzero(np.asarray(probe(jnp.asarray(start, jnp.int32))))
        keep = c + start < n
        cols.append(c[keep] + start)
        rows.append(r[keep])
    return np.concatenate(rows).astype(np.int32), np.concatenate(cols).astype(np.int32)


def color_columns(rows: np.ndarray, cols: np.ndarray, n: int, *, seed: int = 0) -> np.ndarray:
    """Greedy colouring of the columns of an n x n pattern; columns sharing a row differ.

    Largest-first order: decreasing degree in the column-intersection graph (pattern of
    A^T A), ties broken by a seeded random permutation.  Computed in vectorised rounds
    (Jones-Plassmann): a column takes the smallest colour unused by its neighbours once all
    its higher-priority neighbours have one, which gives exactly the sequential greedy
    colouring in that order.  Returns colours int32 [n] in 0 .. n_colors-1.
    """
    A = sp.csc_matrix((np.ones(rows.size, np.int32), (rows, cols)), shape=(n, n))
    G = (A.T @ A).tocoo()
    off = G.row != G.col
    a, b = G.row[off].astype(np.int64), G.col[off].astype(np.int64)  # both directions present
    degree = np.bincount(a, minlength=n)
    order = np.lexsort((np.random.default_rng(seed).permutation(n), -degree))
    prio = np.empty(n, np.int64)
    prio[order] = np.arange(n)  # smaller = coloured earlier
    colors = np.full(n, -1, np.int64)
    while (uncol := colors < 0).any():
        live = uncol[a]
        a, b = a[live], b[live]  # only edges out of uncoloured columns still matter
        blocked = np.zeros(n, bool)
        blocked[a[uncol[b] & (prio[b] < prio[a])]] = True
        sel = uncol & ~blocked
        slot = np.cumsum(sel) - 1
        e = sel[a] & ~uncol[b]  # selected column -> already coloured neighbour
        taken = np.zeros((int(sel.sum()), int(colors.max()) + 2), bool)
        taken[slot[a[e]], colors[b[e]]] = True
        colors[sel] = np.argmin(taken, axis=1)  # first free colour
    return colors.astype(np.int32)


# ---------------------------------------------------------------------- sparse solve
def _perm_sign(p: np.ndarray) -> int:
    """Sign (+1/-1) of the permutation p [n]: (-1)^(n - #cycles), cycles by pointer jumping."""
    n = p.size
    label, jump = np.arange(n), np.asarray(p, np.int64)
    for _ in range(int(np.ceil(np.log2(max(n, 2))))):
        label = np.minimum(label, label[jump])  # min over i, p(i), ..., p^(2^k - 1)(i)
        jump = jump[jump]
    cycles = np.count_nonzero(label == np.arange(n))
    return 1 - 2 * ((n - cycles) % 2)


def _splu_host(vals, rhs, *, indices, indptr, n, transpose, permc_spec):
    """Host side of the sparse solve: CSC values [nnz], rhs [n, k] -> (X [n, k], sign ())."""
    vals, rhs = np.asarray(vals), np.asarray(rhs)
    failed = np.full(rhs.shape, np.nan, rhs.dtype), np.zeros((), rhs.dtype)
    if not np.all(np.isfinite(vals)):
        return failed
    try:
        lu = spla.splu(sp.csc_matrix((vals, indices, indptr), shape=(n, n)), permc_spec=permc_spec)
        X = lu.solve(np.array(rhs, order="F"), trans="T" if transpose else "N")
        d = lu.U.diagonal()
        sign = 0 if np.any(d == 0) else (1 - 2 * (np.count_nonzero(d < 0) % 2))
        sign *= _perm_sign(lu.perm_r) * _perm_sign(lu.perm_c)
    except Exception:  # noqa: BLE001  (singular / failed factorisation: never raise in a callback)
        return failed
    return np.asarray(X, rhs.dtype).reshape(rhs.shape), np.asarray(sign, rhs.dtype)


class SparseJacobianSolver(eqx.Module):
    """Colour-compressed forward-mode Jacobian + SuperLU (``scipy.sparse.linalg.splu``).

    Build unprepared (``SparseJacobianSolver()``) and call :meth:`prepare` host side,
    outside jit; the prepared solver holds only static host data: the pattern ``rows``,
    ``cols`` [nnz] (CSC order) with ``indptr`` [n+1], column ``colors`` [n] and the flat
    ``gather`` index [nnz] of each nonzero in the compressed Jacobian [n_colors, n].
    ``permc_spec`` is SuperLU's column ordering: minimum degree on the pattern of A^T + A
    suits the (nearly) structurally symmetric tree-of-blocks Jacobians (no fill on a tree;
    at n = 10,000 it factored ~2x faster than COLAMD, see benchmarks/linear_timing.py).
    """

    n: int = eqx.field(static=True, default=-1)
    n_colors: int = eqx.field(static=True, default=0)
    rows: _Frozen | None = eqx.field(static=True, default=None)
    cols: _Frozen | None = eqx.field(static=True, default=None)
    indptr: _Frozen | None = eqx.field(static=True, default=None)
    colors: _Frozen | None = eqx.field(static=True, default=None)
    gather: _Frozen | None = eqx.field(static=True, default=None)
    permc_spec: str = eqx.field(static=True, default="MMD_AT_PLUS_A")

    @property
    def nnz(self) -> int:
        return 0 if self.rows is None else int(self.rows.a.size)

    def prepare(self, fn: Callable, x_example, *, seed: int = 0) -> SparseJacobianSolver:
        """Detect the pattern of dfn/dx and colour its columns; returns a prepared copy.

        ``fn`` maps x [n] -> [n]; its sparsity must not depend on captured parameter values.
        """
        rows, cols = sparsity_pattern(fn, x_example, seed=seed)
        return self.from_pattern(rows, cols, int(np.size(x_example)), seed=seed, permc_spec=self.permc_spec)

    @classmethod
    def from_pattern(cls, rows, cols, n: int, *, seed: int = 0, permc_spec: str = "MMD_AT_PLUS_A"):
        """A prepared solver for a known pattern: ``rows``, ``cols`` [nnz] in CSC order (sorted
        by column, then row, no duplicates); entries outside it are taken as zero."""
        rows, cols = np.asarray(rows, np.int32), np.asarray(cols, np.int32)
        colors = color_columns(rows, cols, n, seed=seed)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n))]).astype(np.int32)
        gather = colors[cols].astype(np.int64) * n + rows
        return cls(n=n, n_colors=int(colors.max()) + 1 if n else 0, rows=_Frozen(rows), cols=_Frozen(cols),
                   indptr=_Frozen(indptr), colors=_Frozen(colors), gather=_Frozen(gather), permc_spec=permc_spec)

    def _check(self, x: Array) -> None:
        if self.rows is None:
            raise ValueError("SparseJacobianSolver: call .prepare(fn, x_example) (outside jit) before solve")
        if x.shape != (self.n,):
            raise ValueError(f"SparseJacobianSolver prepared for x of shape ({self.n},), got {x.shape}")

    def jacobian_values(self, fn: Callable, x: Array) -> Array:
        """Nonzeros of J(x) [nnz] in CSC order, from one vmapped JVP over the colour seeds."""
        self._check(x)
        seeds = (jnp.arange(self.n_colors)[:, None] == jnp.asarray(self.colors.a)[None, :]).astype(x.dtype)
        compressed = jax.vmap(lambda s: jax.jvp(fn, (x,), (s,))[1])(seeds)  # [n_colors, n]
        return compressed.reshape(-1)[jnp.asarray(self.gather.a)]

    def solve_values(self, vals: Array, rhs: Array, *, transpose: bool = False) -> tuple[Array, Array]:
        """Factor the CSC matrix with nonzeros ``vals`` [nnz] and solve rhs [n, k] (or [n])."""
        dtype = jnp.result_type(vals.dtype, rhs.dtype)
        host = functools.partial(_splu_host, indices=self.rows.a, indptr=self.indptr.a, n=self.n,
                                 transpose=bool(transpose), permc_spec=self.permc_spec)
        out = (jax.ShapeDtypeStruct(rhs.shape, dtype), jax.ShapeDtypeStruct((), dtype))
        return jax.pure_callback(host, out, vals.astype(dtype), rhs.astype(dtype), vmap_method="sequential")

    def solve(self, fn: Callable, x: Array, rhs: Array, *, transpose: bool = False) -> tuple[Array, Array]:
        """X = J^{-1} rhs (J^{-T} rhs if ``transpose``), J = dfn/dx(x), rhs [n, k] or [n].

        Returns (X like rhs, sign(det J) float scalar); X is NaN and sign 0 when J is singular
        or non-finite.
        """
        return self.solve_values(self.jacobian_values(fn, x), rhs, transpose=transpose)


def jacobian_solver(kind: str, n: int) -> DenseJacobianSolver | SparseJacobianSolver:
    """``"dense"``, ``"sparse"`` or ``"auto"`` (sparse when n > SPARSE_THRESHOLD); unprepared."""
    if kind == "auto":
        kind = "sparse" if n > SPARSE_THRESHOLD else "dense"
    if kind == "dense":
        return DenseJacobianSolver()
    if kind == "sparse":
        return SparseJacobianSolver()
    raise ValueError(f"unknown Jacobian solver kind {kind!r}; use 'dense', 'sparse' or 'auto'")
