"""Critical axial load of a straight column: :func:`buckling_load`.

The straight state is an exact solution of both models for any axial load P on the last
node, and at it the tangent stiffness J(P) is (to round-off, for SOCB and the jointed chain)
a quadratic matrix polynomial A + P B + P² C: the lever arm of
Eq. 9 and the end curvature derivatives are each linear in the force.

1. **Estimate** (not differentiated): A, B, C from J at three loads; with μ = 1/P the
   quadratic eigenproblem μ² A + μ B + C is linearised (companion form) and solved densely
   on the host; the largest real μ > 0 gives the smallest P > 0 and its mode v₀.
2. **Check**: a fourth Jacobian, at 3 × the load scale, measures the model error; the model is
   exact to round-off for SOCB and the jointed chain, so P₀ is the critical load.  A model
   error above 1e-10 (relative), or no real positive μ, is reported (``RESULTS.singular``),
   never returned as an answer.  No Newton refinement is compiled (small forward program).
3. **Derivatives** by the implicit function theorem on the null-vector system
   G(v, P) = [J(P) v; v₀·v − 1] = 0 with the exact J (:class:`socbjax.ImplicitAdjoint`): with u
   the left null vector, dP/dθ = −uᵀ(∂J/∂θ)v / uᵀ(∂J/∂P)v — never through the iterations,
   so ``jax.grad``/``jax.jacfwd``/``jax.vmap``/``jax.jit`` apply (e.g. dPcr/dEI = Pcr/EI).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ._adjoint import ImplicitAdjoint
from ._linear import DenseLU
from ._network import Network, is_traced
from ._residual import Control
from ._solution import RESULTS, ConvergenceError, result_message
from ._solve import make_model

__all__ = ["buckling_load"]


def _check_column(network: Network) -> None:
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (e.g. socbjax.column(...)), got {type(network).__name__}")
    seg = network.segments
    chain = np.array_equal(seg, np.stack([np.arange(len(seg)), np.arange(1, len(seg) + 1)], 1))
    if not chain or network.n_junctions or network.has_probe:
        raise ValueError(
            "buckling_load computes the critical axial load of a straight column (one chain of segments, no branch "
            "junctions or probe, loaded at its last node along the first→last axis); for networks use "
            "socbjax.compress and read the force maximum (result.limit_points)"
        )
    if not is_traced(network.positions):
        pos = np.asarray(network.positions)
        axis = pos[-1] - pos[0]
        if np.linalg.norm(axis) < 1e-12:
            raise ValueError("buckling_load needs a straight column whose first and last nodes differ")
        axis = axis / np.linalg.norm(axis)
        offset = (pos - pos[0]) - np.outer((pos - pos[0]) @ axis, axis)
        tangents = np.asarray(network.tangents) if not is_traced(network.tangents) else None
        if np.abs(offset).max() > 1e-9 * np.linalg.norm(pos[-1] - pos[0]) or (
                tangents is not None and np.min(tangents @ axis) < 1.0 - 1e-9):
            raise ValueError("buckling_load needs a straight column: every node on the line from the first to the last "
                             "node and every tangent along it (a curved or kinked filament has no buckling load; "
                             "follow it with socbjax.compress instead)")
        if np.linalg.norm(network.position_projector[-1] @ axis) > 1e-9:
            raise ValueError("the last node of the column is held along the column axis, so no axial load can act "
                             "there; support it laterally only (socbjax.column does)")


def _straight(model, axis, P):
    """(flat straight state under axial compression P, residual of flat states there)."""
    net = model.network
    loaded = eqx.tree_at(lambda m: m.network, model, net.replace(loads=jnp.zeros_like(net.loads).at[-1].set(-P * axis)))
    state = eqx.tree_at(lambda s: s.forces, loaded.initial_state(), jnp.tile(-P * axis, (net.n_segments, 1)))
    x, unravel = ravel_pytree(state)
    frames = jax.lax.stop_gradient(loaded.frames(state))
    return x, lambda y: loaded.residual(unravel(y), Control.make(), frames)


def _jacobian(model, axis, P):
    x, f = _straight(model, axis, P)
    return jax.jacfwd(f)(x)


def _companion_host(A, B, C):
    """Smallest P > 0 with a real eigenvalue μ = 1/P of μ²A + μB + C, and its mode (NaN if none)."""
    A, B, C = (np.asarray(M) for M in (A, B, C))
    n = A.shape[0]
    try:
        companion = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(A, C), -np.linalg.solve(A, B)]])
        mu, vectors = np.linalg.eig(companion)
    except np.linalg.LinAlgError:
        return np.asarray(np.nan), np.full(n, np.nan)
    real = (np.abs(mu.imag) <= 1e-7 * np.abs(mu)) & (mu.real > 0)
    if not real.any():
        return np.asarray(np.nan), np.full(n, np.nan)
    k = np.flatnonzero(real)[np.argmax(mu.real[real])]
    v = vectors[:n, k].real
    return np.asarray(1.0 / mu.real[k]), v / np.linalg.norm(v)


def _jv(v, P, model, axis):
    """J(P) v: one JVP of the residual at the straight state under axial compression P."""
    x, f = _straight(model, axis, P)
    return jax.jvp(f, (x,), (v,))[1]


def _null_system(y, args):
    """G(v, P) = [J(P) v; v₀·v − 1] (exact: its derivatives are those of the residual)."""
    model, axis, v0 = args
    return jnp.concatenate([_jv(y[:-1], y[-1], model, axis), (jnp.dot(v0, y[:-1]) - 1.0)[None]])


def _buckling_primal(inputs):
    """(v, P) from the quadratic model.  A fourth Jacobian, at 3 × the load scale, checks the
    model (exact to round-off for SOCB and the jointed chain: straight state, lever arm and
    end curvature derivatives linear in P), so no Newton refinement is compiled into the
    forward program; a model error above 1e-10 max|J| (a discretisation where J(P) is not
    quadratic) is reported as a failure instead of returned.  The four Jacobians run in one
    ``lax.map``: one compiled Jacobian, not four."""
    model, axis, scale, _while_loop = inputs  # the adjoint appends the loop it would run
    A, J1, J2, J3 = jax.lax.map(lambda P: _jacobian(model, axis, P), scale * jnp.arange(4.0))
    C = (J2 - 2 * J1 + A) / (2 * scale**2)
    B = (J1 - A) / scale - C * scale
    model_error = jnp.max(jnp.abs(A + 3 * scale * B + 9 * scale**2 * C - J3)) / jnp.max(jnp.abs(J3))
    n = A.shape[0]
    out = (jax.ShapeDtypeStruct((), A.dtype), jax.ShapeDtypeStruct((n,), A.dtype))
    P0, v0 = jax.pure_callback(_companion_host, out, A, B, C, vmap_method="sequential")
    found = jnp.isfinite(P0) & (model_error <= 1e-10)
    result = RESULTS.where(found, RESULTS.successful, RESULTS.singular)
    P0 = jnp.where(found, P0, scale)  # a finite placeholder: the result says it is no answer
    v0 = jnp.where(found, v0, 1.0 / np.sqrt(n))
    return jnp.concatenate([v0, P0[None]]), (result, v0)


def _buckling_rewrite(y, aux, inputs):
    model, axis = inputs[:2]
    return _null_system(y, (model, axis, aux[1]))


@eqx.filter_jit
def _critical(model):
    net = model.network
    axis = net.positions[-1] - net.positions[0]
    axis = axis / jnp.linalg.norm(axis)
    scale = jnp.mean(net.EI) / net.total_length**2
    adjoint = ImplicitAdjoint(DenseLU())
    y, (result, _) = adjoint.apply(_buckling_primal, _buckling_rewrite, (model, axis, scale), tags=frozenset())
    return y[-1], result


def buckling_load(network: Network, *, model: str = "socb", quadrature_order: int = 8, throw: bool = True):
    """Smallest compressive axial force (pN) on the last node of a straight column at which
    the straight state loses stability: the smallest P > 0 with a singular tangent stiffness
    J(P) (see the module docstring).  The axis is the line from the first to the last node.

    Returns a JAX scalar, differentiable (implicit function theorem on the null-vector
    system) and traceable in the column's values (EI, lengths, positions).  Raises
    ``ValueError`` for networks that are not columns and, with ``throw=True`` (default),
    :class:`socbjax.ConvergenceError` (an ``equinox`` runtime error under ``jax.jit``) when no
    compressive critical load exists (e.g. the supports do not allow buckling).  With
    ``throw=False`` it returns ``(P, result)``: ``result`` (a :class:`socbjax.RESULTS`) says
    whether ``P`` is a critical load, e.g. for members of a ``jax.vmap``.
    """
    _check_column(network)
    P, result = _critical(make_model(network, model, quadrature_order=quadrature_order))
    if not throw:
        return P, result
    failed = result != RESULTS.successful
    if is_traced(P):
        return result.error_if(P, failed)
    if bool(failed):
        raise ConvergenceError(f"no compressive buckling load found ({result_message(result)}): the supports may not "
                               "allow buckling under a load on the last node")
    return P
