"""Path following on a scalar S-curve with two folds: x³ − 3x = 6p − 3.

Natural-parameter (displacement) control must stop at the first fold (p = 5/6) with
``Status.CRITICAL_POINT`` and never record a jump; pseudo-arclength must follow the path
through both folds (p turns back to 1/6, then reaches 1) with every point on the curve."""

import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj
from socbjax._linear import DenseJacobianSolver
from socbjax._path import path_run, path_start


def make_F(x_ref):
    return lambda x, p: x**3 - 3.0 * x - (6.0 * p - 3.0)


def follow(method):
    settings = sj.PathSettings(method=method, initial_step=0.05, max_step=0.1, min_step=1e-8, max_steps=400)
    x0 = jnp.asarray([-2.103803402735535])  # the only root at p = 0
    weights = jnp.asarray([1.0, 1.0])
    solver = DenseJacobianSolver()
    carry = path_start(make_F, x0, weights, solver, settings)
    carry = path_run(make_F, carry, weights, jnp.asarray(1.0), solver, settings, jnp.asarray(400))
    k = int(carry["steps"])
    return carry, np.asarray(carry["X"][:k, 0]), np.asarray(carry["P"][:k]), np.asarray(carry["SIGN"][:k])


def test_displacement_control_stops_at_the_fold():
    carry, x, p, _ = follow("displacement")
    assert int(carry["status"]) == sj.Status.CRITICAL_POINT
    assert p.max() < 5 / 6 + 1e-9 and p.max() > 5 / 6 - 0.02  # got close, never jumped over
    assert np.all(x < -1.0)  # every recorded state is on the first branch
    np.testing.assert_allclose(x**3 - 3 * x, 6 * p - 3, atol=1e-9)


def test_arclength_follows_both_folds():
    carry, x, p, sign = follow("arclength")
    assert int(carry["status"]) == sj.Status.CONVERGED and p[-1] == pytest.approx(1.0)
    np.testing.assert_allclose(x**3 - 3 * x, 6 * p - 3, atol=1e-9)
    assert np.all(np.diff(x) > 0)  # monotone along the curve: no branch jumping
    dp = np.sign(np.diff(p))
    assert np.count_nonzero(dp[1:] != dp[:-1]) == 2  # two folds in p
    assert p.min() < 1 / 6 + 0.02 and p.max() > 5 / 6 - 0.02
    assert np.count_nonzero(sign[1:] != sign[:-1]) == 2  # det J changes sign at each fold
