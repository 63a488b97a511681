"""Critical axial load of a straight column: :func:`buckling_load`.

The straight state is an exact solution of both models for any axial load P on the last
node, and at it the tangent stiffness J(P) is (to round-off, for SOCB; approximately for
other discretisations) a quadratic matrix polynomial A + P B + P² C: the lever arm of
Eq. 9 and the end curvature derivatives are each linear in the force.

1. **Estimate** (not differentiated): A, B, C from J at three loads; with μ = 1/P the
   quadratic eigenproblem μ² A + μ B + C is linearised (companion form) and solved densely
   on the host; the largest real μ > 0 gives the smallest P > 0 and its mode v₀.
2. **Critical point** (the one root finder, :class:`socbjax.DampedNewton`): the bordered
   null-vector system G(v, P) = [J(P) v; v₀·v − 1] = 0 with the exact J(P) (one JVP of the
   residual), from (v₀, P₀); its Newton steps take ∂(J(P)v)/∂P from the quadratic model
   (B + 2PC) v, so the forward computation needs no second derivatives.
3. **Derivatives** by the implicit function theorem on G (:class:`socbjax.ImplicitAdjoint`): with u
   the left null vector, dP/dθ = −uᵀ(∂J/∂θ)v / uᵀ(∂J/∂P)v — never through the iterations,
   so ``jax.grad``/``jax.jacfwd``/``jax.vmap``/``jax.jit`` apply (e.g. dPcr/dEI = Pcr/EI).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ._adjoint import ImplicitAdjoint, NonDifferentiable
from ._linear import DenseLU
from ._network import Network, is_traced
from ._residual import Control
from ._root import DampedNewton, newton_result, root_find
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


@eqx.filter_custom_jvp
def _jv_modelled(v, P, B, C, model, axis):
    return _jv(v, P, model, axis)


@_jv_modelled.def_jvp
def _jv_modelled_jvp(primals, tangents):
    """∂(J(P)v)/∂P from the quadratic model, (B + 2PC) v: Newton on G then needs no second
    derivatives of the residual (exact for SOCB; a slightly inexact tangent otherwise, which
    only slows the Newton iteration: its residual is exact)."""
    v, P, B, C, model, axis = primals
    tv, tP = tangents[0], tangents[1]
    out = _jv(v, P, model, axis)
    t = _jv(jnp.zeros_like(v) if tv is None else tv, P, model, axis)
    if tP is not None:
        t = t + (B + 2 * P * C) @ v * tP
    return out, t


def _null_system_modelled(y, args):
    model, axis, v0, B, C = args
    return jnp.concatenate([_jv_modelled(y[:-1], y[-1], B, C, model, axis), (jnp.dot(v0, y[:-1]) - 1.0)[None]])


def _buckling_primal(inputs):
    model, axis, scale, _while_loop = inputs
    A, J1, J2, J3 = jax.vmap(lambda P: _jacobian(model, axis, P))(scale * jnp.arange(4.0))
    C = (J2 - 2 * J1 + A) / (2 * scale**2)
    B = (J1 - A) / scale - C * scale
    n = A.shape[0]
    out = (jax.ShapeDtypeStruct((), A.dtype), jax.ShapeDtypeStruct((n,), A.dtype))
    P0, v0 = jax.pure_callback(_companion_host, out, A, B, C, vmap_method="sequential")
    solver = DampedNewton(atol=1e-11, max_iterations=30, linear_solver=DenseLU())
    sol = root_find(_null_system_modelled, jnp.concatenate([v0, P0[None]]), (model, axis, v0, B, C), solver=solver,
                    adjoint=NonDifferentiable())
    result = RESULTS.where(jnp.isfinite(P0), newton_result(sol), RESULTS.singular)
    return sol.value, (result, v0)


def _buckling_rewrite(y, aux, inputs):
    model, axis, _, _ = inputs
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
    ``ValueError`` for networks that are not columns and, with ``throw=True``,
    :class:`socbjax.ConvergenceError` (an ``equinox`` runtime error under ``jax.jit``) when no
    compressive critical load exists (e.g. the supports do not allow buckling).
    """
    _check_column(network)
    P, result = _critical(make_model(network, model, quadrature_order=quadrature_order))
    if not throw:
        return P
    failed = result != RESULTS.successful
    if is_traced(P):
        return result.error_if(P, failed)
    if bool(failed):
        raise ConvergenceError(f"no compressive buckling load found ({result_message(result)}): the supports may not "
                               "allow buckling under a load on the last node")
    return P
