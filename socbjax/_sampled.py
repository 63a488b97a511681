"""Compression sampled at prescribed probe displacements, differentiable end to end:
``socbjax.compress(network, displacement, at=...)``.

Two stages:

1. **Path (host, not differentiated).**  The adaptive continuation of
   :func:`socbjax.compress` runs on concrete values (``jax.pure_callback`` when the inputs are
   traced), following buckling and collapse with cut-back steps.  For every requested
   displacement uᵢ it hands back a warm start: the path state linearly interpolated between
   the two accepted steps that bracket uᵢ on the requested branch (loading, then unloading).
2. **Equilibria (traced).**  Each uᵢ is solved exactly, ``F(x, uᵢ; θ) = 0`` with the
   loading residual, by :func:`socbjax._implicit.implicit_root`: a few Newton iterations
   from the warm start, with derivatives by the implicit function theorem.  Every sampled
   step therefore carries its own implicit derivative J ẋᵢ = −∂F/∂θ θ̇ − ∂F/∂u u̇ᵢ.

So the samples are smooth functions of θ (``EI``, ``lengths``, ``positions``, ``tangents``,
``loads`` of the network and the ``perturbation`` magnitude) and of ``at`` itself, on the
branch the path followed; finite differences of the whole pipeline agree with the implicit
derivatives (tests/test_sampled.py).  What is *not* differentiated: which branch is followed
(the path is re-run for each new θ) and displacements below the settled start u₀ or past
the end of unloading, which are clipped there (their derivative with respect to ``at`` is
zero).  The path's discrete events (limit points) are not returned under tracing.
"""

from __future__ import annotations

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ._compress import _concat, _gap, _observe, probe_network, run_protocol
from ._implicit import implicit_root
from ._linear import SparseJacobianSolver, jacobian_solver
from ._network import DIFFERENTIABLE_FIELDS, Network
from ._newton import Status
from ._path import PathSettings
from ._perturbation import _perturbation_plan, _strands, default_perturbation, perturbation_pattern
from ._quadrature import get_quadrature
from ._residual import SOCBModel
from ._result import CompressionResult
from ._solve import ConvergenceError
from ._sparsity import prepare_structured, structure_key

__all__ = ["compress_at", "DIFFERENTIABLE_FIELDS"]

DEFAULT_SAMPLES = 64


