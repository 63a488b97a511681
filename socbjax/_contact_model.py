"""The contact set-up of a model: obstacles per (segment, obstacle) slot, node ownership,
the contact law's numbers, and the slots' starting values (host side, numpy).

``contact_setup(network, contact)`` turns the user's :class:`socbjax.Contact` into the
:class:`socbjax._contact_segment.ContactSetup` that :class:`socbjax._residual.SOCBModel`
carries; ``contact=None`` keeps the contact-free model exactly.
"""

from __future__ import annotations

import jax
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
    """(kinds, points [C, d], normals [C, d], radii [C], moving [C], surface [C], names) of
    every obstacle; ``surface`` is 1 for the probe face and the substrate (placed through the
    anchored tips and bases here; :func:`contact_setup` moves them back by d/2 + δ); names:
    "probe face", "substrate", "plane i", "sphere i" (i: the index in ``contact.planes`` /
    ``contact.obstacles``)."""
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
    n_faces = len(kinds)
    for plane in contact.planes:
        kinds.append("plane"), points.append(plane.point), normals.append(plane.normal), radii.append(0.0)
        moving.append(0.0)
    for sphere in contact.obstacles:
        kinds.append("sphere"), points.append(sphere.center), normals.append(np.zeros(d)), radii.append(sphere.radius)
        moving.append(0.0)
    stack = lambda rows: jnp.reshape(jnp.asarray(rows, jnp.float64), (-1, d))  # noqa: E731
    surface = np.arange(len(kinds)) < n_faces
    names = (("probe face", "substrate")[:n_faces] + tuple(f"plane {i}" for i in range(len(contact.planes)))
             + tuple(f"sphere {i}" for i in range(len(contact.obstacles))))
    return (tuple(kinds), stack(points), stack(normals), jnp.asarray(radii, jnp.float64),
            jnp.asarray(moving, jnp.float64), surface.astype(float), names)


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
    """(owns_start, owns_end [S, C], anchored [N, C]): every node's point belongs to one segment (the one that
    ends there; a filament's base to the segment that starts there; a daughter base to its
    mother's segment), and a supported node on an obstacle's surface (anchored) to none.
    ``free_base``: [S] from :func:`_segment_roles`."""
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
    return owns_start.astype(jnp.float64), owns_end.astype(jnp.float64), anchored.astype(jnp.float64)


def _beside_anchors(network: Network, anchored, owns_start, owns_end, smooth_start, smooth_end):
    """Per (segment, obstacle) node roles next to an anchored segment: a segment anchored on an
    obstacle at one end (a strand's base on the substrate, a tip on the probe face) starts
    inside the contact band there, and its slot rests on the anchor (no force); so the node at
    its other end belongs wholly to the neighbouring segment (no hand-over toward the anchored
    one), which keeps that node off the surface.  Returns (owns_start, owns_end, smooth_start,
    smooth_end) [S, C]."""
    seg = np.asarray(network.segments)
    S = len(seg)
    C = anchored.shape[1]
    nxt, prv = np.full(S, -1), np.full(S, -1)
    starting = {int(a): i for i, a in enumerate(seg[:, 0])}
    for i, b in enumerate(seg[:, 1]):
        j = starting.get(int(b), -1)
        if j >= 0 and smooth_end[i] > 0:
            nxt[i], prv[j] = j, i
    smooth_start = jnp.broadcast_to(jnp.asarray(smooth_start)[:, None], (S, C))
    smooth_end = jnp.broadcast_to(jnp.asarray(smooth_end)[:, None], (S, C))
    if C == 0:
        return owns_start, owns_end, smooth_start, smooth_end
    has_next, has_prev = jnp.asarray(nxt >= 0)[:, None], jnp.asarray(prv >= 0)[:, None]
    # the next segment's far end anchored: this segment keeps its end node
    next_anchored = has_next & (anchored[seg[np.maximum(nxt, 0), 1]] > 0)
    # the previous segment's far start anchored: this segment owns its start node
    prev_anchored = has_prev & (anchored[seg[np.maximum(prv, 0), 0]] > 0)
    smooth_end = jnp.where(next_anchored, 0.0, smooth_end)
    smooth_start = jnp.where(prev_anchored, 0.0, smooth_start)
    owns_start = jnp.where(prev_anchored, 1.0, owns_start)
    # and the other side of those nodes gives them up: the anchored segment's start / end
    gives_start = jnp.zeros((S, C)).at[np.maximum(nxt, 0)].max(next_anchored.astype(float)) > 0
    gives_end = jnp.zeros((S, C)).at[np.maximum(prv, 0)].max(prev_anchored.astype(float)) > 0
    smooth_start = jnp.where(gives_start, 0.0, smooth_start)
    owns_end = jnp.where(gives_end, 0.0, owns_end)
    smooth_end = jnp.where(gives_end, 0.0, smooth_end)
    return owns_start, owns_end, smooth_start, smooth_end


