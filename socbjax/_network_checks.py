"""Validation of :func:`socbjax.make_network`'s inputs (host side, before anything is traced).

Topology arguments (segments, supports, junctions, probe, strand ids) must be concrete;
values (positions, tangents, lengths, EI, loads, couples, natural curvature) may be JAX
tracers, and the checks that need them are then skipped.  With concrete values the
reference state must be the stress-free state of every strand (straight, or with 2D natural
curvature a chain of circular arcs), to the relative tolerance
``socbjax._checks.GEOMETRY_RTOL`` (1e-6, plus the round-off of the node coordinates):

* tangents are unit vectors to 1e-3 (``UNIT_TANGENT_TOLERANCE``; they are then normalised
  exactly, so hand-typed directions with four decimals are accepted);
* every segment's chord is non-zero, its length equals the chord and the tangents at both
  its nodes point along the chord (segments run from their first to their second node);
  with natural curvature κ₀ the chord is 2 sin(κ₀l/2)/κ₀ and the end tangents lie at ∓κ₀l/2
  from it (|κ₀l| < π);
* segments and junctions form no closed loop (a network is a forest of open strands), every
  node lies on one or two segments, and at most one segment starts and one ends at a node;
* index arrays (segments, attach, probe, strand) hold integers: booleans and floats are
  refused (``TypeError``), never truncated; out-of-range values (e.g. 2**33) are a
  ``ValueError`` naming the argument.

Units: µm, pN, pN·µm², degrees for angles.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ._checks import (
    GEOMETRY_RTOL,
    MAX_INT32,
    check_array,
    check_index_array,
    check_positive_array,
    describe,
    is_traced,
)

__all__ = [
    "check_degrees",
    "check_loops",
    "check_natural_curvature",
    "check_rest_frames",
    "default_directors",
    "reference_directors",
    "rest_segment",
    "check_reference_state",
    "check_segments",
    "check_supported",
    "concrete_structure",
    "network_value",
    "node_flags",
    "probe_mask",
    "projectors",
    "strand_ids",
    "unit_tangents",
]

UNIT_TANGENT_TOLERANCE = 1e-3  # |t| − 1 allowed before refusing; accepted tangents are normalised

_EPS = np.finfo(np.float64).eps


def concrete_structure(name: str, value):
    """``value``; a traced JAX value is refused: it would fix the compiled program."""
    if is_traced(value):
        raise TypeError(
            f"{name} fixes the network's topology and must be concrete (numpy or Python values), not a traced JAX "
            "value: build the structure outside jax.jit/grad/vmap; only the values positions, tangents, lengths, EI, "
            "loads, couples and natural_curvature may be traced"
        )
    return value


def network_value(name: str, value, shape: tuple, unit: str, *, positive: bool = False):
    """(array of ``shape``, concrete numpy copy or None when traced); scalars broadcast.

    Concrete values stay numpy arrays in the network: inside ``jax.jit`` even
    ``jnp.asarray`` of a constant is a tracer, and the host-side logic that needs concrete
    geometry (probe placement, input checks) must still see it."""
    if value is None:
        return np.zeros(shape), np.zeros(shape)
    arr = (check_positive_array if positive else check_array)(name, value, unit)
    if is_traced(arr):
        if arr.ndim == 0 or (arr.ndim == 1 and len(shape) == 1 and arr.shape == (1,)):
            arr = jnp.broadcast_to(arr, shape)
        if arr.shape != shape:
            raise ValueError(f"{name} must have shape {shape} ({unit}), got {arr.shape}")
        return arr, None
    if arr.ndim == 0:
        arr = np.broadcast_to(arr, shape)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape} ({unit}), got {arr.shape}")
    arr = np.array(arr, copy=True)
    return arr, arr


def check_segments(segments, n: int) -> np.ndarray:
    """[S, 2] int32 (start, end) node indices: distinct nodes, no duplicate segment."""
    seg = check_index_array("segments", concrete_structure("segments", segments), n)
    if seg.size == 0 or seg.ndim != 2 or seg.shape[1] != 2:
        raise ValueError(f"segments must have shape [S, 2] with S >= 1 (pairs of node indices), got shape {seg.shape}")
    same = seg[:, 0] == seg[:, 1]
    if same.any():
        k = int(np.argmax(same))
        raise ValueError(f"segment {k} joins node {seg[k, 0]} to itself; each segment needs two distinct nodes")
    pairs = np.sort(seg, axis=1)
    if len(np.unique(pairs, axis=0)) != len(pairs):
        raise ValueError("two segments join the same pair of nodes (duplicate segment)")
    return seg.astype(np.int32)


def unit_tangents(tangents: np.ndarray) -> np.ndarray:
    """Concrete tangents [N, d] checked to be unit vectors within ``UNIT_TANGENT_TOLERANCE``
    (1e-3: hand-typed directions such as (0.7071, 0.7071) are accepted); those off by more
    than round-off are normalised (the others are returned bit for bit)."""
    norm = np.linalg.norm(tangents, axis=1)
    zero = norm < 1e-12
    if zero.any():
        i = int(np.argmax(zero))
        raise ValueError(f"tangents[{i}] is the zero vector {tangents[i].tolist()}; every node needs the unit tangent "
                         "of its segment(s) (the direction from the segment's first node to its second)")
    off = np.abs(norm - 1.0) > UNIT_TANGENT_TOLERANCE
    if off.any():
        i = int(np.argmax(off))
        raise ValueError(f"tangents[{i}] has length {norm[i]:.9g}, not 1: tangents must be unit vectors (to "
                         f"{UNIT_TANGENT_TOLERANCE:g}); normalise them, e.g. t / np.linalg.norm(t, axis=1, keepdims=True)")
    rounding = np.abs(norm - 1.0) > 4 * _EPS
    return np.where(rounding[:, None], tangents / norm[:, None], tangents)


def check_natural_curvature(kappa, lengths, dim: int, twisting: bool = False):
    """The turn κ₀l [S] (rad) of each segment at rest (2D), or None when it is traced;
    refuses 3D curvature without twist (the torsion-free rod has no material frame to hold
    it) and turns of half a circle or more per segment."""
    if kappa is None:
        return None
    if dim == 3:
        if np.any(kappa != 0) and not twisting:
            k = int(np.argmax(np.any(kappa != 0, axis=1)))
            raise ValueError(f"natural_curvature[{k}] = {kappa[k].tolist()} 1/µm: a naturally curved or twisted 3D "
                             "filament needs its torsional stiffness: pass GJ= (e.g. actin's 8e-3 pN·µm²)")
        bent = None if lengths is None else np.linalg.norm(kappa[:, :2], axis=1) * lengths
        if bent is not None and np.any(bent >= np.pi):
            k = int(np.argmax(bent >= np.pi))
            raise ValueError(f"natural_curvature[{k}] = {kappa[k].tolist()} 1/µm bends segment {k} by "
                             f"{np.degrees(bent[k]):.4g}° at rest; a segment turns by less than 180°: use more, shorter "
                             "segments")
        return np.zeros(len(kappa))
    if lengths is None:
        return None if np.any(kappa != 0) else np.zeros(len(kappa))
    turn = kappa * lengths
    bad = np.abs(turn) >= np.pi
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"natural_curvature[{k}] = {kappa[k]:.6g} 1/µm turns segment {k} (length {lengths[k]:.6g} µm) "
                         f"by {np.degrees(turn[k]):.4g}° at rest; a segment turns by less than 180°: use more, shorter "
                         "segments")
    return turn


def check_reference_state(positions, tangents, segments: np.ndarray, lengths, turn=None) -> None:
    """The stress-free reference state, for whichever of ``positions``, ``tangents`` [N, d]
    and ``lengths`` [S] are concrete (None: traced, skipped).  ``turn`` [S] (rad): each
    segment's turn κ₀l at rest (2D natural curvature; zeros: straight); None when the natural
    curvature is traced, and then only the chords are checked for zero length."""
    if positions is None:
        return
    vec = positions[segments[:, 1]] - positions[segments[:, 0]]
    chord = np.linalg.norm(vec, axis=1)
    roundoff = 64 * _EPS * max(float(np.max(np.abs(positions))), 1.0)  # coordinate round-off (µm)
    floor = np.maximum(1e-9 * np.maximum(chord if lengths is None else lengths, 1.0), roundoff)
    coincident = chord <= floor
    if coincident.any():
        k = int(np.argmax(coincident))
        raise ValueError(f"positions of segment {k}'s end nodes {segments[k].tolist()} coincide at "
                         f"{positions[segments[k, 0]].tolist()} (a zero-length segment); move, merge or remove them")
    if turn is None:
        return
    if lengths is not None:
        expected = lengths * np.sinc(turn / (2 * np.pi))  # 2 sin(κ₀l/2)/κ₀ = l sinc(κ₀l/2)
        off = np.abs(chord - expected) > GEOMETRY_RTOL * lengths + roundoff
        if off.any():
            k = int(np.argmax(off))
            shape = "straight" if turn[k] == 0 else f"an arc turning by {np.degrees(turn[k]):.6g}° (natural curvature)"
            raise ValueError(
                f"lengths[{k}] = {lengths[k]:.9g} µm does not fit the distance {chord[k]:.9g} µm between its nodes "
                f"{segments[k].tolist()}: the reference state must be stress-free, so segment {k}, {shape}, must have "
                f"a chord of {expected[k]:.9g} µm (relative tolerance {GEOMETRY_RTOL:g})")
    if tangents is not None:
        _check_tangents_along_chords(tangents, segments, vec / chord[:, None], GEOMETRY_RTOL + roundoff / chord, turn)


def _rotated(v, angle):
    """2D vectors [S, 2] rotated by ``angle`` [S] (rad)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)


