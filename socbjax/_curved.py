"""Naturally curved filaments: :func:`with_natural_curvature`, :func:`arc`, :func:`helix`,
:func:`crimped_fibre`.

A segment with natural curvature κ₀ (1/µm) is a circular arc at rest: it turns by τ = κ₀l
(rad) over its length l, its chord is l·sin(τ/2)/(τ/2) and its end tangents lie at ∓τ/2 from
the chord (the bending law m = EI (θ' − κ₀), ``docs/equations.md`` §"Natural curvature").
:func:`with_natural_curvature` gives any 2D network the stress-free shape of a new set of
curvatures: starting from one anchor node per connected piece (its position and tangent are
kept), it walks the segments and junctions and places every node where the arcs put it;
branch junctions keep their angle between mother and daughter, and every support keeps its
kind at the node's new position.  Host side (numpy), concrete values only: the shape fixes
the reference positions that supports prescribe.

In 3D a curved rod needs its material frame: only twisting networks (built with ``GJ=``)
take natural curvature, as (κ₁, κ₂, τ₀) on the material frame (d1, d2, t) per segment, and
each segment is then at rest a piece of helix (``docs/equations.md``).  Units: µm, pN,
pN·µm², degrees for angles.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ._builders import cantilever, column
from ._checks import check_array, check_dim, check_int, check_real, describe
from ._network import Network, is_traced
from ._network_checks import check_natural_curvature, check_reference_state, check_rest_frames, rest_segment

__all__ = ["ACTIN_GJ", "arc", "check_curvable", "crimped_fibre", "helix", "with_natural_curvature"]

ACTIN_GJ = 8e-3  # pN·µm²: actin's torsional rigidity 8e-27 N·m² (Tsuda et al., PNAS 93, 12937, 1996)


def check_curvable(network: Network, what: str) -> None:
    """Refuses what :func:`with_natural_curvature` cannot reshape: not a network, padded,
    traced geometry."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network, got {describe(network)}")
    if network.padding is not None:
        raise ValueError(f"{what}: the network is padded (pad_outcrop); curve the outcrop first, then pad it")
    if any(is_traced(getattr(network, k)) for k in ("positions", "tangents", "lengths", "EI", "natural_curvature",
                                                     "directors")):
        raise TypeError(f"{what} places the nodes on the host and needs concrete positions, tangents, lengths, EI and "
                        "natural curvature "
                        "(call it outside jax.jit/grad/vmap; the natural curvature may be traced afterwards via "
                        "network.replace(natural_curvature=...))")


def _anchors(network: Network) -> np.ndarray:
    """Node order by preference as the anchor of its piece: clamped (the base of a filament,
    the seed of an outcrop on the probe), then probe, then other position-supported nodes,
    then the rest (stable in the node index)."""
    fixed = np.einsum("nii->n", np.asarray(network.position_projector)) > 0.5
    probe = np.asarray(network.probe)
    rank = np.where(network.clamped, 0, np.where(probe, 1, np.where(fixed, 2, 3)))
    return np.argsort(rank, kind="stable")


def _walk(network: Network, step) -> None:
    """Breadth-first from one anchor per connected piece; ``step(u, v, kind, index)`` places
    node v from its placed neighbour u across segment ``index`` (kind "ahead": u is the
    start, "back": u is the end) or junction (kind "daughter" / "mother")."""
    moves = [[] for _ in range(network.n_nodes)]
    for k, (a, b) in enumerate(np.asarray(network.segments)):
        moves[a].append((b, "ahead", k))
        moves[b].append((a, "back", k))
    for i in np.flatnonzero(network.attached):
        moves[int(network.attach[i])].append((i, "daughter", i))
        moves[i].append((int(network.attach[i]), "mother", i))
    placed = np.zeros(network.n_nodes, bool)
    for anchor in _anchors(network):
        if placed[anchor]:
            continue
        placed[anchor] = True
        queue = deque([anchor])
        while queue:
            u = queue.popleft()
            for v, kind, index in moves[u]:
                if not placed[v]:
                    step(u, v, kind, index)
                    placed[v] = True
                    queue.append(v)


def _place_2d(network: Network, kappa: np.ndarray):
    lengths = np.asarray(network.lengths, float)
    turns = check_natural_curvature(kappa, lengths, 2)
    chords = lengths * np.sinc(turns / (2 * np.pi))
    positions = np.array(network.positions, float)
    theta = np.arctan2(network.tangents[:, 1], network.tangents[:, 0])
    offset = theta - theta[network.attach]  # junction angles, kept

    def step(u, v, kind, k):
        if kind in ("ahead", "back"):
            sign = 1.0 if kind == "ahead" else -1.0
            direction = theta[u] + 0.5 * sign * turns[k]
            positions[v] = positions[u] + sign * chords[k] * np.array([np.cos(direction), np.sin(direction)])
            theta[v] = theta[u] + sign * turns[k]
        else:
            positions[v] = positions[u]
            theta[v] = theta[u] + (offset[k] if kind == "daughter" else -offset[k])

    _walk(network, step)
    tangents = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    check_reference_state(positions, tangents, np.asarray(network.segments), lengths, turns)
    return positions, tangents, network.directors


