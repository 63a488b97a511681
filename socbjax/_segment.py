"""Equations of one SOCB segment (paper Eqs 5–9), written for a single segment.

The network residual lifts these with ``jax.vmap`` over segments.  Conventions: arc length
s runs from the segment's start node a (s = 0) to its end node b (s = l).  ``n`` is the
internal force in the segment (pN), constant along it (no distributed load): the force that
the material beyond s exerts on the material before s.  ``m`` is the bending moment (pN·µm),
m = EI θ' in the plane, m = EI t × t' in space; statics m' + t × n = 0.

Planar segment (unknowns at each end: angle θ and moment m):

* Eq. 2 coupling at each end:  EI θ''(end) = −(t × n)  (θ'' jumps at a point load, so it
  belongs to the segment end, not to the node).
* Eqs 5, 6a: quintic θ(s) from the Hermite data (θ, m/EI, θ'') at both ends.
* Eq. 7:  r_b − r_a = ∫_0^l t(θ(s)) ds  (Gauss–Legendre).
* Eq. 8:  m_b − m_a = −(r_b − r_a) × n  (chord projections are the moment arms).
* Eq. 9:  EI (θ_b − θ_a) = ∫_0^l m ds = m_a l − [∫_0^l (l − s) t ds] × n  (exact integral
  form; the printed Eq. 9 lacks 1/EI and the m_a l term and integrates over the chord).
* Natural curvature κ₀ (1/µm, constant per segment; a circular arc at rest): the bending law
  becomes m = EI (θ' − κ₀), so the end slopes are θ' = m/EI + κ₀ and Eq. 9 gains EI κ₀ l;
  θ'' = m'/EI is unchanged.  κ₀ = 0 is the paper's naturally straight segment.
* The segment's turn θ_b − θ_a is taken in (−π, π] (angles are unwrapped against the start):
  a segment never turns by half a circle, and the angles at a node may differ by 2π between
  the segments that meet there (a ring or a long arc built from unwrapped tangent angles).

Spatial segment (unknowns at each end: unit tangent t and moment vector m ⊥ t):

* End jets: t' = (m × t)/EI, and from (EI t'' + n) ∥ t with t·t'' = −|t'|²:
  EI t'' = (n·t) t − n − EI |t'|² t.
* The tangent is interpolated in the log chart at u = (t_a + t_b)/|t_a + t_b|
  (see :mod:`socbjax._geometry`; the end jets (w, w', w'') follow from (t, t', t'') by the
  closed-form chain rule of ``sphere_log_jet``): w(s) = log_u t(s) is a quintic Hermite polynomial with
  vector coefficients (Eqs 5, 6a applied component-wise in the plane ⊥ u), and
  t(s) = exp_u w(s).  This replaces the paper's spherical angles in a rotated analysis
  frame: it needs no frame, has no pole, and reduces exactly to the planar quintic when the
  segment bends in any single plane.
* Eq. 7:  r_b − r_a = ∫ t ds  (3 components).
* Eq. 8:  P_u [m_b − m_a + (r_b − r_a) × n] = 0  (2 components; the dropped u-component
  is the twist balance, which a torsion-free rod does not carry).
* Eq. 9:  EI (w_b − w_a) = ∫_0^l (D exp_u w)⁻¹ [m(s) × t(s)] ds  (2 components, ⊥ u),
  with m(s) = m_a − (r(s) − r_a) × n.  This is the exact integral of t' = m × t / EI in the
  chart, and for planar bending it is literally the planar Eq. 9 above.

Both kernels return dimensionless residuals: Eq. 7 divided by l, Eq. 8 by EI/l, Eq. 9 by EI.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._geometry import minimal_rotation, orthonormal_complement, sphere_exp, sphere_exp_differential_inverse, sphere_log_jet
from ._quadrature import SegmentQuadrature

__all__ = ["chart_data", "end_jet", "kirchhoff_jet", "frame_angle", "kirchhoff_segment_curve", "planar_turn", "turned_director", "twist_rows", "planar_segment_residual", "spatial_segment_residual", "spatial_segment_tangents", "planar_segment_angles",
           "planar_segment_curve", "spatial_segment_curve"]


def _cross2(a: Array, b: Array) -> Array:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def planar_turn(theta_a, theta_b):
    """θ_b − θ_a in (−π, π] (rad): the turn of one segment, whatever multiple of 2π lies
    between the two angles."""
    d = theta_b - theta_a
    return jnp.arctan2(jnp.sin(d), jnp.cos(d))


def planar_segment_angles(theta_a, m_a, theta_b, m_b, n, length, EI, basis, kappa0=0.0) -> Float[Array, " K"]:
    """θ at the points tabulated by ``basis`` ([K, 6] Hermite basis) from the end data;
    ``kappa0``: the segment's natural curvature (1/µm)."""
    theta_b = theta_a + planar_turn(theta_a, theta_b)
    t_a = jnp.stack([jnp.cos(theta_a), jnp.sin(theta_a)])
    t_b = jnp.stack([jnp.cos(theta_b), jnp.sin(theta_b)])
    curv2_a = -_cross2(t_a, n) / EI
    curv2_b = -_cross2(t_b, n) / EI
    data = jnp.stack([theta_a, length * (m_a / EI + kappa0), length**2 * curv2_a,
                      theta_b, length * (m_b / EI + kappa0), length**2 * curv2_b])
    return basis @ data