def _check_tangents_along_chords(tangents, segments, unit_chord, tol, turn) -> None:
    curved = np.any(turn != 0)
    for end in (0, 1):
        nodes = segments[:, end]
        expected = _rotated(unit_chord, (end - 0.5) * turn) if curved else unit_chord
        err = np.linalg.norm(tangents[nodes] - expected, axis=1)
        bad = err > tol
        if bad.any():
            k = int(np.argmax(bad))
            i = int(nodes[k])
            angle = np.degrees(np.arccos(np.clip(tangents[i] @ expected[k], -1.0, 1.0)))
            if curved:
                raise ValueError(
                    f"tangents[{i}] = {np.round(tangents[i], 9).tolist()} is at {angle:.6g}° to the stress-free "
                    f"tangent {np.round(expected[k], 9).tolist()} of segment {k} (nodes {segments[k].tolist()}, an arc "
                    f"turning by {np.degrees(turn[k]):.6g}°): at rest the end tangents lie at ∓half the turn from the "
                    "chord")
            raise ValueError(
                f"tangents[{i}] = {np.round(tangents[i], 9).tolist()} is at {angle:.6g}° to segment {k}'s chord "
                f"(nodes {segments[k].tolist()}, direction {np.round(unit_chord[k], 9).tolist()}): in the straight, "
                "stress-free reference state the tangents at both ends of a segment point along its chord, from its "
                "first node to its second")


