"""Sparse LU for SOCB Jacobians whose pattern moves with the filament–filament contact pairs.

With self-contact every pair slot p (:mod:`socbjax._contact_pairs`) couples two segments
i_p, j_p that change from path step to path step: its rows depend on the unknowns near both
segments, and its force, location and shape unknowns enter both segments' rows.  So the
Jacobian's pattern is data, not structure.  :class:`PairedSparseLU` keeps it exact:

* the *static part* — every row and unknown with the pair list empty, where an idle slot
  depends on itself only — is the refined graph pattern of :mod:`socbjax._sparsity`, found
  once per topology;
* the *pair part*, per pair list: the rows of pair p depend on every unknown that a row of
  segment i_p or j_p depends on in the static part (the curve at the pair's points is the
  segment kernel's, which reads nothing else; the end nodes' places and directors that the
  rows also read are the kernel's inputs too) and on the slots of the pairs that share one
  of its segments (their forces act on the same kernels); the rows within graph distance 2
  of i_p or j_p depend on p's unknowns (its force acts on both kernels, and through their
  end forces on the node rows).  A slot's two id unknowns stay out: their rows are
  x_id − list id alone.  (The pair rows' dependencies were first taken as everything
  within graph distance 2 of both segments: 317 unknowns for the widest pair row on the
  6-generation outcrop with 21 pairs, 368 colours; from the kernel rows: 208 and 279.)

Per distinct pair list (host side, cached): the union pattern, coloured greedily
(:func:`socbjax._linear.color_columns`, Curtis–Powell–Reid).  The colours go to the device,
where J costs one JVP per colour actually used, evaluated ``chunk`` colours at a time up to
``max_colors`` (static); SciPy's SuperLU factors it on the host as in
:class:`socbjax.ColouredSparseLU`.  More colours than ``max_colors`` (a very crowded
contact set) fail the solve, never a wrong Jacobian: the NaN direction comes with
``stats["overflow"]``, and Newton reports ``RESULTS.colour_capacity`` (host-driven
:func:`socbjax.compress` then doubles ``max_colors`` and goes on from its last step).

The pair list is read from the linearisation point ``options["point"]`` (DampedNewton and the
implicit adjoint pass it): a pair slot's first two unknowns are its segment ids.  The path
sets them to the step's list before its corrector (``PathProblem.hold_pairs``), so they are
that list from the first Newton iteration on.
"""

from __future__ import annotations

import collections
import functools

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import scipy.sparse as sp

from ._linear import AbstractFullRankSolver, color_columns, factor_solve

__all__ = ["PairGraph", "PairedSparseLU"]


def _indicator(rows, cols, shape) -> sp.csr_matrix:
    rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    return sp.csr_matrix((np.ones(rows.size, np.int32), (rows, cols)), shape=shape)


