"""Material frames of the 3D Kirchhoff rod with twist (networks built with ``GJ=``).

Every node i carries, besides its unit tangent t_i, a material-frame angle ψ_i (rad): the
material director is d1 = cos ψ e + sin ψ (t × e), where e is the node's reference director
g_i (``Network.directors``, default ``orthonormal_complement(T_i)[0]``, T_i the reference
tangent) carried to the current tangent by the smallest rotation T_i → t_i (singular only
for a tangent reversed by 180° from its reference).  In the reference state ψ = 0 and the
material frame is (T, g, T × g).

Clamps fix the whole frame: t = T and ψ = 0.  A branch junction fixes the daughter's frame
in the mother's material frame at the junction node: the daughter's base tangent and
reference director keep the coordinates they have in the mother's reference frame
(replacing the torsion-free rule of parallel transport, ``docs/equations.md``).  The twist
law along a segment is in :mod:`socbjax._segment` (``_kirchhoff_rows``).  Units: rad.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._geometry import minimal_rotation
from ._segment import frame_angle, turned_director

__all__ = ["carried_directors", "material_frames", "twist_targets"]


def _unit(v):
    return v / jnp.linalg.norm(v, axis=-1, keepdims=True)


def _reference_frames(network):
    """[N, 3, 3] reference material frames, rows (T, g, T × g) (g: ``network.directors``)."""
    T = _unit(jnp.asarray(network.tangents))
    g = jnp.asarray(network.directors)
    return jnp.stack([T, g, jnp.cross(T, g)], axis=1)


def carried_directors(tangents, network):
    """[N, 3] reference directors carried to the current unit ``tangents`` [N, 3]."""
    ref = _reference_frames(network)
    return minimal_rotation(ref[:, 0], tangents, ref[:, 1])


def material_frames(tangents, twists, network):
    """[N, 3, 3] current material frames, rows (t, d1, d2), from unit ``tangents`` [N, 3]
    and frame angles ``twists`` [N] (rad)."""
    d1 = turned_director(tangents, carried_directors(tangents, network), twists)
    return jnp.stack([tangents, d1, jnp.cross(tangents, d1)], axis=1)


def twist_targets(tangents, twists, network):
    """(tangent targets [N, 3], frame-angle targets [N]) of the director-fixed nodes: the
    reference frame at clamps; at a daughter base the daughter's reference tangent and
    director expressed in its mother's reference frame and mapped into the mother's current
    material frame (the target angle is measured about the daughter's current tangent)."""
    ref = _reference_frames(network)
    J = network.attach
    frames = material_frames(tangents, twists, network)
    # coordinates of the daughter's reference tangent and director in the mother's reference frame
    c_t = jnp.einsum("nij,nj->ni", ref[J], ref[:, 0])
    c_d = jnp.einsum("nij,nj->ni", ref[J], ref[:, 1])
    target_t = jnp.einsum("nji,nj->ni", frames[J], c_t)
    target_d = jnp.einsum("nji,nj->ni", frames[J], c_d)
    e = carried_directors(tangents, network)
    target_psi = jax.vmap(frame_angle)(tangents, e, target_d)
    attached = jnp.asarray(network.attached)
    return (jnp.where(attached[:, None], target_t, ref[:, 0]), jnp.where(attached, target_psi, 0.0))
