"""Independent reference for the post-buckled column (first mode) by shooting: see
:mod:`socbjax.testing._elastica` for the model and conventions.

:func:`elastica_column_force` / :func:`elastica_column_shape` solve the post-buckled
column of the socbjax column builder (node 0 at the origin, axis +x, last node pushed to
``x(L) = L - Δ``; supports clamped/pinned first, clamped/pinned/free last) on the first-mode
branch.  Dimensionless (``L = EI = 1``) shooting with state ``(s - x, y, θ, m)`` (no
cancellation at small ``Δ``), internal force ``(-P, Q)``, unknowns base moment or angle,
``P`` and ``Q`` scaled by ``√δ`` (``δ = Δ/L``), three-component ``optimistix.Newton``;
continuation in ``√δ`` from the linear buckling mode (smallest root of the 4×4 boundary
determinant) through the sorted inputs.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import scipy.optimize

from ._elastica import check_count, check_value, require_x64


_COLUMN_FIRST = ("clamped", "pinned")
_COLUMN_LAST = ("clamped", "pinned", "free")
_COL_START = 1e-4  # δ = Δ/L where continuation leaves the linear buckling mode
_COL_RATIO, _COL_STEP = 1.5, 0.02  # largest continuation step: δ ratio and δ increment
_COL_TOL = 1e-9  # accepted scaled residual


class ElasticaColumn(eqx.Module):
    """Post-buckled column at one end shortening (first-mode branch, leaving +y).

    Attributes: ``s [n]`` (µm), ``positions [n, 2]`` (µm), ``angle [n]`` (rad),
    ``moment [n]`` (pN·µm), ``force [2]`` (pN, constant internal force ``(-P, Q)``: the
    force applied at the last node), ``axial_force`` ``P`` (pN, compressive positive),
    ``lateral_force`` ``Q`` (pN), ``end_shortening`` ``Δ`` (µm), ``midspan_deflection``
    ``y(L/2)`` (µm), ``residual`` (largest scaled boundary residual).
    """

    s: jax.Array
    positions: jax.Array
    angle: jax.Array
    moment: jax.Array
    force: jax.Array
    axial_force: float
    lateral_force: float
    end_shortening: float
    midspan_deflection: float
    residual: float


def _column_rhs(s, v, args):
    p, q = args  # state (s - x, y, θ, m); s - x avoids cancellation at small δ
    c, sn = jnp.cos(v[2]), jnp.sin(v[2])
    return jnp.stack([2.0 * jnp.sin(0.5 * v[2]) ** 2, sn, v[3], -(c * q + sn * p)])


def _column_states(z, delta, flags, tol, ts):
    """Dimensionless (``L = EI = 1``) state ``[len(ts), 4]``; NaN if integration failed.

    ``z = (β, p, κ)``: base unknown ``√δ β`` (``m(0)`` if clamped, else ``θ(0)``), axial
    force ``p`` and lateral force ``q = √δ κ``; ``flags = (first clamped, last clamped,
    last free)`` as 0/1.
    """
    r = jnp.sqrt(delta)
    v0 = jnp.stack([0.0 * r, 0.0 * r, (1.0 - flags[0]) * r * z[0], flags[0] * r * z[0]])
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_column_rhs), diffrax.Dopri8(), t0=0.0, t1=1.0, dt0=None, y0=v0,
        args=(z[1], r * z[2]), saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol * delta),
        adjoint=diffrax.ForwardMode(), max_steps=100_000, throw=False,
    )
    return jnp.where(sol.result == diffrax.RESULTS.successful, sol.ys, jnp.nan)


def _column_residual(z, args):
    """Scaled residual: ``(s - x)(1)/δ - 1`` and two end conditions divided by ``√δ``."""
    delta, flags, tol = args
    v = _column_states(z, delta, flags, tol, jnp.ones(1))[-1]
    r = jnp.sqrt(delta)
    e1 = jnp.where(flags[2] > 0, v[3], v[1]) / r  # free: m(1); pinned/clamped: y(1)
    e2 = jnp.where(flags[2] > 0, z[2], jnp.where(flags[1] > 0, v[2], v[3]) / r)
    return jnp.stack([v[0] / delta - 1.0, e1, e2])


@eqx.filter_jit
def _column_newton_jit(z0, delta, flags, tol):
    args = (delta, flags, tol)
    sol = optx.root_find(_column_residual, optx.Newton(rtol=tol, atol=tol), z0, args,
                         max_steps=32, throw=False)
    return sol.value, jnp.max(jnp.abs(_column_residual(sol.value, args)))


_column_states_jit = eqx.filter_jit(_column_states)


def _column_mode(first: str, last: str) -> np.ndarray:
    """``z`` as ``δ → 0``: linear buckling mode ``y = c·(1, s, cos ks, sin ks)``, L = EI = 1.

    The smallest ``k`` (``p = k²``) with a nontrivial mode; amplitude from
    ``δ = ½ ∫ y'² ds``, sign so that ``y(½) > 0``.
    """
    def bcs(k):
        c, sn, k2 = np.cos(k), np.sin(k), k * k
        val1, slope1, curv1 = [1, 1, c, sn], [0, 1, -k * sn, k * c], [0, 0, -k2 * c, -k2 * sn]
        end = {"pinned": [val1, curv1], "clamped": [val1, slope1],
               "free": [curv1, [0, 1, 0, 0]]}[last]  # free: q = -k² c1 = 0
        return np.array([[1, 0, 1, 0], [0, 1, 0, k] if first == "clamped" else
                         [0, 0, -k2, 0], *end], dtype=np.float64)

    det = lambda k: np.linalg.det(bcs(k))
    ks = np.linspace(0.5, 10.0, 400)
    vals = np.array([det(k) for k in ks])
    i = int(np.nonzero(vals[:-1] * vals[1:] <= 0.0)[0][0])
    k = scipy.optimize.brentq(det, ks[i], ks[i + 1], xtol=1e-14, rtol=1e-15)
    c = np.linalg.svd(bcs(k))[2][-1]
    x, w = np.polynomial.legendre.leggauss(40)
    s, w = 0.5 * (x + 1.0), 0.5 * w
    slope = c[1] - k * c[2] * np.sin(k * s) + k * c[3] * np.cos(k * s)
    mid = c[0] + 0.5 * c[1] + c[2] * np.cos(0.5 * k) + c[3] * np.sin(0.5 * k)
    amp = np.sign(mid) * np.sqrt(2.0 / np.sum(w * slope**2))  # a / √δ
    base = -k * k * c[2] if first == "clamped" else c[1] + k * c[3]  # y''(0) or y'(0)
    return np.array([amp * base, k * k, -amp * k * k * c[1]])


def _column_inputs(end_shortening, supports, length, EI, tol):
    """Host-side validation shared by the column functions."""
    require_x64()
    if isinstance(supports, str) or len(supports) != 2:
        raise ValueError(f"supports must be a pair (first, last), got {supports!r}")
    first, last = supports
    if first not in _COLUMN_FIRST or last not in _COLUMN_LAST:
        raise ValueError(f"supports must be (first in {_COLUMN_FIRST}, last in "
                         f"{_COLUMN_LAST}), got {tuple(supports)!r}")
    if (first, last) == ("pinned", "free"):
        raise ValueError("supports ('pinned', 'free') is a mechanism (rigid rotation "
                         "about the pin); clamp the first node or support the last")
    L, stiff = check_value("length", length, positive=True), check_value("EI", EI, positive=True)
    tol = check_value("tol", tol, positive=True)
    d = np.asarray(end_shortening, dtype=np.float64)
    if d.ndim > 1 or d.size == 0:
        raise ValueError(f"end_shortening must be a scalar or a non-empty 1-D array, "
                         f"got shape {d.shape}")
    if not np.all(np.isfinite(d)) or not np.all((d > 0) & (d < L)):
        raise ValueError(f"end_shortening must satisfy 0 < Δ < length = {L} µm, got {d}")
    return d / L, first, last, L, stiff, tol


def _column_flags(first: str, last: str) -> jax.Array:
    return jnp.asarray([first == "clamped", last == "clamped", last == "free"], jnp.float64)


def _column_branch(deltas: np.ndarray, first: str, last: str, tol: float) -> list:
    """``z`` at sorted, distinct ``δ = Δ/L`` along the first-mode branch.

    Continuation in ``σ = √δ`` (``z`` is analytic in the mode amplitude ∝ σ) from the
    linear mode at ``σ = 0``: secant predictor, Newton corrector; a step is accepted if
    the scaled residual is below ``_COL_TOL`` and the correction is small (no jump to
    another branch), otherwise it is halved.
    """
    flags, jtol = _column_flags(first, last), jnp.asarray(tol, jnp.float64)
    hist, out, frac = [(0.0, _column_mode(first, last))], [], 1.0  # (δ, z)
    for target in deltas:
        while hist[-1][0] < target:
            d_cur = hist[-1][0]
            d_max = _COL_START if d_cur == 0.0 else min(d_cur * _COL_RATIO,
                                                        d_cur + _COL_STEP)
            d = min(float(target), d_cur + frac * (d_max - d_cur))
            if len(hist) < 2:
                pred = hist[-1][1]
            else:
                (d0, z0), (d1, z1) = hist[-2:]
                t = (np.sqrt(d) - np.sqrt(d1)) / (np.sqrt(d1) - np.sqrt(d0))
                pred = z1 + t * (z1 - z0)
            z, res = _column_newton_jit(jnp.asarray(pred), jnp.asarray(d), flags, jtol)
            z, res = np.asarray(z), float(res)
            if res <= _COL_TOL and np.max(np.abs(z - pred)) <= 0.05 * (1.0 + np.max(
                    np.abs(pred))):  # False for NaN
                hist.append((d, z))
                frac = min(1.0, 2.0 * frac)
                continue
            frac *= 0.5
            if frac < 1e-6:
                raise RuntimeError(f"column continuation failed at Δ/L = {d:.6g} "
                                   f"(supports {first!r}, {last!r}; residual {res:.3e})")
        out.append(hist[-1][1])
    return out


def elastica_column_force(end_shortening, *, supports=("pinned", "pinned"),
                          length: float = 1.0, EI: float = 1.0,
                          tol: float = 1e-12) -> np.ndarray:
    """Axial force of a post-buckled planar elastica column on its first-mode branch.

    Geometry as the socbjax column builder: node 0 at the origin, axis +x, the last node
    pushed along the axis towards node 0 to ``x(L) = L - Δ``. ``supports = (first,
    last)``: first ``"clamped"`` (position fixed, tangent +x) or ``"pinned"`` (position
    fixed, zero moment); last ``"pinned"`` (``y = 0``, zero moment), ``"clamped"``
    (``y = 0``, tangent +x) or ``"free"`` (frictionless flat probe: ``y`` free, zero
    moment and lateral force). The branch is the one leaving the Euler load as
    ``Δ → 0+`` (EI/L²: π² pinned-pinned, 4π² clamped-clamped, 20.19 clamped-pinned,
    π²/4 clamped-free), found by shooting from the linear buckling mode with
    continuation in ``Δ`` through sorted inputs (validated for ``Δ/L ∈ [1e-8, 0.9]``).

    Parameters
    ----------
    end_shortening : float or array_like, shape [m]
        ``Δ`` (µm), ``0 < Δ < length``; any order, duplicates allowed.
    supports : pair of str
        ``(first, last)`` as above; ``("pinned", "free")`` is a mechanism.
    length, EI : float
        Column length (µm) and bending stiffness (pN·µm²), positive.
    tol : float
        Integrator rtol (atol ``tol Δ/L``, dimensionless state) and Newton tolerance.

    Returns
    -------
    numpy.ndarray, shape of ``end_shortening``
        Compressive axial force ``P`` (pN), positive. Raises ``RuntimeError`` if the
        continuation fails.
    """
    d, first, last, L, stiff, tol = _column_inputs(end_shortening, supports, length, EI,
                                                   tol)
    uniq, inv = np.unique(d.ravel(), return_inverse=True)
    p = np.array([z[1] for z in _column_branch(uniq, first, last, tol)])
    return (p[inv] * stiff / L**2).reshape(d.shape)


def elastica_column_shape(end_shortening: float, *, supports=("pinned", "pinned"),
                          length: float = 1.0, EI: float = 1.0, n_output: int = 101,
                          tol: float = 1e-12) -> ElasticaColumn:
    """Deflected shape of the post-buckled column at one end shortening ``Δ`` (µm).

    Same problem, conventions and arguments as :func:`elastica_column_force`. Of the two
    mirror-image branches the one with ``y > 0`` near ``Δ → 0+`` is followed (for
    clamped-pinned at large ``Δ`` the pinned end turns past π and ``y(L/2) < 0`` from
    ``Δ/L ≈ 0.85``; ``P`` turns tensile at ``Δ/L ≈ 0.812``). ``n_output``: equally
    spaced points (ends included), >= 2.

    Returns
    -------
    ElasticaColumn
        ``positions [n, 2]`` with ``positions[0] = (0, 0)``, ``positions[-1] ≈ (L - Δ,
        0)`` (lateral free for a ``"free"`` last node), ``axial_force`` ``P``,
        ``midspan_deflection`` ``y(L/2)``, ...
    """
    d, first, last, L, stiff, tol = _column_inputs(end_shortening, supports, length, EI,
                                                   tol)
    if d.ndim:
        raise ValueError(f"end_shortening must be a scalar here, got shape {d.shape}")
    n = check_count("n_output", n_output)
    d = float(d)
    z = _column_branch(np.array([d]), first, last, tol)[0]
    a = lambda v: jnp.asarray(v, dtype=jnp.float64)
    flags, args = _column_flags(first, last), (a(z), a(d))
    v = np.asarray(_column_states_jit(*args, flags, a(tol), jnp.linspace(0.0, 1.0, n)))
    mid = float(_column_states_jit(*args, flags, a(tol), jnp.full(1, 0.5))[0, 1]) * L
    res = float(_column_newton_jit(*args, flags, a(tol))[1])  # one more Newton: residual
    s = np.linspace(0.0, 1.0, n)
    P, Q = z[1] * stiff / L**2, np.sqrt(d) * z[2] * stiff / L**2
    return ElasticaColumn(
        s=a(L * s), positions=a(L * np.stack([s - v[:, 0], v[:, 1]], axis=1)),
        angle=a(v[:, 2]), moment=a(v[:, 3] * stiff / L), force=a([-P, Q]),
        axial_force=float(P), lateral_force=float(Q), end_shortening=d * L,
        midspan_deflection=mid, residual=res)