class PairGraph:
    """Host data of the pair part of a topology (built once, cached; hashed by identity).

    static : (rows, cols) [nnz] of the static part (CSC order) over n unknowns.
    reach : [V, V] sparse, vertices within graph distance 2 (nodes 0..N−1, segments N..N+S−1);
        only the segments' rows are kept.
    row_vertex : [n₀] the vertex of each of the first n₀ = n − P·W rows (the pair slots' rows
        are the last P·W).
    first_segment : N, the vertex of segment 0.
    """

    def __init__(self, static, n: int, n_pairs: int, width: int, reach, row_vertex, first_segment: int):
        rows, cols = static
        self.n, self.n_pairs, self.width, self.first_segment = n, n_pairs, width, first_segment
        n0, V = n - n_pairs * width, reach.shape[0]
        self.n_segments = V - first_segment
        self.static = _indicator(rows, cols, (n, n)).tocsc()
        self.segment_reach = sp.csr_matrix(reach, dtype=np.int32)[first_segment:]  # [S, V]
        self.rows_at = _indicator(np.arange(n0), row_vertex, (n, V))
        # [S, n]: the unknowns that some row of segment s depends on (its kernel's inputs)
        on_segment = np.flatnonzero(np.asarray(row_vertex) >= first_segment)
        segment_rows = _indicator(np.asarray(row_vertex)[on_segment] - first_segment, on_segment, (self.n_segments, n))
        self.kernel_inputs = sp.csr_matrix((segment_rows @ self.static.tocsr()) != 0, dtype=np.int32)
        live = np.arange(2, width)  # a slot's ids depend on nothing else
        flat = n0 + (np.arange(n_pairs)[:, None] * width + live).ravel()
        self.live = _indicator(flat, np.repeat(np.arange(n_pairs), live.size), (n, n_pairs))
        self._cache: collections.OrderedDict = collections.OrderedDict()

    def pattern(self, ids) -> tuple:
        """(indices int32 [nnz], indptr int32 [n+1], colours int32 [n], number of colours,
        gather int64 [nnz]: colour·n + row of each entry) for the pair list ``ids`` [P, 2]
        (−1: empty slot).  Cached per list."""
        ids = np.asarray(ids, np.int64).reshape(-1, 2)
        key = ids.tobytes()
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        pattern = self.static
        used = np.flatnonzero(np.all((ids >= 0) & (ids < self.n_segments), axis=1))
        if used.size:
            inc = _indicator(np.repeat(used, 2), ids[used].ravel(), (self.n_pairs, self.n_segments))  # [P, S]
            near = inc @ self.segment_reach  # [P, V]: pair p — vertices within 2 of its segments
            share = inc @ inc.T  # [P, P]: pairs with a segment in common
            pattern = (pattern + self.live @ (inc @ self.kernel_inputs) + self.rows_at @ near.T @ self.live.T
                       + self.live @ share @ self.live.T)
        pattern = sp.csc_matrix(pattern != 0)
        pattern.sort_indices()
        rows = pattern.indices.astype(np.int32)
        cols = np.repeat(np.arange(self.n), np.diff(pattern.indptr))
        colors = color_columns(rows, cols, self.n)
        entry = (rows, pattern.indptr.astype(np.int32), colors, int(colors.max()) + 1 if self.n else 0,
                 colors[cols].astype(np.int64) * self.n + rows)
        self._cache[key] = entry
        if len(self._cache) > 16:
            self._cache.popitem(last=False)
        return entry

    def colours(self, ids):
        """Host callback: (colours int32 [n], number of colours int32) of the list ``ids``."""
        _, _, colors, count, _ = self.pattern(ids)
        return colors, np.asarray(count, np.int32)

    def solve(self, products, ids, count, rhs, active, *, transpose: bool, max_colors: int):
        """Host callback, batched like :func:`socbjax._linear.ColouredSparseLU.compute`'s:
        products [..., K, n] (J·seeds), ids [..., P, 2], count [...], rhs [..., n], active
        [...]; each distinct state with an active right-hand side is factored once.  Returns
        (X like the broadcast rhs, sign(det J) [...])."""
        products, ids, count, rhs = (np.asarray(a) for a in (products, ids, count, rhs))
        lead = np.broadcast_shapes(products.shape[:-2], ids.shape[:-2], count.shape, rhs.shape[:-1], np.shape(active))
        grow = lambda a, core: a.reshape((1,) * (len(lead) - a.ndim + core) + a.shape)  # noqa: E731
        products, ids, count = grow(products, 2), grow(ids, 2), grow(count, 0)
        state_lead = np.broadcast_shapes(products.shape[:-2], ids.shape[:-2], count.shape)
        rhs = np.broadcast_to(rhs, lead + rhs.shape[-1:])
        active = np.broadcast_to(np.asarray(active, bool), lead)
        X, signs = np.zeros(rhs.shape, rhs.dtype), np.zeros(lead, rhs.dtype)
        for index in np.ndindex(state_lead):
            where = tuple(slice(None) if state_lead[k] == 1 else i for k, i in enumerate(index))
            if not active[where].any():
                continue
            pick = lambda a, i=index: a[tuple(0 if a.shape[k] == 1 else j for k, j in enumerate(i))]  # noqa: E731
            block = rhs[where].reshape(-1, self.n)
            if int(pick(count)) > max_colors:  # reported as stats["overflow"] (RESULTS.colour_capacity)
                x, sign = np.full(block.shape, np.nan), 0.0
            else:
                indices, indptr, _, _, gather = self.pattern(pick(ids))
                x, sign = factor_solve(pick(products).reshape(-1)[gather], block, indices=indices, indptr=indptr,
                                       n=self.n, transpose=transpose, permc_spec="COLAMD")
            X[where], signs[where] = x.reshape(rhs[where].shape), sign
        return X, signs


