"""The one root finder of socbjax: damped Newton, an ``optimistix`` root finder.

:class:`DampedNewton` is an ``optx.AbstractRootFinder``: use it through ``optx.root_find``
(or :func:`root_find`), with :class:`socbjax.ImplicitAdjoint` for derivatives of the root by the
implicit function theorem (one linear solve per direction, never through the iterations).
It serves every nonlinear solve of the package: the corrector of the path engine
(:mod:`socbjax._path`, on the bordered system of the load ramp and of displacement or
arclength control), the exact re-solves of sampled compressions and the critical-load
null-vector system of :func:`socbjax.buckling_load`.

One step evaluates the residual *and its linearisation* at a trial point (one
``jax.linearize``: the only place the residual is traced, which keeps compile times short):

* the trial point is accepted if ‖f‖∞ ≤ ``atol`` (converged), or if it is the first point,
  or if it decreases the merit ½‖f‖² by the Armijo fraction (1 − 10⁻⁴ α);
* at an accepted point the linear solver factors J (dense LU, coloured sparse LU, or the
  bordered solver of path following; :mod:`socbjax._linear`) and the next trial is the full
  Newton step α = 1; a rejected trial halves α along the last Newton direction;
* the last factorisation — of the final Newton step, within the quadratic-convergence
  neighbourhood of the root (or of the root itself when the start was already converged) —
  is kept: its sign(det J) and, for the bordered solver, the path tangent J⁻¹ ∂F/∂p are in
  the final state (``.sign``, ``.stats``).

Failures are statuses (:class:`socbjax.RESULTS`), never a silent answer: ``max_iterations``
(Newton steps), ``line_search_failed`` (``max_backtracks`` halvings without decrease),
``nonfinite`` (the residual at the start is NaN/inf), ``singular`` (J singular away from
a root) and ``colour_capacity`` (:class:`socbjax.PairedSparseLU` ran out of colours).  On
failure the best accepted iterate is returned.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx
from jaxtyping import Array

from ._adjoint import ImplicitAdjoint
from ._linear import Bordered, DenseLU
from ._solution import RESULTS

__all__ = ["DampedNewton", "NewtonState", "newton_result", "root_find"]


def _inf_norm(f) -> Array:
    return jnp.max(jnp.abs(f))


def _stats_like(solver, n: int, dtype) -> dict:
    """Zero placeholders of the ``stats`` a socbjax linear solver returns (for the state;
    other lineax solvers report no sign: it stays 0)."""
    stats = {"sign": jnp.zeros((), dtype), "overflow": jnp.zeros((), bool)}
    if isinstance(solver, Bordered):
        stats["tangent"] = jnp.zeros((n - 1,), dtype)
    return stats


class NewtonState(eqx.Module):
    """Typed state of :class:`DampedNewton` (all arrays, so it crosses ``jit`` and ``vmap``).

    accepted : the last accepted iterate [n];  merit : ½‖f‖² there (inf before any);
    direction : the Newton direction from it;   alpha : step fraction of the current trial;
    backtracks : halvings since the last acceptance;  iterations : Newton steps taken;
    residual_norm : ‖f‖∞ at the accepted iterate;  stats : the linear solver's ``stats`` of
    the last factorisation (``sign`` = sign(det J), ``tangent`` for :class:`Bordered`,
    ``overflow``: :class:`socbjax.PairedSparseLU` ran out of colours);
    result : a :class:`socbjax.RESULTS` item;  done : the loop may stop.
    """

    accepted: Array
    merit: Array
    direction: Array
    alpha: Array
    backtracks: Array
    iterations: Array
    residual_norm: Array
    stats: dict
    result: RESULTS
    done: Array

    @property
    def sign(self) -> Array:
        return self.stats["sign"]


class DampedNewton(optx.AbstractRootFinder):
    """Newton's method with Armijo backtracking for square systems over flat arrays.

    Parameters
    ----------
    atol : convergence threshold on ‖f‖∞ (the residuals of socbjax are dimensionless; see
        :func:`socbjax.default_atol`).  May be a traced scalar (new values do not recompile).
    max_iterations : Newton steps before ``RESULTS.max_iterations``.
    max_backtracks : step halvings per step before ``RESULTS.line_search_failed``.
    linear_solver : a socbjax solver (:class:`DenseLU`, :class:`ColouredSparseLU`,
        :class:`Bordered`) — they report sign(det J) — or any square ``lineax`` solver.
    armijo : sufficient-decrease fraction.
    step_limit : None, or ``step_limit(y, direction, args)`` → the largest fraction α ∈ (0, 1]
        of a Newton step the problem admits (contact: no gap may jump deep into the contact
        band in one step, IPC's step-length filter); backtracking starts from it.
    """

    atol: Any = 1e-12
    max_iterations: Any = 40
    max_backtracks: Any = 16
    linear_solver: lx.AbstractLinearSolver = DenseLU()
    armijo: float = 1e-4
    rtol: float = 0.0  # optimistix's interface; unused (the test is on ‖f‖∞ alone)
    norm: Callable = _inf_norm
    step_limit: Callable | None = None

    def init(self, fn, y, args, options, f_struct, aux_struct, tags) -> NewtonState:
        del fn, args, options, aux_struct, tags
        dtype = y.dtype
        if y.ndim != 1 or f_struct.shape != y.shape:
            raise ValueError(f"DampedNewton solves square systems over flat arrays; got y {y.shape}, f {f_struct.shape}")
        zero = jnp.zeros((), jnp.int32)
        return NewtonState(
            accepted=y, merit=jnp.asarray(jnp.inf, dtype), direction=jnp.zeros_like(y), alpha=jnp.ones((), dtype),
            backtracks=zero, iterations=zero, residual_norm=jnp.asarray(jnp.inf, dtype),
            stats=_stats_like(self.linear_solver, y.shape[0], dtype), result=RESULTS.successful,
            done=jnp.asarray(False),
        )

    def step(self, fn, y, args, options, state: NewtonState, tags):
        f, lin, aux = jax.linearize(lambda z: fn(z, args), y, has_aux=True)
        merit = 0.5 * jnp.sum(f * f)
        norm = _inf_norm(f)
        first = jnp.isinf(state.merit)
        finite = jnp.isfinite(norm)
        converged = finite & (norm <= self.atol)
        accepted = converged | (finite & (first | (merit <= (1.0 - self.armijo * state.alpha) * state.merit)))

        # A converged point reuses the factorisation of the last Newton step (its sign and
        # tangent describe the converged neighbourhood); only a start that is already
        # converged is factored itself, so every solve reports them.
        factors = accepted & (~converged | first)
        # Under vmap the cond below runs both branches for every member; "active" lets
        # host-side solvers (ColouredSparseLU) skip the factorisations that are discarded.
        # "point": solvers whose pattern depends on the state (PairedSparseLU) read it there.
        linear_options = {**options.get("linear", {}), "active": factors, "point": y}

        def factor(_):
            return self._direction(lin, f, y, linear_options, state.stats, tags)

        def keep(_):
            return state.direction, state.stats

        direction, stats = jax.lax.cond(factors, factor, keep, None)
        bad_direction = accepted & ~converged & ~jnp.all(jnp.isfinite(direction))
        iterations = state.iterations + jnp.where(accepted & ~first, 1, 0)
        backtracks = jnp.where(accepted, 0, state.backtracks + 1)
        first_alpha = 1.0
        if self.step_limit is not None:  # only after a new direction (a backtrack halves α instead)
            first_alpha = jax.lax.cond(factors, lambda _: jnp.asarray(self.step_limit(y, direction, args), y.dtype),
                                       lambda _: jnp.ones((), y.dtype), None)
        alpha = jnp.where(accepted, first_alpha, 0.5 * state.alpha)
        base = jnp.where(accepted, y, state.accepted)
        result = RESULTS.where(first & ~finite, RESULTS.nonfinite, RESULTS.successful)
        result = RESULTS.where(bad_direction, RESULTS.singular, result)
        # PairedSparseLU fails a solve whose pair list needs more colours than it prepared:
        # a capacity, not a singular J (compress grows it).
        result = RESULTS.where(bad_direction & stats["overflow"], RESULTS.colour_capacity, result)
        result = RESULTS.where(~converged & (backtracks > self.max_backtracks), RESULTS.line_search_failed, result)
        result = RESULTS.where(~converged & accepted & (iterations >= self.max_iterations), RESULTS.max_iterations, result)
        done = converged | (result != RESULTS.successful)
        new_y = jnp.where(converged, y, base + alpha * direction)
        new_state = NewtonState(
            accepted=base, merit=jnp.where(accepted, merit, state.merit), direction=direction, alpha=alpha,
            backtracks=backtracks, iterations=iterations, residual_norm=jnp.where(accepted, norm, state.residual_norm),
            stats=stats, result=result, done=done,
        )
        return new_y, new_state, aux

    def _direction(self, lin, f, y, options, stats_like, tags):
        """The Newton direction −J⁻¹f with J = ``lin`` (and the solver's stats).  socbjax
        solvers factor the linear function directly; other lineax solvers go through
        ``lineax.linear_solve``.  The iterations are not differentiated (the adjoint
        differentiates the root), so no linear-solve primitive is needed here."""
        solver = self.linear_solver
        if hasattr(solver, "factor"):
            state = solver.factor(lin, y.shape[0], y.dtype, options)
            direction, _, stats = solver.compute(state, -f, options)
        else:
            operator = lx.FunctionLinearOperator(lin, jax.ShapeDtypeStruct(y.shape, y.dtype), tags=tags)
            sol = lx.linear_solve(operator, -f, solver, options=options, throw=False)
            direction, stats = sol.value, sol.stats
        return direction, {k: stats.get(k, stats_like[k]) for k in stats_like}

    def terminate(self, fn, y, args, options, state: NewtonState, tags):
        # optimistix's loop speaks optx.RESULTS; the detailed socbjax reason stays in the state.
        failed = state.result != RESULTS.successful
        return state.done, optx.RESULTS.where(failed, optx.RESULTS.nonlinear_divergence, optx.RESULTS.successful)

    def postprocess(self, fn, y, aux, args, options, state: NewtonState, tags, result):
        converged = state.done & (state.result == RESULTS.successful)
        return jnp.where(converged, y, state.accepted), aux, {}


def newton_result(solution) -> RESULTS:
    """The :class:`RESULTS` item of an ``optx.root_find`` solution of :class:`DampedNewton`:
    the solver's own reason, or optimistix's (e.g. ``nonfinite``, the evaluation budget)."""
    ours = solution.state.result
    return RESULTS.where(ours == RESULTS.successful, RESULTS.promote(solution.result), ours)


def root_find(fn, y0, args=None, *, solver: DampedNewton, options: dict | None = None,
              adjoint: optx.AbstractAdjoint | None = None, max_evaluations: int | None = None):
    """``optx.root_find(fn, solver, y0, args, ...)`` with ``throw=False``, derivatives by
    :class:`socbjax.ImplicitAdjoint` (with the solver's linear solver) unless ``adjoint`` says
    otherwise, and a budget of residual evaluations that covers every Newton step and
    backtrack; returns the ``optx.Solution`` (``.value``, ``.result``, ``.state``:
    :class:`NewtonState`)."""
    if adjoint is None:
        adjoint = ImplicitAdjoint(solver.linear_solver)
    if max_evaluations is None:
        max_evaluations = 4096  # a bound, not a knob: DampedNewton stops itself well before
    return optx.root_find(fn, solver, y0, args, options or {}, has_aux=False, max_steps=max_evaluations,
                          adjoint=adjoint, throw=False)
