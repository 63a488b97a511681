"""Linear solvers for the Newton systems J Δx = b of socbjax, as ``lineax`` solvers.

Both solvers act on a square operator J [n, n] over flat vectors [n] and assemble it from
matrix–vector products with ``seeds`` (:meth:`seeds`, :meth:`from_products`), so that one
batched product serves a whole Jacobian.  Every ``compute`` also returns sign(det J)
(+1, −1, or 0 when singular) in ``stats["sign"]``: load and path continuation use it to
detect critical points.  Both work inside ``jax.jit``, ``lax.while_loop``, ``lax.cond`` and
``jax.vmap``, and transpose (``solver.transpose``) for reverse-mode implicit derivatives.

* :class:`DenseLU` — J from n products with the unit vectors (``jax.jacfwd`` in effect),
  LAPACK LU (O(n²) memory, O(n³) time).
* :class:`ColouredSparseLU` — J's sparsity pattern is fixed on the host (from the network
  graph, :mod:`socbjax._sparsity`, or by probing, :func:`sparsity_pattern`); its columns are
  coloured so that no two columns of one colour share a row, and J costs one batched product
  over the ``n_colors`` seeds (Curtis–Powell–Reid).  The factorisation is SciPy's SuperLU,
  reached by ``jax.pure_callback``; several right-hand sides (``jax.vmap`` over the vector)
  share one factorisation.
* :class:`BlockDiagonal` — B independent systems of one shape stacked into one flat vector
  [B·n] (the sampled equilibria of a compression): the inner solver's seeds applied to all
  blocks at once give every block's Jacobian from one batched product; each block is
  factored on its own.
* :class:`Bordered` — the bordered system [[J, c], [aᵀ, b]] [Δx; Δp] = [r; h] of path
  following (J from an inner solver, the border column c = ∂F/∂p from the same batched
  product, the row (a, b) passed as ``options["border"]``), solved by block elimination with
  one factorisation of J; also returns J⁻¹c (the path tangent) in ``stats["tangent"]``.
"""

from __future__ import annotations

import functools
import hashlib

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jax import Array

__all__ = ["SPARSE_THRESHOLD", "DenseLU", "ColouredSparseLU", "Bordered", "BlockDiagonal", "color_columns",
           "sparsity_pattern", "solver_kind", "factor_solve", "AbstractFullRankSolver"]

SPARSE_THRESHOLD = 1500  # "auto" picks the sparse solver above this many unknowns


def solver_kind(kind: str, n: int) -> str:
    """``"dense"`` or ``"sparse"`` for ``kind`` in ("dense", "sparse", "auto") and n unknowns."""
    if kind not in ("dense", "sparse", "auto"):
        raise ValueError(f"linear_solver must be 'dense', 'sparse' or 'auto', got {kind!r}")
    if kind == "auto":
        return "sparse" if n > SPARSE_THRESHOLD else "dense"
    return kind


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


def _check_operator(operator: lx.AbstractLinearOperator) -> int:
    structure = operator.in_structure()
    if not isinstance(structure, jax.ShapeDtypeStruct) or len(structure.shape) != 1:
        raise ValueError(f"socbjax linear solvers act on flat vectors [n]; got the structure {structure}")
    if operator.out_structure().shape != structure.shape:
        raise ValueError("socbjax linear solvers need a square operator")
    return structure.shape[0]


class AbstractFullRankSolver(lx.AbstractLinearSolver):
    """lineax's queries for the socbjax solvers: real matrices (conj is the identity), square
    and of full rank (a singular J is a failed solve, reported by the caller)."""

    def conj(self, state, options):
        return state, options

    def assume_full_rank(self):
        return True

    def allow_dependent_columns(self, operator):
        return False

    def allow_dependent_rows(self, operator):
        return False


