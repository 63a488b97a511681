"""A spatial SOCB segment that carries interior point forces exactly, and its obstacle slots.

The 3D counterpart of :mod:`socbjax._contact_segment`.  A point force F at s_k makes the
internal force piecewise constant, n(s) = n_a − Σ_{s_j < s} F_j; the tangent t and its first
derivative stay continuous at s_k, and t'' jumps by (F − (F·t)t)/EI, t''' and higher by
terms that depend on the local state.  In the log chart of the segment (w = log_u t, the
interpolated quantity of Eqs 5–6a in 3D, ``docs/equations.md``), the interpolant is

    w(s) = q(s) + Σ_k Σ_{j=2}^{5} J_kj/j! (s − s_k)₊^j ,

with J_kj the jumps of the j-th derivative of w at s_k.  They come from the exact local
solution on each side: the Taylor series to fifth order of the Kirchhoff rod equations
t' = m × t/EI, m' = −t × n (n = the force before / after the point) from the slot's tangent
and curvature, pushed through the log map by Taylor-mode differentiation
(truncated series arithmetic).  q is then as smooth as a load-free segment's chart coordinate, and
the quintic keeps its sixth order.  Eqs 7–9 integrate over the pieces between the s_k
(composite Gauss–Legendre), with the moment m(s) = m_a − (r(s) − r_a) × n_a
+ Σ_{s_k<s} (r(s) − r_k) × F_k.

Each obstacle slot has ten unknowns: σ_k = s_k/l, the contact force F_k on the filament (pN,
3), the unit tangent t_k and its derivative t'_k (1/µm) at s_k, and ten rows (the location
and force rows of the planar slots, t_k = t(s_k) and t'_k = t'(s_k) of the corrected
interpolant): every row is explicit in the state.  Units: µm, pN, pN·µm².
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ._contact_segment import ContactSetup, contact_slot_rows, corrected_quintic, jump_corrections, rest_sigma
from ._geometry import powers_of, sphere_exp, sphere_exp_differential_inverse
from ._quadrature import HERMITE_TO_MONOMIAL
from ._segment import chart_data, end_jet, kirchhoff_jet, twist_rows

__all__ = ["SPATIAL_SLOT_WIDTH", "spatial_jumps", "spatial_contact_segment", "spatial_contact_segment_rows",
           "initial_spatial_slots"]

SPATIAL_SLOT_WIDTH = 10  # unknowns per 3D slot: σ, F (3), t (3), t' (3)
_JUMP_ORDERS = np.arange(2, 6)


def _rod_series(t, m, n, EI):
    """Taylor coefficients [6, 3] of t(s_k + h) for the rod t' = m × t/EI, m' = −t × n under
    the constant force n (pN), from t (unit) and m (pN·µm) at s_k (Cauchy products)."""
    T, M = [t], [m]
    for j in range(5):
        dt = sum(jnp.cross(M[i], T[j - i]) for i in range(j + 1)) / EI
        T.append(dt / (j + 1))
        M.append(-jnp.cross(T[j], n) / (j + 1))
    return jnp.stack(T)


# Truncated power series (degree 5) in h: arrays [6, ...] of Taylor coefficients.
_CAUCHY = np.array([[[1.0 if i + j == n else 0.0 for j in range(6)] for i in range(6)] for n in range(6)])
_SERIES_Q = 0.25  # below: G and its derivatives from the power series; above: the recurrence
_G_TERMS = 64  # truncation of atan(√q)/√q = Σ (−q)^k/(2k + 1) below q = 0.25: < 1e-30 even after 5 derivatives


def _g_series_matrix() -> np.ndarray:
    """A [6, M] with (A @ [q^m]) _i = d^i/dq^i Σ_k (−q)^k/(2k + 1) = Σ_m a_{m+i} (m+i)!/m! q^m."""
    A = np.zeros((6, _G_TERMS))
    for i in range(6):
        for m in range(_G_TERMS - i):
            A[i, m] = (-1.0) ** (m + i) / (2 * (m + i) + 1) * math.perm(m + i, i)
    return A


_G_SERIES = _g_series_matrix()


def _mul(a, b):
    """Cauchy product of two series (a scalar series times a scalar or vector series)."""
    return jnp.einsum("nij,i...,j...->n...", _CAUCHY, a, b)


def _g_derivatives(q):
    """[6] G(q) = atan(√q)/√q and its first five q-derivatives, accurate for all q ≥ 0: the
    power series below ``_SERIES_Q``; above it the recurrence from 2q G' + G = 1/(1 + q),
    G⁽ⁱ⁺¹⁾ = ((−1)^i i!/(1 + q)^{i+1} − (2i + 1) G⁽ⁱ⁾)/(2q) (round-off grows by < 3e4)."""
    small = q < _SERIES_Q
    qs = jnp.where(small, q, 0.0)  # double where: each branch sees only its own safe values
    ql = jnp.where(small, 1.0, q)
    series = jnp.asarray(_G_SERIES) @ powers_of(qs, _G_TERMS)  # q^m by products: no 0^0 in derivatives
    r = jnp.sqrt(ql)
    rec = [jnp.arctan2(r, 1.0) / r]
    for i in range(5):
        rec.append(((-1.0) ** i * math.factorial(i) / (1.0 + ql) ** (i + 1) - (2 * i + 1) * rec[i]) / (2.0 * ql))
    return jnp.where(small, series, jnp.stack(rec))


def _log_series(u, T):
    """Taylor coefficients [6, 3] of w(h) = log_u t(s_k + h) from those of t, T [6, 3]:
    w = G(q) x/c with c = u·t, x = t − c u, q = |x|²/c² (as :func:`socbjax._geometry.sphere_log`),
    in truncated series arithmetic."""
    c = T @ u
    x = T - c[:, None] * u[None, :]
    inv = [1.0 / c[0]]
    for n in range(1, 6):  # 1/c
        inv.append(-sum(c[i] * inv[n - i] for i in range(1, n + 1)) / c[0])
    inv = jnp.stack(inv)
    q = _mul(_mul(jnp.einsum("nij,id,jd->n", _CAUCHY, x, x), inv), inv)
    dq = q.at[0].set(0.0)
    derivs = _g_derivatives(q[0])
    G, power = jnp.zeros(6).at[0].set(derivs[0]), jnp.zeros(6).at[0].set(1.0)
    for i in range(1, 6):  # G(q0 + δ) = Σ G⁽ⁱ⁾(q0) δ^i / i!
        power = _mul(power, dq)
        G = G + derivs[i] / math.factorial(i) * power
    return _mul(_mul(G, inv), x)


def spatial_jumps(u, sigma, tangents, rates, twist_moment, forces, n_a, length, EI, template=False):
    """Jump coefficients a [C, 4, 3] = l^j J_kj / j! (σ-units) of the chart coordinate across
    the point forces ``forces`` [C, 3] (pN) at σ [C]: J_kj the jump of d^j w/ds^j (j = 2..5).
    ``tangents``, ``rates`` [C, 3]: t and t' (1/µm) at the points; ``twist_moment``: m·t
    (pN·µm, constant along a segment without natural curvature; 0 for the torsion-free rod).
    The force before σ_k is n_a minus the forces of the slots that come earlier (ties by index).
    ``template``: the sparsity template's random states (tangents anywhere on the sphere) take
    the chart at a point near t (same dependences, well-conditioned values)."""
    C = sigma.shape[0]
    idx = jnp.arange(C)
    before = (sigma[None, :] < sigma[:, None]) | ((sigma[None, :] == sigma[:, None]) & (idx[None, :] < idx[:, None]))
    n_minus = n_a[None, :] - before.astype(forces.dtype) @ forces
    n_plus = n_minus - forces

    def one(t, dt, nm, npl):
        t = t / jnp.linalg.norm(t)
        m = EI * jnp.cross(t, dt) + twist_moment * t
        centre = u
        if template:
            centre = (u + 3.0 * t) / jnp.linalg.norm(u + 3.0 * t)
        return (_log_series(centre, _rod_series(t, m, npl, EI)) - _log_series(centre, _rod_series(t, m, nm, EI)))[2:]

    jump = jax.vmap(one)(tangents, rates, n_minus, n_plus)  # [C, 4, 3] Taylor coefficients: J_kj / j!
    return jump * (length ** _JUMP_ORDERS)[None, :, None]


def _composite_offsets(t, widths, quad, length):
    """r(x_p) − r_a [P, 3] at the composite quadrature points (pieces of ``widths``)."""
    K = len(quad.points)
    tp = t.reshape(widths.shape[0], K, 3)
    piece = widths[:, None] * jnp.einsum("k,ikd->id", jnp.asarray(quad.weights), tp)
    start = jnp.cumsum(piece, axis=0) - piece
    within = widths[:, None, None] * jnp.einsum("kj,ijd->ikd", jnp.asarray(quad.integration), tp)
    return length * (start[:, None, :] + within).reshape(-1, 3)


def _interpolant(ends, n_a, F, s, tangents, rates, length, EI, twist, template=False, chart=None):
    """(u, w_a, w_b, monomial coefficients [6, 3], jump coefficients [Q, 4, 3], unit t_a, unit
    t_b, twisting moment) of a segment carrying the point forces F [Q, 3] at σ = s.  The first
    points have ``tangents`` and ``rates`` (t, t′); the last ones (``chart`` = (w, w′) [M, 3]
    each, pair contacts) are given in the segment's own chart: t = exp_u(w), t′ = D exp_u(w)[w′]."""
    _, t_a, m_a, _, t_b, m_b = ends
    n_b = n_a - jnp.sum(F, axis=0)
    if twist is None:
        jet_a, jet_b = end_jet(t_a, m_a, n_a, EI), end_jet(t_b, m_b, n_b, EI)
        twist_moment = 0.0
    else:
        psi_a, psi_b, e_a, e_b, GJ, kappa0 = twist
        jet_a = kirchhoff_jet(t_a, e_a, psi_a, m_a, n_a, EI, GJ, kappa0)
        jet_b = kirchhoff_jet(t_b, e_b, psi_b, m_b, n_b, EI, GJ, kappa0)
        twist_moment = jnp.dot(m_a, jet_a[0])
    u, w_a, w_b, data = chart_data(jet_a, jet_b, length)
    if chart is not None and chart[0].shape[0]:
        t_x, dt_x = jax.vmap(lambda w, dw: jax.jvp(lambda z: sphere_exp(u, z), (w,), (dw,)))(*chart)
        tangents, rates = jnp.concatenate([tangents, t_x]), jnp.concatenate([rates, dt_x])
    a = spatial_jumps(u, s, tangents, rates, twist_moment, F, n_a, length, EI, template)
    end = [c[0] for c in jump_corrections(jnp.ones(1), s, a)]
    data = data - jnp.stack([jnp.zeros(3), jnp.zeros(3), jnp.zeros(3), end[0], end[1], end[2]])
    return u, w_a, w_b, jnp.asarray(HERMITE_TO_MONOMIAL) @ data, a, jet_a[0], jet_b[0], twist_moment


