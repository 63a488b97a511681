"""The sparse LU whose pattern follows the filament–filament contact pairs
(socbjax.PairedSparseLU): its solves against a dense solve of the exact Jacobian (jacfwd) at
generic states of a 3D outcrop with the surfaces and a pair list, and at a 2D state with a
live pair; a self-contact solve with it against the same solve with dense LU."""

import dataclasses

import lineax as lx
import numpy as np
import optimistix as optx
import pytest

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
import socbjax as sj
from conftest import two_filaments

L, EI, D = 1.0, 1.0, 0.01
LOAD = np.array([0.0, -3.0])  # pN at the cantilever's tip: presses it onto the stiff filament


def _random_pairs(net, count, rng):
    """[count, 2] pairs of segments that share no node and no branch junction, none in
    more than 2 pairs."""
    seg, attach = np.asarray(net.segments), np.asarray(net.attach)
    nodes = [set(attach[s]) | set(s) for s in seg]
    ids, used = [], np.zeros(len(seg), int)
    for i, j in rng.permutation([(i, j) for i in range(len(seg)) for j in range(i + 1, len(seg))]):
        if not nodes[i] & nodes[j] and used[i] < 2 and used[j] < 2 and len(ids) < count:
            ids.append((i, j))
            used[[i, j]] += 1
    return np.array(ids)


def _flat_residual(model, state, frames):
    x, unravel = ravel_pytree(state)
    return x, lambda y: ravel_pytree(model.residual(unravel(y), sj.Control.make(0.3, 0.3, 0.5), frames))[0]


@eqx.filter_jit
def _jacobian(model, state, frames):
    x, fn = _flat_residual(model, state, frames)
    return jax.jacfwd(fn)(x)


@eqx.filter_jit
def _sparse_solves(model, solver, state, frames, b):
    """(x with J x = b, y with Jᵀ y = b, both results) by ``solver``, J at ``state``."""
    x, fn = _flat_residual(model, state, frames)
    op = lx.FunctionLinearOperator(lambda v: jax.jvp(fn, (x,), (v,))[1], jax.ShapeDtypeStruct(x.shape, x.dtype))
    factored = solver.init(op, {"point": x})
    got, result, _ = solver.compute(factored, b, {})
    got_t, result_t, _ = solver.compute(solver.transpose(factored, {})[0], b, {})  # the implicit adjoint's solve
    return got, got_t, result, result_t


def _dense_check(model, state, solver, rng):
    """Solve J x = b and Jᵀ x = b with ``solver`` at ``state`` (its pair slots hold the list,
    used as it is: no broad phase) against numpy's solves with the exact Jacobian (jacfwd)."""
    frames = (model.frames(state)[0], model.pair_list(state, rebuild=False))
    J = np.asarray(_jacobian(model, state, frames))
    b = rng.standard_normal(J.shape[0])
    tol = 1e-8 * np.abs(b).max() * np.linalg.cond(J) ** 0.5
    got, got_t, result, result_t = _sparse_solves(model, solver, state, frames, jnp.asarray(b))
    assert result == lx.RESULTS.successful and result_t == lx.RESULTS.successful
    np.testing.assert_allclose(J @ np.asarray(got), b, rtol=0, atol=tol)
    np.testing.assert_allclose(J.T @ np.asarray(got_t), b, rtol=0, atol=tol)


@pytest.fixture(scope="module")
def outcrop():
    """(network, model, its sparse solver): a 2-generation twisting 3D outcrop with the probe
    face and the substrate (obstacle slots on every segment) and self-contact."""
    net = sj.dendritic_outcrop(generations=2, gap=3.0, seed=0)
    model = sj.make_model(net, contact=sj.Contact())
    return net, model, sj.linear_solver_for(model, "sparse")