def check_degrees(segments: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """[N] numbers of segments starting and ending at each node: every node on one or two
    segments, and strands run base to tip (at most one segment starts and one ends at a node)."""
    n_start, n_end = np.bincount(segments[:, 0], minlength=n), np.bincount(segments[:, 1], minlength=n)
    degree = n_start + n_end
    if np.any(degree == 0):
        raise ValueError(f"node {int(np.argmax(degree == 0))} belongs to no segment; remove it (segments must use "
                         "every node)")
    if np.any(degree > 2):
        raise ValueError(f"node {int(np.argmax(degree > 2))} is shared by more than two segments; join filaments with "
                         "branch junctions (attach=[(mother, daughter_base), ...]) instead")
    for count, what in ((n_start, "start"), (n_end, "end")):
        bad = count > 1
        if bad.any():
            raise ValueError(f"segments: {int(count.max())} segments {what} at node {int(np.argmax(bad))}; segments run "
                             "along their strand from base to tip (each node starts and ends at most one): reverse one")
    return n_start, n_end


def node_flags(name: str, value, n: int) -> np.ndarray:
    """[N] bool flags (True/False, or integers 0/1) or all False for None."""
    if value is None:
        return np.zeros(n, bool)
    arr = np.asarray(concrete_structure(name, value))
    if arr.shape != (n,):
        raise ValueError(f"{name} must have one entry per node ({n}), got shape {arr.shape}")
    if arr.dtype.kind == "b":
        return arr.astype(bool)
    if arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must hold booleans (one per node), got dtype {arr.dtype}: {describe(value)}")
    if not np.all((arr == 0) | (arr == 1)):
        raise ValueError(f"{name} must hold booleans or 0/1 (one per node), got {describe(value)}")
    return arr.astype(bool)


def strand_ids(strand, s: int) -> np.ndarray:
    """[S] int32 strand ids (non-negative integers); all 0 for None."""
    if strand is None:
        return np.zeros(s, np.int32)
    arr = check_index_array("strand", concrete_structure("strand", strand), MAX_INT32 + 1, what="strand id")
    if arr.shape != (s,):
        raise ValueError(f"strand must have one id per segment ({s}), got shape {arr.shape}")
    return arr.astype(np.int32)


def projectors(fixed_directions, n: int, dim: int) -> np.ndarray:
    """[N, d, d] orthogonal projectors onto the span of each node's fixed directions."""
    projector = np.zeros((n, dim, dim))
    if fixed_directions is None:
        return projector
    concrete_structure("fixed_directions", fixed_directions)
    if isinstance(fixed_directions, (str, bytes)) or not hasattr(fixed_directions, "__len__"):
        raise TypeError(f"fixed_directions must be a list with one array [k, {dim}] per node, got "
                        f"{describe(fixed_directions)}")
    if len(fixed_directions) != n:
        raise ValueError(f"fixed_directions needs one entry per node ({n}), got {len(fixed_directions)}")
    for i, dirs in enumerate(fixed_directions):
        projector[i] = _projector(f"fixed_directions[{i}]", dirs, dim)
    return projector


def _projector(name: str, dirs, dim: int) -> np.ndarray:
    if isinstance(dirs, np.ndarray) and dirs.size == 0 and dirs.dtype.kind in "iuf":  # a free node (fast path)
        return np.zeros((dim, dim))
    dirs = check_array(name, dirs, "direction vectors")
    if dirs.size == 0:
        return np.zeros((dim, dim))
    dirs = dirs[None] if dirs.ndim == 1 else dirs
    if dirs.ndim != 2 or dirs.shape[1] != dim:
        raise ValueError(f"{name} must be an array [k, {dim}] of directions (k = 0 free, np.eye({dim}) fixed), got "
                         f"shape {dirs.shape}")
    norms = np.linalg.norm(dirs, axis=1)
    if np.any(norms < 1e-12):
        raise ValueError(f"{name} row {int(np.argmax(norms < 1e-12))} is the zero vector, which is no direction; "
                         f"give non-zero directions (np.zeros((0, {dim})) for a free node)")
    q, r = np.linalg.qr(dirs.T)
    if len(dirs) > dim or np.any(np.abs(np.diag(r)) <= 1e-9 * norms.max()):
        # linearly dependent rows: their span (the QR basis would add spurious directions)
        u, sv, _ = np.linalg.svd((dirs / norms[:, None]).T)
        q = u[:, : int(np.sum(sv > 1e-9))]
    return q @ q.T


def probe_mask(probe, n: int) -> np.ndarray:
    """[N] bool: the probe nodes (indices, negative ones counted from the end)."""
    mask = np.zeros(n, bool)
    if probe is None:
        return mask
    mask[check_index_array("probe", concrete_structure("probe", probe), n, allow_negative=True).ravel()] = True
    return mask


def check_loops(n: int, segments: np.ndarray, attach: np.ndarray) -> np.ndarray:
    """[N] root node of each node's connected piece (segments and junctions); a segment or
    junction that joins two nodes already connected closes a loop and is refused."""
    parent = np.arange(n)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    edges = [(f"segments[{k}]", a, b) for k, (a, b) in enumerate(segments.tolist())]
    edges += [(f"the junction attach ({attach[i]}, {i})", int(attach[i]), int(i))
              for i in np.flatnonzero(attach != np.arange(n))]
    for what, a, b in edges:
        ra, rb = find(a), find(b)
        if ra == rb:
            raise ValueError(f"{what} closes a loop (nodes {a} and {b} are already connected through other segments "
                             "or junctions); filament networks are trees of open strands: remove a segment or junction")
        parent[ra] = rb
    return np.array([find(i) for i in range(n)])


def check_supported(roots: np.ndarray, clamped, projector, dim) -> None:
    """Every connected piece (nodes sharing a root of :func:`check_loops`) held against
    rigid-body motion: one clamped fixed node, or enough pinned ones."""
    rank = np.einsum("nii->n", projector).round().astype(int)
    for root in np.unique(roots):
        members = roots == root
        held = np.any(clamped[members] & (rank[members] >= dim)) or (
            np.sum(rank[members] > 0) >= 2 and np.sum(np.minimum(rank[members], dim)) >= dim + 1
        )
        if not held:
            nodes = np.flatnonzero(members)
            raise ValueError(
                f"the piece of the network with nodes {nodes[:8].tolist()}{'...' if len(nodes) > 8 else ''} is not held "
                "against rigid-body motion; clamp one of its nodes or pin at least two"
            )


def default_directors(tangents: np.ndarray) -> np.ndarray:
    """[N, 3] the default reference directors of unit ``tangents`` (numpy, no JAX work):
    ``orthonormal_complement(t)[0]``, the coordinate axis least aligned with t made ⊥ t."""
    axis = np.eye(3)[np.argmin(np.abs(tangents), axis=1)]
    f = axis - np.sum(axis * tangents, axis=1, keepdims=True) * tangents
    return f / np.linalg.norm(f, axis=1, keepdims=True)


def reference_directors(directors, tangents, tan_np, n: int, dim: int):
    """(directors [N, d], concrete copy or None): 3D reference material directors, unit and
    ⊥ the tangents (default ``orthonormal_complement(tangent)[0]``); 2D zeros."""
    if dim == 2:
        if directors is not None:
            raise ValueError("directors: planar filaments have no material director (they do not twist); leave it None")
        return np.zeros((n, 2)), None
    if directors is None:
        if tan_np is None:  # traced tangents: the same construction in JAX
            import jax  # noqa: PLC0415

            from ._geometry import orthonormal_complement  # noqa: PLC0415

            return jax.vmap(orthonormal_complement)(jnp.asarray(tangents))[:, 0], None
        value = default_directors(tan_np)
        return value, value
    arr, arr_np = network_value("directors", directors, (n, 3), "unit vectors")
    if arr_np is None or tan_np is None:
        return arr, None
    norm = np.linalg.norm(arr_np, axis=1)
    off = (np.abs(norm - 1.0) > UNIT_TANGENT_TOLERANCE) | (np.abs(np.sum(arr_np * tan_np, axis=1)) > 1e-6 * norm)
    if off.any():
        i = int(np.argmax(off))
        raise ValueError(f"directors[{i}] = {arr_np[i].tolist()} must be a unit vector ⊥ tangents[{i}] = "
                         f"{tan_np[i].tolist()} (the material director of the reference frame)")
    arr_np = arr_np / norm[:, None]
    return arr_np, arr_np


def rest_segment(t_a, d1_a, kappa, length):
    """(chord [3], R [3, 3]) of a segment at rest from its start frame (tangent t_a,
    director d1_a): the frame turns at the constant Darboux vector Ω = κ₁ d1 + κ₂ d2 + τ₀ t
    (the same from either end), so the end frame is R applied to the start frame and the
    segment is a piece of helix about Ω (numpy)."""
    d2_a = np.cross(t_a, d1_a)
    omega = kappa[0] * d1_a + kappa[1] * d2_a + kappa[2] * t_a
    rate = float(np.linalg.norm(omega))
    if rate * length < 1e-12:
        return length * t_a, np.eye(3)
    axis, angle = omega / rate, rate * length
    along = (t_a @ axis) * axis
    across = t_a - along
    chord = along * length + np.sin(angle) / rate * across + (1 - np.cos(angle)) / rate * np.cross(axis, across)
    K = np.cross(np.eye(3), axis)  # rows e_i × axis: the matrix of v ↦ axis × v
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)  # Rodrigues
    return chord, R


