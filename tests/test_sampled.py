"""compress(..., at=...): equilibria sampled at prescribed probe displacements, with implicit
derivatives checked against closed forms, exact EI scaling and central finite differences
of the whole pipeline (path re-run at every perturbed parameter)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj
from socbjax import ColumnModel, OutcropModel, UnitMeshModel
from test_compress import _pinned_pinned_force

TIGHT = sj.PathSettings(atol=1e-12)
TIGHT_SPARSE = sj.PathSettings(atol=1e-12, linear_solver="sparse")


def _central(f, x, rel=1e-5):
    """Central differences of a scalar function f of the vector x, component by component."""
    x = np.asarray(x, float)
    out = []
    for i in range(x.size):
        h = rel * max(abs(x[i]), 1e-3)
        e = np.zeros_like(x)
        e[i] = h
        out.append((float(f(jnp.asarray(x + e))) - float(f(jnp.asarray(x - e)))) / (2 * h))
    return np.asarray(out)


def test_sampled_column_follows_the_closed_form_and_its_slope():
    """Forces at the samples equal the elliptic-integral elastica; dF/du (implicit, with
    respect to the sampled displacement) equals the closed form's slope; dF/dEI = F/EI (the
    default perturbation scales with EI, so the force scales exactly with EI)."""
    model = ColumnModel(5, supports=("pinned", "pinned"), dim=2)
    at = jnp.array([0.05, 0.15, 0.3])

    def force(EI, a):
        return sj.compress(model.network({"EI": EI}), 0.3, at=a, settings=TIGHT).force

    F = np.asarray(force(0.071, at))
    np.testing.assert_allclose(F, _pinned_pinned_force(np.asarray(at), EI=0.071), rtol=5e-4)
    dF_dEI = np.asarray(jax.jacfwd(force, 0)(0.071, at))
    np.testing.assert_allclose(dF_dEI, F / 0.071, rtol=1e-8)
    slope = np.diag(np.asarray(jax.jacfwd(force, 1)(0.071, at)))
    h = 1e-6
    exact = (_pinned_pinned_force(np.asarray(at) + h, EI=0.071) - _pinned_pinned_force(np.asarray(at) - h, EI=0.071)) / (2 * h)
    np.testing.assert_allclose(slope, exact, rtol=3e-3)


@pytest.mark.slow
def test_grad_jacfwd_vmap_and_jit_agree():
    model = ColumnModel(4, supports=("clamped", "free"), dim=2)
    at = jnp.array([0.1, 0.2])

    def loss(EI):
        return jnp.sum(sj.compress(model.network({"EI": EI}), 0.25, at=at).force ** 2)

    g = float(jax.grad(loss)(0.05))
    assert float(jax.jacfwd(loss)(0.05)) == pytest.approx(g, rel=1e-10)
    assert float(jax.jit(jax.grad(loss))(0.05)) == pytest.approx(g, rel=1e-10)
    batched = jax.vmap(jax.grad(loss))(jnp.array([0.05, 0.1]))
    assert float(batched[0]) == pytest.approx(g, rel=1e-10)
    assert float(batched[1]) == pytest.approx(2 * g, rel=1e-8)  # loss ∝ EI², so dL/dEI ∝ EI


def _unit_mesh_loss(weights, at):
    model = UnitMeshModel(dim=2)
    names = ("EI_mother", "EI_daughter", "branch_angle", "perturbation")

    def loss(theta):
        values = dict(zip(names, theta))
        network = model.network({k: v for k, v in values.items() if k != "perturbation"})
        result = sj.compress(network, 0.5, at=at, perturbation=values["perturbation"], settings=TIGHT)
        return jnp.sum(weights * result.force)

    return loss, np.array([0.071, 0.05, 65.0, 2e-5])


def _outcrop_loss(weights, at):
    model = OutcropModel(generations=3, gap=2.0, dim=2, seed=1)
    names = tuple(model.groups)

    def loss(theta):
        network = model.network(dict(zip(names, theta)))
        return jnp.sum(weights * sj.compress(network, 0.8, at=at, settings=TIGHT_SPARSE).force)

    return loss, np.linspace(0.05, 0.09, len(names))


# the default suite checks the unit mesh against finite differences in notebooks/fit_afm_curve.ipynb
# and a column past buckling below
@pytest.mark.slow
@pytest.mark.parametrize("case", ["unit_mesh", "outcrop"])
def test_implicit_gradients_match_finite_differences(case):
    """Gradient of a weighted sum of sampled forces — before buckling, at the drop and far
    past it — against central differences of the whole pipeline, 1e-6 relative."""
    rng = np.random.default_rng(3)
    # samples stay below the first surface crossing (unit mesh u ≈ 0.43 µm, this outcrop u ≈ 0.76 µm)
    at = jnp.array([0.01, 0.1, 0.3, 0.38]) if case == "unit_mesh" else jnp.array([0.02, 0.2, 0.5, 0.7])
    weights = jnp.asarray(rng.uniform(0.5, 1.5, at.size))
    loss, theta = (_unit_mesh_loss if case == "unit_mesh" else _outcrop_loss)(weights, at)
    implicit = np.asarray(jax.grad(loss)(jnp.asarray(theta)))
    fd = _central(loss, theta)
    scale = np.abs(implicit).max()
    np.testing.assert_allclose(implicit, fd, rtol=1e-6, atol=1e-6 * scale)


def test_column_gradient_matches_finite_differences_past_buckling():
    """Single filament: EI, perturbation and the sampled displacement, 1e-6 relative."""
    model = ColumnModel(5, supports=("clamped", "pinned"), dim=2)
    weights = jnp.array([0.3, 1.0, 2.0])

    def loss(theta):
        EI, perturbation, u = theta
        at = jnp.array([0.02, 0.2, 0.0]) + jnp.array([0.0, 0.0, u])
        result = sj.compress(model.network({"EI": EI}), 0.5, at=at, perturbation=perturbation, settings=TIGHT)
        return jnp.sum(weights * result.force)

    theta = np.array([0.071, 1e-5, 0.4])
    implicit = np.asarray(jax.grad(loss)(jnp.asarray(theta)))
    np.testing.assert_allclose(implicit, _central(loss, theta), rtol=1e-6, atol=1e-6 * np.abs(implicit).max())


@pytest.mark.slow  # suite time; in the default suite: sampling through a fold: the other tests of this file
def test_unloading_samples_retrace_loading():
    """The unit mesh's collapse is reversible: unloading samples equal loading ones."""
    at = jnp.array([0.05, 0.2, 0.4])
    result = sj.compress(sj.unit_dendritic_mesh(dim=2), 0.45, at=at, unload=True)
    assert result.force.shape == (6,) and list(result.phase) == [1, 1, 1, 2, 2, 2]
    np.testing.assert_allclose(result.force[3:][::-1], result.force[:3], rtol=1e-7)
    assert result.converged.all()


