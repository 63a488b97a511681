"""The network data model: a static :class:`Topology` and one pytree of value arrays.

Units throughout socbjax: length µm, force pN, time s; bending stiffness EI in pN·µm²,
moments and couples in pN·µm.

A :class:`Network` is an ``eqx.Module`` whose array leaves are exactly the *values* a user
sweeps, fits or differentiates — reference ``positions`` and ``tangents``, segment
``lengths`` and ``EI``, nodal ``loads`` (forces) and ``couples`` — so a new value never
recompiles, ``jax.grad`` differentiates with respect to them and ``jax.vmap`` batches them.
Everything that fixes the compiled program lives in the static, hashable :class:`Topology`
(``Network.topology``): the segments, supports, junctions, probe and the static selection of
node equations.  ``jax.jit`` of a function of a network therefore traces only the values;
a network of another topology compiles anew.

Supports are encoded per node (all in the topology):

* ``position_projector[i]`` (d×d) is the orthogonal projector onto the directions in which
  node i's position is prescribed (identity: fixed, zero: free, I − a aᵀ: free only along a).
  The prescribed position is ``positions[i]`` (the reference position).
* ``clamped[i]``: the tangent at node i is fixed to ``tangents[i]``.
* ``moment_free[i]``: an end node whose bending moment is prescribed (zero, or the applied
  couple): a free or pinned end.
* ``probe[i]``: node held by the rigid probe; its prescribed position is
  ``positions[i] + u * probe_direction`` (u: probe displacement, µm).
* ``attach[i]``: for the base node of a daughter filament, the mother node it is attached to
  (an Arp2/3 branch junction, :mod:`socbjax._junction`); ``attach[i] == i`` otherwise.

A single filament is a network with one chain of segments (nodes 0..N−1, segment k joins
nodes k and k+1).
"""

from __future__ import annotations

import hashlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._checks import check_array, check_vector, is_traced
from ._junction import check_junction_geometry, check_junctions, transfer_segments
from ._network_checks import (
    check_degrees,
    check_loops,
    check_natural_curvature,
    check_rest_frames,
    reference_directors,
    check_reference_state,
    check_segments,
    check_supported,
    concrete_structure,
    network_value,
    node_flags,
    probe_mask,
    projectors,
    strand_ids,
    unit_tangents,
)

__all__ = ["DIFFERENTIABLE_FIELDS", "Network", "Padding", "Topology", "add_direction", "is_traced", "make_network",
           "node_row_width"]

# Network arrays that carry values (traced, differentiable); everything else is topology.
DIFFERENTIABLE_FIELDS = ("positions", "tangents", "lengths", "EI", "loads", "couples", "natural_curvature", "GJ",
                         "directors")
_STRUCTURE = ("segments", "position_projector", "clamped", "moment_free", "attach", "transfer_segment",
              "leaving_segment", "probe", "probe_direction", "strand", "socb_rows", "twisting")
_DTYPES = {"position_projector": np.float64, "probe_direction": np.float64, "clamped": np.bool_, "moment_free": np.bool_,
           "probe": np.bool_, "twisting": np.bool_}  # every other structure array is int32


