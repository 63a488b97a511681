"""The near list: only segments close to an obstacle carry the contact kernel.

Every segment has one slot per obstacle (:mod:`socbjax._contact_segment`), but far from the
obstacles a slot is idle: its force is zero (the law vanishes beyond the activation distance
δ) and its location row rests at σ = ½ (:func:`socbjax._contact_segment.near_weight` is 0).
Such a segment's equations are the contact-free kernel's.  With ``Contact(slot_capacity=K)``
the residual evaluates the contact kernel (interior forces, composite quadrature, the slot
geometry) only for the K segments nearest to an obstacle, listed before each path step, and
the contact-free kernel of :mod:`socbjax._segment` for all the others, whose slots get the
*idle rows*

    σ − σ_rest,   F / F_s,   (shape unknowns) − (their values when the list was made).

At a solution where no unlisted segment comes within the band of the closest-point rule, this
is the full model's solution (up to the quadrature: one Gauss–Legendre interval instead of
the composite one split at the idle σ): there every unlisted slot has near weight 0 and zero
force, and its shape unknowns enter nothing else (the jumps vanish with the force).  The path
checks exactly that after every step (:meth:`socbjax.SOCBModel.step_admissible`): a segment
outside the list that reached the band rejects the step, which is retried shorter.

Nearness of segment s to obstacle k is judged as the closest-point rule judges it: the lowest
possible gap φ_k(chord midpoint) − l/2 − d/2 against the band max(10 δ, l/20); a segment is
listed when that margin is below ``reach`` (µm; ``Contact(reach=...)``) for some obstacle.
More such segments than K is an overflow: the path stops with ``RESULTS.contact_capacity``,
never truncating the list silently.  A host-driven :func:`socbjax.compress` then doubles K
(:func:`grow_near_list`; every segment once 2K ≥ S), warns, and goes on from its last step
with one recompilation; traced paths (``solve``, ``compress(..., at=...)``) stop.  The list
is data (the K segment ids), so a change of the near set never recompiles.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp

from ._contact_segment import ContactSetup, near_band, rest_sigma, signed_distance

__all__ = ["NearList", "near_margins", "near_list", "idle_slot_rows", "take_segments", "grow_near_list"]

# per-segment fields of ContactSetup that the segment kernels read
_PER_SEGMENT = ("owns_start", "owns_end", "slot_smooth_start", "slot_smooth_end", "active", "pinned", "smooth_start",
                "smooth_end", "seg_owns_start")


class NearList(eqx.Module):
    """The near list of one path step: ``ids`` [K] (the segments that carry the contact
    kernel), ``held`` [S, C, w] (the slots' values when it was made: the idle rows' targets)
    and ``overflow`` (more segments near an obstacle than K)."""

    ids: jax.Array
    held: jax.Array
    overflow: jax.Array


def near_margins(setup: ContactSetup, network, positions, displacement) -> jax.Array:
    """[S] µm: for each segment, the smallest over obstacles of (lowest possible gap − band),
    the band of :func:`socbjax._contact_segment.near_weight`; +inf for a segment with no
    active slot.  A segment with margin ≥ 0 has near weight 0 and no contact force."""
    a, b = network.segments[:, 0], network.segments[:, 1]
    middle = 0.5 * (positions[a] + positions[b])
    axis = jnp.asarray(network.probe_direction, positions.dtype)
    length = network.lengths
    band = near_band(length, setup.activation)
    columns = []
    for k in range(setup.n_obstacles):
        phi = jax.vmap(lambda r, k=k: signed_distance(setup, k, r, displacement, axis)[0])(middle)
        columns.append(phi - 0.5 * length - setup.filament_radius - band)
    margin = jnp.stack(columns, axis=1)
    return jnp.min(jnp.where(setup.active > 0, margin, jnp.inf), axis=1)


def near_list(setup: ContactSetup, network, state, displacement) -> NearList:
    """The K = ``setup.slot_capacity`` segments with the smallest margins (no derivatives)."""
    positions = jax.lax.stop_gradient(state.positions)
    margin = near_margins(setup, network, positions, displacement)
    K = setup.slot_capacity
    _, ids = jax.lax.top_k(-margin, K)
    wanted = jnp.sum(margin < setup.reach)
    return NearList(ids=ids, held=jax.lax.stop_gradient(state.contacts), overflow=wanted > K)


def idle_slot_rows(slots, held, setup: ContactSetup, dim: int) -> jax.Array:
    """[S, C, w] the rows of idle slots (see the module docstring): location σ − σ_rest,
    force F/F_s, shape unknowns − ``held``."""
    location = slots[..., :1] - rest_sigma(setup)[..., None]
    force = slots[..., 1:1 + dim] / setup.force_scale
    return jnp.concatenate([location, force, slots[..., 1 + dim:] - held[..., 1 + dim:]], axis=-1)


def take_segments(setup: ContactSetup, ids) -> ContactSetup:
    """``setup`` restricted to the segments ``ids`` [K] (its per-segment fields gathered)."""
    names = [n for n in _PER_SEGMENT if getattr(setup, n) is not None]
    return eqx.tree_at(lambda s: [getattr(s, n) for n in names], setup, [getattr(setup, n)[ids] for n in names])


def grow_near_list(setup: ContactSetup, n_segments: int) -> ContactSetup:
    """``setup`` with twice the near list's capacity K, or every segment (K = 0: no list)
    once 2K ≥ ``n_segments``.  The state's layout does not depend on K (every segment keeps
    its slots), so a path continues from its last state with the grown list."""
    K = 2 * setup.slot_capacity
    return dataclasses.replace(setup, slot_capacity=0 if K >= n_segments else K)
