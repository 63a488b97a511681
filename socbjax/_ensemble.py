"""Ensembles of compressions: one compiled, vmapped continuation for a batch of networks of
identical structure, optionally sharded across devices: :func:`compress_ensemble`.

The members share everything that fixes the compiled program and the Jacobian's sparsity
(:func:`socbjax._sparsity.structure_key`: dimension, topology, supports, probe, array
shapes); the values of ``positions``, ``tangents``, ``lengths``, ``EI`` and ``loads`` (and the
perturbation) may differ — one outcrop under many EI values, many imperfection patterns or
magnitudes, or geometric variants of one topology.

Each phase of the :func:`socbjax.compress` protocol (settle, loading, unloading) is one
compiled call: ``jax.vmap`` of the phase's ``path_start`` + ``path_run`` (a
``lax.while_loop``) over the batch axis, and the three phases share one compiled program.
The structure enters once, unbatched; the differentiable fields, loads and control ends are
stacked [B, ...] (so new values never recompile).  The vmapped loop runs until its
slowest member is done; finished members idle (their updates are masked), and every Newton
iteration factors all B Jacobians (dense: one batched LU; sparse: B sequential SuperLU
callbacks).  Between phases the host reads the step records and builds the next phase (the
per-member settled displacement u₀ sets the loading endpoints).

With ``devices`` the batch axis is split over a 1-D ``jax.sharding.Mesh`` (axis "batch") by
``jax.shard_map``: each device runs its own vmapped while-loops on B/D members, with no
cross-device communication inside the loop.  See ``docs/scaling.md``.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from ._compress import _check_inputs, _concat, _loads, _package, _Protocol, _run, _start, probe_network, traced_settings
from ._linear import DenseJacobianSolver, _lu_sign
from ._network import DIFFERENTIABLE_FIELDS, Network
from ._newton import Status
from ._path import PathSettings, path_weights
from ._result import CompressionResult
from ._solve import ConvergenceError
from ._sparsity import structure_key

__all__ = ["EnsembleResult", "compress_ensemble"]

_RUNNING = -1


@dataclasses.dataclass(frozen=True, eq=False)
class EnsembleResult:
    """The compressions of an ensemble; see :func:`compress_ensemble`.

    displacement, force : [B, M] probe displacement (µm) and probe force along the probe
        direction (pN, compressive positive) of each member's recorded path (settle point,
        loading, unloading), padded with NaN after the member's ``n_steps[b]`` rows.
    phase : [B, M] int8, 0 settle, 1 loading, 2 unloading, −1 padding.
    n_steps : [B] recorded steps per member.
    status : [B] :class:`socbjax.Status` code per member (CONVERGED: every phase completed).
    results : the B members as :class:`CompressionResult` (unpadded; also ``member(i)``).
    devices : the devices that held the batch (the output shards of the last phase).
    attempts, newton_iterations : [B, phases] attempted steps (accepted and rejected) and
        Newton iterations of each member per phase (0 for phases not reached): the work a
        member needed; the batch runs each phase for max over members of it.
    """

    displacement: np.ndarray
    force: np.ndarray
    phase: np.ndarray
    n_steps: np.ndarray
    status: np.ndarray
    results: list[CompressionResult]
    devices: tuple[str, ...]
    attempts: np.ndarray
    newton_iterations: np.ndarray

    @property
    def completed(self) -> np.ndarray:
        """[B] bool: member completed every phase."""
        return self.status == Status.CONVERGED

    def member(self, i: int) -> CompressionResult:
        return self.results[i]

    def __len__(self) -> int:
        return len(self.results)

    def __repr__(self) -> str:
        return (f"EnsembleResult({len(self)} members, {int(self.completed.sum())} completed, "
                f"{int(self.n_steps.max())} steps max, devices {len(self.devices)})")


class _Member(_Protocol):
    """One member's protocol (problems, phase ends, records); the batch shares one linear solver."""

    def _linear_solver(self, kind):
        return None