def spatial_contact_segment(ends, n_a, length, EI, frame, slots, owns_start, owns_end, setup: ContactSetup,
                            displacement, axis, quad, twist=None, smooth=(0.0, 0.0), active=1.0, pinned=0.0,
                            extra=None):
    """One spatial segment with its obstacle slots.

    ends : (r_a, t_a, m_a, r_b, t_b, m_b) [3] each: positions µm, tangents, moments pN·µm
        (m_a already reduced by the moments handed over at the start node);
    n_a : internal force at the start (pN, the state's segment force);
    frame : [2, 3] the analysis basis ⊥ the mean tangent (:mod:`socbjax._segment`);
    slots : [C, 10] (σ, F pN, t, t' 1/µm); owns_start, owns_end, smooth, active: as for
        :func:`socbjax._contact_segment.planar_contact_segment`;
    twist : None (torsion-free rod) or (ψ_a, ψ_b, e_a, e_b, GJ, κ₀) of a twisting segment
        without natural curvature (κ₁ = κ₂ = 0; τ₀ allowed);
    extra : [M, 10] more interior point forces (σ, F pN, w, w′ 1/µm: filament–filament
        contacts, :mod:`socbjax._contact_pairs`, their point's chart coordinate and its
        arc-length derivative in this segment's log chart; zero force where unused), or None.
    Returns (segment rows [7] or [9] as :func:`socbjax._segment.spatial_segment_residual`,
    slot rows [C, 10], end force n_b [3] pN, the force lumped onto the start node [3] pN
    (zero unless ``setup.lumped``), contact points [C, 3] µm, gaps [C] µm, and at the
    ``extra`` forces' σ (points, unit tangents, w, dw/dσ: [M, 3] each)).
    """
    r_a, _, m_a, r_b, _, m_b = ends
    C = slots.shape[0]
    extra = jnp.zeros((0, SPATIAL_SLOT_WIDTH)) if extra is None else extra
    every = jnp.concatenate([slots, extra])
    sigma, F = every[:, 0], every[:, 1:4]
    tangents, rates = slots[:, 4:7], slots[:, 7:10]
    s = jnp.clip(sigma, 0.0, 1.0)
    F_node = F
    if setup.lumped:  # comparison only: the force goes to the two nodes, the segment never sees it
        F_node, F = F * s[:, None], jnp.zeros_like(F)
    u, w_a, w_b, coef, a, t_a, t_b, twist_moment = _interpolant(ends, n_a, F, s, tangents, rates, length, EI, twist,
                                                                      setup.dense, (extra[:, 4:7], extra[:, 7:10]))
    breaks = jnp.concatenate([jnp.zeros(1), jnp.sort(s), jnp.ones(1)])
    widths = jnp.diff(breaks)
    x = (breaks[:-1, None] + widths[:, None] * jnp.asarray(quad.points)[None, :]).ravel()
    W = (widths[:, None] * jnp.asarray(quad.weights)[None, :]).ravel()
    w, dw = corrected_quintic(x, coef, s, a)
    t, dt = jax.vmap(lambda wk, dwk: jax.jvp(lambda z: sphere_exp(u, z), (wk,), (dwk / length,)))(w, dw)
    after = (x[None, :] > s[:, None]).astype(x.dtype)  # [C, P]
    offsets = _composite_offsets(t, widths, quad, length)  # r(x_p) − r_a
    arms = length * ((1.0 - after) * W) @ t  # r_k − r_a  [C, 3]
    chord = r_b - r_a
    m = (m_a[None, :] - jnp.cross(offsets, n_a[None, :]) + jnp.cross(offsets, after.T @ F)
         - after.T @ jnp.cross(arms, F))
    balance = m_b - m_a + jnp.cross(chord, n_a) - jnp.sum(jnp.cross(chord[None, :] - arms, F), axis=0)

    def perp(v):
        return frame @ (v - jnp.dot(u, v) * u)

    rates_w = jax.vmap(sphere_exp_differential_inverse, in_axes=(None, 0, 0))(u, w, jnp.cross(m, t))
    rows = [(chord - length * (W @ t)) / length, perp(balance) * length / EI,
            perp(EI * (w_b - w_a) - length * (W @ rates_w)) / EI]
    if twist is not None:
        rows.append(twist_rows(u, t, dt, m, W, t_a, t_b, twist, balance, length, EI)[0])
    w_k, dw_k = corrected_quintic(s, coef, s, a)
    t_k, dt_k = jax.vmap(lambda wk, dwk: jax.jvp(lambda z: sphere_exp(u, z), (wk,), (dwk,)))(w_k, dw_k)
    shape = jnp.concatenate([tangents - t_k[:C], length * rates - dt_k[:C]], axis=1)
    points = r_a + arms
    slot_rows, gaps = contact_slot_rows((r_a, r_b, t_a, t_b), points[:C], s[:C], sigma[:C], slots[:, 1:4], tangents,
                                        rates, shape, length, owns_start, owns_end, setup, displacement, axis, smooth,
                                        active, pinned)
    start_load = jnp.sum(every[:, 1:4] - F_node, axis=0) if setup.lumped else jnp.zeros(3)
    at_extra = (points[C:], t_k[C:], w_k[C:], dw_k[C:])
    return jnp.concatenate(rows), slot_rows, n_a - jnp.sum(F_node, axis=0), start_load, points[:C], gaps, at_extra


