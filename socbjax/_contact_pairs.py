"""Filament–filament and self-contact (2D and 3D): the broad phase, the pair slots and their rows.

Every pair of non-adjacent segments that may touch gets a *pair slot* in a list of fixed
capacity P (``Contact(capacity=...)``): the two segments' ids, the locations σ_i, σ_j of the
closest points of the two smooth curves, the contact force F on segment i (−F acts on j, pN),
and the shape data at both points that the interior-force jumps need: θ, κ in 2D (as the
obstacle slots of :mod:`socbjax._contact_segment`); in 3D the chart coordinate w and its
arc-length derivative w′ of each point in its own segment's log chart (t = exp_u w is then a
unit tangent for any value, and a fresh slot's w = 0 is the chart's centre, so stale or empty
values never reach the chart's singularity).  The segment kernels carry both forces exactly.

Broad phase (a spatial hash, jax-md style, fixed capacity): a segment's curve lies inside the
ball of radius l/2 around its chord's midpoint (inextensible: |p − a| + |p − b| ≤ l for every
point p, an ellipsoid inside that ball).  Segments are hashed to square (cubic) cells of side
max l + d + reach; each segment looks at its own and the 3^d − 1 neighbouring cells (at most
2 ``per_segment`` segments per cell) and keeps partners j > i whose circles come within d + reach
(``reach``: how far the next path step may move a segment, enforced by the path's
admissibility test).  Segments sharing a node never pair.  The list is rebuilt from the state
before every path step (:meth:`socbjax.SOCBModel.frames`): pairs still in range keep their
slot (and unknowns), new ones take free slots.  More candidates than slots, or a segment in
more than ``per_segment`` pairs, is an *overflow*: reported (``RESULTS.contact_capacity``),
never truncated silently.  No recompilation when the contact set changes: ids are data.
"""

from __future__ import annotations

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._contact_segment import force_law_rows, handover_weight, location_bias, near_weight

__all__ = ["PAIR_WIDTH", "SPATIAL_PAIR_WIDTH", "pair_width", "PairList", "adjacent_segments", "broad_phase",
           "merge_pairs", "segment_table", "pair_extra", "pair_rows", "initial_pairs"]

PAIR_WIDTH = 10  # 2D: i, j (ids, as numbers), σ_i, σ_j, F_x, F_y, θ_i, κ_i, θ_j, κ_j
# 3D: i, j, σ_i, σ_j, F (3), w_i, w'_i, w_j, w'_j (3 each): each side's chart coordinate and its
# arc-length derivative (1/µm) in its own segment's log chart (socbjax._contact_spatial)
SPATIAL_PAIR_WIDTH = 19


def pair_width(dim: int) -> int:
    """Unknowns (and rows) per pair slot: 10 in 2D, 19 in 3D."""
    return PAIR_WIDTH if dim == 2 else SPATIAL_PAIR_WIDTH


def _side_width(dim: int) -> int:
    return 2 if dim == 2 else 6  # (θ, κ) or (w, w')


_OFFSET, _BASE = 2**19, 2**20  # integer cell coordinates -> one int64 key


class PairList(eqx.Module):
    """The pair list of one path step: ids [P, 2] (segments i < j; −1: empty slot), table
    [S, M, 2] (pair slot and side 0/1 of each pair that touches segment s; −1: none) and
    overflow (bool: more candidates than the capacity)."""

    ids: jax.Array
    table: jax.Array
    overflow: jax.Array


def adjacent_segments(network) -> np.ndarray:
    """[S, A] the segments that share a node with each segment (junction daughters share
    their mother's node), −1 padded (host side)."""
    seg = np.asarray(network.segments)
    attach = np.asarray(network.attach)
    node_of = attach[seg]  # daughter bases count as their mother node
    touching = [set() for _ in range(len(seg))]
    by_node: dict[int, list[int]] = {}
    for s, (a, b) in enumerate(node_of):
        by_node.setdefault(int(a), []).append(s)
        by_node.setdefault(int(b), []).append(s)
    for members in by_node.values():
        for s in members:
            touching[s].update(m for m in members if m != s)
    width = max(1, max(len(t) for t in touching))
    out = -np.ones((len(seg), width), np.int64)
    for s, t in enumerate(touching):
        out[s, : len(t)] = sorted(t)
    return out


def _keys(q):
    q = q + _OFFSET
    key = q[..., 0]
    for k in range(1, q.shape[-1]):
        key = key * _BASE + q[..., k]
    return key


