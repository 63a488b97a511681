"""The SOCB system of a whole network: segment equations (vmapped), force balance (Eq. 10),
supports, junctions and nodal couples, with state packing.

Unknowns (:class:`SOCBState`):

* per node: position r (d), direction (2D: angle θ; 3D: tangent t ∈ R³ with |t| = 1 imposed
  as an equation, so that no direction is singular), bending moment m (2D: scalar; 3D:
  vector with m·t = 0 imposed: the rod is torsion-free);
* per segment: internal force n (d).

The controls of a path (:class:`Control`) are the load factor λ (scaling the network's
``loads`` and ``couples``), the probe displacement u (µm) and whether the probe holds its
nodes along the probe direction (``probe_held`` = 1) or lets them slide freely (0, the
settle phase of :func:`socbjax.compress`).

Equations, all dimensionless (forces by EI/l², moments by EI/l, lengths by l, with the
network's mean l and EI):

* per segment: the kernel of :mod:`socbjax._segment` (2D: 4 rows, 3D: 7 rows), with the
  start moment reduced by the moments handed over at the start node (junction daughters and
  applied couples, :mod:`socbjax._junction`);
* per node, candidates from which ``Network.socb_rows`` selects statically:
  - force balance (Eq. 10)  Σ_{ending at i} n − Σ_{starting at i} n − λF_i = 0  in the free
    directions of the node, prescribed position in the constrained ones;
  - 2D: θ = θ_ref where clamped; m = (handed-over moments) at free/pinned ends;
  - 3D: |t|² = 1 (or t = t_ref where clamped); m·t = 0 (or the end moment at free ends).

A twisting network (3D, built with ``GJ=``; :mod:`socbjax._twist`) adds per node the frame
angle ψ (``SOCBState.twists``), per segment the third component of Eq. 8 and the twist law
(:mod:`socbjax._segment`), and drops m·t = 0: clamps and daughter bases prescribe ψ.

Count (clamped–free chain, N nodes): 2D 6N − 2 unknowns and equations, 3D 12N − 3, 3D with
twist 13N − 3.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._contact_near import near_list, near_margins
from ._contact_pairs import PairList, broad_phase, initial_pairs, merge_pairs, pair_extra, pair_rows, pair_width, segment_table
from ._contact_segment import SLOT_WIDTH, ContactSetup, initial_slots
from ._contact_start import check_start_gaps, settle_locations
from ._contact_spatial import SPATIAL_SLOT_WIDTH, initial_spatial_slots
from ._geometry import orthonormal_complement
from ._junction import director_targets, moment_transfer, nodal_couple_transfer
from ._kernels import contact_kernel, near_kernel, segment_rows, state_tangents
from ._network import Network, node_row_width
from ._quadrature import SegmentQuadrature
from ._segment import planar_turn
from ._twist import twist_targets

__all__ = [
    "Control",
    "SOCBState",
    "SOCBModel",
    "socb_residual",
    "net_nodal_force",
    "routed_nodal_force",
    "route_to_mothers",
    "support_reactions",
    "reference_scales",
    "support_rows",
    "socb_structure",
    "state_tangents",
    "n_twists",
    "slot_width",
]


class Control(eqx.Module):
    """The control parameters of a residual: load factor λ (×``loads`` and ``couples``),
    probe displacement u (µm) and ``probe_held`` (1: probe nodes prescribed along the probe
    direction; 0: free along it).  Scalars, traced."""

    load_factor: Array
    displacement: Array
    probe_held: Array

    @staticmethod
    def make(load_factor=1.0, displacement=0.0, probe_held=1.0) -> Control:
        f = lambda v: jnp.asarray(v, jnp.float64)  # noqa: E731
        return Control(f(load_factor), f(displacement), f(probe_held))

    def towards(self, other: Control, p) -> Control:
        """The linear interpolation self + p (other − self) (p ∈ [0, 1])."""
        return jax.tree_util.tree_map(lambda a, b: a + p * (b - a), self, other)


class SOCBState(eqx.Module):
    """Unknowns of the SOCB system (see module docstring for shapes and units)."""

    positions: Float[Array, "N d"]
    directors: Array  # 2D: angles [N] (rad); 3D: tangents [N, 3]
    moments: Array  # 2D: [N] (pN·µm); 3D: [N, 3]
    forces: Float[Array, "S d"]  # internal force per segment (pN)
    twists: Array  # material-frame angles [N] (rad) of a twisting network, else [0]
    contacts: Array  # contact slots: 2D [S, C, 5] (σ, F pN, θ rad, κ 1/µm; socbjax._contact_segment),
    # 3D [S, C, 10] (σ, F pN, t, t' 1/µm; socbjax._contact_spatial); C = 0 without contact
    pairs: Array  # filament–filament contact slots [P, 10] (2D) or [P, 19] (3D) (socbjax._contact_pairs),
    # P = 0 without


def n_twists(network: Network) -> int:
    """Number of frame-angle unknowns: N for a twisting network, else 0."""
    return network.n_nodes if network.twisting else 0


def reference_scales(network: Network):
    """(length µm, EI pN·µm², force pN) used to make residual rows dimensionless."""
    length = jnp.mean(network.lengths)
    EI = jnp.mean(network.EI)
    return length, EI, EI / length**2


def net_nodal_force(forces: Float[Array, "S d"], network: Network, loads: Float[Array, "N d"],
                    end_forces: Array | None = None) -> Float[Array, "N d"]:
    """Σ_{ending} n − Σ_{starting} n − F at each node (pN): zero at free nodes, and the
    reaction force that the support exerts on the node at supported ones.  ``end_forces``:
    the segments' internal forces at their ends where interior point forces (contact) make
    them differ from ``forces`` (at their starts)."""
    n_nodes = network.n_nodes
    end_forces = forces if end_forces is None else end_forces
    ending = jax.ops.segment_sum(end_forces, network.segments[:, 1], num_segments=n_nodes)
    starting = jax.ops.segment_sum(forces, network.segments[:, 0], num_segments=n_nodes)
    return ending - starting - loads


def route_to_mothers(imbalance: Float[Array, "N d"], network: Network) -> Float[Array, "N d"]:
    """A nodal ``imbalance`` (:func:`net_nodal_force`) with each daughter base's share moved
    to its mother node, so that a junction balances all three segment ends at once (zero at
    daughter bases)."""
    return jax.ops.segment_sum(imbalance, network.attach, num_segments=network.n_nodes)


def routed_nodal_force(forces, network: Network, loads, end_forces=None) -> Float[Array, "N d"]:
    """:func:`net_nodal_force` routed to the mother nodes (:func:`route_to_mothers`)."""
    return route_to_mothers(net_nodal_force(forces, network, loads, end_forces), network)


def support_reactions(imbalance: Float[Array, "N d"], network: Network) -> Float[Array, "N d"]:
    """[N, d] the force each support exerts on its node (pN): the nodal ``imbalance``
    (:func:`net_nodal_force`) in the node's supported directions, zero at free nodes."""
    return jnp.einsum("nij,nj->ni", jnp.asarray(network.position_projector), imbalance)


