"""The path engine (socbjax.follow_path): natural-parameter and pseudo-arclength
continuation on a scalar S-curve with two folds, x³ − 3x = 6p − 3 (independent reference:
the cubic itself), and the load ramp of socbjax.solve: cut-back, budgets, branch tracking.

Natural-parameter control must stop at the first fold (p = 5/6) with ``RESULTS.fold`` and
never record a jump; pseudo-arclength must follow the path through both folds (p turns back
to 1/6, then reaches 1) with every point on the curve."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj


class SCurve(eqx.Module):
    """x³ − 3x − (6λ − 3) = 0 as a socbjax model (state: one number; control: λ = p)."""

    def initial_state(self):
        return jnp.asarray([-2.103803402735535])  # the only root at p = 0

    def frames(self, state):
        return None

    def residual(self, state, control, frames):
        return state**3 - 3.0 * state - (6.0 * control.load_factor - 3.0)


def follow(method):
    settings = sj.PathSettings(method=method, initial_step=0.05, max_step=0.1, min_step=1e-8, max_steps=400,
                               max_attempts=5000, grow=1.5, fast_iterations=4, max_corrector_ratio=0.5, max_turn=0.6,
                               corrector_floor=1e-12, atol=1e-12, max_iterations=25, max_backtracks=12)
    weights = jnp.asarray([1.0, 1.0])
    problem = sj.PathProblem(SCurve(), sj.Control.make(0.0), sj.Control.make(1.0), weights, weights)
    recorder = sj.StepRecorder(400)
    x0 = SCurve().initial_state()
    state = sj.follow_path(problem, sj.start_path(x0, 0.0, settings, recorder), settings, sj.DenseLU(), recorder)
    k = int(state.steps)
    rec = state.recorder
    rows = rec.rows(k)
    return state, rows["X"][:, 0], rows["P"], rows["SIGN"]


def test_natural_parameter_stops_at_the_fold():
    state, x, p, _ = follow("displacement")
    assert state.result == sj.RESULTS.fold
    assert 5 / 6 - 0.02 < p.max() < 5 / 6 + 1e-9  # got close, never jumped over
    assert np.all(x < -1.0)  # every recorded state is on the first branch
    np.testing.assert_allclose(x**3 - 3 * x, 6 * p - 3, atol=1e-9)


def test_arclength_follows_both_folds():
    state, x, p, sign = follow("arclength")
    assert state.result == sj.RESULTS.successful and p[-1] == pytest.approx(1.0)
    np.testing.assert_allclose(x**3 - 3 * x, 6 * p - 3, atol=1e-9)
    assert np.all(np.diff(x) > 0)  # monotone along the curve: no branch jumping
    dp = np.sign(np.diff(p))
    assert np.count_nonzero(dp[1:] != dp[:-1]) == 2  # two folds in p
    assert p.min() < 1 / 6 + 0.02 and p.max() > 5 / 6 - 0.02
    assert np.count_nonzero(sign[1:] != sign[:-1]) == 2  # det J changes sign at each fold


class Corner(eqx.Module):
    """x = tan(1) · w log(1 + e^{(p − ½)/w}), w = 1e-10: a path that turns by 1 rad over a
    stretch far shorter than any step (a floppy strand reaching a stiff contact)."""

    def initial_state(self):
        return jnp.zeros(1)

    def frames(self, state):
        return None

    def residual(self, state, control, frames):
        w = 1e-10
        return state - np.tan(1.0) * w * jnp.logaddexp(0.0, (control.load_factor - 0.5) / w)


@pytest.mark.parametrize("method", ["displacement", "arclength"])
def test_a_corner_of_the_path_is_passed_by_small_steps_only_when_allowed(method):
    """A turn of 1 rad at p = ½ fails the turn and corrector tests at every step size; steps
    within ``corner_step`` may pass it (and then land on the exact path), with corner_step=0
    the run stops there."""
    weights = jnp.asarray([1.0, 1.0])
    problem = sj.PathProblem(Corner(), sj.Control.make(0.0), sj.Control.make(1.0), weights, weights)
    results = {}
    for corner_step in (1e-5, 0.0):
        settings = sj.PathSettings(method=method, initial_step=0.05, max_step=0.1, min_step=1e-8, max_steps=400,
                                   max_attempts=5000, grow=1.5, fast_iterations=4, max_corrector_ratio=0.5,
                                   max_turn=0.6, corrector_floor=1e-12, corner_step=corner_step, atol=1e-12,
                                   max_iterations=25, max_backtracks=12)
        recorder = sj.StepRecorder(400)
        state = sj.follow_path(problem, sj.start_path(Corner().initial_state(), 0.0, settings, recorder), settings,
                               sj.DenseLU(), recorder)
        rows = state.recorder.rows(int(state.steps))
        results[corner_step] = (state, rows["X"][:, 0], rows["P"])
    state, x, p = results[1e-5]
    assert state.result == sj.RESULTS.successful and p[-1] == pytest.approx(1.0)
    np.testing.assert_allclose(x, np.tan(1.0) * np.maximum(p - 0.5, 0.0), atol=1e-9)
    # past the corner the steps return to their size before the cut-backs fast (×4 per
    # step, not grow = 1.5: from ≤ 1e-4 back to ≥ 0.04 in at most 8 steps, not 15)
    step = np.hypot(np.diff(x), np.diff(p))
    past = int(np.argmax(p > 0.5 + 1e-9))
    assert step[past - 1] <= 1e-4 and step[:past - 1].max() >= 0.04
    assert 0 < int(np.argmax(step[past:] >= 0.04)) <= 8
    stopped, _, p0 = results[0.0]
    assert stopped.result == sj.RESULTS.step_too_small and 0.5 - 1e-6 < p0.max() < 0.5 + 1e-6


class Pitchfork(eqx.Module):
    """x³ − (p − ½) x − ε = 0, ε = 10⁻⁶: an imperfect pitchfork.  The path from p = 0 (x ≈ 2ε)
    turns up at p ≈ ½ onto x ≈ +√(p − ½) (det J = 3x² − (p − ½) > 0); beyond ½ a middle
    branch x ≈ −ε/(p − ½) is unstable (det J < 0).  Independent reference: the cubic."""

    def initial_state(self):
        return jnp.asarray([2.0e-6])

    def frames(self, state):
        return None

    def residual(self, state, control, frames):
        return state**3 - (control.load_factor - 0.5) * state - 1e-6


def test_arclength_does_not_step_across_a_near_bifurcation_onto_the_unstable_branch():
    """A step of 0.05 from below p = ½ lands, on the corrector's hyperplane, on the unstable
    middle branch beyond it (sign(det J) flips without a fold); the old engine accepted it and
    followed that branch to p = 1, flagged unstable.  Such steps are now cut back until they
    follow the turn: every point on the cubic, det J of one sign, x(1) = the stable root."""
    weights = jnp.asarray([1.0, 1.0])
    problem = sj.PathProblem(Pitchfork(), sj.Control.make(0.0), sj.Control.make(1.0), weights, weights)
    settings = sj.PathSettings(method="arclength", initial_step=0.05, max_step=0.05, min_step=1e-8, max_steps=400,
                               max_attempts=5000, grow=1.5, fast_iterations=4, max_corrector_ratio=0.5,
                               max_turn=0.6, corrector_floor=1e-12, atol=1e-12, max_iterations=25,
                               max_backtracks=12)
    recorder = sj.StepRecorder(400)
    state = sj.follow_path(problem, sj.start_path(Pitchfork().initial_state(), 0.0, settings, recorder), settings,
                           sj.DenseLU(), recorder)
    rows = state.recorder.rows(int(state.steps))
    x, p, sign = rows["X"][:, 0], rows["P"], rows["SIGN"]
    assert state.result == sj.RESULTS.successful and p[-1] == pytest.approx(1.0)
    np.testing.assert_allclose(x**3 - (p - 0.5) * x, 1e-6, atol=1e-11)
    assert np.all(sign == sign[0]) and np.all(3 * x**2 - (p - 0.5) > 0)
    stable_root = max(np.roots([1.0, 0.0, -0.5, -1e-6]).real)
    assert x[-1] == pytest.approx(stable_root, rel=1e-9)


# ------------------------------------------------------------------ the load ramp of solve
def test_aggressive_first_step_is_cut_back_and_converges():
    """PL²/EI = 10 in one step: Newton from the straight state may fail; cut-back rescues it."""
    settings = sj.PathSettings(initial_step=1.0, max_step=1.0)
    sol = sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 10.0]}, settings=settings)
    ref = sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 10.0]})
    assert sol.converged
    np.testing.assert_allclose(sol.positions, ref.positions, atol=1e-10)


def test_impossible_step_budget_fails_loudly():
    settings = sj.PathSettings(initial_step=0.01, max_step=0.01, max_steps=5)
    sol = sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 1.0]}, settings=settings, throw=False)
    assert not sol.converged and sol.result == sj.RESULTS.max_steps
    assert 0.0 < float(sol.load_factor) < 0.1  # the last accepted state, not an answer at full load
    with pytest.raises(sj.ConvergenceError, match="step budget"):
        sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 1.0]}, settings=settings)


def test_imperfect_column_follows_the_stable_branch_from_any_step_size():
    P = 1.05 * np.pi**2 / 4
    tips = []
    for step in (0.5, 0.1, 0.02):
        settings = sj.PathSettings(initial_step=step, max_step=step)
        sol = sj.solve(sj.column(3, dim=2), {-1: [-P, 1e-3 * P]}, settings=settings)
        tips.append(np.asarray(sol.positions[-1]))
    assert tips[0][1] > 0.2  # buckled toward the imperfection
    np.testing.assert_allclose(tips[0], tips[1], atol=1e-10)
    np.testing.assert_allclose(tips[0], tips[2], atol=1e-10)


def test_settings_are_checked():
    with pytest.raises(ValueError, match="min_step <= initial_step <= max_step"):
        sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 1.0]}, settings=sj.PathSettings(initial_step=2.0, max_step=1.0))
    with pytest.raises(ValueError, match="method"):
        sj.PathSettings(method="newton")
    with pytest.raises(ValueError, match="max_steps"):
        sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 1.0]}, settings=sj.PathSettings(max_steps=0))
    with pytest.raises(ValueError, match="corner_step"):
        sj.PathSettings(corner_step=-1e-5)
    assert sj.PathSettings(corner_step=0.0).corner_step == 0.0  # 0: corners are never passed
