"""Path following in one scalar control parameter: natural-parameter (displacement control)
and pseudo-arclength (Keller/Riks) continuation, with cut-back, stability and event data.

The equilibrium path of ``F(x, p) = 0`` (``x`` the flat state, ``p ∈ [0, 1]`` the phase
parameter; the caller maps p to a probe displacement or a load factor) is followed from a
converged ``(x₀, 0)`` to ``p = 1``.

* **Predictor.**  The unit path tangent τ = (ẋ, ṗ) from J ẋ = −F_p ṗ (J = ∂F/∂x, F_p = ∂F/∂p),
  normalised in the weighted norm ‖(δx, δp)‖² = mean over nodes of (|δr|² + ℓ²|δdirector|²)
  + (p_scale δp)² (ℓ: mean segment length)
  (so the step ``ds`` is in µm) and oriented like the previous step; the predictor is
  (x, p) + ds τ, shortened to land exactly on p = 1.  Both methods use it: near a straight
  strand's buckling the shape changes like √u, so a step in u alone would be a poor guess.
* **Corrector.**  Newton on the bordered system [F(x, p); g(x, p)] = 0 with g = p − p_target
  (displacement control at the predicted p, and the final landing on p = 1) or
  g = ⟨τ, (x, p) − predictor⟩
  (pseudo-arclength: the hyperplane through the predictor normal to τ).  Each iteration
  solves J [a c] = [−F, F_p] with one factorisation of the pluggable Jacobian solver
  (dense or sparse, see :mod:`socbjax._linear`) and eliminates the border (the bordering
  algorithm), so the sparse solver never sees the dense border row.
* **Acceptance.**  A step is accepted only if Newton converged, the corrector moved the
  state by less than ``max_corrector_ratio`` of the step, and the tangent turned by less than
  ``max_turn``; under displacement control also only if sign(det J) did not change (a fold
  in the control parameter cannot be crossed at fixed displacement: the run stops with
  ``Status.CRITICAL_POINT``; use ``method="arclength"``).  Rejected steps are halved; quick
  convergence grows the step by 1.5×.  Nothing unconverged is ever recorded.

Every accepted step writes (x, p, sign det J, sign ṗ, Newton iterations) into preallocated
buffers, so a whole phase is one compiled ``lax.while_loop``.  The loop may stop after a
given number of accepted steps (``chunk``) and be resumed from its carry: that is how the
driver shows progress and writes checkpoints; the result is identical to an unchunked run.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._newton import Status

__all__ = ["PathSettings", "path_start", "path_run"]

_RUNNING = -1
METHODS = ("displacement", "arclength")


class PathSettings(eqx.Module):
    """Step control of path following (steps in µm of probe travel or of arclength).

    method : "displacement" (natural parameter) or "arclength" (pseudo-arclength).
    initial_step, min_step, max_step : step sizes (µm).
    max_steps : buffer capacity: accepted steps per phase (static).
    max_attempts : cap on attempted steps per phase (accepted + rejected).
    fast_iterations : a step converging within this many Newton iterations grows the next.
    max_corrector_ratio : reject when the corrector moved (x, p) by more than this × step.
    max_turn : reject when the path tangent turned by more than this (rad) in one step.
    atol : Newton tolerance on ‖F‖_∞ (dimensionless residual).
    max_iterations, max_backtracks : Newton iteration and step-halving caps.
    """

    method: str = eqx.field(static=True, default="displacement")
    initial_step: float = 0.02
    min_step: float = 1e-7
    max_step: float = 0.05
    max_steps: int = eqx.field(static=True, default=1000)
    max_attempts: int = 5000
    fast_iterations: int = 4
    max_corrector_ratio: float = 0.5
    max_turn: float = 0.6
    atol: float = 1e-10
    max_iterations: int = 25
    max_backtracks: int = 12

    def __check_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not 0 < self.min_step <= self.initial_step <= self.max_step:
            raise ValueError(
                f"need 0 < min_step <= initial_step <= max_step (µm), got {self.min_step}, {self.initial_step}, {self.max_step}"
            )
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, got {self.max_steps}")


def _inner(weights, a, b):
    return jnp.sum(weights * a * b)


def _tangent(c, weights, previous):
    """Unit tangent (−c, 1)/‖·‖ oriented along ``previous`` (c = J⁻¹ F_p)."""
    t = jnp.concatenate([-c, jnp.ones((1,), c.dtype)])
    t = t / jnp.sqrt(_inner(weights, t, t))
    return jnp.where(_inner(weights, t, previous) < 0, -t, t)


def _bordered_newton(F, x, p, g, linsolver, settings):
    """Newton on [F(x, p); g(x, p)] = 0; returns (x, p, status, iterations, sign, c)."""

    def residuals(x, p):
        return F(x, p), g(x, p)

    def merit(r, h):
        return jnp.sum(r * r) + h * h

    def body(carry):
        x, p, r, h, it, _, _, _ = carry
        fp = jax.jvp(lambda q: F(x, q), (p,), (jnp.ones_like(p),))[1]
        sol, sign = linsolver.solve(lambda y: F(y, p), x, jnp.stack([-r, fp], axis=1))
        a, c = sol[:, 0], sol[:, 1]
        gx, gp = jax.grad(g, argnums=(0, 1))(x, p)
        dp = (-h - jnp.dot(gx, a)) / (gp - jnp.dot(gx, c))
        dx = a - c * dp
        m0 = merit(r, h)

        def ls_cond(ls):
            alpha, k, _, _, m = ls
            return ~(m <= (1.0 - 1e-4 * alpha) * m0) & (k < settings.max_backtracks)

        def ls_body(ls):
            alpha, k, _, _, _ = ls
            alpha = 0.5 * alpha
            r1, h1 = residuals(x + alpha * dx, p + alpha * dp)
            return alpha, k + 1, r1, h1, merit(r1, h1)

        alpha, _, r1, h1, m1 = jax.lax.while_loop(
            ls_cond, ls_body, (jnp.asarray(2.0, x.dtype), -1, r, h, jnp.asarray(jnp.inf, x.dtype))
        )
        ok = (m1 <= (1.0 - 1e-4 * alpha) * m0) & jnp.all(jnp.isfinite(dx)) & jnp.isfinite(dp)
        x1 = jnp.where(ok, x + alpha * dx, x)
        p1 = jnp.where(ok, p + alpha * dp, p)
        r1, h1 = jnp.where(ok, r1, r), jnp.where(ok, h1, h)
        it = it + 1
        norm = jnp.maximum(jnp.max(jnp.abs(r1)), jnp.abs(h1))
        status = jnp.where(norm <= settings.atol, Status.CONVERGED, _RUNNING)
        status = jnp.where((status == _RUNNING) & ~ok, Status.LINE_SEARCH_FAILED, status)
        status = jnp.where((status == _RUNNING) & (it >= settings.max_iterations), Status.MAX_ITERATIONS, status)
        return x1, p1, r1, h1, it, status.astype(jnp.int32), sign, c

    r0, h0 = residuals(x, p)
    status0 = jnp.where(jnp.all(jnp.isfinite(r0)), _RUNNING, Status.NONFINITE).astype(jnp.int32)
    init = (x, p, r0, h0, jnp.zeros((), jnp.int32), status0, jnp.zeros((), x.dtype), jnp.zeros_like(x))
    x, p, _, _, it, status, sign, c = jax.lax.while_loop(lambda s: s[5] == _RUNNING, body, init)
    return x, p, status, it, sign, c


def path_start(make_F, x0, weights, linsolver, settings: PathSettings) -> dict:
    """The carry of :func:`path_run` at a converged point (x₀, p = 0): tangent, det sign and
    empty step buffers.  ``make_F(x_ref)`` returns the residual F(x, p) with its analysis
    frames taken at ``x_ref`` (held fixed during one corrector); ``weights`` [n + 1]: the norm
    weights of (x, p) (see module doc)."""
    F = make_F(x0)
    dtype = x0.dtype
    p0 = jnp.zeros((), dtype)
    fp = jax.jvp(lambda q: F(x0, q), (p0,), (jnp.ones_like(p0),))[1]
    sol, sign = linsolver.solve(lambda y: F(y, p0), x0, fp[:, None])
    forward = jnp.zeros(x0.size + 1, dtype).at[-1].set(1.0)
    tau = _tangent(sol[:, 0], weights, forward)
    n, m = x0.size, settings.max_steps
    return dict(
        x=x0,
        p=p0,
        tau=tau,
        sign=sign,
        sign0=sign,
        ds=jnp.asarray(settings.initial_step, dtype),
        steps=jnp.zeros((), jnp.int32),
        attempts=jnp.zeros((), jnp.int32),
        cutbacks=jnp.zeros((), jnp.int32),
        iterations=jnp.zeros((), jnp.int32),
        status=jnp.asarray(_RUNNING, jnp.int32),
        rejected_by_sign=jnp.zeros((), bool),
        X=jnp.zeros((m, n), dtype),
        P=jnp.zeros(m, dtype),
        SIGN=jnp.zeros(m, dtype),
        TAU_P=jnp.zeros(m, dtype),
        ITER=jnp.zeros(m, jnp.int32),
    )


def _attempt(make_F, c, weights, p_scale, linsolver, settings):
    """One predictor–corrector attempt from the carry's last accepted point."""
    arclength = settings.method == "arclength"
    ds, x, p, tau = c["ds"], c["x"], c["p"], c["tau"]
    # Tangent predictor of length ds; when it would pass p = 1, shorten it to land on p = 1.
    reach = jnp.where(tau[-1] > 0, (1.0 - p) / jnp.where(tau[-1] > 0, tau[-1], 1.0), jnp.inf)
    landing = reach <= ds
    h = jnp.minimum(ds, reach)
    guess_x, guess_p = x + h * tau[:-1], jnp.where(landing, 1.0, p + h * tau[-1])
    F = make_F(guess_x)

    def g(xx, pp):
        natural = pp - guess_p
        if not arclength:
            return natural
        along = _inner(weights, tau, jnp.concatenate([xx - guess_x, (pp - guess_p)[None]]))
        return jnp.where(landing, natural, along)

    x1, p1, status, it, sign, cc = _bordered_newton(F, guess_x, guess_p, g, linsolver, settings)
    converged = status == Status.CONVERGED
    secant = jnp.concatenate([x1 - x, (p1 - p)[None]])
    secant = secant / jnp.sqrt(jnp.maximum(_inner(weights, secant, secant), 1e-300))
    tau1 = _tangent(cc, weights, secant)
    tau1 = jnp.where(jnp.all(jnp.isfinite(tau1)), tau1, secant)
    moved = jnp.concatenate([x1 - guess_x, (p1 - guess_p)[None]])
    smooth = jnp.sqrt(_inner(weights, moved, moved)) <= settings.max_corrector_ratio * h + 1e-12
    turned = jnp.arccos(jnp.clip(_inner(weights, tau1, tau), -1.0, 1.0)) <= settings.max_turn
    # Displacement control cannot pass a fold: det J changes sign and the path turns back in p.
    fold = (sign != c["sign"]) | (tau1[-1] <= 0)
    passable = ~fold | arclength
    ok = converged & smooth & turned & passable & (sign != 0)
    return ok, x1, p1, tau1, sign, it, converged & ~passable


