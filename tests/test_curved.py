"""Naturally curved planar filaments (``sj.arc``, ``sj.crimped_fibre``,
``sj.with_natural_curvature``) against an independent shooting solver of the planar
elastica with natural curvature, EI (θ' − κ₀)' = −t × n, integrated by scipy's DOP853 with
a continuation in the load (so it follows the same equilibrium branch from the rest shape)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, fsolve

import socbjax as sj


def _rhs(kappa0, EI, n):
    def rhs(s, y):
        _, _, th, m = y
        return [np.cos(th), np.sin(th), kappa0 + m / EI, -(np.cos(th) * n[1] - np.sin(th) * n[0])]
    return rhs


def _integrate(rhs, span, y0):
    return solve_ivp(rhs, span, y0, method="DOP853", rtol=1e-13, atol=1e-14).y[:, -1]


def shooting_cantilever_tip(kappa0, EI, L, F, steps=40):
    """Tip position (µm) of a cantilever clamped at the origin along +x, natural curvature
    κ₀, tip force F: shooting from the free end (m = 0) to the clamp for the tip angle that
    gives θ(0) = 0, the load raised in ``steps`` increments from the rest shape."""
    F = np.asarray(F, float)
    theta_tip = kappa0 * L
    for lam in np.linspace(0, 1, steps + 1)[1:]:
        def g(t, lam=lam):
            return _integrate(_rhs(kappa0, EI, lam * F), (L, 0), [0, 0, t, 0.0])[2]
        w = next(w for w in (0.05, 0.1, 0.2, 0.4) if g(theta_tip - w) * g(theta_tip + w) < 0)
        theta_tip = brentq(g, theta_tip - w, theta_tip + w, xtol=1e-15)
    return -_integrate(_rhs(kappa0, EI, F), (L, 0), [0, 0, theta_tip, 0.0])[:2]


def shooting_arch(kappa0, EI, L, theta0, P, steps=20):
    """Pinned–pinned arch (first end at the origin, last end on the x axis, free along it)
    pushed by a force P along −x at the last end: unknowns θ(0) and the vertical reaction,
    conditions m(L) = 0 and y(L) = 0.  Returns the last end's x (µm)."""
    guess = np.array([theta0, 0.0])
    for lam in np.linspace(0, 1, steps + 1)[1:]:
        def ends(z, lam=lam):
            y = _integrate(_rhs(kappa0, EI, [-lam * P, z[1]]), (0, L), [0, 0, z[0], 0.0])
            return [y[3], y[1]]
        guess = fsolve(ends, guess, xtol=1e-14)
        assert np.abs(ends(guess)).max() < 1e-12
    return _integrate(_rhs(kappa0, EI, [-P, guess[1]]), (0, L), [0, 0, guess[0], 0.0])[0]


def test_an_arc_is_built_on_its_circle_and_is_stress_free():
    net = sj.arc(7, radius=2.0, angle=120.0, EI=0.071, dim=2)
    centre = np.array([0.0, 2.0])
    np.testing.assert_allclose(np.linalg.norm(net.positions - centre, axis=1), 2.0, rtol=1e-14)
    angles = np.arctan2(net.tangents[:, 1], net.tangents[:, 0])
    np.testing.assert_allclose(angles, np.radians(np.linspace(0, 120, 7)), atol=1e-14)
    np.testing.assert_allclose(net.natural_curvature, 0.5)
    sol = sj.solve(net)  # no load: the rest shape, no moment anywhere
    np.testing.assert_allclose(sol.positions, net.positions, atol=1e-13)
    np.testing.assert_allclose(sol.moments, 0.0, atol=1e-13)