def check_rest_frames(positions, tangents, directors, segments: np.ndarray, lengths, kappa) -> None:
    """A twisting network's reference state is stress-free: every segment is the piece of
    helix of its (κ₁, κ₂, τ₀) from its start frame (tangent, director) to its end frame
    (skipped where a value is traced)."""
    if positions is None or tangents is None or directors is None or lengths is None or kappa is None:
        return
    roundoff = 64 * _EPS * max(float(np.max(np.abs(positions))), 1.0)
    for k, (a, b) in enumerate(segments):
        chord, R = rest_segment(tangents[a], directors[a], kappa[k], float(lengths[k]))
        t_b, d1_b = R @ tangents[a], R @ directors[a]
        gaps = (np.linalg.norm(positions[b] - positions[a] - chord) / lengths[k], np.linalg.norm(tangents[b] - t_b),
                np.linalg.norm(directors[b] - d1_b))
        if max(gaps) > GEOMETRY_RTOL + roundoff / lengths[k]:
            what = ("positions", "tangents", "directors")[int(np.argmax(gaps))]
            raise ValueError(
                f"{what} of segment {k} (nodes {[int(a), int(b)]}) do not fit its stress-free shape: from node {int(a)}'s "
                f"frame, length {lengths[k]:.6g} µm and natural curvature {np.round(kappa[k], 9).tolist()} 1/µm put node "
                f"{int(b)} at {np.round(positions[a] + chord, 9).tolist()} with tangent {np.round(t_b, 9).tolist()} and "
                f"director {np.round(d1_b, 9).tolist()} (relative tolerance {GEOMETRY_RTOL:g}); build curved networks "
                "with socbjax.with_natural_curvature")
