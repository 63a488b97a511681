"""The sparse LU whose pattern follows the filament–filament contact pairs
(socbjax.PairedSparseLU): its solves against a dense solve of the exact Jacobian (jacfwd) at a
state with a live pair, and a self-contact solve with it against the same solve with dense LU."""

import lineax as lx
import numpy as np
import pytest

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
import socbjax as sj
from conftest import two_filaments

L, EI, D = 1.0, 1.0, 0.01
LOAD = np.array([0.0, -3.0])  # pN at the cantilever's tip: presses it onto the stiff filament


CONTACT = sj.Contact(diameter=D, surfaces=False, stiffness=1e6)


@pytest.fixture(scope="module")
def pressed():
    net, tip = two_filaments()
    dense = sj.solve(net, forces={tip: LOAD}, contact=CONTACT, settings=sj.PathSettings(linear_solver="dense"))
    return net, tip, dense


def test_solves_match_a_dense_solve_of_the_exact_jacobian(pressed):
    """At the pressed state (one live pair between the two filaments, force ~3 pN): J x = b
    and Jᵀ x = b through the pair-dependent colouring against numpy's dense solve of jacfwd."""
    net, tip, dense = pressed
    loads = np.array(net.loads)
    loads[tip] = LOAD
    loaded = net.replace(loads=loads)
    model = sj.make_model(loaded, contact=CONTACT)
    solver = sj.linear_solver_for(model, "sparse")
    assert isinstance(solver, sj.PairedSparseLU)
    state = dense.state
    frames = model.frames(state)
    assert int(np.sum(np.asarray(frames[1].ids)[:, 0] >= 0)) >= 1  # a pair is listed
    x, unravel = ravel_pytree(state)
    fn = lambda y: ravel_pytree(model.residual(unravel(y), sj.Control.make(), frames))[0]  # noqa: E731
    J = np.asarray(jax.jit(jax.jacfwd(fn))(x))
    b = np.random.default_rng(0).standard_normal(x.size)
    jvp = jax.jit(lambda v: jax.jvp(fn, (x,), (v,))[1])
    op = lx.FunctionLinearOperator(jvp, jax.ShapeDtypeStruct(x.shape, x.dtype))
    sol_state = solver.init(op, {"point": x})
    got, result, _ = solver.compute(sol_state, jnp.asarray(b), {})
    assert result == lx.RESULTS.successful
    ref = np.linalg.solve(J, b)
    # the penalty (1e6 pN/µm) and the stiff filament make J ill-conditioned: compare residuals
    assert np.linalg.norm(J @ np.asarray(got) - b) < 1e-8 * np.linalg.norm(b) * np.linalg.cond(J) ** 0.5
    np.testing.assert_allclose(np.asarray(got), ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    t_state, _ = solver.transpose(sol_state, {})
    got_t, _, _ = solver.compute(t_state, jnp.asarray(b), {})
    ref_t = np.linalg.solve(J.T, b)
    np.testing.assert_allclose(np.asarray(got_t), ref_t, rtol=0, atol=1e-9 * np.abs(ref_t).max())


def test_the_jacobian_needs_the_state_that_holds_the_pair_list(pressed):
    net, tip, dense = pressed
    model = sj.make_model(net, contact=CONTACT)
    solver = sj.linear_solver_for(model, "sparse")
    x = ravel_pytree(dense.state)[0]
    op = lx.FunctionLinearOperator(lambda v: v, jax.ShapeDtypeStruct(x.shape, x.dtype))
    with pytest.raises(ValueError, match="point"):
        solver.init(op, {})


@pytest.mark.slow
def test_a_self_contact_solve_with_the_sparse_solver_equals_the_dense_one(pressed):
    """The whole load ramp with PairedSparseLU gives the dense-LU equilibrium (same Newton
    path up to round-off).  Slow: about 50 s (two compilations)."""
    net, tip, dense = pressed
    sparse = sj.solve(net, forces={tip: LOAD}, contact=CONTACT, settings=sj.PathSettings(linear_solver="sparse"))
    np.testing.assert_allclose(np.asarray(sparse.positions), np.asarray(dense.positions), atol=1e-10)
    assert float(dense.positions[tip, 1]) > -0.12  # the stiff filament holds the tip up
