"""3D SOCB: Y- versus Z-loading symmetry, any filament direction (±z included), and rigid
motions (property-based, hypothesis)."""

import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import socbjax as sj
from conftest import random_rotation

N = 5  # one compiled shape for the whole module


@functools.lru_cache(maxsize=None)
def planar_solution(load: float) -> np.ndarray:
    """Tip displacement (ΔX, ΔY) of the 2D cantilever under a perpendicular tip load."""
    sol = sj.solve(sj.cantilever(N, dim=2), {-1: [0.0, load]})
    return np.asarray(sol.positions) - np.asarray(sj.cantilever(N, dim=2).positions)



@pytest.mark.parametrize("psi_deg", [0.0, 37.0, 90.0, 180.0, 251.0])
def test_perpendicular_load_in_any_plane_gives_the_planar_solution(psi_deg):
    psi = np.radians(psi_deg)
    load = 2.0
    e = np.array([0.0, np.cos(psi), np.sin(psi)])
    sol = sj.solve(sj.cantilever(N, dim=3), {-1: load * e})
    planar = planar_solution(load)
    expected = planar[:, :1] * np.array([1.0, 0.0, 0.0]) + planar[:, 1:2] * e
    displacement = np.asarray(sol.positions) - np.asarray(sj.cantilever(N, dim=3).positions)
    np.testing.assert_allclose(displacement, expected, atol=1e-10)
    # and the moment vector is normal to that plane
    normal = np.cross([1.0, 0.0, 0.0], e)
    m = np.asarray(sol.moments)
    np.testing.assert_allclose(m - (m @ normal)[:, None] * normal, 0.0, atol=1e-10)


@pytest.mark.parametrize(
    "direction", [(0, 0, 1), (0, 0, -1), (0, 1, 0), (1, 1, 1), (-0.3, 0.2, 0.93)], ids=["+z", "-z", "+y", "diag", "oblique"]
)
def test_filament_along_any_direction_solves_equally_well(direction):
    from socbjax.testing import elastica_cantilever

    axis = np.asarray(direction, float) / np.linalg.norm(direction)
    lateral = np.cross(axis, [0.3, -0.5, 0.8])
    lateral /= np.linalg.norm(lateral)
    net = sj.cantilever(N, dim=3, direction=axis)
    sol = sj.solve(net, {-1: 2.0 * lateral})
    tip = np.asarray(sol.positions[-1])
    exact = np.asarray(elastica_cantilever((0.0, 2.0)).tip_position)  # (along axis, along load)
    expected = exact[0] * axis + exact[1] * lateral
    assert np.linalg.norm(tip - expected) / np.linalg.norm(expected - axis) < 1e-5


def test_out_of_plane_load_on_inclined_filament_matches_rotated_planar():
    """Coupled in-plane/out-plane loading (paper SI 4): load with both y and z components."""
    load = np.array([0.0, 1.2, -0.9])
    sol = sj.solve(sj.cantilever(N, dim=3), {-1: load})
    planar = planar_solution(float(np.linalg.norm(load)))
    e = load / np.linalg.norm(load)
    np.testing.assert_allclose(np.asarray(sol.positions[-1]), [1.0 + planar[-1, 0], 0, 0] + planar[-1, 1] * e, atol=1e-10)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31 - 1),
    load=st.floats(0.2, 6.0),
    axial=st.floats(-0.5, 0.5),
    shift=st.tuples(*[st.floats(-5.0, 5.0)] * 3),
)
def test_rigid_rotation_and_translation_of_the_whole_problem(seed, load, axial, shift):
    """Rotating and translating the whole problem rotates and translates the solution."""
    rng = np.random.default_rng(seed)
    R = random_rotation(rng)
    force = np.array([axial, load * 0.6, load * 0.8])
    base = sj.solve(sj.cantilever(N, dim=3), {-1: force})
    moved = sj.solve(sj.cantilever(N, dim=3, direction=R[:, 0], origin=shift), {-1: R @ force})
    np.testing.assert_allclose(np.asarray(moved.positions), np.asarray(base.positions) @ R.T + np.asarray(shift), atol=1e-9)
    np.testing.assert_allclose(np.asarray(moved.moments), np.asarray(base.moments) @ R.T, atol=1e-9)
    np.testing.assert_allclose(np.asarray(moved.segment_forces), np.asarray(base.segment_forces) @ R.T, atol=1e-9)


def test_three_dimensional_post_buckling_picks_the_imperfection_plane():
    P = 1.1 * np.pi**2 / 4
    e = np.array([0.0, np.cos(0.4), np.sin(0.4)])
    sol = sj.solve(sj.column(N, dim=3), {-1: np.array([-P, 0, 0]) + 1e-3 * P * e})
    sol2 = sj.solve(sj.column(N, dim=2), {-1: [-P, 1e-3 * P]})
    tip2 = np.asarray(sol2.positions[-1])
    np.testing.assert_allclose(np.asarray(sol.positions[-1]), [tip2[0], 0, 0] + tip2[1] * e, atol=1e-9)