class _SeededSolver(AbstractFullRankSolver):
    """A solver that assembles J from products J·seedₖ (rows of :meth:`seeds`).

    ``factor(matvec, n, dtype, options)`` is ``init`` for a plain linear function (the
    linearisation of a residual): the root finder and the implicit adjoint call it directly,
    without wrapping the function into a lineax operator (whose closure conversion does not
    survive ``jax.shard_map``)."""

    def seeds(self, n: int, dtype) -> Array:
        raise NotImplementedError

    def from_products(self, products: Array, n: int):
        raise NotImplementedError

    def factor(self, matvec, n: int, dtype, options):
        return self.from_products(jax.vmap(matvec)(self.seeds(n, dtype)), n)

    def factor_bordered(self, matvec, n: int, dtype, options):
        """(state for J, border column c) of a bordered operator ``matvec`` over [x; p]
        [n + 1] (J = its [:n, :n] block, c = its [:n, n] column): one batched product of
        the seeds and the unit vector of p."""
        seeds = jnp.pad(self.seeds(n, dtype), ((0, 0), (0, 1)))
        seeds = jnp.concatenate([seeds, jnp.zeros((1, n + 1), dtype).at[0, n].set(1.0)])
        products = jax.vmap(matvec)(seeds)
        return self.from_products(products[:-1, :n], n), products[-1, :n]

    def init(self, operator, options):
        n = _check_operator(operator)
        return self.factor(operator.mv, n, operator.in_structure().dtype, options)


# ----------------------------------------------------------------------------- dense
def lu_sign(lu: Array, piv: Array) -> Array:
    """sign(det) from LAPACK-style ``lu`` [n, n] and row-swap pivots ``piv`` [n]; 0 if singular."""
    swaps = jnp.sum(piv != jnp.arange(piv.shape[-1]), axis=-1)
    sign = jnp.prod(jnp.sign(jnp.diagonal(lu, axis1=-2, axis2=-1)), axis=-1) * (1 - 2 * (swaps % 2))
    return jnp.where(jnp.isfinite(sign), sign, 0).astype(lu.dtype)


class DenseLU(_SeededSolver):
    """Dense LU (``jax.scipy.linalg.lu_factor``) of J assembled from n unit-vector products."""

    def seeds(self, n: int, dtype) -> Array:
        return jnp.eye(n, dtype=dtype)

    def from_products(self, products: Array, n: int):
        lu, piv = jax.scipy.linalg.lu_factor(products.T)  # products[k] = J e_k = column k
        return lu, piv, lu_sign(lu, piv), eqxi.Static(False)

    def compute(self, state, vector, options):
        lu, piv, sign, transpose = state
        x = jax.scipy.linalg.lu_solve((lu, piv), vector.astype(lu.dtype), trans=1 if transpose.value else 0)
        return x, lx.RESULTS.successful, {"sign": sign}

    def transpose(self, state, options):
        lu, piv, sign, transpose = state
        return (lu, piv, sign, eqxi.Static(not transpose.value)), options


