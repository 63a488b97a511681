"""A planar SOCB segment that carries interior point forces exactly, and its contact slots.

A point force F at s_k inside a segment makes the internal force piecewise constant,
n(s) = n_a − Σ_{s_j < s} F_j, so θ'' = −(t × n)/EI jumps at s_k, and so do θ''', θ⁗ and
θ⁽⁵⁾ (their closed forms in θ, θ' and n are in ``docs/equations.md`` "Contact").  The
segment's angle is the quintic of Eqs 5–6a plus the known jumps,

    θ(s) = q(s) + Σ_k Σ_{j=2}^{5} J_kj/j! (s − s_k)₊^j ,

so the remainder q is as smooth as a load-free segment's angle and the quintic keeps its
sixth order.  Eqs 7–9 integrate over the pieces between the s_k (composite Gauss–Legendre),
with the moment arms of the interior forces:

* Eq. 7:  r_b − r_a = ∫ t ds;
* Eq. 8:  m_b − m_a + (r_b − r_a) × n_a − Σ_k (r_b − r_k) × F_k = 0;
* Eq. 9:  EI(θ_b − θ_a − κ₀ l) = m_a l − [∫ (l − s) t ds] × n_a + Σ_k [∫_{s_k}^l (l − s) t ds] × F_k;
* end jets θ''(0) = −(t_a × n_a)/EI, θ''(l) = −(t_b × n_b)/EI with n_b = n_a − Σ F_k.

Each contact slot k (one per segment and obstacle) has five unknowns: σ_k = s_k/l, the
contact force F_k on the filament (pN, 2 components), and θ_k, κ_k (the angle and curvature
at s_k, on which the jumps depend), with five rows: σ_k at the closest point of the curve to
the obstacle (projected onto [0, 1]), F_k = f(gap) ∇φ (the penalty law of
:mod:`socbjax._contact` along the obstacle's unit normal at the contact point, stated
through an increasing map: :func:`force_law_rows`),
θ_k = θ(s_k) and κ_k = θ'(s_k).  With the force and the curve's data as unknowns every row
is an explicit function of the state: no inner iteration.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._contact import penalty_force
from ._quadrature import HERMITE_TO_MONOMIAL

__all__ = ["ContactSetup", "SLOT_WIDTH", "planar_contact_segment", "segment_jumps", "contact_segment_rows",
           "initial_slots", "handover_weight", "smoothstep", "end_blend", "location_bias", "near_weight",
           "near_band", "contact_slot_rows", "signed_distance", "jump_corrections", "corrected_quintic",
           "rest_sigma", "force_law_rows"]

_POW = np.arange(6)
_JUMP_ORDERS = np.arange(2, 6)
_FACT = np.array([2.0, 6.0, 24.0, 120.0])
# The location row projects σ − (∇φ·t) onto [0, 1]; far from contact a bias of this size
# toward the segment's middle keeps the row regular where φ is flat along the segment (a
# straight segment parallel to a wall).  It fades as (gap/l)², so it is 0 in contact.
_LOCATION_BIAS = 0.05
# A node inside a filament is a closest point only where ∇φ·t = 0 there (the curve is C¹): the
# force moves from one segment's slot to the next one's over this range of that slope.
_HANDOVER = 0.02
# A slot of a segment anchored on the probe face or the substrate follows the closest-point
# projection where l d²φ/ds² exceeds this (an interior dip; the row's conditioning), and rests
# on the free end below it: a dip it cannot see is shallower than l × this / 8.
_PINNED_BEND = 0.005
# Any other slot takes the projection as l d²φ/ds² rises over [0, _BEND_BLEND] (a dip it
# misses is shallower than l × this / 8: 0.06 nm for l = 0.5 µm, under 1 % of actin's d), and
# otherwise the nearer end, chosen smoothly over end distances within _END_BLEND × δ of each
# other, widened by the ends' mean height above the surface (:func:`end_blend`).  A sharp
# switch chatters where a straight strand end lies flat on a surface: its free tip has
# d²φ/ds² = 0 to rounding and its two ends are equally far (the 8-generation outcrop,
# u ≈ 2.5 µm, where the location row jumped by 3e-4 to 1 between Newton iterates).
_BEND_BLEND = 0.001
_END_BLEND = 0.05
SLOT_WIDTH = 5  # unknowns per 2D slot: σ, F_x, F_y, θ, κ


class ContactSetup(eqx.Module):
    """The obstacles of a model, per (segment, obstacle) slot (internal; built by
    :func:`socbjax._contact_model.contact_setup`).  C obstacles, S segments."""

    kinds: tuple = eqx.field(static=True)  # "plane" | "sphere" per obstacle
    names: tuple = eqx.field(static=True)  # "probe face", "substrate", "plane i", "sphere i" per obstacle
    points: jax.Array  # [C, d] plane point or sphere center (µm), at zero probe displacement
    normals: jax.Array  # [C, d] plane unit normal (allowed side); zeros for spheres
    radii: jax.Array  # [C] sphere radius (µm); 0 for planes
    moving: jax.Array  # [C] 1 for the probe face (moves with the probe displacement)
    owns_start: jax.Array  # [S, C] 1 where the segment's σ = 0 point is its own (see residual)
    owns_end: jax.Array  # [S, C] 1 where the segment's σ = 1 point is its own
    filament_radius: jax.Array  # d/2 (µm)
    activation: jax.Array  # δ (µm)
    stiffness: jax.Array  # k (pN/µm)
    force_scale: jax.Array  # pN, to make the λ rows dimensionless
    smooth_start: jax.Array = None  # [S] 1 where the filament continues smoothly before the start node
    smooth_end: jax.Array = None  # [S] 1 where it continues after the end node
    slot_smooth_start: jax.Array = None  # [S, C] the same per obstacle (0 next to a segment anchored on it)
    slot_smooth_end: jax.Array = None  # [S, C]
    active: jax.Array = None  # [S, C] 0 where the segment is anchored on the obstacle (no contact with it)
    pinned: jax.Array = None  # [S, C] 1 / 2 where its start / end node is anchored on the probe face / substrate
    seg_owns_start: jax.Array = None  # [S] 1 where a segment owns its σ = 0 point (filament bases)
    adjacent: jax.Array = None  # [S, A] segments sharing a node (never a contact pair), −1 padded
    reach: jax.Array = None  # µm: how far beyond touching a pair enters the list (≥ 2 × a step's motion)
    capacity: int = eqx.field(static=True, default=0)  # pair slots P (0: no filament–filament contact)
    per_segment: int = eqx.field(static=True, default=0)  # pairs per segment and segments per hash cell
    dense: bool = eqx.field(static=True, default=False)  # template: every dependence switched on
    lumped: bool = eqx.field(static=True, default=False)  # forces lumped to nodes (comparison only)
    slot_capacity: int = eqx.field(static=True, default=0)  # K near segments with the contact kernel; 0: all

    @property
    def n_obstacles(self) -> int:
        return len(self.kinds)

    @property
    def listed(self) -> bool:
        """Whether only the near list's segments carry the contact kernel
        (:mod:`socbjax._contact_near`; never in the pattern template)."""
        return self.slot_capacity > 0 and not self.dense


def _derivatives(theta, kappa, n, EI):
    """(θ'', θ''', θ⁗, θ⁽⁵⁾) of a piece under the constant internal force n (pN), at a point
    with angle θ and curvature κ = θ' (1/µm)."""
    c = jnp.cos(theta) * n[1] - jnp.sin(theta) * n[0]  # t × n
    d = jnp.cos(theta) * n[0] + jnp.sin(theta) * n[1]  # t · n
    d2 = -c / EI
    d3 = kappa * d / EI
    d4 = (d2 * d + kappa**2 * c) / EI
    d5 = (d3 * d + 3.0 * kappa * d2 * c - kappa**3 * d) / EI
    return jnp.stack([d2, d3, d4, d5])


def segment_jumps(sigma, theta, kappa, forces, n_a, length, EI):
    """Jump coefficients a[k, j] = l^j J_kj / j! (σ-units) of the slots: J_kj is the jump of
    the j-th derivative of θ (j = 2..5) across the point force forces[k] at σ_k; the force
    before σ_k is n_a minus the forces of the slots that come earlier (ties by index)."""
    C = sigma.shape[0]
    idx = jnp.arange(C)
    before = (sigma[None, :] < sigma[:, None]) | ((sigma[None, :] == sigma[:, None]) & (idx[None, :] < idx[:, None]))
    n_minus = n_a[None, :] - before.astype(forces.dtype) @ forces  # [C, 2]
    n_plus = n_minus - forces
    jump = jax.vmap(lambda th, ka, nm, npl: _derivatives(th, ka, npl, EI) - _derivatives(th, ka, nm, EI))(
        theta, kappa, n_minus, n_plus)  # [C, 4]
    return jump * length ** _JUMP_ORDERS / _FACT


def jump_corrections(x, sigma, a):
    """(C, dC/dσ, d²C/dσ²) at the points x [P] of Σ_k Σ_j a_kj (σ − σ_k)₊^j: a [Q, 4] (planar
    angle) or [Q, 4, d] (a vector chart coordinate), j = 2..5."""
    z = jnp.maximum(x[:, None] - sigma[None, :], 0.0)[..., None]  # [P, Q, 1]
    j = _JUMP_ORDERS
    value = jnp.einsum("pqj,qj...->p...", z**j, a)
    first = jnp.einsum("pqj,qj...->p...", j * z ** (j - 1), a)
    second = jnp.einsum("pqj,qj...->p...", j * (j - 1) * z ** (j - 2), a)
    return value, first, second


def corrected_quintic(x, coef, sigma, a):
    """(value, d/dσ) at the points x [P] of the quintic with monomial coefficients ``coef``
    ([6] or [6, d]) plus the jump corrections a (:func:`jump_corrections`)."""
    mono = x[:, None] ** _POW
    dmono = _POW * x[:, None] ** np.maximum(_POW - 1, 0)
    value, first, _ = jump_corrections(x, sigma, a)
    return mono @ coef + value, dmono @ coef + first


def signed_distance(setup: ContactSetup, k: int, r, displacement, axis):
    """(φ µm, unit ∇φ) of obstacle k at the point r: distance of the axis from its surface."""
    point = setup.points[k] + setup.moving[k] * displacement * axis
    if setup.kinds[k] == "plane":
        return jnp.dot(r - point, setup.normals[k]), setup.normals[k]
    offset = r - point
    dist = jnp.sqrt(jnp.sum(offset**2) + 1e-300)
    return dist - setup.radii[k], offset / dist


def planar_contact_segment(ends, n_a, length, EI, kappa0, slots, owns_start, owns_end, setup: ContactSetup,
                           displacement, axis, quad, extra=None, smooth=(0.0, 0.0), active=1.0, pinned=0.0):
    """One planar segment with its contact slots.

    ends : (r_a [2], θ_a, m_a, r_b [2], θ_b, m_b): positions µm, angles rad, moments pN·µm
        (m_a already reduced by the moments handed over at the start node);
    n_a : internal force at the start (pN, the state's segment force);
    slots : [C, 5] (σ, F_x, F_y pN, θ rad, κ 1/µm): location, contact force on the filament,
        angle and curvature there; owns_start, owns_end : [C] (1: the σ = 0 / σ = 1 point
        belongs to this segment; a node counts once, and a node anchored on an obstacle —
        a probe tip on the probe face, a base on the substrate — never);
    displacement, axis : probe displacement (µm) and direction, for the moving probe face;
    extra : [M, 5] more interior point forces in the same layout (filament–filament contacts,
        :mod:`socbjax._contact_pairs`; zero force where unused), or None;
    smooth : (1 where the filament continues through the start node, the same for the end
        node): the node hand-over of the slots' forces (:func:`handover_weight`).
    Returns (segment rows [4] as :func:`socbjax._segment.planar_segment_residual`, slot rows
    [C, 5], end force n_b [2] (pN), the force [2] (pN) lumped onto the start node (zero
    unless ``setup.lumped``), contact points [C, 2] (µm), gaps [C] (µm), and for ``extra``
    (points [M, 2] µm, θ [M] rad, dθ/dσ [M] at its σ)).
    """
    r_a, theta_a, m_a, r_b, theta_b, m_b = ends
    C = slots.shape[0]
    every = slots if extra is None else jnp.concatenate([slots, extra])
    sigma, F, theta_k, kappa_k = every[:, 0], every[:, 1:3], every[:, 3], every[:, 4]
    s = jnp.clip(sigma, 0.0, 1.0)
    turn = jnp.arctan2(jnp.sin(theta_b - theta_a), jnp.cos(theta_b - theta_a))
    F_node = F
    if setup.lumped:  # comparison only: the force goes to the two nodes, the segment never sees it
        F_node, F = F * s[:, None], jnp.zeros_like(F)
    a = segment_jumps(s, theta_k, kappa_k, F, n_a, length, EI)
    n_b = n_a - jnp.sum(F, axis=0)
    end_c, end_d1, end_d2 = jump_corrections(jnp.ones(1), s, a)
    data = jnp.stack([theta_a, length * (m_a / EI + kappa0), -length**2 * _cross(theta_a, n_a) / EI,
                      theta_a + turn - end_c[0], length * (m_b / EI + kappa0) - end_d1[0],
                      -length**2 * _cross(theta_a + turn, n_b) / EI - end_d2[0]])
    coef = jnp.asarray(HERMITE_TO_MONOMIAL) @ data
    # composite Gauss–Legendre between the sorted force points (θ'' jumps there)
    breaks = jnp.concatenate([jnp.zeros(1), jnp.sort(s), jnp.ones(1)])
    widths = jnp.diff(breaks)
    x = (breaks[:-1, None] + widths[:, None] * jnp.asarray(quad.points)[None, :]).ravel()
    W = (widths[:, None] * jnp.asarray(quad.weights)[None, :]).ravel()
    theta, _ = corrected_quintic(x, coef, s, a)
    t = jnp.stack([jnp.cos(theta), jnp.sin(theta)], axis=-1)
    after = (x[None, :] > s[:, None]).astype(x.dtype)  # [Q, P]
    chord = r_b - r_a
    to_end = length * (after * W) @ t  # r_b − r_k  [Q, 2]
    tail = length**2 * (after * W * (1.0 - x)) @ t  # ∫_{s_k}^l (l − s) t ds  [Q, 2]
    lever = length**2 * ((W * (1.0 - x)) @ t)
    length_eq = (chord - length * (W @ t)) / length
    moment_eq = (m_b - m_a + _cross2(chord, n_a) - jnp.sum(_cross2(to_end, F))) * length / EI
    bending_eq = (EI * (turn - kappa0 * length) - (m_a * length - _cross2(lever, n_a) + jnp.sum(_cross2(tail, F)))) / EI
    seg_rows = jnp.concatenate([length_eq, moment_eq[None], bending_eq[None]])
    points = r_a + length * ((1.0 - after) * W) @ t  # r_k
    theta_at, dtheta_at = corrected_quintic(s, coef, s, a)
    tangent = jnp.stack([jnp.cos(theta_k[:C]), jnp.sin(theta_k[:C])], axis=-1)
    bend = kappa_k[:C, None] * jnp.stack([-tangent[:, 1], tangent[:, 0]], axis=-1)  # t' = κ n
    shape = jnp.stack([theta_k[:C] - theta_at[:C], length * kappa_k[:C] - dtheta_at[:C]], axis=1)
    unit = lambda th: jnp.stack([jnp.cos(th), jnp.sin(th)])  # noqa: E731
    slot_rows, gaps = contact_slot_rows((r_a, r_b, unit(theta_a), unit(theta_a + turn)), points[:C], s[:C], sigma[:C],
                                        slots[:, 1:3], tangent, bend, shape, length, owns_start, owns_end, setup,
                                        displacement, axis, smooth, active, pinned)
    start_load = jnp.sum(every[:, 1:3] - F_node, axis=0) if setup.lumped else jnp.zeros(2)
    return (seg_rows, slot_rows, n_a - jnp.sum(F_node, axis=0), start_load, points[:C], gaps,
            (points[C:], theta_at[C:], dtheta_at[C:]))


def _cross(theta, n):
    return jnp.cos(theta) * n[1] - jnp.sin(theta) * n[0]


def _cross2(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _end_distances(setup, ends, displacement, axis):
    """(φ [2, C] µm, slope ∇φ·t [2, C]) of every obstacle at the segment's start and end node
    (``ends`` = (r_a, r_b, unit t_a, unit t_b))."""
    r_a, r_b, t_a, t_b = ends
    phi, slope = [], []
    for r, t in ((r_a, t_a), (r_b, t_b)):
        at = [signed_distance(setup, k, r, displacement, axis) for k in range(setup.n_obstacles)]
        phi.append(jnp.stack([p for p, _ in at]))
        slope.append(jnp.stack([g @ t for _, g in at]))
    return jnp.stack(phi), jnp.stack(slope)


def smoothstep(x):
    """3x² − 2x³ on [0, 1] (0 below, 1 above): a C¹ switch."""
    x = jnp.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def end_blend(end_phi, setup: ContactSetup):
    """Width W [C] (µm) over which a slot's nearer-end rule blends between the ends, from their
    distances ``end_phi`` [2, C] (µm): _END_BLEND δ, widened by the ends' mean gap ḡ where it
    is positive, W = _END_BLEND δ + ḡ₊²/(ḡ₊ + _END_BLEND δ) (C¹).  While blended (|Δφ| < W)
    the nearer end's gap is at least ḡ − W/2 ≥ min(ḡ, ḡ/2) − _END_BLEND δ/2: no end enters the
    surface that the rule does not see, and an end lying flat *above* it (light contact, or
    none) has a blend as wide as its height, so the rule does not flip between Newton iterates
    when rounding or a step tilts it by a fraction of a nanometre."""
    base = _END_BLEND * setup.activation
    mean = jnp.maximum(0.5 * (end_phi[0] + end_phi[1]) - setup.filament_radius, 0.0)
    return base + mean**2 / (mean + base)


def location_bias(sigma, gaps, length):
    """The pull of a slot's location row toward the segment's middle: regular where the
    distance is flat along the segment, fading as (gap/l)² (0 in contact)."""
    return _LOCATION_BIAS * jnp.clip(gaps / length, 0.0, 1.0) ** 2 * (sigma - 0.5)


def near_weight(lowest, length, activation):
    """1 where the closest-point rule of a slot applies, 0 where the slot rests at σ = ½:
    judged on the *lowest possible* gap (µm) of the segment(s), smoothly over the band
    gap < max(10 δ, l/20) (a slot resting at σ = ½ would not see an inclined segment's end
    approach; every curve point lies within l/2 of its chord's midpoint)."""
    band = near_band(length, activation)
    return smoothstep(2.0 * (band - lowest) / band)


def near_band(length, activation):
    """max(10 δ, l/20) (µm): the lowest possible gap below which :func:`near_weight` is
    positive (``length`` l µm, ``activation`` δ µm)."""
    return jnp.maximum(10.0 * activation, 0.05 * length)


def handover_weight(s, slopes, owns_start, owns_end, smooth):
    """Weight [C] of each slot's force.  A filament's tip and base count where the slot sits
    on them (``owns_*``: not where anchored on the obstacle).  A node inside a filament is a
    closest point only where the slope ∇φ·t vanishes there, and the force passes from the
    segment that ends at it (weight g(slope) while its slot sits on the node) to the one that
    starts there (1 − g(slope) near its start), g = 1 for slope ≥ 0 falling to 0 at −_HANDOVER:
    the weights sum to one across the node, and the force is continuous."""
    smooth_start, smooth_end = smooth
    g = lambda slope: 1.0 - smoothstep(-slope / _HANDOVER)  # noqa: E731
    end = jnp.where(s >= 1.0, owns_end * jnp.where(smooth_end > 0, g(slopes[1]), 1.0), 1.0)
    start = jnp.where(smooth_start > 0, 1.0 - g(slopes[0]) * (1.0 - smoothstep(s / 0.25)), jnp.where(s <= 0.0, owns_start, 1.0))
    return end * start


def contact_slot_rows(ends, points, s, sigma, F, tangent, bend, shape, length, owns_start, owns_end, setup,
                      displacement, axis, smooth=(0.0, 0.0), active=1.0, pinned=0.0):
    """Rows of the obstacle slots of one segment, planar or spatial (dimensionless), and their
    gaps [C] (µm).  ``ends`` = (r_a, r_b, unit t_a, unit t_b); ``points`` [C, d] the curve at
    the slots' σ (µm); ``s`` the σ projected onto [0, 1]; ``F`` [C, d] the slots' force
    unknowns (pN); ``tangent``, ``bend`` [C, d]: the slots' unit tangent and its arc-length
    derivative t' (1/µm) unknowns; ``shape`` [C, w]: the rows that tie those unknowns to the
    curve (planar: θ and κ; spatial: t and t').  Rows per slot: location, force (d), shape (w).
    ``active`` [C]: 0 where the segment is anchored on the obstacle (a strand's base on the
    substrate, a tip on the probe face): its axis starts on the surface, inside d/2 of it by
    construction, so it has no contact with that obstacle (its slot rests at σ = ½); the
    node at its free end belongs to the neighbouring segment.  ``pinned`` [C]: 1 (2) where the
    segment's start (end) node is anchored on an obstacle that lies d/2 + δ beyond it (the probe
    face, the substrate): that end sits at the band's edge and carries no force, so where the
    distance along the segment is straight or concave its closest point that matters is the
    free end (a node, shared with the neighbour by the usual hand-over), and where it is convex
    the projection's minimum.  The slot rests on the free end and takes the closest-point
    projection smoothly as l d²φ/ds² rises past ``_PINNED_BEND``: the rule never jumps between
    the ends, and stays regular on a straight segment parallel to the surface.  Any other slot
    rests on the nearer end where l d²φ/ds² ≤ 0 and takes the projection as it rises past
    ``_BEND_BLEND``; the nearer end is blended over end distances within :func:`end_blend`
    of each other (a straight segment lying flat on a surface: its slot sits between the
    ends, each of which is then at most 0.09 × that width deeper than the slot).  Every
    switch is C¹."""
    C = setup.n_obstacles
    if C == 0:
        return jnp.zeros((0, 1 + F.shape[-1] + shape.shape[-1])), jnp.zeros(0)
    phi, grad = [], []
    for k in range(C):  # a handful of obstacles: unrolled
        p, g = signed_distance(setup, k, points[k], displacement, axis)
        phi.append(p)
        grad.append(g)
    phi, grad = jnp.stack(phi), jnp.stack(grad)
    gaps = phi - setup.filament_radius
    slope = jnp.sum(grad * tangent, axis=-1)  # dφ/ds at the slot (dimensionless)
    # d²φ/ds² = ∇φ·t' + t·Hφ·t (a sphere's Hessian: (1 − (∇φ·t)²)/distance): a stationary
    # point with d²φ/ds² ≤ 0 is a maximum (a segment bulging away), and the closest point is
    # then the nearer end, which the row selects instead
    sphere = jnp.asarray([k == "sphere" for k in setup.kinds])
    radial = jnp.maximum(phi + setup.radii, 1e-300)
    bend = jnp.sum(grad * bend, axis=-1) + jnp.where(sphere, (1.0 - slope**2) / radial, 0.0)
    end_phi, end_slope = _end_distances(setup, ends, displacement, axis)
    # σ of the nearer end (0 or 1), blended where the ends are almost equally far
    nearer = smoothstep(0.5 + (end_phi[0] - end_phi[1]) / (2.0 * end_blend(end_phi, setup)))
    bias = location_bias(sigma, gaps, length)
    if setup.dense:  # pattern template: no projection, no ownership, force everywhere
        # σ itself (the row's own diagonal far from contact) and the gap (the bias and the
        # band depend on it, but only intermittently at random points)
        location = slope + sigma + gaps
        magnitude = setup.force_scale * gaps * (1.0 + gaps)  # O(1) rows: the pattern check compares sums
        # the normal part mixes the force's components, as in force_law_rows
        force = (F - 0.5 * jnp.sum(F * grad, axis=-1, keepdims=True) * grad - magnitude[:, None] * grad) / setup.force_scale
    else:
        # the projection of s − ∇φ·t, not of σ − ∇φ·t: beyond an end the curve point (and so the
        # slope) stays at the end, and σ − clip(σ − slope) would be flat in σ there (a singular
        # Jacobian: a pair slot at σ = 1 as its closest point moved back inside the segment,
        # the 6-generation outcrop with self-contact); this row has slope 1 outside [0, 1] and
        # the same roots
        projected = sigma - jnp.clip(s - slope - bias, 0.0, 1.0)
        # d(∇φ·t)/dσ = l d²φ/ds², the projection row's slope: the projection where it is
        # clearly positive (a minimum), an end where it is not, C¹ in between
        convex = smoothstep(bend * length / jnp.where(pinned > 0, _PINNED_BEND, _BEND_BLEND))
        end = jnp.where(pinned > 0, _free_end(pinned), nearer)
        closest = convex * projected + (1.0 - convex) * (sigma - end)
        # far from a plane the slot rests at the segment's middle (its force is 0 there
        # anyway): the closest-point rule, whose choice of branch may jump while a segment is
        # straight and parallel to the plane, takes over near it (:func:`near_weight`).  A
        # sphere's distance is curved along any segment (d²φ/ds² > 0 near it): its rule holds
        # everywhere (a band there moves the slot along a fold).
        middle = 0.5 * (ends[0] + ends[1])  # (r_a + r_b) / 2
        lowest = jnp.stack([signed_distance(setup, k, middle, displacement, axis)[0]
                            for k in range(setup.n_obstacles)]) - 0.5 * length - setup.filament_radius
        near = jnp.where(sphere, 1.0, near_weight(lowest, length, setup.activation))
        near = near * active
        location = near * closest + (1.0 - near) * (sigma - 0.5)
        owned = active * handover_weight(s, end_slope, owns_start, owns_end, smooth)
        force = force_law_rows(F, grad, gaps, owned, setup, length)
    rows = jnp.concatenate([location[:, None], force, shape], axis=1)
    return rows, gaps


def force_law_rows(F, normal, gaps, owned, setup: ContactSetup, length):
    """The force rows [..., d] (dimensionless) of contact points: the force F [..., d] (pN) on
    the filament equals ω f(g) along the unit ``normal`` [..., d], f the penalty law of
    :func:`socbjax._contact.penalty_force` at the gap g [...] (µm), ω = ``owned`` [...] the
    hand-over weight; ``length`` [...] µm the segment's length.

    Tangential part (F − (F·n)n)/F_s; normal part (H(F·n) − H(ω f(g)))/F_s with the same
    increasing map H on both sides: H(F) = F up to F_c and F_c (3 (F/F_c)^{1/3} − 2) above
    (C¹: value and slope 1 match at F_c).  Newton on F − f(g) comes out of a deep guess by
    only a factor 2/3 per iteration (the cube of the depth) wherever the structure holding
    the point is softer than the law's tangent k x² (x = 1 − g/δ); above F_c the row is
    linear in the gap instead, and Newton lands on the law's graph in a step or two
    (``docs/equations.md``, "The force row in the gap where the law is the stiffer side").
    F_c = (kδ/3) x_c³ with k x_c² = F_s/l, a segment's bending stiffness scale EI/l³.  H is
    strictly increasing, so the row vanishes exactly on the law's graph and its gradient
    there is H′ > 0 times that of F − ω f(g): solutions, tangents, sign(det J) and implicit
    derivatives are those of the plain law."""
    delta, k, scale = setup.activation, setup.stiffness, setup.force_scale
    F_n = jnp.sum(F * normal, axis=-1)
    F_c = k * delta / 3.0 * (scale / (length * k)) ** 1.5

    def H(force):
        z = force / F_c
        return F_c * jnp.where(z > 1.0, 3.0 * jnp.cbrt(jnp.maximum(z, 1.0)) - 2.0, z)

    normal_row = (H(F_n) - H(owned * penalty_force(gaps, delta, k))) / scale
    return (F - F_n[..., None] * normal) / scale + normal_row[..., None] * normal


def contact_segment_rows(positions, angles, moments, m_start, forces, slots, network, setup: ContactSetup, control,
                         quad, extra=None):
    """All planar segments with their slots (vmapped): (segment rows [S, 4], slot rows
    [S, C, 5], end forces n_b [S, 2] pN, start-node loads [S, 2] pN, contact points [S, C, 2]
    µm, gaps [S, C] µm, and at the ``extra`` forces [S, M, 5] (pair contacts): points, θ, dθ/dσ)."""
    a, b = network.segments[:, 0], network.segments[:, 1]
    ends = (positions[a], angles[a], m_start, positions[b], angles[b], moments[b])
    axis = jnp.asarray(network.probe_direction, positions.dtype)

    extra = jnp.zeros((network.n_segments, 0, SLOT_WIDTH)) if extra is None else extra

    def one(end, n, length, EI, kappa0, slot, own_a, own_b, more, smooth_a, smooth_b, active, pinned):
        return planar_contact_segment(end, n, length, EI, kappa0, slot, own_a, own_b, setup, control.displacement,
                                      axis, quad, more, (smooth_a, smooth_b), active, pinned)

    return jax.vmap(one)(ends, forces, network.lengths, network.EI, network.natural_curvature, slots,
                         setup.owns_start, setup.owns_end, extra, setup.slot_smooth_start, setup.slot_smooth_end,
                         setup.active, setup.pinned)


def initial_slots(network, setup: ContactSetup | None, angles) -> jax.Array:
    """Slot unknowns [S, C, 5] of a force-free state: the segment middle (σ = ½; a pinned
    slot's free end, where its row rests), zero force, the angle and curvature of the unloaded
    arc there; [S, 0, 5] without contact."""
    C = 0 if setup is None else setup.n_obstacles
    S = network.n_segments
    if C == 0:
        return jnp.zeros((S, 0, SLOT_WIDTH))
    kappa0 = jnp.asarray(network.natural_curvature) if network.dim == 2 else jnp.zeros(S)
    theta = angles[network.segments[:, 0]] + 0.5 * kappa0 * network.lengths
    one = jnp.stack([jnp.full(S, 0.5), jnp.zeros(S), jnp.zeros(S), theta, kappa0], axis=1)
    slots = jnp.broadcast_to(one[:, None, :], (S, C, SLOT_WIDTH))
    return slots.at[..., 0].set(rest_sigma(setup))


def rest_sigma(setup: ContactSetup):
    """[S, C] where each slot rests far from contact: ½, or a pinned slot's free end."""
    return jnp.where(setup.pinned > 0, _free_end(setup.pinned), 0.5)


def _free_end(pinned):
    """σ of a pinned slot's free end (``pinned`` 1: start anchored, free end σ = 1; 2: σ = 0)."""
    return 2.0 - pinned
