"""Ensembles of compressions: one compiled, vmapped continuation for a batch of networks of
identical topology, optionally sharded across devices: :func:`compress_ensemble`.

The members share their :class:`socbjax.Topology` (which fixes the compiled program and the
Jacobian's sparsity); the values of ``positions``, ``tangents``, ``lengths``, ``EI``,
``loads`` and ``couples`` (and the perturbation) may differ — one outcrop under many EI
values, many imperfection patterns or magnitudes, or geometric variants of one topology.

Each phase of the :func:`socbjax.compress` protocol (settle, loading, unloading) is one
compiled call: ``jax.vmap`` of :func:`socbjax._path.follow_path` over the batch axis (the
members are one stacked :class:`Network` pytree), and the three phases share one compiled
program.  The vmapped loop runs until its slowest member is done; finished members idle
(their updates are masked), and every Newton iteration factors all B Jacobians (dense: one
batched LU; sparse: one SuperLU callback per member).  Between phases the host reads the step
records and builds the next phase (the per-member settled displacement u₀ sets the loading
endpoints).

With ``devices`` the batch axis is split over a 1-D ``jax.sharding.Mesh`` (axis "batch") by
``jax.shard_map``: each device runs its own vmapped while-loops on B/D members, with no
cross-device communication inside the loop.  See ``docs/scaling.md``.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Sequence

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from ._probe import (applied_loads, check_compress_inputs, check_compress_options, compress_settings, package_path,
                     probe_network)
from ._linear import DenseLU, lu_sign
from ._network import Network, is_traced
from ._path import StepRecorder, follow_path, start_path
from ._protocol import UNLOAD_MARGIN, phase_problem, settled_displacement
from ._quadrature import get_quadrature
from ._residual import SOCBModel
from ._result import CompressionResult
from ._sampled import compress_at
from ._solution import RESULTS, ConvergenceError, result_from_name, result_message, result_name
from ._sparsity import linear_solver_for

__all__ = ["EnsembleResult", "compress_ensemble"]


class EnsembleResult(eqx.Module):
    """The compressions of an ensemble; see :func:`compress_ensemble`.

    displacement, force : [B, M] probe displacement (µm) and probe force along the probe
        direction (pN, compressive positive) of each member's recorded path (settle point,
        loading, unloading), padded with NaN after the member's ``n_steps[b]`` rows.
    phase : [B, M] int8, 0 settle, 1 loading, 2 unloading, −1 padding.
    n_steps : [B] recorded steps per member.
    results : the B members as :class:`CompressionResult` (unpadded; also ``member(i)``);
        ``member(i).result`` is member i's :class:`socbjax.RESULTS` item.
    attempts, newton_iterations : [B, phases] attempted steps (accepted and rejected) and
        Newton iterations of each member per phase (0 for phases not reached).
    devices : the devices that held the batch.
    """

    displacement: np.ndarray
    force: np.ndarray
    phase: np.ndarray
    n_steps: np.ndarray
    results: tuple
    attempts: np.ndarray
    newton_iterations: np.ndarray
    devices: tuple = eqx.field(static=True, default=())

    @property
    def completed(self) -> np.ndarray:
        """[B] bool: member completed every phase."""
        return np.array([r.completed for r in self.results])

    @property
    def result(self):
        """The first failure among the members (``RESULTS.successful`` if none failed)."""
        for r in self.results:
            if not r.completed:
                return r.result
        return RESULTS.successful

    def member(self, i: int) -> CompressionResult:
        return self.results[i]

    def __len__(self) -> int:
        return len(self.results)

    def __repr__(self) -> str:
        n, steps, devices = len(self), int(self.n_steps.max()), len(self.devices)
        return (f"EnsembleResult({n} member{'' if n == 1 else 's'}, {int(self.completed.sum())} completed, "
                f"at most {steps} step{'' if steps == 1 else 's'}, {devices} device{'' if devices == 1 else 's'})")


# --------------------------------------------------------------------------- validation
def _check_members(networks) -> list[Network]:
    if isinstance(networks, Network) or not isinstance(networks, Sequence):
        raise TypeError("networks must be a sequence (list or tuple) of socbjax Networks of identical topology")
    if not len(networks):
        raise ValueError("networks is empty: an ensemble needs at least one member")
    for i, net in enumerate(networks):
        if not isinstance(net, Network):
            raise TypeError(f"member {i} of networks is a {type(net).__name__}, not a socbjax Network")
    for i, net in enumerate(networks[1:], 1):
        if net.topology != networks[0].topology:
            raise ValueError(
                f"member {i} differs from member 0 in its topology ({_difference(networks[0], net)}): the members of an "
                "ensemble must share dimension, segments, junctions, strands, supports and probe; only the values of "
                "positions, tangents, lengths, EI, loads, couples and natural_curvature may differ (group networks of different topology "
                "into separate ensembles)"
            )
    return list(networks)


def _difference(a: Network, b: Network) -> str:
    if a.dim != b.dim:
        return f"dim {a.dim} vs {b.dim}"
    for name in ("segments", "attach", "strand", "clamped", "probe", "position_projector", "probe_direction"):
        x, y = getattr(a, name), getattr(b, name)
        if x.shape != y.shape or not np.array_equal(x, y):
            return name
    return "structure"


def _member_perturbations(perturbation, B: int) -> list:
    if perturbation is None or np.ndim(perturbation) == 0:
        return [perturbation] * B
    if is_traced(perturbation) and np.ndim(perturbation) == 1 and np.shape(perturbation)[0] == B:
        return [perturbation[i] for i in range(B)]
    values = list(np.asarray(perturbation, dtype=float).ravel()) if np.ndim(perturbation) == 1 else None
    if values is None or len(values) != B:
        raise ValueError(f"perturbation must be None, one force (pN) or one per member ({B}), got shape {np.shape(perturbation)}")
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
def _mapped_lu(J):
    lu, piv = jax.scipy.linalg.lu_factor(J)
    return lu, piv


@_mapped_lu.def_vmap
def _mapped_lu_vmap(axis_size, in_batched, J):
    J = J if in_batched[0] else jnp.broadcast_to(J, (axis_size, *J.shape))
    return jax.lax.map(_mapped_lu, J), (True, True)


class MappedDenseLU(DenseLU):
    """:class:`DenseLU` whose factorisation runs one matrix at a time under ``vmap``.

    jaxlib's batched CPU LU splits the batch over XLA's intra-op thread pool and waits inside
    a pool worker; when several host devices (``--xla_force_host_platform_device_count``)
    each run such a batched LU, all workers can end up waiting and the program deadlocks
    (observed with 2 host devices on 2 cores).  Sharded CPU ensembles therefore factor their
    members in a ``lax.map`` loop (the same LAPACK call per matrix, so the same numbers)."""

    def from_products(self, products, n):
        lu, piv = _mapped_lu(products.T)
        return lu, piv, lu_sign(lu, piv), eqxi.Static(False)


def _phase_body(models, index, u0s, u_max, xs, states, live, settings, chunk, *, inner, recorder):
    def one(model, u0, x, state, alive):
        if state is None:
            state = eqx.tree_at(lambda s: s.done, start_path(x, 0.0, settings, recorder), ~alive)
        problem = phase_problem(model, index, u0, u_max, settings)
        return follow_path(problem, state, settings, inner, recorder, stop_after=chunk)

    return jax.vmap(one)(models, u0s, xs, states, live)


@eqx.filter_jit
def _phase(models, index, u0s, u_max, xs, states, live, settings, chunk, inner, recorder, mesh):
    body = functools.partial(_phase_body, inner=inner, recorder=recorder)
    args = (models, index, u0s, u_max, xs, states, live, settings, chunk)
    if mesh is None:
        return body(*args)
    specs = (P("batch"), P(), P("batch"), P(), P("batch"), P("batch"), P("batch"), P(), P())
    return jax.shard_map(body, mesh=mesh, in_specs=specs, out_specs=P("batch"), check_vma=False)(*args)


def _place(tree, mesh, spec):
    """Global arrays laid out by ``spec`` over ``mesh`` (each process supplies its shards)."""
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


def _pad(items: list, size: int) -> list:
    return items + [items[0]] * (size - len(items))


def _stack(trees):
    return jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *trees)


class _Batch:
    """The phases of every member, run as one vmapped (optionally sharded) program."""

    def __init__(self, models, u_max, unload, settings, inner, mesh, progress):
        self.B, self.mesh, self.settings, self.u_max = len(models), mesh, settings, float(u_max)
        self.size = self.B if mesh is None else -(-self.B // mesh.size) * mesh.size
        self.models = _place(_stack(_pad(models, self.size)), mesh, P("batch"))
        self.inner, self.recorder, self.progress = inner, StepRecorder(settings.max_steps), progress
        self.chunk = 25 if progress else settings.max_steps
        self.names = ["settle", "loading"] + (["unloading"] if unload else [])
        self.x = [ravel_pytree(m.initial_state())[0] for m in models]
        self.u0, self.sign_ref = np.zeros(self.B), np.zeros(self.B)
        self.status = ["successful"] * self.B
        self.parts = [[] for _ in range(self.B)]
        self.work = np.zeros((self.B, len(self.names), 2), np.int64)
        self.devices = ()

    def _run(self, index, live):
        shared = _place((jnp.asarray(index), jnp.asarray(self.u_max), self.settings.traced(), jnp.asarray(self.chunk)),
                        self.mesh, P())
        batched = _place((jnp.asarray(_pad(list(self.u0), self.size)), jnp.stack(_pad(self.x, self.size)),
                          jnp.asarray(_pad(list(live), self.size))), self.mesh, P("batch"))
        args = dict(inner=self.inner, recorder=self.recorder, mesh=self.mesh)
        state = _phase(self.models, shared[0], batched[0], shared[1], batched[1], None, batched[2], shared[2], shared[3], **args)
        while True:
            done = _to_host(state.done)[: self.B]
            if self.progress:
                sys.stderr.write(f"\r{self.names[index]:>9s}: {int(done.sum())}/{self.B} members done, "
                                 f"steps {int(_to_host(state.steps).max()):5d}")
                sys.stderr.flush()
            if done.all():
                break
            state = _phase(self.models, shared[0], batched[0], shared[1], batched[1], state, batched[2], shared[2], shared[3], **args)
        if self.progress:
            sys.stderr.write("\n")
        self.devices = tuple(str(d) for d in state.done.sharding.device_set)
        return state

    def _finish(self, index, state, b):
        k = int(_to_host(state.steps)[b])
        rec = {name: _to_host(v)[b, :k] for name, v in vars(state.recorder).items()}
        x = _to_host(state.x)[b]
        self.work[b, index] = int(_to_host(state.attempts)[b]), int(_to_host(state.iterations)[b])
        self.status[b] = result_name(jax.tree_util.tree_map(lambda a: _to_host(a)[b], state.result))
        if index == 0:
            self.u0[b] = float(settled_displacement(jax.tree_util.tree_map(lambda a: a[b], self.models), jnp.asarray(x)))
            self.parts[b] = [dict(X=x[None], U=np.array([self.u0[b]]), SIGN=np.zeros(1), ITER=np.array([k], np.int32),
                                  PHASE=np.zeros(1, np.int8))]
        else:
            if index == 1:
                self.sign_ref[b] = float(_to_host(state.sign0)[b])
                self.parts[b][0]["SIGN"] = np.array([self.sign_ref[b]])
            u0 = self.u0[b]
            u_from, u_to = (u0, self.u_max) if index == 1 else (self.u_max, u0 + UNLOAD_MARGIN * (self.u_max - u0))
            self.parts[b].append(dict(X=rec["X"], U=u_from + rec["P"] * (u_to - u_from), SIGN=rec["SIGN"],
                                      ITER=rec["ITER"], PHASE=np.full(k, index, np.int8)))
        self.x[b] = jnp.asarray(x)

    def run(self):
        for index in range(len(self.names)):
            live = np.array([s == "successful" for s in self.status])
            if not live.any():
                break
            state = self._run(index, live)
            for b in np.flatnonzero(live):
                self._finish(index, state, int(b))


# ----------------------------------------------------------------------------- results
def _results(batch: _Batch, models, settings, unload) -> EnsembleResult:
    recs = [{k: np.concatenate([p[k] for p in parts]) for k in parts[0]} for parts in batch.parts]
    M = max(len(r["U"]) for r in recs)
    results = [package_path(model, rec, {"u0": batch.u0[b], "sign_ref": batch.sign_ref[b]}, result_from_name(batch.status[b]),
                            settings, batch.u_max, unload, None) for b, (model, rec) in enumerate(zip(models, recs))]
    B = len(results)
    disp, force, phase = np.full((B, M), np.nan), np.full((B, M), np.nan), np.full((B, M), -1, np.int8)
    for b, r in enumerate(results):
        disp[b, : r.n_steps], force[b, : r.n_steps], phase[b, : r.n_steps] = r.displacement, r.force, r.phase
    return EnsembleResult(disp, force, phase, np.array([r.n_steps for r in results]), tuple(results),
                          batch.work[..., 0], batch.work[..., 1], batch.devices)


def _where(member) -> str:
    """Why a member did not complete, and where (µm)."""
    crossing = member.first_crossing
    at = (f"first crossing at u = {crossing.displacement:.4g} µm" if crossing is not None
          else f"reached u = {member.displacement[-1]:.4g} µm")
    return f"{result_message(member.result)} ({at})"


# -------------------------------------------------------------------------------- API
def _sampled_ensemble(nets, displacement, at, unload, perturbations, settings, throw) -> EnsembleResult:
    """The members sampled at ``at``: ``jax.vmap`` of the traced ``compress(..., at=...)``
    over the stacked members (one compiled program; jit/grad/jacfwd/vmap apply)."""
    quad = get_quadrature(settings.quadrature_order)
    nets = [probe_network(n) for n in nets]
    members = [n.replace(loads=applied_loads(n, p)) for n, p in zip(nets, perturbations)]
    stacked = _stack(members)

    def one(net):
        return compress_at(SOCBModel(net, quad), displacement, at, unload=unload, settings=settings, throw=throw)

    batched = jax.vmap(one)(stacked)
    B = len(members)
    results = tuple(jax.tree_util.tree_map(lambda a, i=i: a[i], batched) for i in range(B))
    zeros = np.zeros((B, 3 if unload else 2), np.int64)
    M = batched.displacement.shape[1]
    return EnsembleResult(batched.displacement, batched.force, batched.phase, np.full(B, M), results, zeros, zeros)


def compress_ensemble(networks: Sequence[Network], displacement: float, *, at=None, unload: bool = False,
                      method: str | None = None, perturbation=None, settings=None, devices=None, progress: bool = False,
                      throw: bool = True) -> EnsembleResult:
    """Compress every network of an ensemble by ``displacement`` µm: the protocol of
    :func:`socbjax.compress`, run for the whole batch as one compiled, vmapped continuation.

    Parameters
    ----------
    networks : B networks of identical :class:`socbjax.Topology`: only the values of
        ``positions``, ``tangents``, ``lengths``, ``EI``, ``loads`` and ``couples`` may
        differ.  Typical: one outcrop under many EI values or imperfection patterns
        (``net.replace(loads=sj.strand_perturbation(net, f, seed=k))``).  Outcrops grown from
        different seeds differ in topology: they are separate ensembles.
    displacement : probe travel (µm), the same for every member; must stay below each
        member's probe–surface gap.
    at : probe displacements (µm, [M]) at which to sample every member, as
        ``compress(..., at=...)`` does: then the whole ensemble is one traced, vmapped program
        (``jax.jit``, ``jax.grad``, ``jax.jacfwd``, ``jax.vmap`` apply; derivatives by the
        implicit function theorem) and the result's curves are [B, M] (``attempts`` and
        ``newton_iterations`` are zero).  Traced inputs imply ``at`` (64 equal steps).
    unload, method, settings : as for :func:`socbjax.compress` (one Jacobian-solver
        preparation serves the batch).
    perturbation : None (each member's loads, else the default 1e-4 EI/L² per strand), one
        lateral force (pN) for all members, or a sequence of B forces.
    devices : None (the default device), an int (the first n of ``jax.devices()``) or a
        list of jax devices: the batch axis is sharded over them with ``jax.shard_map`` (B
        padded to a multiple of their number).  Several hosts: call
        ``jax.distributed.initialize()`` first in every process, build the same B networks
        in each, and pass ``devices=jax.devices()``.  On a CPU,
        ``XLA_FLAGS=--xla_force_host_platform_device_count=N`` (set before jax starts) splits
        it into N devices.  See ``docs/scaling.md``.
    progress : report the members still running to stderr (the phases then run in chunks
        of 25 steps; the curves are identical).
    throw : raise :class:`socbjax.ConvergenceError` naming the members that did not complete
        (``error.result`` holds the ensemble); with ``throw=False`` check ``result.completed``.

    Returns an :class:`EnsembleResult`: curves [B, M] padded with NaN, ``n_steps`` [B], and
    each member as a :class:`CompressionResult` (``result.member(i)``), equal to
    ``socbjax.compress(networks[i], ...)`` up to round-off.
    """
    check_compress_options(unload=unload, method=method, throw=throw, progress=progress)  # before any work
    nets = _check_members(networks)
    perturbations = _member_perturbations(perturbation, len(nets))
    settings = compress_settings(settings, method, displacement)
    if at is not None or is_traced(nets, perturbation, displacement):
        if devices is not None:
            raise ValueError("devices applies to full paths; for sampled ensembles shard the inputs of your jitted function")
        return _sampled_ensemble(nets, displacement, at, unload, perturbations, settings, throw)
    mesh = _resolve_devices(devices)
    models = []
    for i, (net, pert) in enumerate(zip(nets, perturbations)):
        try:
            net, u_max = check_compress_inputs(net, displacement)
        except ValueError as exc:
            raise ValueError(f"member {i}: {exc}") from None
        try:
            loads = applied_loads(net, pert)
        except ValueError as exc:
            raise ValueError(f"member {i}: {exc}") from None
        models.append(SOCBModel(net.replace(loads=loads), get_quadrature(settings.quadrature_order)))
    inner = linear_solver_for(models[0], settings.linear_solver)
    if mesh is not None and type(inner) is DenseLU and any(d.platform == "cpu" for d in mesh.devices.flat):
        inner = MappedDenseLU()
    batch = _Batch(models, u_max, unload, settings, inner, mesh, progress)
    batch.run()
    result = _results(batch, models, settings, unload)
    if throw and not result.completed.all():
        failed = np.flatnonzero(~result.completed)
        lines = "; ".join(f"member {i}: {_where(result.results[i])}" for i in failed[:8])
        err = ConvergenceError(f"compress_ensemble: {failed.size} of {len(result)} members did not complete "
                               f"({lines}{'; ...' if failed.size > 8 else ''}). Try method='arclength', smaller "
                               "PathSettings steps, or throw=False.")
        err.result = result
        raise err
    return result
