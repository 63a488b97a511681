"""Independent reference solver for the planar elastica (Kirchhoff rod) by shooting.

Units: µm, pN; moments in pN·µm, bending stiffness ``EI`` in pN·µm². Float64 is
required: call ``jax.config.update("jax_enable_x64", True)`` (this module never changes
global config and raises ``RuntimeError`` otherwise).

Model: inextensible, unshearable planar rod, arc length ``s ∈ [0, L]``, tangent angle
``θ(s)``. With no distributed load the internal force ``n`` (exerted by the part beyond
``s`` on the part before ``s``) is constant and the state ``(x, y, θ, m)`` obeys
``x' = cos θ, y' = sin θ, θ' = m / EI, m' = -(cos θ n_y - sin θ n_x)``.

:func:`shoot_elastica` integrates this initial-value problem (``diffrax.Dopri8``, PID
step control). :func:`elastica_cantilever` solves the clamped-free problem (``n`` = tip
force, ``m(L) = 0``) by shooting on ``u = m(0) L / EI`` with ``optimistix.Newton``;
when Newton fails it scans ``u`` (``|m(0)| <= |F| L`` always holds) and bisects
(``optimistix.Bisection``) the sign change nearest the guess. With the default guess,
loads ``|F| L²/EI > 1`` are reached by a geometric load ramp with branch tracking
(quasi-static loading). Shooting sensitivity grows like ``exp(sqrt(|F| L²/EI))``; the
default path is validated for ``|F| L²/EI <= 100`` (perpendicular tip load).

Public functions validate inputs on the host (not for use inside ``jax.jit``); the
numerical cores are jitted once per ``n_output`` and reused.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

_RESIDUAL_TOL = 1e-9  # accepted |m(L)|, in units of EI / L
_N_SCAN = 257  # grid points of the bracketing fallback
_P_DIRECT = 1.0  # |F| L²/EI above which the default guess uses the load ramp
_RAMP_RATIO = 1.2


class ElasticaProfile(eqx.Module):
    """Rod sampled at ``n`` equally spaced arc lengths (both ends included).

    Attributes: ``s [n]`` (µm), ``positions [n, 2]`` (µm), ``angle [n]`` (rad),
    ``moment [n]`` (pN·µm), ``force [2]`` (pN, constant internal force).
    """

    s: jax.Array
    positions: jax.Array
    angle: jax.Array
    moment: jax.Array
    force: jax.Array


class ElasticaSolution(eqx.Module):
    """Cantilever equilibrium: :class:`ElasticaProfile` fields plus summaries.

    Extra attributes: ``tip_position [2]`` (µm), ``tip_angle`` (rad), ``base_moment``
    (pN·µm), ``converged`` (bool), ``end_moment_residual`` (``|m(L)|``, pN·µm).
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


def _checked(name: str, value, shape: tuple = (), positive: bool = False):
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    if positive and not np.all(arr > 0):
        raise ValueError(f"{name} must be positive, got {arr}")
    return arr if shape else float(arr)


def _count(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 2:
        raise ValueError(f"{name} must be an integer >= 2, got {value!r}")
    return int(value)


def _rhs(s, y, args):
    force, EI = args
    c, sn = jnp.cos(y[2]), jnp.sin(y[2])
    return jnp.stack([c, sn, y[3] / EI, -(c * force[1] - sn * force[0])])


def _trajectory(y0, force, length, EI, rtol, atol, n: int):
    """State ``[n, 4]`` at ``n`` equally spaced ``s``; NaN if the integration failed."""
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_rhs), diffrax.Dopri8(), t0=0.0, t1=length, dt0=None, y0=y0,
        args=(force, EI), saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, length, n)),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        adjoint=diffrax.ForwardMode(),  # Newton differentiates in forward mode
        max_steps=100_000, throw=False,
    )
    return jnp.where(sol.result == diffrax.RESULTS.successful, sol.ys, jnp.nan)


_shoot_jit = eqx.filter_jit(_trajectory)


def _end_moment(u, args):
    """Dimensionless end moment ``m(L) L / EI`` for base moment ``u = m(0) L / EI``."""
    base, force, length, EI, tol = args
    y0 = jnp.concatenate([base, (u * EI / length)[None]])
    return _trajectory(y0, force, length, EI, tol, tol, 2)[-1, 3] * length / EI


