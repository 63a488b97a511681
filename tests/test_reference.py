"""Tests of the shooting reference solver for the planar elastica."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import socbjax._reference as ref  # noqa: E402
from socbjax._reference import (  # noqa: E402
    elastica_cantilever,
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


@pytest.mark.parametrize("force_fallback", [False, True])
def test_bracketing_fallback_finds_same_solution(monkeypatch, force_fallback):
    # At PL²/EI = 10, m(L) is non-monotone in m(0) and Newton from 6.0 leaves its basin;
    # the scan + bisection fallback must return the (unique) root. Forcing Newton to
    # report failure makes sure the fallback itself is exercised.
    default = elastica_cantilever((0.0, 10.0))
    if force_fallback:
        newton = ref._newton_jit
        monkeypatch.setattr(ref, "_newton_jit", lambda *a: (newton(*a)[0], False))
    sol = elastica_cantilever((0.0, 10.0), base_moment_guess=6.0)
    np.testing.assert_allclose(sol.tip_position, default.tip_position, atol=1e-9)
    assert sol.end_moment_residual < 1e-10


def test_unconverged_solution_is_never_silent(monkeypatch):
    monkeypatch.setattr(ref, "_solve_base_moment", lambda *a, **k: 0.5)
    with pytest.raises(RuntimeError, match=r"tip_force=\[0.0, 2.0\].*\|m\(L\)\|"):
        elastica_cantilever((0.0, 2.0))
    sol = elastica_cantilever((0.0, 2.0), raise_on_failure=False)
    assert not sol.converged and sol.end_moment_residual > 1e-3


@pytest.mark.parametrize("kwargs, match", [
    (dict(tip_force=(1.0, 2.0, 3.0)), "tip_force must have shape"),
    (dict(tip_force=(np.nan, 1.0)), "tip_force must be finite"),
    (dict(tip_force=(0.0, 1.0), length=0.0), "length must be positive"),
    (dict(tip_force=(0.0, 1.0), EI=-1.0), "EI must be positive"),
    (dict(tip_force=(0.0, 1.0), EI=np.inf), "EI must be finite"),
    (dict(tip_force=(0.0, 1.0), n_output=1), "n_output must be an integer"),
    (dict(tip_force=(0.0, 1.0), n_output=10.0), "n_output must be an integer"),
    (dict(tip_force=(0.0, 1.0), tol=0.0), "tol must be positive"),
    (dict(tip_force=(0.0, 1.0), base_angle=(0.0, 1.0)), "base_angle must have shape"),
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