# ------------------------------------------------------------------- sparsity, colours
def sparsity_pattern(fn, x_example, *, seed: int = 0, chunk: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Exact nonzero pattern of J = dfn/dx, host side, by probing.

    J is probed column by column (``chunk`` unit vectors per batched JVP, one compilation)
    at two points x_example + N(0, 1) noise; an entry belongs to the pattern if it is
    nonzero (or NaN) at either point.  Returns (rows, cols), int32 arrays [nnz] in CSC order.
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

    Largest-first order (decreasing degree in the column-intersection graph AᵀA, ties by a
    seeded permutation), computed in vectorised Jones–Plassmann rounds, which gives exactly
    the sequential greedy colouring in that order.  Returns colours int32 [n].
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
        label = np.minimum(label, label[jump])
        jump = jump[jump]
    cycles = np.count_nonzero(label == np.arange(n))
    return 1 - 2 * ((n - cycles) % 2)


def factor_solve(vals, rhs, *, indices, indptr, n, transpose, permc_spec):
    """One SuperLU factorisation of the CSC matrix ``vals`` [nnz], solving rhs [k, n]."""
    if not np.all(np.isfinite(vals)):
        return np.full(rhs.shape, np.nan), 0.0
    try:
        matrix = sp.csc_matrix((vals, indices, indptr), shape=(n, n), copy=True)
        # entries of the pattern that are exactly zero here (the idle contact slots of a near
        # list, socbjax._contact_near) would only add fill: the same matrix without them
        matrix.eliminate_zeros()
        lu = spla.splu(matrix, permc_spec=permc_spec)
        X = lu.solve(np.array(rhs.T, order="F"), trans="T" if transpose else "N").T
        d = lu.U.diagonal()
        sign = 0 if np.any(d == 0) else (1 - 2 * (np.count_nonzero(d < 0) % 2))
        sign *= _perm_sign(lu.perm_r) * _perm_sign(lu.perm_c)
    except Exception:  # noqa: BLE001  (singular / failed factorisation: never raise in a callback)
        return np.full(rhs.shape, np.nan), 0.0
    return X, float(sign)


def _splu_host(vals, rhs, active, **kw):
    """Host side of the sparse solve, batched: vals [..., nnz] (size-1 leading axes where
    unbatched), rhs [..., n] and the flags ``active`` [...] broadcast against each other;
    every distinct value set with an active right-hand side is factored once (inactive
    members — solves whose result a vmapped ``lax.cond`` discards — get zeros and sign 0).
    Returns (X like the broadcast rhs, sign [...])."""
    vals, rhs = np.asarray(vals), np.asarray(rhs)
    lead = np.broadcast_shapes(vals.shape[:-1], rhs.shape[:-1], np.shape(active))
    vals = vals.reshape((1,) * (len(lead) - vals.ndim + 1) + vals.shape)
    rhs = np.broadcast_to(rhs, lead + rhs.shape[-1:])
    active = np.broadcast_to(np.asarray(active, bool), lead)
    X, signs = np.zeros(rhs.shape, rhs.dtype), np.zeros(lead, rhs.dtype)
    for index in np.ndindex(vals.shape[:-1]):
        where = tuple(slice(None) if vals.shape[k] == 1 else i for k, i in enumerate(index))
        if not active[where].any():
            continue
        block = rhs[where]
        x, sign = factor_solve(vals[index], block.reshape(-1, block.shape[-1]), **kw)
        X[where], signs[where] = x.reshape(block.shape), sign
    return X, signs


class ColouredSparseLU(_SeededSolver):
    """Colour-compressed Jacobian + SuperLU (``scipy.sparse.linalg.splu``).

    Built by :meth:`from_pattern` (or :func:`socbjax._sparsity.prepare_sparse_solver`)
    outside jit; holds only static host data: the pattern ``rows``, ``cols`` [nnz] (CSC
    order) with ``indptr`` [n+1], column ``colors`` [n] and the flat ``gather`` index [nnz]
    of each nonzero in the compressed Jacobian [n_colors, n].  ``permc_spec`` is SuperLU's
    column ordering (COLAMD by default: on SOCB network Jacobians at straight states the
    symmetric minimum-degree ordering factored ~100× slower).
    """

    n: int = eqx.field(static=True)
    n_colors: int = eqx.field(static=True)
    rows: _Frozen = eqx.field(static=True)
    cols: _Frozen = eqx.field(static=True)
    indptr: _Frozen = eqx.field(static=True)
    colors: _Frozen = eqx.field(static=True)
    gather: _Frozen = eqx.field(static=True)
    permc_spec: str = eqx.field(static=True, default="COLAMD")

    @property
    def nnz(self) -> int:
        return int(self.rows.a.size)

    @classmethod
    def from_pattern(cls, rows, cols, n: int, *, seed: int = 0, permc_spec: str = "COLAMD") -> ColouredSparseLU:
        """A solver for a known pattern: ``rows``, ``cols`` [nnz] in CSC order (sorted by
        column, then row, no duplicates); entries outside it are taken as zero."""
        rows, cols = np.asarray(rows, np.int32), np.asarray(cols, np.int32)
        colors = color_columns(rows, cols, n, seed=seed)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n))]).astype(np.int32)
        gather = colors[cols].astype(np.int64) * n + rows
        return cls(n=n, n_colors=int(colors.max()) + 1 if n else 0, rows=_Frozen(rows), cols=_Frozen(cols),
                   indptr=_Frozen(indptr), colors=_Frozen(colors), gather=_Frozen(gather), permc_spec=permc_spec)

    @classmethod
    def probe(cls, fn, x_example, *, seed: int = 0, permc_spec: str = "COLAMD") -> ColouredSparseLU:
        """A solver for dfn/dx, its pattern found by probing (:func:`sparsity_pattern`)."""
        rows, cols = sparsity_pattern(fn, x_example, seed=seed)
        return cls.from_pattern(rows, cols, int(np.size(x_example)), seed=seed, permc_spec=permc_spec)

    def seeds(self, n: int, dtype) -> Array:
        if n != self.n:
            raise ValueError(f"ColouredSparseLU prepared for {self.n} unknowns, used with {n}")
        return (jnp.arange(self.n_colors)[:, None] == jnp.asarray(self.colors.a)[None, :]).astype(dtype)

    def from_products(self, products: Array, n: int):
        return products.reshape(-1)[jnp.asarray(self.gather.a)], eqxi.Static(False)

    def compute(self, state, vector, options):
        values, transpose = state
        dtype = jnp.result_type(values.dtype, vector.dtype)
        host = functools.partial(_splu_host, indices=self.rows.a, indptr=self.indptr.a, n=self.n,
                                 transpose=bool(transpose.value), permc_spec=self.permc_spec)
        out = (jax.ShapeDtypeStruct(vector.shape, dtype), jax.ShapeDtypeStruct((), dtype))
        active = jnp.asarray(options.get("active", True), bool)  # see DampedNewton.step
        x, sign = jax.pure_callback(host, out, values.astype(dtype), vector.astype(dtype), active,
                                    vmap_method="expand_dims")
        return x, lx.RESULTS.successful, {"sign": sign}

    def transpose(self, state, options):
        values, transpose = state
        return (values, eqxi.Static(not transpose.value)), options

    def values(self, fn, x: Array) -> Array:
        """Nonzeros of dfn/dx at x [nnz] in CSC order, from one batched JVP."""
        seeds = self.seeds(x.shape[0], x.dtype)
        return self.from_products(jax.vmap(lambda s: jax.jvp(fn, (x,), (s,))[1])(seeds), x.shape[0])[0]