def broad_phase(centers, radii, reach, adjacent, capacity: int, per_cell: int):
    """(ids [capacity, 2] (−1 empty), overflow) of the segment pairs whose bounding circles
    (centers [S, d] µm, radii [S] µm) come within ``reach`` µm, from a spatial hash."""
    S, d = centers.shape
    h = 2.0 * jnp.max(radii) + reach
    q = jnp.floor(centers / h).astype(jnp.int64)
    key = _keys(q)
    order = jnp.argsort(key)
    sorted_keys = key[order]
    offsets = jnp.asarray(list(itertools.product((-1, 0, 1), repeat=d)), jnp.int64)
    near = _keys(q[:, None, :] + offsets[None])  # [S, O]
    start = jnp.searchsorted(sorted_keys, near, side="left")
    stop = jnp.searchsorted(sorted_keys, near, side="right")
    crowded = jnp.any(stop - start > per_cell)
    idx = start[..., None] + jnp.arange(per_cell)  # [S, O, M]
    j = order[jnp.clip(idx, 0, S - 1)]
    i = jnp.broadcast_to(jnp.arange(S)[:, None, None], j.shape)
    dist = jnp.linalg.norm(centers[i] - centers[j], axis=-1)
    ok = (idx < stop[..., None]) & (j > i) & (dist < radii[i] + radii[j] + reach)
    ok = ok & ~jnp.any(jnp.asarray(adjacent)[i] == j[..., None], axis=-1)
    flat = ok.ravel()
    chosen = jnp.nonzero(flat, size=capacity, fill_value=flat.size)[0]
    pairs = jnp.stack([i.ravel(), j.ravel()], axis=1)
    ids = jnp.where((chosen < flat.size)[:, None], pairs[jnp.clip(chosen, 0, flat.size - 1)], -1)
    return ids, crowded | (jnp.sum(flat) > capacity)


def merge_pairs(old, new, n_segments: int):
    """Pair ids [P, 2] that keep every old pair still in ``new`` in its slot and put the other
    new pairs in the free slots (the new list has at most P pairs, so they fit)."""
    P = old.shape[0]
    okey = jnp.where(old[:, 0] >= 0, old[:, 0] * n_segments + old[:, 1], -1)
    nkey = jnp.where(new[:, 0] >= 0, new[:, 0] * n_segments + new[:, 1], -2)
    keep = (okey >= 0) & jnp.isin(okey, nkey)
    fresh = (nkey >= 0) & ~jnp.isin(nkey, jnp.where(keep, okey, -3))
    free_slots = jnp.nonzero(~keep, size=P, fill_value=P)[0]
    rank = jnp.cumsum(fresh) - 1
    target = jnp.where(fresh, free_slots[jnp.clip(rank, 0, P - 1)], P)
    ids = jnp.where(keep[:, None], old, -1)
    return ids.at[target].set(new, mode="drop")


def segment_table(ids, n_segments: int, per_segment: int):
    """([S, M, 2] (pair slot, side) of the pairs at each segment, −1 empty; overflow)."""
    P = ids.shape[0]
    ends = ids.reshape(-1)
    slot = jnp.repeat(jnp.arange(P), 2)
    side = jnp.tile(jnp.arange(2), P)
    key = jnp.where(ends >= 0, ends, n_segments)
    order = jnp.argsort(key, stable=True)
    sk = key[order]
    start = jnp.searchsorted(sk, jnp.arange(n_segments), side="left")
    stop = jnp.searchsorted(sk, jnp.arange(n_segments), side="right")
    idx = start[:, None] + jnp.arange(per_segment)
    o = order[jnp.clip(idx, 0, 2 * P - 1)]
    table = jnp.where((idx < stop[:, None])[..., None], jnp.stack([slot[o], side[o]], axis=-1), -1)
    return table, jnp.any(stop - start > per_segment)


def pair_extra(pairs, table):
    """Interior point forces that the pairs put on each segment: [S, M, 5] (σ, F, θ, κ) in 2D,
    [S, M, 10] (σ, F, w, w') in 3D (chart coordinates of the segment's own chart)."""
    dim = 2 if pairs.shape[-1] == PAIR_WIDTH else 3
    b = _side_width(dim)
    p, side = jnp.maximum(table[..., 0], 0), jnp.maximum(table[..., 1], 0)
    row = pairs[p]  # [S, M, width]
    sign = jnp.where(side == 0, 1.0, -1.0)[..., None]
    used = (table[..., 0] >= 0)[..., None]
    columns = 4 + dim + side[..., None] * b + jnp.arange(b)  # the side's shape block
    shape = jnp.take_along_axis(row, columns, axis=-1)
    sigma = jnp.take_along_axis(row, (2 + side)[..., None], axis=-1)
    extra = jnp.concatenate([sigma, sign * row[..., 4:4 + dim], shape], axis=-1)
    idle = jnp.zeros(1 + dim + b).at[0].set(0.5)
    return jnp.where(used, extra, idle)