def path_run(make_F, carry: dict, weights, p_scale, linsolver, settings: PathSettings, chunk) -> dict:
    """Continue the path in ``carry`` until p = 1, failure, the buffer is full, or ``chunk``
    more steps have been accepted (status stays running: call again to resume)."""
    stop_at = carry["steps"] + chunk

    def cond(c):
        return (c["status"] == _RUNNING) & (c["steps"] < stop_at)

    def body(c):
        ok, x1, p1, tau1, sign, it, sign_flip = _attempt(make_F, c, weights, p_scale, linsolver, settings)
        k = c["steps"]
        fast = it <= settings.fast_iterations
        new = dict(c)
        new["x"] = jnp.where(ok, x1, c["x"])
        new["p"] = jnp.where(ok, p1, c["p"])
        new["tau"] = jnp.where(ok, tau1, c["tau"])
        new["sign"] = jnp.where(ok, sign, c["sign"])
        new["ds"] = jnp.where(ok, jnp.minimum(jnp.where(fast, 1.5, 1.0) * c["ds"], settings.max_step), 0.5 * c["ds"])
        new["steps"] = k + ok.astype(jnp.int32)
        new["attempts"] = c["attempts"] + 1
        new["cutbacks"] = c["cutbacks"] + (~ok).astype(jnp.int32)
        new["iterations"] = c["iterations"] + it
        # A fold ahead: some rejection since the last accepted step crossed it (det J sign or
        # a backward tangent), or the path is nearly vertical in p (|dp/ds| p_scale < 0.1).
        near_fold = (settings.method != "arclength") & (jnp.abs(c["tau"][-1]) * p_scale < 0.1)
        new["rejected_by_sign"] = jnp.where(ok, False, c["rejected_by_sign"] | sign_flip | near_fold)
        idx = jnp.minimum(k, settings.max_steps - 1)
        for name, value in (("X", x1), ("P", p1), ("SIGN", sign), ("TAU_P", tau1[-1]), ("ITER", it)):
            new[name] = jnp.where(ok, c[name].at[idx].set(value), c[name])
        done = ok & (p1 >= 1.0 - 1e-12)
        too_small = ~ok & (new["ds"] < settings.min_step)
        failure = jnp.where(new["rejected_by_sign"], Status.CRITICAL_POINT, Status.CONTINUATION_FAILED)
        full = (new["steps"] >= settings.max_steps) | (new["attempts"] >= settings.max_attempts)
        status = jnp.where(done, Status.CONVERGED, jnp.where(too_small, failure, jnp.where(full, Status.MAX_STEPS, _RUNNING)))
        new["status"] = status.astype(jnp.int32)
        return new

    return jax.lax.while_loop(cond, body, carry)


def path_weights(x_template: Array, geometry_mask: Array, n_nodes: int, p_scale) -> Array:
    """Norm weights [n + 1]: ``geometry_mask`` (squared µm per unit of each state entry,
    zero for entries left out) averaged over nodes, and p scaled to µm."""
    w = geometry_mask / n_nodes
    return jnp.concatenate([w, jnp.asarray(p_scale, x_template.dtype)[None] ** 2])