# --------------------------------------------------------------------------- validation
def _structure_difference(a: Network, b: Network) -> str:
    """What differs in structure between ``a`` and ``b`` (see :func:`structure_key`)."""
    if a.dim != b.dim:
        return f"dim ({a.dim} vs {b.dim})"
    for name in sorted(vars(a)):
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        if x.shape != y.shape:
            return f"the shape of {name} ({x.shape} vs {y.shape})"
        if name not in DIFFERENTIABLE_FIELDS and x.ndim and not np.array_equal(x != 0, y != 0):
            return f"{name}"
    return "the structure"


def _check_members(networks) -> list[Network]:
    if isinstance(networks, Network) or not isinstance(networks, Sequence):
        raise TypeError("networks must be a sequence (list or tuple) of socbjax Networks of identical structure")
    if not len(networks):
        raise ValueError("networks is empty: an ensemble needs at least one member")
    for i, net in enumerate(networks):
        if not isinstance(net, Network):
            raise TypeError(f"member {i} of networks is a {type(net).__name__}, not a socbjax Network")
    nets = [probe_network(net) for net in networks]
    key = structure_key(nets[0])
    for i, net in enumerate(nets[1:], 1):
        if structure_key(net) != key:
            raise ValueError(
                f"member {i} differs from member 0 in {_structure_difference(nets[0], net)}: the members of an "
                "ensemble must share dimension, topology (segments, junctions, strands), supports, probe and array "
                "shapes; only the values of positions, tangents, lengths, EI and loads may differ "
                "(pad or group networks of different topology into separate ensembles)"
            )
    return nets


def _member_perturbations(perturbation, B: int) -> list:
    if perturbation is None or np.ndim(perturbation) == 0:
        return [perturbation] * B
    values = list(np.asarray(perturbation, dtype=float).ravel()) if np.ndim(perturbation) == 1 else None
    if values is None or len(values) != B:
        raise ValueError(f"perturbation must be None, one force (pN) or one per member ({B}), "
                         f"got shape {np.shape(perturbation)}")
    return values


def _resolve_devices(devices):
    if devices is None:
        return None
    available = jax.devices()
    if isinstance(devices, (int, np.integer)) and not isinstance(devices, bool):
        if not 1 <= devices <= len(available):
            raise ValueError(f"devices={devices}: between 1 and the {len(available)} available devices "
                             "(on a CPU set XLA_FLAGS=--xla_force_host_platform_device_count=N before jax starts)")
        devices = available[:devices]
    devices = list(devices)
    if not devices or not all(isinstance(d, jax.Device) for d in devices):
        raise ValueError("devices must be None, a positive int, or a non-empty list of jax devices (jax.devices())")
    return Mesh(np.array(devices), ("batch",))


# --------------------------------------------------------------------- batched phases
@jax.custom_batching.custom_vmap
def _mapped_lu_solve(J, rhs):
    lu, piv = jax.scipy.linalg.lu_factor(J)
    return jax.scipy.linalg.lu_solve((lu, piv), rhs.astype(lu.dtype)), _lu_sign(lu, piv)


@_mapped_lu_solve.def_vmap
def _mapped_lu_solve_vmap(axis_size, in_batched, J, rhs):
    J, rhs = (a if b else jnp.broadcast_to(a, (axis_size, *a.shape)) for a, b in zip((J, rhs), in_batched))
    return jax.lax.map(lambda a: _mapped_lu_solve(*a), (J, rhs)), (True, True)


class _MappedDenseSolver(DenseJacobianSolver):
    """:class:`DenseJacobianSolver` whose LU runs one matrix at a time under ``vmap``.

    jaxlib's batched CPU LU (``lapack_dgetrf_ffi``) splits the batch over XLA's intra-op
    thread pool and waits inside a pool worker; when several host devices (from
    ``--xla_force_host_platform_device_count``) each run such a batched LU, all workers can
    end up waiting and the program deadlocks (observed with 2 host devices on 2 cores).
    Sharded CPU ensembles therefore factor their members in a ``lax.map`` loop (the same
    LAPACK call per matrix, so the same numbers); the Jacobians stay batched."""

    def solve(self, fn, x, rhs, *, transpose: bool = False):
        if transpose:
            return super().solve(fn, x, rhs, transpose=True)
        return _mapped_lu_solve(jax.jacfwd(fn)(x), rhs)


