"""Load continuation: cut-back, path following through a sharp turn, loud failure."""

import numpy as np

import socbjax as sj


def test_aggressive_first_step_is_cut_back_and_converges():
    """PL²/EI = 10 in one step: Newton from the straight state may fail; cut-back rescues it."""
    settings = sj.ContinuationSettings(initial_step=1.0, max_step=1.0)
    sol = sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 10.0]}, continuation=settings)
    ref = sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 10.0]})
    assert sol.converged
    np.testing.assert_allclose(sol.positions, ref.positions, atol=1e-10)


def test_impossible_step_budget_fails_loudly():
    settings = sj.ContinuationSettings(initial_step=0.01, max_step=0.01, max_steps=5)
    sol = sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 1.0]}, continuation=settings, throw=False)
    assert not sol.converged and sol.status == sj.Status.CONTINUATION_FAILED
    assert 0.0 < float(sol.load_factor) < 0.1  # the last accepted state, not an answer at full load


def test_imperfect_column_follows_the_stable_branch_from_any_step_size():
    P = 1.05 * np.pi**2 / 4
    tips = []
    for step in (0.5, 0.1, 0.02):
        settings = sj.ContinuationSettings(initial_step=step, max_step=step)
        sol = sj.solve(sj.column(3, dim=2), {-1: [-P, 1e-3 * P]}, continuation=settings)
        tips.append(np.asarray(sol.positions[-1]))
    assert tips[0][1] > 0.2  # buckled toward the imperfection
    np.testing.assert_allclose(tips[0], tips[1], atol=1e-10)
    np.testing.assert_allclose(tips[0], tips[2], atol=1e-10)