def planar_segment_curve(theta_a, m_a, theta_b, m_b, n, length, EI, basis, dbasis, kappa0=0.0):
    """(θ [K], dθ/ds [K] in 1/µm) at the points tabulated by ``basis`` and its σ-derivative
    ``dbasis`` ([K, 6] each): the segment's quintic and its curvature."""
    return (planar_segment_angles(theta_a, m_a, theta_b, m_b, n, length, EI, basis, kappa0),
            planar_segment_angles(theta_a, m_a, theta_b, m_b, n, length, EI, dbasis, kappa0) / length)


def planar_segment_residual(
    r_a: Float[Array, "2"],
    theta_a: Float[Array, ""],
    m_a: Float[Array, ""],
    r_b: Float[Array, "2"],
    theta_b: Float[Array, ""],
    m_b: Float[Array, ""],
    n: Float[Array, "2"],
    length: Float[Array, ""],
    EI: Float[Array, ""],
    quad: SegmentQuadrature,
    kappa0: Float[Array, ""] = 0.0,
) -> Float[Array, "4"]:
    """Residuals (Eq. 7 x, Eq. 7 y, Eq. 8, Eq. 9) of one planar segment, dimensionless;
    ``kappa0``: natural curvature (1/µm)."""
    theta = planar_segment_angles(theta_a, m_a, theta_b, m_b, n, length, EI, quad.basis, kappa0)
    t = jnp.stack([jnp.cos(theta), jnp.sin(theta)], axis=-1)  # [K, 2]
    w = jnp.asarray(quad.weights)
    sigma = jnp.asarray(quad.points)
    chord = r_b - r_a
    length_eq = (chord - length * (w @ t)) / length
    moment_eq = (m_b - m_a + _cross2(chord, n)) * length / EI
    lever = length**2 * ((w * (1.0 - sigma)) @ t)  # ∫_0^l (l − s) t ds = ∫_0^l (r(s) − r_a) ds
    bending_eq = (EI * (planar_turn(theta_a, theta_b) - kappa0 * length) - (m_a * length - _cross2(lever, n))) / EI
    return jnp.concatenate([length_eq, moment_eq[None], bending_eq[None]])


def end_jet(t, m, n, EI):
    """(unit t, t' 1/µm, t'' 1/µm²) at a segment end of a torsion-free rod under the internal
    force n (pN) with moment m (pN·µm)."""
    t = t / jnp.linalg.norm(t)
    dt = jnp.cross(m, t) / EI
    ddt = (jnp.dot(n, t) * t - n) / EI - jnp.dot(dt, dt) * t
    return t, dt, ddt


