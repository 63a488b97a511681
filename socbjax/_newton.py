"""Damped Newton on ``jax.jacfwd`` Jacobians, jit-compatible, with a status for every result.

The solver acts on a flat vector x and a residual ``fn(x) -> R`` of the same size (the
SOCB and jointed systems are square).  Each iteration assembles the Jacobian by forward
mode, solves J Δx = −R and takes the largest step α ∈ {1, ½, ¼, …} that decreases ‖R‖₂
(Armijo backtracking on ½‖R‖²).  The linear algebra is pluggable: by default the dense
``jax.jacfwd`` Jacobian and a ``lineax`` solver (dense LU); with ``jacobian_solver`` set to a
prepared :class:`~socbjax._linear.SparseJacobianSolver` (or any object with the same
``solve(fn, x, rhs) -> (X, sign det J)`` method) the Jacobian is never formed densely, so
one iteration costs O(n) for the tree-structured SOCB systems (colour-compressed jvps plus
a sparse LU; see ``docs/scaling.md``).
Convergence is ‖R‖_∞ ≤ ``atol`` on the dimensionless residual.  A result never hides a
failure: ``status`` says why the iteration stopped.
"""

from __future__ import annotations

import enum
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array, Float, Int

__all__ = ["Status", "NewtonSolver", "NewtonResult"]


class Status(enum.IntEnum):
    """Why a solve stopped.  Only ``CONVERGED`` is an answer."""

    CONVERGED = 0
    MAX_ITERATIONS = 1
    NONFINITE = 2
    LINE_SEARCH_FAILED = 3
    CONTINUATION_FAILED = 4
    CRITICAL_POINT = 5
    MAX_STEPS = 6

    @property
    def message(self) -> str:
        return {
            Status.CONVERGED: "converged",
            Status.MAX_ITERATIONS: "Newton reached its iteration limit without converging",
            Status.NONFINITE: "the residual or Newton step became NaN/inf",
            Status.LINE_SEARCH_FAILED: "the line search could not reduce the residual (singular or ill-posed system)",
            Status.CONTINUATION_FAILED: "load continuation cut the step below its minimum without converging",
            Status.CRITICAL_POINT: (
                "the load path reaches a critical point (limit load or bifurcation: the tangent stiffness "
                "turns singular), beyond which no equilibrium continues this path under load control; "
                "add a small imperfection load, or stop below the critical load; under displacement "
                "control use method='arclength' to follow the path through folds"
            ),
            Status.MAX_STEPS: "the continuation used up its step budget (PathSettings.max_steps / max_attempts)",
        }[self]


_RUNNING = -1


class NewtonResult(eqx.Module):
    """Outcome of one Newton solve: final iterate, status code, iterations, ‖R‖_∞."""

    x: Float[Array, " n"]
    status: Int[Array, ""]
    iterations: Int[Array, ""]
    residual_norm: Float[Array, ""]
    jacobian: Float[Array, "n n"]  # J at the last iterate where it was assembled ([0, 0] with a jacobian_solver)
    sign: Float[Array, ""] = None  # sign(det J) of the last factorisation (jacobian_solver only)

    @property
    def converged(self) -> Array:
        return self.status == Status.CONVERGED


class NewtonSolver(eqx.Module):
    """Damped Newton with Armijo backtracking.

    Parameters
    ----------
    atol : convergence threshold on ‖R‖_∞ of the dimensionless residual.
    max_iterations : Newton iterations before giving up (``Status.MAX_ITERATIONS``).
    max_backtracks : step halvings allowed per iteration (``Status.LINE_SEARCH_FAILED``).
    linear_solver : any square ``lineax`` solver (default dense LU) for the dense Jacobian.
    jacobian_solver : ``None`` (dense ``jax.jacfwd`` + ``linear_solver``) or a prepared
        Jacobian solver from :mod:`socbjax._linear` (``DenseJacobianSolver``,
        ``SparseJacobianSolver``) that assembles and factors J itself; then
        ``NewtonResult.jacobian`` is empty ([0, 0]) and ``NewtonResult.sign`` carries
        sign(det J) of the last factorisation.
    """

    atol: float = 1e-12
    max_iterations: int = 40
    max_backtracks: int = 16
    linear_solver: lx.AbstractLinearSolver = lx.LU()
    jacobian_solver: object = None

    def __call__(self, fn: Callable[[Array], Array], x0: Float[Array, " n"]) -> NewtonResult:
        # At least one iteration is always taken, so that the returned Jacobian is that of
        # the converged neighbourhood (continuation reuses it for its tangent and det sign).
        r0 = fn(x0)
        status0 = jnp.where(jnp.isfinite(_inf_norm(r0)), _RUNNING, Status.NONFINITE).astype(jnp.int32)

        def cond(carry):
            return carry[3] == _RUNNING

        def body(carry):
            x, r, iteration, _, jac = carry
            if self.jacobian_solver is None:
                jac = jax.jacfwd(fn)(x)
                step = lx.linear_solve(lx.MatrixLinearOperator(jac), -r, self.linear_solver, throw=False).value
            else:
                step, sign = self.jacobian_solver.solve(fn, x, -r)
                jac = jnp.reshape(sign, (1, 1))  # only the determinant sign is carried
            merit = jnp.sum(r * r)

            def ls_cond(ls):
                alpha, k, _, new_merit = ls
                bad = ~(new_merit <= (1.0 - 1e-4 * alpha) * merit)  # also catches NaN
                return bad & (k < self.max_backtracks)

            def ls_body(ls):
                alpha, k, _, _ = ls
                alpha = 0.5 * alpha
                r_new = fn(x + alpha * step)
                return alpha, k + 1, r_new, jnp.sum(r_new * r_new)

            # Start at α = 2 with an infinite merit: the first pass evaluates the full step, so
            # the residual is traced once for the whole line search (compile time).
            alpha, k, r_new, new_merit = jax.lax.while_loop(
                ls_cond, ls_body, (jnp.asarray(2.0, x.dtype), -1, r, jnp.asarray(jnp.inf, x.dtype))
            )
            accepted = new_merit <= (1.0 - 1e-4 * alpha) * merit
            x_new = jnp.where(accepted, x + alpha * step, x)
            r_new = jnp.where(accepted, r_new, r)
            norm = _inf_norm(r_new)
            iteration = iteration + 1
            status = jnp.where(norm <= self.atol, Status.CONVERGED, _RUNNING)
            status = jnp.where((status == _RUNNING) & ~accepted, Status.LINE_SEARCH_FAILED, status)
            status = jnp.where(jnp.all(jnp.isfinite(step)) & jnp.isfinite(norm), status, Status.NONFINITE)
            status = jnp.where((status == _RUNNING) & (iteration >= self.max_iterations), Status.MAX_ITERATIONS, status)
            return x_new, r_new, iteration, status.astype(jnp.int32), jac

        size = x0.size if self.jacobian_solver is None else 1
        init = (x0, r0, jnp.zeros((), jnp.int32), status0, jnp.zeros((size, size), x0.dtype))
        x, r, iterations, status, jac = jax.lax.while_loop(cond, body, init)
        if self.jacobian_solver is None:
            return NewtonResult(x=x, status=status, iterations=iterations, residual_norm=_inf_norm(r), jacobian=jac)
        return NewtonResult(x=x, status=status, iterations=iterations, residual_norm=_inf_norm(r),
                            jacobian=jnp.zeros((0, 0), x.dtype), sign=jac[0, 0])


def _inf_norm(r: Array) -> Array:
    return jnp.max(jnp.abs(r))
