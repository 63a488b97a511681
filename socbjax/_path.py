"""The one path engine: :func:`follow_path` (continuation in one scalar control parameter).

The equilibrium path of ``F(x, p) = 0`` (``x`` the flat state, ``p ∈ [0, 1]`` the path
parameter; :class:`PathProblem` maps p to the controls of the residual: a load factor for the
load ramp of :func:`socbjax.solve`, a probe displacement for :func:`socbjax.compress`) is
followed from a converged ``(x₀, p₀)`` to ``p = 1``.  Pluggable pieces:

* the **parametrisation** — :class:`NaturalParameter` (the corrector holds p at its
  predicted value: load ramps and displacement control; a fold in p stops the run with
  ``RESULTS.fold``) or :class:`PseudoArclength` (the corrector moves in the hyperplane
  through the predictor normal to the path tangent, so folds and snap-backs are followed);
* the **step controller** (:class:`PathSettings`, ``socbjax._path_settings``): step sizes, growth, cut-back, budgets and
  the acceptance tests below;
* the **recorder** (:class:`NoRecorder`, :class:`StepRecorder`, ``socbjax._sampled``'s
  sample recorder): what is kept of each accepted step, in preallocated buffers.

Each attempt: the unit tangent τ = (ẋ, ṗ) (from J ẋ = −F_p ṗ, normalised in the weighted
norm ‖(δx, δp)‖²_w = Σ wᵢ δxᵢ² + w_p δp²) gives the predictor y + h τ, shortened to land on
p = 1; :class:`socbjax.DampedNewton` corrects it on the bordered system [F; g] = 0 (the
:class:`socbjax._linear.Bordered` solver: one factorisation of J per Newton step, which also
yields sign(det J) and the next tangent).  A step is accepted only if Newton converged, the
corrector moved the state by at most ``max_corrector_ratio`` of the predicted increment
(in the ``check`` norm), the tangent turned by at most ``max_turn`` and det J ≠ 0 (a step
no longer than ``corner_step`` may pass a corner: a turn up to 1.25 rad, a corrector up to 3×
the increment; see :func:`_accept`); under
natural-parameter control also only if sign(det J) did not change (a critical point: the
run stops with ``RESULTS.critical_point`` when the step shrinks below its minimum) and the
path did not turn back in p (``RESULTS.fold``).  Pseudo-arclength passes folds, and a sign
change without a fold only with a step no longer than max(``corner_step``, 2 ``min_step``)
(longer steps across the near-bifurcation of an imperfect network land on its unstable
branch); its first step from the start is a natural-parameter step (see
:func:`_first_arclength_step`).  Rejected steps are halved; quick convergence grows the
next step.  Nothing unconverged is ever recorded.

The whole run is one ``lax.while_loop`` over a typed :class:`PathState`; the loop may stop
after a given number of accepted steps and be resumed from its state (progress and
checkpoints of :func:`socbjax.compress`); the result is identical to an unchunked run.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from ._adjoint import NonDifferentiable
from ._linear import Bordered
from ._path_settings import PathSettings
from ._residual import Control
from ._root import DampedNewton, newton_result, root_find
from ._solution import RESULTS

__all__ = ["NaturalParameter", "PseudoArclength", "PathProblem", "PathState", "PathPoint", "NoRecorder",
           "StepRecorder", "StepRecords", "follow_path", "start_path", "parametrisation", "model_frames",
           "state_template", "state_unravel"]

# ----------------------------------------------------------------- parametrisations
class NaturalParameter(eqx.Module):
    """Natural-parameter continuation: the corrector fixes p at the predictor's value."""

    passes_folds = False

    def border(self, tau, weights):
        """The constraint row (a [n], b): a·(x − x̂) + b (p − p̂) = 0."""
        return jnp.zeros_like(tau[:-1]), jnp.ones((), tau.dtype)


class PseudoArclength(eqx.Module):
    """Pseudo-arclength (Keller/Riks): the corrector moves ⊥ (weighted) to the tangent τ."""

    passes_folds = True

    def border(self, tau, weights):
        w = weights * tau
        return w[:-1], w[-1]


def parametrisation(method: str):
    """The parametrisation of a ``PathSettings.method``."""
    return PseudoArclength() if method == "arclength" else NaturalParameter()