def _spatial_interpolant(t_a, m_a, t_b, m_b, n, length, EI, basis):
    """Mean tangent u, chart data w_a, w_b and the chart coordinates w at the basis points."""
    u, w_a, w_b, data = chart_data(end_jet(t_a, m_a, n, EI), end_jet(t_b, m_b, n, EI), length)
    return u, w_a, w_b, basis @ data


def chart_data(jet_a, jet_b, length):
    """(u, w_a, w_b, Hermite data [6, 3]) of the log-chart quintic from the end jets (t, t', t'')."""
    (t_a, dt_a, ddt_a), (t_b, dt_b, ddt_b) = jet_a, jet_b
    u = t_a + t_b
    u = u / jnp.linalg.norm(u)
    w_a, dw_a, ddw_a = sphere_log_jet(u, t_a, dt_a, ddt_a)
    w_b, dw_b, ddw_b = sphere_log_jet(u, t_b, dt_b, ddt_b)
    data = jnp.stack([w_a, length * dw_a, length**2 * ddw_a, w_b, length * dw_b, length**2 * ddw_b])
    return u, w_a, w_b, data


def spatial_segment_tangents(t_a, m_a, t_b, m_b, n, length, EI, basis) -> Float[Array, "K 3"]:
    """Unit tangents at the points tabulated by ``basis`` from the end data."""
    u, _, _, w = _spatial_interpolant(t_a, m_a, t_b, m_b, n, length, EI, basis)
    return jax.vmap(sphere_exp, in_axes=(None, 0))(u, w)


def spatial_segment_curve(t_a, m_a, t_b, m_b, n, length, EI, basis, dbasis):
    """(t [K, 3], dt/ds [K, 3] in 1/µm): unit tangents of the interpolant and their arc-length
    derivative, t' = D exp_u(w) w', at the points of ``basis`` / ``dbasis``."""
    u, _, _, w = _spatial_interpolant(t_a, m_a, t_b, m_b, n, length, EI, basis)
    _, _, _, dw = _spatial_interpolant(t_a, m_a, t_b, m_b, n, length, EI, dbasis)
    return _chart_tangents(u, w, dw / length)


def _chart_tangents(u, w, dw):
    """(t [K, 3], t' [K, 3]) = (exp_u w, D exp_u(w) w') at chart points w with rates w'."""
    return jax.vmap(lambda wk, dwk: jax.jvp(lambda z: sphere_exp(u, z), (wk,), (dwk,)))(w, dw)


def _kirchhoff_interpolant(t_a, m_a, t_b, m_b, n, length, EI, basis, dbasis, twist):
    """(u, w_a, w_b, w, t, t', unit t_a, unit t_b) of a twisting segment's chart quintic,
    from end jets that carry the natural curvature on the material frame."""
    psi_a, psi_b, e_a, e_b, GJ, kappa0 = twist
    jet_a = kirchhoff_jet(t_a, e_a, psi_a, m_a, n, EI, GJ, kappa0)
    jet_b = kirchhoff_jet(t_b, e_b, psi_b, m_b, n, EI, GJ, kappa0)
    u, w_a, w_b, data = chart_data(jet_a, jet_b, length)
    w = basis @ data
    t, dt = _chart_tangents(u, w, dbasis @ data / length)
    return u, w_a, w_b, w, t, dt, jet_a[0], jet_b[0]


def kirchhoff_segment_curve(t_a, m_a, t_b, m_b, n, length, EI, basis, dbasis, twist):
    """(t [K, 3], dt/ds [K, 3]) of a twisting segment's interpolant (end jets with the
    natural curvature on the material frame; ``twist`` as for
    :func:`spatial_segment_residual`)."""
    return _kirchhoff_interpolant(t_a, m_a, t_b, m_b, n, length, EI, basis, dbasis, twist)[4:6]


def frame_angle(t, e, d):
    """Angle (rad) about the unit vector t from e to d (both ⊥ t)."""
    return jnp.arctan2(jnp.dot(jnp.cross(e, d), t), jnp.dot(e, d))


