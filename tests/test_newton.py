"""Damped Newton: quadratic convergence, statuses for failures, no silent NaN."""

import jax
import jax.numpy as jnp
import numpy as np

from socbjax import NewtonSolver, Status


def test_converges_on_a_nonlinear_system():
    def fn(x):
        return jnp.array([x[0] ** 2 + x[1] ** 2 - 4.0, jnp.exp(x[0]) + x[1] - 1.0])

    res = jax.jit(lambda x0: NewtonSolver()(fn, x0))(jnp.array([1.0, -1.0]))
    assert int(res.status) == Status.CONVERGED
    np.testing.assert_allclose(fn(res.x), 0.0, atol=1e-12)
    assert int(res.iterations) < 10


def test_line_search_globalises_arctan():
    """Undamped Newton diverges on arctan from x0 = 3; the line search must not."""
    res = NewtonSolver()(lambda x: jnp.arctan(x), jnp.array([3.0]))
    assert int(res.status) == Status.CONVERGED and abs(float(res.x[0])) < 1e-12


def test_no_root_reports_failure_not_an_answer():
    res = NewtonSolver(max_iterations=30)(lambda x: x**2 + 1.0, jnp.array([0.5]))
    assert int(res.status) != Status.CONVERGED
    assert float(res.residual_norm) >= 1.0


def test_nan_residual_is_flagged():
    res = NewtonSolver()(lambda x: jnp.sqrt(x - 10.0), jnp.array([1.0]))
    assert int(res.status) == Status.NONFINITE