def _split(problems):
    """Stack the members' :class:`_Problem` s: (batched, stacked [B, ...]: the network's
    differentiable fields, loads, control ends and any other leaf that differs; shared: the
    structure, once); either tree has None where the other holds.  So the three phases, and
    new values of any differentiable field, reuse one compiled program."""
    def varies(*xs):
        x0 = np.asarray(xs[0])
        return any(x is not xs[0] and not np.array_equal(np.asarray(x), x0) for x in xs[1:])

    mask = jax.tree_util.tree_map(varies, *problems)
    values = lambda p: (p.loads, p.control0, p.control1, *(getattr(p.model.network, f) for f in DIFFERENTIABLE_FIELDS))
    mask = eqx.tree_at(values, mask, (True,) * (3 + len(DIFFERENTIABLE_FIELDS)))
    trees = problems
    batched = jax.tree_util.tree_map(lambda m, *xs: jnp.stack([jnp.asarray(x) for x in xs]) if m else None, mask, *trees)
    shared = jax.tree_util.tree_map(lambda m, x: None if m else x, mask, trees[0])
    return batched, shared


def _phase_body(batched, shared, xc, weights, scale, chunk, settings, *, linsolver, start):
    def one(b, xc, w, s):
        problem = eqx.combine(b, shared)
        carry = _start(problem, xc, w, linsolver, settings) if start else xc
        return _run(problem, carry, w, s, linsolver, settings, chunk)

    return jax.vmap(one)(batched, xc, weights, scale)


@eqx.filter_jit
def _phase(batched, shared, xc, weights, scale, chunk, settings, linsolver, start, mesh):
    """One compiled call: the vmapped phase (start + while-loop) over the batch, each device
    running its own shard of the batch axis when ``mesh`` is given."""
    body = functools.partial(_phase_body, linsolver=linsolver, start=start)
    args = (batched, shared, xc, weights, scale, chunk, settings)
    if mesh is None:
        return body(*args)
    specs = (P("batch"), P(), P("batch"), P("batch"), P("batch"), P(), P())
    return jax.shard_map(body, mesh=mesh, in_specs=specs, out_specs=P("batch"), check_vma=False)(*args)


def _place(tree, mesh, spec):
    """Global arrays laid out by ``spec`` over ``mesh`` (also across processes: each process
    supplies its own shards from the full host value)."""
    if mesh is None:
        return tree

    def put(a):
        if not eqx.is_array(a):
            return a
        host = np.asarray(a)
        return jax.make_array_from_callback(host.shape, NamedSharding(mesh, spec), lambda idx: host[idx])

    return jax.tree_util.tree_map(put, tree)


def _to_host(a) -> np.ndarray:
    if a.is_fully_addressable:
        return np.asarray(a)
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(a, tiled=True))


def _pad(rows: list, size: int) -> list:
    return rows + [rows[-1]] * (size - len(rows))


