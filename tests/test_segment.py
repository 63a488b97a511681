"""One segment's equations (Eqs 5–9): exact cases, and the 3D kernel against the planar one."""

import jax.numpy as jnp
import numpy as np
import pytest

from socbjax._quadrature import get_quadrature
from socbjax._segment import planar_segment_residual, spatial_segment_residual

QUAD = get_quadrature(8)


@pytest.mark.parametrize("curvature", [0.0, 0.3, 2.0])
def test_planar_circular_arc_is_exact(curvature):
    """Pure bending (n = 0) makes a circular arc: θ linear, m = EI κ constant."""
    EI, l, theta_a = 0.071, 0.5, 0.4
    theta_b = theta_a + curvature * l
    r_a = jnp.array([0.2, -0.1])
    if curvature:
        chord = np.array([np.sin(theta_b) - np.sin(theta_a), np.cos(theta_a) - np.cos(theta_b)]) / curvature
    else:
        chord = l * np.array([np.cos(theta_a), np.sin(theta_a)])
    m = EI * curvature
    res = planar_segment_residual(r_a, theta_a, m, r_a + chord, theta_b, m, jnp.zeros(2), l, EI, QUAD)
    np.testing.assert_allclose(res, 0.0, atol=1e-13)


def test_planar_straight_segment_under_axial_force():
    theta = 0.9
    t = np.array([np.cos(theta), np.sin(theta)])
    res = planar_segment_residual(jnp.zeros(2), theta, 0.0, jnp.asarray(1.3 * t), theta, 0.0, jnp.asarray(-4.0 * t), 1.3, 2.0, QUAD)
    np.testing.assert_allclose(res, 0.0, atol=1e-14)


def test_planar_residual_detects_wrong_chord():
    res = planar_segment_residual(jnp.zeros(2), 0.0, 0.0, jnp.array([0.9, 0.0]), 0.0, 0.0, jnp.zeros(2), 1.0, 1.0, QUAD)
    assert abs(float(res[0]) + 0.1) < 1e-14


def _planar_data(rng):
    return dict(
        r_a=rng.normal(size=2),
        theta_a=rng.uniform(-3, 3),
        m_a=rng.normal(),
        r_b=rng.normal(size=2),
        m_b=rng.normal(),
        n=rng.normal(size=2),
        length=rng.uniform(0.3, 1.0),
        EI=rng.uniform(0.5, 2.0),
    )


def test_spatial_kernel_reduces_to_planar_kernel(rng):
    """For data in a plane the 3D equations are exactly the planar Eqs 7–9."""
    for _ in range(5):
        d = _planar_data(rng)
        theta_b = d["theta_a"] + rng.uniform(-0.8, 0.8)
        planar = planar_segment_residual(
            d["r_a"], d["theta_a"], d["m_a"], d["r_b"], theta_b, d["m_b"], d["n"], d["length"], d["EI"], QUAD
        )

        def lift(v):
            return np.array([v[0], v[1], 0.0])

        def tangent(th):
            return np.array([np.cos(th), np.sin(th), 0.0])

        ez = np.array([0.0, 0.0, 1.0])
        u = tangent(d["theta_a"]) + tangent(theta_b)
        u /= np.linalg.norm(u)
        frame = jnp.asarray(np.stack([ez, np.cross(ez, u)]))
        spatial = spatial_segment_residual(
            lift(d["r_a"]), tangent(d["theta_a"]), d["m_a"] * ez, lift(d["r_b"]), tangent(theta_b), d["m_b"] * ez,
            lift(d["n"]), d["length"], d["EI"], frame, QUAD,
        )
        np.testing.assert_allclose(np.asarray(spatial)[[0, 1, 3, 6]], planar, rtol=1e-11, atol=1e-11)
        np.testing.assert_allclose(np.asarray(spatial)[[2, 4, 5]], 0.0, atol=1e-12)


def _spatial_data(rng):
    def unit(v):
        return v / np.linalg.norm(v)

    t_a = unit(rng.normal(size=3))
    t_b = unit(t_a + 0.5 * rng.normal(size=3))
    m_a = np.cross(t_a, rng.normal(size=3))
    m_b = np.cross(t_b, rng.normal(size=3))
    return [rng.normal(size=3), t_a, m_a, rng.normal(size=3), t_b, m_b, rng.normal(size=3)]


def test_spatial_kernel_is_rotation_equivariant(rng):
    from conftest import random_rotation

    data = _spatial_data(rng)
    u = data[1] + data[4]
    u /= np.linalg.norm(u)
    frame = np.linalg.qr(np.stack([u, rng.normal(size=3), rng.normal(size=3)], 1))[0][:, 1:].T
    base = spatial_segment_residual(*data, 0.6, 1.3, jnp.asarray(frame), QUAD)
    R = random_rotation(rng)
    rotated = spatial_segment_residual(*[R @ v for v in data], 0.6, 1.3, jnp.asarray(frame @ R.T), QUAD)
    np.testing.assert_allclose(rotated[:3], R @ np.asarray(base[:3]), atol=1e-12)
    np.testing.assert_allclose(rotated[3:], base[3:], atol=1e-12)


def test_spatial_solution_set_does_not_depend_on_frame(rng):
    """The analysis frame only picks combinations of the ⊥u components."""
    data = _spatial_data(rng)
    u = data[1] + data[4]
    u /= np.linalg.norm(u)
    q = np.linalg.qr(np.stack([u, rng.normal(size=3), rng.normal(size=3)], 1))[0]
    frame1 = q[:, 1:].T
    angle = 0.7
    rot = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])
    frame2 = rot @ frame1
    r1 = spatial_segment_residual(*data, 0.6, 1.3, jnp.asarray(frame1), QUAD)
    r2 = spatial_segment_residual(*data, 0.6, 1.3, jnp.asarray(frame2), QUAD)
    np.testing.assert_allclose(r2[3:5], rot @ np.asarray(r1[3:5]), atol=1e-12)
    np.testing.assert_allclose(r2[5:7], rot @ np.asarray(r1[5:7]), atol=1e-12)