def turned_director(t, e, angle):
    """e (⊥ the unit t) turned about t by ``angle`` (rad): cos·e + sin·(t × e); batched on
    the leading axes."""
    angle = jnp.asarray(angle)[..., None]
    return jnp.cos(angle) * e + jnp.sin(angle) * jnp.cross(t, e)


def kirchhoff_jet(t, e, psi, m, n, EI, GJ, kappa0):
    """End jet (t, t', t'') of a Kirchhoff rod and its material directors: t' = (m/EI + k) × t
    with the natural curvature vector k = κ₁ d1 + κ₂ d2, and t'' from m' = −t × n and
    k' = Ω × k (Ω = t × t' + τ t, τ = m·t/GJ + τ₀)."""
    t = t / jnp.linalg.norm(t)
    d1 = turned_director(t, e, psi)
    k = kappa0[0] * d1 + kappa0[1] * jnp.cross(t, d1)
    curv = m / EI + k
    dt = jnp.cross(curv, t)
    omega = jnp.cross(t, dt) + (jnp.dot(m, t) / GJ + kappa0[2]) * t
    ddt = jnp.cross(-jnp.cross(t, n) / EI + jnp.cross(omega, k), t) + jnp.cross(curv, dt)
    return t, dt, ddt


def _kirchhoff_rows(r_a, t_a, m_a, r_b, t_b, m_b, n, length, EI, frame, quad, twist):
    """The nine rows of a twisting segment (see :func:`spatial_segment_residual`).

    The material frame is followed along the segment: with E(s) the frame carried from a
    fixed f ⊥ u to t(s) by the smallest rotation (twist rate about t:
    ω = −u·(t × t')/(1 + u·t)), the material angle φ relative to E obeys φ' = τ − ω with
    τ = m·t/GJ + τ₀, and φ = ψ + α at a node whose frame is ψ from its reference director e
    (α: the angle from E to e).  The twist law is ψ_b + α_b − ψ_a − α_a + ∫ω ds = ∫τ ds
    (mod 2π); φ at the quadrature points places the natural curvature vector there, which
    enters Eq. 9 as EI t' = (m + EI k) × t."""
    psi_a, kappa0 = twist[0], twist[5]
    u, w_a, w_b, w, t, dt, ta, tb = _kirchhoff_interpolant(t_a, m_a, t_b, m_b, n, length, EI, jnp.asarray(quad.basis),
                                                           jnp.asarray(quad.dbasis), twist)
    weights, chord = jnp.asarray(quad.weights), r_b - r_a

    def perp(v):
        return frame @ (v - jnp.dot(u, v) * u)

    offsets = length * (jnp.asarray(quad.integration) @ t)  # r(s_k) − r_a, [K, 3]
    m = m_a[None, :] - jnp.cross(offsets, n[None, :])
    balance = m_b - m_a + jnp.cross(chord, n)
    twist_eq, (f, alpha_a, omega, tau) = twist_rows(u, t, dt, m, weights, ta, tb, twist, balance, length, EI)
    E = minimal_rotation(u, t, f)  # [K, 3]: the frames that α_a and ω refer to
    phi = psi_a + alpha_a + length * (jnp.asarray(quad.integration) @ (tau - omega))
    d1 = turned_director(t, E, phi)
    k = kappa0[0] * d1 + kappa0[1] * jnp.cross(t, d1)
    rates = jax.vmap(sphere_exp_differential_inverse, in_axes=(None, 0, 0))(u, w, jnp.cross(m + EI * k, t))
    return jnp.concatenate([
        (chord - length * (weights @ t)) / length,
        perp(balance) * length / EI,
        perp(EI * (w_b - w_a) - length * (weights @ rates)) / EI,
        twist_eq,
    ])