def support_rows(state_positions, imbalance, network: Network, control: Control | None = None):
    """Node rows [N, d]: prescribed position (µm, by the reference length) in the supported
    directions of each node, force balance (by the reference force) in the free ones.  The
    probe nodes move by ``control.displacement`` along the probe direction, and slide freely
    along it when ``control.probe_held`` is 0."""
    control = Control.make() if control is None else control
    length, _, force = reference_scales(network)
    attached = network.attached[:, None]
    eye = jnp.eye(network.dim)
    axis = jnp.asarray(network.probe_direction)
    released = (1.0 - control.probe_held) * jnp.outer(axis, axis)
    P = jnp.asarray(network.position_projector) - jnp.where(network.probe[:, None, None], released, 0.0)
    P = jnp.where(attached[..., None], eye[None], P)
    moved = network.positions + control.displacement * network.probe[:, None] * axis[None, :]
    target = jnp.where(attached, state_positions[network.attach], moved)
    fixed = jnp.einsum("nij,nj->ni", P, state_positions - target) / length
    free = jnp.einsum("nij,nj->ni", eye[None] - P, imbalance) / force
    return fixed + free


def _frames(state: SOCBState, network: Network) -> Float[Array, "S 2 3"]:
    """Per-segment 'analysis frames' (paper Fig. 3): a basis of the plane ⊥ the segment's
    mean tangent, taken from ``state`` and held fixed during a Newton solve."""
    if network.dim == 2:
        return jnp.zeros((network.n_segments, 2, 3))
    t = state_tangents(state.directors, 3)
    mean = t[network.segments[:, 0]] + t[network.segments[:, 1]]
    mean = mean / jnp.linalg.norm(mean, axis=-1, keepdims=True)
    return jax.lax.stop_gradient(jax.vmap(orthonormal_complement)(mean))


