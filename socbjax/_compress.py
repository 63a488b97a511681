"""Displacement-controlled compression of a network by a rigid probe: :func:`compress`.

Protocol (each phase one path of :mod:`socbjax._path`, all compiled once):

0. **settle** — the network's fixed loads (e.g. the lateral perturbation) are ramped on with
   the probe free along its direction (zero probe force), so the start state is an
   equilibrium that is not a taut straight strand (an inextensible straight strand spanning
   probe and surface carries any axial force: its stiffness matrix is singular);
1. **loading** — the probe displacement u goes from the settled u₀ to ``displacement``;
2. **unloading** (``unload=True``) — u goes back to u₀.

Units: µm, pN.  The measured force is the probe's reaction along the probe direction,
compressive positive.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ._linear import SparseJacobianSolver, jacobian_solver
from ._network import Network, _add_direction
from ._newton import Status
from ._path import PathSettings, path_run, path_start, path_weights
from ._perturbation import _strands, default_perturbation, strand_perturbation
from ._quadrature import get_quadrature
from ._residual import SOCBModel, routed_nodal_force
from ._result import PHASES, CompressionResult, LimitPoint
from ._solve import ConvergenceError
from ._sparsity import prepare_structured, structure_key

__all__ = ["compress", "probe_network", "strand_perturbation"]

_UNLOAD_MARGIN = 1e-4  # unloading ends at u0 + margin × (displacement − u0)


def _is_chain(network: Network) -> bool:
    seg = np.asarray(network.segments)
    return network.n_junctions == 0 and np.array_equal(seg, np.stack([np.arange(len(seg)), np.arange(1, len(seg) + 1)], 1))


def probe_network(network: Network) -> Network:
    """``network`` itself if it has probe nodes; for a single filament (e.g.
    :func:`socbjax.column`) the last node becomes the probe, moving toward the first node."""
    if bool(np.any(np.asarray(network.probe))):
        return network
    if not _is_chain(network):
        raise ValueError(
            "the network has no probe nodes; build it with make_network(..., probe=[...]) or a builder "
            "such as socbjax.dendritic_outcrop"
        )
    pos = np.asarray(network.positions)
    direction = pos[0] - pos[-1]
    direction = direction / np.linalg.norm(direction)
    projector = np.asarray(network.position_projector).copy()
    projector[-1] = _add_direction(projector[-1:], direction)[0]
    probe = np.zeros(network.n_nodes, bool)
    probe[-1] = True
    return eqx.tree_at(
        lambda n: (n.position_projector, n.probe, n.probe_direction),
        network,
        (projector, probe, direction),  # numpy: structure stays concrete under jax.jit
    )


def _gap(network: Network) -> float:
    pos, probe = np.asarray(network.positions), np.asarray(network.probe)
    fixed = (np.einsum("nii->n", np.asarray(network.position_projector)) > 0.5) & ~probe
    if not fixed.any():
        return np.inf
    reach = (pos[fixed] - pos[probe].mean(axis=0)) @ np.asarray(network.probe_direction)
    return float(reach.max())


def _check_inputs(network, displacement, settings) -> float:
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network, got {type(network).__name__}")
    u = float(displacement)
    if not np.isfinite(u) or u <= 0:
        raise ValueError(f"displacement must be a positive probe travel (µm), got {displacement!r}")
    gap = _gap(network)
    if not np.isfinite(gap):
        raise ValueError(
            "nothing supports the network opposite the probe (no fixed node other than probe nodes): "
            "compressing it would only translate it; e.g. grow the outcrop until strands reach the surface"
        )
    if u >= gap:
        raise ValueError(
            f"displacement {u} µm reaches the opposing support (gap {gap:.4g} µm between probe and surface); "
            "choose a smaller displacement"
        )
    if settings.max_step > 0.25 * u:
        settings = eqx.tree_at(lambda s: (s.max_step, s.initial_step), settings, (0.25 * u, min(settings.initial_step, 0.25 * u)))
    return u, settings


def _loads(network: Network, perturbation) -> np.ndarray:
    loads = np.asarray(network.loads)
    if perturbation is not None:
        magnitude = float(perturbation)
        if not np.isfinite(magnitude) or magnitude < 0:
            raise ValueError(f"perturbation must be a non-negative force (pN), got {perturbation!r}")
        return loads + strand_perturbation(network, magnitude)
    if np.any(loads != 0):
        return loads
    magnitude = default_perturbation(network.EI, network.lengths, _strands(network))
    return strand_perturbation(network, float(magnitude))


class _Problem(eqx.Module):
    """Everything a phase needs, as one pytree (the compiled phase is shared by all phases)."""

    model: SOCBModel
    loads: jax.Array
    control0: jax.Array  # (λ, u) at p = 0
    control1: jax.Array  # (λ, u) at p = 1

    def make_F(self, unravel):
        def make(x_ref):
            frames = self.model.frames(unravel(x_ref))

            def F(x, p):
                lam, u = self.control0 + p * (self.control1 - self.control0)
                return self.model.residual(unravel(x), lam * self.loads, frames, u)

            return F

        return make


def traced_settings(settings):
    """``settings`` with its numeric fields as arrays: ``eqx.filter_jit`` traces arrays but
    holds Python numbers static, so new step sizes or caps would otherwise recompile."""
    def leaf(v):
        return v if isinstance(v, bool) else jnp.asarray(v)

    return jax.tree_util.tree_map(leaf, settings)


@eqx.filter_jit
def _start(problem, x0, weights, linsolver, settings):
    _, unravel = ravel_pytree(problem.model.initial_state())
    return path_start(problem.make_F(unravel), x0, weights, linsolver, settings)


@eqx.filter_jit
def _run(problem, carry, weights, p_scale, linsolver, settings, chunk):
    _, unravel = ravel_pytree(problem.model.initial_state())
    return path_run(problem.make_F(unravel), carry, weights, p_scale, linsolver, settings, chunk)


@eqx.filter_jit
def _observe(model, X, U, loads):
    """Per recorded step: positions, tangents, moments, segment forces, probe force, end forces."""
    net = model.network
    _, unravel = ravel_pytree(model.initial_state())

    def one(x, u):
        st = unravel(x)
        reaction = routed_nodal_force(st.forces, net, loads)
        axial = reaction @ net.probe_direction
        probe_force = jnp.sum(jnp.where(net.probe, axial, 0.0))
        if net.dim == 2:
            t = jnp.stack([jnp.cos(st.directors), jnp.sin(st.directors)], -1)
        else:
            t = st.directors / jnp.linalg.norm(st.directors, axis=-1, keepdims=True)
        return st.positions, t, st.moments, st.forces, probe_force, -axial

    return jax.vmap(one)(X, U)


class _Progress:
    def __init__(self, enabled: bool, total: float):
        self.enabled, self.total = enabled, total

    def __call__(self, phase: str, u: float, steps: int, done: bool = False):
        if not self.enabled:
            return
        frac = min(max(u / self.total, 0.0), 1.0) if self.total else 1.0
        bar = "#" * int(30 * frac)
        end = "\n" if done else ""
        sys.stderr.write(f"\r{phase:>9s} [{bar:<30s}] u = {u:8.4f} µm  steps {steps:5d}{end}")
        sys.stderr.flush()


def _fingerprint(network, loads, displacement, unload, settings, quadrature_order) -> str:
    h = hashlib.sha256()
    for leaf in jax.tree_util.tree_leaves(network):
        h.update(np.ascontiguousarray(np.asarray(leaf)).tobytes())
    h.update(np.ascontiguousarray(loads).tobytes())
    h.update(repr((float(displacement), bool(unload), settings, quadrature_order)).encode())
    return h.hexdigest()


def _phase_plan(u0: float, u_max: float, unload: bool):
    plan = [("loading", (1.0, u0), (1.0, u_max))]
    if unload:
        plan.append(("unloading", (1.0, u_max), (1.0, u0)))
    return plan


def _carry_to_numpy(carry) -> dict:
    return {f"carry/{k}": np.asarray(v) for k, v in carry.items()}


def _run_phase(problem, carry, weights, p_scale, linsolver, settings, chunk, report, save):
    """Chunked while-loop over one phase; ``report(p, steps, done)`` and ``save(carry)`` run
    between chunks on the host."""
    while int(carry["status"]) == -1:
        carry = _run(problem, carry, weights, jnp.asarray(p_scale), linsolver, settings, jnp.asarray(chunk))
        running = int(carry["status"]) == -1
        report(float(carry["p"]), int(carry["steps"]), not running)
        if running:
            save(carry)
    return carry


def _records(carry, u0, u1, phase):
    k = int(carry["steps"])
    return dict(
        X=np.asarray(carry["X"][:k]),
        U=u0 + np.asarray(carry["P"][:k]) * (u1 - u0),
        SIGN=np.asarray(carry["SIGN"][:k]),
        ITER=np.asarray(carry["ITER"][:k]),
        PHASE=np.full(k, phase, np.int8),
    )


def _concat(parts: list[dict]) -> dict:
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _limit_points(U, F, SIGN, PHASE) -> list[LimitPoint]:
    """Events between consecutive recorded steps of each phase (see :class:`LimitPoint`)."""
    events = []
    for phase in (1, 2):
        idx = np.flatnonzero(PHASE == phase)
        if not idx.size or idx[0] == 0:
            continue
        idx = np.concatenate([[idx[0] - 1], idx])  # start from the phase's first point
        name = PHASES[phase]
        du, dF = np.diff(U[idx]), np.diff(F[idx])
        tiny = 1e-9 * max(float(np.abs(F[idx]).max()), 1e-300)
        su = np.sign(np.where(np.abs(du) > 1e-12, du, 0.0))
        sF = np.sign(np.where(np.abs(dF) > tiny, dF, 0.0))  # force rising or falling along the path
        folds = set()
        for j in range(1, len(du)):
            at = int(idx[j])
            if su[j] * su[j - 1] < 0:
                folds.add(at)
                events.append(LimitPoint("fold", at, float(U[at]), float(F[at]), name))
            elif sF[j] * sF[j - 1] < 0:
                kind = "force_maximum" if sF[j - 1] > 0 else "force_minimum"
                events.append(LimitPoint(kind, at, float(U[at]), float(F[at]), name))
        for j in range(len(du)):
            a, b = int(idx[j]), int(idx[j + 1])
            if SIGN[a] != SIGN[b] and not folds & {a, b}:
                events.append(LimitPoint("bifurcation", b, float(U[b]), float(F[b]), name))
    return sorted(events, key=lambda e: e.step)


def compress(
    network: Network,
    displacement: float,
    *,
    unload: bool = False,
    method: str = "displacement",
    perturbation: float | None = None,
    settings: PathSettings | None = None,
    linear_solver: str = "auto",
    quadrature_order: int = 8,
    progress: bool = False,
    checkpoint: str | Path | None = None,
    checkpoint_every: int = 50,
    resume: bool = False,
    throw: bool = True,
    parameters: dict | None = None,
    at=None,
) -> CompressionResult:
    """Compress ``network`` with its probe by ``displacement`` µm (and withdraw it if ``unload``).

    Parameters
    ----------
    network : a network with probe nodes (e.g. :func:`socbjax.dendritic_outcrop`), or a single
        filament such as :func:`socbjax.column`, whose last node then becomes the probe and
        moves toward the first (its lateral support is kept: "free" = frictionless push).
    displacement : total probe travel (µm) from the as-built probe position; must be smaller
        than the probe–surface gap.
    unload : then withdraw the probe back toward the settled start u₀, stopping at
        u₀ + 1e-4 (displacement − u₀) (reversibility, hysteresis; see the source for why).
    method : "displacement" (natural-parameter control; stops with ``Status.CRITICAL_POINT`` at
        a fold) or "arclength" (pseudo-arclength: follows folds and snap-backs).  Overrides
        ``settings.method``.
    perturbation : lateral force (pN) on the middle node of every strand, added to the
        network's ``loads``.  Default: the network's loads or, if it has none, 1e-4 EI/L² per
        strand (L: the longest strand) — an imperfection is needed: a straight inextensible
        strand between probe and surface carries any axial force (singular stiffness).
    settings : :class:`PathSettings` (steps in µm; max step capped at displacement/4).
    linear_solver : "dense", "sparse" (coloured Jacobian + sparse LU) or "auto".
    progress : print a progress bar over continuation steps to stderr.
    checkpoint, checkpoint_every : write the run's state to this HDF5 file every N accepted
        steps (atomically); ``resume=True`` continues from it and ends with the same curve as
        an uninterrupted run.
    throw : raise :class:`ConvergenceError` when the protocol does not complete (the partial
        result is ``error.result``); with ``throw=False`` check ``result.completed``.
    parameters : extra JSON-able metadata stored in the result (e.g. builder arguments).
    at : probe displacements (µm, [M]) at which to return the equilibria instead of the
        adaptive path steps: the path is still followed adaptively (host side), then each
        requested point is solved exactly, warm-started from the path.  These points are
        differentiable (implicit function theorem, never unrolled Newton) with respect to
        ``at`` and to the network's ``EI``, ``lengths``, ``positions``, ``tangents``,
        ``loads`` and ``perturbation``.  Under ``jax.grad`` / ``jax.jacfwd`` / ``jax.vmap``
        / ``jax.jit`` (traced inputs) ``at`` defaults to 64 equal steps up to
        ``displacement``.  See :func:`socbjax._sampled.compress_at` for the details.
    """
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (e.g. socbjax.column(...)), got {type(network).__name__}")
    options = dict(unload=unload, method=method, perturbation=perturbation, settings=settings,
                   linear_solver=linear_solver, quadrature_order=quadrature_order, progress=progress)
    if at is not None or _traced(network, perturbation):
        from ._sampled import compress_at

        return compress_at(network, displacement, at, throw=throw, parameters=parameters, **options)
    protocol, status, network, options = run_protocol(
        network, displacement, **options, checkpoint=checkpoint, checkpoint_every=checkpoint_every, resume=resume
    )
    result = _package(protocol.model, protocol.loads, _concat(protocol.parts), protocol.extra, status, network, parameters, options)
    if throw and not result.completed:
        err = ConvergenceError(
            f"compress stopped: {result.status_message} (reached u = {result.displacement[-1]:.4g} µm, "
            f"{result.n_steps} steps). Try method='arclength', smaller PathSettings steps, or throw=False."
        )
        err.result = result
        raise err
    return result


def _traced(*trees) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(trees))


def run_protocol(network, displacement, *, unload, method, perturbation, settings, linear_solver, quadrature_order,
                 progress=False, checkpoint=None, checkpoint_every=50, resume=False):
    """Validate the inputs and run the settle/loading/unloading phases on the host (concrete
    arrays only).  Returns (protocol with its records, status, probed network, options)."""
    network = probe_network(network)
    settings = PathSettings() if settings is None else settings
    if method != settings.method:
        settings = PathSettings(**{**{f: getattr(settings, f) for f in settings.__dataclass_fields__}, "method": method})
    u_max, settings = _check_inputs(network, displacement, settings)
    if resume and checkpoint is None:
        raise ValueError("resume=True needs checkpoint=<path of the checkpoint file>")
    if int(checkpoint_every) < 1:
        raise ValueError(f"checkpoint_every must be a positive number of steps, got {checkpoint_every!r}")
    protocol = _Protocol(network, _loads(network, perturbation), u_max, unload, settings, linear_solver, quadrature_order)
    protocol.checkpoint, protocol.progress = checkpoint, _Progress(progress, u_max)
    protocol.chunk = int(checkpoint_every) if (checkpoint or progress) else settings.max_steps
    if resume and Path(checkpoint).exists():
        protocol.resume()
    status = protocol.run()
    options = dict(settings=settings, u_max=u_max, unload=unload, quadrature_order=quadrature_order)
    return protocol, status, network, options


def _path_geometry(model) -> jax.Array:
    """Norm weights of the state: node positions and directors (× mean segment length, so in
    µm); moments and forces grow along any path and would hide a jump between branches."""
    zeros = jax.tree_util.tree_map(jnp.zeros_like, model.initial_state())
    ell = jnp.mean(model.network.lengths)
    ones = (jnp.ones_like(zeros.positions), jnp.full_like(zeros.directors, ell**2))
    return ravel_pytree(eqx.tree_at(lambda st: (st.positions, st.directors), zeros, ones))[0]


class _Protocol:
    """The settle / loading / unloading phases of one compression, with checkpoints."""

    def __init__(self, network, loads, u_max, unload, settings, linear_solver, quadrature_order):
        self.network, self.loads, self.u_max, self.settings = network, jnp.asarray(loads), u_max, settings
        self.model = SOCBModel(network, get_quadrature(quadrature_order))
        self.x0, self.unravel = ravel_pytree(self.model.initial_state())
        self.geometry = _path_geometry(self.model)
        axial = jnp.outer(network.probe_direction, network.probe_direction)
        free = eqx.tree_at(
            lambda n: n.position_projector, network,
            network.position_projector - jnp.where(network.probe[:, None, None], axial, 0.0),
        )  # settle: the probe is free along its direction
        self.settle = _Problem(SOCBModel(free, self.model.quad), self.loads, jnp.array([0.0, 0.0]), jnp.array([1.0, 0.0]))
        self.linsolver = self._linear_solver(linear_solver)
        self.names = ["settle", "loading"] + (["unloading"] if unload else [])
        self.fingerprint = _fingerprint(network, np.asarray(loads), u_max, unload, settings, quadrature_order)
        self.start, self.saved, self.extra, self.parts = 0, None, {}, []
        self.checkpoint, self.progress, self.chunk = None, _Progress(False, u_max), settings.max_steps

    def _linear_solver(self, kind):
        backend = jacobian_solver(kind, self.x0.size)
        F_settle = self.settle.make_F(self.unravel)(self.x0)
        if not isinstance(backend, SparseJacobianSolver):
            return backend.prepare(lambda y: F_settle(y, 0.5), self.x0)
        # The pattern must cover both the settle and the loading residuals (probe rows differ).
        F_load = self._problem(0.0, 0.1).make_F(self.unravel)(self.x0)
        return prepare_structured([lambda y: F_settle(y, 0.5), lambda y: F_load(y, 0.5)], self.x0, self.model.structure(),
                                  cache_key=structure_key(self.network, "protocol"))

    def _problem(self, u_from, u_to):
        return _Problem(self.model, self.loads, jnp.array([1.0, u_from]), jnp.array([1.0, u_to]))

    def resume(self):
        from ._io import load_checkpoint

        arrays, meta = load_checkpoint(self.checkpoint)
        if meta.get("fingerprint") != self.fingerprint:
            raise ValueError(f"checkpoint {self.checkpoint} belongs to a different run (network, loads or settings differ)")
        self.start = int(meta["phase_index"])
        self.saved = {k[6:]: jnp.asarray(v) for k, v in arrays.items() if k.startswith("carry/")}
        self.extra = {k[6:]: v for k, v in arrays.items() if k.startswith("extra/")}
        records = {k[8:]: v for k, v in arrays.items() if k.startswith("records/")}
        self.parts = [records] if "X" in records else []

    def _save(self, index, carry):
        if not self.checkpoint:
            return
        from ._io import save_checkpoint

        arrays = _carry_to_numpy(carry)
        arrays.update({f"extra/{k}": np.asarray(v) for k, v in self.extra.items()})
        if self.parts:
            arrays.update({f"records/{k}": v for k, v in _concat(self.parts).items()})
        save_checkpoint(self.checkpoint, arrays, {"fingerprint": self.fingerprint, "phase_index": index})

    def _phase(self, index):
        """(problem, p-scale µm, start state, (u at p = 0, u at p = 1)) of a phase."""
        if index == 0:
            return self.settle, 4.0 * self.settings.max_step, self.x0, (0.0, 0.0)
        u0 = float(self.extra["u0"])
        # Unloading stops just short of the settled start: there the strands are straight
        # again and the stiffness turns singular (the force falls from ~Euler to 0 over a
        # vanishing displacement), which no step size resolves reliably.
        ends = (u0, self.u_max) if index == 1 else (self.u_max, u0 + _UNLOAD_MARGIN * (self.u_max - u0))
        return self._problem(*ends), abs(ends[1] - ends[0]), jnp.asarray(self.parts[-1]["X"][-1]), ends

    def _finish(self, index, carry, ends):
        if index == 0:  # only the settled end state is part of the curve
            k = int(carry["steps"])
            x_settled = np.asarray(carry["X"][k - 1]) if k else np.asarray(self.x0)
            moved = self.unravel(jnp.asarray(x_settled)).positions - self.network.positions
            self.extra["u0"] = float(np.mean(np.asarray(moved[self.network.probe] @ self.network.probe_direction)))
            self.parts = [dict(X=x_settled[None], U=np.array([self.extra["u0"]]), SIGN=np.zeros(1), ITER=np.array([k], np.int32), PHASE=np.zeros(1, np.int8))]
            return
        if index == 1:
            self.extra["sign_ref"] = float(carry["sign0"])
            self.parts[0]["SIGN"] = np.array([self.extra["sign_ref"]])
        self.parts.append(_records(carry, *ends, index))

    def run(self) -> int:
        status = Status.CONVERGED
        for index in range(self.start, len(self.names)):
            problem, scale, x_start, ends = self._phase(index)
            weights = path_weights(self.x0, self.geometry, self.network.n_nodes, scale)
            resumed = self.saved is not None and index == self.start
            settings = traced_settings(self.settings)
            carry = self.saved if resumed else _start(problem, x_start, weights, self.linsolver, settings)

            def report(p, steps, done, name=self.names[index], ends=ends):
                self.progress(name, ends[0] + p * (ends[1] - ends[0]), steps, done)

            carry = _run_phase(problem, carry, weights, scale, self.linsolver, settings, self.chunk, report, lambda c, i=index: self._save(i, c))
            status = int(carry["status"])
            self._finish(index, carry, ends)
            if status != Status.CONVERGED:
                break
        return status


def _package(model, loads, rec, extra, status, network, parameters, options) -> CompressionResult:
    X, U = jnp.asarray(rec["X"]), jnp.asarray(rec["U"])
    positions, tangents, moments, forces, probe_force, axial = (np.asarray(a) for a in _observe(model, X, U, loads))
    fixed = np.einsum("nii->n", np.asarray(network.position_projector)) > 0.5
    ends = np.flatnonzero(fixed & ~np.asarray(network.probe) & ~np.asarray(network.attached))
    sign_ref = extra.get("sign_ref", rec["SIGN"][0])
    settings = options["settings"]
    params = {
        "displacement_um": options["u_max"],
        "unload": bool(options["unload"]),
        "method": settings.method,
        "quadrature_order": options["quadrature_order"],
        "settled_displacement_um": float(extra.get("u0", 0.0)),
        "perturbation_pN": float(np.abs(np.asarray(loads)).sum(axis=-1).max()),
        "settings": {f: getattr(settings, f) for f in settings.__dataclass_fields__},
        "n_nodes": int(network.n_nodes),
        "n_segments": int(network.n_segments),
        "n_junctions": int(network.n_junctions),
        "gap_um": _gap(network) if np.isfinite(_gap(network)) else None,
        **(parameters or {}),
    }
    return CompressionResult(
        displacement=np.asarray(rec["U"]),
        force=probe_force,
        converged=np.ones(len(rec["U"]), bool),
        stable=rec["SIGN"] == sign_ref,
        phase=rec["PHASE"].astype(np.int8),
        positions=positions,
        tangents=tangents,
        moments=moments,
        segment_forces=forces,
        end_nodes=ends,
        end_forces=axial[:, ends],
        iterations=rec["ITER"].astype(np.int32),
        limit_points=_limit_points(np.asarray(rec["U"]), probe_force, rec["SIGN"], rec["PHASE"]),
        status=int(status),
        network=network,
        parameters=json.loads(json.dumps(params, default=float)),
    )