def _is_tracer(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _check_structure(network: Network) -> None:
    for name, value in vars(network).items():
        if name not in DIFFERENTIABLE_FIELDS and any(_is_tracer(v) for v in jax.tree_util.tree_leaves(value)):
            raise TypeError(
                f"Network.{name} depends on traced values; only {', '.join(DIFFERENTIABLE_FIELDS)} may be "
                "differentiated (the topology, supports and probe are structure): build the network outside "
                "jax.jit and replace only those arrays inside (e.g. eqx.tree_at, or a socbjax.FitModel's network(values))"
            )


def _targets(at, displacement, traced: bool):
    if at is None:
        if not traced:
            raise ValueError("at=None: give the probe displacements to sample")
        return jnp.linspace(displacement / DEFAULT_SAMPLES, displacement, DEFAULT_SAMPLES)
    at = jnp.atleast_1d(jnp.asarray(at, jnp.float64))
    if at.ndim != 1 or at.shape[0] == 0:
        raise ValueError(f"at must be a non-empty 1-D array of probe displacements (µm), got shape {at.shape}")
    if not _is_tracer(at):
        values = np.asarray(at)
        if not np.all(np.isfinite(values)):
            raise ValueError("at contains NaN or inf; give finite probe displacements (µm)")
        if values.max() > displacement + 1e-12:
            raise ValueError(f"at reaches {values.max():.4g} µm, beyond displacement={displacement:.4g} µm; raise displacement")
    return at


def _bracket(U, X, same_side, u, rising: bool):
    """Warm start at u on a branch with displacements U [k] (first crossing) and states
    X [k, n]: (x, u_eff, side) with side −1 before the branch start (clipped there), 0 inside,
    +1 beyond the branch end (clipped there).  Between two steps on the same side of a critical
    point (``same_side`` [k−1]: equal sign det J) the states are interpolated; across one the
    nearer step's state is used, so Newton starts on a branch, not between two."""
    beyond = U >= u if rising else U <= u
    if beyond[0]:
        return X[0], U[0], -1 if U[0] != u else 0
    hit = np.flatnonzero(beyond)
    if not hit.size:
        return X[-1], U[-1], 1
    j = int(hit[0])
    w = (u - U[j - 1]) / (U[j] - U[j - 1])
    if not same_side[j - 1]:
        return (X[j] if w >= 0.5 else X[j - 1]), u, 0
    return (1 - w) * X[j - 1] + w * X[j], u, 0


def _host_samples(rec, extra, at, unload, completed):
    """Warm starts X [B, n], effective displacements U [B], clip flags, stability (sign of
    det J at both bracketing steps equals the settled start's) and whether each sample lies
    on a branch the path actually reached."""
    U, X, SIGN, PHASE = rec["U"], rec["X"], rec["SIGN"], rec["PHASE"]
    sign_ref = extra.get("sign_ref", SIGN[0])
    out = {k: [] for k in ("X", "U", "clipped", "stable", "reached")}
    for phase in (1, 2) if unload else (1,):
        idx = np.flatnonzero(PHASE == phase)
        idx = np.concatenate([[idx[0] - 1], idx]) if idx.size else np.array([len(U) - 1])
        signs = SIGN[idx] == sign_ref
        same_side = SIGN[idx][1:] == SIGN[idx][:-1]
        for u in (at if phase == 1 else at[::-1]):
            x, u_eff, side = _bracket(U[idx], X[idx], same_side, float(u), rising=phase == 1)
            j = int(np.searchsorted(U[idx], u_eff) if phase == 1 else np.searchsorted(-U[idx], -u_eff))
            stable = bool(signs[min(j, len(idx) - 1)] and signs[max(j - 1, 0)])
            reached = side <= 0 or (phase == 2 and completed)
            for key, value in zip(out, (x, u_eff, side != 0, stable, reached)):
                out[key].append(value)
    return {k: np.asarray(v) for k, v in out.items()}


def _run_host(treedef, has_magnitude, displacement, unload, options, magnitude, at, *leaves):
    """The host stage (called directly, or through jax.pure_callback on traced inputs)."""
    network = jax.tree_util.tree_unflatten(treedef, [np.asarray(leaf) for leaf in leaves])
    perturbation = float(magnitude) if has_magnitude else None
    protocol, status, network, _ = run_protocol(network, displacement, unload=unload, perturbation=perturbation, **options)
    completed = int(status) == Status.CONVERGED
    samples = _host_samples(_concat(protocol.parts), protocol.extra, np.asarray(at), unload, completed)
    default_used = perturbation is None and not np.any(np.asarray(network.loads) != 0)  # compress's rule
    return (samples["X"], samples["U"], samples["clipped"], samples["stable"], samples["reached"],
            np.asarray(status, np.int32), np.asarray(protocol.extra.get("u0", 0.0)), _perturbation_plan(network)["reference"],
            np.asarray(default_used))


def _template(network: Network) -> Network:
    """A concrete network of the same structure with generic values (sparsity pattern only)."""
    rng = np.random.default_rng(7)
    values = []
    for name in DIFFERENTIABLE_FIELDS:
        shape = getattr(network, name).shape
        v = rng.uniform(0.5, 1.5, shape) if name in ("lengths", "EI") else rng.normal(size=shape)
        if name == "tangents":
            v = v / np.linalg.norm(v, axis=-1, keepdims=True)
        values.append(jnp.asarray(v))
    return eqx.tree_at(lambda n: [getattr(n, f) for f in DIFFERENTIABLE_FIELDS], network, values)


def _linear_solver(model: SOCBModel, kind: str):
    x0, unravel = ravel_pytree(model.initial_state())
    solver = jacobian_solver(kind, x0.size)
    if not isinstance(solver, SparseJacobianSolver):
        return solver
    concrete = SOCBModel(_template(model.network), model.quad)
    frames = concrete.frames(concrete.initial_state())
    fn = lambda y: concrete.residual(unravel(y), concrete.network.loads, frames, 0.3)  # noqa: E731
    return prepare_structured([fn], np.zeros(x0.size), concrete.structure(), cache_key=structure_key(model.network, "sampled"))


def _applied_loads(network: Network, perturbation, reference, default_used):
    """Applied loads [N, d] (pN), traced in the network's arrays and ``perturbation``; the
    same rule as :func:`socbjax.compress`, decided on the host's concrete values
    (``default_used``: no perturbation given and the network has no loads)."""
    plan = _perturbation_plan(network, reference=False)
    plan["reference"] = reference
    pattern = perturbation_pattern(network.positions, plan, network.probe_direction, network.n_nodes)
    if perturbation is not None:
        return network.loads + perturbation * pattern
    default = default_perturbation(network.EI, network.lengths, _strands(network)) * pattern
    return jnp.where(default_used, default, network.loads)


@eqx.filter_jit
def _resolve(model: SOCBModel, loads, X, U, linsolver, atol: float, max_iterations: int):
    """Each sample's equilibrium at its displacement, from its warm start (vmapped)."""
    _, unravel = ravel_pytree(model.initial_state())

    def one(x0, u):
        frames = model.frames(unravel(jax.lax.stop_gradient(x0)))  # analysis basis only
        F = lambda x: model.residual(unravel(x), loads, frames, u)  # noqa: E731
        return implicit_root(F, x0, linsolver, atol=atol, max_iterations=max_iterations)

    return jax.vmap(one)(X, U)


def _displacement(displacement) -> float:
    if _is_tracer(displacement):
        raise TypeError(
            "displacement sets the range of the path and must be a Python float even under jax transformations; "
            "differentiate with respect to the sampled displacements `at` instead"
        )
    return float(displacement)


def compress_at(network: Network, displacement: float, at=None, *, unload: bool = False, method: str = "displacement",
                perturbation=None, settings: PathSettings | None = None, linear_solver: str = "auto",
                quadrature_order: int = 8, progress: bool = False, throw: bool = True,
                parameters: dict | None = None) -> CompressionResult:
    """:func:`socbjax.compress` sampled at the probe displacements ``at`` [M] (µm): see the
    module docstring.  Returns a :class:`CompressionResult` with M rows (loading, phase 1) and,
    if ``unload``, M more (unloading, phase 2, ``at`` reversed); its arrays are jax arrays
    (traced under transformations); ``limit_points`` is empty (run without ``at`` for them).
    ``throw``: a sample that did not converge raises (``ConvergenceError``; under ``jit`` an
    equinox runtime error); with ``throw=False`` check ``converged``."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network, got {type(network).__name__}")
    displacement = _displacement(displacement)
    traced = any(_is_tracer(leaf) for leaf in jax.tree_util.tree_leaves((network, perturbation, at)))
    _check_structure(network)
    if not bool(np.any(np.asarray(network.probe))) and _is_tracer(network.positions):
        raise TypeError("a network without probe nodes needs concrete positions to place its probe; use probe_network first")
    network = probe_network(network)
    settings = PathSettings() if settings is None else settings
    at = _targets(at, displacement, traced)
    model = SOCBModel(network, get_quadrature(quadrature_order))
    n, M = ravel_pytree(model.initial_state())[0].size, at.shape[0]
    B = M * (2 if unload else 1)
    options = dict(method=method, settings=settings, linear_solver=linear_solver, quadrature_order=quadrature_order, progress=progress)
    leaves, treedef = jax.tree_util.tree_flatten(network)
    magnitude = jnp.asarray(0.0 if perturbation is None else perturbation, jnp.float64)
    host = lambda *args: _run_host(treedef, perturbation is not None, displacement, unload, options, *args)  # noqa: E731
    operands = jax.lax.stop_gradient((magnitude, at, *leaves))
    if traced:
        S = jax.ShapeDtypeStruct
        shapes = (S((B, n), jnp.float64), S((B,), jnp.float64), S((B,), jnp.bool_), S((B,), jnp.bool_), S((B,), jnp.bool_),
                  S((), jnp.int32), S((), jnp.float64), S((len(_strands(network)), network.dim), jnp.float64),
                  S((), jnp.bool_))
        out = jax.pure_callback(host, shapes, *operands, vmap_method="sequential")
    else:
        out = host(*(np.asarray(o) for o in operands))
    X_warm, U_host, clipped, stable, reached, status, u0, reference, default_used = out
    targets = jnp.concatenate([at, at[::-1]]) if unload else at
    U = jnp.where(clipped, U_host, targets)
    loads = _applied_loads(network, perturbation, reference, default_used)
    # Newton aims 100× below the path tolerance (post-buckling Jacobians are ill-conditioned, so
    # ‖F‖ ≈ atol can leave ~1e-6 relative force errors) and accepts anything within it.
    X, iterations, residual = _resolve(model, loads, jnp.asarray(X_warm), U, _linear_solver(model, linear_solver),
                                       1e-2 * settings.atol, settings.max_iterations)
    converged = jnp.asarray(reached) & (residual <= settings.atol) & jnp.all(jnp.isfinite(X), axis=1)
    return _package(model, loads, X, U, converged, stable, iterations, status, unload, M, throw, traced, parameters,
                    dict(displacement_um=displacement, settings=settings, u0=u0))


def _package(model, loads, X, U, converged, stable, iterations, status, unload, M, throw, traced, parameters, info):
    network = model.network
    positions, tangents, moments, forces, probe_force, axial = _observe(model, X, U, loads)
    fixed = np.einsum("nii->n", np.asarray(network.position_projector)) > 0.5
    attached = np.asarray(network.attach) != np.arange(network.n_nodes)
    ends = np.flatnonzero(fixed & ~np.asarray(network.probe) & ~attached)
    if throw and traced:
        probe_force = eqx.error_if(probe_force, ~jnp.all(converged), "compress(at=...): a sampled equilibrium did not converge")
    settings = info["settings"]
    params = {"displacement_um": info["displacement_um"], "unload": bool(unload), "sampled": True, "n_samples": int(M),
              "method": settings.method, "n_nodes": int(network.n_nodes), "n_segments": int(network.n_segments),
              "n_junctions": int(network.n_junctions), **(parameters or {})}
    if not traced:
        params["settled_displacement_um"] = float(info["u0"])
        params["gap_um"] = _gap(network) if np.isfinite(_gap(network)) else None
    phase = np.repeat(np.array([1, 2], np.int8)[: 2 if unload else 1], M)
    result = CompressionResult(
        displacement=U, force=probe_force, converged=converged, stable=jnp.asarray(stable), phase=phase,
        positions=positions, tangents=tangents, moments=moments, segment_forces=forces, end_nodes=ends,
        end_forces=axial[:, ends], iterations=iterations, limit_points=[], status=status, network=network,
        parameters=json.loads(json.dumps(params, default=float)),
    )
    if not traced:
        result = _to_numpy(result)
        if throw and not bool(np.all(result.converged)):
            bad = np.flatnonzero(~result.converged)
            err = ConvergenceError(
                f"compress(at=...): {bad.size} sampled equilibria did not converge or lie beyond the path "
                f"({Status(int(status)).message}), first at u = {float(result.displacement[bad[0]]):.4g} µm"
            )
            err.result = result
            raise err
    return result


def _to_numpy(result: CompressionResult) -> CompressionResult:
    import dataclasses

    arrays = {f.name: np.asarray(getattr(result, f.name)) for f in dataclasses.fields(result)
              if f.name not in ("limit_points", "network", "parameters", "status")}
    return dataclasses.replace(result, status=int(result.status), **arrays)