def test_a_loaded_arc_converges_to_the_shooting_solution_at_sixth_order():
    R, phi, EI = 1.0, 90.0, 1.0
    L = R * np.radians(phi)
    F = np.array([0.0, -1.5])  # F L²/EI = 3.7: the tip turns from 90° to −8°
    tip = shooting_cantilever_tip(1 / R, EI, L, F)
    errors = {}
    for n in (3, 5, 9):
        sol = sj.solve(sj.arc(n, radius=R, angle=phi, EI=EI, dim=2), {n - 1: F})
        errors[n] = np.abs(np.asarray(sol.positions[-1]) - tip).max()
    # measured: 2.3e-5, 3.8e-7, 5.8e-9 µm (orders 5.9, 6.0)
    assert errors[3] < 1e-4 and errors[5] < 1e-6 and errors[9] < 2e-8, errors
    assert np.log2(errors[5] / errors[9]) > 5.5, errors
    jointed = sj.solve(sj.arc(9, radius=R, angle=phi, EI=EI, dim=2), {8: F}, model="jointed")
    assert np.abs(np.asarray(jointed.positions[-1]) - tip).max() > 1e5 * errors[9]  # jointed: second order, 1e-2


def test_an_arch_compressed_along_its_chord_matches_shooting():
    R, phi, EI, P = 1.0, 120.0, 1.0, 0.8
    L, theta0 = R * np.radians(phi), -np.radians(phi) / 2
    n = 9
    s = np.linspace(0, L, n)
    positions = R * np.stack([np.sin(s / R + theta0) - np.sin(theta0), np.cos(theta0) - np.cos(s / R + theta0)], 1)
    tangents = np.stack([np.cos(s / R + theta0), np.sin(s / R + theta0)], 1)
    fixed = [np.eye(2)] + [np.zeros((0, 2))] * (n - 2) + [np.array([[0.0, 1.0]])]
    net = sj.make_network(positions, tangents, [(k, k + 1) for k in range(n - 1)], L / (n - 1), EI,
                          fixed_directions=fixed, natural_curvature=1 / R)
    x_end = shooting_arch(1 / R, EI, L, theta0, P)
    sol = sj.solve(net, {n - 1: [-P, 0.0]})
    assert abs(float(sol.positions[-1, 0]) - x_end) < 1e-7
    assert positions[-1, 0] - x_end > 0.05  # the chord really shortened


def test_gradient_with_respect_to_natural_curvature_matches_finite_differences():
    net = sj.arc(5, radius=1.0, angle=90.0, EI=1.0, dim=2)

    def tip_y(kappa):
        return sj.solve(net.replace(natural_curvature=kappa), {4: jnp.array([0.3, -0.5])}).positions[-1, 1]

    k0 = jnp.asarray(net.natural_curvature)
    grad = jax.jit(jax.grad(tip_y))(k0)
    h = 1e-5
    fd = np.array([(tip_y(k0.at[i].add(h)) - tip_y(k0.at[i].add(-h))) / (2 * h) for i in range(4)])
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-9)
    assert np.all(np.asarray(grad) > 0)  # more curvature lifts the tip of a quarter circle


def test_a_crimped_fibre_follows_its_sine_generated_curve():
    fibre = sj.crimped_fibre(17, length=4.0, wavelength=2.0, crimp_angle=30.0, supports=("pinned", "pinned"))
    s = np.linspace(0, 4.0, 17)
    angles = np.arctan2(fibre.tangents[:, 1], fibre.tangents[:, 0])
    np.testing.assert_allclose(angles, np.radians(30.0) * np.sin(np.pi * s), atol=1e-13)
    assert abs(fibre.positions[-1, 1]) < 1e-12  # whole wavelengths: the end is back on the axis
    # x of the end = ∫ cos θ ds; the circular pieces approximate the curve to O(l⁴)
    assert 3.0 < fibre.positions[-1, 0] < 4.0
    sol = sj.solve(fibre, {16: [0.05, 0.0]})  # pulled: the crimp straightens, the fibre lengthens
    assert sol.positions[-1, 0] > fibre.positions[-1, 0]
    np.testing.assert_allclose(np.asarray(sol.positions)[[0, -1], 1], 0.0, atol=1e-12)