class Topology:
    """The static structure of a network: read-only numpy arrays, hashed and compared by
    content, so that it can be a static field of :class:`Network` (part of the pytree
    structure, never traced).

    Attributes (N nodes, S segments, d dimensions): ``dim``; ``segments`` [S, 2] int;
    ``position_projector`` [N, d, d]; ``clamped``, ``moment_free``, ``probe`` [N] bool;
    ``attach``, ``transfer_segment``, ``leaving_segment`` [N] int (``leaving_segment[i]``:
    the segment that starts at node i, S if none); ``probe_direction`` [d]; ``strand`` [S]
    int; ``socb_rows`` [R] int (the static selection of SOCB node equations); ``twisting``
    [N] bool (3D Kirchhoff rod with twist: every node carries a material-frame angle; all
    False for the torsion-free rod and in 2D).
    """

    __slots__ = ("dim", "_key", *_STRUCTURE)

    def __init__(self, *, dim: int, **arrays):
        if set(arrays) != set(_STRUCTURE):
            raise TypeError(f"Topology needs exactly {_STRUCTURE}, got {sorted(arrays)}")
        object.__setattr__(self, "dim", int(dim))
        h = hashlib.blake2b(repr(("socbjax.Topology", int(dim))).encode(), digest_size=20)
        for name in _STRUCTURE:
            a = np.array(arrays[name], dtype=_DTYPES.get(name, np.int32), copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)
            h.update(repr((name, a.shape, a.dtype.str)).encode())
            h.update(np.ascontiguousarray(a).tobytes())
        object.__setattr__(self, "_key", h.digest())

    def __setattr__(self, name, value):
        raise AttributeError("Topology is immutable; use Topology.replace(...)")

    def replace(self, **changes) -> Topology:
        """A copy with some arrays replaced (e.g. a probe added)."""
        return Topology(dim=self.dim, **{name: changes.get(name, getattr(self, name)) for name in _STRUCTURE})

    @property
    def key(self) -> str:
        """Hex fingerprint of the whole structure (equal topologies, equal keys)."""
        return self._key.hex()

    def __hash__(self) -> int:
        return hash(self._key)

    def __eq__(self, other) -> bool:
        return self is other or (isinstance(other, Topology) and self._key == other._key)

    def __repr__(self) -> str:
        n, s = self.clamped.shape[0], self.segments.shape[0]
        return f"Topology(dim={self.dim}, nodes={n}, segments={s}, key={self.key[:12]})"


class Padding(eqx.Module):
    """Per-realisation supports of a network padded to a common topology (values, traced and
    batched like the network's other values; see :func:`socbjax.pad_outcrop`).

    ``projector`` [N, d, d] replaces the topology's ``position_projector`` (which nodes are
    pinned may differ between the realisations that share one compiled program);
    ``active`` [N] (1.0 or 0.0) marks the nodes of the realisation itself: padding nodes
    (0.0) are unloaded free tails and subtrees that carry no force, and the surface checks
    ignore them.
    """

    projector: Float[Array, "N d d"]
    active: Float[Array, " N"]