# ----------------------------------------------------------------------- problem
class PathProblem(eqx.Module):
    """``F(x, p)`` of a model along a straight line of controls, control(p) = control0 +
    p (control1 − control0).  ``weights`` [n + 1] define the step norm; ``check`` [n + 1]
    the norm of the corrector and turn tests (both include p last)."""

    model: eqx.Module
    control0: Control
    control1: Control
    weights: Array
    check: Array

    def unravel(self):
        return state_unravel(self.model)

    def control(self, p) -> Control:
        """The controls at path parameter p (control0 at 0, control1 at 1)."""
        return self.control0.towards(self.control1, p)

    def residual(self, x, p, frames):
        return self.model.residual(self.unravel()(x), self.control(p), frames)

    def frames(self, y):
        """The model's frames at [x; p]: ``model.path_frames(state, control)`` where the model
        has it (:meth:`socbjax.SOCBModel.path_frames`: the near list needs the probe face's
        place), else ``model.frames(state)``."""
        return model_frames(self.model, self.unravel()(y[:-1]), self.control(y[-1]))

    def hold_pairs(self, y, frames):
        """[x; p] with the pair slots' ids set to the step's list (Newton's first step would put
        them there: their rows are x_id − list id); PairedSparseLU reads the list from x."""
        hold = getattr(self.model, "hold_pairs", None)
        return y if hold is None else jnp.concatenate([ravel_pytree(hold(self.unravel()(y[:-1]), frames))[0], y[-1:]])

    def admissible(self, x0, y1, frames):
        """(whether the step x0 → y1 = [x1; p1] under the step's ``frames`` passes the model's
        own test, whether the model's capacity overflowed there): contact, no filament moved
        through an obstacle or another filament, and no more contact pairs (near segments) than
        slots (:meth:`socbjax.SOCBModel.step_admissible`)."""
        test = getattr(self.model, "step_admissible", None)
        if test is None:
            return jnp.asarray(True), jnp.asarray(False)
        displacement = self.control(y1[-1]).displacement
        return test(self.unravel()(x0), self.unravel()(y1[:-1]), frames, displacement)

    def step_limit(self, y0, y1):
        """The largest fraction α ∈ (0, 1] of a Newton step y0 → y1 ([x; p] each) that the
        model admits (:meth:`socbjax.SOCBModel.newton_step_limit`; 1 without one)."""
        test = getattr(self.model, "newton_step_limit", None)
        if test is None:
            return jnp.ones((), y0.dtype)
        return test(self.unravel()(y0[:-1]), self.unravel()(y1[:-1]), self.control(y0[-1]), self.control(y1[-1]))


def state_template(model):
    """A state with ``model``'s structure (values unspecified): ``model.state_template()``
    where the model has one (:meth:`socbjax.SOCBModel.state_template`: no contact start),
    else ``model.initial_state()``."""
    template = getattr(model, "state_template", None)
    return model.initial_state() if template is None else template()


def state_unravel(model):
    """The function from a flat state [n] to ``model``'s state (:func:`state_template`)."""
    return ravel_pytree(state_template(model))[1]


def model_frames(model, state, control):
    """``model.path_frames(state, control)`` where the model has it (the frames that depend on
    the controls: :meth:`socbjax.SOCBModel.path_frames`), else ``model.frames(state)``."""
    placed = getattr(model, "path_frames", None)
    return model.frames(state) if placed is None else placed(state, control)


def _corrector_limit(y, direction, args):
    """The largest fraction of a corrector step y → y + direction that the problem admits
    (:meth:`PathProblem.step_limit`; ``args`` as for :func:`_corrector_fn`)."""
    return args[0].step_limit(y, y + direction)


def _newton(settings: PathSettings, inner) -> DampedNewton:
    """The corrector: :class:`DampedNewton` on the bordered system with ``inner``."""
    return DampedNewton(atol=settings.atol, max_iterations=settings.max_iterations,
                        max_backtracks=settings.max_backtracks, linear_solver=Bordered(inner),
                        step_limit=_corrector_limit)


_CORNER_TURN = 1.25  # rad: the largest turn a corner step may take (PathSettings.corner_step)
_CORNER_RATIO = 3.0  # ≈ tan(_CORNER_TURN): the corrector of a step across such a corner


def _norm(weights, v):
    return jnp.sqrt(jnp.maximum(jnp.sum(weights * v * v), 0.0))


def _unit_tangent(v, weights, previous):
    """(−v, 1) normalised in the weighted norm and oriented along ``previous`` (v = J⁻¹F_p)."""
    t = jnp.concatenate([-v, jnp.ones((1,), v.dtype)])
    t = t / _norm(weights, t)
    return jnp.where(jnp.sum(weights * t * previous) < 0, -t, t)


