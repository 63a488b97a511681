"""Smooth filament shapes between nodes, from the SOCB angle polynomials (Eqs 5, 6a, 7).

SOCB nodes carry the whole C²-continuous angle field, so a 2-node solution already draws a
smooth curve: each segment's tangent is evaluated from its quintic at fine points and
integrated (Gauss–Legendre on [0, σ]) from the start node.  For the jointed model the shape
is the polyline through the nodes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._network import Network
from ._quadrature import gauss_legendre, hermite_basis
from ._residual import SOCBState
from ._segment import planar_segment_angles, spatial_segment_tangents

__all__ = ["filament_curve"]


def filament_curve(solution, network: Network, points_per_segment: int = 24) -> np.ndarray:
    """Points along every segment, [S, P, d] (µm), end points included.

    ``solution`` is a :class:`socbjax.Solution` of ``network``.
    """
    state = solution.state
    if not isinstance(state, SOCBState):
        pos = np.asarray(solution.positions)
        seg = np.asarray(network.segments)
        s = np.linspace(0.0, 1.0, points_per_segment)[None, :, None]
        return pos[seg[:, 0]][:, None, :] * (1 - s) + pos[seg[:, 1]][:, None, :] * s
    sigma = np.linspace(0.0, 1.0, points_per_segment)
    gx, gw = gauss_legendre(8)
    sub = (sigma[:, None] * gx[None, :]).ravel()  # points of the sub-quadratures on [0, σ_p]
    basis = jnp.asarray(hermite_basis(tuple(sub.tolist())))
    a, b = network.segments[:, 0], network.segments[:, 1]
    d, m, n = state.directors, state.moments, state.forces
    if network.dim == 2:
        theta = jax.vmap(planar_segment_angles, in_axes=(0, 0, 0, 0, 0, 0, 0, None))(
            d[a], m[a], d[b], m[b], n, network.lengths, network.EI, basis
        )
        t = jnp.stack([jnp.cos(theta), jnp.sin(theta)], axis=-1)
    else:
        t = jax.vmap(spatial_segment_tangents, in_axes=(0, 0, 0, 0, 0, 0, 0, None))(
            d[a], m[a], d[b], m[b], n, network.lengths, network.EI, basis
        )
    t = np.asarray(t).reshape(network.n_segments, len(sigma), len(gx), network.dim)
    offsets = np.einsum("spkd,k->spd", t, gw) * sigma[None, :, None] * np.asarray(network.lengths)[:, None, None]
    return np.asarray(state.positions)[np.asarray(a)][:, None, :] + offsets