def test_sampled_input_errors():
    net = sj.column(4, supports=("pinned", "pinned"))
    with pytest.raises(ValueError, match="beyond displacement"):
        sj.compress(net, 0.2, at=[0.1, 0.3])
    with pytest.raises(ValueError, match="finite"):
        sj.compress(net, 0.2, at=[0.1, np.nan])
    with pytest.raises(ValueError, match="checkpoint"):
        sj.compress(net, 0.2, at=[0.1], checkpoint="run.h5")
    # topology cannot be traced: a clear error names it
    positions, tangents = np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([[1.0, 0.0], [1.0, 0.0]])
    with pytest.raises(TypeError, match="segments fixes the network's topology"):
        jax.jit(lambda seg: sj.make_network(positions, tangents, seg, 1.0, 1.0, clamped=[True, False], fixed_directions=[np.eye(2), np.zeros((0, 2))]).EI)(
            jnp.array([[0, 1]]))
    EI = jax.jit(lambda e: sj.make_network(positions, tangents, [[0, 1]], 1.0, e, clamped=[True, False], fixed_directions=[np.eye(2), np.zeros((0, 2))]).EI)(2.0)
    assert float(EI[0]) == 2.0  # values may be traced


def test_traced_displacement_is_allowed():
    """The path range may be traced too (one compiled program for any travel)."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    f = jax.jit(lambda u: sj.compress(model.network({}), u, at=jnp.array([0.1])).force[0])
    assert float(f(0.2)) == pytest.approx(float(f(0.3)), rel=1e-9)  # the sample does not depend on the range


@pytest.mark.slow
def test_gradient_with_respect_to_applied_loads():
    """Network loads are differentiable: a lateral load on the middle of a pinned column,
    implicit derivative of the sampled forces against central differences."""
    net = sj.probe_network(sj.column(5, supports=("pinned", "pinned"), EI=0.071, dim=2))
    direction = np.zeros(net.loads.shape)
    direction[2, 1] = 1.0

    def loss(s):
        loaded = net.replace(loads=s * jnp.asarray(direction))
        return jnp.sum(sj.compress(loaded, 0.2, at=jnp.array([0.01, 0.1, 0.2]), settings=TIGHT).force)

    s = 0.05
    implicit = float(jax.grad(loss)(s))
    fd = _central(lambda x: loss(x[0]), np.array([s]))[0]
    assert implicit == pytest.approx(fd, rel=1e-6)