def _corrector_fn(y, args):
    problem, frames, a, b, guess = args
    F = problem.residual(y[:-1], y[-1], frames)
    g = jnp.dot(a, y[:-1] - guess[:-1]) + b * (y[-1] - guess[-1])
    return jnp.concatenate([F, g[None]])


def _correct(problem, guess, border, newton):
    """Newton on [F; g] from ``guess`` = [x̂; p̂]: (y, result, iterations, sign, tangent v,
    residual norm, the step's frames)."""
    frames = problem.frames(guess)
    guess = problem.hold_pairs(guess, frames)
    args = jax.lax.stop_gradient((problem, frames, border[0], border[1], guess))
    sol = root_find(_corrector_fn, jax.lax.stop_gradient(guess), args, solver=newton,
                    options={"linear": {"border": args[2:4]}}, adjoint=NonDifferentiable())
    state = sol.state
    return (sol.value, newton_result(sol), state.iterations, state.stats["sign"], state.stats["tangent"],
            state.residual_norm, args[1])


# ---------------------------------------------------------------------- recorders
class PathPoint(eqx.Module):
    """A point of the path handed to recorders: state x, parameter p, sign(det J), unit
    tangent tau [n + 1] and the Newton iterations that found it."""

    x: Array
    p: Array
    sign: Array
    tau: Array
    iterations: Array


class NoRecorder(eqx.Module):
    """Keeps nothing (load ramps of :func:`socbjax.solve`)."""

    def init(self, x0, p0):
        return None

    def record(self, rec, ok, index, previous: PathPoint, new: PathPoint):
        return rec


class StepRecords(eqx.Module):
    """Buffers of :class:`StepRecorder` (m rows): X [m, n], P, SIGN (sign det J), TAU_P
    (dp/ds of the unit tangent) [m], ITER [m] (Newton iterations)."""

    X: Array
    P: Array
    SIGN: Array
    TAU_P: Array
    ITER: Array

    def rows(self, k: int) -> dict:
        """The first k rows as numpy arrays (sliced on the host: no program per k)."""
        return {name: np.asarray(getattr(self, name))[:k] for name in ("X", "P", "SIGN", "TAU_P", "ITER")}


class StepRecorder(eqx.Module):
    """Every accepted step into :class:`StepRecords` of ``capacity`` rows."""

    capacity: int = eqx.field(static=True)

    def init(self, x0, p0) -> StepRecords:
        m, n = self.capacity, x0.shape[0]
        zeros = jnp.zeros(m, x0.dtype)
        return StepRecords(X=jnp.zeros((m, n), x0.dtype), P=zeros, SIGN=zeros, TAU_P=zeros, ITER=jnp.zeros(m, jnp.int32))

    def record(self, rec: StepRecords, ok, index, previous: PathPoint, new: PathPoint) -> StepRecords:
        i = jnp.minimum(index, self.capacity - 1)

        def put(buffer, value):  # select the row, not the buffer: an in-place row update, not a copy of [m, n]
            return buffer.at[i].set(jnp.where(ok, value, buffer[i]))

        return StepRecords(X=put(rec.X, new.x), P=put(rec.P, new.p), SIGN=put(rec.SIGN, new.sign),
                           TAU_P=put(rec.TAU_P, new.tau[-1]), ITER=put(rec.ITER, new.iterations))


# ------------------------------------------------------------------------- state
class PathState(eqx.Module):
    """The carry of :func:`follow_path` (typed; all arrays, so it crosses jit and vmap).

    x [n], p : last accepted point; tau [n + 1] : unit tangent there; sign : sign(det J)
    there; sign0 : at the start; ds : next step size; steps, attempts, cutbacks, iterations :
    counters (after the start); primed : the start has been solved; sign_rejected,
    fold_rejected : a rejection since the last acceptance was by a det sign change / a fold;
    residual_norm : Newton's ‖F‖∞ at x; result : :class:`socbjax.RESULTS` (``running`` is
    ``successful`` with ``done`` False); done; recorder : the recorder's buffers;
    recover : the largest step size cut back since the path last reached it, to which fast
    accepted steps return (0: none); streak : attempts accepted in a row.
    """

    x: Array
    p: Array
    tau: Array
    sign: Array
    sign0: Array
    ds: Array
    steps: Array
    attempts: Array
    cutbacks: Array
    iterations: Array
    primed: Array
    sign_rejected: Array
    fold_rejected: Array
    residual_norm: Array
    result: RESULTS
    done: Array
    recorder: object
    recover: Array
    streak: Array