# ------------------------------------------------------------------------- bordered
class Bordered(AbstractFullRankSolver):
    """The bordered system of path following, [[J, c], [aᵀ, b]] over flat [x; p] [n + 1].

    ``inner`` (:class:`DenseLU` or :class:`ColouredSparseLU`) factors J; J and the border
    column c = J_aug[:n, n] come from one batched product of the operator with the inner
    solver's seeds and the unit vector of p.  The border row (a [n], b) must be given as
    ``options["border"]`` (the constraint of the parametrisation is affine and known to the
    caller; it cannot be read off a column-compressed product).  Block elimination:
    J [u, v] = [r, c] (one factorisation, two right-hand sides), Δp = (h − a·u)/(b − a·v),
    Δx = u − v Δp.  ``stats``: ``sign`` = sign(det J) and ``tangent`` = J⁻¹c.
    """

    inner: _SeededSolver

    def init(self, operator, options):
        return self.factor(operator.mv, _check_operator(operator), operator.in_structure().dtype, options)

    def factor(self, matvec, m: int, dtype, options):
        """The state for the bordered operator ``matvec`` over [x; p] (m = n + 1)."""
        if "border" not in options:
            raise ValueError("Bordered needs options={'border': (a, b)}, the constraint row of the parametrisation")
        inner_state, c = self.inner.factor_bordered(matvec, m - 1, dtype, options)
        a, b = options["border"]
        return inner_state, c, a, b

    def compute(self, state, vector, options):
        inner_state, c, a, b = state
        r, h = vector[:-1], vector[-1]
        uv, _, stats = jax.vmap(lambda rhs: self.inner.compute(inner_state, rhs, options))(jnp.stack([r, c]))
        u, v = uv[0], uv[1]
        dp = (h - a @ u) / (b - a @ v)
        dx = u - v * dp
        out = {"sign": stats["sign"][0], "tangent": v}
        if "overflow" in stats:  # PairedSparseLU: more colours than prepared
            out["overflow"] = stats["overflow"][0]
        return jnp.concatenate([dx, dp[None]]), lx.RESULTS.successful, out

    def transpose(self, state, options):
        raise NotImplementedError("Bordered is a forward solver of path correctors; it is never transposed")


# -------------------------------------------------------------------- block diagonal
class BlockDiagonal(_SeededSolver):
    """``blocks`` independent square systems of size n = m / blocks, stacked as [B·n], each
    solved by ``inner``.  J is block diagonal, so seed k of the inner solver, repeated in
    every block, yields column k of every block in one product."""

    inner: _SeededSolver
    blocks: int = eqx.field(static=True)

    def seeds(self, m: int, dtype) -> Array:
        n = m // self.blocks
        return jnp.tile(self.inner.seeds(n, dtype), (1, self.blocks))

    def from_products(self, products: Array, m: int):
        n = m // self.blocks
        per_block = jnp.swapaxes(products.reshape(products.shape[0], self.blocks, n), 0, 1)  # [B, k, n]
        return jax.vmap(lambda p: self.inner.from_products(p, n))(per_block)

    def compute(self, state, vector, options):
        b = vector.reshape(self.blocks, -1)
        x, _, stats = jax.vmap(lambda st, r: self.inner.compute(st, r, options))(state, b)
        return x.reshape(-1), lx.RESULTS.successful, {"sign": jnp.prod(stats["sign"])}

    def transpose(self, state, options):
        return jax.vmap(lambda st: self.inner.transpose(st, options)[0])(state), options
