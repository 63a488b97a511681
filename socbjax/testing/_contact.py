"""References for contact: the planar elastica pressed onto a point obstacle and the 3D rod
pressed onto a sphere (shooting across the jump of the internal force, scipy), and the lobes
of the clamped–clamped elastica (elliptic integrals).  They share no code with socbjax's contact model.

Units: µm, pN, pN·µm².
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve, least_squares
from scipy.special import ellipe, ellipeinc, ellipj, ellipk, ellipkinc

__all__ = ["rod_on_sphere", "elastica_on_point_obstacle", "clamped_elastica_lobe_gap", "elastica_end_shortening"]


def elastica_on_point_obstacle(tip_load, obstacle, diameter, law, guess, *, length=1.0, EI=1.0) -> dict:
    """A cantilever clamped at the origin along x, loaded by ``tip_load`` (pN, [2]) and pressed
    onto a point ``obstacle`` (µm, [2]): the Kirchhoff elastica integrated (DOP853, rtol
    1e-13) from the clamp to the contact point s_c and on to the tip, with the internal force
    jumping by the contact force F = f(gap) ν there (ν from the obstacle to the axis, at the
    point where the axis is closest to it; gap = |r − obstacle| − d/2; f(g) = (kδ/3)(1 − g/δ)³
    below δ, ``law`` = (δ µm, k pN/µm)).  ``guess``: (clamp moment pN·µm, s_c µm, |F| pN,
    angle of ν rad).  Returns {"tip": [x, y, θ], "contact_s": s_c, "force": |F|}."""
    tip_load, obstacle = np.asarray(tip_load, float), np.asarray(obstacle, float)
    delta, k = law
    opts = dict(rtol=1e-13, atol=1e-14, method="DOP853")

    def rhs(s, y, n):
        return [np.cos(y[2]), np.sin(y[2]), y[3] / EI, -(np.cos(y[2]) * n[1] - np.sin(y[2]) * n[0])]

    def legs(z):
        m0, sc, lam, phi = z
        contact = lam * np.array([np.cos(phi), np.sin(phi)])
        a = solve_ivp(rhs, (0, sc), [0, 0, 0, m0], args=(tip_load + contact,), **opts).y[:, -1]
        return a, solve_ivp(rhs, (sc, length), a, args=(tip_load,), **opts).y[:, -1]

    def equations(z):
        a, b = legs(z)
        r, t = a[:2], np.array([np.cos(a[2]), np.sin(a[2])])
        gap = np.linalg.norm(r - obstacle) - diameter / 2
        return [b[3], (r - obstacle) @ t, z[2] - k * delta / 3 * max(1 - gap / delta, 0) ** 3,
                np.arctan2(*(r - obstacle)[::-1]) - z[3]]

    z, _, ok, message = fsolve(equations, guess, xtol=1e-14, full_output=True)
    if ok not in (1, 3) or np.abs(equations(z)).max() > 1e-11:  # 3: converged to round-off
        raise RuntimeError(f"elastica_on_point_obstacle did not converge: {message}")
    return {"tip": legs(z)[1][:3], "contact_s": float(z[1]), "force": float(z[2])}


def clamped_elastica_lobe_gap(k: float, length: float = 1.0) -> float:
    """Axis distance (µm) between the two lobes of the clamped–clamped (first mode) elastica
    of modulus k: twice the distance along the axis from the middle to the first point where
    the tangent is at 90° (where the lobe reaches farthest toward the middle)."""
    m = k * k
    lam = 4 * ellipk(m) / length

    def x(s):
        return 2 / lam * ellipeinc(ellipj(lam * s, m)[3], m) - s

    return 2 * (x(length / 2) - x(ellipkinc(np.arcsin(1 / (np.sqrt(2) * k)), m) / lam))


def elastica_end_shortening(k: float, length: float = 1.0) -> float:
    """End shortening Δ (µm) of the pinned–pinned or clamped–clamped first-mode elastica of
    modulus k: 2L(1 − E(k)/K(k))."""
    return 2 * length * (1 - ellipe(k * k) / ellipk(k * k))


def rod_on_sphere(tip_load, center, radius, diameter, law, guess, *, length=1.0, EI=1.0, line=None) -> dict:
    """A 3D torsion-free cantilever clamped at the origin along x, loaded by ``tip_load``
    (pN, [3]) and pressed onto a rigid sphere (``center`` µm [3], ``radius`` µm; 0: a point):
    the Kirchhoff rod r' = t, t' = m × t/EI, m' = −t × n integrated (DOP853, rtol 1e-13)
    from the clamp to the contact point s_c and on to the tip, the internal force n jumping
    by the contact force F = f(gap) ν at s_c (ν the sphere's outward normal through the axis
    point, s_c where (r − center)·t = 0, gap = |r − center| − radius − d/2, ``law`` = (δ µm,
    k pN/µm) as in :func:`elastica_on_point_obstacle`).  ``line`` [3] (optional): the obstacle
    is instead the rigid straight line through ``center`` along ``line`` (a crossing rod's
    axis; distances and the normal ν measured perpendicular to it; ``radius``: the crossing
    rod's radius).  ``guess``: (m_y, m_z at the clamp pN·µm, s_c µm, F [3] pN).  Returns
    {"tip": r(L) [3], "tip_tangent": t(L) [3], "contact_s": s_c, "force": F [3]}."""
    tip_load, center = np.asarray(tip_load, float), np.asarray(center, float)
    along = None if line is None else np.asarray(line, float) / np.linalg.norm(line)
    delta, k = law
    opts = dict(rtol=1e-13, atol=1e-14, method="DOP853")

    def rhs(s, y, n):
        t, m = y[3:6], y[6:9]
        return np.concatenate([t, np.cross(m, t) / EI, -np.cross(t, n)])

    def legs(z):
        force = np.asarray(z[3:6])
        start = np.array([0, 0, 0, 1.0, 0, 0, 0, z[0], z[1]])
        a = solve_ivp(rhs, (0, z[2]), start, args=(tip_load + force,), **opts).y[:, -1]
        return a, solve_ivp(rhs, (z[2], length), a, args=(tip_load,), **opts).y[:, -1]

    def equations(z):
        a, b = legs(z)
        offset = a[:3] - center
        if along is not None:
            offset = offset - (offset @ along) * along
        dist = np.linalg.norm(offset)
        gap = dist - radius - diameter / 2
        law_force = k * delta / 3 * max(1 - gap / delta, 0) ** 3 * offset / dist
        return np.concatenate([b[6:9], [offset @ a[3:6]], np.asarray(z[3:6]) - law_force])

    out = least_squares(equations, np.asarray(guess, float), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    if np.abs(equations(out.x)).max() > 1e-10:
        raise RuntimeError(f"rod_on_sphere did not converge: {out.message}")
    _, b = legs(out.x)
    return {"tip": b[:3], "tip_tangent": b[3:6], "contact_s": float(out.x[2]), "force": np.asarray(out.x[3:6])}
