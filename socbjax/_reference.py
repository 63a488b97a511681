"""Independent reference solver for the planar elastica (Kirchhoff rod) by shooting.

Units: lengths in µm, forces in pN, moments in pN·µm, bending stiffness ``EI`` in
pN·µm². All arithmetic is float64; enable it with
``jax.config.update("jax_enable_x64", True)`` (this module never flips global config).

Model: an inextensible, unshearable planar rod with arc length ``s ∈ [0, L]`` and
tangent angle ``θ(s)``. With no distributed load the internal force ``n`` (exerted by
the part beyond ``s`` on the part before ``s``) is constant, and the state
``y = (x, y, θ, m)`` obeys::

    x' = cos θ,   y' = sin θ,   θ' = m / EI,   m' = -(cos θ n_y - sin θ n_x).

:func:`shoot_elastica` integrates this initial-value problem with ``diffrax.Dopri8``
and a PID step-size controller. :func:`elastica_cantilever` solves the clamped-free
boundary-value problem (tip force ``F`` so ``n = F``; condition ``m(L) = 0``) by
shooting on the dimensionless base moment ``u = m(0) L / EI``: Newton's method
(``optimistix.Newton``) from a guess, falling back to a scan of ``u`` over the a-priori
bound ``|m(0)| <= |F| L`` followed by ``optimistix.Bisection`` on the sign change
nearest the guess. Past buckling several equilibria exist; the guess selects one.

The public functions validate their inputs on the host and are therefore not meant to
be called inside ``jax.jit``; the numerical cores are jitted and reused across calls
with identical ``n_output``/``tol``.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

_RESIDUAL_TOL = 1e-9  # accepted |m(L)| in units of EI / L
_N_SCAN = 257  # grid points of the bracketing fallback
_P_DIRECT = 1.0  # above this |F| L^2 / EI the default guess is reached by a load ramp
_RAMP_RATIO = 1.2


class ElasticaProfile(eqx.Module):
    """Shooting result sampled at ``n`` equally spaced arc lengths (ends included).

    Attributes: ``s [n]`` (µm), ``positions [n, 2]`` (µm), ``angle [n]`` (rad),
    ``moment [n]`` (pN·µm), ``force [2]`` (pN, the constant internal force).
    """

    s: jax.Array
    positions: jax.Array
    angle: jax.Array
    moment: jax.Array
    force: jax.Array


class ElasticaSolution(eqx.Module):
    """Cantilever equilibrium: the profile fields plus tip/base summaries.

    Attributes: ``s [n]``, ``positions [n, 2]``, ``angle [n]``, ``moment [n]``,
    ``force [2]`` as in :class:`ElasticaProfile`; ``tip_position [2]`` (µm),
    ``tip_angle`` (rad), ``base_moment`` (pN·µm), ``converged`` (bool) and
    ``end_moment_residual`` (``|m(L)|``, pN·µm).
    """

    s: jax.Array
    positions: jax.Array
    angle: jax.Array
    moment: jax.Array
    force: jax.Array
    tip_position: jax.Array
    tip_angle: jax.Array
    base_moment: jax.Array
    converged: bool
    end_moment_residual: float


def _require_x64() -> None:
    if not jax.config.read("jax_enable_x64"):
        raise RuntimeError("enable float64: jax.config.update('jax_enable_x64', True)")


def _scalar(name: str, value, positive: bool = False) -> float:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != ():
        raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
    if not np.isfinite(arr):
        raise ValueError(f"{name} must be finite, got {float(arr)}")
    if positive and arr <= 0:
        raise ValueError(f"{name} must be positive, got {float(arr)}")
    return float(arr)


def _vector2(name: str, value) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (2,):
        raise ValueError(f"{name} must be a 2-vector, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    return arr


def _count(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 2:
        raise ValueError(f"{name} must be an integer >= 2, got {value!r}")
    return int(value)


def _rhs(s, y, args):
    force, EI = args
    c, sn = jnp.cos(y[2]), jnp.sin(y[2])
    return jnp.stack([c, sn, y[3] / EI, -(c * force[1] - sn * force[0])])


def _trajectory(y0, force, length, EI, rtol, atol, n: int):
    """Integrate the elastica ODE; returns the state ``[n, 4]`` at n equal steps."""
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_rhs),
        diffrax.Dopri8(),
        t0=0.0,
        t1=length,
        dt0=None,
        y0=y0,
        args=(force, EI),
        saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, length, n)),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        adjoint=diffrax.ForwardMode(),  # Newton needs forward-mode derivatives
        max_steps=1_000_000,
    )
    return sol.ys


_shoot_jit = eqx.filter_jit(_trajectory)


def _end_moment(u, args):
    """Dimensionless end moment ``m(L) L / EI`` as a function of ``u = m(0) L / EI``."""
    base, force, length, EI, tol = args
    y0 = jnp.concatenate([base, (u * EI / length)[None]])
    return _trajectory(y0, force, length, EI, tol, tol, 2)[-1, 3] * length / EI


@eqx.filter_jit
def _newton_jit(base, force, length, EI, u0, tol: float):
    solver = optx.Newton(rtol=tol, atol=tol)
    args = (base, force, length, EI, tol)
    sol = optx.root_find(_end_moment, solver, u0, args, max_steps=64, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


@eqx.filter_jit
def _scan_jit(base, force, length, EI, us, tol: float):
    args = (base, force, length, EI, tol)
    return jax.vmap(lambda u: _end_moment(u, args))(us)


@eqx.filter_jit
def _bisect_jit(base, force, length, EI, lower, upper, tol: float):
    solver = optx.Bisection(rtol=tol, atol=max(tol, 1e-11))
    args = (base, force, length, EI, tol)
    opts = dict(lower=lower, upper=upper)
    sol = optx.root_find(
        _end_moment, solver, 0.5 * (lower + upper), args, options=opts,
        max_steps=256, throw=False,
    )
    return sol.value


def shoot_elastica(
    base_position,
    base_angle,
    base_moment,
    force,
    *,
    length: float = 1.0,
    EI: float = 1.0,
    n_output: int = 101,
    rtol: float = 1e-12,
    atol: float = 1e-12,
) -> ElasticaProfile:
    """Integrate the planar elastica from ``s = 0`` to ``s = length``.

    Parameters
    ----------
    base_position : array_like, shape [2]
        Position ``r(0)`` in µm.
    base_angle : float
        Tangent angle ``θ(0)`` in rad.
    base_moment : float
        Bending moment ``m(0) = EI θ'(0)`` in pN·µm.
    force : array_like, shape [2]
        Constant internal force ``n`` in pN (for a cantilever: the tip force).
    length, EI : float
        Rod length (µm) and bending stiffness (pN·µm²), both positive.
    n_output : int
        Number of equally spaced output points (both ends included), >= 2.
    rtol, atol : float
        Tolerances of the adaptive Dopri8 integration.

    Returns
    -------
    ElasticaProfile
        ``s [n]``, ``positions [n, 2]``, ``angle [n]``, ``moment [n]``, ``force [2]``.
    """
    _require_x64()
    r0 = _vector2("base_position", base_position)
    f = _vector2("force", force)
    y0 = np.array([r0[0], r0[1], _scalar("base_angle", base_angle),
                   _scalar("base_moment", base_moment)])
    L = _scalar("length", length, positive=True)
    stiff = _scalar("EI", EI, positive=True)
    n = _count("n_output", n_output)
    tols = [_scalar(k, v, positive=True) for k, v in (("rtol", rtol), ("atol", atol))]
    f64 = lambda v: jnp.asarray(v, dtype=jnp.float64)  # noqa: E731
    ys = _shoot_jit(f64(y0), f64(f), f64(L), f64(stiff), f64(tols[0]), f64(tols[1]), n)
    return ElasticaProfile(s=jnp.linspace(0.0, L, n), positions=ys[:, :2],
                           angle=ys[:, 2], moment=ys[:, 3], force=f64(f))


def _root_near(base, force, L, EI, guess: float, tol: float, window: float | None) -> float:
    """Root of the end moment near ``guess``: Newton, else scan-and-bisect.

    ``window=None``: accept any Newton root, else scan the a-priori range
    ``|m(0)| <= |F| L``. Otherwise accept Newton only within ``window`` of
    ``guess``, else scan ``guess ± 3 window``. The sign change nearest ``guess`` is bisected.
    """
    u, ok = _newton_jit(base, force, L, EI, jnp.asarray(guess, jnp.float64), tol)
    u = float(u)
    if bool(ok) and np.isfinite(u) and (window is None or abs(u - guess) <= window):
        return u
    if window is None:
        bound = 1.02 * float(jnp.linalg.norm(force)) * float(L) ** 2 / float(EI)
        us = np.linspace(-bound, bound, _N_SCAN)
    else:
        us = np.linspace(guess - 3 * window, guess + 3 * window, _N_SCAN)
    vals = np.asarray(_scan_jit(base, force, L, EI, jnp.asarray(us), tol))
    brackets = np.nonzero(vals[:-1] * vals[1:] <= 0.0)[0]
    if brackets.size == 0:
        return u  # nothing better; the caller's residual check reports the failure
    i = int(brackets[np.argmin(np.abs(0.5 * (us[brackets] + us[brackets + 1]) - guess))])
    return float(_bisect_jit(base, force, L, EI, us[i], us[i + 1], tol))


def _solve_base_moment(base, force, L, EI, u0: float, tol: float, ramp: bool) -> float:
    """Dimensionless base moment ``u = m(0) L / EI`` with ``m(L) = 0``.

    With ``ramp`` and ``|F| L²/EI > _P_DIRECT`` the load is raised geometrically from
    ``_P_DIRECT`` (quasi-static loading); each step starts from a polynomial
    extrapolation of the previous roots and must stay near it (branch tracking).
    """
    p = float(jnp.linalg.norm(force)) * float(L) ** 2 / float(EI)
    if not ramp or p <= _P_DIRECT:
        return _root_near(base, force, L, EI, u0, tol, None)
    n_steps = int(np.ceil(np.log(p / _P_DIRECT) / np.log(_RAMP_RATIO))) + 2
    lams = np.geomspace(_P_DIRECT / (_RAMP_RATIO * p), 1.0, n_steps)
    us = [_root_near(base, force * lam, L, EI, u0 * lam, tol, None) for lam in lams[:2]]
    err = np.inf  # last prediction error: roots crowd together as the load grows
    for lam in lams[2:]:  # extrapolate in the (uniform) log-load step index
        pred = 2 * us[-1] - us[-2] if len(us) == 2 else 3 * (us[-1] - us[-2]) + us[-3]
        step = abs(pred - us[-1])
        window = min(0.25 * step, max(5.0 * err, 0.02 * step)) + 1e-6 * (1.0 + abs(pred))
        us.append(_root_near(base, force * lam, L, EI, pred, tol, window))
        err = abs(us[-1] - pred)
    return us[-1]


def elastica_cantilever(
    tip_force,
    *,
    length: float = 1.0,
    EI: float = 1.0,
    base_angle: float = 0.0,
    base_moment_guess: float | None = None,
    n_output: int = 101,
    tol: float = 1e-12,
    raise_on_failure: bool = True,
) -> ElasticaSolution:
    """Cantilever clamped at the origin with a fixed-direction tip force.

    Parameters
    ----------
    tip_force : array_like, shape [2]
        Dead (fixed-direction) load at ``s = length`` in pN.
    length, EI : float
        Rod length (µm) and bending stiffness (pN·µm²), both positive.
    base_angle : float
        Clamp angle ``θ(0)`` in rad.
    base_moment_guess : float or None
        Initial guess for ``m(0)`` in pN·µm. Default: small-deflection value
        ``L (t0 × F)``. For compressive loads past buckling several equilibria exist
        (e.g. the straight one and buckled ones); the guess selects the branch
        (Newton's basin, or the bracket nearest the guess in the fallback).
    n_output : int
        Number of equally spaced output points, >= 2.
    tol : float
        Integration (rtol = atol) and root-finding tolerance.
    raise_on_failure : bool
        If True (default) raise ``RuntimeError`` when ``|m(L)| > 1e-9 EI / L``;
        otherwise return with ``converged=False``.

    Returns
    -------
    ElasticaSolution
    """
    _require_x64()
    f = _vector2("tip_force", tip_force)
    L = _scalar("length", length, positive=True)
    stiff = _scalar("EI", EI, positive=True)
    theta0 = _scalar("base_angle", base_angle)
    n = _count("n_output", n_output)
    tol = _scalar("tol", tol, positive=True)
    if base_moment_guess is None:
        m_guess = L * (np.cos(theta0) * f[1] - np.sin(theta0) * f[0])
    else:
        m_guess = _scalar("base_moment_guess", base_moment_guess)
    f64 = lambda v: jnp.asarray(v, dtype=jnp.float64)  # noqa: E731
    base = f64([0.0, 0.0, theta0])
    u = _solve_base_moment(base, f64(f), f64(L), f64(stiff), m_guess * L / stiff, tol,
                           ramp=base_moment_guess is None)
    prof = shoot_elastica((0.0, 0.0), theta0, u * stiff / L, f, length=L, EI=stiff,
                          n_output=n, rtol=tol, atol=tol)
    residual = abs(float(prof.moment[-1]))
    converged = bool(np.isfinite(residual) and residual <= _RESIDUAL_TOL * stiff / L)
    if raise_on_failure and not converged:
        raise RuntimeError(
            f"elastica_cantilever did not converge for tip_force={f.tolist()} pN "
            f"(length={L}, EI={stiff}): |m(L)| = {residual:.3e} pN·µm"
        )
    return ElasticaSolution(
        s=prof.s, positions=prof.positions, angle=prof.angle, moment=prof.moment,
        force=prof.force, tip_position=prof.positions[-1], tip_angle=prof.angle[-1],
        base_moment=prof.moment[0], converged=converged, end_moment_residual=residual,
    )


def elastica_tip_deflection(
    load_parameter: float, *, n_output: int = 101, tol: float = 1e-12
) -> tuple[float, float]:
    """Dimensionless tip displacements of the classic perpendicular-load cantilever.

    Rod along +x with ``L = EI = 1`` and tip force ``(0, P)``, ``P = PL²/EI``.

    Parameters
    ----------
    load_parameter : float
        ``P L² / EI`` (dimensionless).
    n_output, tol : see :func:`elastica_cantilever`.

    Returns
    -------
    (float, float)
        ``(ΔX/L, ΔY/L)``: shortening ``1 - x(L)`` (positive) and deflection ``y(L)``.
    """
    p = _scalar("load_parameter", load_parameter)
    sol = elastica_cantilever((0.0, p), n_output=n_output, tol=tol)
    return 1.0 - float(sol.tip_position[0]), float(sol.tip_position[1])
