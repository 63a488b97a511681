"""Least-squares fits of model parameters to a force–compression curve: :func:`fit`.

Model.  For parameter values θ the predicted force at a data compression cᵢ (µm) is

    F̂ᵢ = force_scale · F(cᵢ + contact_offset; θ) + baseline,   F = 0 before contact,

where F(u; θ) is the probe force of the model (:mod:`socbjax._models`) at probe
displacement u, computed by :func:`socbjax.compress` with ``at=`` the data compressions: the
path is followed adaptively through buckling and collapse, and every data point is then
solved *exactly* (no interpolation across a sharp force drop), with derivatives by the
implicit function theorem.  The loss is ½ Σ (F̂ᵢ − Fᵢ)² (pN²) over the chosen branch
(approach/loading by default).  Curves with more than ``max_points`` points are averaged in
compression bins first.

Optimisers.  ``"lm"`` (default): Levenberg–Marquardt on the unconstrained parameters (bounds
by transforms, :class:`socbjax.Parameter`) with Marquardt's diagonal scaling; the residual
Jacobian costs one linear solve per parameter and data point.  A step is taken only if the
loss decreases; otherwise the damping grows ×4 and the step is retried, which also rejects
steps into a region where the path cannot be followed — this is what keeps the fit robust at
the collapse, where the force and its derivatives change fast.  ``"adam"`` and ``"lbfgs"``
(optax) minimise the same loss with ``jax.value_and_grad``.

Uncertainties (Gauss–Newton).  With J the residual Jacobian in the unconstrained variables
z at the optimum, s² = Σ r²/(m − p) and Cz = s² (JᵀJ)⁻¹; the values' covariance is
D Cz D with D = dθ/dz (delta method).  Standard errors are its square roots and the
correlation matrix its normalisation.  A correlation of magnitude ≥ 0.995 (or a singular
JᵀJ) marks the fit as not identifiable; fitting ``force_scale`` together with every EI is
refused up front: the force of an elastica scales exactly with EI at fixed geometry, so one
curve determines only the product EI × force_scale.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from ._afm import ForceCurve
from ._models import FitModel, make_fit_model
from ._parameters import NUISANCE_PARAMETERS

__all__ = ["fit", "FitResult", "fit_problem"]

OPTIMIZERS = ("lm", "adam", "lbfgs")
BRANCHES = ("loading", "unloading")
_CORRELATION_LIMIT = 0.995


@dataclasses.dataclass(eq=False)
class FitResult:
    """Outcome of :func:`fit`.  Units: µm, pN, pN·µm², degrees (see ``units``).

    names : the free parameters, in the order of ``correlation``.
    values : every parameter the model was evaluated with (fitted and fixed).
    standard_errors : Gauss–Newton standard error of each free parameter.
    correlation, covariance : [p, p] over the free parameters.
    loss : final ½ Σ r² with r = (model − data)/σ (pN² when unweighted); rms : √(mean
        (model − data)²) (pN).
    converged, message : whether the optimiser met its tolerance, and why it stopped.
    identifiable : False when two free parameters are (nearly) perfectly correlated or JᵀJ is
        singular — then the values are not determined by the data (see ``warnings``).
    history : per iteration ``{"iteration", "loss", "values", "damping"}``.
    compression, force, model_force, residuals : [m] the data points fitted and the model.
    """

    model: str
    names: tuple
    values: dict
    standard_errors: dict
    correlation: np.ndarray
    covariance: np.ndarray
    loss: float
    rms: float
    converged: bool
    message: str
    identifiable: bool
    warnings: list
    history: list
    compression: np.ndarray
    force: np.ndarray
    model_force: np.ndarray
    units: dict
    optimizer: str
    n_evaluations: int
    elapsed_s: float

    @property
    def residuals(self) -> np.ndarray:
        return self.model_force - self.force

    def summary(self) -> str:
        lines = [f"fit of {self.model} ({self.optimizer}): {self.message}; loss {self.loss:.4g} pN², "
                 f"rms {self.rms:.4g} pN over {self.force.size} points"]
        for name in self.names:
            lines.append(f"  {name:<14s} = {self.values[name]:.6g} ± {self.standard_errors[name]:.2g} {self.units[name]}")
        fixed = [n for n in self.values if n not in self.names]
        if fixed:
            lines.append("  fixed: " + ", ".join(f"{n} = {self.values[n]:.4g} {self.units[n]}" for n in fixed))
        lines.extend(f"  WARNING: {w}" for w in self.warnings)
        return "\n".join(lines)

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for key in ("correlation", "covariance", "compression", "force", "model_force"):
            out[key] = np.asarray(out[key]).tolist()
        out["residuals"] = self.residuals.tolist()
        return json.loads(json.dumps(out, default=float))

    def save(self, path) -> None:
        """Write the result as JSON, atomically (temporary file, then rename)."""
        from ._io import _atomic_path

        text = json.dumps(self.to_dict(), indent=2)
        _atomic_path(path, lambda tmp: tmp.write_text(text))


# ------------------------------------------------------------------------- set-up checks
def _data(curve, branch: str, max_points: int, min_compression):
    if isinstance(curve, ForceCurve):
        segment = 0 if branch == "loading" else 1
        part = curve if np.all(curve.segment == segment) else (curve.approach if segment == 0 else curve.retract)
        if len(part) == 0 or part.compression.max() <= 0:
            raise ValueError(f"the {branch} branch never passes the contact point (no compression > 0): nothing to fit")
        low = -0.25 * part.compression.max() if min_compression is None else float(min_compression)
        part = part.select(min_compression=low)
        if len(part) > max_points:
            part = part.binned(max_points)
        c, F = np.asarray(part.compression, float), np.asarray(part.force, float)
    else:
        try:
            c, F = (np.asarray(a, float) for a in curve)
        except (TypeError, ValueError) as err:
            raise TypeError("curve must be a socbjax.ForceCurve or a pair (compression µm, force pN)") from err
        if c.ndim != 1 or c.shape != F.shape:
            raise ValueError(f"compression and force must be 1-D arrays of equal length, got {c.shape} and {F.shape}")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(F))):
            bad = int(np.sum(~np.isfinite(c)) + np.sum(~np.isfinite(F)))
            raise ValueError(f"the curve contains {bad} NaN/inf values; drop those points before fitting")
        if c.size and np.any(np.diff(c) < 0):
            raise ValueError(
                "compression must be non-decreasing along the curve (one branch, sorted); sort the points, or load "
                "a measured curve with socbjax.load_curve, which separates approach and retract"
            )
        if min_compression is not None:
            keep = c >= float(min_compression)
            c, F = c[keep], F[keep]
    if c.size < 3:
        raise ValueError(f"the {branch} branch has {c.size} points; a fit needs at least 3")
    if c.max() <= 0:
        raise ValueError("the curve never passes the contact point (all compressions ≤ 0): nothing to fit")
    return c, F


def _parameter_table(model: FitModel, free, fixed, initial, bounds):
    table = {**model.parameters, **NUISANCE_PARAMETERS}
    free = tuple(free.split(",")) if isinstance(free, str) else tuple(free)
    fixed, initial, bounds = dict(fixed or {}), dict(initial or {}), dict(bounds or {})
    for name in (*free, *fixed, *initial, *bounds):
        if name not in table:
            raise ValueError(f"unknown parameter {name!r} for model {model.name}; known: {sorted(table)}")
    if not free:
        raise ValueError("no free parameters: name at least one in free=, e.g. free=('EI',)")
    both = set(free) & set(fixed)
    if both or len(set(free)) != len(free):
        raise ValueError(f"parameters listed twice or both free and fixed: {sorted(both) or free}")
    for name, (lo, hi) in bounds.items():
        table[name] = table[name].with_bounds(lo, hi)
    for name in initial:
        if name not in free:
            raise ValueError(f"initial value given for {name!r}, which is not free; use fixed= for fixed values")
    fixed = {n: table[n].check(v, "fixed value") for n, v in fixed.items()}
    start = {n: table[n].check(initial.get(n, table[n].value), "initial value") for n in free}
    return table, free, fixed, start


def _check_identifiable(model: FitModel, free, fixed) -> None:
    if "force_scale" not in free:
        return
    source = np.full(model.base.n_segments, "EI", dtype=object)  # the parameter each segment's EI comes from
    for name, mask in model.groups.items():
        if name in free or name in fixed:
            source[mask] = name
    ei_free = sorted(set(source) & set(free))
    if all(name in free for name in source):
        raise ValueError(
            f"force_scale and {', '.join(ei_free)} are not separately identifiable from one curve: at fixed geometry "
            "the force scales with EI (exactly with the default perturbation, which scales with EI), "
            "F ∝ EI × force_scale, so only their product is determined. "
            "Fix one of them, e.g. fixed={'force_scale': 1.0} (one outcrop under the probe) or fix EI"
        )


# ----------------------------------------------------------------------- the residuals
def _sigma(sigma, m: int, curve) -> np.ndarray:
    """Per-point force uncertainty [m] (pN): 1 (unweighted), a scalar, or one per point."""
    if sigma is None:
        return np.ones(m)
    s = np.asarray(sigma, float)
    if s.ndim == 1 and isinstance(curve, ForceCurve) and s.size != m:
        raise ValueError("per-point sigma needs the curve as (compression, force) arrays (ForceCurves may be binned)")
    s = np.broadcast_to(s, (m,)) if s.ndim == 0 else s
    if s.shape != (m,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError(f"sigma must be positive and finite, a scalar or one value per point ({m}), got shape {s.shape}")
    return np.array(s)


def fit_problem(curve, model="unit-mesh", *, free=("EI",), fixed=None, initial=None, bounds=None, branch="loading",
                max_points: int = 80, min_compression=None, method: str = "displacement", settings=None,
                model_options=None, sigma=None) -> dict:
    """Everything :func:`fit` optimises, checked and assembled (no optimisation): a dict with
    ``residuals`` (z [p] -> r [m]: (model − data)/σ; traced, differentiable; NaN where the
    path cannot be followed, or a ``ConvergenceError`` with ``throw=True`` untraced), ``to_values`` (z -> dict),
    ``z0``, the data arrays, the parameter ``table`` and the model.  Useful to evaluate
    the loss or its gradient at chosen values (e.g. to check gradients)."""
    if branch not in BRANCHES:
        raise ValueError(f"branch must be one of {BRANCHES}, got {branch!r}")
    if int(max_points) < 3:
        raise ValueError(f"max_points must be at least 3, got {max_points!r}")
    model = make_fit_model(model, **(model_options or {}))
    free = tuple(n.strip() for n in free.split(",")) if isinstance(free, str) else tuple(free)
    c, F = _data(curve, branch, int(max_points), min_compression)
    bounds = dict(bounds or {})
    if "contact_offset" in free and "contact_offset" not in bounds:
        # the offset moves the contact point within the data's own range: beyond it the model
        # would be sampled past the data (or entirely before contact) and the fit is degenerate
        bounds["contact_offset"] = (-0.5 * float(c.max()), 0.1 * float(c.max()))
    table, free, fixed, start = _parameter_table(model, free, fixed, initial, bounds)
    _check_identifiable(model, free, fixed)
    offset_room = max(0.0, table["contact_offset"].upper or 0.0) if "contact_offset" in free else 0.0
    reach = float(c.max()) + max(fixed.get("contact_offset", start.get("contact_offset", 0.0)), 0.0) + offset_room
    if reach >= model.gap:
        raise ValueError(
            f"the curve reaches {float(c.max()):.4g} µm of compression (plus contact offset), but the {model.name} model "
            f"can be compressed by less than {model.gap:.4g} µm (probe–surface gap); crop the curve, e.g. "
            f"curve.select(max_compression={0.9 * model.gap:.3g}), or use a model with a larger gap"
        )
    physical = [n for n in (*free, *fixed) if n in model.parameters]

    def to_values(z):
        values = {n: table[n].to_value(z[i]) for i, n in enumerate(free)}
        return {**fixed, **values}

    sigma = _sigma(sigma, c.size, curve)
    c_j, F_j, sigma_j = jnp.asarray(c), jnp.asarray(F), jnp.asarray(sigma)
    unload = branch == "unloading"
    floor = 1e-6 * reach

    def residuals(z, throw: bool = False):
        from ._compress import compress

        values = to_values(z)
        network = model.network({n: values[n] for n in physical})
        u = c_j + values.get("contact_offset", 0.0)
        result = compress(network, reach, at=jnp.clip(u, floor, reach), unload=unload, method=method,
                          settings=settings, perturbation=values.get("perturbation"), throw=throw)
        force = result.force[c.size:][::-1] if unload else result.force
        predicted = values.get("force_scale", 1.0) * jnp.where(u > 0, force, 0.0) + values.get("baseline", 0.0)
        # a path that fails at these values gives NaN residuals: the optimiser rejects the step
        return jnp.where(jnp.all(result.converged), (predicted - F_j) / sigma_j, jnp.nan)

    z0 = jnp.asarray([table[n].to_z(start[n]) for n in free])
    return dict(residuals=residuals, to_values=to_values, z0=z0, compression=c, force=F, sigma=sigma, table=table,
                free=free, fixed=fixed, model=model, reach=reach)


class _Progress:
    def __init__(self, enabled: bool, total: int):
        self.enabled, self.total = enabled, total

    def __call__(self, iteration: int, loss: float, values: dict, done: bool = False):
        if not self.enabled:
            return
        bar = "#" * int(30 * min(iteration / max(self.total, 1), 1.0))
        shown = " ".join(f"{k}={float(v):.4g}" for k, v in values.items())
        sys.stderr.write(f"\r fit [{bar:<30s}] it {iteration:3d} loss {loss:.4e} {shown}" + ("\n" if done else ""))
        sys.stderr.flush()


def _float_values(values: dict) -> dict:
    return {k: float(v) for k, v in values.items()}


def _levenberg_marquardt(jac, z, max_iterations, tolerance, report):
    """Minimise ½|r(z)|²; ``jac(z)`` -> (J [m, p], r [m]).  Returns (z, r, J, history, converged,
    message, evaluations)."""
    J, r = (np.asarray(a) for a in jac(z))
    loss, damping, history, evaluations = 0.5 * float(r @ r), 1e-3, [], 1
    converged, message = False, f"reached max_iterations={max_iterations}"
    for iteration in range(1, max_iterations + 1):
        A, g = J.T @ J, J.T @ r
        scale = np.maximum(np.diag(A), 1e-12 * max(np.diag(A).max(), 1e-300))
        if np.max(np.abs(g) / np.sqrt(scale)) <= tolerance * max(math.sqrt(2 * loss), 1e-300):
            converged, message = True, "converged (gradient below tolerance)"
            break
        for _ in range(12):
            step = np.linalg.solve(A + damping * np.diag(scale), -g)
            trial = z + step
            J_new, r_new = (np.asarray(a) for a in jac(jnp.asarray(trial)))
            # NaN residuals: the path could not be followed at the trial values; reject the step
            loss_new = 0.5 * float(r_new @ r_new) if np.all(np.isfinite(r_new)) and np.all(np.isfinite(J_new)) else math.inf
            evaluations += 1
            if loss_new < loss:
                break
            damping *= 4.0
        else:
            message = "stopped: no step decreased the loss (at a minimum to within the path's accuracy)"
            converged = True
            break
        decrease = loss - loss_new
        z, J, r, loss, damping = jnp.asarray(trial), J_new, r_new, loss_new, max(damping / 3.0, 1e-9)
        history.append({"iteration": iteration, "loss": loss, "damping": damping, "z": np.asarray(z).tolist()})
        report(iteration, loss)
        if decrease <= tolerance * loss or np.max(np.abs(step)) <= tolerance * (1.0 + float(np.max(np.abs(z)))):
            converged, message = True, "converged (relative loss decrease or step below tolerance)"
            break
    return z, r, J, history, converged, message, evaluations


def _optax(loss_and_grad, loss_fn, z, optimizer, max_iterations, tolerance, learning_rate, report):
    import optax

    opt = optax.adam(learning_rate) if optimizer == "adam" else optax.lbfgs()
    state, history, previous = opt.init(z), [], math.inf
    converged, message = False, f"reached max_iterations={max_iterations}"
    for iteration in range(1, max_iterations + 1):
        loss, grad = loss_and_grad(z)
        if not (np.isfinite(float(loss)) and np.all(np.isfinite(np.asarray(grad)))):
            z = jnp.asarray(history[-2]["z"]) if len(history) > 1 else z
            message = (f"stopped at iteration {iteration}: the path could not be followed at the optimiser's step; "
                       "use optimizer='lm' (which rejects such steps) or a smaller learning_rate")
            break
        if optimizer == "lbfgs":
            updates, state = opt.update(grad, state, z, value=loss, grad=grad, value_fn=loss_fn)
        else:
            updates, state = opt.update(grad, state, z)
        z = optax.apply_updates(z, updates)
        history.append({"iteration": iteration, "loss": float(loss), "damping": None, "z": np.asarray(z).tolist()})
        report(iteration, float(loss), z)
        if abs(previous - float(loss)) <= tolerance * float(loss):
            converged, message = True, "converged (relative loss change below tolerance)"
            break
        previous = float(loss)
    return z, history, converged, message, iteration


# ------------------------------------------------------------------------------ fit
def _check_start(residuals, problem) -> None:
    """Evaluate the model once at the initial values, untraced, so that a path that cannot be
    followed over the data's range fails here with the solver's own message."""
    from ._solve import ConvergenceError

    try:
        r = np.asarray(residuals(problem["z0"], throw=True))
    except ConvergenceError as err:
        raise ValueError(
            f"the model cannot be evaluated over the data's compression range (up to {problem['reach']:.4g} µm) at the "
            f"initial values: {err} Crop the curve (max_compression), use method='arclength', or start elsewhere"
        ) from None
    if not np.all(np.isfinite(r)):
        raise ValueError("the model gives non-finite forces at the initial values")


def _with_value(fn):
    def both(z):
        r = fn(z)
        return r, r

    return both


def _uncertainties(J, r, z, table, free):
    """Gauss–Newton covariance of the values, correlation, identifiability and warnings."""
    m, p = J.shape
    s2 = float(r @ r) / max(m - p, 1)
    A = J.T @ J
    warnings = []
    for i, name in enumerate(free):
        lo, hi = table[name].lower, table[name].upper
        value = float(table[name].to_value(float(z[i])))
        near = 1e-3 * (hi - lo) if lo is not None and hi is not None else 1e-9 * max(abs(value), 1e-300)
        if (lo is not None and value - lo <= near) or (hi is not None and hi - value <= near):
            warnings.append(f"{name} = {value:.4g} {table[name].unit} is at its bound ({lo}, {hi}): the data push it "
                            "further, the model does not describe them there; its error is not meaningful")
    cond = np.linalg.cond(A) if p else 1.0
    D = np.array([float(jax.grad(table[n].to_value)(float(z[i]))) for i, n in enumerate(free)])
    singular = not np.isfinite(cond) or cond > 1e14
    if singular:
        warnings.append(f"JᵀJ is singular (condition number {cond:.3g}): the data do not determine all of {list(free)}")
        cov = np.full((p, p), np.inf)
    else:
        cov = D[:, None] * (s2 * np.linalg.inv(A)) * D[None, :]
    se = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    identifiable = not singular
    for i in range(p):
        for j in range(i + 1, p):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) >= _CORRELATION_LIMIT:
                identifiable = False
                warnings.append(f"{free[i]} and {free[j]} are correlated {corr[i, j]:+.4f}: not separately identifiable "
                                "from this curve; fix one of them")
    return se, corr, cov, identifiable, warnings


def fit(curve, model="unit-mesh", *, free=("EI",), fixed: dict | None = None, initial: dict | None = None,
        bounds: dict | None = None, branch: str = "loading", optimizer: str = "lm", max_iterations: int = 30,
        tolerance: float = 1e-8, learning_rate: float = 0.05, max_points: int = 80, min_compression=None,
        method: str = "displacement",
        settings=None, model_options: dict | None = None, sigma=None, progress: bool = False) -> FitResult:
    """Fit model parameters to a force–compression curve (see the module docstring).

    Parameters
    ----------
    curve : a :class:`socbjax.ForceCurve` (e.g. from :func:`socbjax.load_curve`) or a pair
        (compression µm [m], force pN [m]), compression positive into the sample.
    model : "column", "unit-mesh", "outcrop" or a :class:`socbjax.FitModel`;
        ``model_options`` go to its constructor (e.g. ``{"dim": 3}``).
    free : names of the fitted parameters (tuple, or comma-separated string): the model's
        (``EI``, ``EI_mother``, ``EI_gen1``, ``branch_angle``, ``perturbation``, …) and the
        data's ``contact_offset`` (µm), ``baseline`` (pN), ``force_scale``.
    fixed : name -> value for parameters held at a value other than their default.
    initial : name -> starting value of free parameters (default: the parameter defaults).
    bounds : name -> (lower, upper) replacing a parameter's bounds (None: open side).  A free
        ``contact_offset`` is bounded to (−½, +0.1) × the data's maximum compression by default.
    branch : "loading" (approach, default) or "unloading" (retract).
    optimizer : "lm" (Levenberg–Marquardt, default), "adam" or "lbfgs" (optax).
    max_iterations, tolerance : optimiser limits (relative loss decrease / step size).
    learning_rate : Adam's step size in the unconstrained variables.
    max_points : curves with more points are averaged in this many compression bins.
    min_compression : drop points below this compression (µm); default for a ForceCurve
        −¼ of its maximum compression (some baseline before contact, not the whole approach).
    method, settings : path following of :func:`socbjax.compress`: "displacement" (default,
        the AFM's own control; stops with a clear error at a fold) or "arclength" (follows
        snap-throughs; samples then take the first crossing of each compression).
    sigma : force uncertainty per point (pN; scalar or [m] for array curves): weighted least
        squares, residuals (model − data)/σ; standard errors are scaled by the residual
        variance either way (like ``scipy.optimize.curve_fit`` with ``absolute_sigma=False``).
    progress : a progress line over optimiser iterations on stderr.

    Returns a :class:`FitResult`.  Raises ``ValueError`` for unknown or doubly-specified
    parameters, values outside bounds, non-identifiable combinations, curves that never reach
    contact or reach beyond the model's gap, and fewer than 3 points.
    """
    if optimizer not in OPTIMIZERS:
        raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {optimizer!r}")
    if int(max_iterations) < 1:
        raise ValueError(f"max_iterations must be a positive integer, got {max_iterations!r}")
    problem = fit_problem(curve, model, free=free, fixed=fixed, initial=initial, bounds=bounds, branch=branch,
                          max_points=max_points, min_compression=min_compression, method=method, settings=settings,
                          model_options=model_options, sigma=sigma)
    residuals, free, table = problem["residuals"], problem["free"], problem["table"]
    t0 = time.perf_counter()
    _check_start(residuals, problem)
    jac = jax.jit(jax.jacfwd(_with_value(residuals), has_aux=True))  # one path per evaluation
    bar = _Progress(progress, int(max_iterations))

    def report(iteration, loss, z=None):
        bar(iteration, loss, _float_values(problem["to_values"](z if z is not None else z_now[0])))

    z_now = [problem["z0"]]
    if optimizer == "lm":
        def tracked(z):
            z_now[0] = z
            return jac(z)

        z, r, J, history, converged, message, evaluations = _levenberg_marquardt(
            tracked, problem["z0"], int(max_iterations), float(tolerance), report)
    else:
        loss_fn = jax.jit(lambda z: 0.5 * jnp.sum(residuals(z) ** 2))
        loss_and_grad = jax.jit(jax.value_and_grad(lambda z: 0.5 * jnp.sum(residuals(z) ** 2)))

        z, history, converged, message, evaluations = _optax(
            loss_and_grad, loss_fn, problem["z0"], optimizer, int(max_iterations), float(tolerance),
            float(learning_rate), report)
    J, r = (np.asarray(a) for a in jac(jnp.asarray(z)))
    values = _float_values(problem["to_values"](jnp.asarray(z)))
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        from ._solve import ConvergenceError

        raise ConvergenceError(f"the fit ended at {values}, where the model path cannot be followed ({message}); "
                               "use optimizer='lm' or other initial values")
    bar(len(history), 0.5 * float(r @ r), values, done=True)
    for h in history:
        h["values"] = _float_values(problem["to_values"](jnp.asarray(h.pop("z"))))
    se, corr, cov, identifiable, warnings = _uncertainties(J, r, np.asarray(z), table, free)
    weighted, r = r, r * problem["sigma"]  # back to pN
    units = {n: table[n].unit for n in values}
    return FitResult(
        model=problem["model"].name, names=free, values=values, standard_errors=dict(zip(free, map(float, se))),
        correlation=corr, covariance=cov, loss=0.5 * float(weighted @ weighted), rms=float(np.sqrt(np.mean(r**2))),
        converged=bool(converged), message=message, identifiable=identifiable, warnings=warnings, history=history,
        compression=problem["compression"], force=problem["force"], model_force=problem["force"] + r, units=units,
        optimizer=optimizer, n_evaluations=int(evaluations) + 1, elapsed_s=time.perf_counter() - t0,
    )
