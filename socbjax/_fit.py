"""Least-squares fits of model parameters to a force–compression curve: :func:`fit`.

Model and residuals: :mod:`socbjax._fit_problem` (the probe force of a model, computed by
:func:`socbjax.compress` with ``at=`` the data compressions, with implicit derivatives).  The
loss is ½ Σ ((F̂ᵢ − Fᵢ)/σᵢ)² over the chosen branch (approach/loading by default).  Curves
with more than ``FitSettings.max_points`` points are averaged in compression bins first.

Optimisers and uncertainties: :mod:`socbjax._least_squares` (Levenberg–Marquardt by default,
Gauss–Newton standard errors).  Fitting ``force_scale`` together with every EI is refused up
front: the force of an elastica scales exactly with EI at fixed geometry, so one curve
determines only the product EI × force_scale.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._afm import hysteresis_energy
from ._io import finite_json
from ._fit_problem import BRANCHES, check_start, fit_problem, scaled_start
from ._fit_residuals import loss, loss_and_gradient, residuals_and_jacobian
from ._goodness import judge_fit
from ._least_squares import gauss_newton_uncertainties, levenberg_marquardt, optax_minimise
from ._path_settings import PathSettings
from ._progress import plural
from ._solution import RESULTS, ConvergenceError, result_name

__all__ = ["OPTIMIZERS", "FitResult", "FitSettings", "fit"]

OPTIMIZERS = ("lm", "adam", "lbfgs")


@dataclasses.dataclass(frozen=True)
class FitSettings:
    """How :func:`fit` optimises and which data it uses.

    optimizer : "lm" (Levenberg–Marquardt, default), "adam" or "lbfgs" (optax).
    max_iterations, tolerance : optimiser limits (relative loss decrease / step size).
    se_tolerance : Levenberg–Marquardt also stops when an accepted step moved every free
        parameter by less than this fraction of its standard error (default 0.02, cf. MINUIT's
        estimated-distance-to-minimum criterion 2e-4 ≈ (0.02 σ)²/2): further steps cannot change
        the answer measurably, and on a curve whose force jumps at contact (inextensible
        filaments) they creep along the contact point at a growing damping; 0: off.
    learning_rate : Adam's step size in the unconstrained variables.
    branch : "loading" (approach, default), "unloading" (retract) or "both" (a ForceCurve's
        approach and retract together, one path; ``FitResult.goodness`` then holds the
        hysteresis of data and model, ``hysteresis_data``/``hysteresis_model`` in pN·µm).
    max_points : curves with more points are averaged in this many compression bins.
    min_compression : drop points below this compression (µm); default for a ForceCurve
        −¼ of its maximum compression (some baseline before contact, not the whole approach).
    method : path following of :func:`socbjax.compress`: "displacement" (default, the AFM's
        own control; stops with a clear error at a fold) or "arclength" (follows
        snap-throughs; samples then take the first crossing of each compression).
    path : :class:`socbjax.PathSettings` of those compressions.
    """

    optimizer: str = "lm"
    max_iterations: int = 30
    tolerance: float = 1e-8
    se_tolerance: float = 0.02
    learning_rate: float = 0.05
    branch: str = "loading"
    max_points: int = 80
    min_compression: float | None = None
    method: str = "displacement"
    path: PathSettings | None = None

    def __post_init__(self):
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"FitSettings.optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if isinstance(self.max_iterations, bool) or int(self.max_iterations) != self.max_iterations or self.max_iterations < 1:
            raise ValueError(f"FitSettings.max_iterations must be a positive integer, got {self.max_iterations!r}")
        for name in ("tolerance", "learning_rate"):
            value = getattr(self, name)
            if not (math.isfinite(float(value)) and float(value) > 0):
                raise ValueError(f"FitSettings.{name} must be a positive finite number, got {value!r}")
        if not (math.isfinite(float(self.se_tolerance)) and float(self.se_tolerance) >= 0):
            raise ValueError(f"FitSettings.se_tolerance must be a finite fraction >= 0 of a standard error (0: off), "
                             f"got {self.se_tolerance!r}")
        if self.branch not in BRANCHES:
            raise ValueError(f"FitSettings.branch must be one of {BRANCHES}, got {self.branch!r}")
        if self.method not in ("displacement", "arclength"):
            raise ValueError(f"FitSettings.method must be 'displacement' or 'arclength', got {self.method!r}")
        if self.path is not None and not isinstance(self.path, PathSettings):
            raise TypeError(f"FitSettings.path must be a socbjax.PathSettings, got {type(self.path).__name__}")


class FitResult(eqx.Module):
    """Outcome of :func:`fit`.  Units: µm, pN, pN·µm², degrees (see ``units``).

    names : the free parameters, in the order of ``correlation``.
    values : every parameter the model was evaluated with (fitted and fixed).
    standard_errors : Gauss–Newton standard error of each free parameter.
    correlation, covariance : [p, p] over the free parameters.
    loss : final ½ Σ r² with r = (model − data)/σ (pN² when unweighted); rms : √(mean
        (model − data)²) (pN).
    converged, message : True only when the optimiser met its tolerance after moving the
        parameters (or started at a stationary point) and the model explains the data
        (R² > 0); ``message`` says why it stopped ("did not move ...", "hit the iteration
        budget ...", "not a fit: R² = ..." otherwise; ``result`` then is
        ``RESULTS.did_not_move``, ``nonlinear_max_steps_reached``, ``poor_fit``, or
        ``nonlinear_divergence`` when the optimiser's step left the followable path).
    r_squared : 1 − Σ(model − data)² / Σ(data − mean)² over the fitted points.
    identifiable : False when two free parameters are (nearly) perfectly correlated or JᵀJ is
        singular — then the values are not determined by the data (see ``warnings``).
    history : per iteration ``{"iteration", "loss", "values", "damping"}``.
    compression, force, model_force, residuals : [m] the data points fitted and the model.
    result : :class:`socbjax.RESULTS` item (``successful`` when ``converged``).
    noise (pN), noise_source ("baseline", "sigma" or "residuals"), chi2_reduced, misfit, aic,
        bic, n_parameters, goodness (every statistic): :func:`socbjax.goodness_of_fit`.  misfit
        (structured residuals or too large a χ²; a warning "the model misfits the data
        systematically: ..." gives the evidence) is independent of ``converged``.
    comparison : a :class:`socbjax.ModelComparison` when ``fit(..., compare=...)``, else None.
    realisation_errors : for models averaging random realisations (:class:`socbjax.LawnModel`):
        each free parameter's standard error from random outcrops alone (the model's finite
        sample of realisations and the experiment's own outcrops under the probe:
        :meth:`socbjax.LawnModel.realisation_covariance`); combine it with
        ``standard_errors`` in quadrature for the total.
    """

    model: str
    names: tuple
    values: dict
    standard_errors: dict
    correlation: np.ndarray
    covariance: np.ndarray
    loss: float
    rms: float
    r_squared: float
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
    result: RESULTS
    noise: float = math.nan
    noise_source: str = ""
    chi2_reduced: float = math.nan
    misfit: bool = False
    aic: float = math.nan
    bic: float = math.nan
    n_parameters: int = 0
    goodness: dict | None = None
    comparison: object = None
    realisation_errors: dict | None = None

    @property
    def residuals(self) -> np.ndarray:
        return self.model_force - self.force

    def summary(self) -> str:
        head = (f"fit of {self.model} ({self.optimizer}): {self.message}; loss {self.loss:.4g} pN², "
                f"rms {self.rms:.4g} pN, R² {self.r_squared:.3g}, over {plural(self.force.size, 'point')}")
        lines = [head]
        for name in self.names:
            extra = (f"  (realisations: ± {self.realisation_errors[name]:.2g})"
                     if self.realisation_errors and name in self.realisation_errors else "")
            lines.append(f"  {name:<14s} = {self.values[name]:.6g} ± {self.standard_errors[name]:.2g} {self.units[name]}"
                         + extra)
        fixed = [n for n in self.values if n not in self.names]
        if fixed:
            lines.append("  fixed: " + ", ".join(f"{n} = {self.values[n]:.4g} {self.units[n]}" for n in fixed))
        g = self.goodness or {}
        if "hysteresis_data" in g:
            lines.append(f"  hysteresis (approach − retract work): data {g['hysteresis_data']:.4g}, model "
                         f"{g['hysteresis_model']:.4g} pN·µm")
        chi2_p = "not a test" if self.noise_source == "residuals" else f"p = {g.get('chi2_p', math.nan):.2g}"
        lines.append(f"  goodness: noise {self.noise:.3g} pN (from the {self.noise_source}), χ²_red {self.chi2_reduced:.3g} "
                     f"({chi2_p}), runs test p = {g.get('runs', {}).get('p_value', math.nan):.2g}; AIC {self.aic:.5g}, "
                     f"BIC {self.bic:.5g}; " + ("MISFIT: the residuals are systematic" if self.misfit else "no systematic misfit"))
        lines.extend(f"  WARNING: {w}" for w in self.warnings)
        if self.comparison is not None:
            lines.append(self.comparison.table())
        return "\n".join(lines)

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in ("result", "comparison")}
        out["result"] = result_name(self.result)
        out["comparison"] = None if self.comparison is None else self.comparison.to_dict()
        for key in ("correlation", "covariance", "compression", "force", "model_force"):
            out[key] = np.asarray(out[key]).tolist()
        out["residuals"] = self.residuals.tolist()
        return finite_json(json.loads(json.dumps(out, default=float)))

    def save(self, path) -> None:
        """Write the result as JSON, atomically (temporary file, then rename)."""
        from ._io import atomic_path

        text = json.dumps(self.to_dict(), indent=2, allow_nan=False)
        atomic_path(path, lambda tmp: tmp.write_text(text))


class _Progress:
    """Progress on stderr, one line each: the phases (first evaluation, compilation), every
    optimiser iteration (iteration, loss, values, elapsed time), a rejected step when more
    than a second has passed without a line, and the end."""

    def __init__(self, enabled: bool, total: int, units: dict):
        self.enabled, self.total, self.units = enabled, total, units
        self.t0 = self.last = time.perf_counter()

    def _line(self, text: str) -> None:
        if self.enabled:
            self.last = time.perf_counter()
            sys.stderr.write(f" fit {self.last - self.t0:6.1f} s: {text}\n")
            sys.stderr.flush()

    def note(self, text: str) -> None:
        self._line(text)

    def _shown(self, values: dict) -> str:
        return ", ".join(f"{k} = {float(v):.6g} {self.units.get(k, '')}".rstrip() for k, v in values.items())

    def __call__(self, iteration: int, loss: float, values: dict, done: bool = False):
        head = f"done after {plural(iteration, 'iteration')}" if done else f"iteration {iteration}/{self.total}"
        self._line(f"{head}: loss {loss:.6g}; {self._shown(values)}")

    def rejected(self, iteration: int, damping: float) -> None:
        if time.perf_counter() - self.last >= 1.0:
            self._line(f"iteration {iteration}/{self.total}: step rejected (loss not lower), damping raised to {damping:.3g}")


def _float_values(values: dict) -> dict:
    return {k: float(v) for k, v in values.items()}


# ------------------------------------------------------------------------------ fit
def _optimise(problem, settings: FitSettings, jac, report, bar):
    """Run the chosen optimiser: (z, history, converged, message, evaluations)."""
    if settings.optimizer == "lm":
        z, _, _, history, converged, message, evaluations = levenberg_marquardt(
            jac, problem.z0, settings.max_iterations, settings.tolerance, report, bar.rejected, settings.se_tolerance)
        return z, history, converged, message, evaluations
    bar.note(f"compiling the loss's gradient ({settings.optimizer})")
    return optax_minimise(functools.partial(loss_and_gradient, problem.residuals), functools.partial(loss, problem.residuals),
                          problem.z0, settings.optimizer, settings.max_iterations, settings.tolerance,
                          settings.learning_rate, report)


def fit(curve, model="unit-mesh", *, free=("EI",), fixed: dict | None = None, initial: dict | None = None,
        bounds: dict | None = None, sigma=None, settings: FitSettings | None = None, model_options: dict | None = None,
        progress: bool = False, compare=None) -> FitResult:
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
    sigma : force uncertainty per point (pN; scalar or [m] for array curves): weighted least
        squares, residuals (model − data)/σ; standard errors are scaled by the residual
        variance either way (like ``scipy.optimize.curve_fit`` with ``absolute_sigma=False``).
    settings : :class:`socbjax.FitSettings` (optimiser, iterations, tolerance, branch, data
        binning and cropping, path following of the model).
    progress : a progress line over optimiser iterations on stderr.
    compare : models (names or FitModels), e.g. ``("column", "unit-mesh")``: also fit those
        (:func:`socbjax.compare_models`; default free parameters, this fit's dimension) and
        store the table, with this fit as a row, in ``result.comparison``.

    Returns a :class:`FitResult`.  Raises ``ValueError`` for unknown or doubly-specified
    parameters, values outside bounds, non-identifiable combinations, curves that never reach
    contact, and fewer than 3 points; ``FitRangeError`` (a ``ValueError``, with ``cause``
    "gap", "surface", "fold" or "path") when the model cannot be evaluated over the curve's
    range at the start: beyond its probe–surface gap, past the compression where its nodes
    cross the surface (no contact model), or past a fold under displacement control.

    Start: EI parameters without an ``initial`` value (when they set every segment's EI and
    neither ``force_scale`` nor ``perturbation`` is given) start at the default scaled to the
    data's force level — one least-squares factor, exact because the force is proportional
    to EI at fixed geometry.
    """
    settings = FitSettings() if settings is None else settings
    if not isinstance(settings, FitSettings):
        raise TypeError(f"settings must be a socbjax.FitSettings, got {type(settings).__name__}")
    problem = fit_problem(curve, model, free=free, fixed=fixed, initial=initial, bounds=bounds, sigma=sigma,
                          branch=settings.branch, max_points=settings.max_points,
                          min_compression=settings.min_compression, method=settings.method, path=settings.path,
                          model_options=model_options)
    t0 = time.perf_counter()
    table = problem.table
    bar = _Progress(progress, settings.max_iterations, {n: table[n].unit for n in table})
    bar.note(f"{plural(problem.force.size, 'data point')} up to {float(np.max(problem.compression)):.4g} µm, "
             f"{plural(len(problem.free), 'free parameter')} ({', '.join(problem.free)}); evaluating the {problem.model.name} "
             "model and its Jacobian at the start (the first evaluation compiles them: tens of seconds)")
    # One compiled program (the residuals and their Jacobian) serves the start's checks, the
    # optimiser and the uncertainties, and every later fit of this model, free names and data
    # size (the data are its inputs); a start that fails is diagnosed afterwards.
    jac = functools.partial(residuals_and_jacobian, problem.residuals)

    def residuals(z):
        return jac(jnp.asarray(z))[1]

    r0 = check_start(problem, problem.z0, residuals)
    loss0 = 0.5 * float(r0 @ r0)
    problem, note = scaled_start(problem, r0, dict(initial or {}), residuals)
    if note:
        bar.note(note)

    def report(iteration, loss, z):
        bar(iteration, loss, _float_values({n: v for n, v in problem.to_values(z).items() if n in problem.free}))

    z, history, converged, message, evaluations = _optimise(problem, settings, jac, report, bar)
    result = _result(problem, settings, jac, z, history, converged, message, evaluations, bar, t0, loss0,
                     sigma_given=sigma is not None)
    if compare is None:
        return result
    from ._compare import attach_comparison

    return attach_comparison(result, curve, compare, model, free=problem.free, model_options=model_options,
                             settings=settings, sigma=sigma, progress=progress, dim=problem.model.base.dim)


def _stationary(J: np.ndarray, r: np.ndarray) -> bool:
    """The residual is (numerically) orthogonal to every Jacobian column: a least-squares
    stationary point, whatever the optimiser (cosines below 1e-3)."""
    norms = np.linalg.norm(J, axis=0) * np.linalg.norm(r)
    return bool(np.all(np.abs(J.T @ r) <= 1e-3 * np.where(norms > 0, norms, 1.0)))


def _status(converged: bool, message: str, moved: bool, stationary: bool, r_squared: float):
    """(result, message): "converged" only when the optimiser met its tolerance, the
    parameters moved (or the start already was stationary) and the model explains the data."""
    if not r_squared > 0.0:
        return RESULTS.poor_fit, f"not a fit: R² = {r_squared:.3g} ({message})"
    if not moved and not stationary:
        return RESULTS.did_not_move, f"did not move from the initial values ({message})"
    if not converged and message.startswith("reached max_iterations"):
        return RESULTS.nonlinear_max_steps_reached, f"hit the iteration budget: {message}"
    if not converged:
        return RESULTS.nonlinear_divergence, message
    return RESULTS.successful, message


def _hysteresis(problem, r) -> dict:
    """Data and model hysteresis (pN·µm) when both branches were fitted, else {}."""
    back = problem.retract
    if back is None or back.all() or not back.any():
        return {}
    c, F, model = problem.compression, problem.force, problem.force + r
    return {"hysteresis_data": hysteresis_energy(c[~back], F[~back], c[back], F[back]),
            "hysteresis_model": hysteresis_energy(c[~back], model[~back], c[back], model[back])}


def _result(problem, settings, jac, z, history, converged, message, evaluations, bar, t0, loss0,
            sigma_given: bool = False) -> FitResult:
    J, r = (np.asarray(a) for a in jac(jnp.asarray(z)))
    values = _float_values(problem.to_values(jnp.asarray(z)))
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        raise ConvergenceError(f"the fit ended at {values}, where the model path cannot be followed ({message}); "
                               "use the 'lm' optimizer or other initial values")
    bar(len(history), 0.5 * float(r @ r), {n: values[n] for n in problem.free}, done=True)
    for h in history:
        h["values"] = _float_values(problem.to_values(jnp.asarray(h.pop("z"))))
    free, table = problem.free, problem.table
    se, corr, cov, identifiable, warnings = gauss_newton_uncertainties(J, r, np.asarray(z), table, free)
    weighted, r = r, r * problem.sigma  # back to pN
    spread = float(np.sum((problem.force - problem.force.mean()) ** 2))
    r_squared = 1.0 - float(r @ r) / spread if spread > 0 else -math.inf
    moved = 0.5 * float(weighted @ weighted) < loss0 * (1.0 - 1e-12)
    result, message = _status(converged, message, moved, _stationary(J, weighted), r_squared)
    goodness = judge_fit(problem, values, r, sigma_given)
    realisation = (problem.model.realisation_errors(problem, values, J, np.asarray(z))
                   if hasattr(problem.model, "realisation_errors") and np.all(np.isfinite(se)) else None)
    if goodness.misfit:
        warnings = [goodness.warning()] + warnings
    if result != RESULTS.successful:
        warnings = [f"{message}: {RESULTS[result]}"] + warnings
    if goodness.notes:
        warnings = warnings + ["; ".join(goodness.notes)]
    return FitResult(
        model=problem.model.name, names=free, values=values, standard_errors=dict(zip(free, map(float, se))),
        correlation=corr, covariance=cov, loss=0.5 * float(weighted @ weighted), rms=float(np.sqrt(np.mean(r**2))),
        converged=bool(result == RESULTS.successful), message=message, identifiable=identifiable, warnings=warnings,
        history=history, r_squared=r_squared,
        compression=problem.compression, force=problem.force, model_force=problem.force + r,
        units={n: table[n].unit for n in values}, optimizer=settings.optimizer, n_evaluations=int(evaluations) + 1,
        elapsed_s=time.perf_counter() - t0, result=result, noise=goodness.noise, noise_source=goodness.noise_source,
        chi2_reduced=goodness.chi2_reduced, misfit=goodness.misfit, aic=goodness.aic, bic=goodness.bic,
        n_parameters=len(free), goodness={**goodness.to_dict(), **_hysteresis(problem, r)}, realisation_errors=realisation,
    )
