"""The 3D Kirchhoff rod with twist (networks built with ``GJ=``) against references built
here: closed forms (pure twist, the Kirchhoff helix of a pure end couple) and a shooting
solver of the Kirchhoff rod with a material frame, r' = t, D' = Ω × D with
Ω = (m − (m·t) t)/EI + (m·t)/GJ t, m' = −t × n (scipy DOP853, fsolve on the clamp moment
with a load continuation), across a rigid kink."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

import socbjax as sj


def reference_director(T):
    """The documented reference director: the first vector of the plane ⊥ T that is built
    from the coordinate axis least aligned with T (``orthonormal_complement``)."""
    T = np.asarray(T, float)
    axis = np.eye(3)[np.argmin(np.abs(T))]
    f = axis - (axis @ T) * T
    return f / np.linalg.norm(f)


def frame(T):
    g = reference_director(T)
    return np.array([T, g, np.cross(T, g)], float)


def _rhs(EI, GJ, n):
    def rhs(s, y):
        D, m = y[3:12].reshape(3, 3), y[12:]
        t = D[0]
        M = m @ t
        omega = (m - M * t) / EI + M / GJ * t
        return np.concatenate([t, np.cross(omega[None, :], D).ravel(), -np.cross(t, n)])
    return rhs


def _run(rhs, L, y0):
    return solve_ivp(rhs, (0, L), y0, method="DOP853", rtol=1e-13, atol=1e-14).y[:, -1]


def shooting_l_shape(L1, L2, EI, GJ, F, steps=10):
    """Tip position of an L: leg 1 along +x clamped at the origin (whole frame), a rigid 90°
    kink, leg 2 along +y, tip force F; the kink keeps leg 2's frame fixed in leg 1's."""
    F = np.asarray(F, float)
    kink = frame([0, 1, 0]) @ frame([1, 0, 0]).T  # leg 2's reference frame in leg 1's coordinates

    def tip(m0, load):
        y = _run(_rhs(EI, GJ, load), L1, np.concatenate([np.zeros(3), frame([1, 0, 0]).ravel(), m0]))
        y = np.concatenate([y[:3], (kink @ y[3:12].reshape(3, 3)).ravel(), y[12:]])
        return _run(_rhs(EI, GJ, load), L2, y)

    m0 = np.zeros(3)
    for lam in np.linspace(0, 1, steps + 1)[1:]:
        m0 = fsolve(lambda z, lam=lam: tip(z, lam * F)[12:], m0, xtol=1e-13)
    end = tip(m0, F)
    assert np.abs(end[12:]).max() < 1e-10  # the free tip carries no moment
    return end[:3]


def l_shape(n, L1, L2, EI, GJ):
    s = np.linspace(0, 1, n)
    pos = [np.array([L1 * x, 0, 0]) for x in s] + [np.array([L1, L2 * y, 0]) for y in s]
    tan = [np.array([1.0, 0, 0])] * n + [np.array([0, 1.0, 0])] * n
    segs = [(k, k + 1) for k in range(n - 1)] + [(n + k, n + k + 1) for k in range(n - 1)]
    lengths = [L1 / (n - 1)] * (n - 1) + [L2 / (n - 1)] * (n - 1)
    fixed = [np.eye(3)] + [np.zeros((0, 3))] * (2 * n - 1)
    return sj.make_network(pos, tan, segs, lengths, EI, fixed_directions=fixed, clamped=np.arange(2 * n) == 0,
                           attach=[(n - 1, n)], GJ=GJ)


def test_a_pure_twisting_couple_twists_by_M_l_over_GJ():
    GJ = np.array([0.5, 0.7, 1.1, 0.9])
    net = sj.cantilever(5, length=2.0, EI=1.0, GJ=GJ)  # the helix test's program (same topology)
    sol = sj.solve(net, couples={4: [0.3, 0.0, 0.0]})
    np.testing.assert_allclose(sol.positions, net.positions, atol=1e-13)  # stays straight
    expected = np.concatenate([[0.0], np.cumsum(0.3 * 0.5 / GJ)])  # ψ = Σ M l / GJ
    np.testing.assert_allclose(sol.state.twists, expected, atol=1e-13)
    np.testing.assert_allclose(np.asarray(sol.moments)[:, 0], 0.3, atol=1e-13)  # the twisting moment
    assert reference_director([1, 0, 0]) @ np.array([0, 1.0, 0]) == 1.0  # along x the reference director is y
    d1 = np.asarray(sol.material_frames())[-1, 1]
    np.testing.assert_allclose(d1, [0, np.cos(expected[-1]), np.sin(expected[-1])], atol=1e-13)


HELIX = dict(EI=1.0, GJ=0.7, L=1.0, C=np.array([1.2, 2.0, 0.0]))  # |C| L/EI = 2.3 rad; C·t0 = 1.2 twists


def helix_errors(nodes):
    """(position errors, tip-frame errors) of the SOCB cantilever under the end couple C
    against the exact helix (t precesses about C at |C|/EI) and an ODE integration of the
    material frame."""
    EI, GJ, L, C = HELIX["EI"], HELIX["GJ"], HELIX["L"], HELIX["C"]
    k, c = np.linalg.norm(C) / EI, C / np.linalg.norm(C)
    t0 = np.array([1.0, 0, 0])
    along, across = (t0 @ c) * c, t0 - (t0 @ c) * c

    def helix(s):
        return along * s + np.sin(k * s) / k * across + (1 - np.cos(k * s)) / k * np.cross(c, across)

    end = _run(_rhs(EI, GJ, np.zeros(3)), L, np.concatenate([np.zeros(3), frame(t0).ravel(), C]))
    errors, frame_errors = {}, {}
    for n in nodes:
        sol = sj.solve(sj.cantilever(n, length=L, EI=EI, GJ=GJ), couples={n - 1: C})
        exact = np.array([helix(s) for s in np.linspace(0, L, n)])
        errors[n] = np.abs(np.asarray(sol.positions) - exact).max()
        frame_errors[n] = np.abs(np.asarray(sol.material_frames())[-1] - end[3:12].reshape(3, 3)).max()
    return errors, frame_errors, helix(L)


def test_an_end_couple_with_a_twisting_part_makes_the_kirchhoff_helix():
    errors, frame_errors, tip = helix_errors((5,))
    assert errors[5] < 3e-8 and frame_errors[5] < 3e-8, (errors, frame_errors)  # measured 6.6e-9, 8.8e-9
    free = sj.solve(sj.cantilever(5, length=HELIX["L"], EI=HELIX["EI"]), couples={4: HELIX["C"]})
    assert np.abs(np.asarray(free.positions[-1]) - tip).max() > 0.05  # torsion-free: the twisting part is lost


@pytest.mark.slow
def test_helix_and_l_shape_converge_at_high_order_with_3_5_9_nodes():
    errors, frame_errors, _ = helix_errors((3, 5, 9))
    # measured: positions 2.1e-6, 6.6e-9, 2.3e-10; end frame 3.0e-6, 8.8e-9, 3.2e-10
    assert errors[3] < 1e-5 and errors[9] < 1e-9 and frame_errors[3] < 1e-5 and frame_errors[9] < 1e-9
    for ratio in (1.0, 0.7):
        tip = shooting_l_shape(1.0, 1.0, 1.0, ratio, [0.0, 0.0, 1.0])
        err = {n: np.abs(np.asarray(sj.solve(l_shape(n, 1.0, 1.0, 1.0, ratio), {2 * n - 1: [0, 0, 1.0]}).positions[-1])
                         - tip).max() for n in (3, 5, 9)}
        # measured (ratio 1): 8.2e-7, 1.3e-8, 2.0e-10 µm; (0.7): 6.7e-7, 1.0e-8, 1.6e-10
        assert err[3] < 3e-6 and err[9] < 1e-9 and np.log2(err[5] / err[9]) > 5.5, err
        torsion_free = sj.solve(l_shape(5, 1.0, 1.0, 1.0, None), {9: [0, 0, 1.0]})
        assert np.abs(np.asarray(torsion_free.positions[-1]) - tip).max() > 0.1  # the old junction rule is far off


@pytest.mark.parametrize("ratio", [1.0, pytest.param(0.7, marks=pytest.mark.slow)])
def test_an_l_shaped_filament_twists_its_first_leg_as_the_shooting_solution(ratio):
    EI, F = 1.0, np.array([0.0, 0.0, 1.0])  # out of the plane of the L: leg 1 twists
    tip = shooting_l_shape(1.0, 1.0, EI, ratio * EI, F, steps=2)
    net = l_shape(5, 1.0, 1.0, EI, ratio * EI)
    sol = sj.solve(net, {9: F})
    assert np.abs(np.asarray(sol.positions[-1]) - tip).max() < 5e-8  # measured 1.3e-8 (ratio 1), 1.0e-8 (0.7)
    r, t = np.asarray(sol.positions), np.asarray(sol.tangents)
    statics = np.cross(r[-1] - r[2], F) @ t[2]  # leg 1 carries the tip force's moment about its tangent as twist
    assert abs(statics) > 0.3 and np.asarray(sol.moments)[2] @ t[2] == pytest.approx(statics, rel=1e-8)


def test_planar_bending_does_not_twist():
    loads = {4: [0.0, -1.5, 0.0]}
    twisting = sj.solve(sj.cantilever(5, EI=1.0, GJ=0.3), loads)
    free = sj.solve(sj.cantilever(5, EI=1.0), loads)
    np.testing.assert_allclose(twisting.positions, free.positions, atol=1e-12)
    np.testing.assert_allclose(twisting.state.twists, 0.0, atol=1e-12)
    np.testing.assert_allclose(twisting.moments, free.moments, atol=1e-12)


def test_gradients_with_respect_to_GJ_and_the_natural_curvature_match_finite_differences():
    net = sj.arc(5, radius=1.0, angle=90.0, EI=1.0, GJ=0.7)  # curved and twisting: both drive the tip
    F = jnp.array([0.2, -0.3, 0.4])

    def tip_z(GJ, kappa):
        return sj.solve(net.replace(GJ=GJ, natural_curvature=kappa), {4: F}).positions[-1, 2]

    GJ, kappa = jnp.asarray(net.GJ), jnp.asarray(net.natural_curvature)
    grad_GJ, grad_kappa = jax.grad(tip_z, argnums=(0, 1))(GJ, kappa)
    rng = np.random.default_rng(0)
    dGJ, dkappa = jnp.asarray(rng.uniform(0.5, 1.5, GJ.shape)), jnp.asarray(rng.normal(size=kappa.shape))
    h = 1e-5
    fd_GJ = (tip_z(GJ + h * dGJ, kappa) - tip_z(GJ - h * dGJ, kappa)) / (2 * h)
    fd_kappa = (tip_z(GJ, kappa + h * dkappa) - tip_z(GJ, kappa - h * dkappa)) / (2 * h)
    assert float(grad_GJ @ dGJ) == pytest.approx(float(fd_GJ), rel=1e-6)
    assert float(jnp.sum(grad_kappa * dkappa)) == pytest.approx(float(fd_kappa), rel=1e-6)
    assert abs(float(fd_GJ)) > 1e-3  # the twist really drives the tip


@pytest.mark.slow
def test_twisting_networks_square_compress_and_save(tmp_path):
    mesh = sj.unit_dendritic_mesh(dim=3, GJ=8e-3)
    assert mesh.twisting
    model = sj.make_model(mesh)
    state = model.initial_state()
    assert model.residual(state, sj.Control.make(), model.frames(state)).size == model.n_unknowns
    result = sj.compress(mesh, 0.1, method="arclength")
    assert result.completed
    back = sj.load(sj.save(result, tmp_path / "twist.h5"))
    assert back.network.topology == mesh.topology
    np.testing.assert_array_equal(back.network.GJ, mesh.GJ)
    np.testing.assert_array_equal(back.twists, result.twists)
    assert result.twists.shape == (result.n_steps, mesh.n_nodes) and np.abs(result.twists).max() > 1e-6
    frames = back.solution(result.n_steps - 1).material_frames()  # loaded back: ψ recorded in the file
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", frames, frames), np.broadcast_to(np.eye(3), frames.shape),
                               atol=1e-12)
    with pytest.raises(ValueError, match="twisting"):
        sj.solve(sj.cantilever(3)).material_frames()


@pytest.mark.slow
def test_a_compressed_twisting_column_row_is_the_force_controlled_equilibrium():
    """Each row of a displacement-controlled path of a curved, twisting column (with ψ
    recorded) is the equilibrium that force control reaches under the recorded probe force:
    positions, frame angles, material frames and the smooth curve agree to round-off."""
    column = sj.column(5, dim=3, GJ=0.6, natural_curvature=[0.4, -0.3, 0.5])  # out-of-plane at rest
    result = sj.compress(column, 0.1, at=np.array([0.05, 0.1]))
    axis, tip = np.asarray(result.network.probe_direction), column.n_nodes - 1
    for k in range(result.n_steps):
        row = result.solution(k)
        loads = np.asarray(result.network.loads).copy()  # the perturbation compress applied, and the probe force
        loads[tip] += float(result.force[k]) * axis
        reference = sj.solve(column.replace(loads=loads))
        assert reference.result == sj.RESULTS.successful and np.abs(reference.state.twists).max() > 1e-3
        np.testing.assert_allclose(row.state.twists, reference.state.twists, atol=1e-10)
        np.testing.assert_allclose(row.positions, reference.positions, atol=1e-10)
        np.testing.assert_allclose(row.material_frames(), reference.material_frames(), atol=1e-10)
        np.testing.assert_allclose(row.curve().positions, reference.curve().positions, atol=1e-10)
    assert sj.plot_snapshots(result).axes  # the smooth curves of a curved twisting path need its recorded ψ


def test_actin_networks_twist_by_default_with_actins_torsional_stiffness():
    """3D dendritic builders and their models default to actin's GJ (Tsuda et al. 1996:
    8e-27 N·m² = 8e-3 pN·µm²); GJ=None is the paper's torsion-free model; 2D never twists."""
    assert sj.ACTIN_GJ == pytest.approx(8e-27 / 1e-12 / 1e-12)  # N·m² -> pN·µm²
    for net in (sj.unit_dendritic_mesh(), sj.dendritic_outcrop(generations=2), sj.UnitMeshModel().base,
                sj.OutcropModel(generations=2).base, sj.LawnModel(generations=2, n_outcrops=1).base):
        assert net.twisting and np.all(np.asarray(net.GJ) == sj.ACTIN_GJ)
    for net in (sj.unit_dendritic_mesh(GJ=None), sj.dendritic_outcrop(generations=2, GJ=None),
                sj.unit_dendritic_mesh(dim=2), sj.UnitMeshModel(GJ=None).base, sj.cantilever(3), sj.column(3)):
        assert not net.twisting
    lawn = sj.LawnModel(generations=2, n_outcrops=1)  # GJ scales with the fitted EI: force ∝ EI
    np.testing.assert_allclose(np.asarray(lawn.network({"EI": 0.142}).GJ), 2 * sj.ACTIN_GJ)


def test_what_twist_does_not_cover_yet_is_refused_with_the_reason():
    with pytest.raises(ValueError, match="torsion-free"):
        sj.solve(sj.cantilever(3, GJ=1.0), {2: [0, 0.1, 0]}, model="jointed")
    with pytest.raises(ValueError, match="GJ"):
        sj.cantilever(3, GJ=-1.0)
    assert not sj.cantilever(3, dim=2, GJ=1.0).twisting  # planar filaments do not twist
