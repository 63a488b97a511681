"""Naturally curved filaments: :func:`with_natural_curvature`, :func:`arc`, :func:`crimped_fibre`.

A segment with natural curvature κ₀ (1/µm) is a circular arc at rest: it turns by τ = κ₀l
(rad) over its length l, its chord is l·sin(τ/2)/(τ/2) and its end tangents lie at ∓τ/2 from
the chord (the bending law m = EI (θ' − κ₀), ``docs/equations.md`` §"Natural curvature").
:func:`with_natural_curvature` gives any 2D network the stress-free shape of a new set of
curvatures: starting from one anchor node per connected piece (its position and tangent are
kept), it walks the segments and junctions and places every node where the arcs put it;
branch junctions keep their angle between mother and daughter, and every support keeps its
kind at the node's new position.  Host side (numpy), concrete values only: the shape fixes
the reference positions that supports prescribe.

3D filaments stay naturally straight in this version: a curved rod in space needs its
material frame and twist (not modelled yet), and the 3D builders say so.  Units: µm, pN,
pN·µm², degrees for angles.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ._builders import cantilever, column
from ._checks import check_array, check_dim, check_int, check_real, describe
from ._network import Network, is_traced
from ._network_checks import check_natural_curvature, check_reference_state

__all__ = ["arc", "check_curvable", "crimped_fibre", "with_natural_curvature"]

_TWIST_NEEDED = ("curved filaments in 3D need the twist and material frame of a Kirchhoff rod, which socbjax does "
                 "not model yet; build the filament in the plane with dim=2")


def check_curvable(network: Network, what: str) -> None:
    """Refuses what :func:`with_natural_curvature` cannot reshape: not a network, 3D, padded,
    traced geometry."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network, got {describe(network)}")
    if network.dim != 2:
        raise NotImplementedError(f"{what}: {_TWIST_NEEDED}")
    if network.padding is not None:
        raise ValueError(f"{what}: the network is padded (pad_outcrop); curve the outcrop first, then pad it")
    if any(is_traced(getattr(network, k)) for k in ("positions", "tangents", "lengths", "EI", "natural_curvature")):
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


def _neighbours(network: Network, turns: np.ndarray, chords: np.ndarray):
    """Per node, the moves to its neighbours: (other node, Δθ, chord length, chord angle
    relative to this node's tangent angle)."""
    moves = [[] for _ in range(network.n_nodes)]
    for k, (a, b) in enumerate(np.asarray(network.segments)):
        moves[a].append((b, turns[k], chords[k], 0.5 * turns[k]))
        moves[b].append((a, -turns[k], -chords[k], -0.5 * turns[k]))
    theta = np.arctan2(network.tangents[:, 1], network.tangents[:, 0])
    for i in np.flatnonzero(network.attached):
        J = int(network.attach[i])
        offset = np.arctan2(np.sin(theta[i] - theta[J]), np.cos(theta[i] - theta[J]))
        moves[J].append((i, offset, 0.0, 0.0))
        moves[i].append((J, -offset, 0.0, 0.0))
    return moves


def with_natural_curvature(network: Network, natural_curvature) -> Network:
    """The 2D ``network`` with per-segment ``natural_curvature`` [S] (1/µm, or a scalar;
    positive turns counter-clockwise) and the stress-free shape that goes with it.

    Topology, supports, probe direction, loads, couples and EI are unchanged; each connected
    piece keeps the position and tangent of one anchor node (its first clamped node, else
    its first probe node, else its first position-supported node, else its first node) and every
    other node moves to where the arcs place it: a supported node's prescribed position is
    its new reference position.  Junction angles are kept.  ``ValueError`` for a turn κ₀l of
    half a circle or more in one segment; ``NotImplementedError`` in 3D (see module).
    """
    check_curvable(network, "with_natural_curvature")
    if is_traced(natural_curvature):
        raise TypeError("natural_curvature sets the reference shape here and must be concrete; to differentiate with "
                        "respect to it, build the shape once and then use network.replace(natural_curvature=...)")
    kappa = np.broadcast_to(check_array("natural_curvature", natural_curvature, "1/µm"), (network.n_segments,))
    lengths = np.asarray(network.lengths, float)
    turns = check_natural_curvature(np.array(kappa, float), lengths, 2)
    moves = _neighbours(network, turns, lengths * np.sinc(turns / (2 * np.pi)))
    positions = np.array(network.positions, float)
    theta = np.arctan2(network.tangents[:, 1], network.tangents[:, 0])
    placed = np.zeros(network.n_nodes, bool)
    for anchor in _anchors(network):
        if placed[anchor]:
            continue
        placed[anchor] = True
        queue = deque([anchor])
        while queue:
            u = queue.popleft()
            for v, dtheta, chord, chord_angle in moves[u]:
                if placed[v]:
                    continue
                direction = theta[u] + chord_angle
                positions[v] = positions[u] + chord * np.array([np.cos(direction), np.sin(direction)])
                theta[v] = theta[u] + dtheta
                placed[v] = True
                queue.append(v)
    tangents = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    check_reference_state(positions, tangents, np.asarray(network.segments), lengths, turns)
    return Network(positions=positions, tangents=tangents, lengths=network.lengths, EI=network.EI, loads=network.loads,
                   couples=network.couples, natural_curvature=np.array(kappa, float), GJ=network.GJ,
                   topology=network.topology)


def _check_dim_2(dim, GJ, what: str) -> None:
    if check_dim(dim) == 3:
        raise NotImplementedError(f"{what}(dim=3): {_TWIST_NEEDED}")
    if GJ is not None:
        raise NotImplementedError(f"{what}: GJ (torsional stiffness) needs twist, which socbjax does not model yet; "
                                  "leave GJ=None (planar filaments do not twist)")


def arc(n_nodes: int, *, radius: float, angle: float, EI=0.071, GJ=None, dim: int = 3) -> Network:
    """A naturally curved filament, stress-free as built: a circular arc of ``radius`` (µm)
    turning by ``angle`` (degrees, positive) that starts at the origin along +x and curves
    toward +y in the x–y plane; node 0 clamped, the last node free; equal segments of natural
    curvature 1/radius.  ``EI`` (pN·µm², default actin's 0.071) scalar or per segment.

    Only ``dim=2`` is available in this version (``dim=3`` and ``GJ`` raise
    ``NotImplementedError``: a curved rod in space needs twist).  Each segment must turn by
    less than 180° (``ValueError`` otherwise: use more nodes)."""
    _check_dim_2(dim, GJ, "arc")
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    R = check_real("radius", radius, "µm", low=0.0)
    phi = check_real("angle", angle, "degrees", low=0.0)
    if phi / (n - 1) >= 180.0:
        raise ValueError(f"angle = {angle!r}° over {n - 1} segments turns each by {phi / (n - 1):.4g}°; a segment turns "
                         f"by less than 180°: use n_nodes > {int(phi // 180) + 1}")
    straight = cantilever(n, length=R * np.radians(phi), EI=EI, dim=2)
    return with_natural_curvature(straight, 1.0 / R)


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
    keep their orientation: a "pinned" last node slides along x).  ``dim=3`` raises
    ``NotImplementedError`` (see :func:`arc`)."""
    _check_dim_2(dim, None, "crimped_fibre")
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
