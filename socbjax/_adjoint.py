"""Derivatives of equilibria by the implicit function theorem: :class:`ImplicitAdjoint`.

An ``optimistix.AbstractAdjoint`` (pass it as ``adjoint=`` to ``optx.root_find`` or to any
socbjax entry point).  For a root x*(θ) of F(x, θ) = 0 it never differentiates the
iterations that found it: differentiating F(x*(θ), θ) = 0 gives J ẋ = −(∂F/∂θ) θ̇ with
J = ∂F/∂x at x*, so a forward derivative costs one linear solve with J and a reverse one a
solve with Jᵀ, with the socbjax linear solver of the forward Newton (dense LU, or the
coloured sparse Jacobian + SuperLU with its transposed solve).

It is optimistix's ``ImplicitAdjoint`` with the tangent solve written as
``jax.lax.custom_linear_solve`` around a socbjax solver instead of ``lineax.linear_solve``:
with jax 0.10, reverse mode through a *vmapped* ``lineax.linear_solve`` fails to batch
(``ValueError: at vmap out_axes[0], got axis spec None but output was batched``;
optimistix issue #129 reports the same family of failures), which ``jax.grad`` of
``jax.vmap`` of a sampled compression needs.
"""

from __future__ import annotations

import functools

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import lineax as lx
import optimistix as optx

from ._linear import DenseLU

__all__ = ["ImplicitAdjoint", "NonDifferentiable", "implicit_solve"]


def _is_none(x):
    return x is None


def _factor(solver, f, x):
    """The solver's state for J = df/dx at x (f: flat -> flat)."""
    _, lin = jax.linearize(f, x)
    if hasattr(solver, "factor"):
        return solver.factor(lin, x.shape[0], x.dtype, {"point": x})
    return solver.init(lx.FunctionLinearOperator(lin, jax.ShapeDtypeStruct(x.shape, x.dtype)), {})


def implicit_solve(solver, f, x, rhs):
    """J⁻¹ rhs with J = df/dx at x, as a ``jax.lax.custom_linear_solve`` (transposable: the
    cotangent solve is Jᵀ⁻¹ by the same factorisation, ``solver.transpose``)."""
    state = _factor(solver, f, x)

    def matvec(v):
        return jax.jvp(f, (x,), (v,))[1]

    def solve(_, b):
        return solver.compute(state, b, {})[0]

    def transpose_solve(_, b):
        return solver.compute(solver.transpose(state, {})[0], b, {})[0]

    return jax.lax.custom_linear_solve(matvec, rhs, solve, transpose_solve)


@eqx.filter_custom_jvp
def _implicit(fn_primal, fn_rewrite, inputs, solver):
    del fn_rewrite, solver
    return jtu.tree_map(jnp.asarray, fn_primal(inputs))


@_implicit.def_jvp
def _implicit_jvp(primals, tangents):
    fn_primal, fn_rewrite, inputs, solver = primals
    t_inputs = tangents[2]
    root, residual = _implicit(fn_primal, fn_rewrite, inputs, solver)
    no_tangent = jtu.tree_map(_is_none, t_inputs, is_leaf=_is_none)
    nondiff, diff = eqx.partition(inputs, no_tangent, is_leaf=_is_none)
    _, rhs = jax.jvp(lambda d: fn_rewrite(root, residual, eqx.combine(d, nondiff)), (diff,), (t_inputs,))
    f = lambda x: fn_rewrite(x, residual, inputs)  # noqa: E731
    t_root = -implicit_solve(solver, f, root, rhs)
    t_residual = jtu.tree_map(lambda r: None, residual)
    return (root, residual), (t_root, t_residual)


class ImplicitAdjoint(optx.AbstractAdjoint):
    """Backpropagate through a root by the implicit function theorem (see the module doc).

    ``linear_solver``: a socbjax solver (:class:`socbjax.DenseLU`,
    :class:`socbjax.ColouredSparseLU`), or None (default): the socbjax entry points then use
    the solver of the forward solve (dense LU where nothing says otherwise).  The root must
    be a flat array (as in every socbjax solve).
    """

    linear_solver: lx.AbstractLinearSolver | None = None

    def with_solver(self, inner) -> ImplicitAdjoint:
        """This adjoint, with ``inner`` where no linear solver was chosen."""
        return self if self.linear_solver is not None else ImplicitAdjoint(inner)

    def apply(self, primal_fn, rewrite_fn, inputs, tags):
        del tags
        inputs = inputs + (functools.partial(eqxi.while_loop, kind="lax"),)
        solver = DenseLU() if self.linear_solver is None else self.linear_solver
        root, residual = _implicit(primal_fn, rewrite_fn, inputs, solver)
        return root, jtu.tree_map(eqxi.nondifferentiable_backward, residual)


class NonDifferentiable(optx.AbstractAdjoint):
    """For solves that are never differentiated (the correctors of path following, whose
    inputs are stopped): runs the loop as a plain ``lax.while_loop`` with no custom
    derivative rule to trace.  Differentiating through it gives zero (stop_gradient)."""

    def apply(self, primal_fn, rewrite_fn, inputs, tags):
        del rewrite_fn, tags
        dynamic, static = eqx.partition(inputs, eqx.is_inexact_array)
        inputs = eqx.combine(jax.lax.stop_gradient(dynamic), static)
        return primal_fn(inputs + (functools.partial(eqxi.while_loop, kind="lax"),))