def test_with_natural_curvature_keeps_junction_angles_and_support_kinds():
    mesh = sj.unit_dendritic_mesh(dim=2)
    rng = np.random.default_rng(1)
    curved = sj.with_natural_curvature(mesh, 0.2 * rng.standard_normal(mesh.n_segments))
    assert curved.topology == mesh.topology
    J = np.flatnonzero(mesh.attached)
    assert len(J) > 0

    def branch_angles(net):
        t = np.asarray(net.tangents)
        return np.degrees(np.arccos(np.sum(t[J] * t[mesh.attach[J]], axis=1)))

    np.testing.assert_allclose(branch_angles(curved), branch_angles(mesh), atol=1e-9)
    assert np.abs(np.asarray(curved.positions) - np.asarray(mesh.positions)).max() > 0.01  # the shape did change
    sol = sj.solve(curved)
    np.testing.assert_allclose(sol.positions, curved.positions, atol=1e-12)
    np.testing.assert_allclose(sol.moments, 0.0, atol=1e-12)


def test_bad_curvature_inputs_name_the_argument_and_the_fix():
    with pytest.raises(ValueError, match="GJ"):  # a curved 3D rod needs its material frame
        sj.with_natural_curvature(sj.cantilever(3), [0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="n_nodes > 2"):
        sj.arc(2, radius=1.0, angle=270.0, dim=2)
    with pytest.raises(ValueError, match="radius"):
        sj.arc(5, radius=-1.0, angle=90.0, dim=2)
    net = sj.cantilever(3, dim=2)
    with pytest.raises(ValueError, match=r"natural_curvature\[0\].*less than 180"):
        sj.with_natural_curvature(net, 8.0)
    with pytest.raises(ValueError, match="stress-free"):  # curvature without the shape that goes with it
        sj.make_network(net.positions, net.tangents, net.segments, net.lengths, net.EI,
                        fixed_directions=[np.eye(2), np.zeros((0, 2)), np.zeros((0, 2))], clamped=[True, False, False],
                        natural_curvature=0.5)
    with pytest.raises(ValueError, match="GJ"):
        sj.make_network(np.array([[0, 0, 0], [1.0, 0, 0]]), np.array([[1.0, 0, 0]] * 2), [(0, 1)], 1.0, 1.0,
                        fixed_directions=[np.eye(3), np.zeros((0, 3))], clamped=[True, False],
                        natural_curvature=[[0.0, 0.1, 0.0]])
    with pytest.raises(ValueError, match="crimp_angle"):
        sj.crimped_fibre(9, length=2.0, wavelength=1.0, crimp_angle=95.0)


# ----------------------------------------------------------------------------- 3D: twisting networks


def kirchhoff_tip(network, F, steps=6):
    """Tip of a naturally curved 3D cantilever (uniform κ₁, κ₂, τ₀; clamped frame at node 0)
    under a tip force F: shooting of the Kirchhoff rod with its material frame,
    Ω = (m − (m·t)t)/EI + κ₁d1 + κ₂d2 + (m·t/GJ + τ₀) t, m' = −t × n, on the clamp moment."""
    EI, GJ = float(network.EI[0]), float(network.GJ[0])
    kappa, L = np.asarray(network.natural_curvature)[0], float(np.sum(network.lengths))
    t0, d0 = np.asarray(network.tangents[0], float), np.asarray(network.directors[0], float)

    def tip(m0, n):
        def rhs(s, y):
            D, m = y[3:12].reshape(3, 3), y[12:]
            t, d1, d2 = D
            M = m @ t
            omega = (m - M * t) / EI + kappa[0] * d1 + kappa[1] * d2 + (M / GJ + kappa[2]) * t
            return np.concatenate([t, np.cross(omega[None, :], D).ravel(), -np.cross(t, n)])
        y0 = np.concatenate([np.zeros(3), t0, d0, np.cross(t0, d0), m0])
        return solve_ivp(rhs, (0, L), y0, method="DOP853", rtol=1e-13, atol=1e-12).y[:, -1]

    m0, scale = np.zeros(3), EI / L
    for lam in np.linspace(0, 1, steps + 1)[1:]:
        m0 = fsolve(lambda z, lam=lam: tip(z, lam * np.asarray(F))[12:] / scale, m0, xtol=1e-14)
    end = tip(m0, np.asarray(F))
    assert np.abs(end[12:]).max() < 1e-9 * scale
    return end[:3]


BATHE = dict(radius=100.0, angle=45.0, EI=1e7 / 12, GJ=5e6 * 0.1406)  # unit square section, E = 1e7, ν = 0


def test_a_3d_arc_is_stress_free_and_bends_in_its_plane_as_the_planar_arc():
    arc3 = sj.arc(5, radius=2.0, angle=120.0, EI=0.071, GJ=0.05)  # 5 nodes: the Bathe test's program
    assert arc3.twisting
    np.testing.assert_allclose(np.linalg.norm(np.asarray(arc3.positions) - [0, 2.0, 0], axis=1), 2.0, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(arc3.positions)[:, 2], 0.0, atol=1e-15)
    rest = sj.solve(arc3)
    np.testing.assert_allclose(rest.positions, arc3.positions, atol=1e-12)
    # (a load near 0.011 pN buckles this soft-twisting arc out of its plane: lateral-torsional buckling)
    planar = sj.solve(sj.arc(5, radius=2.0, angle=120.0, EI=0.071, dim=2), {4: [0.0, -0.005]})
    spatial = sj.solve(arc3, {4: [0.0, -0.005, 0.0]})
    np.testing.assert_allclose(np.asarray(spatial.positions)[:, :2], planar.positions, atol=1e-11)
    np.testing.assert_allclose(np.asarray(spatial.positions)[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(spatial.state.twists, 0.0, atol=1e-12)


def test_the_bathe_bolourchi_bend_matches_kirchhoff_shooting():
    """45° bend of radius 100, tip force 600 out of its plane (inextensible, unshearable
    version of Bathe & Bolourchi 1979; with extension and shear the literature tip is about
    (47.2, 15.8, 53.4))."""
    P = np.array([0.0, 0.0, 600.0])
    tip = kirchhoff_tip(sj.arc(5, **BATHE), P, steps=3)
    sol = sj.solve(sj.arc(5, **BATHE), {4: P})
    assert np.abs(np.asarray(sol.positions[-1]) - tip).max() < 1e-4  # measured 3.4e-5 on a length of 78.5
    assert np.allclose(tip, [46.89, 15.56, 53.60], atol=0.01)
    curve = np.asarray(sol.curve(points_per_segment=5).positions)  # the smooth curve on the material-frame jets
    np.testing.assert_allclose(curve[:, -1], np.asarray(sol.positions)[1:], atol=1e-9 * 78.5)
    assert abs(tip[2]) > 50  # a large out-of-plane deflection: the first leg of the bend twists


@pytest.mark.slow
def test_the_bathe_bolourchi_bend_converges_at_sixth_order():
    P = np.array([0.0, 0.0, 600.0])
    tip = kirchhoff_tip(sj.arc(9, **BATHE), P, steps=12)
    err = {n: np.abs(np.asarray(sj.solve(sj.arc(n, **BATHE), {n - 1: P}).positions[-1]) - tip).max() for n in (3, 5, 9)}
    # measured: 2.3e-3, 3.4e-5, 5.1e-7 (order 6.1)
    assert err[3] < 5e-3 and err[9] < 1e-6 and np.log2(err[5] / err[9]) > 5.5, err


def test_a_helix_is_built_on_its_helix_and_rests_there():
    h = sj.helix(5, radius=1.0, pitch=2.0, turns=0.5, EI=0.071, GJ=0.05)  # 5 nodes: the arc tests' program
    c, speed = 2.0 / (2 * np.pi), np.hypot(1.0, 2.0 / (2 * np.pi))
    phi = np.linspace(0, np.pi, 5)
    exact = np.stack([np.cos(phi) - 1.0, np.sin(phi), c * phi], axis=1)  # started at the origin, axis at x = −1
    np.testing.assert_allclose(h.positions, exact, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(np.asarray(h.natural_curvature)[:, :2], axis=1), 1.0 / speed**2,
                               rtol=1e-12)  # κ = R/(R² + c²)
    np.testing.assert_allclose(np.asarray(h.natural_curvature)[:, 2], c / speed**2, rtol=1e-12)  # τ = c/(R² + c²)
    rest = np.abs(np.asarray(sj.solve(h).positions) - exact).max()
    assert rest < 5e-6  # the quintic holds a helix piece to the discretisation error: 1.3e-6 µm here,
    # 4.0e-7 µm with 13 nodes per turn


def test_builders_take_natural_curvature_and_GJ():
    bent = sj.cantilever(5, length=1.0, dim=2, natural_curvature=0.5)
    np.testing.assert_allclose(bent.positions, sj.with_natural_curvature(sj.cantilever(5, dim=2), 0.5).positions)
    mesh = sj.unit_dendritic_mesh(dim=3, GJ=8e-3, natural_curvature=[0.2, -0.1, 0.05])  # checked stress-free
    assert mesh.twisting and np.allclose(mesh.natural_curvature, [0.2, -0.1, 0.05])
    t, J = np.asarray(mesh.tangents), np.flatnonzero(mesh.attached)
    straight = np.asarray(sj.unit_dendritic_mesh(dim=3).tangents)
    np.testing.assert_allclose(np.sum(t[J] * t[mesh.attach[J]], 1), np.sum(straight[J] * straight[mesh.attach[J]], 1),
                               atol=1e-12)  # the branch angle is kept
    outcrop = sj.dendritic_outcrop(generations=2, dim=2, natural_curvature=0.05)
    assert np.allclose(outcrop.natural_curvature, 0.05)


@pytest.mark.slow
def test_the_kirchhoff_shooting_reference_agrees_with_collocation():
    """The second method for the 3D references: scipy's collocation (solve_bvp) of the same
    Kirchhoff rod, r(0) = 0 and D(0) clamped, m(L) = 0, on the Bathe–Bolourchi bend."""
    from scipy.integrate import solve_bvp

    net = sj.arc(5, **BATHE)
    EI, GJ, kappa = BATHE["EI"], BATHE["GJ"], np.asarray(net.natural_curvature)[0]
    L, P = float(np.sum(net.lengths)), np.array([0.0, 0.0, 600.0])
    t0, d0 = np.asarray(net.tangents[0], float), np.asarray(net.directors[0], float)
    D0 = np.array([t0, d0, np.cross(t0, d0)])
    shooting = kirchhoff_tip(net, P, steps=12)

    def rhs(s, y):
        out = np.empty_like(y)
        for j in range(y.shape[1]):
            D, m = y[3:12, j].reshape(3, 3), y[12:, j]
            t, d1, d2 = D
            M = m @ t
            omega = (m - M * t) / EI + kappa[0] * d1 + kappa[1] * d2 + (M / GJ + kappa[2]) * t
            out[:, j] = np.concatenate([t, np.cross(omega[None, :], D).ravel(), -np.cross(t, P)])
        return out

    def bc(ya, yb):
        return np.concatenate([ya[:3], ya[3:12] - D0.ravel(), yb[12:] / (EI / L)])

    s = np.linspace(0, L, 41)  # initial guess: the unloaded arc
    rest = sj.solve(sj.arc(41, **BATHE))
    frames = np.asarray(rest.material_frames()).reshape(41, 9)
    guess = np.concatenate([np.asarray(rest.positions), frames, np.zeros((41, 3))], axis=1).T
    for lam in np.linspace(0.25, 1.0, 4):  # the same load ramp, so the same branch
        solution = solve_bvp(_scaled(rhs, lam), bc, s, guess, tol=1e-10, max_nodes=20000)
        assert solution.success, solution.message
        s, guess = solution.x, solution.y
    assert np.abs(guess[:3, -1] - shooting).max() < 1e-6


def _scaled(rhs, lam):
    """``rhs`` with the force part (the last three rows, m' = −t × P) scaled by ``lam``."""
    def scaled(s, y):
        out = rhs(s, y)
        out[12:] *= lam
        return out
    return scaled
