"""Frame-free geometry on the unit sphere of tangent directions (used by the 3D SOCB segment).

A 3D segment interpolates its tangent t(s) in the *log chart* centred at the segment's mean
tangent u (``sphere_log``/``sphere_exp``, the azimuthal-equidistant chart): w(s) = log_u t(s)
is a vector in the plane ⊥ u whose length is the angle between u and t(s).  The chart needs
no choice of axes (it commutes with every rotation), has no singularity for any direction in
space (±z included), and maps a planar curve through u to the straight line of its angle,
so the 3D interpolant reduces exactly to the planar quintic of Eq. 5.

All functions are smooth, with Taylor branches near zero angle so that ``jax.jacfwd`` of
them is finite for straight segments (the double-``where`` trick).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = [
    "powers_of",
    "sphere_log",
    "sphere_log_jet",
    "sphere_exp",
    "sphere_exp_differential_inverse",
    "rotation_vector",
    "orthonormal_complement",
    "minimal_rotation",
]

_SMALL = 1e-2  # squared-angle threshold below which Taylor series are used (error < 1e-16)

# Taylor coefficients in q = ρ² (computed with sympy; see module docstring).
_ATAN_OVER = tuple((-1.0) ** k / (2 * k + 1) for k in range(24))  # atan(ρ)/ρ in q = ρ²
_COS = (1.0, -1 / 2, 1 / 24, -1 / 720, 1 / 40320, -1 / 3628800, 1 / 479001600)
_SINC = (1.0, -1 / 6, 1 / 120, -1 / 5040, 1 / 362880, -1 / 39916800, 1 / 6227020800)
# h(ρ) = (ρ/sin ρ − 1/cos ρ)/ρ²
_H = (
    -1 / 3,
    -17 / 90,
    -125 / 1512,
    -2581 / 75600,
    -832319 / 59875200,
    -921964937 / 163459296000,
    -299012803 / 130767436800,
)


def powers_of(q: Array, n: int) -> Array:
    """[..., n] the powers q⁰ … q^(n−1), by log₂ n products of doubling blocks.  Not Horner's
    n dependent steps: these series are inlined into every residual, Jacobian and line search
    of a 3D solve, and Horner's unrolled steps were a quarter of its compiled program."""
    p, qk = jnp.ones_like(q)[..., None], q
    while p.shape[-1] < n:
        p = jnp.concatenate([p, p * qk[..., None]], axis=-1)
        qk = qk * qk
    return p[..., :n]


def _series(coeffs: tuple[float, ...], q: Array, powers: Array | None = None) -> Array:
    """Σ_k coeffs[k] q^k (``powers`` from :func:`powers_of`, at least len(coeffs) of them)."""
    powers = powers_of(q, len(coeffs)) if powers is None else powers[..., : len(coeffs)]
    return jnp.sum(powers * jnp.asarray(coeffs, dtype=powers.dtype), axis=-1)


def _even_function(q: Array, direct, coeffs: tuple[float, ...]) -> Array:
    """Evaluate an even function f(ρ) given q = ρ² ≥ 0, safely (and differentiably) at 0."""
    small = q < _SMALL
    q_safe = jnp.where(small, _SMALL, q)
    return jnp.where(small, _series(coeffs, q), direct(jnp.sqrt(q_safe)))


def _angle_over_sine(s_squared: Array, c: Array) -> Array:
    """atan2(s, c)/s for c > 0 given s² (the angle over its sine-length), smooth at s = 0."""
    return _even_function(s_squared / (c * c), lambda r: jnp.arctan2(r, 1.0) / r, _ATAN_OVER) / c  # atan2: Taylor-mode (jet) ready


def sphere_log(u: Float[Array, "3"], t: Float[Array, "3"]) -> Float[Array, "3"]:
    """Log map at the unit vector ``u`` of the direction of ``t`` (any non-zero length).

    Returns w ⊥ u with |w| = angle(u, t) and w ∥ (t − (u·t) u).  Homogeneous of degree 0
    in t.  Valid for angle(u, t) < 90°, which holds for both ends of a segment when u is
    the normalised sum of its end tangents.
    """
    c = jnp.dot(u, t)
    x = t - c * u
    return _angle_over_sine(jnp.dot(x, x), c) * x


def sphere_exp(u: Float[Array, "3"], w: Float[Array, "3"]) -> Float[Array, "3"]:
    """Exponential map at the unit vector ``u`` of w ⊥ u: cos|w| u + sin|w| w/|w|."""
    q = jnp.dot(w, w)
    cos = _even_function(q, jnp.cos, _COS)
    sinc = _even_function(q, lambda r: jnp.sin(r) / r, _SINC)
    return cos * u + sinc * w