def slot_width(dim: int) -> int:
    """Unknowns (and rows) per obstacle slot: 5 in 2D, 10 in 3D."""
    return SLOT_WIDTH if dim == 2 else SPATIAL_SLOT_WIDTH


def _start_moments(state: SOCBState, network: Network, control: Control):
    """(moment at each segment's start less what the start node hands over [S], the handed-over
    moments at the nodes: junction, applied couples) — pN·µm."""
    junction_segment, junction_node = moment_transfer(state, network)
    couple_segment, couple_node = nodal_couple_transfer(control.load_factor * network.couples, network)
    return state.moments[network.segments[:, 0]] - junction_segment - couple_segment, junction_node, couple_node


def _start_node_loads(start_loads, network: Network):
    """[N, d] the segments' start-node loads [S, d] (lumped contact) summed at their nodes."""
    return jax.ops.segment_sum(start_loads, network.segments[:, 0], num_segments=network.n_nodes)


def socb_residual(state: SOCBState, network: Network, control: Control, frames: Float[Array, "S 2 3"],
                  quad: SegmentQuadrature, contact: ContactSetup | None = None) -> Float[Array, " R"]:
    """The full SOCB residual vector (dimensionless): segment rows, node rows, and with
    ``contact`` the contact slots' rows last."""
    r, d, m = state.positions, state.directors, state.moments
    length_ref, EI_ref, _ = reference_scales(network)
    m_start, junction_node, couple_node = _start_moments(state, network, control)
    end_forces, slot_rows, loads = None, jnp.zeros(0), control.load_factor * network.loads
    if contact is not None:
        extra, pair_frame = None, None
        if contact.capacity:
            frames, pair_frame = frames
            extra = pair_extra(state.pairs, pair_frame.table)
        if contact.listed:
            frames, near = frames
            seg, slot_rows, end_forces, start_loads = near_kernel(state, network, contact, control, quad, frames,
                                                                   m_start, near)
        else:
            seg, slot_rows, end_forces, start_loads, _, _, at_pairs = contact_kernel(
                state, network, contact, control, quad, frames, m_start, extra)
        loads = loads + _start_node_loads(start_loads, network)
        if pair_frame is not None:
            slot_rows = jnp.concatenate([slot_rows.ravel(), pair_rows(state.pairs, pair_frame, at_pairs, network,
                                                                      contact, (r, d))[0].ravel()])
    else:
        seg = segment_rows(state, network, quad, frames, m_start)
    imbalance = routed_nodal_force(state.forces, network, loads, end_forces)
    support = support_rows(r, imbalance, network, control)
    end_moment = (m - junction_node - couple_node) * (length_ref / EI_ref)
    if network.dim == 2:  # angles agree modulo 2π (arctan2 of the reference wraps at ±π)
        director_error = planar_turn(0.0, d - director_targets(d, network))
        candidates = jnp.concatenate([support, director_error[:, None], end_moment[:, None]], axis=1)
        return jnp.concatenate([seg.ravel(), candidates.ravel()[network.socb_rows], slot_rows.ravel()])
    norm_row = 0.5 * (jnp.sum(d * d, axis=1) - 1.0)
    torsion_free = jnp.sum(m * d, axis=1) * (length_ref / EI_ref)
    if network.twisting:  # the whole frame is fixed at clamps and daughter bases
        target_t, target_psi = twist_targets(state_tangents(d, 3), state.twists, network)
        frame_error = planar_turn(target_psi, state.twists)
        candidates = jnp.concatenate([support, norm_row[:, None], d - target_t, torsion_free[:, None], end_moment,
                                      frame_error[:, None]], axis=1)
    else:
        candidates = jnp.concatenate([support, norm_row[:, None], d - director_targets(d, network),
                                      torsion_free[:, None], end_moment], axis=1)
    return jnp.concatenate([seg.ravel(), candidates.ravel()[network.socb_rows], slot_rows.ravel()])


