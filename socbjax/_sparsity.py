"""Sparsity of the network Jacobians, and the choice of linear solver for a model.

:func:`socbjax._residual.socb_structure` maps every unknown and residual row to a vertex of
the network graph (nodes and segments; daughter bases joined to their mother nodes).  A row
depends only on unknowns within graph distance 2 of its vertex, so that neighbourhood is a
conservative pattern: a few structural zeros, no missed entries — refined by evaluating the
Jacobian at random points and checked against a random directional derivative.  This
replaces column-by-column probing (seconds per thousand unknowns) by three sparse matrix
products (milliseconds).  The jointed model is probed (:func:`socbjax._linear.sparsity_pattern`).

The pattern depends only on the topology: it is computed once per topology on a *template*
network (the same topology with random values, loads and couples, so that it holds for any
values; a padded network's template is half-pinned at every node, so that it holds for any
pins, :class:`socbjax.Padding`), cached, and reused by every solve, compression, ensemble and fit of that topology —
also when the actual values are traced.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jax.flatten_util import ravel_pytree

from ._contact_pairs import PairList, pair_width
from ._linear import ColouredSparseLU, DenseLU, solver_kind, sparsity_pattern
from ._network import DIFFERENTIABLE_FIELDS, Padding
from ._paired import PairGraph, PairedSparseLU
from ._residual import Control, SOCBModel

__all__ = ["graph_reach", "structural_pattern", "prepare_sparse_solver", "linear_solver_for", "template_model"]

_PREPARED: dict = {}


def graph_reach(edges, n_vertices: int, radius: int = 2) -> sp.csr_matrix:
    """[V, V] int32 sparse: 1 where two vertices are within ``radius`` edges of each other."""
    A = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n_vertices, n_vertices))
    A = ((A + A.T + sp.eye(n_vertices)) > 0).astype(np.int32).tocsr()
    reach = A
    for _ in range(radius - 1):
        reach = ((reach @ A) > 0).astype(np.int32)
    return reach


def structural_pattern(structure, radius: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) [nnz] in CSC order: row r may depend on unknown u when their vertices are
    within ``radius`` of each other in the graph."""
    unknown_vertex, row_vertex, edges, n_vertices = structure
    n = unknown_vertex.size
    reach = graph_reach(edges, n_vertices, radius)
    R = sp.csr_matrix((np.ones(n, np.int32), (np.arange(n), row_vertex)), shape=(n, n_vertices))
    U = sp.csr_matrix((np.ones(n, np.int32), (unknown_vertex, np.arange(n))), shape=(n_vertices, n))
    pattern = (R @ reach @ U).tocsc()
    pattern.sort_indices()
    cols = np.repeat(np.arange(n), np.diff(pattern.indptr))
    return pattern.indices.astype(np.int64), cols.astype(np.int64)


def template_model(model):
    """``model`` on a network of the same topology with generic concrete values (random
    lengths, EI, loads and couples; perturbed positions and tangents), for patterns."""
    rng = np.random.default_rng(7)
    net = model.network
    values = {}
    for name in DIFFERENTIABLE_FIELDS:
        shape = getattr(net, name).shape
        v = rng.uniform(0.5, 1.5, shape) if name in ("lengths", "EI", "GJ") else rng.normal(size=shape)
        if name == "tangents":
            v = v / np.linalg.norm(v, axis=-1, keepdims=True)
        values[name] = jnp.asarray(v)
    net = net.replace(**values)
    if net.padding is not None:  # pins are values: half-pinned everywhere has the union pattern
        d = net.dim
        half = jnp.broadcast_to(0.5 * jnp.eye(d), (net.n_nodes, d, d))
        net = eqx.tree_at(lambda n: n.padding, net, Padding(projector=half, active=jnp.ones(net.n_nodes)))
    fields = [getattr(model, f) for f in ("quad",) if hasattr(model, f)]
    contact = getattr(model, "contact", None)
    if contact is not None:  # every contact dependence switched on (no projection, no ownership)
        return type(model)(net, *fields, contact=dataclasses.replace(contact, dense=True))
    return type(model)(net, *fields)


def _residual_fn(template):
    """The residual as a function of (flat state, probe_held): one function whose Jacobian at
    probe_held = ½ has the union pattern of the held and released probe (the settle phase)."""
    # the structure only: the pattern is found at random points around it, so the contact
    # slots need not sit on their closest points (settling them compiles for seconds)
    state0 = template.state_template()
    x0, unravel = ravel_pytree(state0)
    frames = template.frames(state0)
    if getattr(template, "n_pairs", 0):  # the static part: an empty pair list (socbjax._paired)
        bases, pairs = frames
        frames = (bases, PairList(ids=-jnp.ones_like(pairs.ids), table=-jnp.ones_like(pairs.table),
                                  overflow=pairs.overflow))
    return x0, lambda y, h: template.residual(unravel(y), Control.make(1.0, 0.3, h), frames)


