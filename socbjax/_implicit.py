"""Equilibria with derivatives by the implicit function theorem: :func:`implicit_root`.

A converged equilibrium x*(θ) of ``F(x, θ) = 0`` is differentiated without unrolling the
Newton iterations that found it.  Differentiating ``F(x*(θ), θ) = 0`` gives

    J ẋ = −(∂F/∂θ) θ̇,        J = ∂F/∂x at x*,

so a forward derivative (JVP) costs one linear solve with J and a reverse derivative (VJP)
one solve with Jᵀ, whatever the number of Newton iterations.  This is ``jax.lax.custom_root``
with the tangent solve wrapped in ``jax.lax.custom_linear_solve`` (so it transposes for
reverse mode) and done by the same pluggable Jacobian solver as the forward Newton (dense LU
or coloured sparse Jacobian + SuperLU, :mod:`socbjax._linear`).  ``θ`` is anything ``F``
closes over (network arrays, loads, the probe displacement): ``jax.jvp``, ``jax.grad``,
``jax.jacfwd`` and ``jax.vmap`` all apply.

The primal solve is a plain Newton iteration from a warm start that is already close (a
neighbouring converged continuation step); it reports its iterations and final residual so
the caller can refuse a state that did not converge.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = ["implicit_root"]


def _newton(F: Callable, x0: Array, linsolver, atol: float, max_iterations: int) -> tuple[Array, Array]:
    """Newton from a close warm start, steps halved (up to 8 times) until ‖F‖₂ decreases:
    (x, iterations)."""

    def cond(carry):
        _, r, it = carry
        return (jnp.max(jnp.abs(r)) > atol) & (it < max_iterations) & jnp.all(jnp.isfinite(r))

    def body(carry):
        x, r, it = carry
        dx, _ = linsolver.solve(F, x, -r)
        norm = jnp.sum(r * r)

        def shorter(ls):
            alpha, _, r_new, k = ls
            return ~(jnp.sum(r_new * r_new) < norm) & (k < 8)

        def halve(ls):
            alpha, _, _, k = ls
            alpha = 0.5 * alpha
            return alpha, x + alpha * dx, F(x + alpha * dx), k + 1

        x_full = x + dx
        _, x, r, _ = jax.lax.while_loop(shorter, halve, (jnp.ones((), x.dtype), x_full, F(x_full), 0))
        return x, r, it + 1

    x, _, it = jax.lax.while_loop(cond, body, (x0, F(x0), jnp.zeros((), jnp.int32)))
    return x, it


def implicit_root(
    F: Callable[[Array], Array],
    x_guess: Float[Array, " n"],
    linsolver,
    *,
    atol: float = 1e-10,
    max_iterations: int = 25,
) -> tuple[Float[Array, " n"], Array, Array]:
    """Solve ``F(x) = 0`` from ``x_guess``; derivatives of the root with respect to whatever
    ``F`` closes over follow the implicit function theorem (never the iterations).

    Parameters
    ----------
    F : residual x [n] -> [n] (dimensionless); may close over traced parameters.
    x_guess : [n] warm start, close to the root (Newton with step halving).
    linsolver : a prepared :class:`DenseJacobianSolver` / :class:`SparseJacobianSolver`
        (``solve(fn, x, rhs, transpose=...)``), used for the Newton steps and for the
        tangent (J) and cotangent (Jᵀ) solves.
    atol, max_iterations : Newton tolerance on ‖F‖_∞ and iteration cap.

    Returns
    -------
    (x [n], iterations (int), ‖F(x)‖_∞); the caller decides what a large residual means.
    """
    n = x_guess.shape[0]
    zero = jnp.zeros((n,), x_guess.dtype)

    def solve(f, x0):
        x, it = _newton(f, x0, linsolver, atol, max_iterations)
        return x, it.astype(x0.dtype)  # a float aux: custom_root gives aux zero tangents of its dtype

    def tangent_solve(g, y):
        # g is F linearised at the root: its Jacobian is J, whatever the point it is taken at.
        return jax.lax.custom_linear_solve(
            g,
            y,
            solve=lambda matvec, b: linsolver.solve(matvec, zero, b)[0],
            transpose_solve=lambda vecmat, b: linsolver.solve(g, zero, b, transpose=True)[0],
        )

    x, iterations = jax.lax.custom_root(F, x_guess, solve, tangent_solve, has_aux=True)
    residual = jnp.max(jnp.abs(F(jax.lax.stop_gradient(x))))
    return x, jax.lax.stop_gradient(iterations).astype(jnp.int32), residual
