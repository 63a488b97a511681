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

from ._junction import check_junctions, transfer_segments

__all__ = ["Network", "Topology", "make_network", "DIFFERENTIABLE_FIELDS", "is_traced", "add_direction"]

# Network arrays that carry values (traced, differentiable); everything else is topology.
DIFFERENTIABLE_FIELDS = ("positions", "tangents", "lengths", "EI", "loads", "couples")
_STRUCTURE = ("segments", "position_projector", "clamped", "moment_free", "attach", "transfer_segment",
              "leaving_segment", "probe", "probe_direction", "strand", "socb_rows")
_DTYPES = {"position_projector": np.float64, "probe_direction": np.float64, "clamped": np.bool_, "moment_free": np.bool_,
           "probe": np.bool_}  # every other structure array is int32


def is_traced(*trees) -> bool:
    """True if any leaf of ``trees`` is a JAX tracer (inside jit, grad, vmap, ...)."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(trees))


class Topology:
    """The static structure of a network: read-only numpy arrays, hashed and compared by
    content, so that it can be a static field of :class:`Network` (part of the pytree
    structure, never traced).

    Attributes (N nodes, S segments, d dimensions): ``dim``; ``segments`` [S, 2] int;
    ``position_projector`` [N, d, d]; ``clamped``, ``moment_free``, ``probe`` [N] bool;
    ``attach``, ``transfer_segment``, ``leaving_segment`` [N] int (``leaving_segment[i]``:
    the segment that starts at node i, S if none); ``probe_direction`` [d]; ``strand`` [S]
    int; ``socb_rows`` [R] int (the static selection of SOCB node equations).
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
    topology : the static structure (``segments``, supports, junctions, probe, ...), whose
        arrays are also available as read-only numpy attributes of the network.
    """

    positions: Float[Array, "N d"]
    tangents: Float[Array, "N d"]
    lengths: Float[Array, " S"]
    EI: Float[Array, " S"]
    loads: Float[Array, "N d"]
    couples: Array
    topology: Topology = eqx.field(static=True)

    # ---------------------------------------------------------------- structure views
    @property
    def dim(self) -> int:
        return self.topology.dim

    segments = property(lambda self: self.topology.segments)
    position_projector = property(lambda self: self.topology.position_projector)
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
            xp = jnp if is_traced(value) or isinstance(value, jax.Array) else np  # concrete stays numpy (see _value)
            arr = xp.asarray(value, dtype=np.float64)
            arr = xp.broadcast_to(arr, old.shape) if arr.ndim == 0 else arr
            if arr.shape != old.shape:
                raise ValueError(f"Network.replace: {name} must have shape {old.shape}, got {arr.shape}")
            new[name] = arr
        return eqx.tree_at(lambda n: [getattr(n, k) for k in new], self, list(new.values()))

    def with_topology(self, **structure) -> Network:
        """The same values on a topology with some structure arrays replaced."""
        return Network(**{k: getattr(self, k) for k in DIFFERENTIABLE_FIELDS}, topology=self.topology.replace(**structure))


# Candidate node equations, per node, in a fixed order (see _residual / _jointed):
#   2D SOCB:    force/position (2) | clamp θ (1) | end moment (1)                 -> 4
#   3D SOCB:    force/position (3) | |t|=1 (1) | clamp t (3) | m·t=0 (1) | end m (3) -> 11
def _socb_rows(dim: int, director_fixed: np.ndarray, moment_free: np.ndarray) -> np.ndarray:
    """Static selection of node equations: clamped and daughter-base nodes prescribe the
    director, free/pinned ends the moment (see :mod:`socbjax._residual`)."""
    if dim == 2:
        local = np.array([[1, 1, c, f] for c, f in zip(director_fixed, moment_free)], bool).reshape(-1, 4)
    else:
        local = np.array(
            [[1, 1, 1, not c, c, c, c, not f, f, f, f] for c, f in zip(director_fixed, moment_free)], bool
        ).reshape(-1, 11)
    return np.flatnonzero(local.ravel()).astype(np.int32)


def _concrete_structure(name: str, value):
    if is_traced(value):
        raise TypeError(
            f"{name} fixes the network's topology and must be concrete (numpy or Python values), not a traced JAX "
            "value: build the structure outside jax.jit/grad/vmap; only the values positions, tangents, lengths, EI, "
            "loads and couples may be traced"
        )
    return value


def _as_node_array(name: str, value, n: int, dtype, default) -> np.ndarray:
    if value is None:
        return np.full(n, default, dtype=dtype)
    arr = np.asarray(_concrete_structure(name, value))
    if arr.shape != (n,):
        raise ValueError(f"{name} must have one entry per node ({n}), got shape {arr.shape}")
    return arr.astype(dtype)


def _value(name: str, value, shape: tuple, unit: str):
    """(array of ``shape``, concrete numpy copy or None when traced); scalars broadcast.

    Concrete values stay numpy arrays in the network: inside ``jax.jit`` even
    ``jnp.asarray`` of a constant is a tracer, and the host-side logic that needs concrete
    geometry (probe placement, input checks) must still see it."""
    if value is None:
        return np.zeros(shape), np.zeros(shape)
    if is_traced(value):
        arr = jnp.asarray(value, jnp.float64)
        arr = jnp.broadcast_to(arr, shape) if arr.ndim == 0 or (arr.ndim == 1 and len(shape) == 1 and arr.shape == (1,)) else arr
        if arr.shape != shape:
            raise ValueError(f"{name} must have shape {shape} ({unit}), got {arr.shape}")
        return arr, None
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.broadcast_to(arr, shape)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape} ({unit}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values; give finite {unit}")
    arr = np.array(arr, copy=True)
    return arr, arr


def _check_segments(segments, n) -> np.ndarray:
    seg = np.asarray(_concrete_structure("segments", segments))
    if seg.size and not np.issubdtype(seg.dtype, np.integer):
        if not np.all(seg == np.round(seg)):
            raise ValueError("segments must hold integer node indices (got fractional values)")
    seg = seg.astype(np.int64)
    if seg.ndim != 2 or seg.shape[1] != 2:
        raise ValueError(f"segments must have shape [S, 2], got {seg.shape}")
    if seg.size and (seg.min() < 0 or seg.max() >= n):
        raise ValueError(f"segments reference a node index outside 0..{n - 1}")
    if np.any(seg[:, 0] == seg[:, 1]):
        raise ValueError("a segment joins a node to itself; each segment needs two distinct nodes")
    pairs = np.sort(seg, axis=1)
    if len(np.unique(pairs, axis=0)) != len(pairs):
        raise ValueError("two segments join the same pair of nodes (duplicate segment)")
    return seg.astype(np.int32)


def _check_values(positions, segments, lengths, EI):
    """Checks that need concrete values (skipped for traced ones)."""
    if lengths is not None and np.any(lengths <= 0):
        raise ValueError("segment lengths must be positive (µm); remove zero-length segments")
    if EI is not None and np.any(EI <= 0):
        raise ValueError("EI must be positive (pN·µm²)")
    if positions is not None and lengths is not None and len(segments):
        chord = np.linalg.norm(positions[segments[:, 1]] - positions[segments[:, 0]], axis=1)
        bad = chord <= 1e-9 * np.maximum(lengths, 1.0)
        if np.any(bad):
            raise ValueError(f"segment {int(np.argmax(bad))} has coincident end nodes (zero-length segment); merge or remove it")


def _check_supported(n, segments, attach, clamped, projector, dim):
    """Every connected piece must be held against rigid-body motion."""
    parent = np.arange(n)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in list(map(tuple, segments)) + [(i, attach[i]) for i in range(n) if attach[i] != i]:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    roots = np.array([find(i) for i in range(n)])
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


def _projectors(fixed_directions, n: int, dim: int) -> np.ndarray:
    projector = np.zeros((n, dim, dim))
    if fixed_directions is None:
        return projector
    _concrete_structure("fixed_directions", fixed_directions)
    if len(fixed_directions) != n:
        raise ValueError(f"fixed_directions needs one entry per node ({n}), got {len(fixed_directions)}")
    for i, dirs in enumerate(fixed_directions):
        dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, dim)
        if len(dirs):
            q, _ = np.linalg.qr(dirs.T)
            projector[i] = q @ q.T
    return projector


def _probe_mask(probe, n: int) -> np.ndarray:
    mask = np.zeros(n, bool)
    if probe is None:
        return mask
    idx = np.asarray(_concrete_structure("probe", probe)).ravel()
    if idx.size and not np.issubdtype(idx.dtype, np.integer):
        raise TypeError(f"probe must hold integer node indices, got dtype {idx.dtype}")
    if idx.size and (idx.min() < -n or idx.max() >= n):
        raise ValueError(f"probe references a node outside 0..{n - 1}")
    mask[idx.astype(np.int64)] = True
    return mask


def _shapes(positions) -> tuple[int, int]:
    shape = np.shape(positions)
    if len(shape) != 2 or shape[1] not in (2, 3):
        raise ValueError(f"positions must have shape [N, 2] or [N, 3], got {shape}")
    return shape


def make_network(positions, tangents, segments, lengths, EI, *, fixed_directions=None, clamped=None, attach=None,
                 probe=None, probe_direction=None, loads=None, couples=None, strand=None) -> Network:
    """Build and validate a :class:`Network`.

    Parameters
    ----------
    positions, tangents : [N, d] reference node positions (µm) and unit tangents of the
        straight, stress-free reference state.
    segments : [S, 2] (start, end) node indices; a strand's segments run base to tip.
    lengths, EI : [S] or scalars, contour length (µm) and bending stiffness (pN·µm²).
    fixed_directions : list (one per node) of arrays [k, d] of directions along which the
        node's position is prescribed (k = 0 free, ``np.eye(d)`` fixed point).
    clamped : [N] bool, tangent prescribed (end nodes only).
    attach : [J, 2] (mother node, daughter base node) pairs: Arp2/3 branch junctions.
    probe : node indices held by the rigid probe; probe_direction : [d] its direction of
        motion when compressing (default: from the first probe node toward the centroid of
        the other supported nodes, else −x).
    loads : [N, d] fixed external nodal forces (pN); couples : 2D [N] / 3D [N, 3] fixed
        external nodal couples (pN·µm).  strand : [S] int strand ids.

    ``positions``, ``tangents``, ``lengths``, ``EI``, ``loads`` and ``couples`` may be JAX
    arrays or tracers (inside ``jax.jit``, ``jax.grad``, ``jax.vmap``): they become the
    network's traced values, and the checks that need their values (positive lengths and EI,
    distinct end nodes) are then skipped.  Everything else is topology and must be concrete.
    Moment-free ends are derived: nodes with one segment that are neither clamped nor
    daughter bases.  Raises ``ValueError`` (``TypeError`` for traced topology) for
    inconsistent input.
    """
    n, dim = _shapes(positions)
    seg = _check_segments(segments, n)
    s = len(seg)
    positions, pos_np = _value("positions", positions, (n, dim), "µm")
    tangents, tan_np = _value("tangents", tangents, (n, dim), "unit vectors")
    lengths, len_np = _value("lengths", lengths, (s,), "µm")
    EI, EI_np = _value("EI", EI, (s,), "pN·µm²")
    loads, _ = _value("loads", loads, (n, dim), "pN")
    couples, _ = _value("couples", couples, (n,) if dim == 2 else (n, 3), "pN·µm")
    _check_values(pos_np, seg, len_np, EI_np)
    n_start, n_end = np.bincount(seg[:, 0], minlength=n), np.bincount(seg[:, 1], minlength=n)
    degree = n_start + n_end
    if np.any(degree == 0):
        raise ValueError(f"node {int(np.argmax(degree == 0))} belongs to no segment; remove it")
    if np.any(degree > 2):
        raise ValueError(f"node {int(np.argmax(degree > 2))} is shared by more than two segments; join filaments with "
                         "branch junctions (attach=[(mother, daughter_base), ...]) instead")
    clamped = _as_node_array("clamped", clamped, n, bool, False)
    if np.any(clamped & (degree != 1)):
        raise ValueError("only end nodes (one segment) can be clamped")
    projector = _projectors(fixed_directions, n, dim)
    probe_mask = _probe_mask(probe, n)
    direction = _probe_direction(probe_direction, probe_mask, projector, pos_np, dim)
    projector = np.where(probe_mask[:, None, None], add_direction(projector, direction), projector)
    fixed_any = np.einsum("nii->n", projector) > 0.5
    attach_arr = check_junctions(_concrete_structure("attach", attach), n, degree, n_end, n_start, clamped, fixed_any, probe_mask)
    attached = attach_arr != np.arange(n)
    _check_supported(n, seg, attach_arr, clamped, projector, dim)
    moment_free = (degree == 1) & ~clamped & ~attached
    strand = np.zeros(s, np.int32) if strand is None else np.asarray(_concrete_structure("strand", strand))
    if strand.shape != (s,):
        raise ValueError(f"strand must have one id per segment ({s}), got shape {strand.shape}")
    leaving = np.full(n, s)
    leaving[seg[:, 0]] = np.arange(s)
    topology = Topology(
        dim=dim, segments=seg, position_projector=projector, clamped=clamped, moment_free=moment_free,
        attach=attach_arr.astype(np.int32), transfer_segment=transfer_segments(attach_arr, seg, n_start).astype(np.int32),
        leaving_segment=leaving.astype(np.int32), probe=probe_mask, probe_direction=direction,
        strand=strand.astype(np.int32), socb_rows=_socb_rows(dim, clamped | attached, moment_free),
    )
    return Network(positions=positions, tangents=tangents, lengths=lengths, EI=EI, loads=loads, couples=couples,
                   topology=topology)


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
    d = np.asarray(_concrete_structure("probe_direction", direction), dtype=np.float64).ravel()
    if d.shape != (dim,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-12:
        raise ValueError(f"probe_direction must be a finite non-zero vector with {dim} components, got {direction!r}")
    return d / np.linalg.norm(d)