def pair_rows(pairs, frame: PairList, outputs, network, setup, nodes):
    """Rows [P, width] of the pair slots (dimensionless), their gaps [P] (µm; +inf for empty
    slots) and points [P, 2 sides, d] (µm).  ``outputs``: the segment kernel's values at the
    pairs' points, planar (points [S, M, 2], θ [S, M], dθ/dσ [S, M]) or spatial (points, unit
    tangents, chart coordinates w, dw/dσ: [S, M, 3] each); ``nodes``: (positions [N, d] µm,
    directors: angles [N] rad or unit tangents [N, 3]) of the state."""
    dim = network.dim
    points = outputs[0]
    S, M = frame.table.shape[:2]
    P = pairs.shape[0]
    # where each (pair slot, side) sits in the segment table
    flat = frame.table.reshape(-1, 2)
    where = jnp.full((P, 2), S * M, jnp.int64).at[jnp.where(flat[:, 0] >= 0, flat[:, 0], P), flat[:, 1]].set(
        jnp.arange(S * M), mode="drop")
    valid = (frame.ids[:, 0] >= 0) & jnp.all(where < S * M, axis=1)
    at = jnp.clip(where, 0, S * M - 1)
    gather = lambda v: v.reshape(S * M, *v.shape[2:])[at]  # noqa: E731  [P, 2 sides, ...]
    r = gather(points)
    seg = jnp.clip(frame.ids, 0, S - 1)
    length = jnp.asarray(network.lengths)[seg]  # [P, 2]
    sigma, F = pairs[:, 2:4], pairs[:, 4:4 + dim]
    shape_k = pairs[:, 4 + dim:].reshape(P, 2, -1)  # per side: (θ, κ) or (w, w')
    diff = r[:, 0] - r[:, 1]
    dist = jnp.sqrt(jnp.sum(diff**2, axis=-1) + 1e-300)
    u = diff / dist[:, None]
    gaps = dist - 2.0 * setup.filament_radius
    if dim == 2:
        th, dth = gather(outputs[1]), gather(outputs[2])
        tangent = jnp.stack([jnp.cos(shape_k[..., 0]), jnp.sin(shape_k[..., 0])], axis=-1)  # [P, 2, 2]
        shape = jnp.stack([shape_k[..., 0] - th, length * shape_k[..., 1] - dth], axis=-1)  # [P, 2 sides, 2]
    else:
        tangent, w_at, dw_at = gather(outputs[1]), gather(outputs[2]), gather(outputs[3])
        shape = jnp.concatenate([shape_k[..., :3] - w_at, length[..., None] * shape_k[..., 3:] - dw_at], axis=-1)
    slope = jnp.stack([jnp.sum(u * tangent[:, 0], -1), -jnp.sum(u * tangent[:, 1], -1)], axis=1)
    s = jnp.clip(sigma, 0.0, 1.0)
    bias = location_bias(sigma, gaps[:, None], length)
    # the band is judged on the pair's lowest possible gap (bounding circles of radius l/2
    # around the chords' midpoints), not on the gap at the current σ
    r_nodes, directors = nodes
    a, b = jnp.asarray(network.segments)[seg, 0], jnp.asarray(network.segments)[seg, 1]  # [P, 2]
    centers = 0.5 * (r_nodes[a] + r_nodes[b])
    lowest = (jnp.linalg.norm(centers[:, 0] - centers[:, 1], axis=-1) - 0.5 * jnp.sum(length, axis=1)
              - 2.0 * setup.filament_radius)
    near = near_weight(lowest[:, None], length, setup.activation)
    # s, not σ, inside the projection: slope 1 beyond the ends (see contact_slot_rows)
    location = near * (sigma - jnp.clip(s - slope - bias, 0.0, 1.0)) + (1.0 - near) * (sigma - 0.5)
    # each side's node hand-over (as for obstacles): the slope at its end nodes of the distance
    # to the other side's closest point
    other = r[:, ::-1]  # [P, 2 sides, d]
    if dim == 2:
        node_tangent = lambda node: jnp.stack([jnp.cos(directors[node]), jnp.sin(directors[node])], -1)  # noqa: E731
    else:
        node_tangent = lambda node: directors[node] / jnp.linalg.norm(directors[node], axis=-1, keepdims=True)  # noqa: E731

    def node_slope(node):
        offset = r_nodes[node] - other
        return jnp.sum(offset * node_tangent(node), axis=-1) / jnp.sqrt(jnp.sum(offset**2, axis=-1) + 1e-300)

    slopes = jnp.stack([node_slope(a), node_slope(b)])  # [2 ends, P, 2 sides]
    one = jnp.ones_like(s)
    owned = jnp.prod(handover_weight(s, slopes, setup.seg_owns_start[seg], one, (setup.smooth_start[seg],
                                                                                  setup.smooth_end[seg])), axis=1)
    force = force_law_rows(F, u, gaps, owned, setup, jnp.mean(length, axis=1))
    rows = jnp.concatenate([location, force, shape.reshape(P, -1)], axis=1)
    idle = jnp.concatenate([sigma - 0.5, F / setup.force_scale, pairs[:, 4 + dim:]], axis=1)
    rows = jnp.where(valid[:, None], rows, idle)
    id_rows = pairs[:, :2] - frame.ids.astype(pairs.dtype)  # the list is held during a step
    return jnp.concatenate([id_rows, rows], axis=1), jnp.where(valid, gaps, jnp.inf), jnp.where(valid[:, None, None], r, 0.0)


def initial_pairs(capacity: int, dim: int = 2) -> jax.Array:
    """[P, width] empty pair slots (ids −1, σ = ½, no force; 3D: w = 0, the chart's centre)."""
    one = jnp.zeros(pair_width(dim)).at[:4].set(jnp.asarray([-1.0, -1.0, 0.5, 0.5]))
    return jnp.broadcast_to(one, (capacity, pair_width(dim)))