def _refined(template, x0, fn) -> ColouredSparseLU:
    """The graph pattern, coloured, evaluated at random points (one compiled program); the
    non-zeros found, coloured again; checked against an exact directional derivative."""
    n = x0.size
    rows, cols = structural_pattern(template.structure())
    conservative = ColouredSparseLU.from_pattern(rows, cols, n)
    values = jax.jit(lambda z, h: conservative.values(lambda y: fn(y, h), z))
    rng = np.random.default_rng(1)
    points = [jnp.asarray(np.asarray(x0) + rng.uniform(-0.3, 0.3, n)) for _ in range(3)]
    half = jnp.asarray(0.5)
    keep = np.zeros(rows.size, bool)
    for z in points[:2]:
        keep |= np.asarray(values(z, half)) != 0
    if getattr(template, "contact", None) is not None:
        keep |= _contact_local(template, rows, cols, keep)
    # check: the conservative pattern must carry the whole Jacobian (an exact jvp at a third point)
    v = rng.normal(size=n)
    exact = np.asarray(jax.jit(lambda z, t: jax.jvp(lambda y: fn(y, half), (z,), (t,))[1])(points[2], jnp.asarray(v)))
    approx = np.zeros(n)
    np.add.at(approx, rows, np.asarray(values(points[2], half)) * v[cols])
    if not np.allclose(approx, exact, rtol=1e-8, atol=1e-8 * max(1.0, float(np.abs(exact).max()))):
        raise RuntimeError("the graph sparsity pattern misses dependencies of the residual; use linear_solver='dense'")
    return ColouredSparseLU.from_pattern(rows[keep], cols[keep], n)


def _contact_local(template, rows, cols, found) -> np.ndarray:
    """[nnz] the entries of a segment's rows (kernel, contact slots) on the unknowns at it and
    its nodes, and on every unknown that any row of the same segment depends on (``found``:
    the entries seen at the random points).  Contact switches (ownership hand-over, the
    location clip, the band) are flat at random points, and an interior pair force adds such
    dependencies: where a refinement by values dropped them, Newton's direction was wrong (a
    3-generation outcrop with self-contact took 149 Newton iterations against 107 with the
    dense LU).  A slot's rows see the segment's curve, so they depend on all that the
    segment's kernel rows do — also the moments handed over at a branch node two graph steps
    away (the 6-generation outcrop with the surfaces lost them: J·v was 1 % wrong and Newton
    took 149 iterations to u = 1.03 µm, against 110 with them)."""
    unknown_vertex, row_vertex, edges, V = template.structure()
    N, S = template.network.n_nodes, template.network.n_segments
    adjacent = graph_reach(edges, V, radius=1).tocsr()
    at_segment = (row_vertex[rows] >= N) & (row_vertex[rows] < N + S)
    near = np.asarray(adjacent[row_vertex[rows], unknown_vertex[cols]]).ravel() != 0
    n = unknown_vertex.size
    seen = sp.csr_matrix((np.ones(int(found.sum()), np.int32), (row_vertex[rows[found]], cols[found])), shape=(V, n))
    curve = np.asarray(seen[row_vertex[rows], cols]).ravel() != 0
    return at_segment & (near | curve)


def _paired(model, static: ColouredSparseLU) -> PairedSparseLU:
    """The :class:`PairedSparseLU` of a model with pair slots, around its static part."""
    net, P, W = model.network, model.n_pairs, pair_width(model.network.dim)
    _, row_vertex, edges, _ = model.structure()
    V, n0 = net.n_nodes + net.n_segments, static.n - P * W
    graph = PairGraph((static.rows.a, static.cols.a), static.n, P, W, graph_reach(edges, V), row_vertex[:n0],
                      net.n_nodes)
    # a crowded segment: the columns near it, and the live unknowns of every pair at it and
    # at its neighbours share its rows (2 per_segment pairs: a hash cell holds that many).
    # Twice that: the greedy colouring goes past it (the 6-generation outcrop with self-contact
    # needed 334 colours at u = 0.49 µm against 320 prepared, and the path stopped).  Only the
    # colours in use are evaluated; the rest is memory ([max_colors, n] products).
    bound = static.n_colors + 8 * model.contact.per_segment * (W - 2)
    chunk = 16
    return PairedSparseLU(graph=graph, n=static.n, n_pairs=P, width=W, max_colors=-(-bound // chunk) * chunk,
                          chunk=chunk)


def prepare_sparse_solver(model) -> ColouredSparseLU | PairedSparseLU:
    """The :class:`ColouredSparseLU` for ``model``'s Jacobian, or with filament–filament pair
    slots the :class:`PairedSparseLU` around it (cached per topology)."""
    contact = getattr(model, "contact", None)
    key = (model.network.topology, model.network.padding is not None, type(model).__name__, getattr(model, "quad", None),
           None if contact is None else (contact.kinds, contact.lumped, contact.capacity, contact.per_segment))
    if key in _PREPARED:
        return _PREPARED[key]
    # Host-side set-up from random template values, also when called while the user's
    # function is being traced (jit of a solve): evaluate eagerly, never stage.
    with jax.ensure_compile_time_eval():
        template = template_model(model)
        x0, fn = _residual_fn(template)
        if isinstance(model, SOCBModel):
            solver = _refined(template, x0, fn)
            if model.n_pairs:
                solver = _paired(model, solver)
        else:
            rows, cols = sparsity_pattern(lambda y: fn(y, 0.5), x0)
            solver = ColouredSparseLU.from_pattern(rows, cols, x0.size)
    _PREPARED[key] = solver
    return solver


def linear_solver_for(model, kind: str = "auto", *, batched: bool = False):
    """:class:`DenseLU` or the prepared sparse solver for ``model`` ("dense", "sparse", or
    "auto": sparse above 1,500 unknowns): :class:`ColouredSparseLU`, or with
    filament–filament pair slots :class:`PairedSparseLU` (whose pattern follows the pairs;
    ``batched``: for :class:`BlockDiagonal` re-solves, where pairs take dense LU).  Host
    side; works for traced values."""
    if batched and getattr(model, "n_pairs", 0):
        return DenseLU()
    return prepare_sparse_solver(model) if solver_kind(kind, model.n_unknowns) == "sparse" else DenseLU()