class Network(eqx.Module):
    """A filament network: traced values plus a static :class:`Topology`.

    Attributes (values; every one may be a JAX array or tracer)
    ----------
    positions : [N, d] reference node positions (µm); prescribed positions of supports.
    tangents : [N, d] unit reference tangents at nodes; clamp directions.
    lengths : [S] segment contour lengths (µm).
    EI : [S] bending stiffness per segment (pN·µm²).
    loads : [N, d] fixed external nodal forces (pN), e.g. a lateral perturbation.
    couples : 2D [N], 3D [N, 3] fixed external nodal couples (pN·µm).
    natural_curvature : 2D [S] curvature of each segment at rest (1/µm; each segment is a
        circular arc when unloaded, 0: straight); 3D [S, 3] the natural curvature and twist
        (κ₁, κ₂, τ₀) on the material frame (d1, d2, t) (1/µm), twisting networks only.
    GJ : [S] torsional stiffness per segment (pN·µm²); used by 3D networks built with
        ``GJ=`` (``twisting``), zeros otherwise.
    directors : 3D [N, 3] reference material director d1 at each node (unit, ⊥ tangent;
        default ``orthonormal_complement(tangent)[0]``), used by twisting networks; 2D
        [N, 2] zeros.
    topology : the static structure (``segments``, supports, junctions, probe, ...), whose
        arrays are also available as read-only numpy attributes of the network.
    padding : None, or the :class:`Padding` of a realisation padded to a common topology
        (its supports override the topology's ``position_projector``).
    """

    positions: Float[Array, "N d"]
    tangents: Float[Array, "N d"]
    lengths: Float[Array, " S"]
    EI: Float[Array, " S"]
    loads: Float[Array, "N d"]
    couples: Array
    natural_curvature: Array
    GJ: Float[Array, " S"]
    directors: Array
    topology: Topology = eqx.field(static=True)
    padding: Padding | None = None

    # ---------------------------------------------------------------- structure views
    @property
    def dim(self) -> int:
        return self.topology.dim

    segments = property(lambda self: self.topology.segments)

    @property
    def position_projector(self):
        """[N, d, d] per-node projector onto the prescribed directions: the topology's, or a
        padded network's own (a value, possibly traced)."""
        return self.topology.position_projector if self.padding is None else self.padding.projector

    clamped = property(lambda self: self.topology.clamped)
    moment_free = property(lambda self: self.topology.moment_free)
    attach = property(lambda self: self.topology.attach)
    transfer_segment = property(lambda self: self.topology.transfer_segment)
    leaving_segment = property(lambda self: self.topology.leaving_segment)
    probe = property(lambda self: self.topology.probe)
    probe_direction = property(lambda self: self.topology.probe_direction)
    strand = property(lambda self: self.topology.strand)
    socb_rows = property(lambda self: self.topology.socb_rows)

    @property
    def twisting(self) -> bool:
        """True for a 3D Kirchhoff rod with twist (built with ``GJ=``): nodes carry a
        material-frame angle, moments a twisting component m·t = GJ τ."""
        return bool(self.topology.twisting.any())

    @property
    def n_nodes(self) -> int:
        return self.topology.clamped.shape[0]

    @property
    def n_segments(self) -> int:
        return self.topology.segments.shape[0]

    @property
    def attached(self) -> np.ndarray:
        """[N] bool, daughter base nodes (tied to a mother node by a branch junction)."""
        return self.attach != np.arange(self.n_nodes)

    @property
    def n_junctions(self) -> int:
        return int(np.sum(self.attached))

    @property
    def has_probe(self) -> bool:
        return bool(np.any(self.probe))

    @property
    def total_length(self) -> Array:
        """Sum of segment lengths (µm; a JAX scalar, traced with the lengths)."""
        return jnp.sum(self.lengths)

    def replace(self, **values) -> Network:
        """A network of the same topology with some values replaced (same shapes), e.g.
        ``net.replace(EI=2 * net.EI)``; values may be traced."""
        unknown = set(values) - set(DIFFERENTIABLE_FIELDS)
        if unknown:
            raise ValueError(f"Network.replace: {sorted(unknown)} are not values; replaceable: {DIFFERENTIABLE_FIELDS}")
        new = {}
        for name, value in values.items():
            old = getattr(self, name)
            xp = jnp if is_traced(value) or isinstance(value, jax.Array) else np  # concrete stays numpy (see network_value)
            arr = xp.asarray(value, dtype=np.float64)
            arr = xp.broadcast_to(arr, old.shape) if arr.ndim == 0 else arr
            if arr.shape != old.shape:
                raise ValueError(f"Network.replace: {name} must have shape {old.shape}, got {arr.shape}")
            new[name] = arr
        return eqx.tree_at(lambda n: [getattr(n, k) for k in new], self, list(new.values()))

    def with_topology(self, **structure) -> Network:
        """The same values on a topology with some structure arrays replaced."""
        if self.padding is not None:
            raise ValueError("with_topology: a padded network's supports are values; change the unpadded network")
        return Network(**{k: getattr(self, k) for k in DIFFERENTIABLE_FIELDS}, topology=self.topology.replace(**structure))


# Candidate node equations, per node, in a fixed order (see _residual / _jointed):
#   2D SOCB:    force/position (2) | clamp θ (1) | end moment (1)                 -> 4
#   3D SOCB:    force/position (3) | |t|=1 (1) | clamp t (3) | m·t=0 (1) | end m (3) -> 11
#   3D twisting: the same | frame angle ψ (1)                                     -> 12
def _socb_rows(dim: int, director_fixed: np.ndarray, moment_free: np.ndarray, twisting: bool = False) -> np.ndarray:
    """Static selection of node equations: clamped and daughter-base nodes prescribe the
    director (and with twist the frame angle), free/pinned ends the moment; the torsion-free
    rod has m·t = 0 elsewhere (see :mod:`socbjax._residual`)."""
    if dim == 2:
        local = np.array([[1, 1, c, f] for c, f in zip(director_fixed, moment_free)], bool).reshape(-1, 4)
    elif twisting:
        local = np.array(
            [[1, 1, 1, not c, c, c, c, 0, f, f, f, c] for c, f in zip(director_fixed, moment_free)], bool
        ).reshape(-1, 12)
    else:
        local = np.array(
            [[1, 1, 1, not c, c, c, c, not f, f, f, f] for c, f in zip(director_fixed, moment_free)], bool
        ).reshape(-1, 11)
    return np.flatnonzero(local.ravel()).astype(np.int32)


def node_row_width(network) -> int:
    """Candidate node equations per node (4 in 2D, 11 in 3D, 12 with twist)."""
    return 4 if network.dim == 2 else 11 + int(bool(np.asarray(network.topology.twisting).any()))