def _run_batch(plans, weights, runner, progress, name):
    """Run one phase for all members (``plans``: per member (problem, p-scale, x start, ends));
    returns the host-side per-member carries."""
    B, mesh = len(plans), runner["mesh"]
    size = B if mesh is None else -(-B // mesh.size) * mesh.size  # pad to a multiple of the devices
    batched, shared = _split(_pad([p[0] for p in plans], size))
    xs = jnp.stack(_pad([jnp.asarray(p[2]) for p in plans], size))
    scales = jnp.asarray(_pad([float(p[1]) for p in plans], size))
    w = jnp.stack(_pad(weights, size))
    batched, xs, scales, w = _place((batched, xs, scales, w), mesh, P("batch"))
    shared, settings, chunk = _place((shared, traced_settings(runner["settings"]), jnp.asarray(runner["chunk"])), mesh, P())
    args = dict(linsolver=runner["linsolver"], mesh=mesh)
    carry = _phase(batched, shared, xs, w, scales, chunk, settings, start=True, **args)
    while True:
        status = _to_host(carry["status"])[:B]
        if progress:
            done = int(np.sum(status != _RUNNING))
            sys.stderr.write(f"\r{name:>9s}: {done}/{B} members done, steps {int(_to_host(carry['steps']).max()):5d}")
            sys.stderr.flush()
        if not np.any(status == _RUNNING):
            break
        carry = _phase(batched, shared, carry, w, scales, chunk, settings, start=False, **args)
    if progress:
        sys.stderr.write("\n")
    runner["devices"] = tuple(str(d) for d in carry["status"].sharding.device_set)
    steps = _to_host(carry["steps"])[:B]
    kmax = max(int(steps.max()), 1)
    host = {k: _to_host(carry[k]) for k in ("status", "steps", "sign0", "attempts", "iterations")}
    host.update({k: _to_host(carry[k][:, :kmax]) for k in ("X", "P", "SIGN", "ITER")})
    return [{k: v[i] for k, v in host.items()} for i in range(B)]


def _run_protocol(members, runner, progress):
    """All phases for all members; a member that fails a phase stops there (its slot in later
    phases runs a copy of a live member, discarded).  Returns the status per member and the
    work [B, phases, 2] (attempts, Newton iterations)."""
    status = np.full(len(members), int(Status.CONVERGED))
    work = np.zeros((len(members), len(members[0].names), 2), np.int64)
    for index, name in enumerate(members[0].names):
        live = np.flatnonzero(status == Status.CONVERGED)
        if not live.size:
            break
        plans = {int(i): members[i]._phase(index) for i in live}
        order = [plans.get(i, plans[int(live[0])]) for i in range(len(members))]
        weights = [path_weights(m.x0, m.geometry, m.network.n_nodes, plan[1]) for m, plan in zip(members, order)]
        carries = _run_batch(order, weights, runner, progress, name)
        for i in live:
            members[i]._finish(index, carries[i], plans[int(i)][3])
            status[i] = int(carries[i]["status"])
            work[i, index] = carries[i]["attempts"], carries[i]["iterations"]
    return status, work


# ----------------------------------------------------------------------------- results
def _padded_records(rec: dict, M: int) -> dict:
    """The records repeated on their last row up to M rows: one compiled observation serves
    every member, and repeated rows add no events (no change in u, F or det sign)."""
    k = len(rec["U"])
    return {key: np.concatenate([v, np.repeat(v[-1:], M - k, axis=0)]) for key, v in rec.items()}


def _trim(result: CompressionResult, k: int, M: int) -> CompressionResult:
    rows = {f.name: getattr(result, f.name)[:k] for f in dataclasses.fields(result)
            if f.name != "end_nodes" and isinstance(getattr(result, f.name), np.ndarray)
            and getattr(result, f.name).ndim and getattr(result, f.name).shape[0] == M}
    return dataclasses.replace(result, **rows)


def _results(members, status, work, options, devices) -> EnsembleResult:
    recs = [_concat(m.parts) for m in members]
    M = max(len(r["U"]) for r in recs)
    results = [
        _trim(_package(m.model, m.loads, _padded_records(rec, M), m.extra, int(s), m.network, None, options), len(rec["U"]), M)
        for m, rec, s in zip(members, recs, status)
    ]
    B = len(results)
    disp, force, phase = np.full((B, M), np.nan), np.full((B, M), np.nan), np.full((B, M), -1, np.int8)
    for b, r in enumerate(results):
        disp[b, : r.n_steps], force[b, : r.n_steps], phase[b, : r.n_steps] = r.displacement, r.force, r.phase
    n_steps = np.array([r.n_steps for r in results])
    return EnsembleResult(disp, force, phase, n_steps, np.asarray(status, np.int32), results, devices, work[..., 0], work[..., 1])


# -------------------------------------------------------------------------------- API
def compress_ensemble(
    networks: Sequence[Network],
    displacement: float,
    *,
    unload: bool = False,
    method: str = "displacement",
    perturbation=None,
    settings: PathSettings | None = None,
    linear_solver: str = "auto",
    quadrature_order: int = 8,
    devices=None,
    progress: bool = False,
    throw: bool = True,
) -> EnsembleResult:
    """Compress every network of an ensemble by ``displacement`` µm: the protocol of
    :func:`socbjax.compress`, run for the whole batch as one compiled, vmapped continuation.

    Parameters
    ----------
    networks : B networks of identical structure (same dimension, topology, supports, probe
        and array shapes; :func:`socbjax._sparsity.structure_key`): only the values of
        ``positions``, ``tangents``, ``lengths``, ``EI`` and ``loads`` may differ.  Typical:
        one outcrop under many EI values or imperfection patterns
        (``eqx.tree_at(lambda n: n.loads, net, strand_perturbation(net, f, seed=k))``).
        Outcrops grown from different seeds differ in topology: they are separate ensembles.
    displacement : probe travel (µm), the same for every member; must stay below each
        member's probe–surface gap.
    unload, method, settings, linear_solver, quadrature_order : as for
        :func:`socbjax.compress` (one Jacobian-solver preparation serves the batch).
    perturbation : None (each member's loads, else the default 1e-4 EI/L² per strand), one
        lateral force (pN) for all members, or a sequence of B forces.
    devices : None (the default device), an int (the first n of ``jax.devices()``) or a
        list of jax devices: the batch axis is sharded over them with ``jax.shard_map``
        (B padded to a multiple of their number; every device runs its own while-loops).
        Several GPUs: ``devices=jax.devices()``.  Several hosts: call
        ``jax.distributed.initialize()`` first in every process, build the same B networks
        in each, and pass ``devices=jax.devices()`` (the global list); every process gets
        the whole result.  On a CPU, ``XLA_FLAGS=--xla_force_host_platform_device_count=N``
        (set before jax starts) splits it into N devices.  See ``docs/scaling.md``.
    progress : report the members still running to stderr (the phases then run in chunks
        of 25 steps; the curves are identical).
    throw : raise :class:`ConvergenceError` naming the members that did not complete
        (``error.result`` holds the ensemble); with ``throw=False`` check ``result.completed``.

    Returns
    -------
    :class:`EnsembleResult`: curves [B, M] padded with NaN, ``n_steps`` [B], ``status`` [B],
    and each member as a :class:`CompressionResult` (``result.member(i)``), equal to
    ``socbjax.compress(networks[i], ...)`` up to round-off.

    Example::

        net = sj.dendritic_outcrop(generations=4, gap=4.0, dim=2)
        ens = sj.compress_ensemble([eqx.tree_at(lambda n: n.EI, net, net.EI * s) for s in (0.5, 1, 2)], 0.5)
        ens.force.shape  # (3, M); ens.member(1) is compress(members[1], 0.5)
    """
    nets = _check_members(networks)
    perturbations = _member_perturbations(perturbation, len(nets))
    mesh = _resolve_devices(devices)
    settings = PathSettings() if settings is None else settings
    if method != settings.method:
        settings = PathSettings(**{**{f: getattr(settings, f) for f in settings.__dataclass_fields__}, "method": method})
    members = []
    for i, (net, pert) in enumerate(zip(nets, perturbations)):
        try:
            u_max, member_settings = _check_inputs(net, displacement, settings)
            loads = _loads(net, pert)
        except ValueError as exc:
            raise ValueError(f"member {i}: {exc}") from None
        members.append(_Member(net, loads, u_max, unload, member_settings, linear_solver, quadrature_order))
    settings = member_settings
    chunk = 25 if progress else settings.max_steps
    linsolver = _Protocol._linear_solver(members[0], linear_solver)
    if mesh is not None and type(linsolver) is DenseJacobianSolver and any(d.platform == "cpu" for d in mesh.devices.flat):
        linsolver = _MappedDenseSolver()
    runner = dict(mesh=mesh, settings=settings, linsolver=linsolver, chunk=chunk, devices=())
    status, work = _run_protocol(members, runner, progress)
    options = dict(settings=settings, u_max=u_max, unload=unload, quadrature_order=quadrature_order)
    result = _results(members, status, work, options, runner["devices"])
    if throw and not result.completed.all():
        failed = np.flatnonzero(~result.completed)
        lines = "; ".join(f"member {i}: {Status(int(result.status[i])).message} (reached u = "
                          f"{result.results[i].displacement[-1]:.4g} µm)" for i in failed[:8])
        err = ConvergenceError(f"compress_ensemble: {failed.size} of {len(result)} members did not complete "
                               f"({lines}{'; ...' if failed.size > 8 else ''}). Try method='arclength', smaller "
                               "PathSettings steps, or throw=False.")
        err.result = result
        raise err
    return result
