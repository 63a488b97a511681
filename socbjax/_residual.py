"""The SOCB system of a whole network: segment equations (vmapped), force balance (Eq. 10)
and supports, with state packing.

Unknowns (:class:`SOCBState`):

* per node: position r (d), direction (2D: angle θ; 3D: tangent t ∈ R³ with |t| = 1 imposed
  as an equation, so that no direction is singular), bending moment m (2D: scalar; 3D:
  vector with m·t = 0 imposed: the rod is torsion-free);
* per segment: internal force n (d).

Equations, all dimensionless (forces by EI/l², moments by EI/l, lengths by l, with the
network's mean l and EI):

* per segment: the kernel of :mod:`socbjax._segment` (2D: 4 rows, 3D: 7 rows);
* per node, candidates from which ``Network.socb_rows`` selects statically:
  - force balance (Eq. 10)  Σ_{ending at i} n − Σ_{starting at i} n − F_i = 0  in the free
    directions of the node, prescribed position in the constrained ones;
  - 2D: θ = θ_ref where clamped; m = 0 at free/pinned ends;
  - 3D: |t|² = 1 (or t = t_ref where clamped); m·t = 0 (or m = 0 at free/pinned ends).

Count (clamped–free chain, N nodes): 2D 6N − 2 unknowns and equations, 3D 12N − 3.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._geometry import orthonormal_complement
from ._network import Network
from ._quadrature import SegmentQuadrature
from ._segment import planar_segment_residual, spatial_segment_residual

__all__ = [
    "SOCBState",
    "socb_initial_state",
    "socb_residual",
    "socb_frames",
    "net_nodal_force",
    "routed_nodal_force",
    "reference_scales",
    "socb_structure",
]


class SOCBState(eqx.Module):
    """Unknowns of the SOCB system (see module docstring for shapes and units)."""

    positions: Float[Array, "N d"]
    directors: Array  # 2D: angles [N] (rad); 3D: tangents [N, 3]
    moments: Array  # 2D: [N] (pN·µm); 3D: [N, 3]
    forces: Float[Array, "S d"]  # internal force per segment (pN)


def socb_initial_state(network: Network) -> SOCBState:
    """The unloaded straight reference state (an exact solution at zero load)."""
    if network.dim == 2:
        directors = jnp.arctan2(network.tangents[:, 1], network.tangents[:, 0])
        moments = jnp.zeros(network.n_nodes)
    else:
        directors = network.tangents
        moments = jnp.zeros((network.n_nodes, 3))
    return SOCBState(
        positions=network.positions,
        directors=directors,
        moments=moments,
        forces=jnp.zeros((network.n_segments, network.dim)),
    )


def reference_scales(network: Network):
    """(length µm, EI pN·µm², force pN) used to make residual rows dimensionless."""
    length = jnp.mean(network.lengths)
    EI = jnp.mean(network.EI)
    return length, EI, EI / length**2


def socb_frames(state: SOCBState, network: Network) -> Float[Array, "S 2 3"]:
    """Per-segment 'analysis frames' (paper Fig. 3): a basis of the plane ⊥ the segment's
    mean tangent, taken from ``state`` and held fixed during a Newton solve."""
    if network.dim == 2:
        return jnp.zeros((network.n_segments, 2, 3))
    t = state.directors / jnp.linalg.norm(state.directors, axis=-1, keepdims=True)
    mean = t[network.segments[:, 0]] + t[network.segments[:, 1]]
    mean = mean / jnp.linalg.norm(mean, axis=-1, keepdims=True)
    return jax.lax.stop_gradient(jax.vmap(orthonormal_complement)(mean))


def net_nodal_force(forces: Float[Array, "S d"], network: Network, loads: Float[Array, "N d"]) -> Float[Array, "N d"]:
    """Σ_{ending} n − Σ_{starting} n − F at each node (pN): zero at free nodes, and the
    reaction force that the support exerts on the node at supported ones."""
    n_nodes = network.n_nodes
    ending = jax.ops.segment_sum(forces, network.segments[:, 1], num_segments=n_nodes)
    starting = jax.ops.segment_sum(forces, network.segments[:, 0], num_segments=n_nodes)
    return ending - starting - loads


def routed_nodal_force(forces, network: Network, loads) -> Float[Array, "N d"]:
    """:func:`net_nodal_force` with each daughter base's share moved to its mother node, so
    that a junction balances all three segment ends at once (zero at daughter bases)."""
    imbalance = net_nodal_force(forces, network, loads)
    return jax.ops.segment_sum(imbalance, network.attach, num_segments=network.n_nodes)


def _unit(v):
    return v / jnp.linalg.norm(v, axis=-1, keepdims=True)


def _transport(a, b, v):
    """Minimal rotation taking unit a to unit b (about a × b), applied to v.  Singular only
    for b = −a (a mother tangent reversed by 180° at a junction)."""
    ab = a + b
    return v + 2.0 * jnp.sum(a * v, -1, keepdims=True) * b - jnp.sum(ab * v, -1, keepdims=True) / (
        1.0 + jnp.sum(a * b, -1, keepdims=True)
    ) * ab


def _support_rows(state_positions, imbalance, network: Network, displacement=0.0):
    length, _, force = reference_scales(network)
    attached = network.attached[:, None]
    eye = jnp.eye(network.dim)
    P = jnp.where(attached[..., None], eye[None], network.position_projector)
    moved = network.positions + displacement * network.probe[:, None] * network.probe_direction[None, :]
    target = jnp.where(attached, state_positions[network.attach], moved)
    fixed = jnp.einsum("nij,nj->ni", P, state_positions - target) / length
    free = jnp.einsum("nij,nj->ni", eye[None] - P, imbalance) / force
    return fixed + free


def _director_targets(directors, network: Network):
    """Prescribed directors: the reference one at clamps; at a daughter base, the reference
    daughter direction carried along with the mother's current tangent (2D: fixed angle
    offset; 3D: minimal rotation of the reference pair, see docs/equations.md)."""
    attached = network.attached
    J = network.attach
    if network.dim == 2:
        ref = jnp.arctan2(network.tangents[:, 1], network.tangents[:, 0])
        offset = jnp.arctan2(jnp.sin(ref - ref[J]), jnp.cos(ref - ref[J]))
        return jnp.where(attached, directors[J] + offset, ref)
    carried = _transport(network.tangents[J], _unit(directors[J]), network.tangents)
    return jnp.where(attached[:, None], carried, network.tangents)


def _moment_transfer(state, network: Network):
    """Daughter base moments handed to the mother (Σ end moments = 0 at a junction).

    Returns (per segment [S] / [S, 3]: subtracted from the start moment of the mother segment
    that leaves the junction; per node: subtracted in the end-moment equation of a mother
    node where no segment leaves).  In 3D the component along the mother tangent (a twist,
    which the torsion-free rod does not carry) is dropped."""
    m, J, n_seg = state.moments, network.attach, network.n_segments
    if network.dim == 3:
        tJ = _unit(state.directors[J])
        m = m - jnp.sum(m * tJ, -1, keepdims=True) * tJ
    m = jnp.where(network.attached.reshape((-1,) + (1,) * (m.ndim - 1)), m, 0.0)
    to_segment = jax.ops.segment_sum(m, network.transfer_segment, num_segments=n_seg + 1)[:n_seg]
    at_end = (network.transfer_segment == n_seg).reshape((-1,) + (1,) * (m.ndim - 1))
    to_node = jax.ops.segment_sum(jnp.where(at_end, m, 0.0), J, num_segments=network.n_nodes)
    return to_segment, to_node


def socb_residual(
    state: SOCBState,
    network: Network,
    loads: Float[Array, "N d"],
    frames: Float[Array, "S 2 3"],
    quad: SegmentQuadrature,
    displacement=0.0,
) -> Float[Array, " R"]:
    """The full SOCB residual vector (dimensionless), segment rows first, then node rows.

    ``loads`` [N, d] external nodal forces (pN); ``displacement`` probe displacement (µm)."""
    a, b = network.segments[:, 0], network.segments[:, 1]
    r, d, m = state.positions, state.directors, state.moments
    length_ref, EI_ref, _ = reference_scales(network)
    to_segment, to_node = _moment_transfer(state, network)
    m_start = m[a] - to_segment
    if network.dim == 2:
        seg = jax.vmap(planar_segment_residual, in_axes=(0,) * 9 + (None,))(
            r[a], d[a], m_start, r[b], d[b], m[b], state.forces, network.lengths, network.EI, quad
        )
    else:
        seg = jax.vmap(spatial_segment_residual, in_axes=(0,) * 10 + (None,))(
            r[a], d[a], m_start, r[b], d[b], m[b], state.forces, network.lengths, network.EI, frames, quad
        )
    imbalance = routed_nodal_force(state.forces, network, loads)
    support = _support_rows(r, imbalance, network, displacement)
    moment_scale = length_ref / EI_ref
    director_target = _director_targets(d, network)
    if network.dim == 2:
        candidates = jnp.concatenate(
            [support, (d - director_target)[:, None], ((m - to_node) * moment_scale)[:, None]], axis=1
        )
    else:
        candidates = jnp.concatenate(
            [
                support,
                (0.5 * (jnp.sum(d * d, axis=1) - 1.0))[:, None],
                d - director_target,
                (jnp.sum(m * d, axis=1) * moment_scale)[:, None],
                (m - to_node) * moment_scale,
            ],
            axis=1,
        )
    return jnp.concatenate([seg.ravel(), candidates.ravel()[network.socb_rows]])


def socb_structure(network: Network):
    """Graph structure of the SOCB system, for sparse Jacobians (host side, numpy).

    Vertices are the nodes (0..N−1) and segments (N..N+S−1); edges join a segment to its two
    nodes and a daughter base to its mother node.  Returns (vertex of each unknown [n],
    vertex of each residual row [n], edges [E, 2], number of vertices).  Every residual row
    at vertex v depends only on unknowns at vertices within graph distance 2 of v (segment
    rows: their nodes, and through the moment transfer the daughter bases at their start
    node; force rows at a mother node: the daughters' segments).
    """
    n_nodes, n_seg, d = network.n_nodes, network.n_segments, network.dim
    node_ids = np.arange(n_nodes)
    director_width = 1 if d == 2 else 3
    unknown = np.concatenate([
        np.repeat(node_ids, d), np.repeat(node_ids, director_width), np.repeat(node_ids, director_width),
        np.repeat(n_nodes + np.arange(n_seg), d),
    ])
    seg_rows = 4 if d == 2 else 7
    width = 4 if d == 2 else 11
    rows = np.concatenate([np.repeat(n_nodes + np.arange(n_seg), seg_rows), np.asarray(network.socb_rows) // width])
    seg = np.asarray(network.segments)
    attach = np.asarray(network.attach)
    daughters = np.flatnonzero(attach != node_ids)
    edges = np.concatenate([
        np.stack([seg[:, 0], n_nodes + np.arange(n_seg)], 1),
        np.stack([seg[:, 1], n_nodes + np.arange(n_seg)], 1),
        np.stack([daughters, attach[daughters]], 1),
    ])
    return unknown, rows, edges, n_nodes + n_seg


class SOCBModel(eqx.Module):
    """The SOCB discretisation of a network, as used by the solvers.

    ``quadrature_order`` Gauss–Legendre points per segment (Eq. 7; default 8).
    """

    network: Network
    quad: SegmentQuadrature = eqx.field(static=True)

    def initial_state(self) -> SOCBState:
        return socb_initial_state(self.network)

    def structure(self):
        """See :func:`socb_structure`."""
        return socb_structure(self.network)

    def frames(self, state: SOCBState):
        return socb_frames(state, self.network)

    def residual(self, state: SOCBState, loads, frames, displacement=0.0):
        return socb_residual(state, self.network, loads, frames, self.quad, displacement)
