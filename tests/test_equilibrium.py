"""What users read off a static equilibrium (socbjax.Solution): the smooth curve between
nodes, end rotations, maximum deflection, support reactions and nodal couples — against the
exact elastica (socbjax.testing), closed forms (a pure end couple bends a cantilever into a
circular arc, M L/EI = 2π closes it) and statics."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj
from socbjax.testing import elastica_cantilever


@pytest.fixture(scope="module")
def cantilever_p2():
    """The 5-node planar cantilever at PL²/EI = 2 and the exact elastica."""
    return sj.solve(sj.cantilever(5, dim=2), {-1: [0.0, 2.0]}), elastica_cantilever((0.0, 2.0), n_output=401)


def test_curve_between_nodes_follows_the_exact_elastica(cantilever_p2):
    sol, exact = cantilever_p2
    curve = sol.curve(points_per_segment=33)
    assert curve.positions.shape == (4, 33, 2) and curve.s.shape == (4, 33)
    s = np.asarray(curve.s) + np.arange(4)[:, None] * 0.25  # arc length along the filament
    ref, grid = np.asarray(exact.positions), np.asarray(exact.s)
    expected = np.stack([np.interp(s, grid, ref[:, k]) for k in range(2)], -1)
    assert np.abs(np.asarray(curve.positions) - expected).max() < 2e-6  # the reference's linear interpolation dominates
    theta = np.interp(s, grid, np.asarray(exact.angle))
    tangents = np.asarray(curve.tangents)
    assert np.abs(np.arctan2(tangents[..., 1], tangents[..., 0]) - theta).max() < 1e-5
    np.testing.assert_allclose(np.asarray(curve.positions[:, 0]), np.asarray(sol.positions[:-1]), atol=1e-15)
    np.testing.assert_allclose(np.asarray(curve.positions[:, -1]), np.asarray(sol.positions[1:]), atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(np.asarray(curve.tangents), axis=-1), 1.0, atol=1e-14)
    # statics: m(s) = (r_tip − r(s)) × F for a tip force F; EI κ agrees with it (EI = 1)
    F = np.array([0.0, 2.0])
    arm = np.asarray(sol.positions[-1]) - np.asarray(curve.positions)
    np.testing.assert_allclose(np.asarray(curve.moment), arm[..., 0] * F[1] - arm[..., 1] * F[0], atol=1e-12)
    np.testing.assert_allclose(np.asarray(curve.curvature), np.asarray(curve.moment), atol=2e-4)


def test_max_deflection_end_rotation_and_reactions(cantilever_p2):
    sol, exact = cantilever_p2
    tip = np.asarray(exact.tip_position)
    assert float(sol.max_deflection()) == pytest.approx(tip[1], rel=1e-6)  # Mattiasson: 0.49346
    assert float(sol.end_rotation()) == pytest.approx(float(exact.tip_angle), rel=1e-6)
    np.testing.assert_allclose(np.asarray(sol.reactions[0]), [0.0, -2.0], atol=1e-10)  # balances the load
    # the clamp couple balances the moment of the load about the clamp: R + r_tip × F = 0
    assert float(sol.reaction_moments[0]) == pytest.approx(-2.0 * float(sol.positions[-1, 0]), rel=1e-12)
    assert float(np.abs(np.asarray(sol.reaction_moments[1:])).max()) == 0.0


@pytest.mark.parametrize("dim, nodes", [(2, 3), pytest.param(3, 5, marks=pytest.mark.slow)])
def test_tip_couple_of_2pi_rolls_a_cantilever_into_a_closed_circle(dim, nodes):
    """A pure end couple gives constant curvature M/EI: M = 2π EI/L closes the circle, with
    the tip back at the clamp.  (3D: under a fixed-direction couple sign(det J) changes along
    the planar path — out-of-plane critical points of a rod under an axial end couple — so
    the ramp runs with detect_critical_points=False.)"""
    EI, L = 0.5, 2.0
    M = 2 * np.pi * EI / L
    settings = sj.PathSettings(detect_critical_points=dim == 2)
    sol = sj.solve(sj.cantilever(nodes, dim=dim, EI=EI, length=L), couples={-1: M if dim == 2 else [0.0, 0.0, M]},
                   settings=settings)
    assert np.abs(np.asarray(sol.positions[-1])).max() < 1e-6
    curve = sol.curve(16)
    radius = L / (2 * np.pi)
    centre = np.array([0.0, radius, 0.0][:dim])
    np.testing.assert_allclose(np.linalg.norm(curve.polyline() - centre, axis=1), radius, atol=1e-9)
    kappa = np.asarray(curve.curvature) if dim == 2 else np.asarray(curve.curvature)[..., 2]
    np.testing.assert_allclose(kappa, 1 / radius, rtol=1e-9)
    if dim == 2:
        assert float(sol.end_rotation()) == pytest.approx(2 * np.pi, rel=1e-12)  # winding kept


def test_couple_and_force_arguments():
    net = sj.cantilever(3, dim=2)
    a = sj.solve(net, couples={-1: 0.7})
    b = sj.solve(net, couples=np.array([0.0, 0.0, 0.7]))
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-14)
    assert float(a.end_rotation()) == pytest.approx(0.7, rel=1e-12)  # θ = M L / EI
    with pytest.raises(ValueError, match="a scalar"):
        sj.solve(net, couples={-1: [0.0, 1.0]})
    with pytest.raises(ValueError, match="node 7"):
        sj.solve(net, couples={7: 1.0})
    with pytest.raises(ValueError, match="NaN"):
        sj.solve(net, couples={-1: float("nan")})
    with pytest.raises(ValueError, match="3 components"):
        sj.solve(sj.cantilever(3, dim=3), couples={-1: 1.0})


def test_curve_quantities_are_differentiable():
    """The tip deflection of the smooth curve depends on P L²/EI only: EI ∂δ/∂EI = −P ∂δ/∂P."""
    def deflection(EI, P):
        return sj.solve(sj.cantilever(4, dim=2, EI=EI), {-1: jnp.stack([0.0, P])}).max_deflection()

    dEI, dP = jax.grad(deflection, argnums=(0, 1))(1.3, 1.7)
    assert float(1.3 * dEI) == pytest.approx(-1.7 * float(dP), rel=1e-9)
    h = 1e-5
    fd = (float(deflection(1.3, 1.7 + h)) - float(deflection(1.3, 1.7 - h))) / (2 * h)
    assert float(dP) == pytest.approx(fd, rel=1e-6)
