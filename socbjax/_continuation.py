"""Load continuation: ramp the applied loads λ F, λ: 0 → 1, warm-starting each step.

One compiled ``lax.while_loop``: each step predicts the next state by secant extrapolation
of the last two accepted states, corrects with Newton, and on failure halves the step and
retries from the last accepted state (automatic cut-back).  Quick convergence doubles the
step.  A step is also rejected when the sign of det J changes between the last accepted state
and the new one: along a load path det J vanishes only at a critical point (limit load or
bifurcation), so a sign change means Newton jumped to another branch (typically the unstable
near-straight branch just past buckling) rather than following the path.  If steps are cut to
``min_step`` for that reason the run stops with ``Status.CRITICAL_POINT``.  If the step falls below ``min_step`` the run stops with
``Status.CONTINUATION_FAILED`` and returns the last *accepted* state and its load factor:
never a state that did not converge.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, Float, Int

from ._newton import NewtonSolver, Status

__all__ = ["ContinuationSettings", "ContinuationResult", "load_continuation"]

_RUNNING = -1


class ContinuationSettings(eqx.Module):
    """Step control of load continuation (load factors are fractions of the full load).

    initial_step : first increment of λ.   min_step : smallest increment before giving up.
    max_step : largest increment.          max_steps : cap on attempted steps.
    fast_iterations : a step converging in at most this many iterations doubles the next.
    check_path_continuity : reject steps across which sign(det J) changes (see module doc).
    """

    initial_step: float = 0.25
    min_step: float = 1e-6
    max_step: float = 1.0
    max_steps: int = 500
    fast_iterations: int = 5
    check_path_continuity: bool = True


class ContinuationResult(eqx.Module):
    """Last accepted state of a load ramp and how the ramp went."""

    state: object  # the model's state pytree
    status: Int[Array, ""]
    load_factor: Float[Array, ""]
    steps: Int[Array, ""]
    cutbacks: Int[Array, ""]
    iterations: Int[Array, ""]
    residual_norm: Float[Array, ""]


def load_continuation(
    model,
    loads: Float[Array, "N d"],
    state0,
    *,
    solver: NewtonSolver,
    settings: ContinuationSettings,
) -> ContinuationResult:
    """Solve ``model.residual(state, λ loads, frames) = 0`` for λ = 1 by continuation from
    ``state0`` (a solution at λ = 0).  Jit-compatible; see module docstring."""
    x0, unravel = ravel_pytree(state0)
    dtype = x0.dtype

    def newton_at(x_guess, lam):
        frames = model.frames(unravel(x_guess))

        def fn(x):
            return model.residual(unravel(x), lam * loads, frames)

        result = solver(fn, x_guess)
        if settings.check_path_continuity:
            sign = jnp.linalg.slogdet(jax.jacfwd(fn)(result.x))[0]
        else:
            sign = jnp.ones((), dtype)
        return result, sign

    def cond(c):
        return c["status"] == _RUNNING

    def body(c):
        lam_try = jnp.minimum(c["lam"] + c["step"], 1.0)
        has_secant = c["lam"] > c["lam_prev"]
        slope = (c["x"] - c["x_prev"]) / jnp.where(has_secant, c["lam"] - c["lam_prev"], 1.0)
        guess = c["x"] + jnp.where(has_secant, lam_try - c["lam"], 0.0) * slope
        result, sign = newton_at(guess, lam_try)
        converged = result.status == Status.CONVERGED
        same_branch = sign == c["sign"]
        ok = converged & same_branch
        fast = result.iterations <= settings.fast_iterations
        grown = jnp.minimum(jnp.where(fast, 2.0, 1.0) * c["step"], settings.max_step)
        new = dict(
            x=jnp.where(ok, result.x, c["x"]),
            x_prev=jnp.where(ok, c["x"], c["x_prev"]),
            lam=jnp.where(ok, lam_try, c["lam"]),
            lam_prev=jnp.where(ok, c["lam"], c["lam_prev"]),
            step=jnp.where(ok, grown, 0.5 * c["step"]),
            steps=c["steps"] + 1,
            cutbacks=c["cutbacks"] + jnp.where(ok, 0, 1),
            iterations=c["iterations"] + result.iterations,
            residual_norm=jnp.where(ok, result.residual_norm, c["residual_norm"]),
            status=c["status"],
            sign=c["sign"],
        )
        done = ok & (lam_try >= 1.0)
        failed = (~ok & (new["step"] < settings.min_step)) | (new["steps"] >= settings.max_steps)
        failure = jnp.where(converged & ~same_branch, Status.CRITICAL_POINT, Status.CONTINUATION_FAILED)
        new["status"] = jnp.where(done, Status.CONVERGED, jnp.where(failed, failure, _RUNNING))
        new["status"] = new["status"].astype(jnp.int32)
        return new

    init = dict(
        x=x0,
        x_prev=x0,
        lam=jnp.zeros((), dtype),
        lam_prev=jnp.zeros((), dtype),
        step=jnp.asarray(settings.initial_step, dtype),
        steps=jnp.zeros((), jnp.int32),
        cutbacks=jnp.zeros((), jnp.int32),
        iterations=jnp.zeros((), jnp.int32),
        residual_norm=jnp.zeros((), dtype),
        status=jnp.asarray(_RUNNING, jnp.int32),
    )
    if settings.check_path_continuity:
        frames0 = model.frames(state0)
        init["sign"] = jnp.linalg.slogdet(jax.jacfwd(lambda x: model.residual(unravel(x), 0.0 * loads, frames0))(x0))[0]
    else:
        init["sign"] = jnp.ones((), dtype)
    out = jax.lax.while_loop(cond, body, init)
    return ContinuationResult(
        state=unravel(out["x"]),
        status=out["status"],
        load_factor=out["lam"],
        steps=out["steps"],
        cutbacks=out["cutbacks"],
        iterations=out["iterations"],
        residual_norm=out["residual_norm"],
    )
