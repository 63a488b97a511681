"""The network data model: one pytree of batched arrays.

Units throughout socbjax: length µm, force pN, time s; bending stiffness EI in pN·µm²,
moments in pN·µm.

A :class:`Network` holds the reference (stress-free, here straight) geometry, the segment
connectivity, per-segment length and EI, and the supports, all as arrays so that a new EI,
length or support position never recompiles, ``jax.grad`` can differentiate with respect to
them and ``jax.vmap`` can batch them.  Only ``dim`` is static.  A single filament is a network
with one chain of segments (nodes 0..N−1, segment k joins nodes k and k+1).

Supports are encoded per node:

* ``position_projector[i]`` (d×d) is the orthogonal projector onto the directions in which
  node i's position is prescribed (identity: fixed, zero: free, I − a aᵀ: free only along a).
  The prescribed position is ``positions[i]`` (the reference position).
* ``clamped[i]``: the tangent at node i is fixed to ``tangents[i]``.
* ``moment_free[i]``: an end node whose bending moment vanishes (free or pinned end).
* ``probe[i]``: node held by the rigid probe; its prescribed position is
  ``positions[i] + u * probe_direction`` (u: probe displacement, µm), always prescribed along
  ``probe_direction`` (plus whatever ``position_projector`` fixes).
* ``attach[i]``: for the base node of a daughter filament, the mother node it is attached to
  (an Arp2/3 branch junction, see docs/equations.md §Junctions); ``attach[i] == i`` otherwise.
  The daughter base is a separate node whose position and tangent are tied to the mother node's;
  its segment-end force goes into the mother node's force balance and its bending moment into
  the mother's moment balance (``transfer_segment``).
* ``loads[i]``: fixed external nodal force (pN), e.g. a lateral perturbation.

``row_index`` selects, statically, which candidate node equations are used (see
:mod:`socbjax._residual`); it is derived by :func:`make_network` and must not be edited.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

__all__ = ["Network", "make_network", "DIFFERENTIABLE_FIELDS"]

# Network arrays that may carry traced (differentiated) values; everything else is structure.
DIFFERENTIABLE_FIELDS = ("positions", "tangents", "lengths", "EI", "loads")


class Network(eqx.Module):
    """A filament network (topology, reference geometry, stiffness and supports).

    Attributes
    ----------
    positions : [N, d] reference node positions (µm); prescribed positions of supports.
    tangents : [N, d] unit reference tangents at nodes; clamp directions.
    segments : [S, 2] int, (start node, end node) of each segment.
    lengths : [S] segment contour lengths (µm).
    EI : [S] bending stiffness per segment (pN·µm²).
    position_projector : [N, d, d] projector onto prescribed position directions.
    clamped : [N] bool, tangent prescribed.
    moment_free : [N] bool, bending moment prescribed zero (free or pinned end).
    attach : [N] int, mother node of a daughter base node (itself otherwise).
    transfer_segment : [N] int, for a daughter base node the mother segment that starts at the
        mother node (its start moment jumps by the daughter's moment), S when there is none
        (the jump then enters the mother node's end-moment equation); S for other nodes.
    probe : [N] bool, node moves with the probe.
    probe_direction : [d] unit vector along which the probe moves when compressing.
    loads : [N, d] fixed external nodal forces (pN).
    strand : [S] int, strand (physical fibre continuous through branch points) of each segment.
    socb_rows : int array selecting the SOCB node equations (the jointed model uses all
        force/position rows, so it needs no selection).
    dim : 2 or 3 (static).
    """

    positions: Float[Array, "N d"]
    tangents: Float[Array, "N d"]
    segments: Int[Array, "S 2"]
    lengths: Float[Array, " S"]
    EI: Float[Array, " S"]
    position_projector: Float[Array, "N d d"]
    clamped: Bool[Array, " N"]
    moment_free: Bool[Array, " N"]
    attach: Int[Array, " N"]
    transfer_segment: Int[Array, " N"]
    probe: Bool[Array, " N"]
    probe_direction: Float[Array, " d"]
    loads: Float[Array, "N d"]
    strand: Int[Array, " S"]
    socb_rows: Int[Array, " R"]
    dim: int = eqx.field(static=True)

    @property
    def n_nodes(self) -> int:
        return self.positions.shape[0]

    @property
    def n_segments(self) -> int:
        return self.segments.shape[0]

    @property
    def total_length(self) -> float:
        """Sum of segment lengths (µm)."""
        return float(np.sum(np.asarray(self.lengths)))

    @property
    def attached(self) -> Array:
        """[N] bool, daughter base nodes (tied to a mother node by a branch junction)."""
        return self.attach != jnp.arange(self.n_nodes)

    @property
    def n_junctions(self) -> int:
        return int(np.sum(np.asarray(self.attach) != np.arange(self.n_nodes)))


# Candidate node equations, per node, in a fixed order (see _residual / _jointed):
#   2D SOCB:    force/position (2) | clamp θ (1) | zero moment (1)                 -> 4
#   3D SOCB:    force/position (3) | |t|=1 (1) | clamp t (3) | m·t=0 (1) | m=0 (3) -> 11
def _socb_rows(dim: int, director_fixed: np.ndarray, moment_free: np.ndarray) -> np.ndarray:
    """Static selection of node equations: clamped and daughter-base nodes prescribe the
    director, free/pinned ends the moment (see :mod:`socbjax._residual`)."""
    if dim == 2:
        local = np.array([[1, 1, c, f] for c, f in zip(director_fixed, moment_free)], bool)
    else:
        local = np.array(
            [[1, 1, 1, not c, c, c, c, not f, f, f, f] for c, f in zip(director_fixed, moment_free)], bool
        )
    return np.flatnonzero(local.ravel()).astype(np.int32)


def _as_node_array(name: str, value, n: int, dtype, default) -> np.ndarray:
    if value is None:
        return np.full(n, default, dtype=dtype)
    arr = np.asarray(value, dtype=dtype)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have one entry per node ({n}), got shape {arr.shape}")
    return arr


def _check_topology(positions, segments, lengths, n):
    if segments.ndim != 2 or segments.shape[1] != 2:
        raise ValueError(f"segments must have shape [S, 2], got {segments.shape}")
    if segments.size and (segments.min() < 0 or segments.max() >= n):
        raise ValueError("segments reference a node index outside 0..N-1")
    if np.any(segments[:, 0] == segments[:, 1]):
        raise ValueError("a segment joins a node to itself; each segment needs two distinct nodes")
    if np.any(lengths <= 0):
        raise ValueError("segment lengths must be positive (µm); remove zero-length segments")
    chord = np.linalg.norm(positions[segments[:, 1]] - positions[segments[:, 0]], axis=1)
    if np.any(chord <= 1e-9 * np.maximum(lengths, 1.0)):
        k = int(np.argmax(chord <= 1e-9 * np.maximum(lengths, 1.0)))
        raise ValueError(f"segment {k} has coincident end nodes (zero-length segment); merge or remove it")
    pairs = np.sort(segments, axis=1)
    if len(np.unique(pairs, axis=0)) != len(pairs):
        raise ValueError("two segments join the same pair of nodes (duplicate segment)")


def _check_junctions(attach_pairs, n, degree, n_end, n_start, clamped, fixed_any, probe):
    """Validate (mother, daughter) pairs; returns attach [N]."""
    attach = np.arange(n)
    pairs = np.asarray(attach_pairs, dtype=np.int64).reshape(-1, 2) if attach_pairs is not None else np.zeros((0, 2), int)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= n):
        bad = pairs[(pairs < 0) | (pairs >= n)][0]
        raise ValueError(f"a junction references node {bad}, which does not exist (valid: 0..{n - 1})")
    if len(np.unique(pairs[:, 1])) != len(pairs):
        raise ValueError("duplicate junction: a daughter base node is attached more than once")
    for mother, daughter in pairs:
        if mother == daughter:
            raise ValueError(f"junction ({mother}, {daughter}) attaches a node to itself")
        if degree[daughter] != 1 or n_start[daughter] != 1:
            raise ValueError(
                f"daughter base node {daughter} must start exactly one segment (the daughter's first) "
                f"and end none; it has {n_start[daughter]} starting and {n_end[daughter]} ending"
            )
        if clamped[daughter] or fixed_any[daughter] or probe[daughter]:
            raise ValueError(f"daughter base node {daughter} is tied to its mother node; it cannot also be supported")
        if n_end[mother] > 1 or n_start[mother] > 1:
            raise ValueError(
                f"mother node {mother} must lie on one strand (at most one segment ending and one starting there)"
            )
        attach[daughter] = mother
    if np.any(attach[attach] != attach):
        raise ValueError("a daughter base node cannot itself be the mother node of a junction; branch from the strand")
    return attach


def _transfer_segments(attach, segments, n_start):
    s = len(segments)
    start_of = np.full(len(attach), s)
    start_of[segments[:, 0]] = np.arange(s)
    transfer = np.full(len(attach), s)
    daughters = np.flatnonzero(attach != np.arange(len(attach)))
    mothers = attach[daughters]
    transfer[daughters] = np.where(n_start[mothers] == 1, start_of[mothers], s)
    return transfer


def _check_supported(n, segments, attach, clamped, projector, dim):
    """Every connected piece must be held against rigid-body motion."""
    parent = np.arange(n)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in list(map(tuple, segments)) + [(i, attach[i]) for i in range(n) if attach[i] != i]:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    roots = np.array([find(i) for i in range(n)])
    rank = np.einsum("nii->n", projector).round().astype(int)
    for root in np.unique(roots):
        members = roots == root
        held = np.any(clamped[members] & (rank[members] >= dim)) or (
            np.sum(rank[members] > 0) >= 2 and np.sum(np.minimum(rank[members], dim)) >= dim + 1
        )
        if not held:
            nodes = np.flatnonzero(members)
            raise ValueError(
                f"the piece of the network with nodes {nodes[:8].tolist()}{'...' if len(nodes) > 8 else ''} is not held "
                "against rigid-body motion; clamp one of its nodes or pin at least two"
            )


def make_network(
    positions,
    tangents,
    segments,
    lengths,
    EI,
    *,
    fixed_directions=None,
    clamped=None,
    attach=None,
    probe=None,
    probe_direction=None,
    loads=None,
    strand=None,
) -> Network:
    """Build and validate a :class:`Network` from array-likes (numpy-side, before tracing).

    Parameters
    ----------
    positions, tangents : [N, d] reference node positions (µm) and unit tangents of the
        straight, stress-free reference state.
    segments : [S, 2] (start, end) node indices; a strand's segments run base to tip.
    lengths, EI : [S] or scalars, contour length (µm) and bending stiffness (pN·µm²).
    fixed_directions : list (one per node) of arrays [k, d] of directions along which the
        node's position is prescribed (k = 0 free, ``np.eye(d)`` fixed point).
    clamped : [N] bool, tangent prescribed (end nodes only).
    attach : [J, 2] (mother node, daughter base node) pairs: Arp2/3 branch junctions.  The
        daughter base is its own node, at the mother node's position, starting one segment;
        the mother node has at most one segment ending and one starting there.
    probe : node indices held by the rigid probe; probe_direction : [d] its direction of
        motion when compressing (default: from the first probe node toward the centroid of
        the other supported nodes, else −x).
    loads : [N, d] fixed external nodal forces (pN).  strand : [S] int strand ids.

    Moment-free ends are derived: nodes with one segment that are neither clamped nor
    daughter bases.  Raises ``ValueError`` for inconsistent input (missing nodes, duplicate
    junctions or segments, zero-length segments, pieces not held against rigid motion).
    """
    positions = np.asarray(positions, dtype=np.float64)
    tangents = np.asarray(tangents, dtype=np.float64)
    segments = np.asarray(segments, dtype=np.int32)
    if positions.ndim != 2 or positions.shape[1] not in (2, 3):
        raise ValueError(f"positions must have shape [N, 2] or [N, 3], got {positions.shape}")
    n, dim = positions.shape
    if tangents.shape != (n, dim):
        raise ValueError(f"tangents must have shape {(n, dim)}, got {tangents.shape}")
    s = len(segments)
    lengths = np.broadcast_to(np.asarray(lengths, dtype=np.float64), (s,)).copy()
    EI = np.broadcast_to(np.asarray(EI, dtype=np.float64), (s,)).copy()
    loads = np.zeros((n, dim)) if loads is None else np.asarray(loads, dtype=np.float64)
    if loads.shape != (n, dim):
        raise ValueError(f"loads must have shape {(n, dim)} (pN), got {loads.shape}")
    for name, arr in (("positions", positions), ("tangents", tangents), ("lengths", lengths), ("EI", EI), ("loads", loads)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} contains NaN or infinite values")
    _check_topology(positions, segments, lengths, n)
    if np.any(EI <= 0):
        raise ValueError("EI must be positive (pN·µm²)")
    n_start = np.bincount(segments[:, 0], minlength=n)
    n_end = np.bincount(segments[:, 1], minlength=n)
    degree = n_start + n_end
    if np.any(degree == 0):
        raise ValueError(f"node {int(np.argmax(degree == 0))} belongs to no segment; remove it")
    if np.any(degree > 2):
        raise ValueError(
            f"node {int(np.argmax(degree > 2))} is shared by more than two segments; join filaments with "
            "branch junctions (attach=[(mother, daughter_base), ...]) instead"
        )
    clamped = _as_node_array("clamped", clamped, n, bool, False)
    if np.any(clamped & (degree != 1)):
        raise ValueError("only end nodes (one segment) can be clamped")
    projector = np.zeros((n, dim, dim))
    if fixed_directions is not None:
        if len(fixed_directions) != n:
            raise ValueError(f"fixed_directions needs one entry per node ({n}), got {len(fixed_directions)}")
        for i, dirs in enumerate(fixed_directions):
            dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, dim)
            if len(dirs):
                q, _ = np.linalg.qr(dirs.T)
                projector[i] = q @ q.T
    probe_mask = np.zeros(n, bool)
    if probe is not None:
        idx = np.asarray(probe, dtype=np.int64).ravel()
        if idx.size and (idx.min() < -n or idx.max() >= n):
            raise ValueError(f"probe references a node outside 0..{n - 1}")
        probe_mask[idx] = True
    direction = _probe_direction(probe_direction, probe_mask, projector, positions, dim)
    projector = np.where(probe_mask[:, None, None], _add_direction(projector, direction), projector)
    fixed_any = np.einsum("nii->n", projector) > 0.5
    attach_arr = _check_junctions(attach, n, degree, n_end, n_start, clamped, fixed_any, probe_mask)
    attached = attach_arr != np.arange(n)
    _check_supported(n, segments, attach_arr, clamped, projector, dim)
    moment_free = (degree == 1) & ~clamped & ~attached
    strand = np.zeros(s, np.int32) if strand is None else np.asarray(strand, dtype=np.int32)
    if strand.shape != (s,):
        raise ValueError(f"strand must have one id per segment ({s}), got shape {strand.shape}")
    return Network(
        positions=jnp.asarray(positions),
        tangents=jnp.asarray(tangents),
        segments=jnp.asarray(segments),
        lengths=jnp.asarray(lengths),
        EI=jnp.asarray(EI),
        position_projector=jnp.asarray(projector),
        clamped=jnp.asarray(clamped),
        moment_free=jnp.asarray(moment_free),
        attach=jnp.asarray(attach_arr, dtype=jnp.int32),
        transfer_segment=jnp.asarray(_transfer_segments(attach_arr, segments, n_start), dtype=jnp.int32),
        probe=jnp.asarray(probe_mask),
        probe_direction=jnp.asarray(direction),
        loads=jnp.asarray(loads),
        strand=jnp.asarray(strand),
        socb_rows=jnp.asarray(_socb_rows(dim, clamped | attached, moment_free)),
        dim=dim,
    )


def _add_direction(projector, direction):
    """Projectors onto span(P) + span(direction)."""
    out = []
    for P in projector:
        basis = np.concatenate([P, direction[:, None]], axis=1)
        u, sv, _ = np.linalg.svd(basis)
        q = u[:, sv > 1e-9]
        out.append(q @ q.T)
    return np.asarray(out)


def _probe_direction(direction, probe_mask, projector, positions, dim):
    if direction is None:
        if not probe_mask.any():
            return np.eye(dim)[0]
        others = (np.einsum("nii->n", projector) > 0.5) & ~probe_mask
        if others.any():
            d = positions[others].mean(axis=0) - positions[probe_mask].mean(axis=0)
            if np.linalg.norm(d) > 1e-12:
                return d / np.linalg.norm(d)
        return -np.eye(dim)[0]
    d = np.asarray(direction, dtype=np.float64).ravel()
    if d.shape != (dim,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-12:
        raise ValueError(f"probe_direction must be a finite non-zero vector with {dim} components, got {direction!r}")
    return d / np.linalg.norm(d)