def start_path(x0, p0, settings: PathSettings, recorder) -> PathState:
    """A fresh :class:`PathState` at (x₀, p₀) (solved, with its tangent, by the first pass of
    :func:`follow_path`)."""
    dtype = x0.dtype
    zero = jnp.zeros((), jnp.int32)
    p0 = jnp.asarray(p0, dtype)
    forward = jnp.zeros(x0.shape[0] + 1, dtype).at[-1].set(1.0)
    return PathState(
        x=x0, p=p0, tau=forward, sign=jnp.zeros((), dtype), sign0=jnp.zeros((), dtype),
        ds=jnp.asarray(settings.initial_step, dtype), steps=zero, attempts=zero, cutbacks=zero, iterations=zero,
        primed=jnp.asarray(False), sign_rejected=jnp.asarray(False), fold_rejected=jnp.asarray(False),
        residual_norm=jnp.zeros((), dtype), result=RESULTS.successful, done=jnp.asarray(False),
        recorder=recorder.init(x0, p0), recover=jnp.zeros((), dtype), streak=zero,
    )


def _predict(c: PathState, problem, param, settings):
    """(last point y [n + 1], predictor guess [n + 1], border row (a, b)) of the next attempt
    (at the start: the start itself, held at its p)."""
    tau = c.tau
    reach = jnp.where(tau[-1] > 0, (1.0 - c.p) / jnp.where(tau[-1] > 0, tau[-1], 1.0), jnp.inf)
    landing = (reach <= c.ds) | ~c.primed
    h = jnp.where(c.primed, jnp.minimum(c.ds, reach), 0.0)
    y = jnp.concatenate([c.x, c.p[None]])
    guess = y + h * tau
    guess = guess.at[-1].set(jnp.where(landing & c.primed, 1.0, guess[-1]))
    natural = NaturalParameter().border(tau, problem.weights)
    along = param.border(tau, problem.weights)
    fixed = landing | _first_arclength_step(c, param)
    border = jax.tree_util.tree_map(lambda n, a: jnp.where(fixed, n, a), natural, along)
    return y, guess, border


def _first_arclength_step(c: PathState, param) -> Array:
    """Whether the next attempt is an arclength path's first step from its start: it is taken
    and judged as a natural-parameter step (the corrector at the predictor's p; no critical
    point crossed; no corner step).  A probe path starts at a near-straight network, a
    near-bifurcation whose path rises almost vertically in force at fixed geometry: there the
    arclength corrector's hyperplane, blind to the forces, contains the unbuckled branch at
    every force, and the first step landed on it or on a higher mode: a 5-node clamped–clamped
    column at 26.6 pN (Euler load 2.8 pN), every step reported stable; the unit mesh of
    Fig. 6 at 188 pN, peaking at 199 pN, against 3.88 pN under displacement control.  At
    fixed p Newton finds the branch the imperfection selects, as under displacement control,
    and the path's tangent is taken there.  The corner rule does not apply to this step (it
    once accepted such a landing)."""
    return c.primed & (c.steps == 0) & param.passes_folds