def socb_structure(network: Network, n_obstacles: int = 0, n_pairs: int = 0):
    """Graph structure of the SOCB system, for sparse Jacobians (host side, numpy).

    Vertices are the nodes (0..N−1), segments (N..N+S−1) and filament–filament pair slots
    (N+S..N+S+P−1, no edges); edges join a segment to its two nodes and a daughter base to
    its mother node.  Returns (vertex of each unknown [n],
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
        np.repeat(n_nodes + np.arange(n_seg), d), node_ids[:n_nodes if network.twisting else 0],
    ])
    seg_rows, width = (4, 4) if d == 2 else (9 if network.twisting else 7, node_row_width(network))
    rows = np.concatenate([np.repeat(n_nodes + np.arange(n_seg), seg_rows), np.asarray(network.socb_rows) // width])
    slots = np.repeat(n_nodes + np.arange(n_seg), n_obstacles * slot_width(d))  # contact slots: at their segment
    # each pair slot is a vertex of its own, without edges: the segments it joins change from
    # step to step (socbjax._paired adds those couplings per pair list)
    pairs = np.repeat(n_nodes + n_seg + np.arange(n_pairs), pair_width(d))
    unknown, rows = np.concatenate([unknown, slots, pairs]), np.concatenate([rows, slots, pairs])
    seg, attach = np.asarray(network.segments), np.asarray(network.attach)
    daughters = np.flatnonzero(attach != node_ids)
    edges = np.concatenate([
        np.stack([seg[:, 0], n_nodes + np.arange(n_seg)], 1),
        np.stack([seg[:, 1], n_nodes + np.arange(n_seg)], 1),
        np.stack([daughters, attach[daughters]], 1),
    ])
    return unknown, rows, edges, n_nodes + n_seg + n_pairs


class SOCBModel(eqx.Module):
    """The SOCB discretisation of a network, as used by the solvers: ``network`` (values
    traced), the Gauss–Legendre ``quad`` (static; Eq. 7, default order 8) and the
    ``contact`` set-up (None: no contact; :mod:`socbjax._contact_model`)."""

    network: Network
    quad: SegmentQuadrature = eqx.field(static=True)
    contact: ContactSetup | None = None
    name = "socb"

    def initial_state(self, *, check: bool = False) -> SOCBState:
        """The unloaded straight reference state (an exact solution at zero load): the
        :meth:`state_template`, contact slots settled on their closest points (``check``: a
        ValueError where two pieces start within the law's range, :func:`check_start_gaps`)."""
        state = self.state_template()
        if self.contact is None:
            return state
        state, gaps = settle_locations(self, state, Control.make(load_factor=0.0))
        if check:
            check_start_gaps(self, state, gaps)
        return state

    def state_template(self) -> SOCBState:
        """The reference state before the contact start: the structure (shapes, dtypes) of
        every state of this model.  Settling the slots (:meth:`initial_state`) runs a small
        Newton solve, seconds of compilation that callers needing only the structure skip."""
        net = self.network
        if net.dim == 2:
            directors, moments = jnp.arctan2(net.tangents[:, 1], net.tangents[:, 0]), jnp.zeros(net.n_nodes)
        else:
            directors, moments = net.tangents, jnp.zeros((net.n_nodes, 3))
        state = SOCBState(positions=net.positions, directors=directors, moments=moments,
                          forces=jnp.zeros((net.n_segments, net.dim)), twists=jnp.zeros(n_twists(net)),
                          contacts=(initial_slots(net, self.contact, directors) if net.dim == 2 else
                                    initial_spatial_slots(net, self.contact, directors)),
                          pairs=self._initial_pairs(net))
        return state

    def _initial_pairs(self, net: Network):
        """Empty pair slots holding the pairs of the reference state's broad phase (so that
        the start is an equilibrium: the ids rows vanish)."""
        empty = initial_pairs(self.n_pairs, net.dim)
        if not self.n_pairs:
            return empty
        return empty.at[:, :2].set(self._broad_phase(net.positions)[0].astype(empty.dtype))

    def _broad_phase(self, positions):
        """(pair ids [P, 2], overflow) of the broad phase at ``positions`` (no derivatives)."""
        net, c = self.network, self.contact
        r = jax.lax.stop_gradient(positions)
        a, b = net.segments[:, 0], net.segments[:, 1]
        return broad_phase(0.5 * (r[a] + r[b]), 0.5 * net.lengths, 2.0 * c.filament_radius + c.reach, c.adjacent,
                           c.capacity, 2 * c.per_segment)

    @property
    def n_unknowns(self) -> int:
        """Size of the flat state (host side, no tracing)."""
        net, w = self.network, (1 if self.network.dim == 2 else 3)
        return (net.n_nodes * (net.dim + 2 * w) + net.n_segments * (net.dim + self.n_obstacles * slot_width(net.dim))
                + n_twists(net) + self.n_pairs * pair_width(net.dim))

    @property
    def n_pairs(self) -> int:
        """Filament–filament contact slots P (0 without self-contact)."""
        return 0 if self.contact is None else self.contact.capacity

    @property
    def n_obstacles(self) -> int:
        """Contact obstacles C (each segment has one slot per obstacle); 0 without contact."""
        return 0 if self.contact is None else self.contact.n_obstacles

    def structure(self):
        """See :func:`socb_structure`."""
        return socb_structure(self.network, self.n_obstacles, self.n_pairs)

    def frames(self, state: SOCBState, control: Control | None = None):
        """Held fixed during a Newton solve: the 3D analysis bases, and with self-contact the
        pair list rebuilt from ``state`` (:mod:`socbjax._contact_pairs`), or with
        ``Contact(slot_capacity=...)`` the near list (:mod:`socbjax._contact_near`; the probe
        face placed by ``control``'s displacement, 0 when None)."""
        bases = _frames(state, self.network)
        if self.n_pairs:
            return bases, self.pair_list(state)
        if self.contact is not None and self.contact.listed:
            displacement = 0.0 if control is None else control.displacement
            return bases, near_list(self.contact, self.network, state, jax.lax.stop_gradient(displacement))
        return bases

    def path_frames(self, state: SOCBState, control: Control):
        """:meth:`frames` of a path step at ``control`` (the path's hook)."""
        return self.frames(state, control)

    def hold_pairs(self, state: SOCBState, frames) -> SOCBState:
        """``state`` with its pair slots' ids set to those of ``frames`` (:meth:`frames`)."""
        if not self.n_pairs:
            return state
        ids = frames[1].ids.astype(state.pairs.dtype)
        return eqx.tree_at(lambda s: s.pairs, state, state.pairs.at[:, :2].set(ids))

    def pair_list(self, state: SOCBState, rebuild: bool = True) -> PairList:
        """The pairs of ``state``: its own ids (``rebuild=False``) or, merged with them, those
        of a fresh broad phase at its positions."""
        net, c = self.network, self.contact
        ids = jax.lax.stop_gradient(state.pairs[:, :2]).astype(jnp.int64)
        overflow = jnp.asarray(False)
        if rebuild:
            found, overflow = self._broad_phase(state.positions)
            ids = merge_pairs(ids, found, net.n_segments)
        table, crowded = segment_table(ids, net.n_segments, c.per_segment)
        return PairList(ids=ids, table=table, overflow=overflow | crowded)

    def residual(self, state: SOCBState, control: Control, frames):
        return socb_residual(state, self.network, control, frames, self.quad, self.contact)

    def contact_geometry(self, state: SOCBState, control: Control | None = None):
        """Contact slots of ``state``: (points [c, d] µm, gaps [c] µm, forces on the filament
        [c, d] pN, counted [c] bool, end forces [S, d] pN, nodal loads of lumped contact [N, d]
        pN) over the c = S·C obstacle slots, then the P pair slots (their point on
        segment i; force on i).
        A slot is not counted where it sits on the start node of a segment inside a filament
        (the segment ending there reports that point) or on a node anchored on the obstacle
        (a probe tip on the probe face), nor on a segment anchored on it, nor where a pair slot
        is empty."""
        parts = self._contact_parts(state, Control.make() if control is None else control)
        return (*parts[:5], parts[6])

    def _contact_parts(self, state: SOCBState, control: Control):
        """:meth:`contact_geometry`'s first five outputs, the pair slots' points on both sides
        [P, 2, d], and the nodal loads [N, d] of lumped contact."""
        net, c, dim = self.network, self.contact, self.network.dim
        m_start = _start_moments(state, net, control)[0]
        frame = self.pair_list(state, rebuild=False) if self.n_pairs else None
        extra = None if frame is None else pair_extra(state.pairs, frame.table)
        _, _, end_forces, start_loads, points, gaps, at_pairs = contact_kernel(
            state, net, c, control, self.quad, _frames(state, net), m_start, extra)
        s = jnp.clip(state.contacts[..., 0], 0.0, 1.0)
        counted = (c.active * jnp.where(s >= 1.0, c.owns_end, 1.0) * jnp.where(s <= 0.0, c.owns_start, 1.0)) > 0
        out = (points.reshape(-1, dim), gaps.reshape(-1), state.contacts[..., 1:1 + dim].reshape(-1, dim),
               counted.reshape(-1))
        both = jnp.zeros((0, 2, dim))
        if frame is not None:
            _, pair_gaps, both = pair_rows(state.pairs, frame, at_pairs, net, c, (state.positions, state.directors))
            out = (jnp.concatenate([out[0], both[:, 0]]), jnp.concatenate([out[1], pair_gaps]),
                   jnp.concatenate([out[2], state.pairs[:, 4:4 + dim]]),
                   jnp.concatenate([out[3], frame.ids[:, 0] >= 0]))
        return (*out, end_forces, both, _start_node_loads(start_loads, net))

    def step_admissible(self, old: SOCBState, new: SOCBState, frames=None, displacement=0.0):
        """(admissible, overflow) of a path step.  Not admissible when a segment may have moved
        through a sphere or point obstacle or through another segment (a plane cannot be
        crossed unseen: the gap turns negative): each curve point of a segment moves by at
        most D = max |Δr| at its nodes + l · max |Δθ| along it (taken as 1.5 × the larger nodal
        turn), and a segment whose axis was φ from a sphere cannot reach it if D < φ.  A listed
        pair that may have come closer (D_i + D_j ≥ its axis distance) must still have its
        closest points on the same sides of each other; pairs not in the list are farther than
        ``reach`` apart, so 2 max D < reach.  Overflow: the new state has more candidate pairs
        than the capacity (``RESULTS.contact_capacity``).  With the near list (``frames`` of
        the step, :mod:`socbjax._contact_near`) instead: not admissible when a segment outside
        it reached the band of the closest-point rule (probe face at ``displacement`` µm);
        overflow: more near segments than the list holds."""
        c = self.contact
        if c is not None and c.listed and frames is not None:  # no segment outside the near list came near
            outside = jnp.ones(self.network.n_segments, bool).at[frames[1].ids].set(False)
            margin = near_margins(c, self.network, new.positions, displacement)
            return ~jnp.any(outside & (margin < 0.0)), frames[1].overflow
        if c is None or ("sphere" not in c.kinds and not self.n_pairs):
            return jnp.asarray(True), jnp.asarray(False)
        net = self.network
        a, b = net.segments[:, 0], net.segments[:, 1]
        moved = jnp.linalg.norm(new.positions - old.positions, axis=-1)
        turned = jnp.abs(new.directors - old.directors)  # 2D: angles; 3D: the chord of the unit tangents
        turned = turned if net.dim == 2 else 1.1 * jnp.linalg.norm(turned, axis=-1)
        turned = 1.5 * jnp.maximum(turned[a], turned[b])  # the turn inside a segment, with a margin
        reach = jnp.maximum(moved[a], moved[b]) + net.lengths * turned  # [S]
        _, gaps, _, _, _, both_old, _ = self._contact_parts(old, Control.make())
        C, S = self.n_obstacles, net.n_segments
        spheres = np.array([k == "sphere" for k in c.kinds], bool)
        phi = gaps[: S * C].reshape(S, C)[:, spheres] + c.filament_radius
        ok = jnp.all(reach[:, None] < phi)
        if not self.n_pairs:
            return ok, jnp.asarray(False)
        ids = jnp.clip(old.pairs[:, :2].astype(jnp.int64), 0, S - 1)
        axis_distance = jnp.where(old.pairs[:, 0] >= 0, gaps[S * C:] + 2.0 * c.filament_radius, jnp.inf)
        # a listed pair that moved closer than D_i + D_j: still on the same side of each other
        # (the separation of its closest points along the old direction has not turned over)
        both_new = self._contact_parts(new, Control.make())[5]
        same_side = jnp.sum((both_old[:, 0] - both_old[:, 1]) * (both_new[:, 0] - both_new[:, 1]), axis=-1) > 0
        near = reach[ids[:, 0]] + reach[ids[:, 1]] >= axis_distance
        ok = ok & jnp.all(~near | same_side) & (2.0 * jnp.max(reach) < c.reach)
        return ok, self.pair_list(new).overflow

    def newton_step_limit(self, old: SOCBState, new: SOCBState, control_old: Control, control_new: Control):
        """The largest fraction α ∈ [0.01, 1] of a Newton step old → new (gaps taken linear
        along it) after which no counted contact gap g lies below 2 g₀ − 5δ/4 (g₀ its gap
        at ``old``, δ the activation distance): a gap outside the band may enter it by δ/4
        (force ≤ kδ/192), one inside may at most double its depth 1 − g/δ (plus ¼).  Outside
        the band the linearisation sees no contact force, so an unlimited step would carry a
        node deep into the stiff penalty, whose residual Newton then reduces only linearly
        (the step-length filter of IPC, for a penalty instead of a barrier).  1 without
        contact."""
        if self.contact is None:
            return jnp.ones(())
        _, g0, _, counted = self.contact_geometry(old, control_old)[:4]
        g1 = self.contact_geometry(new, control_new)[1]
        delta = self.contact.activation
        lower = jnp.minimum(2.0 * g0 - 1.25 * delta, 0.75 * delta)
        falls = counted & (g1 < lower) & (g0 > lower)
        alpha = jnp.where(falls, (g0 - lower) / jnp.where(falls, g0 - g1, 1.0), 1.0)
        return jnp.clip(jnp.min(alpha, initial=1.0), 0.01, 1.0)

    def contact_ends(self, state: SOCBState):
        """(internal force at each segment's end [S, d] pN, extra nodal loads [N, d] pN): the
        state's (start) forces less the segments' interior contact forces, and the loads that
        lumped contact (comparison only) puts on start nodes; (forces, 0) without contact."""
        if self.contact is None:
            return state.forces, jnp.zeros_like(state.positions)
        return self.contact_geometry(state)[4:]

    def tangents(self, state: SOCBState) -> Array:
        return state_tangents(state.directors, self.network.dim)

    def node_moments(self, state: SOCBState) -> Array:
        return state.moments
