"""The contact set-up of a model: obstacles per (segment, obstacle) slot, node ownership,
the contact law's numbers, and the slots' starting values (host side, numpy).

``contact_setup(network, contact)`` turns the user's :class:`socbjax.Contact` into the
:class:`socbjax._contact_segment.ContactSetup` that :class:`socbjax._residual.SOCBModel`
carries; ``contact=None`` keeps the contact-free model exactly.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ._contact import Contact
from ._contact_pairs import adjacent_segments
from ._contact_segment import ContactSetup
from ._network import Network
from ._probe import probe_frame

__all__ = ["contact_setup"]

# A supported node this close to an obstacle's surface (µm) is anchored on it (a probe tip
# on the probe face, a base on the substrate): its point is never a contact.
ANCHOR_TOLERANCE = 1e-9


def _obstacle_table(network: Network, contact: Contact):
    """(kinds, points [C, d], normals [C, d], radii [C], moving [C]) of every obstacle."""
    d = network.dim
    kinds, points, normals, radii, moving = [], [], [], [], []
    if contact.surfaces and network.has_probe:
        origin, gap = probe_frame(network)  # traced with traced positions
        axis = np.asarray(network.probe_direction, float)
        faces = [(origin, axis, 1.0)]
        if gap is not None:  # the substrate: the plane of the farthest opposing support
            faces.append((origin + gap * axis, -axis, 0.0))
        for point, normal, move in faces:
            kinds.append("plane"), points.append(point), normals.append(normal), radii.append(0.0), moving.append(move)
    for plane in contact.planes:
        kinds.append("plane"), points.append(plane.point), normals.append(plane.normal), radii.append(0.0)
        moving.append(0.0)
    for sphere in contact.obstacles:
        kinds.append("sphere"), points.append(sphere.center), normals.append(np.zeros(d)), radii.append(sphere.radius)
        moving.append(0.0)
    stack = lambda rows: jnp.reshape(jnp.asarray(rows, jnp.float64), (-1, d))  # noqa: E731
    return tuple(kinds), stack(points), stack(normals), jnp.asarray(radii, jnp.float64), jnp.asarray(moving, jnp.float64)


def _segment_roles(network: Network) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[S] each, 1 where: the segment's start node is a filament base (not the end of another
    segment, not a daughter base: it owns that point); another segment ends at its start node;
    another segment starts at its end node (the filament goes on smoothly through those nodes;
    a daughter's base is a corner)."""
    seg, attach = np.asarray(network.segments), np.asarray(network.attach)
    is_end, is_start = np.zeros(network.n_nodes, bool), np.zeros(network.n_nodes, bool)
    is_end[seg[:, 1]], is_start[seg[:, 0]] = True, True
    free_base = ~is_end & (attach == np.arange(network.n_nodes))
    return free_base[seg[:, 0]].astype(float), is_end[seg[:, 0]].astype(float), is_start[seg[:, 1]].astype(float)


def _ownership(network: Network, kinds, points, normals, radii, free_base):
    """(owns_start, owns_end) [S, C]: every node's point belongs to one segment (the one that
    ends there; a filament's base to the segment that starts there; a daughter base to its
    mother's segment), and a supported node on an obstacle's surface to none.  ``free_base``:
    [S] from :func:`_segment_roles`."""
    seg = np.asarray(network.segments)
    n_nodes = network.n_nodes
    pos = jnp.asarray(network.positions)  # traced under jit: ownership is data, not structure
    P = jnp.asarray(network.position_projector)
    columns = []
    for k, kind in enumerate(kinds):
        if kind == "plane":
            on = jnp.abs((pos - points[k]) @ normals[k]) < ANCHOR_TOLERANCE
            held = jnp.einsum("i,nij,j->n", normals[k], P, normals[k]) > 0.5
            columns.append(on & (held | jnp.asarray(network.probe)))
        else:
            columns.append(jnp.abs(jnp.linalg.norm(pos - points[k], axis=1) - radii[k]) < ANCHOR_TOLERANCE)
    anchored = jnp.stack(columns, axis=1) if columns else jnp.zeros((n_nodes, 0), bool)
    owns_start = (jnp.asarray(free_base)[:, None] > 0) & ~anchored[seg[:, 0]]
    owns_end = ~anchored[seg[:, 1]]
    return owns_start.astype(jnp.float64), owns_end.astype(jnp.float64)


def contact_setup(network: Network, contact: Contact | None, *, dense: bool = False) -> ContactSetup | None:
    """The model's contact set-up for ``network`` (None for ``contact=None``); refuses what
    is not built yet with a message that says so."""
    if contact is None:
        return None
    if not isinstance(contact, Contact):
        raise TypeError(f"contact must be None or a socbjax.Contact (e.g. contact=socbjax.Contact(planes=...)), got "
                        f"{type(contact).__name__}")
    if network.dim != 2:
        raise NotImplementedError("contact is built for planar (2D) networks so far; 3D contact (outcrops) is the "
                                  "next step of issue 15. Use contact=None for 3D networks.")
    if network.padding is not None:
        raise ValueError("contact is not supported on padded networks (socbjax.pad_outcrop); solve each realisation")
    for i, obstacle in enumerate(contact.planes + contact.obstacles):
        if obstacle.dim != network.dim:
            raise ValueError(f"contact obstacle {i} is {obstacle.dim}D but the network is {network.dim}D; give points "
                             f"and normals with {network.dim} components")
    kinds, points, normals, radii, moving = _obstacle_table(network, contact)
    free_base, smooth_start, smooth_end = _segment_roles(network)
    owns_start, owns_end = _ownership(network, kinds, points, normals, radii, free_base)
    EI, length = jnp.mean(network.EI), jnp.mean(network.lengths)
    delta, k = contact.law(EI)
    f = lambda v: jnp.asarray(v, jnp.float64)  # noqa: E731
    S = network.n_segments
    capacity = (max(8, S) if contact.capacity is None else contact.capacity) if contact.self_contact else 0
    reach = jnp.maximum(0.25 * length, 20.0 * delta) if contact.reach is None else contact.reach
    return ContactSetup(kinds=kinds, points=f(points), normals=f(normals), radii=f(radii), moving=f(moving),
                        owns_start=f(owns_start), owns_end=f(owns_end), filament_radius=f(contact.diameter / 2),
                        activation=f(delta), stiffness=f(k), force_scale=f(EI / length**2),
                        smooth_start=f(smooth_start), smooth_end=f(smooth_end), seg_owns_start=f(free_base),
                        adjacent=jnp.asarray(adjacent_segments(network)),
                        reach=f(reach), capacity=capacity, per_segment=contact.per_segment, dense=dense,
                        lumped=contact.lumped)