def _accept(c: PathState, problem, param, settings, y, guess, y1, converged, sign, v):
    """Acceptance tests of one attempt: (ok, new unit tangent, sign flip, fold)."""
    w, check = problem.weights, problem.check
    secant = y1 - y
    secant = jnp.where(_norm(w, secant) > 0, secant / jnp.maximum(_norm(w, secant), 1e-300), c.tau)
    tau1 = _unit_tangent(v, w, jnp.where(c.primed, secant, c.tau))
    tau1 = jnp.where(jnp.all(jnp.isfinite(tau1)), tau1, secant)
    floor = settings.corrector_floor * (1.0 + _norm(check, jnp.concatenate([c.x, jnp.zeros(1, y.dtype)])))
    corrector, increment = _norm(check, y1 - guess), _norm(check, guess - y)
    smooth = corrector <= settings.max_corrector_ratio * increment + floor
    turn = jnp.arccos(jnp.clip(jnp.sum(w * tau1 * c.tau), -1.0, 1.0))
    turned = turn <= settings.max_turn
    # A corner: the tangent turns by the same angle however small the step (a strand held by
    # almost nothing meets a surface: the penalty's band is crossed over a stretch of path far
    # shorter than min_step).  The corrector then moves ~tan(turn) × the increment, in
    # proportion to the step, unlike a jump to another branch; tiny steps may pass it.
    corner_step = 0.0 if settings.corner_step is None else settings.corner_step  # None (follow_path by hand): never
    first = _first_arclength_step(c, param)
    corner = ((c.ds <= corner_step) & (turn <= _CORNER_TURN) & ~first
              & (corrector <= _CORNER_RATIO * increment + floor))
    smooth, turned = smooth | corner, turned | corner
    sign_flip = (sign != c.sign) & settings.detect_critical_points
    fold = tau1[-1] <= 0
    natural_ok = ~sign_flip & ~fold
    # Arclength passes folds, and a critical point only with a step no longer than the corner
    # step (at least 2 min_step): a long step across the near-bifurcation of an imperfect
    # network lands, on the corrector's hyperplane, on the unstable branch beyond it (an
    # imperfect pitchfork in tests/test_path.py; the 4-generation outcrop's first loading step
    # at 0.31 pN, where displacement control buckles it at 0.18 pN); shorter steps follow the
    # turn.  An even number of crossings keeps the sign: the first-step rule guards the start.
    crossing_step = jnp.maximum(corner_step, 2.0 * settings.min_step)
    crossing_ok = ~sign_flip | fold | (c.ds <= crossing_step)
    passes = jnp.where(first, natural_ok, crossing_ok) if param.passes_folds else natural_ok
    ok = converged & smooth & turned & (sign != 0) & passes
    return jnp.where(c.primed, ok, converged), tau1, sign_flip, fold


def _attempt(c: PathState, problem, param, settings, newton, recorder) -> PathState:
    y, guess, border = _predict(c, problem, param, settings)
    y1, result, iterations, sign, v, residual_norm, frames = _correct(problem, guess, border, newton)
    converged = result == RESULTS.successful
    ok, tau1, sign_flip, fold = _accept(c, problem, param, settings, y, guess, y1, converged, sign, v)
    admissible, overflow = problem.admissible(c.x, y1, frames)
    ok = ok & (admissible | ~c.primed) & ~(overflow & converged)
    primed = c.primed
    grown, recover = _next_step(c, ok, iterations, settings)
    new = PathPoint(x=y1[:-1], p=y1[-1], sign=sign, tau=tau1, iterations=iterations)
    previous = PathPoint(x=c.x, p=c.p, sign=c.sign, tau=c.tau, iterations=jnp.zeros((), jnp.int32))
    rec = recorder.record(c.recorder, ok & primed, c.steps, previous, new)
    steps = c.steps + (ok & primed).astype(jnp.int32)
    attempts = c.attempts + primed.astype(jnp.int32)
    natural = not param.passes_folds
    near_fold = natural & (jnp.abs(c.tau[-1]) * jnp.sqrt(problem.weights[-1]) < 0.1)
    sign_rejected = jnp.where(ok, False, c.sign_rejected | (converged & sign_flip & ~fold))
    fold_rejected = jnp.where(ok, False, c.fold_rejected | (converged & fold & natural) | near_fold)
    ds = jnp.where(ok, jnp.where(primed, grown, c.ds), 0.5 * c.ds)
    done_ok = ok & primed & (y1[-1] >= 1.0 - 1e-12)
    small = primed & ~ok & (ds < settings.min_step)
    failure = RESULTS.where(fold_rejected, RESULTS.fold,
                            RESULTS.where(sign_rejected, RESULTS.critical_point, RESULTS.step_too_small))
    out = RESULTS.where(small, failure, RESULTS.successful)
    out = RESULTS.where(~primed & ~ok, RESULTS.not_equilibrium, out)
    out = RESULTS.where(overflow & converged, RESULTS.contact_capacity, out)
    out = RESULTS.where(result == RESULTS.colour_capacity, RESULTS.colour_capacity, out)  # no smaller step helps
    full = (steps >= settings.max_steps) | (attempts >= settings.max_attempts)
    out = RESULTS.where((out == RESULTS.successful) & ~done_ok & full, RESULTS.max_steps, out)
    return PathState(
        x=jnp.where(ok, y1[:-1], c.x), p=jnp.where(ok, y1[-1], c.p), tau=jnp.where(ok, tau1, c.tau),
        sign=jnp.where(ok, sign, c.sign), sign0=jnp.where(primed, c.sign0, sign), ds=ds, steps=steps,
        attempts=attempts, cutbacks=c.cutbacks + (primed & ~ok).astype(jnp.int32),
        iterations=c.iterations + jnp.where(primed, iterations, 0), primed=primed | ok,
        sign_rejected=sign_rejected, fold_rejected=fold_rejected,
        residual_norm=jnp.where(ok, residual_norm, c.residual_norm), result=out,
        done=done_ok | (out != RESULTS.successful), recorder=rec, recover=recover,
        streak=jnp.where(ok & primed, c.streak + 1, jnp.where(primed, 0, c.streak)),
    )