def _place_3d(network: Network, kappa: np.ndarray):
    if not network.twisting:
        raise ValueError("with_natural_curvature: a naturally curved 3D filament needs its torsional stiffness; build "
                         "the network with GJ= (e.g. actin's 8e-3 pN·µm²)")
    lengths = np.asarray(network.lengths, float)
    check_natural_curvature(kappa, lengths, 3, True)
    positions = np.array(network.positions, float)
    frames = np.array([[t, d, np.cross(t, d)] for t, d in zip(np.asarray(network.tangents, float),
                                                                np.asarray(network.directors, float))])
    J = np.asarray(network.attach)
    relative = np.einsum("nij,nkj->nik", frames, frames[J])  # each node's frame in its mother's: kept at junctions

    def step(u, v, kind, k):
        if kind == "ahead":
            chord, R = rest_segment(frames[u, 0], frames[u, 1], kappa[k], lengths[k])
            frames[v] = frames[u] @ R.T
            positions[v] = positions[u] + chord
        elif kind == "back":
            R = rest_segment(frames[u, 0], frames[u, 1], kappa[k], lengths[k])[1]  # Ω is the same at both ends
            frames[v] = frames[u] @ R
            positions[v] = positions[u] - rest_segment(frames[v, 0], frames[v, 1], kappa[k], lengths[k])[0]
        else:
            positions[v] = positions[u]
            frames[v] = relative[k] @ frames[u] if kind == "daughter" else relative[k].T @ frames[u]

    _walk(network, step)
    check_rest_frames(positions, frames[:, 0], frames[:, 1], np.asarray(network.segments), lengths, kappa)
    return positions, frames[:, 0], frames[:, 1]


def with_natural_curvature(network: Network, natural_curvature) -> Network:
    """``network`` with per-segment ``natural_curvature`` and the stress-free shape that
    goes with it.

    2D: [S] (1/µm, or a scalar; positive turns counter-clockwise), each segment a circular
    arc.  3D (a twisting network, built with ``GJ=``): [S, 3] (or [3]) the natural curvature
    and twist (κ₁, κ₂, τ₀) on the material frame (d1, d2, t) (1/µm), each segment a piece of
    helix (an arc for τ₀ = 0); the reference material directors are carried along.

    Topology, supports, probe direction, loads, couples, EI and GJ are unchanged; each
    connected piece keeps the position and frame of one anchor node (its first clamped
    node, else its first probe node, else its first position-supported node, else its first
    node) and every other node moves to where the segments place it: a supported node's
    prescribed position is its new reference position.  Junction angles (3D: the daughter's
    frame in the mother's) are kept.  ``ValueError`` for a segment that turns by half a
    circle or more, or for a torsion-free 3D network.
    """
    check_curvable(network, "with_natural_curvature")
    if is_traced(natural_curvature):
        raise TypeError("natural_curvature sets the reference shape here and must be concrete; to differentiate with "
                        "respect to it, build the shape once and then use network.replace(natural_curvature=...)")
    shape = (network.n_segments,) if network.dim == 2 else (network.n_segments, 3)
    kappa = np.array(np.broadcast_to(check_array("natural_curvature", natural_curvature, "1/µm"), shape), float)
    positions, tangents, directors = (_place_2d if network.dim == 2 else _place_3d)(network, kappa)
    return Network(positions=positions, tangents=tangents, lengths=network.lengths, EI=network.EI, loads=network.loads,
                   couples=network.couples, natural_curvature=kappa, GJ=network.GJ, directors=directors,
                   topology=network.topology)


def arc(n_nodes: int, *, radius: float, angle: float, EI=0.071, GJ=None, dim: int = 3) -> Network:
    """A naturally curved filament, stress-free as built: a circular arc of ``radius`` (µm)
    turning by ``angle`` (degrees, positive) that starts at the origin along +x and curves
    toward +y in the x–y plane; node 0 clamped, the last node free; equal segments of natural
    curvature 1/radius.  ``EI`` (pN·µm², default actin's 0.071) scalar or per segment.

    ``dim=3`` (default) builds a Kirchhoff rod with twist, ``GJ`` (pN·µm²) defaulting to
    actin's 8e-3 (Tsuda et al. 1996); its material frame at rest is the arc's (no natural
    twist).  ``dim=2``: a planar arc (``GJ`` unused).  Each segment must turn by less than
    180° (``ValueError`` otherwise: use more nodes)."""
    dim = check_dim(dim)
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    R = check_real("radius", radius, "µm", low=0.0)
    phi = check_real("angle", angle, "degrees", low=0.0)
    if phi / (n - 1) >= 180.0:
        raise ValueError(f"angle = {angle!r}° over {n - 1} segments turns each by {phi / (n - 1):.4g}°; a segment turns "
                         f"by less than 180°: use n_nodes > {int(phi // 180) + 1}")
    if dim == 2:
        return with_natural_curvature(cantilever(n, length=R * np.radians(phi), EI=EI, dim=2), 1.0 / R)
    straight = cantilever(n, length=R * np.radians(phi), EI=EI, dim=3, GJ=ACTIN_GJ if GJ is None else GJ)
    return with_natural_curvature(straight, _components(straight, 0, np.array([0.0, 0.0, 1.0 / R])))


