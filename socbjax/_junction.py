"""Arp2/3 branch junctions: validation of (mother, daughter) pairs and the junction
conditions of the SOCB residual (docs/equations.md §Branch junctions).

A junction ties a daughter's base node to a node of its mother strand:

* kinematics — the daughter base sits at the mother node (a position row of the residual,
  :func:`socbjax._residual.support_rows`) and its tangent keeps the reference branch angle
  relative to the mother's current tangent (:func:`director_targets`: 2D a fixed angle
  offset; 3D the minimal rotation that carries the reference mother tangent to the current
  one, applied to the reference daughter tangent);
* forces — the daughter's segment-end force enters the mother node's force balance
  (``socbjax._residual.routed_nodal_force``);
* moments — the daughter's base moment is handed to the mother (:func:`moment_transfer`):
  subtracted from the start moment of the mother segment that leaves the junction, or, where
  none leaves, from the mother node's end-moment equation.  In 3D the component along the
  mother tangent (a twist, which the torsion-free rod cannot carry) is dropped; a twisting
  network (built with ``GJ=``) keeps it and fixes the daughter's whole frame in the mother's
  material frame instead (:mod:`socbjax._twist`).

Nodal couples (external, fixed-direction "dead" end moments, pN·µm) enter the same way as a
daughter's moment (:func:`nodal_couple_transfer`): the internal moment jumps by −C across a
node carrying the couple C, so the segment leaving the node starts with m − C and at a node
where no segment leaves the end-moment equation becomes m = C.  In 3D the torsion-free rod
carries the bending part of C exactly; a twisting component (C·t ≠ 0 at equilibrium) has no
torsional stiffness to act on there, and acts on GJ in a twisting network.

Host-side functions take and return numpy arrays (topology is concrete); the traced ones take
the network and the current state.  Units: pN·µm for moments.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import GEOMETRY_RTOL, MIN_BRANCH_ANGLE, check_index_array
from ._geometry import minimal_rotation

__all__ = ["check_junction_geometry", "check_junctions", "director_targets", "moment_transfer", "nodal_couple_transfer", "transfer_segments"]


def check_junctions(attach_pairs, n: int, degree, n_end, n_start, clamped, fixed_any, probe) -> np.ndarray:
    """Validate (mother, daughter) pairs [J, 2] (host side); returns ``attach`` [N] (the
    mother node of each daughter base node, the node itself otherwise)."""
    attach = np.arange(n)
    pairs = np.zeros((0, 2), np.int64) if attach_pairs is None else check_index_array("attach", attach_pairs, n)
    if pairs.shape == (2,):  # a single (mother, daughter) pair
        pairs = pairs[None]
    if pairs.size == 0:
        pairs = pairs.reshape(0, 2)
    if pairs.ndim != 2 or pairs.shape[1] != 2:
        raise ValueError(f"attach must be (mother node, daughter base node) pairs, shape [J, 2], got shape {pairs.shape}")
    if len(np.unique(pairs[:, 1])) != len(pairs):
        raise ValueError("duplicate junction: a daughter base node is attached more than once")
    for mother, daughter in pairs:
        if mother == daughter:
            raise ValueError(f"junction ({mother}, {daughter}) attaches a node to itself")
        if degree[daughter] != 1 or n_start[daughter] != 1:
            raise ValueError(
                f"daughter base node {daughter} must start exactly one segment (the daughter's first) "
                f"and end none; it has {n_start[daughter]} starting and {n_end[daughter]} ending"
            )
        if clamped[daughter] or fixed_any[daughter] or probe[daughter]:
            raise ValueError(f"daughter base node {daughter} is tied to its mother node; it cannot also be supported")
        if n_end[mother] > 1 or n_start[mother] > 1:
            raise ValueError(
                f"mother node {mother} must lie on one strand (at most one segment ending and one starting there)"
            )
        attach[daughter] = mother
    if np.any(attach[attach] != attach):
        raise ValueError("a daughter base node cannot itself be the mother node of a junction; branch from the strand")
    return attach


def check_junction_geometry(attach: np.ndarray, positions, tangents, lengths) -> None:
    """Concrete reference geometry of the junctions (skipped where traced): every daughter
    base sits at its mother node (to ``GEOMETRY_RTOL`` of the shortest segment, plus
    round-off) and the daughter's tangent makes an angle of [MIN_BRANCH_ANGLE,
    180° − MIN_BRANCH_ANGLE] with the mother's: a daughter (nearly) parallel or antiparallel
    to its mother overlaps it and the junction has no well-defined azimuth."""
    daughters = np.flatnonzero(attach != np.arange(len(attach)))
    if not daughters.size:
        return
    mothers = attach[daughters]
    if positions is not None:
        scale = GEOMETRY_RTOL * (1.0 if lengths is None else float(np.min(lengths)))
        tol = scale + 64 * np.finfo(np.float64).eps * max(float(np.max(np.abs(positions))), 1.0)
        gap = np.linalg.norm(positions[daughters] - positions[mothers], axis=1)
        if np.any(gap > tol):
            k = int(np.argmax(gap > tol))
            raise ValueError(f"positions: the daughter base node {daughters[k]} of attach ({mothers[k]}, {daughters[k]}) is "
                             f"{gap[k]:.6g} µm from its mother node; in the reference state a daughter starts at its "
                             "mother node: give both the same position")
    if tangents is not None:
        a, b = tangents[daughters], tangents[mothers]
        cross = np.linalg.norm(a[:, :, None] * b[:, None, :] - b[:, :, None] * a[:, None, :], axis=(1, 2)) / np.sqrt(2)
        angle = np.degrees(np.arctan2(cross, np.sum(a * b, axis=1)))  # accurate near 0° and 180°, unlike arccos
        slack = 1e-9  # degrees: the limits themselves (e.g. a builder's 0.1°) pass despite round-off
        bad = (angle < MIN_BRANCH_ANGLE - slack) | (angle > 180.0 - MIN_BRANCH_ANGLE + slack)
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(
                f"attach ({mothers[k]}, {daughters[k]}): the daughter's tangent (tangents[{daughters[k]}]) is at "
                f"{angle[k]:.6g}° to the mother's (tangents[{mothers[k]}]); "
                f"branch angles must lie in [{MIN_BRANCH_ANGLE:g}°, {180 - MIN_BRANCH_ANGLE:g}°] (a daughter parallel or "
                "antiparallel to its mother overlaps it)")


def transfer_segments(attach: np.ndarray, segments: np.ndarray, n_start: np.ndarray) -> np.ndarray:
    """[N]: for a daughter base node the mother segment that starts at its mother node (whose
    start moment takes the daughter's moment), S where none starts there; S for other nodes."""
    s = len(segments)
    start_of = np.full(len(attach), s)
    start_of[segments[:, 0]] = np.arange(s)
    transfer = np.full(len(attach), s)
    daughters = np.flatnonzero(attach != np.arange(len(attach)))
    mothers = attach[daughters]
    transfer[daughters] = np.where(n_start[mothers] == 1, start_of[mothers], s)
    return transfer


def _unit(v):
    return v / jnp.linalg.norm(v, axis=-1, keepdims=True)


def director_targets(directors, network):
    """Prescribed directors [N] (2D angles) or [N, 3]: the reference one at clamps; at a
    daughter base the reference daughter direction carried along with the mother's current
    tangent (2D: fixed angle offset; 3D: minimal rotation of the reference pair)."""
    attached = jnp.asarray(network.attached)
    J = network.attach
    if network.dim == 2:
        ref = jnp.arctan2(network.tangents[:, 1], network.tangents[:, 0])
        offset = jnp.arctan2(jnp.sin(ref - ref[J]), jnp.cos(ref - ref[J]))
        return jnp.where(attached, directors[J] + offset, ref)
    carried = minimal_rotation(network.tangents[J], _unit(directors[J]), network.tangents)
    return jnp.where(attached[:, None], carried, network.tangents)


def _perpendicular(m, directors, nodes, dim):
    """3D: m minus its component along the unit tangent at ``nodes`` (the twist)."""
    if dim == 2:
        return m
    t = _unit(directors[nodes])
    return m - jnp.sum(m * t, -1, keepdims=True) * t


def _split_transfer(m, network, targets_segment, targets_node):
    """Scatter per-node moments ``m`` to (segments [S(,3)], nodes [N(,3)])."""
    n_seg = network.n_segments
    to_segment = jax.ops.segment_sum(m, targets_segment, num_segments=n_seg + 1)[:n_seg]
    at_end = (targets_segment == n_seg).reshape((-1,) + (1,) * (m.ndim - 1))
    to_node = jax.ops.segment_sum(jnp.where(at_end, m, 0.0), targets_node, num_segments=network.n_nodes)
    return to_segment, to_node


def moment_transfer(state, network):
    """Daughter base moments handed to the mother (Σ end moments = 0 at a junction).

    Returns (per segment [S] / [S, 3]: subtracted from the start moment of the mother segment
    that leaves the junction; per node: subtracted in the end-moment equation of a mother
    node where no segment leaves).  In 3D the twist component along the mother tangent is
    dropped by the torsion-free rod and kept by a twisting network."""
    J = network.attach
    # the torsion-free rod drops the twist; with twist the mother carries the whole moment
    m = state.moments if network.twisting else _perpendicular(state.moments, state.directors, J, network.dim)
    attached = jnp.asarray(network.attached).reshape((-1,) + (1,) * (m.ndim - 1))
    return _split_transfer(jnp.where(attached, m, 0.0), network, network.transfer_segment, J)


def nodal_couple_transfer(couples, network):
    """External nodal couples C (2D [N], 3D [N, 3], pN·µm) as moment jumps: (per segment, the
    amount subtracted from the start moment of the segment leaving each node; per node, the
    amount subtracted in the end-moment equation where no segment leaves)."""
    return _split_transfer(couples, network, network.leaving_segment, np.arange(network.n_nodes))