class PairedSparseLU(AbstractFullRankSolver):
    """Sparse LU of an SOCB Jacobian with filament–filament pair slots (see the module doc).

    Made by :func:`socbjax._sparsity.prepare_sparse_solver` for a model with self-contact.
    ``factor`` needs ``options["point"]``, the flat state [n] (or [n + 1] bordered) at
    which J is taken: its pair slots hold the pair list.  Not for :class:`BlockDiagonal`
    (every block would need its own colours); batched re-solves use dense LU.
    """

    graph: PairGraph = eqx.field(static=True)
    n: int = eqx.field(static=True)
    n_pairs: int = eqx.field(static=True)
    width: int = eqx.field(static=True)
    max_colors: int = eqx.field(static=True)
    chunk: int = eqx.field(static=True, default=16)

    def _ids(self, point) -> jax.Array:
        if point is None:
            raise ValueError("PairedSparseLU needs options={'point': x}, the state at which the Jacobian is taken "
                             "(its pair slots hold the pair list)")
        slots = point[self.n - self.n_pairs * self.width:self.n].reshape(self.n_pairs, self.width)
        return jnp.round(jax.lax.stop_gradient(slots[:, :2])).astype(jnp.int32)

    def factor(self, matvec, n: int, dtype, options):
        """State (J·seeds [max_colors, n], pair ids [P, 2], colours used, transposed flag)."""
        if n != self.n:
            raise ValueError(f"PairedSparseLU prepared for {self.n} unknowns, used with {n}")
        ids = self._ids(options.get("point"))
        out = (jax.ShapeDtypeStruct((n,), jnp.int32), jax.ShapeDtypeStruct((), jnp.int32))
        colors, count = jax.pure_callback(self.graph.colours, out, ids, vmap_method="sequential")
        size = self.chunk

        def chunk(k, products):
            seeds = ((k * size + jnp.arange(size))[:, None] == colors[None, :]).astype(dtype)
            return jax.lax.dynamic_update_slice(products, jax.vmap(matvec)(seeds), (k * size, jnp.zeros_like(k)))

        n_chunks = (jnp.minimum(count, self.max_colors) + size - 1) // size
        products = jax.lax.fori_loop(0, n_chunks, chunk, jnp.zeros((self.max_colors, n), dtype))
        return products, ids, count, eqxi.Static(False)

    def factor_bordered(self, matvec, n: int, dtype, options):
        """(state for J, border column c) of a bordered operator over [x; p] [n + 1]."""
        point = options.get("point")
        state = self.factor(lambda v: matvec(jnp.concatenate([v, jnp.zeros((1,), v.dtype)]))[:n], n, dtype,
                            {"point": None if point is None else point[:n]})
        return state, matvec(jnp.zeros((n + 1,), dtype).at[n].set(1.0))[:n]

    def init(self, operator, options):
        n = operator.in_structure().shape[0]
        return self.factor(operator.mv, n, operator.in_structure().dtype, options)

    def compute(self, state, vector, options):
        products, ids, count, transpose = state
        dtype = jnp.result_type(products.dtype, vector.dtype)
        host = functools.partial(self.graph.solve, transpose=bool(transpose.value), max_colors=self.max_colors)
        out = (jax.ShapeDtypeStruct(vector.shape, dtype), jax.ShapeDtypeStruct((), dtype))
        active = jnp.asarray(options.get("active", True), bool)
        x, sign = jax.pure_callback(host, out, products.astype(dtype), ids, count, vector.astype(dtype), active,
                                    vmap_method="expand_dims")
        return x, lx.RESULTS.successful, {"sign": sign, "overflow": count > self.max_colors}

    def transpose(self, state, options):
        products, ids, count, transpose = state
        return (products, ids, count, eqxi.Static(not transpose.value)), options