def _check_spatial(network: Network, contact: Contact) -> None:
    """Refuse what 3D contact does not do yet, naming the fix."""
    if network.twisting:
        kappa = network.natural_curvature
        if not isinstance(kappa, jax.core.Tracer) and np.any(np.asarray(kappa)[:, :2] != 0):
            raise NotImplementedError("3D contact on filaments with natural curvature (κ₁, κ₂ ≠ 0) is not built yet; "
                                      "use a straight rest shape (natural_curvature=None) with contact")


def contact_setup(network: Network, contact: Contact | None, *, dense: bool = False) -> ContactSetup | None:
    """The model's contact set-up for ``network`` (None for ``contact=None``); refuses what
    is not built yet with a message that says so."""
    if contact is None:
        return None
    if not isinstance(contact, Contact):
        raise TypeError(f"contact must be None or a socbjax.Contact (e.g. contact=socbjax.Contact(planes=...)), got "
                        f"{type(contact).__name__}")
    if network.dim == 3:
        _check_spatial(network, contact)
    if network.padding is not None:
        raise ValueError("contact is not supported on padded networks (socbjax.pad_outcrop); solve each realisation")
    for i, obstacle in enumerate(contact.planes + contact.obstacles):
        if obstacle.dim != network.dim:
            raise ValueError(f"contact obstacle {i} is {obstacle.dim}D but the network is {network.dim}D; give points "
                             f"and normals with {network.dim} components")
    kinds, points, normals, radii, moving, surface, names = _obstacle_table(network, contact)
    free_base, smooth_start, smooth_end = _segment_roles(network)
    owns_start, owns_end, anchored = _ownership(network, kinds, points, normals, radii, free_base)
    # The probe face and the substrate lie d/2 + δ beyond the anchored tips and bases: an
    # anchored axis end then sits at the band's edge (no force), and the anchored segments obey
    # the contact law like every other (their interior cannot dip through).  Other obstacles
    # with anchored nodes exempt the anchored segments (docs/equations.md "Anchored segments").
    exempt = anchored * (1.0 - jnp.asarray(surface))[None, :]
    slot_roles = _beside_anchors(network, exempt, owns_start, owns_end, smooth_start, smooth_end)
    seg = np.asarray(network.segments)
    EI, length = jnp.mean(network.EI), jnp.mean(network.lengths)
    delta, k = contact.law(EI)
    points = points - ((contact.diameter / 2 + delta) * jnp.asarray(surface))[:, None] * normals
    pinned = jnp.where(anchored[seg[:, 0]] > 0, 1.0, 2.0 * anchored[seg[:, 1]]) * jnp.asarray(surface)[None, :]
    f = lambda v: jnp.asarray(v, jnp.float64)  # noqa: E731
    S = network.n_segments
    capacity = (max(8, S) if contact.capacity is None else contact.capacity) if contact.self_contact else 0
    reach = jnp.maximum(0.25 * length, 20.0 * delta) if contact.reach is None else contact.reach
    return ContactSetup(kinds=kinds, names=names, points=f(points), normals=f(normals), radii=f(radii), moving=f(moving),
                        owns_start=f(slot_roles[0]), owns_end=f(slot_roles[1]), slot_smooth_start=f(slot_roles[2]),
                        slot_smooth_end=f(slot_roles[3]),
                        active=f(1.0 - jnp.maximum(exempt[seg[:, 0]], exempt[seg[:, 1]])), pinned=f(pinned),
                        filament_radius=f(contact.diameter / 2),
                        activation=f(delta), stiffness=f(k), force_scale=f(EI / length**2),
                        smooth_start=f(smooth_start), smooth_end=f(smooth_end), seg_owns_start=f(free_base),
                        adjacent=jnp.asarray(adjacent_segments(network)),
                        reach=f(reach), capacity=capacity, per_segment=contact.per_segment, dense=dense,
                        lumped=contact.lumped, slot_capacity=contact.near_capacity(S))
