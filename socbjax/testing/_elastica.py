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

:func:`elastica_kinked_cantilever` is the same cantilever made of two straight parts
(lengths and ``EI`` each) joined by a rigid corner: the tangent angle jumps by
``kink_angle`` while position and moment are continuous; same shooting, scan and load
ramp, on ``m(0)`` with the end moment of part 2 as residual.

:func:`elastica_column_force` / :func:`elastica_column_shape` solve the post-buckled
column of the socbjax column builder (node 0 at the origin, axis +x, last node pushed
to ``x(L) = L - Δ``; supports clamped/pinned first, clamped/pinned/free last) on the
first-mode branch. Dimensionless (``L = EI = 1``) shooting with state ``(s - x, y, θ,
m)`` (no cancellation at small ``Δ``), internal force ``(-P, Q)``, unknowns base
moment or angle, ``P`` and ``Q`` scaled by ``√δ`` (``δ = Δ/L``), three-component
``optimistix.Newton``; continuation in ``√δ`` from the linear buckling mode (smallest
root of the 4×4 boundary determinant) through the sorted inputs.

Public functions validate inputs on the host (not for use inside ``jax.jit``); the
numerical cores are jitted once (per residual, per ``n_output``) and reused.
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


def require_x64() -> None:
    if not jax.config.read("jax_enable_x64"):
        raise RuntimeError("enable float64: jax.config.update('jax_enable_x64', True)")


def check_value(name: str, value, shape: tuple = (), positive: bool = False):
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    if positive and not np.all(arr > 0):
        raise ValueError(f"{name} must be positive, got {arr}")
    return arr if shape else float(arr)


def check_count(name: str, value) -> int:
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


def _kinked_end_moment(u, args):
    """``m(L1 + L2) Lt / EI1`` for ``u = m(0) Lt / EI1`` (``Lt = L1 + L2``), kinked rod."""
    base, force, lengths, EIs, kink, tol = args
    scale = (lengths[0] + lengths[1]) / EIs[0]
    y = _trajectory(jnp.concatenate([base, (u / scale)[None]]), force, lengths[0], EIs[0],
                    tol, tol, 2)[-1]
    y = y.at[2].add(kink)  # rigid corner: the tangent turns, r and m are continuous
    return _trajectory(y, force, lengths[1], EIs[1], tol, tol, 2)[-1, 3] * scale