# After cut-backs (a corner of the path: a contact coming on, where the tangent turns within a
# stretch far shorter than the step), fast steps accepted in a row grow by this factor instead
# of PathSettings.grow until they are back at the largest step cut back.  At grow = 1.5 a cut
# from 0.05 to 1e-6 took 27 steps to grow back (83 of the 237 steps of the 6-generation
# outcrop's run with the surfaces moved the probe by less than 1e-3 µm).  In a row: while
# the path still approaches the corner, accepted and rejected steps alternate, and a return
# there only adds rejections.
_RETURN = 4.0


def _next_step(c: PathState, ok, iterations, settings):
    """(the step after an accepted attempt, the step size to return to) from the attempt's
    outcome (``ok``) and its Newton iterations."""
    fast = iterations <= settings.fast_iterations
    returning = fast & (c.recover > c.ds) & (c.streak >= 1)
    grown = jnp.where(returning, jnp.minimum(_RETURN * c.ds, jnp.maximum(c.recover, settings.grow * c.ds)),
                      jnp.where(fast, settings.grow, 1.0) * c.ds)
    grown = jnp.minimum(grown, settings.max_step)
    recover = jnp.where(ok & c.primed, jnp.where(grown >= c.recover, 0.0, c.recover),
                        jnp.where(c.primed, jnp.maximum(c.recover, c.ds), c.recover))
    return grown, recover


def follow_path(problem: PathProblem, state: PathState, settings: PathSettings, inner, recorder, *,
                stop_after=None) -> PathState:
    """Continue the path in ``state`` until p = 1, a failure, or ``stop_after`` more accepted
    steps (then ``state.done`` is False: call again to resume).  ``settings``: a filled
    :class:`PathSettings`; ``inner``: the linear solver of J (:class:`socbjax.DenseLU`,
    :class:`socbjax.ColouredSparseLU`); ``recorder``: what to keep of accepted steps.
    Differentiation does not pass through the path (use the implicit adjoint on its end)."""
    problem = jax.lax.stop_gradient(problem)
    param = parametrisation(settings.method)
    newton = _newton(settings, inner)
    stop_at = state.steps + (settings.max_steps if stop_after is None else stop_after)

    def cond(c):
        return ~c.done & (c.steps < stop_at)

    def body(c):
        return _attempt(c, problem, param, settings, newton, recorder)

    return jax.lax.while_loop(cond, body, state)


def path_weights(model, p_scale) -> Array:
    """Norm weights [n + 1] for probe paths: node positions and directors (× mean segment
    length, so in µm), averaged over nodes, and p scaled to µm by ``p_scale``; moments and
    forces grow along any path and would hide a jump between branches."""
    zeros = jax.tree_util.tree_map(jnp.zeros_like, state_template(model))
    ell = jnp.mean(model.network.lengths)
    fields = ("positions", "directors") if hasattr(zeros, "directors") else ("positions", "directions")
    ones = tuple(jnp.full_like(getattr(zeros, f), 1.0 if f == "positions" else ell**2) for f in fields)
    geometry = ravel_pytree(eqx.tree_at(lambda st: tuple(getattr(st, f) for f in fields), zeros, ones))[0]
    return jnp.concatenate([geometry / model.network.n_nodes, jnp.asarray(p_scale, geometry.dtype)[None] ** 2])


def position_weights(model) -> Array:
    """Weights [n + 1] selecting the node positions (p weight 0): the corrector test of load
    ramps, which compares geometric changes only (forces and moments grow with λ)."""
    zeros = jax.tree_util.tree_map(jnp.zeros_like, state_template(model))
    positions = ravel_pytree(eqx.tree_at(lambda st: st.positions, zeros, jnp.ones_like(zeros.positions)))[0]
    return jnp.concatenate([positions, jnp.zeros(1, positions.dtype)])