@pytest.mark.slow  # 67 s alone, 150 s in the 2-worker suite (compilation of a 3D contact model)
def test_the_jacobian_is_exact_at_generic_states_of_a_3d_outcrop_with_surfaces_and_pairs(outcrop):
    """Perturbed states with random pair lists: an interior pair force makes its segments'
    own rows depend on more unknowns than without (a missed dependency gave a wrong Newton
    direction); the sparse solve must still be the exact one."""
    net, model, solver = outcrop
    assert isinstance(solver, sj.PairedSparseLU)
    rng = np.random.default_rng(0)
    x0, unravel = ravel_pytree(model.initial_state())
    for _ in range(2):
        state = unravel(x0 + 0.02 * rng.standard_normal(x0.size))
        ids = -np.ones((model.n_pairs, 2))
        pairs = _random_pairs(net, 3, rng)
        ids[:len(pairs)] = pairs
        slots = np.asarray(state.pairs).copy()
        slots[:, :2], slots[:, 2:4] = ids, rng.uniform(0.2, 0.8, (model.n_pairs, 2))
        _dense_check(model, eqx.tree_at(lambda s: s.pairs, state, jnp.asarray(slots)), solver, rng)


@pytest.mark.slow  # the shared fixture prepares the solver (about 30 s)
def test_the_jacobian_needs_the_state_that_holds_the_pair_list(outcrop):
    _, model, solver = outcrop
    x = ravel_pytree(model.initial_state())[0]
    op = lx.FunctionLinearOperator(lambda v: v, jax.ShapeDtypeStruct(x.shape, x.dtype))
    with pytest.raises(ValueError, match="point"):
        solver.init(op, {})


CONTACT = sj.Contact(diameter=D, surfaces=False, stiffness=1e6)


@pytest.fixture(scope="module")
def pressed():
    net, tip = two_filaments()
    dense = sj.solve(net, forces={tip: LOAD}, contact=CONTACT, settings=sj.PathSettings(linear_solver="dense"))
    return net, tip, dense


@pytest.mark.slow  # 45 s; the 3D check above covers generic states in the default suite
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


@pytest.mark.slow
def test_a_self_contact_solve_with_the_sparse_solver_equals_the_dense_one(pressed):
    """The whole load ramp with PairedSparseLU gives the dense-LU equilibrium (same Newton
    path up to round-off).  Slow: about 50 s (two compilations)."""
    net, tip, dense = pressed
    sparse = sj.solve(net, forces={tip: LOAD}, contact=CONTACT, settings=sj.PathSettings(linear_solver="sparse"))
    np.testing.assert_allclose(np.asarray(sparse.positions), np.asarray(dense.positions), atol=1e-10)
    assert float(dense.positions[tip, 1]) > -0.12  # the stiff filament holds the tip up


@pytest.mark.slow  # shares the pressed state (about 20 s)
def test_a_pair_list_that_needs_more_colours_than_prepared_is_a_capacity_not_a_wrong_step(pressed):
    """With fewer colours prepared than the pair list needs, the solve never returns a
    direction built from a truncated Jacobian: it is NaN with ``stats["overflow"]``, and
    Newton stops at once with ``RESULTS.colour_capacity`` (not ``singular``); the solver as
    prepared converges from the same start (to an equilibrium of the held frames)."""
    net, tip, dense = pressed
    loads = np.array(net.loads)
    loads[tip] = LOAD
    model = sj.make_model(net.replace(loads=loads), contact=CONTACT)
    solver = sj.linear_solver_for(model, "sparse")
    frames = model.frames(dense.state)
    x, fn = _flat_residual(model, dense.state, frames)
    fn = lambda y, args, f=fn: f(y)  # noqa: E731
    small = dataclasses.replace(solver, max_colors=8, chunk=8)
    y0 = x + 1e-4 * np.random.default_rng(1).standard_normal(x.size)
    op = lx.FunctionLinearOperator(lambda v: jax.jvp(lambda y: fn(y, None), (y0,), (v,))[1],
                                   jax.ShapeDtypeStruct(x.shape, x.dtype))
    direction, _, stats = small.compute(small.init(op, {"point": y0}), -fn(y0, None), {})
    assert bool(stats["overflow"]) and not np.any(np.isfinite(np.asarray(direction)))
    failed = optx.root_find(fn, sj.DampedNewton(linear_solver=small), y0, throw=False, max_steps=60)
    assert failed.state.result == sj.RESULTS.colour_capacity and int(failed.state.iterations) == 0
    solved = optx.root_find(fn, sj.DampedNewton(linear_solver=solver), y0, throw=False, max_steps=60)
    assert solved.state.result == sj.RESULTS.successful and not bool(solved.state.stats["overflow"])
