"""Tests of the shooting reference solver for the planar elastica."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ellipe, ellipj, ellipk

from socbjax.testing import (
    elastica_cantilever,
    elastica_column_force,
    elastica_column_shape,
    elastica_kinked_cantilever,
    elastica_tip_deflection,
    shoot_elastica,
)

# Mattiasson (1981), perpendicular tip load: PL²/EI -> (ΔX/L shortening, ΔY/L deflection)
MATTIASSON = {1.0: (0.05643, 0.30172), 2.0: (0.16064, 0.49346),
              5.0: (0.38763, 0.71379), 10.0: (0.55500, 0.81061)}


def _rot(alpha):
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[c, -s], [s, c]])


def _ellipk(k):
    """Complete elliptic integral K(k) by the arithmetic-geometric mean."""
    a, b = 1.0, np.sqrt(1.0 - k * k)
    for _ in range(40):
        a, b = 0.5 * (a + b), np.sqrt(a * b)
    return np.pi / (2.0 * a)


@pytest.mark.parametrize("p", sorted(MATTIASSON))
def test_mattiasson_table(p):
    dx, dy = elastica_tip_deflection(p)
    assert dx == pytest.approx(MATTIASSON[p][0], abs=2e-5)
    assert dy == pytest.approx(MATTIASSON[p][1], abs=2e-5)


@pytest.mark.parametrize("p", [0.5, 2.0, 10.0])
def test_perpendicular_load_matches_first_integral_quadrature(p):
    # θ'' = -p cos θ, θ(0)=0, θ'(1)=0 gives θ'² = 2p(sin α - sin θ), α = tip angle:
    # 1 = ∫_0^α dθ/θ', y_L = ∫ sin θ dθ/θ', x_L = sqrt(2 sin α / p), m(0) = p x_L.
    sol = elastica_cantilever((0.0, p))
    alpha = float(sol.tip_angle)
    x, w = np.polynomial.legendre.leggauss(200)
    t = 0.5 * np.sqrt(alpha) * (x + 1.0)  # θ = α - t² removes the endpoint singularity
    g = 2.0 * t / np.sqrt(2.0 * p * (np.sin(alpha) - np.sin(alpha - t**2)))
    w = 0.5 * np.sqrt(alpha) * w
    assert np.sum(w * g) == pytest.approx(1.0, abs=1e-9)
    assert float(sol.tip_position[1]) == pytest.approx(np.sum(w * g * np.sin(alpha - t**2)),
                                                      abs=1e-9)
    assert float(sol.tip_position[0]) == pytest.approx(np.sqrt(2 * np.sin(alpha) / p),
                                                      abs=1e-10)
    assert float(sol.base_moment) == pytest.approx(p * float(sol.tip_position[0]), abs=1e-10)
    assert np.all(np.diff(np.asarray(sol.angle)) > 0)  # monotone: fundamental branch


def test_small_load_matches_linear_beam_theory():
    p = 1e-3
    dx, dy = elastica_tip_deflection(p)
    assert dy == pytest.approx(p / 3.0, rel=1e-5)  # PL³/(3EI)
    # θ ≈ p (s - s²/2): ΔX = ∫ θ²/2 ds = p²/15 = (3/5) ΔY² / L
    assert dx == pytest.approx(p**2 / 15.0, rel=1e-4)


def test_pure_moment_gives_circular_arc():
    M, L, EI = 2.5, 1.3, 0.7
    prof = shoot_elastica((0.0, 0.0), 0.0, M, (0.0, 0.0), length=L, EI=EI)
    k = M / EI
    np.testing.assert_allclose(prof.positions[-1], [np.sin(k * L) / k,
                                                    (1 - np.cos(k * L)) / k], atol=1e-10)
    np.testing.assert_allclose(prof.angle, k * np.asarray(prof.s), atol=1e-10)
    np.testing.assert_allclose(prof.moment, M, atol=1e-12)
    assert prof.s.shape == (101,) and prof.positions.shape == (101, 2)
    assert float(prof.s[0]) == 0.0 and float(prof.s[-1]) == pytest.approx(L)


def test_shoot_translation_and_rotation_invariance():
    F, r0, a = np.array([0.4, -1.1]), np.array([0.3, -2.0]), 0.7
    base = shoot_elastica((0.0, 0.0), 0.2, 0.9, F)
    moved = shoot_elastica(r0, 0.2 + a, 0.9, _rot(a) @ F)
    np.testing.assert_allclose(moved.positions, r0 + np.asarray(base.positions) @ _rot(a).T,
                               atol=1e-10)
    np.testing.assert_allclose(moved.angle, np.asarray(base.angle) + a, atol=1e-10)


@pytest.mark.parametrize("alpha", [0.3, -1.2, 2.5])
def test_cantilever_rotation_invariance(alpha):
    F = np.array([0.7, 2.1])
    base = elastica_cantilever(F)
    rot = elastica_cantilever(_rot(alpha) @ F, base_angle=alpha)
    np.testing.assert_allclose(rot.tip_position, _rot(alpha) @ np.asarray(base.tip_position),
                               atol=1e-9)
    assert float(rot.base_moment) == pytest.approx(float(base.base_moment), abs=1e-9)


def test_scaling_with_stiffness_and_length():
    F = np.array([-0.5, 3.0])
    base = elastica_cantilever(F)
    stiff = elastica_cantilever(2.0 * F, EI=2.0)
    np.testing.assert_allclose(stiff.positions, base.positions, atol=1e-10)
    np.testing.assert_allclose(stiff.moment, 2.0 * np.asarray(base.moment), atol=1e-9)
    longer = elastica_cantilever(F / 9.0, length=3.0)  # same F L²/EI
    np.testing.assert_allclose(longer.positions, 3.0 * np.asarray(base.positions), atol=1e-9)


def test_solution_fields_and_global_moment_balance():
    F = np.array([0.8, -1.7])
    sol = elastica_cantilever(F, length=2.0, EI=3.0, n_output=11)
    assert sol.converged and sol.end_moment_residual < 1e-9
    assert sol.positions.shape == (11, 2) and sol.s.shape == (11,)
    np.testing.assert_allclose(sol.tip_position, sol.positions[-1])
    np.testing.assert_allclose(np.asarray(sol.positions[0]), 0.0)
    x, y = np.asarray(sol.tip_position)  # m(0) = r(L) × F (moment of the tip force)
    assert float(sol.base_moment) == pytest.approx(x * F[1] - y * F[0], abs=1e-10)


@pytest.mark.parametrize("p, guess", [(4.0, 3.0), (10.0, 6.0)])
def test_buckled_branch_selected_by_guess(p, guess):
    # Axial compression: θ'' = -p sin θ, so √p = K(sin(α/2)), m(0) = 2√p sin(α/2).
    straight = elastica_cantilever((-p, 0.0))
    np.testing.assert_allclose(straight.angle, 0.0, atol=1e-12)
    sol = elastica_cantilever((-p, 0.0), base_moment_guess=guess)
    k = np.sin(float(sol.tip_angle) / 2.0)
    assert abs(float(sol.tip_angle)) > 1.0
    assert _ellipk(abs(k)) == pytest.approx(np.sqrt(p), abs=1e-9)
    assert float(sol.base_moment) == pytest.approx(2.0 * np.sqrt(p) * k, abs=1e-9)


@pytest.mark.slow  # suite time; in the default suite: the reference itself: the other tests of this file
@pytest.mark.parametrize("root_finder", ["auto", "bracketing"])
def test_bracketing_fallback_finds_same_solution(root_finder):
    # At PL²/EI = 10, m(L) is non-monotone in m(0) and Newton from 6.0 leaves its basin;
    # the scan + bisection fallback must return the (unique) root. root_finder="bracketing"
    # skips Newton, so the fallback itself is exercised.
    default = elastica_cantilever((0.0, 10.0))
    sol = elastica_cantilever((0.0, 10.0), base_moment_guess=6.0, root_finder=root_finder)
    np.testing.assert_allclose(sol.tip_position, default.tip_position, atol=1e-9)
    assert sol.end_moment_residual < 1e-10


def test_unconverged_solution_is_never_silent():
    # Newton alone from a guess outside its basin does not converge: the solver must say so.
    with pytest.raises(RuntimeError, match=r"tip_force=\[0.0, 10.0\].*\|m\(L\)\|"):
        elastica_cantilever((0.0, 10.0), base_moment_guess=6.0, root_finder="newton")
    sol = elastica_cantilever((0.0, 10.0), base_moment_guess=6.0, root_finder="newton", raise_on_failure=False)
    assert not sol.converged and sol.end_moment_residual > 1e-3


@pytest.mark.parametrize("kwargs, match", [
    ({"tip_force": (1.0, 2.0, 3.0)}, "tip_force must have shape"),
    ({"tip_force": (np.nan, 1.0)}, "tip_force must be finite"),
    ({"tip_force": (0.0, 1.0), "length": 0.0}, "length must be positive"),
    ({"tip_force": (0.0, 1.0), "EI": -1.0}, "EI must be positive"),
    ({"tip_force": (0.0, 1.0), "EI": np.inf}, "EI must be finite"),
    ({"tip_force": (0.0, 1.0), "n_output": 1}, "n_output must be an integer"),
    ({"tip_force": (0.0, 1.0), "n_output": 10.0}, "n_output must be an integer"),
    ({"tip_force": (0.0, 1.0), "tol": 0.0}, "tol must be positive"),
    ({"tip_force": (0.0, 1.0), "base_angle": (0.0, 1.0)}, "base_angle must have shape"),
])
def test_cantilever_input_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        elastica_cantilever(**kwargs)


def test_shoot_and_deflection_input_validation():
    with pytest.raises(ValueError, match="base_position must have shape"):
        shoot_elastica((0.0,), 0.0, 1.0, (0.0, 0.0))
    with pytest.raises(ValueError, match="base_moment must be finite"):
        shoot_elastica((0.0, 0.0), 0.0, np.nan, (0.0, 0.0))
    with pytest.raises(ValueError, match="rtol must be positive"):
        shoot_elastica((0.0, 0.0), 0.0, 1.0, (0.0, 0.0), rtol=-1e-9)
    with pytest.raises(ValueError, match="load_parameter must be finite"):
        elastica_tip_deflection(np.inf)


def test_float32_mode_raises_clear_error():
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="enable float64"):
            elastica_cantilever((0.0, 1.0))
        with pytest.raises(RuntimeError, match="enable float64"):
            shoot_elastica((0.0, 0.0), 0.0, 1.0, (0.0, 0.0))
    finally:
        jax.config.update("jax_enable_x64", True)


# ------------------------------------------------------------ kinked cantilever
@pytest.mark.slow  # suite time; in the default suite: the reference itself: the other tests of this file
def test_kinked_without_kink_reproduces_cantilever():
    F = np.array([0.7, -2.1])
    kinked = elastica_kinked_cantilever(F, lengths=(0.5, 0.5), kink_angle=0.0, n_output=6)
    straight = elastica_cantilever(F, n_output=11)  # s = 0, 0.1, ..., 1
    np.testing.assert_allclose(kinked.tip_position, straight.tip_position, atol=1e-10)
    assert float(kinked.tip_angle) == pytest.approx(float(straight.tip_angle), abs=1e-10)
    assert float(kinked.base_moment) == pytest.approx(float(straight.base_moment), abs=1e-10)
    pos, ref_pos = np.asarray(kinked.positions), np.asarray(straight.positions)
    np.testing.assert_allclose(pos[:6], ref_pos[:6], atol=1e-10)
    np.testing.assert_allclose(pos[6:], ref_pos[5:], atol=1e-10)
    np.testing.assert_allclose(kinked.s, np.r_[np.linspace(0, 0.5, 6), np.linspace(0.5, 1, 6)],
                               atol=1e-15)


def _kinked_linear_tip(F, L1, L2, kink, EI1, EI2):
    """Small-deflection tip displacement and rotation (unit-load method, base along +x)."""
    t0, t1 = np.array([1.0, 0.0]), np.array([np.cos(kink), np.sin(kink)])
    tip = L1 * t0 + L2 * t1
    x, w = np.polynomial.legendre.leggauss(8)
    u, rot = np.zeros(2), 0.0
    for start, t, L, EI in [(np.zeros(2), t0, L1, EI1), (L1 * t0, t1, L2, EI2)]:
        for xi, wi in zip(x, w):
            d = tip - (start + 0.5 * L * (xi + 1.0) * t)  # lever arm to the tip
            kappa = (d[0] * F[1] - d[1] * F[0]) / EI     # m(s) = (T - r) × F
            u += 0.5 * L * wi * kappa * np.array([-d[1], d[0]])  # δT = ∫ κ ẑ × (T - r)
            rot += 0.5 * L * wi * kappa
    return tip, u, rot


@pytest.mark.parametrize("kink, F", [(0.9, (0.3e-4, 1.0e-4)), (-2.0, (-1.0e-4, 0.2e-4))])
def test_kinked_small_load_matches_linear_beam_theory(kink, F):
    F, (L1, L2), (EI1, EI2) = np.asarray(F), (0.7, 1.3), (2.0, 0.5)
    sol = elastica_kinked_cantilever(F, lengths=(L1, L2), kink_angle=kink, EI=(EI1, EI2))
    tip0, u, rot = _kinked_linear_tip(F, L1, L2, kink, EI1, EI2)
    u_sol = np.asarray(sol.tip_position) - tip0
    assert np.linalg.norm(u_sol - u) <= 1e-3 * np.linalg.norm(u)
    assert float(sol.tip_angle) - kink == pytest.approx(rot, rel=1e-3)
    assert sol.converged and sol.end_moment_residual < 1e-12


@pytest.mark.parametrize("F", [(0.5, 2.0), (-6.0, 4.0)])
def test_kinked_corner_and_part_two_as_cantilever(F):
    # Continuity at the corner, and part 2 is itself a cantilever clamped at the corner.
    F, n, kink = np.asarray(F), 41, 1.1
    sol = elastica_kinked_cantilever(F, lengths=(0.7, 1.3), kink_angle=kink, EI=(2.0, 0.5),
                                     n_output=n)
    pos, ang, mom = (np.asarray(v) for v in (sol.positions, sol.angle, sol.moment))
    np.testing.assert_allclose(pos[n - 1], pos[n], atol=0)
    assert ang[n] - ang[n - 1] == pytest.approx(kink, abs=1e-14)
    assert mom[n] == mom[n - 1] and abs(mom[-1]) < 1e-9
    x, y = np.asarray(sol.tip_position)
    assert float(sol.base_moment) == pytest.approx(x * F[1] - y * F[0], abs=1e-9)
    part2 = elastica_cantilever(F, length=1.3, EI=0.5, base_angle=ang[n], n_output=n)
    np.testing.assert_allclose(pos[n:], pos[n] + np.asarray(part2.positions), atol=1e-9)
    assert float(part2.base_moment) == pytest.approx(mom[n], abs=1e-9)


@pytest.mark.parametrize("alpha", [0.4, -2.3])
def test_kinked_base_angle_rotates_solution(alpha):
    F, kw = np.array([1.5, -3.0]), {"lengths": (0.6, 0.9), "kink_angle": -0.8, "EI": (1.0, 1.7)}
    base = elastica_kinked_cantilever(F, **kw)
    rot = elastica_kinked_cantilever(_rot(alpha) @ F, base_angle=alpha, **kw)
    np.testing.assert_allclose(rot.positions, np.asarray(base.positions) @ _rot(alpha).T,
                               atol=1e-9)
    np.testing.assert_allclose(rot.angle, np.asarray(base.angle) + alpha, atol=1e-9)
    assert float(rot.base_moment) == pytest.approx(float(base.base_moment), abs=1e-9)


def test_kinked_large_load_ramp_matches_direct_solve_from_near_guess():
    F = 20.0 * np.array([0.3, 1.0]) / np.hypot(0.3, 1.0)  # |F| Lt²/min(EI) = 40
    kw = {"lengths": (0.7, 1.3), "kink_angle": 1.1, "EI": (2.0, 2.5)}
    sol = elastica_kinked_cantilever(F, **kw)  # load ramp with branch tracking
    assert sol.converged and sol.end_moment_residual < 1e-9
    x, y = np.asarray(sol.tip_position)
    assert float(sol.base_moment) == pytest.approx(x * F[1] - y * F[0], abs=1e-8)
    assert 0 < float(sol.tip_angle) - 1.1 < np.pi  # rotated towards the load
    direct = elastica_kinked_cantilever(F, base_moment_guess=float(sol.base_moment) + 0.05,
                                        **kw)  # no ramp: Newton from a nearby guess
    np.testing.assert_allclose(direct.positions, sol.positions, atol=1e-9)


@pytest.mark.parametrize("kwargs, match", [
    ({"lengths": (1.0, 0.0)}, "lengths must be positive"),
    ({"lengths": (1.0, 2.0, 3.0)}, "lengths must have shape"),
    ({"EI": (1.0, -1.0)}, "EI must be positive"),
    ({"EI": (1.0, 2.0, 3.0)}, "EI must have shape"),
    ({"kink_angle": np.nan}, "kink_angle must be finite"),
    ({"tip_force": (1.0,)}, "tip_force must have shape"),
    ({"n_output": 1}, "n_output must be an integer"),
])
def test_kinked_input_validation(kwargs, match):
    args = {"tip_force": (0.0, 1.0), "kink_angle": 0.5} | kwargs
    with pytest.raises(ValueError, match=match):
        elastica_kinked_cantilever(args.pop("tip_force"), **args)


# ------------------------------------------------------------ post-buckled columns
def _pp_closed_form(delta):
    """Pinned-pinned, L = EI = 1: Δ/L = 2(1 - E/K) -> (P = 4K², k) (scipy m = k²)."""
    k = brentq(lambda k: 2.0 * (1.0 - ellipe(k * k) / ellipk(k * k)) - delta, 1e-12,
               1.0 - 1e-12, xtol=1e-15, rtol=1e-15)
    return 4.0 * ellipk(k * k) ** 2, k


DELTAS = np.array([0.9, 1e-4, 0.05, 0.3, 1e-3, 0.6, 0.3])  # unsorted, with a duplicate


@pytest.mark.parametrize("supports, p_scale, l_scale", [
    (("pinned", "pinned"), 1.0, 1.0),    # P = 4K² EI/L²
    (("clamped", "clamped"), 4.0, 0.5),  # = pinned-pinned of length L/2
    (("clamped", "free"), 0.25, 2.0),    # = pinned-pinned of length 2L, same Δ/L
])
def test_column_force_matches_closed_form(supports, p_scale, l_scale):
    L, EI = 2.5, 0.8
    P = elastica_column_force(DELTAS * L, supports=supports, length=L, EI=EI)
    exact = np.array([p_scale * _pp_closed_form(d)[0] * EI / L**2 for d in DELTAS])
    assert P.shape == DELTAS.shape and P[3] == P[6]
    np.testing.assert_allclose(P, exact, rtol=1e-10)  # measured 2e-13


@pytest.mark.parametrize("supports, lam", [
    (("pinned", "pinned"), lambda K: 2 * K),
    (("clamped", "clamped"), lambda K: 4 * K),
    (("clamped", "free"), lambda K: K),
])
@pytest.mark.parametrize("delta", [0.02, 0.7])
def test_column_shape_matches_closed_form(supports, lam, delta):
    # Pendulum analogy (L = EI = 1): with u = λ s, λ = √P, sin(θ/2) = k sn(u) for
    # the clamped ends (θ(0) = 0), y = (2k/λ)(1 - cn(λ s)); pinned-pinned is the same
    # curve shifted by a quarter wave: y = (2k/λ) cn(K - λ s).
    (_, k), n = _pp_closed_form(delta), 41
    K = ellipk(k * k)
    sol = elastica_column_shape(delta, supports=supports, n_output=n)
    s, lmb = np.linspace(0.0, 1.0, n), lam(K)
    if supports[0] == "pinned":
        y = 2 * k / lmb * ellipj(K - lmb * s, k * k)[1]
    else:
        y = 2 * k / lmb * (1.0 - ellipj(lmb * s, k * k)[1])
    np.testing.assert_allclose(np.asarray(sol.positions)[:, 1], y, atol=1e-10)
    y_mid = 2 * k / lmb * (1.0 - ellipj(0.5 * lmb, k * k)[1])  # k/K unless clamped-free
    assert sol.midspan_deflection == pytest.approx(y_mid, abs=1e-10)
    assert sol.axial_force == pytest.approx(lmb**2, rel=1e-10)
    assert float(sol.positions[-1, 0]) == pytest.approx(1.0 - delta, abs=1e-10)
    assert sol.lateral_force == pytest.approx(0.0, abs=1e-7) and sol.residual < 1e-9
    np.testing.assert_allclose(np.asarray(sol.positions[0]), 0.0, atol=0)


def test_clamped_pinned_small_shortening_limit():
    # Euler load of the clamped-pinned column: P = x² EI/L² with tan x = x, x ≈ 4.4934.
    x = brentq(lambda x: np.tan(x) - x, 4.4, 4.6, xtol=1e-15)
    L, EI = 1.7, 2.3
    d = np.array([1e-5, 2e-5])
    P = elastica_column_force(d * L, supports=("clamped", "pinned"), length=L, EI=EI)
    P0 = 2 * P[0] - P[1]  # P = P_cr + c Δ + O(Δ²)
    assert P0 * L**2 / EI == pytest.approx(x**2, rel=1e-8)
    assert P0 * L**2 / EI == pytest.approx(20.1907, abs=1e-4)
    assert np.all(P > P0)  # the post-buckling path rises initially


def test_clamped_pinned_equals_mirrored_pinned_clamped():
    # Same column shot from the other end: equal P, mirrored shape, P → tensile late.
    d, n = np.array([0.01, 0.3, 0.6, 0.9]), 51
    cp = elastica_column_force(d, supports=("clamped", "pinned"))
    pc = elastica_column_force(d, supports=("pinned", "clamped"))
    np.testing.assert_allclose(cp, pc, rtol=1e-9, atol=1e-9)
    assert np.all(np.diff(cp[1:]) < 0) and cp[-1] < 0 < cp[-2]
    a = elastica_column_shape(0.6, supports=("clamped", "pinned"), n_output=n)
    b = elastica_column_shape(0.6, supports=("pinned", "clamped"), n_output=n)
    pa, pb = np.asarray(a.positions), np.asarray(b.positions)
    np.testing.assert_allclose(pb[::-1], np.c_[0.4 - pa[:, 0], pa[:, 1]], atol=1e-9)
    assert a.axial_force == pytest.approx(cp[2], rel=1e-10)
    # base moment balances the moment of the end force (-P, Q) applied at (L - Δ, 0)
    assert float(a.moment[0]) == pytest.approx(0.4 * a.lateral_force, rel=1e-9)
    assert float(a.moment[-1]) == pytest.approx(0.0, abs=1e-9)
    assert float(a.angle[0]) == 0.0 and abs(float(pa[-1, 1])) < 1e-10


def test_column_scaling_and_branch_independent_of_sampling():
    sup = ("clamped", "pinned")
    alone = elastica_column_force(0.9, supports=sup)
    dense = elastica_column_force(np.linspace(0.01, 0.9, 30), supports=sup)
    assert alone.shape == () and float(alone) == pytest.approx(dense[-1], rel=1e-10)
    scaled = elastica_column_force(0.9 * 3.0, supports=sup, length=3.0, EI=2.0)
    assert float(scaled) == pytest.approx(float(alone) * 2.0 / 9.0, rel=1e-10)


@pytest.mark.parametrize("kwargs, match", [
    ({"end_shortening": 0.0}, "0 < Δ < length"),
    ({"end_shortening": [0.1, 1.0]}, "0 < Δ < length"),
    ({"end_shortening": np.nan}, "0 < Δ < length"),
    ({"end_shortening": [[0.1]]}, "scalar or a non-empty 1-D"),
    ({"supports": ("pinned", "free")}, "mechanism"),
    ({"supports": ("free", "pinned")}, "supports must be"),
    ({"supports": "pinned"}, "supports must be a pair"),
    ({"length": -1.0}, "length must be positive"),
    ({"EI": 0.0}, "EI must be positive"),
])
def test_column_input_validation(kwargs, match):
    args = {"end_shortening": 0.1} | kwargs
    with pytest.raises(ValueError, match=match):
        elastica_column_force(args.pop("end_shortening"), **args)


def test_column_shape_input_validation():
    with pytest.raises(ValueError, match="must be a scalar here"):
        elastica_column_shape([0.1, 0.2])
    with pytest.raises(ValueError, match="n_output must be an integer"):
        elastica_column_shape(0.1, n_output=1)
