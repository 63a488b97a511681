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

``row_index`` selects, statically, which candidate node equations are used (see
:mod:`socbjax._residual`); it is derived by :func:`make_network` and must not be edited.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

__all__ = ["Network", "make_network"]


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


# Candidate node equations, per node, in a fixed order (see _residual / _jointed):
#   2D SOCB:    force/position (2) | clamp θ (1) | zero moment (1)                 -> 4
#   3D SOCB:    force/position (3) | |t|=1 (1) | clamp t (3) | m·t=0 (1) | m=0 (3) -> 11
def _socb_rows(dim: int, clamped: np.ndarray, moment_free: np.ndarray) -> np.ndarray:
    rows = []
    width = 4 if dim == 2 else 11
    for i, (c, f) in enumerate(zip(clamped, moment_free)):
        base = i * width
        if dim == 2:
            local = [0, 1] + ([2] if c else []) + ([3] if f else [])
        else:
            local = [0, 1, 2] + ([4, 5, 6] if c else [3]) + ([8, 9, 10] if f else [7])
        rows.extend(base + k for k in local)
    return np.asarray(rows, dtype=np.int32)


def make_network(
    positions,
    tangents,
    segments,
    lengths,
    EI,
    *,
    fixed_directions=None,
    clamped=None,
) -> Network:
    """Build and validate a :class:`Network` from array-likes (numpy-side, before tracing).

    ``fixed_directions`` is a list (one per node) of arrays [k, d] of unit vectors along which
    the node's position is prescribed (k = 0 free, k = d fixed).  Moment-free ends are derived:
    end nodes (degree 1) that are not clamped.
    """
    positions = np.asarray(positions, dtype=np.float64)
    tangents = np.asarray(tangents, dtype=np.float64)
    segments = np.asarray(segments, dtype=np.int32)
    n, dim = positions.shape
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim}")
    lengths = np.broadcast_to(np.asarray(lengths, dtype=np.float64), (len(segments),)).copy()
    EI = np.broadcast_to(np.asarray(EI, dtype=np.float64), (len(segments),)).copy()
    if segments.ndim != 2 or segments.shape[1] != 2:
        raise ValueError(f"segments must have shape [S, 2], got {segments.shape}")
    if segments.size and (segments.min() < 0 or segments.max() >= n):
        raise ValueError("segments reference a node index outside 0..N-1")
    for name, arr in (("positions", positions), ("tangents", tangents), ("lengths", lengths), ("EI", EI)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} contains NaN or infinite values")
    if np.any(lengths <= 0):
        raise ValueError("segment lengths must be positive (µm)")
    if np.any(EI <= 0):
        raise ValueError("EI must be positive (pN·µm²)")
    degree = np.bincount(segments.ravel(), minlength=n)
    if np.any(degree > 2):
        raise ValueError(
            "nodes shared by more than two segments (junctions) are not supported by this "
            "network type; build branched networks with the network builders"
        )
    clamped = np.zeros(n, bool) if clamped is None else np.asarray(clamped, bool)
    if np.any(clamped & (degree != 1)):
        raise ValueError("only end nodes (one segment) can be clamped")
    moment_free = (degree == 1) & ~clamped
    projector = np.zeros((n, dim, dim))
    if fixed_directions is not None:
        for i, dirs in enumerate(fixed_directions):
            dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, dim)
            if len(dirs):
                q, _ = np.linalg.qr(dirs.T)
                projector[i] = q @ q.T
    return Network(
        positions=jnp.asarray(positions),
        tangents=jnp.asarray(tangents),
        segments=jnp.asarray(segments),
        lengths=jnp.asarray(lengths),
        EI=jnp.asarray(EI),
        position_projector=jnp.asarray(projector),
        clamped=jnp.asarray(clamped),
        moment_free=jnp.asarray(moment_free),
        socb_rows=jnp.asarray(_socb_rows(dim, clamped, moment_free)),
        dim=dim,
    )
