"""Frame-free sphere maps used by the 3D segment."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from socbjax._geometry import rotation_vector, sphere_exp, sphere_exp_differential_inverse, sphere_log


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 0.05, 0.3, 1.2])
def test_exp_log_are_inverse(angle, rng):
    u = _unit(rng.normal(size=3))
    p = _unit(np.cross(u, rng.normal(size=3)))
    w = angle * p
    t = sphere_exp(jnp.asarray(u), jnp.asarray(w))
    assert np.isclose(float(jnp.linalg.norm(t)), 1.0, atol=1e-15)
    assert np.isclose(float(jnp.dot(t, u)), np.cos(angle), atol=1e-15)
    np.testing.assert_allclose(sphere_log(jnp.asarray(u), t), w, atol=1e-14)


def test_log_is_scale_invariant(rng):
    u = _unit(rng.normal(size=3))
    t = _unit(u + 0.4 * rng.normal(size=3))
    np.testing.assert_allclose(sphere_log(u, 3.7 * t), sphere_log(u, t), atol=1e-14)


@pytest.mark.parametrize("angle", [0.0, 1e-3, 0.5])
def test_exp_differential_inverse_matches_autodiff(angle, rng):
    u = jnp.asarray(_unit(rng.normal(size=3)))
    basis = np.linalg.qr(np.stack([np.asarray(u), rng.normal(size=3), rng.normal(size=3)], 1))[0][:, 1:]
    w = angle * basis[:, 0] + 0.3 * angle * basis[:, 1]
    # D exp restricted to the tangent plane, as a 3×2 map on plane coordinates
    dexp = jax.jacfwd(lambda c: sphere_exp(u, jnp.asarray(basis) @ c))(jnp.asarray(basis.T @ w))
    y = dexp @ jnp.asarray([0.7, -1.1])
    back = sphere_exp_differential_inverse(u, jnp.asarray(w), y)
    np.testing.assert_allclose(back, basis @ np.array([0.7, -1.1]), atol=1e-12)


def test_jacobians_finite_at_zero_angle():
    u = jnp.array([0.0, 0.0, 1.0])  # along z: no pole anywhere
    for fn in (lambda t: sphere_log(u, t), lambda w: sphere_exp(u, w)):
        x = u if fn.__code__.co_varnames[0] == "t" else jnp.zeros(3)
        jac = jax.jacfwd(jax.jacfwd(fn))(x)
        assert np.all(np.isfinite(np.asarray(jac)))


def test_rotation_vector_angle_and_axis(rng):
    a = _unit(rng.normal(size=3))
    axis = _unit(np.cross(a, rng.normal(size=3)))
    angle = 0.8
    b = np.cos(angle) * a + np.sin(angle) * np.cross(axis, a)
    np.testing.assert_allclose(rotation_vector(jnp.asarray(a), jnp.asarray(b)), angle * axis, atol=1e-14)


@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.01, 0.31, 0.33, 0.9])
def test_log_jet_closed_form_equals_nested_forward_mode(angle, rng):
    from socbjax._geometry import sphere_log_jet

    u = _unit(rng.normal(size=3))
    p = _unit(np.cross(u, rng.normal(size=3)))
    t = np.cos(angle) * u + np.sin(angle) * p
    dt, ddt = np.cross(rng.normal(size=3), t), rng.normal(size=3)

    def curve(eps):
        return sphere_log(jnp.asarray(u), jnp.asarray(t + eps * dt + 0.5 * eps**2 * ddt))

    def first(eps):
        return jax.jvp(curve, (eps,), (1.0,))

    (w, dw), (_, ddw) = jax.jvp(first, (0.0,), (1.0,))
    closed = sphere_log_jet(jnp.asarray(u), jnp.asarray(t), jnp.asarray(dt), jnp.asarray(ddt))
    for a, b in zip(closed, (w, dw, ddw)):
        np.testing.assert_allclose(a, b, atol=1e-13)