def sphere_exp_differential_inverse(
    u: Float[Array, "3"], w: Float[Array, "3"], y: Float[Array, "3"]
) -> Float[Array, "3"]:
    """(D exp_u(w))⁻¹ y for a vector y tangent to the sphere at exp_u(w); result ⊥ u.

    With ρ = |w|, p = u × w: the radial direction is stretched by 1 and the transverse one
    by sin ρ/ρ, which gives  P_u y / cos ρ + h(ρ) (y·p) p  with h = (ρ/sin ρ − 1/cos ρ)/ρ².
    """
    q = jnp.dot(w, w)
    cos = _even_function(q, jnp.cos, _COS)
    h = _even_function(q, lambda r: (r / jnp.sin(r) - 1.0 / jnp.cos(r)) / (r * r), _H)
    p = jnp.cross(u, w)
    projected = y - jnp.dot(u, y) * u
    return projected / cos + h * jnp.dot(y, p) * p


def rotation_vector(a: Float[Array, "3"], b: Float[Array, "3"]) -> Float[Array, "3"]:
    """Rotation vector (angle × unit axis) of the smallest rotation taking direction a to b."""
    axb = jnp.cross(a, b)
    return _angle_over_sine(jnp.dot(axb, axb), jnp.dot(a, b)) * axb


def minimal_rotation(a: Array, b: Array, v: Array) -> Array:
    """The smallest rotation taking the unit vector a to the unit vector b (about a × b),
    applied to v (any leading batch shape, vectors on the last axis).  Singular only for
    b = −a."""
    ab = a + b
    dot = lambda x, y: jnp.sum(x * y, -1, keepdims=True)  # noqa: E731
    return v + 2.0 * dot(a, v) * b - dot(ab, v) / (1.0 + dot(a, b)) * ab


def orthonormal_complement(u: Float[Array, "3"]) -> Float[Array, "2 3"]:
    """Two orthonormal vectors spanning the plane ⊥ the unit vector u.

    Not smooth over the whole sphere (no such field exists); used only with values frozen
    for the duration of a Newton solve, where only the span matters.
    """
    axis = jnp.eye(3)[jnp.argmin(jnp.abs(u))]
    f = axis - jnp.dot(axis, u) * u
    f = f / jnp.linalg.norm(f)
    g = jnp.cross(u, f)
    return jnp.stack([f, g])


_JET_SMALL = 0.1  # q threshold for the series of G, G', G'' below (truncation < 1e-17)
_G = _ATAN_OVER  # atan(√q)/√q = Σ a_k q^k
_G1 = tuple(k * _G[k] for k in range(1, 24))
_G2 = tuple(k * (k - 1) * _G[k] for k in range(2, 24))


def _atan_ratio_and_derivatives(q: Array):
    """G(q) = atan(√q)/√q and its first two q-derivatives, smooth and accurate for q ≥ 0."""
    small = q < _JET_SMALL
    qs = jnp.where(small, _JET_SMALL, q)
    r = jnp.sqrt(qs)
    g = jnp.arctan(r) / r
    g1 = (1.0 / (1.0 + qs) - g) / (2.0 * qs)
    g2 = (-1.0 / (1.0 + qs) ** 2 - 3.0 * g1) / (2.0 * qs)
    table = powers_of(q, len(_G))
    return (
        jnp.where(small, _series(_G, q, table), g),
        jnp.where(small, _series(_G1, q, table), g1),
        jnp.where(small, _series(_G2, q, table), g2),
    )


def sphere_log_jet(u: Float[Array, "3"], t: Array, dt: Array, ddt: Array):
    """(w, w', w'') of w(s) = log_u t(s) from the jet (t, t', t'') of a curve t(s).

    Closed form of the first two derivatives of ``sphere_log`` along a curve (equal to
    nested forward-mode differentiation, but a much smaller program to compile).  With
    c = u·t, x = t − c u, q = |x|²/c² and G(q) = atan(√q)/√q:  w = g x with g = G(q)/c.
    """
    c, c1, c2 = jnp.dot(u, t), jnp.dot(u, dt), jnp.dot(u, ddt)
    x, x1, x2 = t - c * u, dt - c1 * u, ddt - c2 * u
    X, X1, X2 = jnp.dot(x, x), 2.0 * jnp.dot(x, x1), 2.0 * (jnp.dot(x1, x1) + jnp.dot(x, x2))
    q = X / c**2
    q1 = X1 / c**2 - 2.0 * X * c1 / c**3
    q2 = X2 / c**2 - 4.0 * X1 * c1 / c**3 - 2.0 * X * c2 / c**3 + 6.0 * X * c1**2 / c**4
    G, G1, G2 = _atan_ratio_and_derivatives(q)
    g = G / c
    g1 = G1 * q1 / c - G * c1 / c**2
    g2 = G2 * q1**2 / c + G1 * q2 / c - 2.0 * G1 * q1 * c1 / c**2 - G * c2 / c**2 + 2.0 * G * c1**2 / c**3
    return g * x, g1 * x + g * x1, g2 * x + 2.0 * g1 * x1 + g * x2