def spatial_contact_segment_rows(positions, tangents, moments, m_start, forces, slots, network, setup: ContactSetup,
                                 control, quad, frames, twist=None, extra=None):
    """All spatial segments with their slots (vmapped): (segment rows [S, 7 or 9], slot rows
    [S, C, 10], end forces n_b [S, 3] pN, start-node loads [S, 3] pN, contact points [S, C, 3]
    µm, gaps [S, C] µm, and at the ``extra`` forces [S, M, 10] (pair contacts): points,
    tangents, w, dw/dσ).  ``twist``: per-segment (ψ_a, ψ_b, e_a, e_b, GJ, κ₀) or None."""
    a, b = network.segments[:, 0], network.segments[:, 1]
    ends = (positions[a], tangents[a], m_start, positions[b], tangents[b], moments[b])
    axis = jnp.asarray(network.probe_direction, positions.dtype)
    extra = jnp.zeros((network.n_segments, 0, SPATIAL_SLOT_WIDTH)) if extra is None else extra

    def one(end, n, length, EI, frame, slot, own_a, own_b, smooth_a, smooth_b, active, pinned, tw, more):
        return spatial_contact_segment(end, n, length, EI, frame, slot, own_a, own_b, setup, control.displacement,
                                       axis, quad, tw, (smooth_a, smooth_b), active, pinned, more)

    return jax.vmap(one)(ends, forces, network.lengths, network.EI, frames, slots, setup.owns_start, setup.owns_end,
                         setup.slot_smooth_start, setup.slot_smooth_end, setup.active, setup.pinned, twist, extra)


def initial_spatial_slots(network, setup: ContactSetup | None, tangents) -> jax.Array:
    """Slot unknowns [S, C, 10] of a force-free straight state: the segment middle (σ = ½; a
    pinned slot's free end, where its row rests), zero force, the start tangent and zero
    curvature."""
    C = 0 if setup is None else setup.n_obstacles
    S = network.n_segments
    if C == 0:
        return jnp.zeros((S, 0, SPATIAL_SLOT_WIDTH))
    t = tangents[network.segments[:, 0]]
    one = jnp.concatenate([jnp.full((S, 1), 0.5), jnp.zeros((S, 3)), t, jnp.zeros((S, 3))], axis=1)
    slots = jnp.broadcast_to(one[:, None, :], (S, C, SPATIAL_SLOT_WIDTH))
    return slots.at[..., 0].set(rest_sigma(setup))
