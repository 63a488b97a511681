"""Load continuation: ramp the applied loads λ F, λ: 0 → 1, warm-starting each step.

One compiled ``lax.while_loop``: each step predicts the next state along the path tangent
dx/dλ = −J⁻¹ ∂R/∂λ (Euler predictor), corrects with Newton, and on failure halves the step
and retries from the last accepted state (automatic cut-back).  A converged step is still
rejected when the Newton correction is large compared with the predicted increment: then the
path bends too sharply for the step (e.g. near the buckling load of a slightly imperfect
column) and Newton may have landed on another branch.  A step is also rejected when the
sign of det J changes between the last accepted state and the new one: along a load path
det J vanishes only at a critical point (limit load or bifurcation), so a sign change means
Newton jumped to another branch (typically the unstable near-straight branch just past
buckling).  Quick convergence doubles the step.

If the step falls below ``min_step`` the run stops with ``Status.CRITICAL_POINT`` (the last
rejection was a determinant sign change) or ``Status.CONTINUATION_FAILED`` (otherwise), and
returns the last *accepted* state and its load factor: never a state that did not converge.
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
    max_corrector_ratio : reject a step whose Newton correction of the node positions exceeds
        this fraction of the tangent predictor's position increment (the path turned too
        sharply for the step size).
    check_path_continuity : reject steps across which sign(det J) changes (see module doc).
    """

    initial_step: float = 0.25
    min_step: float = 1e-6
    max_step: float = 1.0
    max_steps: int = 500
    fast_iterations: int = 5
    max_corrector_ratio: float = 0.5
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
    # Step acceptance compares geometric (node position) changes only: forces and moments
    # grow with λ on any path and would hide a jump between branches.
    geometry = ravel_pytree(
        eqx.tree_at(lambda s: s.positions, jax.tree_util.tree_map(jnp.zeros_like, state0), jnp.ones_like(state0.positions))
    )[0]

    def residual_fn(lam, frames):
        return lambda x: model.residual(unravel(x), lam * loads, frames)

    def analyse(x, lam, frames, jac):
        """sign(det J) and the path tangent dx/dλ = −J⁻¹ ∂R/∂λ near an equilibrium x.  Dense:
        J is Newton's last Jacobian (within its quadratic-convergence neighbourhood of x), so
        this costs one solve; with a ``jacobian_solver`` J is assembled and factored at x."""
        _, dr_dlam = jax.jvp(lambda l: model.residual(unravel(x), l * loads, frames), (lam,), (jnp.ones_like(lam),))
        if solver.jacobian_solver is None:
            tangent = -jnp.linalg.solve(jac, dr_dlam)
            sign = jnp.linalg.slogdet(jac)[0]
        else:
            tangent, sign = solver.jacobian_solver.solve(residual_fn(lam, frames), x, -dr_dlam)
        sign = sign if settings.check_path_continuity else jnp.ones((), dtype)
        return sign, jnp.where(jnp.all(jnp.isfinite(tangent)), tangent, 0.0)

    def cond(c):
        return c["status"] == _RUNNING

    def body(c):
        # The first pass solves at λ = 0 (already an equilibrium) only to get J, its
        # determinant sign and the path tangent there: one traced Newton serves both.
        primed = c["sign"] != 0
        lam_try = jnp.where(primed, jnp.minimum(c["lam"] + c["step"], 1.0), c["lam"])
        guess = c["x"] + (lam_try - c["lam"]) * c["tangent"]
        frames = model.frames(unravel(guess))
        result = solver(residual_fn(lam_try, frames), guess)
        converged = result.status == Status.CONVERGED
        sign, tangent = analyse(result.x, lam_try, frames, result.jacobian)
        same_branch = ~primed | (sign == c["sign"])
        predicted = jnp.linalg.norm(geometry * (guess - c["x"]))
        corrected = jnp.linalg.norm(geometry * (result.x - guess))
        size = jnp.linalg.norm(geometry * c["x"])
        smooth = corrected <= settings.max_corrector_ratio * predicted + 1e-9 * (1.0 + size)
        ok = converged & same_branch & smooth
        fast = result.iterations <= settings.fast_iterations
        grown = jnp.where(primed, jnp.minimum(jnp.where(fast, 2.0, 1.0) * c["step"], settings.max_step), c["step"])
        new = dict(
            x=jnp.where(ok, result.x, c["x"]),
            tangent=jnp.where(ok, tangent, c["tangent"]),
            sign=jnp.where(primed, c["sign"], jnp.where(ok, sign, 0.0)),
            lam=jnp.where(ok, lam_try, c["lam"]),
            step=jnp.where(ok, grown, 0.5 * c["step"]),
            steps=c["steps"] + jnp.where(primed, 1, 0),
            cutbacks=c["cutbacks"] + jnp.where(ok, 0, 1),
            iterations=c["iterations"] + jnp.where(primed, result.iterations, 0),
            residual_norm=jnp.where(ok, result.residual_norm, c["residual_norm"]),
        )
        done = ok & primed & (lam_try >= 1.0)
        failed = (~ok & (new["step"] < settings.min_step)) | (new["steps"] >= settings.max_steps)
        failed = failed | (~primed & ~ok)  # the λ = 0 state itself is not an equilibrium
        failure = jnp.where(converged & ~same_branch, Status.CRITICAL_POINT, Status.CONTINUATION_FAILED)
        status = jnp.where(done, Status.CONVERGED, jnp.where(failed, failure, _RUNNING))
        new["status"] = status.astype(jnp.int32)
        return new

    init = dict(
        x=x0,
        tangent=jnp.zeros_like(x0),
        sign=jnp.zeros((), dtype),
        lam=jnp.zeros((), dtype),
        step=jnp.asarray(settings.initial_step, dtype),
        steps=jnp.zeros((), jnp.int32),
        cutbacks=jnp.zeros((), jnp.int32),
        iterations=jnp.zeros((), jnp.int32),
        residual_norm=jnp.zeros((), dtype),
        status=jnp.asarray(_RUNNING, jnp.int32),
    )
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
