"""Compression sampled at prescribed probe displacements, differentiable end to end:
``socbjax.compress(network, displacement, at=...)``.

One traced computation (one compiled program per topology; ``jax.jit``, ``jax.vmap``,
``jax.grad``, ``jax.jacfwd`` apply):

1. **Path (not differentiated).**  The adaptive protocol of :func:`socbjax.compress`
   (settle, loading, unloading) runs on the path engine inside ``lax.scan`` over the phases,
   following buckling and collapse with cut-back steps.  A sample recorder keeps, for every
   requested displacement uᵢ, a warm start at its *first crossing* on the requested branch
   (loading, then unloading): the path state linearly interpolated between the two accepted
   steps that bracket uᵢ — or, across a critical point (sign det J differs between them),
   the nearer step's state, so Newton starts on a branch, not between two.
2. **Equilibria (traced).**  Each uᵢ is solved exactly, ``F(x, uᵢ; θ) = 0`` with the loading
   residual, by :class:`socbjax.DampedNewton` from its warm start, through
   ``optx.root_find`` with :class:`socbjax.ImplicitAdjoint`: derivatives by the implicit function
   theorem, J ẋᵢ = −∂F/∂θ θ̇ − ∂F/∂u u̇ᵢ, never through the iterations.

So the samples are smooth functions of θ (``EI``, ``lengths``, ``positions``, ``tangents``,
``loads`` of the network and the ``perturbation`` magnitude) and of ``at`` itself, on the
branch the path followed.  What is *not* differentiated: which branch is followed (the path
is re-run for each new θ) and displacements below the settled start u₀ or past the end of
unloading, which are clipped there (their derivative with respect to ``at`` is zero; the
settled u₀ itself is held constant).  The path's discrete events (limit points) are not
returned.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from ._adjoint import ImplicitAdjoint
from ._probe import applied_loads, crossing_exempt, end_nodes, observe, parameters_json, probe_gap, surface_crossing
from ._network import is_traced
from ._protocol import UNLOAD_MARGIN, phase_problem, settled_displacement
from ._residual import Control
from ._result import CompressionResult
from ._linear import BlockDiagonal
from ._root import DampedNewton, root_find
from ._path import follow_path, model_frames, start_path, state_unravel
from ._solution import RESULTS, ConvergenceError, result_message
from ._sparsity import linear_solver_for

__all__ = ["compress_at", "SampleRecorder", "DEFAULT_SAMPLES"]

DEFAULT_SAMPLES = 64


class Samples(eqx.Module):
    """Buffers of :class:`SampleRecorder` (B samples): warm starts X [B, n], whether each was
    reached (``hit``), and sign(det J) at its two bracketing steps (``SA``, ``SB``)."""

    X: Array
    hit: Array
    SA: Array
    SB: Array


class SampleRecorder(eqx.Module):
    """Warm starts at the first crossing of each target ``targets`` [B] (in the phase's path
    parameter p ∈ [0, 1]) by the accepted steps; only ``active`` [B] targets are recorded."""

    targets: Array
    active: Array

    def init(self, x0, p0) -> Samples:
        B, n = self.targets.shape[0], x0.shape[0]
        zeros = jnp.zeros(B, x0.dtype)
        return Samples(X=jnp.zeros((B, n), x0.dtype), hit=jnp.zeros(B, bool), SA=zeros, SB=zeros)

    def record(self, rec: Samples, ok, index, previous, new) -> Samples:
        p, p1, t = previous.p, new.p, self.targets
        crossed = ok & self.active & ~rec.hit & ((p - t) * (p1 - t) <= 0)
        dp = p1 - p
        w = jnp.clip(jnp.where(dp != 0, (t - p) / jnp.where(dp != 0, dp, 1.0), 0.0), 0.0, 1.0)[:, None]
        x, x1 = previous.x[None, :], new.x[None, :]
        same_side = previous.sign == new.sign
        warm = jnp.where(same_side, (1 - w) * x + w * x1, jnp.where(w >= 0.5, x1, x))
        return Samples(X=jnp.where(crossed[:, None], warm, rec.X), hit=rec.hit | crossed,
                       SA=jnp.where(crossed, previous.sign, rec.SA), SB=jnp.where(crossed, new.sign, rec.SB))


def _phase_targets(index, at, unload, u0, u_max):
    """(targets in p [B], active [B]) of phase ``index`` for the samples ``at`` (and, when
    unloading, ``at`` reversed)."""
    M = at.shape[0]
    u_end = u0 + UNLOAD_MARGIN * (u_max - u0)
    loading = jnp.clip((at - u0) / (u_max - u0), 0.0, 1.0)
    parts, masks = [loading], [jnp.full(M, index == 1)]
    if unload:
        parts.append(jnp.clip((u_max - at[::-1]) / (u_max - u_end), 0.0, 1.0))
        masks.append(jnp.full(M, index == 2))
    return jnp.concatenate(parts), jnp.concatenate(masks)


def _protocol_scan(model, at, unload, u_max, settings, inner):
    """The phases in one ``lax.scan`` (one compiled path program): the recorded warm starts,
    hits and bracketing signs per sample, u₀, the reference sign and the protocol result."""
    x0 = ravel_pytree(model.initial_state())[0]
    B = at.shape[0] * (2 if unload else 1)
    samples = SampleRecorder(jnp.zeros(B), jnp.zeros(B, bool)).init(x0, 0.0)

    def phase(carry, index):
        x, u0, sign_ref, failed, result, rec = carry
        targets, active = _phase_targets(index, at, unload, u0, u_max)
        recorder = SampleRecorder(targets, active)
        state = start_path(x, 0.0, settings, recorder)
        state = eqx.tree_at(lambda s: s.done, state, failed)
        final = follow_path(phase_problem(model, index, u0, u_max, settings), state, settings, inner, recorder)
        rec = jax.tree_util.tree_map(lambda new, old: jnp.where(active.reshape((-1,) + (1,) * (new.ndim - 1)), new, old),
                                     final.recorder, rec)
        u0 = jnp.where(index == 0, settled_displacement(model, final.x), u0)
        sign_ref = jnp.where(index == 1, final.sign0, sign_ref)
        newly = ~failed & (final.result != RESULTS.successful)
        return (final.x, u0, sign_ref, failed | newly, RESULTS.where(newly, final.result, result), rec), None

    init = (x0, jnp.zeros(()), jnp.zeros(()), jnp.asarray(False), RESULTS.successful, samples)
    (_, u0, sign_ref, _, result, rec), _ = jax.lax.scan(phase, init, jnp.arange(3 if unload else 2))
    return rec, u0, sign_ref, result


def _clip(u, lower, upper):
    """u clipped to [lower, upper], with derivative 1 (not jnp.clip's ½) at the bounds."""
    return jnp.where(u < lower, lower, jnp.where(u > upper, upper, u))


def _resolve_fn(y, args):
    model, frames, U = args
    unravel = state_unravel(model)
    X = y.reshape(U.shape[0], -1)
    return jax.vmap(lambda x, f, u: model.residual(unravel(x), Control.make(1.0, u), f))(X, frames, U).reshape(-1)


def _resolve(model, X, U, settings, inner):
    """Every sample's equilibrium from its warm start, as one block-diagonal root find (one
    Newton iteration serves all samples; each block factored on its own), with implicit
    derivatives: (X [B, n], Newton iterations, ‖F‖∞ per sample)."""
    B = X.shape[0]
    blocks = BlockDiagonal(inner, B)
    solver = DampedNewton(atol=1e-2 * settings.atol, max_iterations=settings.max_iterations,
                          max_backtracks=settings.max_backtracks, linear_solver=blocks)
    unravel = state_unravel(model)
    warm = jax.lax.stop_gradient(X)
    # analysis bases (and the near list of obstacle contact, with each sample's probe face)
    frames = jax.lax.stop_gradient(jax.vmap(lambda x, u: model_frames(model, unravel(x), Control.make(1.0, u)))(warm, U))
    sol = root_find(_resolve_fn, warm.reshape(-1), (model, frames, U), solver=solver, adjoint=ImplicitAdjoint(blocks))
    X = sol.value.reshape(B, -1)
    residual = jnp.max(jnp.abs(jax.lax.stop_gradient(_resolve_fn(sol.value, (model, frames, U))).reshape(B, -1)), axis=1)
    return X, jnp.full(B, sol.state.iterations), residual


@eqx.filter_jit
def _sampled(model, displacement, at, unload, settings, inner):
    u_max = jnp.asarray(displacement, jnp.float64)
    rec, u0, sign_ref, result = _protocol_scan(jax.lax.stop_gradient(model), jax.lax.stop_gradient(at), unload,
                                               jax.lax.stop_gradient(u_max), settings, inner)
    u0 = jax.lax.stop_gradient(u0)
    u_end = u0 + UNLOAD_MARGIN * (u_max - u0)
    U = _clip(at, u0, u_max)
    if unload:
        U = jnp.concatenate([U, _clip(at[::-1], u_end, u_max)])
    X, iterations, residual = _resolve(model, rec.X, U, settings, inner)
    converged = rec.hit & (residual <= settings.atol) & jnp.all(jnp.isfinite(X), axis=1)
    stable = (rec.SA == sign_ref) & (rec.SB == sign_ref)
    result = RESULTS.where((result == RESULTS.successful) & ~jnp.all(converged),
                           RESULTS.where(jnp.all(rec.hit), RESULTS.max_iterations, RESULTS.not_reached), result)
    observed = observe(model, X, model.network.loads, U)
    return U, X, iterations, converged, stable, result, observed, u0


def _targets(at, displacement):
    if at is None:
        return jnp.linspace(1.0 / DEFAULT_SAMPLES, 1.0, DEFAULT_SAMPLES) * displacement
    at = jnp.atleast_1d(jnp.asarray(at, jnp.float64))
    if at.ndim != 1 or at.shape[0] == 0:
        raise ValueError(f"at must be a non-empty 1-D array of probe displacements (µm), got shape {at.shape}")
    if not is_traced(at):
        values = np.asarray(at)
        if not np.all(np.isfinite(values)):
            raise ValueError("at contains NaN or inf; give finite probe displacements (µm)")
        if not is_traced(displacement) and values.max() > float(displacement) + 1e-12:
            raise ValueError(f"at reaches {values.max():.4g} µm, beyond displacement={float(displacement):.4g} µm; "
                             "raise displacement")
    return at


def compress_at(model, displacement, at=None, *, unload=False, perturbation=None, settings, throw=True,
                parameters=None) -> CompressionResult:
    """:func:`socbjax.compress` sampled at the probe displacements ``at`` [M] (µm): see the
    module docstring.  Returns a :class:`CompressionResult` with M rows (loading, phase 1) and,
    if ``unload``, M more (unloading, phase 2, ``at`` reversed)."""
    at = _targets(at, displacement)
    net = model.network
    loaded = eqx.tree_at(lambda m: m.network, model, net.replace(loads=applied_loads(net, perturbation)))
    inner = linear_solver_for(loaded, settings.linear_solver, batched=True)
    # displacement as an array: filter_jit holds a Python float static, and every new depth
    # (each curve of a fit or batch) would compile the whole path again
    U, X, iterations, converged, stable, result, observed, u0 = _sampled(loaded, jnp.asarray(displacement, jnp.float64), at,
                                                                        bool(unload), settings.traced(), inner)
    positions, tangents, moments, forces, probe_force, axial, twists = observed[:7]
    count, min_gap, contact_force, contact_points, contact_forces, reactions = observed[7:]
    crossed = jnp.any(surface_crossing(net, positions, U) & converged)
    if crossing_exempt(model):
        crossed = jnp.asarray(False)
    result = RESULTS.where((result == RESULTS.successful) & crossed, RESULTS.surface_crossed, result)
    M = at.shape[0]
    ends = end_nodes(net)
    params = {"unload": bool(unload), "sampled": True, "n_samples": int(M), "method": settings.method,
              "n_nodes": int(net.n_nodes), "n_segments": int(net.n_segments), "n_junctions": int(net.n_junctions),
              **(parameters or {})}
    if not is_traced(displacement):
        params["displacement_um"] = float(displacement)
    if not is_traced(net.positions):
        gap = probe_gap(net)
        params["gap_um"] = gap if np.isfinite(gap) else None
    out = CompressionResult(
        displacement=U, force=probe_force, converged=converged, stable=stable,
        phase=np.repeat(np.array([1, 2], np.int8)[: 2 if unload else 1], M), positions=positions, tangents=tangents,
        moments=moments, segment_forces=forces, twists=twists, end_nodes=ends, end_forces=axial[:, ends],
        iterations=iterations, contact_count=count, min_gap=min_gap, contact_force=contact_force,
        contact_points=contact_points, contact_forces=contact_forces, reactions=reactions,
        result=result, network=loaded.network, limit_points=(), parameters_json=parameters_json(params))
    if not throw:
        return out
    failed = ~jnp.all(converged) | (result == RESULTS.surface_crossed)
    if is_traced(out):
        return eqx.error_if(out, failed, "compress(at=...): a sampled equilibrium did not converge, lies beyond the "
                            "path, or has nodes beyond the surface or the probe plane (computed without contact)")
    if bool(failed) and bool(jnp.all(converged)):
        err = ConvergenceError(f"compress(at=...): {result_message(result)}")
        err.result = out
        raise err
    if bool(failed):
        bad = np.flatnonzero(~np.asarray(converged))
        err = ConvergenceError(f"compress(at=...): {bad.size} sampled equilibria did not converge or lie beyond the path "
                               f"({result_message(result)}), first at u = {float(U[bad[0]]):.4g} µm")
        err.result = out
        raise err
    return out
