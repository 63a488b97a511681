"""The smooth filament curve between nodes (SOCB Eqs 5, 6a, 7 evaluated at any arc length).

SOCB nodes carry the whole C²-continuous angle field, so a 2-node solution already is a
smooth curve: each segment's tangent is its quintic interpolant (2D angle; 3D log-chart
interpolant, :mod:`socbjax._segment`), the positions are its integral from the start node
(Gauss–Legendre on [0, s]), the curvature is the interpolant's derivative, and the bending
moment follows exactly from statics, m(s) = m_b − (r(s) − r_b) × n (constant internal force
n in the segment; m_b the end moment).  For the jointed model the segments are the rigid
bars (straight, zero curvature inside; the moment is the same statics).

Everything is a JAX function of the equilibrium (positions, tangents, moments, segment
forces), so it is differentiable and works under ``jit`` and ``vmap``.  Units: µm, 1/µm,
pN·µm.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ._checks import is_traced
from ._quadrature import gauss_legendre, hermite_basis, hermite_basis_derivative
from ._segment import kirchhoff_segment_curve, planar_segment_curve, spatial_segment_curve
from ._twist import carried_directors

__all__ = ["FilamentCurve", "filament_curve"]


class FilamentCurve(eqx.Module):
    """Points along every segment (S segments, P points each, both end nodes included).

    s : [S, P] arc length from the segment's start node (µm).
    positions, tangents : [S, P, d] points (µm) and unit tangents.
    curvature : 2D [S, P] signed curvature dθ/ds; 3D [S, P, 3] curvature vector t × t' (1/µm).
    moment : 2D [S, P] bending moment; 3D [S, P, 3] moment vector (pN·µm).
    """

    s: Array
    positions: Array
    tangents: Array
    curvature: Array
    moment: Array

    def polyline(self) -> np.ndarray:
        """All points of all segments as one [S·P, d] numpy array (for plotting)."""
        return np.asarray(self.positions).reshape(-1, self.positions.shape[-1])


def _cross(a, b):
    if a.shape[-1] == 2:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return jnp.cross(a, b)


def _smooth(network, tangents, moments, forces, sigma, twists=None):
    """(tangents [S, K, d], d tangent/ds) of the SOCB interpolants at normalised points σ."""
    seg = network.segments
    basis = jnp.asarray(hermite_basis(tuple(sigma.tolist())))
    dbasis = jnp.asarray(hermite_basis_derivative(tuple(sigma.tolist())))
    a, b = seg[:, 0], seg[:, 1]
    if network.dim == 2:
        theta = jnp.arctan2(tangents[:, 1], tangents[:, 0])  # the kernel unwraps each end against its start
        theta_a, theta_b = theta[a], theta[b]
        theta, dtheta = jax.vmap(planar_segment_curve, in_axes=(0,) * 7 + (None, None, 0))(
            theta_a, moments[a], theta_b, moments[b], forces, network.lengths, network.EI, basis, dbasis,
            network.natural_curvature)
        t = jnp.stack([jnp.cos(theta), jnp.sin(theta)], axis=-1)
        dt = dtheta[..., None] * jnp.stack([-jnp.sin(theta), jnp.cos(theta)], axis=-1)
        return t, dt
    if network.twisting:  # jets on the material frame (its angles matter only with natural curvature)
        twists = jnp.zeros(network.n_nodes) if twists is None else twists
        e = carried_directors(tangents, network)
        twist = (twists[a], twists[b], e[a], e[b], network.GJ, network.natural_curvature)
        return jax.vmap(kirchhoff_segment_curve, in_axes=(0,) * 7 + (None, None, 0))(
            tangents[a], moments[a], tangents[b], moments[b], forces, network.lengths, network.EI, basis, dbasis, twist)
    return jax.vmap(spatial_segment_curve, in_axes=(0,) * 7 + (None, None))(
        tangents[a], moments[a], tangents[b], moments[b], forces, network.lengths, network.EI, basis, dbasis)


def filament_curve(network, positions, tangents, moments, forces, *, points_per_segment: int = 16,
                   model: str = "socb", bar_directions=None, twists=None) -> FilamentCurve:
    """The curve of an equilibrium (``positions`` [N, d], unit ``tangents`` [N, d], node
    ``moments``, segment ``forces`` [S, d]) at ``points_per_segment`` equally spaced points
    per segment (≥ 2).  ``model="jointed"`` draws the rigid bars, whose directions
    ``bar_directions`` [S, d] default to the chords.  ``twists`` [N]: the frame angles of a
    twisting network (needed where it has natural curvature).

    For step k of a compression pass ``result.positions[k]``, ``result.tangents[k]``,
    ``result.moments[k]`` and ``result.segment_forces[k]``.  For a path computed with contact
    this is each segment's curve without its interior contact forces (the result does not
    store the slots; the figures draw it so too)."""
    P = int(points_per_segment)
    if P < 2:
        raise ValueError(f"points_per_segment must be at least 2 (the two end nodes), got {points_per_segment!r}")
    curved = is_traced(network.natural_curvature) or np.any(np.asarray(network.natural_curvature) != 0)
    if model != "jointed" and network.twisting and twists is None and curved:
        raise ValueError("filament_curve: a naturally curved twisting network needs its frame angles (twists=...) to "
                         "place its curvature between the nodes; use Solution.curve()")
    seg = network.segments
    a, b = seg[:, 0], seg[:, 1]
    sigma = np.linspace(0.0, 1.0, P)
    lengths = network.lengths
    if model == "jointed":
        chord = positions[b] - positions[a]
        d = chord / jnp.linalg.norm(chord, axis=-1, keepdims=True) if bar_directions is None else bar_directions
        pts = positions[a][:, None, :] + jnp.asarray(sigma)[None, :, None] * chord[:, None, :]
        t = jnp.broadcast_to(d[:, None, :], pts.shape)
        curvature = jnp.zeros(pts.shape[:2] if network.dim == 2 else pts.shape)
    else:
        gx, gw = gauss_legendre(8)
        sub = (sigma[:, None] * gx[None, :]).ravel()  # points of the sub-quadratures on [0, σ_p]
        t_sub, _ = _smooth(network, tangents, moments, forces, sub, twists)
        t_sub = t_sub.reshape(network.n_segments, P, gx.size, network.dim)
        offsets = jnp.einsum("spkd,k->spd", t_sub, jnp.asarray(gw)) * jnp.asarray(sigma)[None, :, None] * lengths[:, None, None]
        pts = positions[a][:, None, :] + offsets
        t, dt = _smooth(network, tangents, moments, forces, sigma, twists)
        curvature = _cross(t, dt)
    m_end = moments[b]
    arm = pts - positions[b][:, None, :]
    n = jnp.broadcast_to(forces[:, None, :], arm.shape)
    moment = (m_end[:, None] if network.dim == 2 else m_end[:, None, :]) - _cross(arm, n)
    s = jnp.asarray(sigma)[None, :] * lengths[:, None]
    return FilamentCurve(s=s, positions=pts, tangents=t, curvature=curvature, moment=moment)