# Root-finding cores, generic in the residual ``fn(u, args)`` (static: one compilation
# per residual); ``args[1]`` is the force and ``args[-1]`` the tolerance.
@eqx.filter_jit
def _newton_jit(fn, args, u0, tol):
    sol = optx.root_find(fn, optx.Newton(rtol=tol, atol=tol), u0, args, max_steps=64,
                         throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


@eqx.filter_jit
def _scan_jit(fn, args, us):
    return jax.vmap(lambda u: fn(u, args))(us)


@eqx.filter_jit
def _bisect_jit(fn, args, lower, upper, tol):
    sol = optx.root_find(fn, optx.Bisection(rtol=tol, atol=tol), 0.5 * (lower + upper),
                         args, options={"lower": lower, "upper": upper}, max_steps=128,
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
    require_x64()
    r0, f = check_value("base_position", base_position, (2,)), check_value("force", force, (2,))
    th0, m0 = check_value("base_angle", base_angle), check_value("base_moment", base_moment)
    L, stiff = check_value("length", length, positive=True), check_value("EI", EI, positive=True)
    rt, at = check_value("rtol", rtol, positive=True), check_value("atol", atol, positive=True)
    n = check_count("n_output", n_output)
    a = lambda v: jnp.asarray(v, dtype=jnp.float64)
    ys = _shoot_jit(a([r0[0], r0[1], th0, m0]), a(f), a(L), a(stiff), a(rt), a(at), n)
    if not bool(jnp.all(jnp.isfinite(ys))):
        raise RuntimeError(f"shoot_elastica: integration failed (base_moment={m0}, "
                           f"force={f.tolist()}, length={L}, EI={stiff})")
    return ElasticaProfile(s=jnp.linspace(0.0, L, n), positions=ys[:, :2],
                           angle=ys[:, 2], moment=ys[:, 3], force=a(f))


def _root_near(fn, args, guess: float, bound: float, window: float | None, mode: str = "auto") -> float:
    """Root ``u`` of ``fn(u, args)`` near ``guess``: Newton, else scan and bisect (``mode``:
    "auto"; "newton" never falls back; "bracketing" skips Newton).

    ``window=None`` accepts any Newton root and scans ``|u| <= bound``; otherwise Newton
    must land within ``window`` of ``guess`` and the scan covers ``guess ± 3 window``.
    The sign change nearest ``guess`` is bisected.
    """
    tol = args[-1]
    u, ok = (guess, False) if mode == "bracketing" else _newton_jit(fn, args, jnp.asarray(guess, jnp.float64), tol)
    u = float(u)
    if mode == "newton" or (bool(ok) and np.isfinite(u) and (window is None or abs(u - guess) <= window)):
        return u
    if window is None:
        us = np.linspace(-bound, bound, _N_SCAN)
    else:
        us = np.linspace(guess - 3 * window, guess + 3 * window, _N_SCAN)
    vals = np.asarray(_scan_jit(fn, args, jnp.asarray(us)))
    brackets = np.nonzero(vals[:-1] * vals[1:] <= 0.0)[0]
    if brackets.size == 0:
        return u if np.isfinite(u) else guess  # the caller's residual check reports it
    i = int(brackets[np.argmin(np.abs(0.5 * (us[brackets] + us[brackets + 1]) - guess))])
    return float(_bisect_jit(fn, args, us[i], us[i + 1], tol))


def _solve_base_moment(fn, args, u0: float, p: float, ramp: bool, mode: str = "auto") -> float:
    """Root ``u`` of ``fn(u, args)`` (dimensionless base moment); optionally by a load ramp.

    ``p``: dimensionless load (``|F| L²/EI``); the roots obey ``|u| <= p`` and the scan
    covers ``|u| <= 1.02 p``. The ramp scales the force ``args[1]`` geometrically.
    """
    if not ramp or p <= _P_DIRECT:
        return _root_near(fn, args, u0, 1.02 * p, None, mode)
    scaled = lambda lam: (args[0], args[1] * lam, *args[2:])
    n_steps = int(np.ceil(np.log(p / _P_DIRECT) / np.log(_RAMP_RATIO))) + 2
    lams = np.geomspace(_P_DIRECT / (_RAMP_RATIO * p), 1.0, n_steps)
    us = [_root_near(fn, scaled(lam), u0 * lam, 1.02 * p * lam, None, mode) for lam in lams[:2]]
    err = np.inf  # last prediction error: roots crowd together as the load grows
    for lam in lams[2:]:  # extrapolate in the (uniform) log-load step index
        pred = 2 * us[-1] - us[-2] if len(us) == 2 else 3 * (us[-1] - us[-2]) + us[-3]
        step = abs(pred - us[-1])
        window = min(0.25 * step, max(5.0 * err, 0.02 * step)) + 1e-6 * (1.0 + abs(pred))
        us.append(_root_near(fn, scaled(lam), pred, 1.02 * p * lam, window, mode))
        err = abs(us[-1] - pred)
    return us[-1]


def elastica_cantilever(tip_force, *, length: float = 1.0, EI: float = 1.0,
                        base_angle: float = 0.0, base_moment_guess: float | None = None,
                        n_output: int = 101, tol: float = 1e-12,
                        raise_on_failure: bool = True, root_finder: str = "auto") -> ElasticaSolution:
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
    root_finder : "auto" (Newton on the base moment, with a scan + bisection fallback),
        "newton" (no fallback) or "bracketing" (scan + bisection only).

    Returns
    -------
    ElasticaSolution
    """
    require_x64()
    f = check_value("tip_force", tip_force, (2,))
    L, stiff = check_value("length", length, positive=True), check_value("EI", EI, positive=True)
    th0, tol = check_value("base_angle", base_angle), check_value("tol", tol, positive=True)
    n = check_count("n_output", n_output)
    if root_finder not in ("auto", "newton", "bracketing"):
        raise ValueError(f"root_finder must be 'auto', 'newton' or 'bracketing', got {root_finder!r}")
    if base_moment_guess is None:
        m_guess = L * (np.cos(th0) * f[1] - np.sin(th0) * f[0])
    else:
        m_guess = check_value("base_moment_guess", base_moment_guess)
    a = lambda v: jnp.asarray(v, dtype=jnp.float64)
    u = _solve_base_moment(_end_moment, (a([0.0, 0.0, th0]), a(f), a(L), a(stiff), a(tol)),
                           m_guess * L / stiff, float(np.linalg.norm(f)) * L**2 / stiff,
                           ramp=base_moment_guess is None, mode=root_finder)
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
    p = check_value("load_parameter", load_parameter)
    sol = elastica_cantilever((0.0, p), n_output=n_output, tol=tol)
    return 1.0 - float(sol.tip_position[0]), float(sol.tip_position[1])


def _pair(name: str, value):
    """A positive pair ``[2]`` from a scalar or a pair."""
    arr = np.asarray(value, dtype=np.float64)
    return check_value(name, np.broadcast_to(arr, (2,)) if arr.ndim == 0 else arr, (2,), True)


def elastica_kinked_cantilever(tip_force, *, lengths=(0.5, 0.5), kink_angle: float,
                               EI=1.0, base_angle: float = 0.0,
                               base_moment_guess: float | None = None, n_output: int = 101,
                               tol: float = 1e-12,
                               raise_on_failure: bool = True) -> ElasticaSolution:
    """Cantilever of two straight parts joined by a rigid corner, dead force at the tip.

    Part 1 (length ``L1``, stiffness ``EI1``) is clamped at the origin with tangent angle
    ``base_angle``. At its end the tangent angle jumps by ``kink_angle`` while position
    and bending moment are continuous (the corner transmits force and moment). Part 2
    (``L2``, ``EI2``) ends free, loaded by ``tip_force`` with zero end moment; the
    internal force equals ``tip_force`` everywhere. Solved by shooting on ``m(0)``
    (:func:`elastica_cantilever`'s Newton / scan-and-bisect / load ramp, with
    ``p = |F| (L1 + L2)² / min(EI)``).

    Parameters
    ----------
    tip_force : array_like, shape [2]
        Tip force ``F`` (pN).
    lengths : pair of float
        ``(L1, L2)`` (µm), positive.
    kink_angle : float
        Jump of the tangent angle at the corner (rad, counter-clockwise positive).
    EI : float or pair of float
        Bending stiffness (pN·µm²) of both parts, or ``(EI1, EI2)``; positive.
    base_angle : float
        Clamp angle ``θ(0)`` (rad).
    base_moment_guess : float or None
        Guess for ``m(0)`` (pN·µm), selecting the branch; ``None``: linear theory
        ``r0_tip × F`` of the undeformed tip, continued by a load ramp when ``p > 1``.
    n_output, tol, raise_on_failure :
        As in :func:`elastica_cantilever`; ``n_output`` points per part.

    Returns
    -------
    ElasticaSolution
        ``s [2 n_output]`` (µm; ``s = L1`` appears twice: the corner before and after
        the jump), ``positions [2 n, 2]``, ``angle``, ``moment [2 n]``, ``force [2]``;
        ``tip_position``, ``tip_angle``, ``base_moment``, ``converged`` and
        ``end_moment_residual`` (``|m(L1 + L2)|``, pN·µm).
    """
    require_x64()
    f = check_value("tip_force", tip_force, (2,))
    (L1, L2), (EI1, EI2) = _pair("lengths", lengths), _pair("EI", EI)
    kink, th0 = check_value("kink_angle", kink_angle), check_value("base_angle", base_angle)
    tol, n = check_value("tol", tol, positive=True), check_count("n_output", n_output)
    if base_moment_guess is None:
        tip0 = L1 * np.array([np.cos(th0), np.sin(th0)]) + L2 * np.array(
            [np.cos(th0 + kink), np.sin(th0 + kink)])
        m_guess = tip0[0] * f[1] - tip0[1] * f[0]
    else:
        m_guess = check_value("base_moment_guess", base_moment_guess)
    a = lambda v: jnp.asarray(v, dtype=jnp.float64)
    Lt = L1 + L2
    args = (a([0.0, 0.0, th0]), a(f), a([L1, L2]), a([EI1, EI2]), a(kink), a(tol))
    u = _solve_base_moment(_kinked_end_moment, args, m_guess * Lt / EI1,
                           float(np.linalg.norm(f)) * Lt**2 / min(EI1, EI2),
                           ramp=base_moment_guess is None)
    one = shoot_elastica((0.0, 0.0), th0, u * EI1 / Lt, f, length=L1, EI=EI1,
                         n_output=n, rtol=tol, atol=tol)
    two = shoot_elastica(one.positions[-1], float(one.angle[-1]) + kink,
                         float(one.moment[-1]), f, length=L2, EI=EI2, n_output=n,
                         rtol=tol, atol=tol)
    residual = abs(float(two.moment[-1]))
    converged = residual <= _RESIDUAL_TOL * min(EI1, EI2) / Lt  # False for NaN
    if raise_on_failure and not converged:
        raise RuntimeError(f"elastica_kinked_cantilever did not converge for tip_force="
                           f"{f.tolist()} pN (lengths={[L1, L2]}, EI={[EI1, EI2]}, "
                           f"kink_angle={kink}): |m(L)| = {residual:.3e} pN·µm")
    cat = lambda p, q: jnp.concatenate([p, q])
    return ElasticaSolution(
        s=cat(one.s, L1 + two.s), positions=cat(one.positions, two.positions),
        angle=cat(one.angle, two.angle), moment=cat(one.moment, two.moment), force=one.force,
        tip_position=two.positions[-1], tip_angle=two.angle[-1], base_moment=one.moment[0],
        converged=converged, end_moment_residual=residual)