def _shapes(positions) -> tuple[int, int]:
    if not is_traced(positions):
        positions = check_array("positions", positions, "µm")
    shape = np.shape(positions)
    if len(shape) != 2 or shape[1] not in (2, 3) or shape[0] < 2:
        raise ValueError(f"positions must have shape [N, 2] or [N, 3] with N >= 2 nodes (µm), got {shape}")
    return shape


def make_network(positions, tangents, segments, lengths, EI, *, fixed_directions=None, clamped=None, attach=None,
                 probe=None, probe_direction=None, loads=None, couples=None, strand=None,
                 natural_curvature=None, GJ=None, directors=None) -> Network:
    """Build and validate a :class:`Network`.

    Parameters
    ----------
    positions, tangents : [N, d] reference node positions (µm) and unit tangents of the
        straight, stress-free reference state (N >= 2, d = 2 or 3).
    segments : [S, 2] (start, end) node indices (integers); a strand's segments run base to tip.
    lengths, EI : [S] or scalars, contour length (µm) and bending stiffness (pN·µm²).
    fixed_directions : list (one per node) of arrays [k, d] of non-zero directions along
        which the node's position is prescribed (their span; k = 0 free, ``np.eye(d)`` fixed point).
    clamped : [N] bool, tangent prescribed (end nodes only).
    attach : [J, 2] (mother node, daughter base node) pairs: Arp2/3 branch junctions; the
        daughter base sits at the mother node, at an angle of 0.1°–179.9° to it.
    probe : node indices held by the rigid probe; probe_direction : [d] its direction of
        motion when compressing (default: from the first probe node toward the centroid of
        the other supported nodes, else −x).
    loads : [N, d] fixed external nodal forces (pN); couples : 2D [N] / 3D [N, 3] fixed
        external nodal couples (pN·µm).  strand : [S] non-negative integer strand ids.
    natural_curvature : 2D [S] or scalar, each segment's curvature at rest (1/µm, positive:
        turning counter-clockwise; default 0, straight).  3D: [S, 3] (κ₁, κ₂, τ₀) on the
        material frame (d1, d2, t), only with ``GJ``: each segment is then at rest a piece of
        helix (an arc for τ₀ = 0, a twisted straight piece for κ = 0).
    directors : 3D [N, 3] reference material directors d1 (unit, ⊥ the tangents), the
        frames of the stress-free state (default: ``orthonormal_complement(tangent)[0]``).
    GJ : [S] or scalar torsional stiffness (pN·µm²).  In 3D it makes the network a
        Kirchhoff rod with twist: every node gets a material frame (its angle ψ about the
        tangent, from the reference director ``orthonormal_complement(tangent)[0]``), clamps
        and junctions fix the whole frame, moments keep their twisting component.  None
        (default): the torsion-free rod.  In 2D it is stored and unused.

    ``positions``, ``tangents``, ``lengths``, ``EI``, ``loads``, ``couples`` and
    ``natural_curvature`` may be JAX arrays or tracers (inside ``jax.jit``, ``jax.grad``,
    ``jax.vmap``): they become the network's traced values, and the checks that need their
    values are then skipped.  Everything else is topology and must be concrete.  With
    concrete values the reference state must be the stress-free one (relative tolerance
    1e-6, see :mod:`socbjax._network_checks`): unit tangents (normalised when within the
    tolerance), each segment a straight piece as long as its chord with the tangents at
    both its nodes along the chord, or with natural curvature κ₀ an arc of that length
    (chord 2 sin(κ₀l/2)/κ₀, end tangents at ∓κ₀l/2 from the chord, κ₀l < π),
    no coincident end nodes, daughter bases at their mother nodes.  Segments and junctions
    must form no closed loop, and every piece must be held against rigid-body motion.
    Moment-free ends are derived: nodes with one segment that are neither clamped nor
    daughter bases.  Raises ``TypeError`` for wrong types (floats or booleans as indices,
    strings, traced topology) and ``ValueError`` for inconsistent values; every message
    names the argument.
    """
    n, dim = _shapes(positions)
    seg = check_segments(segments, n)
    s = len(seg)
    positions, pos_np = network_value("positions", positions, (n, dim), "µm")
    tangents, tan_np = network_value("tangents", tangents, (n, dim), "unit vectors")
    lengths, len_np = network_value("lengths", lengths, (s,), "µm", positive=True)
    EI, _ = network_value("EI", EI, (s,), "pN·µm²", positive=True)
    loads, _ = network_value("loads", loads, (n, dim), "pN")
    couples, _ = network_value("couples", couples, (n,) if dim == 2 else (n, 3), "pN·µm")
    natural_curvature, kappa_np = network_value("natural_curvature", natural_curvature, (s,) if dim == 2 else (s, 3),
                                                "1/µm")
    twisting = GJ is not None and dim == 3
    turn = check_natural_curvature(kappa_np, len_np, dim, twisting)
    GJ, _ = network_value("GJ", GJ, (s,), "pN·µm²", positive=True) if GJ is not None else (np.zeros(s), None)
    if tan_np is not None:
        tangents = tan_np = unit_tangents(tan_np)
    directors, dir_np = reference_directors(directors, tangents, tan_np, n, dim)
    n_start, n_end = check_degrees(seg, n)
    degree = n_start + n_end
    clamped = node_flags("clamped", clamped, n)
    if np.any(clamped & (degree != 1)):
        raise ValueError(f"only end nodes (one segment) can be clamped; node {int(np.argmax(clamped & (degree != 1)))} "
                         "has two")
    projector = projectors(fixed_directions, n, dim)
    probe_nodes = probe_mask(probe, n)
    direction = _probe_direction(probe_direction, probe_nodes, projector, pos_np, dim)
    if probe_nodes.any():
        projector[probe_nodes] = add_direction(projector[probe_nodes], direction)
    fixed_any = np.einsum("nii->n", projector) > 0.5
    attach_arr = check_junctions(concrete_structure("attach", attach), n, degree, n_end, n_start, clamped, fixed_any,
                                 probe_nodes)
    roots = check_loops(n, seg, attach_arr)
    if twisting:
        check_rest_frames(pos_np, tan_np, dir_np, seg, len_np, kappa_np)
    else:
        check_reference_state(pos_np, tan_np, seg, len_np, turn)
    check_junction_geometry(attach_arr, pos_np, tan_np, len_np)
    attached = attach_arr != np.arange(n)
    check_supported(roots, clamped, projector, dim)
    moment_free = (degree == 1) & ~clamped & ~attached
    strand = strand_ids(strand, s)
    leaving = np.full(n, s)
    leaving[seg[:, 0]] = np.arange(s)
    topology = Topology(
        dim=dim, segments=seg, position_projector=projector, clamped=clamped, moment_free=moment_free,
        attach=attach_arr.astype(np.int32), transfer_segment=transfer_segments(attach_arr, seg, n_start).astype(np.int32),
        leaving_segment=leaving.astype(np.int32), probe=probe_nodes, probe_direction=direction,
        strand=strand, socb_rows=_socb_rows(dim, clamped | attached, moment_free, twisting),
        twisting=np.full(n, twisting),
    )
    return Network(positions=positions, tangents=tangents, lengths=lengths, EI=EI, loads=loads, couples=couples,
                   natural_curvature=natural_curvature, GJ=GJ, directors=directors, topology=topology)


def add_direction(projector: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Projectors [N, d, d] onto span(P) + span(direction) (host side)."""
    out = []
    for P in np.asarray(projector):
        basis = np.concatenate([P, np.asarray(direction)[:, None]], axis=1)
        u, sv, _ = np.linalg.svd(basis)
        q = u[:, sv > 1e-9]
        out.append(q @ q.T)
    return np.asarray(out)


def _probe_direction(direction, probe_mask, projector, positions, dim):
    if direction is None:
        if not probe_mask.any():
            return np.eye(dim)[0]
        if positions is None:
            raise TypeError("probe_direction must be given explicitly when the positions are traced (it is topology)")
        others = (np.einsum("nii->n", projector) > 0.5) & ~probe_mask
        if others.any():
            d = positions[others].mean(axis=0) - positions[probe_mask].mean(axis=0)
            if np.linalg.norm(d) > 1e-12:
                return d / np.linalg.norm(d)
        return -np.eye(dim)[0]
    d = check_vector("probe_direction", concrete_structure("probe_direction", direction), dim, "direction", nonzero=True)
    return d / np.linalg.norm(d)