def twist_rows(u, t, dt, m, weights, t_a, t_b, twist, balance, length, EI):
    """The two rows of a twisting segment (Eq. 8 about u, the twist law; see
    :func:`_kirchhoff_rows`) from its unit tangents t and their derivatives t' [K, 3]
    (1/µm) and moments m [K, 3] (pN·µm) at stations of quadrature weights [K] (σ-units), the
    end tangents, ``twist`` (ψ_a, ψ_b, e_a, e_b, GJ, κ₀) and the moment balance [3] (pN·µm);
    with (f, α_a, ω [K], τ [K]) for the material angle along the segment (f ⊥ u: the
    vector the minimal-rotation frames start from).  The contact kernel's
    composite quadrature calls it too."""
    psi_a, psi_b, e_a, e_b, GJ, kappa0 = twist
    f = orthonormal_complement(u)[0]  # any f ⊥ u: nothing depends on it
    alpha_a = frame_angle(t_a, minimal_rotation(u, t_a, f), e_a)
    alpha_b = frame_angle(t_b, minimal_rotation(u, t_b, f), e_b)
    omega = -jnp.einsum("i,ki->k", u, jnp.cross(t, dt)) / (1.0 + t @ u)
    tau = jnp.sum(m * t, axis=1) / GJ + kappa0[2]
    turn = psi_b + alpha_b - psi_a - alpha_a + length * (weights @ omega)
    rows = jnp.stack([jnp.dot(u, balance) * length / EI, planar_turn(0.0, turn) - length * (weights @ tau)])
    return rows, (f, alpha_a, omega, tau)


def spatial_segment_residual(
    r_a: Float[Array, "3"],
    t_a: Float[Array, "3"],
    m_a: Float[Array, "3"],
    r_b: Float[Array, "3"],
    t_b: Float[Array, "3"],
    m_b: Float[Array, "3"],
    n: Float[Array, "3"],
    length: Float[Array, ""],
    EI: Float[Array, ""],
    frame: Float[Array, "2 3"],
    quad: SegmentQuadrature,
    twist=None,
) -> Float[Array, "7"]:
    """Residuals (Eq. 7 ×3, Eq. 8 ×2, Eq. 9 ×2) of one spatial segment, dimensionless.

    ``frame`` spans (approximately) the plane ⊥ the segment's mean tangent; it only selects
    which two independent combinations of the ⊥u components are returned, so the solution
    does not depend on it (it must merely not be parallel to u).

    ``twist``: None for the torsion-free rod, or for the Kirchhoff rod with twist
    (ψ_a, ψ_b, e_a, e_b, GJ, κ₀): the material-frame angles at both ends (rad) about the
    reference directors e_a, e_b (⊥ t_a, t_b), the torsional stiffness (pN·µm²) and the
    natural curvature and twist (κ₁, κ₂, τ₀) (1/µm, on d1, d2, t); then two more rows
    follow (Eq. 8 about u, the twist law; :func:`_kirchhoff_rows`) and m·t is the twisting
    moment.
    """
    if twist is not None:
        return _kirchhoff_rows(r_a, t_a, m_a, r_b, t_b, m_b, n, length, EI, frame, quad, twist)
    u, w_a, w_b, w = _spatial_interpolant(t_a, m_a, t_b, m_b, n, length, EI, jnp.asarray(quad.basis))
    t = jax.vmap(sphere_exp, in_axes=(None, 0))(u, w)  # [K, 3]
    weights = jnp.asarray(quad.weights)
    chord = r_b - r_a
    length_eq = (chord - length * (weights @ t)) / length

    def perp(v):
        return frame @ (v - jnp.dot(u, v) * u)

    moment_eq = perp(m_b - m_a + jnp.cross(chord, n)) * length / EI
    offsets = length * (jnp.asarray(quad.integration) @ t)  # r(s_k) − r_a, [K, 3]
    m = m_a[None, :] - jnp.cross(offsets, n[None, :])
    rates = jax.vmap(sphere_exp_differential_inverse, in_axes=(None, 0, 0))(u, w, jnp.cross(m, t))
    bending_eq = perp(EI * (w_b - w_a) - length * (weights @ rates)) / EI
    return jnp.concatenate([length_eq, moment_eq, bending_eq])
