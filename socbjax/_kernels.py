"""The segment kernels of a whole network (vmapped over segments): contact-free
(:mod:`socbjax._segment`), with contact slots (:mod:`socbjax._contact_segment`,
:mod:`socbjax._contact_spatial`), and the near list's mix of the two
(:mod:`socbjax._contact_near`)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._contact_near import NearList, idle_slot_rows, take_segments
from ._contact_segment import contact_segment_rows
from ._contact_spatial import spatial_contact_segment_rows
from ._network import Network
from ._segment import planar_segment_residual, spatial_segment_residual
from ._twist import carried_directors

__all__ = ["state_tangents", "twist_data", "segment_rows", "contact_kernel", "near_kernel"]


def state_tangents(directors, dim: int) -> Array:
    """Unit tangents [N, d] from SOCB directors (2D angles, 3D tangent vectors)."""
    if dim == 2:
        return jnp.stack([jnp.cos(directors), jnp.sin(directors)], axis=-1)
    return directors / jnp.linalg.norm(directors, axis=-1, keepdims=True)


def twist_data(state, network):
    """Per-segment (ψ_a, ψ_b, e_a, e_b, GJ, κ₀) of a twisting network, else None."""
    if not network.twisting:
        return None
    a, b = network.segments[:, 0], network.segments[:, 1]
    e = carried_directors(state_tangents(state.directors, 3), network)
    return (state.twists[a], state.twists[b], e[a], e[b], network.GJ, network.natural_curvature)


class _Segments(NamedTuple):
    """The per-segment data of a network that the contact kernels read, for a subset."""

    segments: Array
    lengths: Array
    EI: Array
    natural_curvature: Array
    probe_direction: Array
    n_segments: int


def _take(network: Network, ids) -> _Segments:
    """``network``'s segments ``ids`` [K], as the contact kernels read them."""
    return _Segments(jnp.asarray(network.segments)[ids], network.lengths[ids], network.EI[ids],
                     network.natural_curvature[ids], network.probe_direction, int(ids.shape[0]))


def contact_kernel(state, network, contact, control, quad, frames, m_start, extra=None, ids=None):
    """(segment rows, slot rows, end forces, start-node loads, points, gaps, pair data or None)
    of the segments with their contact slots, planar or spatial; with ``ids`` [K] only of
    those segments (the near list, :mod:`socbjax._contact_near`)."""
    r, d, m = state.positions, state.directors, state.moments
    forces, slots, twist, dim = state.forces, state.contacts, twist_data(state, network), network.dim
    if ids is not None:
        forces, slots, m_start, frames = forces[ids], slots[ids], m_start[ids], frames[ids]
        twist = None if twist is None else tuple(t[ids] for t in twist)
        network, contact = _take(network, ids), take_segments(contact, ids)
    if dim == 2:
        return contact_segment_rows(r, d, m, m_start, forces, slots, network, contact, control, quad, extra)
    return spatial_contact_segment_rows(r, d, m, m_start, forces, slots, network, contact, control, quad, frames, twist,
                                        extra)


def near_kernel(state, network, contact, control, quad, bases, m_start, near: NearList):
    """(segment rows, slot rows, end forces, start-node loads) with the near list: the contact
    kernel for the listed segments, the contact-free kernel and idle slot rows for the others
    (:mod:`socbjax._contact_near`)."""
    ids = near.ids
    seg, slots, ends, starts = contact_kernel(state, network, contact, control, quad, bases, m_start, ids=ids)[:4]
    plain = segment_rows(state, network, quad, bases, m_start)
    idle = idle_slot_rows(state.contacts, near.held, contact, network.dim)
    return (plain.at[ids].set(seg), idle.at[ids].set(slots), state.forces.at[ids].set(ends),
            jnp.zeros_like(state.forces).at[ids].set(starts))


def segment_rows(state, network, quad, frames, m_start):
    """Segment rows [S, 4] (2D) or [S, 7 or 9] (3D) of the contact-free kernel."""
    a, b = network.segments[:, 0], network.segments[:, 1]
    r, d, m = state.positions, state.directors, state.moments
    if network.dim == 2:
        kernel = jax.vmap(planar_segment_residual, in_axes=(0,) * 9 + (None, 0))
        return kernel(r[a], d[a], m_start, r[b], d[b], m[b], state.forces, network.lengths, network.EI, quad,
                      network.natural_curvature)
    twist = twist_data(state, network)
    kernel = jax.vmap(spatial_segment_residual, in_axes=(0,) * 10 + (None, 0))
    return kernel(r[a], d[a], m_start, r[b], d[b], m[b], state.forces, network.lengths, network.EI, frames, quad, twist)