def _components(network: Network, node: int, darboux) -> np.ndarray:
    """(κ₁, κ₂, τ₀): a world Darboux vector on the reference material frame of ``node``."""
    t, d1 = np.asarray(network.tangents[node], float), np.asarray(network.directors[node], float)
    return np.array([darboux @ d1, darboux @ np.cross(t, d1), darboux @ t])


def helix(n_nodes: int, *, radius: float, pitch: float, turns: float, EI=0.071, GJ=None) -> Network:
    """A naturally helical filament, stress-free as built (3D, a Kirchhoff rod with twist):
    the helix of ``radius`` and ``pitch`` (µm per turn, positive: right-handed) about an axis
    parallel to +z, ``turns`` turns long, starting at the origin; node 0 clamped, the last
    node free, equal segments.  Its material frame at rest is the Frenet frame carried from
    node 0, so each segment has the helix's curvature R/(R² + c²) and twist c/(R² + c²)
    (c = pitch/2π).  ``GJ`` defaults to actin's 8e-3 pN·µm², ``EI`` to 0.071."""
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    R = check_real("radius", radius, "µm", low=0.0)
    c = check_real("pitch", pitch, "µm") / (2 * np.pi)
    N = check_real("turns", turns, "turns", low=0.0)
    speed = np.hypot(R, c)
    length = 2 * np.pi * N * speed
    t0 = np.array([0.0, R, c]) / speed
    binormal = np.cross(t0, [-1.0, 0.0, 0.0])  # the principal normal points to the axis (−x from the start)
    darboux = (c * t0 + R * binormal) / speed**2  # τ t + κ B
    if R / speed**2 * length / (n - 1) >= np.pi:
        raise ValueError(f"turns = {turns!r} over {n - 1} segments bends each by 180° or more: use more nodes")
    straight = cantilever(n, length=length, EI=EI, dim=3, direction=t0, GJ=ACTIN_GJ if GJ is None else GJ)
    return with_natural_curvature(straight, _components(straight, 0, darboux))


def crimped_fibre(n_nodes: int, *, length: float, wavelength: float, crimp_angle: float, EI=0.071,
                  supports=("clamped", "free"), dim: int = 2) -> Network:
    """A crimped (wavy) fibre, stress-free as built: the sine-generated curve whose tangent
    angle is θ(s) = crimp_angle · sin(2π s / wavelength) along the contour s ∈ [0, length]
    (µm), starting at the origin with mean direction +x (the shape of crimped collagen and of
    meanders).  Segment k is the arc that turns from θ(s_k) to θ(s_{k+1}), so the node
    tangents are the curve's own; with a whole number of wavelengths and of segments per
    half wavelength the last node lies on the x axis.

    ``crimp_angle`` in degrees (0 < crimp_angle < 90), ``wavelength`` the contour length of
    one period (µm); ``supports`` as for :func:`socbjax.column` (the supported directions
    keep their orientation: a "pinned" last node slides along x).  Planar only: ``dim=3``
    raises ``NotImplementedError`` (give a twisting 3D network its (κ₁, κ₂, τ₀) per segment
    with :func:`socbjax.with_natural_curvature`)."""
    if check_dim(dim) == 3:
        raise NotImplementedError("crimped_fibre(dim=3): the 3D crimp is not built in; give a twisting 3D network its "
                                  "(κ₁, κ₂, τ₀) per segment with socbjax.with_natural_curvature")
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    L = check_real("length", length, "µm", low=0.0)
    lam = check_real("wavelength", wavelength, "µm", low=0.0)
    amp = check_real("crimp_angle", crimp_angle, "degrees", low=0.0)
    if amp >= 90.0:
        raise ValueError(f"crimp_angle must be below 90° (the fibre would fold back), got {crimp_angle!r}")
    s = np.linspace(0.0, L, n)
    theta = np.radians(amp) * np.sin(2 * np.pi * s / lam)
    straight = column(n, length=L, EI=EI, supports=supports, dim=2)  # node 0 (the anchor) keeps θ(0) = 0
    return with_natural_curvature(straight, np.diff(theta) / np.diff(s))
