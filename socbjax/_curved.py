"""Naturally curved filaments: :func:`with_natural_curvature` (the builders :func:`arc`,
:func:`helix` and :func:`crimped_fibre` are in :mod:`socbjax._builders`).

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

from ._checks import check_array, describe
from ._network import Network, is_traced
from ._network_checks import check_natural_curvature, check_reference_state, check_rest_frames, rest_segment

__all__ = ["ACTIN_GJ", "check_curvable", "with_natural_curvature"]

ACTIN_GJ = 8e-3  # pN·µm²: actin's torsional rigidity 8e-27 N·m² (Tsuda et al., PNAS 93, 12937, 1996)


def check_curvable(network: Network, what: str) -> None:
    """Refuses what :func:`with_natural_curvature` cannot reshape: not a network, padded,
    traced geometry."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network, got {describe(network)}")
    if network.padding is not None:
        raise ValueError(f"{what}: the network is padded (pad_outcrop), and its inert pieces must stay straight; give "
                         "the unpadded network its shape first, then pad it (pad_outcrop keeps the shape)")
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
