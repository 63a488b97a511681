"""The jointed baseline (paper Eq. 4): straight rigid segments joined by rotational springs.

This is the idealisation the paper compares against (Figs 4, 5c) and the basis of most
bead–spring and jointed-rod filament models.  Each segment is a rigid bar of length l with
direction d (2D: angle ψ; 3D: unit vector, |d| = 1 imposed as an equation).  The bending
moment at a joint is the spring law of Eq. 4, m = EI Δθ / l:

* interior joint between bars p and q:  m = k · rot(d_p → d_q)  with
  k = 2 / (l_p/EI_p + l_q/EI_q)  (two half-bars in series; EI/l for equal bars);
* clamped end: the first bar's direction stands for the tangent at its midpoint, half a bar
  from the clamp, so the clamp spring is k = 2 EI / l (the consistent discrete elastica,
  second-order accurate; with EI/l at the clamp the model converges only at first order);
* free and pinned ends: no spring;
* 2D natural curvature κ₀: each bar is the chord of an arc turning by κ₀l at rest, so a
  spring's rest angle is the sum of the half-turns of the bars on either side of it (a
  clamp's: the half-turn of its bar); the springs act on the angle minus the rest angle.

rot(a → b) is the rotation angle (2D, signed) or rotation vector (3D) from a to b.
Equations: per bar, r_b − r_a = l d (d rows), moment balance of the bar
m_b − m_a + (r_b − r_a) × n = 0 (2D: 1 row; 3D: 2 rows ⊥ d, the twist row being
identically zero), and in 3D |d|² = 1; per node, force balance (Eq. 10) or prescribed
position, exactly as in SOCB.  Unknowns: node positions, bar directions, bar forces.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._geometry import orthonormal_complement, rotation_vector
from ._network import Network
from ._residual import Control, net_nodal_force, support_rows

__all__ = ["JointedState", "JointedModel", "joint_moments"]


class JointedState(eqx.Module):
    """positions [N, d] (µm); directions [S] (2D angle, rad) or [S, 3] (unit); forces [S, d] (pN)."""

    positions: Float[Array, "N d"]
    directions: Array
    forces: Float[Array, "S d"]


def _unit(network: Network, directions):
    if network.dim == 2:
        return jnp.stack([jnp.cos(directions), jnp.sin(directions)], axis=-1)
    return directions / jnp.linalg.norm(directions, axis=-1, keepdims=True)


def _rotation(network: Network, a, b):
    if network.dim == 2:
        return jnp.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], jnp.sum(a * b, axis=-1))
    return jax.vmap(rotation_vector)(a, b)


def joint_moments(state: JointedState, network: Network):
    """Bending moment at every node (2D [N], 3D [N, 3], pN·µm) from the joint springs."""
    n_nodes = network.n_nodes
    a, b = network.segments[:, 0], network.segments[:, 1]
    d = _unit(network, state.directions)
    compliance = network.lengths / network.EI  # l/EI per bar
    # Each node sees at most two bars (chains): the one ending there (p) and starting (q).
    seg_ids = jnp.arange(network.n_segments)
    p = jax.ops.segment_max(seg_ids, b, num_segments=n_nodes)  # bar ending at node (or <0)
    q = jax.ops.segment_max(seg_ids, a, num_segments=n_nodes)  # bar starting at node
    has_p, has_q = p >= 0, q >= 0
    p_safe, q_safe = jnp.where(has_p, p, 0), jnp.where(has_q, q, 0)
    d_in = jnp.where(has_p[:, None], d[p_safe], network.tangents)  # clamp direction if none
    d_out = jnp.where(has_q[:, None], d[q_safe], network.tangents)
    interior = 2.0 / (compliance[p_safe] + compliance[q_safe])
    clamp = 2.0 / jnp.where(has_p, compliance[p_safe], compliance[q_safe])
    k = jnp.where(has_p & has_q, interior, jnp.where(network.clamped, clamp, 0.0))
    rot = _rotation(network, d_in, d_out)
    if network.dim == 3:
        return k[:, None] * rot
    half_turn = 0.5 * network.natural_curvature * network.lengths
    rest = jnp.where(has_p, half_turn[p_safe], 0.0) + jnp.where(has_q, half_turn[q_safe], 0.0)
    return k * (rot - rest)


class JointedModel(eqx.Module):
    """The jointed discretisation of a network (same solver interface as SOCB).

    Nodal couples C enter the bar moment balances as moment jumps: the bar leaving a node
    starts with m − C, and at a node where no bar leaves the ending bar ends with m + C
    (see :mod:`socbjax._junction`); 3D twisting components are dropped with the ⊥d projection.
    """

    network: Network
    name = "jointed"

    @property
    def n_unknowns(self) -> int:
        """Size of the flat state (host side, no tracing)."""
        net = self.network
        return net.n_nodes * net.dim + net.n_segments * ((1 if net.dim == 2 else 3) + net.dim)

    def initial_state(self) -> JointedState:
        net = self.network
        t = net.tangents[net.segments[:, 0]]
        # 2D: the chord of a naturally curved segment lies at half its turn from the start tangent
        directions = jnp.arctan2(t[:, 1], t[:, 0]) + 0.5 * net.natural_curvature * net.lengths if net.dim == 2 else t
        return JointedState(net.positions, directions, jnp.zeros((net.n_segments, net.dim)))

    def frames(self, state: JointedState):
        if self.network.dim == 2:
            return jnp.zeros((self.network.n_segments, 2, 3))
        d = _unit(self.network, state.directions)
        return jax.lax.stop_gradient(jax.vmap(orthonormal_complement)(d))

    def residual(self, state: JointedState, control: Control, frames) -> Float[Array, " R"]:
        net = self.network
        a, b = net.segments[:, 0], net.segments[:, 1]
        r = state.positions
        d = _unit(net, state.directions)
        chord = r[b] - r[a]
        length_eq = (chord - net.lengths[:, None] * d) / net.lengths[:, None]
        m = joint_moments(state, net)
        C = control.load_factor * net.couples
        tip = (net.leaving_segment == net.n_segments).reshape((-1,) + (1,) * (C.ndim - 1))
        m_start, m_end = m[a] - C[a], m[b] + jnp.where(tip, C, 0.0)[b]
        n = state.forces
        if net.dim == 2:
            torque = chord[:, 0] * n[:, 1] - chord[:, 1] * n[:, 0]
            moment_eq = ((m_end - m_start + torque) * net.lengths / net.EI)[:, None]
            seg = jnp.concatenate([length_eq, moment_eq], axis=1)
        else:
            balance = m_end - m_start + jnp.cross(chord, n)
            moment_eq = jnp.einsum("sij,sj->si", frames, balance) * (net.lengths / net.EI)[:, None]
            norm_eq = 0.5 * (jnp.sum(state.directions**2, axis=1) - 1.0)
            seg = jnp.concatenate([length_eq, moment_eq, norm_eq[:, None]], axis=1)
        imbalance = net_nodal_force(n, net, control.load_factor * net.loads)
        support = support_rows(r, imbalance, net, control)
        return jnp.concatenate([seg.ravel(), support.ravel()])

    def tangents(self, state: JointedState) -> Array:
        """Node tangents [N, d]: the normalised mean of the bar directions meeting there."""
        net = self.network
        d = _unit(net, state.directions)
        summed = jax.ops.segment_sum(jnp.concatenate([d, d]), jnp.concatenate([net.segments[:, 0], net.segments[:, 1]]),
                                     net.n_nodes)
        return summed / jnp.linalg.norm(summed, axis=-1, keepdims=True)

    def node_moments(self, state: JointedState) -> Array:
        return joint_moments(state, self.network)
