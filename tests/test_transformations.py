"""The README's "JAX transformations" table: every public entry point under jax.jit,
jax.grad (reverse mode), jax.jacfwd and jax.vmap, checked against exact identities and
central finite differences of full re-solves (never against the code's own earlier output).

Exact identities used (a filament's shape depends on its loads only through P L²/EI, and an
elastica's forces scale with EI at fixed geometry):
* solve: EI ∂y/∂EI = −P ∂y/∂P for the tip deflection y; θ_tip = M L/EI under a tip couple;
* buckling_load: dPcr/dEI = Pcr/EI and dPcr/dL = −2 Pcr/L;
* compress(at=) and compress_ensemble(at=): dF/dEI = F/EI (the default perturbation scales
  with EI, so the whole problem does).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj


def _central(f, x, h):
    return (float(f(x + h)) - float(f(x - h))) / (2 * h)


# ------------------------------------------------------------------------------ solve
def _tip(EI, P):
    return sj.solve(sj.cantilever(3, dim=2, EI=EI), {-1: jnp.stack([0.0, P])}).positions[-1, 1]


def test_solve_under_jit_grad_jacfwd_vmap():
    EI, P = 1.3, 1.7
    y = float(_tip(EI, P))
    assert float(jax.jit(_tip)(EI, P)) == pytest.approx(y, rel=1e-13)
    dEI, dP = jax.grad(_tip, argnums=(0, 1))(EI, P)
    assert float(EI * dEI) == pytest.approx(-P * float(dP), rel=1e-8)  # shape depends on P/EI only
    assert float(dP) == pytest.approx(_central(lambda p: _tip(EI, p), P, 1e-5), rel=1e-6)  # full re-solves
    assert float(jax.jacfwd(_tip)(EI, P)) == pytest.approx(float(dEI), rel=1e-10)
    EIs, Ps = jnp.array([0.8, 1.3, 2.0]), jnp.array([1.0, 1.7, 0.5])
    np.testing.assert_allclose(jax.vmap(_tip)(EIs, Ps), [float(_tip(e, p)) for e, p in zip(EIs, Ps)], rtol=1e-12)
    batched_EI, batched_P = jax.jit(jax.vmap(jax.grad(_tip, argnums=(0, 1))))(EIs, Ps)  # a composition
    np.testing.assert_allclose(batched_P[1], float(dP), rtol=1e-10)
    np.testing.assert_allclose(EIs * batched_EI, -Ps * batched_P, rtol=1e-8)


@pytest.mark.slow  # suite time; in the default suite: solve under every transformation: test_solve_under_jit_grad_jacfwd_vmap; curve quantities: tests/test_equilibrium.py
def test_solve_with_couples_and_curves_under_transformations():
    """θ_tip = M L/EI exactly (uniform curvature): its derivatives are L/EI and −M L/EI²."""
    def rotation(M, EI):
        return sj.solve(sj.cantilever(3, dim=2, EI=EI, length=1.5), couples={-1: M}).end_rotation()

    M, EI = 0.4, 0.9
    dM, dEI = jax.grad(rotation, argnums=(0, 1))(M, EI)
    assert float(dM) == pytest.approx(1.5 / EI, rel=1e-10) and float(dEI) == pytest.approx(-M * 1.5 / EI**2, rel=1e-10)
    batched = jax.jit(jax.vmap(rotation, in_axes=(0, None)))(jnp.array([0.1, 0.4]), EI)
    np.testing.assert_allclose(batched, [0.1 * 1.5 / EI, 0.4 * 1.5 / EI], rtol=1e-12)
    assert float(jax.jacfwd(rotation)(M, EI)) == pytest.approx(1.5 / EI, rel=1e-10)


# ---------------------------------------------------------------------------- buckling
def _pcr(EI, L):
    return sj.buckling_load(sj.column(4, supports=("pinned", "pinned"), dim=2, EI=EI, length=L))


def test_buckling_load_under_jit_grad_jacfwd_vmap():
    EI, L = 0.071, 1.2
    P = float(_pcr(EI, L))
    assert P == pytest.approx(np.pi**2 * EI / L**2, rel=1e-4)  # Euler (4 nodes)
    dEI, dL = jax.grad(_pcr, argnums=(0, 1))(EI, L)
    assert float(dEI) == pytest.approx(P / EI, rel=1e-8)
    assert float(dL) == pytest.approx(-2 * P / L, rel=1e-8)
    assert float(jax.jacfwd(_pcr)(EI, L)) == pytest.approx(P / EI, rel=1e-8)
    assert float(jax.jit(_pcr)(EI, L)) == pytest.approx(P, rel=1e-12)
    np.testing.assert_allclose(jax.vmap(_pcr, in_axes=(0, None))(jnp.array([0.071, 0.142]), L), [P, 2 * P], rtol=1e-10)


# ------------------------------------------------------------------- compress(at=...)
AT = jnp.array([0.05, 0.2])


def _sampled_force(EI):
    net = sj.column(4, supports=("pinned", "pinned"), dim=2, EI=EI)
    return sj.compress(net, 0.25, at=AT).force


def test_sampled_compression_under_jit_and_vmap():
    """jit and vmap here; jacfwd (dF/dEI = F/EI, dF/du against the closed form) and grad (central
    differences past buckling) of compress(at=...) in the default suite's tests/test_sampled.py,
    both here under `pytest -m slow` (each compiles the whole sampled path again: ~20 s)."""
    EI = 0.071
    F = np.asarray(_sampled_force(EI))
    np.testing.assert_allclose(jax.jit(_sampled_force)(EI), F, rtol=1e-12)
    np.testing.assert_allclose(jax.vmap(_sampled_force)(jnp.array([EI, 2 * EI])), np.stack([F, 2 * F]), rtol=1e-8)


@pytest.mark.slow
def test_sampled_compression_under_grad_and_jacfwd():
    EI = 0.071
    F = np.asarray(_sampled_force(EI))
    np.testing.assert_allclose(jax.jacfwd(_sampled_force)(EI), F / EI, rtol=1e-6)  # F ∝ EI
    g = float(jax.grad(lambda e: jnp.sum(_sampled_force(e)))(EI))
    assert g == pytest.approx(F.sum() / EI, rel=1e-6)


@pytest.mark.slow
def test_sampled_ensemble_under_jit_grad_jacfwd_vmap():
    nets = [sj.column(4, supports=("pinned", "pinned"), dim=2, EI=EI) for EI in (0.05, 0.1)]

    def total(scale):
        members = [n.replace(EI=n.EI * scale) for n in nets]
        return jnp.sum(sj.compress_ensemble(members, 0.25, at=AT).force)

    value = float(total(1.0))
    assert float(jax.grad(total)(1.0)) == pytest.approx(value, rel=1e-6)  # ∝ scale
    assert float(jax.jacfwd(total)(1.0)) == pytest.approx(value, rel=1e-6)
    assert float(jax.jit(total)(1.0)) == pytest.approx(value, rel=1e-12)
    np.testing.assert_allclose(jax.vmap(total)(jnp.array([1.0, 3.0])), [value, 3 * value], rtol=1e-8)


# ---------------------------------------------------------------------------- fit losses
@pytest.mark.slow  # every fit in the default suite differentiates these residuals under jit (jacfwd)
def test_fit_loss_under_jit_grad_jacfwd_vmap():
    model = sj.ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.2, 6)
    truth = np.asarray(sj.compress(model.network({"EI": 0.071}), 0.2, at=c).force)
    problem = sj.fit_problem((c, 1.1 * truth), model, free=("EI", "baseline"))

    def loss(z):
        return 0.5 * jnp.sum(problem.residuals(z) ** 2)

    z = problem.z0 + jnp.array([0.1, 0.05])
    g = np.asarray(jax.grad(loss)(z))
    fd = [_central(lambda t, i=i: loss(z.at[i].set(t)), float(z[i]), 1e-5) for i in range(2)]
    np.testing.assert_allclose(g, fd, rtol=1e-6)
    np.testing.assert_allclose(jax.jacfwd(problem.residuals)(z), jax.jacrev(problem.residuals)(z), rtol=1e-9, atol=1e-12)
    assert float(jax.jit(loss)(z)) == pytest.approx(float(loss(z)), rel=1e-12)
    np.testing.assert_allclose(jax.vmap(loss)(jnp.stack([z, problem.z0])), [float(loss(z)), float(loss(problem.z0))], rtol=1e-10)