@eqx.filter_jit
def _newton_jit(base, force, length, EI, u0, tol):
    sol = optx.root_find(_end_moment, optx.Newton(rtol=tol, atol=tol), u0,
                         (base, force, length, EI, tol), max_steps=64, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


@eqx.filter_jit
def _scan_jit(base, force, length, EI, us, tol):
    return jax.vmap(lambda u: _end_moment(u, (base, force, length, EI, tol)))(us)


@eqx.filter_jit
def _bisect_jit(base, force, length, EI, lower, upper, tol):
    sol = optx.root_find(_end_moment, optx.Bisection(rtol=tol, atol=tol),
                         0.5 * (lower + upper), (base, force, length, EI, tol),
                         options=dict(lower=lower, upper=upper), max_steps=128,
                         throw=False)  # stalls at round-off: keep the last midpoint
    return sol.value


def shoot_elastica(base_position, base_angle, base_moment, force, *, length: float = 1.0,
                   EI: float = 1.0, n_output: int = 101, rtol: float = 1e-12,
                   atol: float = 1e-12) -> ElasticaProfile:
    """Integrate the planar elastica from ``s = 0`` to ``s = length``.

    Parameters
    ----------
    base_position : array_like, shape [2]
        ``r(0)`` (µm).
    base_angle, base_moment : float
        ``θ(0)`` (rad) and ``m(0) = EI θ'(0)`` (pN·µm).
    force : array_like, shape [2]
        Constant internal force ``n`` (pN); for a cantilever, the tip force.
    length, EI : float
        Rod length (µm) and bending stiffness (pN·µm²), positive.
    n_output : int
        Number of equally spaced output points (ends included), >= 2.
    rtol, atol : float
        Tolerances of the adaptive Dopri8 integrator.

    Returns
    -------
    ElasticaProfile
        ``s [n]``, ``positions [n, 2]``, ``angle [n]``, ``moment [n]``, ``force [2]``.
    """
    _require_x64()
    r0, f = _checked("base_position", base_position, (2,)), _checked("force", force, (2,))
    th0, m0 = _checked("base_angle", base_angle), _checked("base_moment", base_moment)
    L, stiff = _checked("length", length, positive=True), _checked("EI", EI, positive=True)
    rt, at = _checked("rtol", rtol, positive=True), _checked("atol", atol, positive=True)
    n = _count("n_output", n_output)
    a = lambda v: jnp.asarray(v, dtype=jnp.float64)  # noqa: E731
    ys = _shoot_jit(a([r0[0], r0[1], th0, m0]), a(f), a(L), a(stiff), a(rt), a(at), n)
    if not bool(jnp.all(jnp.isfinite(ys))):
        raise RuntimeError(f"shoot_elastica: integration failed (base_moment={m0}, "
                           f"force={f.tolist()}, length={L}, EI={stiff})")
    return ElasticaProfile(s=jnp.linspace(0.0, L, n), positions=ys[:, :2],
                           angle=ys[:, 2], moment=ys[:, 3], force=a(f))


def _root_near(base, force, L, EI, guess: float, tol, window: float | None) -> float:
    """Root ``u`` near ``guess``: Newton, else scan and bisect the nearest sign change.

    ``window=None`` accepts any Newton root and scans ``|u| <= 1.02 |F| L²/EI``;
    otherwise Newton must land within ``window`` of ``guess`` and the scan covers
    ``guess ± 3 window``.
    """
    u, ok = _newton_jit(base, force, L, EI, jnp.asarray(guess, jnp.float64), tol)
    u = float(u)
    if bool(ok) and np.isfinite(u) and (window is None or abs(u - guess) <= window):
        return u
    if window is None:
        bound = 1.02 * float(jnp.linalg.norm(force) * L**2 / EI)
        us = np.linspace(-bound, bound, _N_SCAN)
    else:
        us = np.linspace(guess - 3 * window, guess + 3 * window, _N_SCAN)
    vals = np.asarray(_scan_jit(base, force, L, EI, jnp.asarray(us), tol))
    brackets = np.nonzero(vals[:-1] * vals[1:] <= 0.0)[0]
    if brackets.size == 0:
        return u if np.isfinite(u) else guess  # the caller's residual check reports it
    i = int(brackets[np.argmin(np.abs(0.5 * (us[brackets] + us[brackets + 1]) - guess))])
    return float(_bisect_jit(base, force, L, EI, us[i], us[i + 1], tol))


def _solve_base_moment(base, force, L, EI, u0: float, tol, ramp: bool) -> float:
    """``u = m(0) L / EI`` with ``m(L) = 0``; optionally by a tracked load ramp."""
    p = float(jnp.linalg.norm(force) * L**2 / EI)
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


def elastica_cantilever(tip_force, *, length: float = 1.0, EI: float = 1.0,
                        base_angle: float = 0.0, base_moment_guess: float | None = None,
                        n_output: int = 101, tol: float = 1e-12,
                        raise_on_failure: bool = True) -> ElasticaSolution:
    """Cantilever clamped at the origin, fixed-direction (dead) force at the free end.

    Parameters
    ----------
    tip_force : array_like, shape [2]
        Tip force ``F`` (pN).
    length, EI : float
        Rod length (µm) and bending stiffness (pN·µm²), positive.
    base_angle : float
        Clamp angle ``θ(0)`` (rad).
    base_moment_guess : float or None
        Guess for ``m(0)`` (pN·µm); selects the branch where several equilibria exist
        (compression past buckling, very large loads). ``None``: beam-theory value
        ``L (t0 × F)``, continued by a load ramp when ``|F| L²/EI > 1``. For
        near-axial compression past buckling ``None`` may give the straight or an
        unstable branch; pass a guess near the wanted buckled state.
    n_output : int
        Number of equally spaced output points, >= 2.
    tol : float
        Integrator rtol = atol and root-finder tolerance.
    raise_on_failure : bool
        Raise ``RuntimeError`` if ``|m(L)| > 1e-9 EI / L``; if False, return the
        solution with ``converged=False`` instead.

    Returns
    -------
    ElasticaSolution
    """
    _require_x64()
    f = _checked("tip_force", tip_force, (2,))
    L, stiff = _checked("length", length, positive=True), _checked("EI", EI, positive=True)
    th0, tol = _checked("base_angle", base_angle), _checked("tol", tol, positive=True)
    n = _count("n_output", n_output)
    if base_moment_guess is None:
        m_guess = L * (np.cos(th0) * f[1] - np.sin(th0) * f[0])
    else:
        m_guess = _checked("base_moment_guess", base_moment_guess)
    a = lambda v: jnp.asarray(v, dtype=jnp.float64)  # noqa: E731
    u = _solve_base_moment(a([0.0, 0.0, th0]), a(f), a(L), a(stiff), m_guess * L / stiff,
                           a(tol), ramp=base_moment_guess is None)
    prof = shoot_elastica((0.0, 0.0), th0, u * stiff / L, f, length=L, EI=stiff,
                          n_output=n, rtol=tol, atol=tol)
    residual = abs(float(prof.moment[-1]))
    converged = residual <= _RESIDUAL_TOL * stiff / L  # False for NaN
    if raise_on_failure and not converged:
        raise RuntimeError(f"elastica_cantilever did not converge for tip_force="
                           f"{f.tolist()} pN (length={L}, EI={stiff}): "
                           f"|m(L)| = {residual:.3e} pN·µm")
    return ElasticaSolution(
        s=prof.s, positions=prof.positions, angle=prof.angle, moment=prof.moment,
        force=prof.force, tip_position=prof.positions[-1], tip_angle=prof.angle[-1],
        base_moment=prof.moment[0], converged=converged, end_moment_residual=residual)


def elastica_tip_deflection(load_parameter: float, *, n_output: int = 101,
                            tol: float = 1e-12) -> tuple[float, float]:
    """Tip displacements of the unit cantilever (``L = EI = 1``) under load ``(0, P)``.

    Parameters
    ----------
    load_parameter : float
        ``P L²/EI`` (dimensionless); the rod starts along +x.
    n_output, tol :
        As in :func:`elastica_cantilever`.

    Returns
    -------
    tuple of float
        ``(ΔX/L, ΔY/L)``: shortening ``1 - x(L)`` (positive) and deflection ``y(L)``.
    """
    p = _checked("load_parameter", load_parameter)
    sol = elastica_cantilever((0.0, p), n_output=n_output, tol=tol)
    return 1.0 - float(sol.tip_position[0]), float(sol.tip_position[1])
